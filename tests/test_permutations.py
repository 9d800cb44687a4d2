import itertools

import numpy as np
import pytest

from transync.permutations import (
    assignment_to_matrix,
    check_assignment,
    compose,
    cycle_inconsistency,
    invert,
    is_partial_permutation_matrix,
    matrix_to_assignment,
    random_permutation,
    solve_lap,
)


def test_matrix_round_trip_partial(rng):
    a = np.array([3, -1, 0, 1])
    X = assignment_to_matrix(a, n2=5)
    assert X.shape == (4, 5)
    assert is_partial_permutation_matrix(X)
    np.testing.assert_array_equal(matrix_to_assignment(X), a)


def test_invert_round_trip(rng):
    p = random_permutation(9, rng)
    np.testing.assert_array_equal(compose(p, invert(p, 9)), np.arange(9))
    np.testing.assert_array_equal(compose(invert(p, 9), p), np.arange(9))


def test_compose_matches_matrix_product(rng):
    a = np.array([2, 0, -1, 1])
    b = np.array([1, -1, 3])
    np.testing.assert_array_equal(
        assignment_to_matrix(compose(a, b), 4),
        assignment_to_matrix(a, 3) @ assignment_to_matrix(b, 4))


def test_solve_lap_brute_force(rng):
    for n1, n2 in [(4, 4), (3, 5), (5, 3)]:
        S = rng.random((n1, n2))
        a = solve_lap(S)
        best = max(
            sum(S[i, p[i]] for i in range(min(n1, n2)))
            if n1 <= n2 else sum(S[p[j], j] for j in range(n2))
            for p in itertools.permutations(range(max(n1, n2)), min(n1, n2)))
        got = sum(S[i, a[i]] for i in range(n1) if a[i] >= 0)
        assert got == pytest.approx(best)
        assert (a >= 0).sum() == min(n1, n2)


def test_solve_lap_threshold():
    a = solve_lap(np.array([[0.9, 0.1], [0.2, 0.05]]), min_score=0.1)
    np.testing.assert_array_equal(a, [0, -1])


@pytest.mark.parametrize("bad, msg", [
    (np.array([[0, 1]]), "1-d"),
    (np.array([0, 0]), "injective"),
    (np.array([-2, 0]), ">= -1"),
    (np.array([0.5, 1.0]), "integers"),
])
def test_check_assignment_errors(bad, msg):
    with pytest.raises((ValueError, TypeError), match=msg):
        check_assignment(bad)


def test_check_assignment_range():
    with pytest.raises(ValueError, match="< n2=2"):
        check_assignment([0, 2], n2=2)


def test_matrix_to_assignment_rejects_soft():
    with pytest.raises(ValueError, match="solve_lap"):
        matrix_to_assignment(np.full((2, 2), 0.5))


def test_cycle_inconsistency_detects_a_broken_triangle(rng):
    P = [random_permutation(5, rng) for _ in range(4)]
    # consistent: pairwise i->j = P_j^{-1} o P_i  (node u of i -> universe P_i[u] -> node of j)
    pairs = {(i, j): compose(P[i], invert(P[j], 5)) for i in range(4) for j in range(i + 1, 4)}
    rep = cycle_inconsistency(pairs)
    assert rep["n_triangles"] == 4 and rep["inconsistent_triangles"] == 0.0
    pairs[(0, 1)] = pairs[(0, 1)][[1, 0, 2, 3, 4]]
    rep = cycle_inconsistency(pairs)
    assert rep["inconsistent_triangles"] == 0.5   # the two triangles through (0, 1)
    assert rep["cycle_error"] > 0


# ---------------------------------------------------------------- partial maps and cycles

def _partial_collection(seed, sizes=(5, 6, 8, 3, 7), d=8):
    from transync.permutations import MultiMatching

    rng = np.random.default_rng(seed)
    labels = [rng.permutation(d)[:k] for k in sizes]
    m = MultiMatching(labels, d)
    pairs = np.array([[i, j] for i in range(len(sizes)) for j in range(i + 1, len(sizes))])
    return m, pairs, np.array(sizes)


@pytest.mark.parametrize("seed", range(5))
def test_partial_maps_from_universe_labels_are_cycle_consistent(seed):
    from transync.permutations import cycle_inconsistency_arrays

    m, pairs, sizes = _partial_collection(seed)
    rep = cycle_inconsistency_arrays(pairs, m.pairwise_array(pairs), sizes)
    assert rep["n_triangles"] == 10 and rep["cycle_error"] == 0.0


