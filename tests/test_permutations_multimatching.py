"""MultiMatching: the one type for universe labels and the pairwise maps derived from them
(issue 9, item 1)."""

import pickle

import numpy as np
import pytest

from transync.permutations import MultiMatching, assignment_to_matrix, cycle_inconsistency


def _random_matching(rng, n_objects=6, d=7):
    labels = []
    for _ in range(n_objects):
        n = int(rng.integers(1, d + 1))
        lab = rng.permutation(d)[:n]
        lab[rng.random(n) < 0.2] = -1                     # some nodes not placed
        labels.append(lab)
    return MultiMatching(labels, d)


def test_pairwise_follows_slots_and_is_cycle_consistent(rng):
    m = _random_matching(rng)
    for i in range(m.n_objects):
        for j in range(m.n_objects):
            a = m.pairwise(i, j)
            assert a.shape == (m.sizes[i],)
            for u, v in enumerate(a):
                slot = m.labels[i][u]
                if v >= 0:
                    assert m.labels[j][v] == slot >= 0
                else:
                    assert slot < 0 or slot not in m.labels[j]
    full = MultiMatching([rng.permutation(5) for _ in range(6)])
    assert cycle_inconsistency(full.pairwise_dict())["inconsistent_triangles"] == 0.0


def test_absolute_to_matrix_and_pairwise_array_agree(rng):
    m = _random_matching(rng)
    X = np.vstack([m.absolute(g) for g in range(m.n_objects)])
    T = X @ X.T
    np.fill_diagonal(T, 1.0)
    np.testing.assert_array_equal(m.to_matrix(), T)
    pairs = np.array([[0, 1], [3, 2], [5, 0]])
    arr = m.pairwise_array(pairs)
    for p, (i, j) in enumerate(pairs):
        np.testing.assert_array_equal(arr[p, : m.sizes[i]], m.pairwise(i, j))
        assert np.all(arr[p, m.sizes[i]:] == -1)
        np.testing.assert_array_equal(m.absolute(i) @ m.absolute(j).T,
                                      assignment_to_matrix(m.pairwise(i, j), m.sizes[j]))
    assert set(m.pairwise_dict()) == {(i, j) for i in range(6) for j in range(i + 1, 6)}


def test_tables_do_not_depend_on_the_universe_size():
    """A huge n_universe costs nothing: the maps use the slots actually used."""
    m = MultiMatching([np.array([5, 10**12]), np.array([10**12, -1, 5])], 10**15)
    np.testing.assert_array_equal(m.pairwise(0, 1), [2, 0])
    np.testing.assert_array_equal(m.pairwise(1, 0), [1, -1, 0])
    assert m.to_matrix().shape == (5, 5)


def test_accuracy_against_labels_maps_and_results():
    truth = MultiMatching([np.array([0, 1, 2]), np.array([2, 0, 1]), np.array([1, 2])])
    assert truth.accuracy(truth) == 1.0
    pred = MultiMatching([np.array([0, 1, 2]), np.array([2, 0, -1]), np.array([1, 2])])
    assert truth.accuracy(pred) == pytest.approx(5 / 7)
    assert truth.accuracy(pred.labels) == pytest.approx(5 / 7)          # plain labels
    assert truth.accuracy(pred.pairwise_dict()) == pytest.approx(5 / 7)  # pairwise maps
    # a missing pair recovers nothing; a reversed key is inverted
    maps = {(1, 0): truth.pairwise(1, 0), (0, 2): truth.pairwise(0, 2)}
    assert truth.accuracy(maps) == pytest.approx(5 / 7)
    assert truth.accuracy(pred, pairs=[[0, 2]]) == 1.0
    with pytest.raises(ValueError, match=r"`other` must hold 3 objects of sizes \[3, 3, 2\]"):
        truth.accuracy([np.array([0, 1, 2])])
    with pytest.raises(ValueError, match=r"`other\[\(0, 1\)\]` must have length 3"):
        truth.accuracy({(0, 1): np.array([0, 1])})
    with pytest.raises(ValueError, match=r"`pairs` must hold object indices in \[0, 3\)"):
        truth.accuracy(pred, pairs=[[0, 3]])