def test_partial_maps_inconsistency_is_found_in_every_orientation():
    """A violation visible only through the middle object i (j -> i -> k) is still found."""
    from transync.permutations import cycle_inconsistency_arrays

    pairs = np.array([[0, 1], [0, 2], [1, 2]])
    sizes = np.array([2, 2, 2])
    # node 0 of graph 0 <-> node 0 of graph 1 and node 0 of graph 2, but 1 -> 2 leaves node 0
    # of graph 1 unmatched: only the orientations through graph 0 see it
    maps = np.array([[0, -1], [0, -1], [-1, -1]])
    rep = cycle_inconsistency_arrays(pairs, maps, sizes)
    assert rep["inconsistent_triangles"] == 1.0 and rep["cycle_error"] == 0.5
    # a node unmatched by the first hop constrains nothing: consistent
    ok = np.array([[0, -1], [-1, -1], [-1, -1]])
    assert cycle_inconsistency_arrays(pairs, ok, sizes)["cycle_error"] == 0.0


def test_full_permutations_count_as_before():
    """For full permutations the orientations agree: one swap in one map of a triangle."""
    from transync.permutations import cycle_inconsistency_arrays

    pairs = np.array([[0, 1], [0, 2], [1, 2]])
    maps = np.array([[0, 1, 2], [0, 1, 2], [1, 0, 2]])
    rep = cycle_inconsistency_arrays(pairs, maps, [3, 3, 3])
    assert rep["cycle_error"] == pytest.approx(2 / 3)


def test_cycle_inconsistency_sizes_make_the_direction_irrelevant():
    # a partial map given only as (j, i) leaves node 1 of object 0 unseen: its inferred size was
    # 1 and the error doubled (0.5 -> 1.0); with `sizes` both directions agree
    from transync.permutations import cycle_inconsistency, invert

    sizes = [2, 1, 1, 4]
    p = {(0, 1): np.array([-1, -1]), (0, 2): np.array([0, -1]), (1, 2): np.array([0]),
         (2, 3): np.array([3])}
    rev = {(j, i): invert(a, sizes[j]) for (i, j), a in p.items()}
    assert cycle_inconsistency(p)["cycle_error"] == 0.5
    assert cycle_inconsistency(rev, sizes=sizes) == cycle_inconsistency(p, sizes=sizes) \
        == cycle_inconsistency(p)
    with pytest.raises(ValueError, match="`sizes` gives object 0 1 nodes"):
        cycle_inconsistency({(0, 1): np.array([0, 1])}, sizes=[1, 2])
    with pytest.raises(ValueError, match=r"keys must be pairs .* got \(-1, 2\)"):
        cycle_inconsistency({(-1, 2): np.array([0])})


def test_cycle_inconsistency_refuses_maps_that_give_an_object_two_sizes():
    """Without `sizes`, object 0 as a source of 3 and of 2 nodes, or object 1 a target of node
    4 and a source of 2 nodes, was scored (cycle errors 0.33 and 1.0) instead of refused, as
    `sizes` and the synchronizers refuse it."""
    from transync.permutations import cycle_inconsistency

    a = np.arange
    with pytest.raises(ValueError, match=r"`pairwise\[\(0, 2\)\]` has 2 entries, but "
                                         r"`pairwise\[\(0, 1\)\]` has 3"):
        cycle_inconsistency({(0, 1): a(3), (1, 2): a(3), (0, 2): a(2)})
    with pytest.raises(ValueError, match=r"`pairwise\[\(0, 1\)\]` maps a node to node 4 of "
                                         r"object 1, but `pairwise\[\(1, 2\)\]` gives object 1 "
                                         r"2 nodes"):
        cycle_inconsistency({(0, 1): np.array([4, 0]), (1, 2): a(2), (0, 2): a(2)})
    # partial maps between objects of different sizes, both directions given: consistent
    p = {(0, 1): np.array([0, 1, -1]), (1, 0): np.array([0, 1]), (1, 2): np.array([0, -1]),
         (2, 0): np.array([2, 0, 1, -1])}
    assert cycle_inconsistency(p) == cycle_inconsistency(p, sizes=[3, 2, 4])


def test_cycle_inconsistency_of_maps_into_empty_objects():
    # the last object seen only through empty maps was not counted, and an internal `pairs`
    # argument was named in the error
    from transync.permutations import MultiMatching, cycle_inconsistency

    m = MultiMatching([np.array([], dtype=int), np.array([], dtype=int), np.array([0, 1])], 3)
    assert cycle_inconsistency(m.pairwise_dict())["cycle_error"] == 0.0


def test_cycle_inconsistency_sparse_indices_sizes_and_self_keys():
    """A key (0, 10**6) built a (10**6, 10**6) pair table (MemoryError, 7 TiB); sizes naming an
    object of 10**9 nodes padded every map to that width (a hang); a self key (0, 0) was
    ignored silently."""
    a = np.array
    assert cycle_inconsistency({(0, 10**6): a([0])})["n_triangles"] == 0
    assert cycle_inconsistency({(0, 10**30): a([0])})["n_triangles"] == 0
    tri = {(0, 1): a([1, 0]), (1, 2): a([1, 0]), (0, 2): a([0, 1])}
    far = {(5, 70): a([1, 0]), (70, 900): a([1, 0]), (5, 900): a([0, 1])}
    assert cycle_inconsistency(tri) == cycle_inconsistency(far)
    with pytest.raises(ValueError, match=r"`sizes` gives object 2 1000000000 nodes"):
        cycle_inconsistency(tri, sizes=[2, 2, 10**9])
    with pytest.raises(ValueError, match=r"distinct non-negative object indices, got \(0, 0\)"):
        cycle_inconsistency({(0, 0): a([0])})


def test_cycle_inconsistency_arrays_scales_past_ten_thousand_objects():
    """The (N, N) pair table refused (and before that allocated) N**2 entries: a chain of
    20 000 objects, which synchronize_permutations reports on, failed after its solve."""
    from transync.permutations import cycle_inconsistency_arrays

    N = 20_000
    pairs = np.column_stack([np.arange(N - 1), np.arange(1, N)])
    maps = np.tile([1, 0], (N - 1, 1))
    rep = cycle_inconsistency_arrays(pairs, maps, np.full(N, 2))
    assert rep["n_triangles"] == 0 and not rep["sampled"]       # a chain has no triangle
    tri = np.array([[0, 1], [1, 2], [0, 2]])
    rep = cycle_inconsistency_arrays(tri, np.array([[1, 0], [1, 0], [1, 0]]), [2, 2, 2])
    assert rep == {"n_triangles": 1, "inconsistent_triangles": 1.0, "cycle_error": 1.0,
                   "sampled": False}


def test_cycle_inconsistency_arrays_refuses_maps_that_are_not_assignments():
    """The array form scored a node mapped twice (cycle error 0.5) and a target beyond its
    object, which the dict form refuses."""
    from transync.permutations import cycle_inconsistency_arrays as cia

    pairs = [[0, 1], [1, 2], [0, 2]]
    with pytest.raises(ValueError, match=r"`maps\[0\]` \(pair \(0, 1\)\) uses a target twice"):
        cia(pairs, [[0, 0], [0, 1], [0, 1]], [2, 2, 2])
    with pytest.raises(ValueError, match=r"`maps\[0\]` \(pair \(0, 1\)\) targets a node beyond "
                                         r"the size of object 1"):
        cia(pairs, [[1, 0], [0, -1], [0, 1]], [2, 1, 2])
    with pytest.raises(ValueError, match=r"`maps\[1\]` \(pair \(1, 2\)\) maps a node beyond "
                                         r"the size of object 1"):
        cia(pairs, [[0, -1], [0, 1], [0, 1]], [2, 1, 2])
    ok = cia(pairs, [[0, -1], [0, -1], [0, 1]], [2, 1, 2])      # partial, padded: valid
    assert ok["n_triangles"] == 1


def test_first_invalid_assignment_is_the_batched_check_assignment():
    """One home for validating many int assignments at once (the synchronizations' parser and
    cycle_inconsistency_arrays): the first invalid one in order, or None past one sort key."""
    from transync.permutations import check_assignment, first_invalid_assignment

    maps = [np.array([1, 0, -1]), np.array([0]), np.array([2, -1, 2]), np.array([-2, 0])]
    flat, lengths = np.concatenate(maps), np.array([len(m) for m in maps])
    assert first_invalid_assignment(flat, lengths) == 2
    for k, m in enumerate(maps):                       # the same verdict as one by one
        ok = True
        try:
            check_assignment(m)
        except ValueError:
            ok = False
        assert ok == (k < 2)
    assert first_invalid_assignment(flat[:4], lengths[:2]) == -1
    assert first_invalid_assignment(np.array([2**61, 0, 1]), np.array([1, 1, 1])) is None


def test_cycle_inconsistency_arrays_checks_huge_targets_row_by_row():
    from transync.permutations import cycle_inconsistency_arrays as cia

    big = 2**61
    with pytest.raises(ValueError, match=r"`maps\[0\]` \(pair \(0, 1\)\) uses a target twice"):
        cia([[0, 1], [1, 2], [0, 2]], [[big - 1, big - 1], [0, 1], [0, 1]], [2, big, 2])