def test_equality_pickle_and_immutability():
    m = MultiMatching([np.array([1, 0]), np.array([0, -1, 1])])
    assert m.n_universe == 2 and m.sizes.tolist() == [2, 3]
    m2 = pickle.loads(pickle.dumps(m))
    assert m2 == m and m2 is not m
    assert m != MultiMatching([np.array([1, 0]), np.array([0, -1, 1])], 3)
    with pytest.raises(ValueError):
        m.labels[0][0] = 1                                # read-only: the result is frozen
    assert MultiMatching.from_labels(m) is m
    assert MultiMatching.from_labels(m, 4).n_universe == 4


def test_degenerate_but_legal():
    empty = MultiMatching([])
    assert empty.n_objects == 0 and empty.n_universe == 0
    assert empty.accuracy(empty) == 1.0
    one = MultiMatching([np.array([0]), np.array([0])])
    np.testing.assert_array_equal(one.pairwise(1, 0), [0])
    unplaced = MultiMatching([np.array([-1, -1]), np.array([], dtype=int)], 3)
    np.testing.assert_array_equal(unplaced.pairwise(0, 1), [-1, -1])
    assert unplaced.to_matrix().shape == (2, 2)


@pytest.mark.parametrize("labels, kwargs, exc, match", [
    ([np.array([0, 0])], {}, ValueError, r"`labels\[0\]` must be injective"),
    ([np.array([0, 1]), np.array([0, 3])], {"n_universe": 3}, ValueError,
     r"`labels\[1\]` entries must be < n_universe=3, got 3"),
    ([np.array([0, -2])], {}, ValueError, r"`labels\[0\]` entries must be >= -1, got -2"),
    ([np.array([0.0, np.nan])], {}, TypeError, r"`labels\[0\]` must hold integers .*nan"),
    ([np.array([0.5])], {}, TypeError, r"`labels\[0\]` must hold integers .*0.5"),
    ([np.array(["a"])], {}, TypeError, r"`labels\[0\]` must hold integers"),
    ([np.array([1j])], {}, TypeError, r"`labels\[0\]` must hold integers"),
    ([np.zeros((2, 2), int)[None]], {}, ValueError, r"`labels\[0\]` must be a 1-d"),
    ("abc", {}, TypeError, "`labels` must be a sequence"),
    ([np.array([0])], {"n_universe": -1}, ValueError, "`n_universe` must be >= 0"),
    ([np.array([0])], {"n_universe": 1.5}, TypeError, "`n_universe` must be an int"),
])
def test_validation(labels, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        MultiMatching(labels, **kwargs)


def test_object_indices_checked():
    m = MultiMatching([np.array([0]), np.array([0])])
    with pytest.raises(ValueError, match=r"`j` must be an object index in \[0, 2\), got 2"):
        m.pairwise(0, 2)
    with pytest.raises(TypeError, match="`g` must be an int"):
        m.absolute("0")
    with pytest.raises(ValueError, match="max_size"):
        m.to_matrix(max_size=1)


def test_converters_bound_their_outputs():
    """Issue 13: huge sizes gave MemoryError; now a clear error names the argument."""
    from transync.permutations import assignment_to_matrix, identity, invert, random_permutation
    with pytest.raises(ValueError, match="`n` must be <= 100000000"):
        identity(10**12)
    with pytest.raises(ValueError, match="`n` must be <= 100000000"):
        random_permutation(10**12, rng=0)
    with pytest.raises(ValueError, match="`n2` must be <= 100000000"):
        invert(np.array([0, 1]), 10**12)
    with pytest.raises(ValueError, match="would build a matrix of"):
        assignment_to_matrix(np.arange(20000), 10**5)
    with pytest.raises(TypeError, match="`n2` must be an int"):
        assignment_to_matrix(np.array([0]), 2.5)


def test_pairs_given_in_one_direction_only_with_unequal_sizes():
    """Regression: maps given only as (j, i) were inverted with the wrong target size."""
    from transync.permutations import MultiMatching, cycle_inconsistency

    m = MultiMatching([np.array([0, 1, 2]), np.array([2, 1])])
    assert m.accuracy({(1, 0): np.array([2, 1])}) == 1.0
    assert m.accuracy({(0, 1): np.array([-1, 1, 0])}) == 1.0
    rep = cycle_inconsistency({(1, 0): np.array([2, 1]), (1, 2): np.array([0, 1]),
                               (0, 2): np.array([-1, 1, 0])})
    assert rep["n_triangles"] == 1 and rep["inconsistent_triangles"] == 0.0


def test_many_objects_need_no_objects_by_slots_table(monkeypatch):
    """10**5 objects of 2 nodes in distinct slots: pairwise(0, 1) allocated a 10**5 x 2 * 10**5
    table (149 GiB, MemoryError); the binary-search lookup gives the dense table's answers."""
    import transync.permutations as perm

    big = MultiMatching([np.array([2 * g, 2 * g + 1]) for g in range(10**5)])
    np.testing.assert_array_equal(big.pairwise(0, 1), [-1, -1])
    same = MultiMatching([np.array([0, 1])] * 10**5)
    np.testing.assert_array_equal(same.pairwise(7, 99_999), [0, 1])
    rng = np.random.default_rng(0)
    for trial in range(20):
        d = int(rng.integers(1, 9))
        labels = [np.where(rng.random(k) < 0.3, -1, rng.permutation(d)[:k])
                  for k in rng.integers(0, d + 1, size=int(rng.integers(1, 7)))]
        dense = MultiMatching(labels).pairwise_array(pairs=None if len(labels) > 1 else [])
        monkeypatch.setattr(perm, "_DENSE_INVERSE", 0)
        m = MultiMatching(labels)
        np.testing.assert_array_equal(m.pairwise_array(pairs=None if len(labels) > 1 else []),
                                      dense)
        for i in range(len(labels)):
            for j in range(len(labels)):
                monkeypatch.setattr(perm, "_DENSE_INVERSE", 2**24)
                want = MultiMatching(labels).pairwise(i, j)
                monkeypatch.setattr(perm, "_DENSE_INVERSE", 0)
                np.testing.assert_array_equal(MultiMatching(labels).pairwise(i, j), want)
        monkeypatch.setattr(perm, "_DENSE_INVERSE", 2**24)


def test_dense_views_and_pair_lookup_name_their_own_limits():
    """to_matrix(max_size="a") raised a bare comparison TypeError and max_size=nan switched the
    limit off; absolute() and to_matrix() named an internal `n2` / `assignment`; pair_rows did
    no validation ([[0, 5]] among 3 objects collided with the key of (1, 2))."""
    import numpy as np
    import pytest

    from transync.permutations import MultiMatching, pair_rows

    m = MultiMatching([np.array([0, -1, 1]), np.array([1, 0])], 3)
    for bad in ("a", float("nan"), None):
        with pytest.raises(TypeError, match="`max_size` must be an int"):
            m.to_matrix(max_size=bad)
    with pytest.raises(ValueError, match=r"absolute\(0\) would build a 1 x 1000000000000000000 "):
        MultiMatching([[0]], n_universe=10**18).absolute(0)
    with pytest.raises(ValueError, match=r"to_matrix\(\) would build a 30000 x 30000 matrix \(at "
                                         r"most 20000 x 20000"):
        MultiMatching([np.arange(30000)]).to_matrix(max_size=10**9)
    T = m.to_matrix()
    assert T.shape == (5, 5) and np.array_equal(np.diag(T), np.ones(5))
    assert T[0, 4] == 1 and T[2, 3] == 1 and T[1].sum() == 1       # node 1 unplaced
    with pytest.raises(ValueError, match=r"`pairs` must hold object indices in \[0, 3\)"):
        pair_rows([[0, 5]], 3)
    with pytest.raises(TypeError, match="`pairs`"):
        pair_rows("ab", 3)
    with pytest.raises(ValueError, match=r"`pairs` must have shape \(Q, 2\)"):
        pair_rows([[0, 1, 2]], 3)
    assert pair_rows([[0, 1], [2, 1]], 3)(np.array([1, 0]), np.array([2, 2])).tolist() == [1, -1]