def test_first_invalid_assignment_checks_its_arrays():
    """Public since it validates ENZYMES' maps at once; it leaked numpy's IndexError on lengths
    that do not add up and on float entries (found by a review)."""
    from transync.permutations import first_invalid_assignment

    assert first_invalid_assignment(np.array([1, 0, 0, -1, 2, 2]), np.array([2, 2, 2])) == 2
    assert first_invalid_assignment([0, 1, 0], [2, 1]) == -1            # lists are arrays
    with pytest.raises(ValueError, match=r"`lengths` must sum to len\(flat\) = 1, got 2"):
        first_invalid_assignment(np.array([0]), np.array([2]))
    with pytest.raises(TypeError, match="`flat` must hold integers"):
        first_invalid_assignment(np.array([0.5]), np.array([1]))
    with pytest.raises(ValueError, match="`lengths` must be non-negative, got -1"):
        first_invalid_assignment(np.array([0, 1]), np.array([-1, 3]))


def test_cycle_inconsistency_refuses_a_target_too_large_to_pad_to():
    """A target of 10**12 made the object that size, and padding the maps to it asked for
    7 TiB (a MemoryError); it is refused by name, as `sizes` that large already were."""
    with pytest.raises(ValueError, match=r"`pairwise\[\(0, 1\)\]` maps a node to node "
                                         r"1000000000000 of object 1: .*\(more than 1e\+08\)"):
        cycle_inconsistency({(0, 1): np.array([10**12, -1, 0])})
    res = cycle_inconsistency({(0, 1): np.array([5, -1, 0]), (1, 2): np.arange(6),
                               (0, 2): np.array([5, -1, 0])})
    assert res["n_triangles"] == 1 and res["cycle_error"] == 0.0


def test_none_is_not_an_assignment():
    with pytest.raises(TypeError, match="`assignment` must be a 1-d integer index array, got "
                                        "NoneType"):
        check_assignment(None)



def test_cycle_inconsistency_finds_the_triangles_of_a_sparse_view_graph():
    # triples were drawn among all C(N, 3): one inconsistent triangle beside a chain of 200
    # objects was never hit, and {"n_triangles": 0, "cycle_error": 0.0} read as consistent
    from transync.permutations import cycle_inconsistency, cycle_inconsistency_arrays

    d = {(0, 1): np.array([1, 0]), (1, 2): np.array([1, 0]), (0, 2): np.array([1, 0])}
    d.update({(g, g + 1): np.array([0, 1]) for g in range(2, 199)})
    want = {"n_triangles": 1, "inconsistent_triangles": 1.0, "cycle_error": 1.0,
            "sampled": False}
    assert cycle_inconsistency(d, rng=0) == want
    assert cycle_inconsistency_arrays([[0, 1], [1, 2], [0, 2]], [[1, 0]] * 3, [2] * 200,
                                      rng=0) == want
    # above max_triangles: a uniform sample of the triangles themselves, every one checked
    rng = np.random.default_rng(0)
    N, n = 30, 4
    iu = np.array(np.triu_indices(N, 1)).T
    keep = iu[rng.random(len(iu)) < 0.5]
    maps = np.array([rng.permutation(n) for _ in range(len(keep))])
    full = cycle_inconsistency_arrays(keep, maps, [n] * N)
    assert not full["sampled"] and full["n_triangles"] > 300
    part = cycle_inconsistency_arrays(keep, maps, [n] * N, max_triangles=200, rng=1)
    assert part["sampled"] and part["n_triangles"] == 200
    assert abs(part["cycle_error"] - full["cycle_error"]) < 0.1


def test_named_refusals_of_other_and_dtype():
    from transync.permutations import MultiMatching, assignment_to_matrix

    m = MultiMatching([np.array([0]), np.array([0])])
    with pytest.raises(TypeError, match=r"`other` must be a MultiMatching.*got NoneType"):
        m.accuracy(None)                      # named `labels`, the constructor's argument
    with pytest.raises(TypeError, match=r"`dtype` must be a numpy data type, got 'bogus'"):
        assignment_to_matrix([0], 1, dtype="bogus")          # numpy's own message


def test_pair_rows_answers_only_for_its_own_pairs():
    # (0, 3) with N = 2 has the key of (1, 1) and got its row; (0, 1.9) was read as (0, 1)
    from transync.permutations import pair_rows

    rows = pair_rows([[0, 1], [1, 1]], 2)
    assert rows(np.array([0, 0, -1]), np.array([3, 1, 1])).tolist() == [-1, 0, -1]
    with pytest.raises(TypeError, match=r"queries must be integer arrays"):
        rows(np.array([0]), np.array([1.9]))
