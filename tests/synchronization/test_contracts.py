"""Synchronization results and inputs: one result type, picklable results, one pairwise parser
with one meaning of `mask`, and clear errors on bad input (issues 9 and 13)."""

import pickle
import warnings

import numpy as np
import scipy.sparse as sp
import pytest

from transync.datasets import make_noisy_linear_maps, make_permutation_collection
from transync.exceptions import ConvergenceWarning, DegenerateInputError
from transync.permutations import MultiMatching, assignment_to_matrix
from transync.synchronization import (
    BirkhoffSyncResult,
    LinearMapSyncResult,
    PermutationSyncResult,
    birkhoff_von_neumann,
    synchronize_doubly_stochastic,
    synchronize_homographies,
    synchronize_linear_maps,
    synchronize_permutations,
)


@pytest.fixture(scope="module")
def data():
    return make_permutation_collection(7, 5, corruption=0.2, rng=3)


def _soft(data):
    return {k: assignment_to_matrix(a, 5) for k, a in data.pairwise.items()}


# ------------------------------------------------------------------------------ result types

@pytest.mark.parametrize("method", ["spectral", "orthogonal", "matcheig"])
def test_permutation_results_pickle_and_keep_their_type(data, method):
    res = synchronize_permutations(data.pairwise, method=method, rng=0)
    assert type(res) is PermutationSyncResult
    assert isinstance(res.matching, MultiMatching)
    assert res.labels is res.matching.labels and res.n_universe == res.matching.n_universe
    back = pickle.loads(pickle.dumps(res))
    assert back.matching == res.matching
    assert back.cycle_consistent == res.cycle_consistent == (method != "matcheig")
    assert back.objective == res.objective
    for key, a in res.pairwise_dict().items():
        np.testing.assert_array_equal(back.pairwise(*key), a)
    np.testing.assert_array_equal(back.to_matrix(), res.to_matrix())


def test_matcheig_pairwise_is_blockwise_rounding_on_a_disconnected_problem():
    a = make_permutation_collection(4, 5, rng=12)
    b = make_permutation_collection(3, 5, rng=13)
    pw = dict(a.pairwise)
    pw.update({(i + 4, j + 4): m for (i, j), m in b.pairwise.items()})
    res = pickle.loads(pickle.dumps(synchronize_permutations(pw, method="matcheig")))
    assert np.all(res.pairwise(0, 5) == -1)                 # different components
    np.testing.assert_array_equal(res.pairwise(4, 6), b.true_pairwise(0, 2))
    np.testing.assert_array_equal(res.pairwise(1, 3), a.true_pairwise(1, 3))


def test_matcheig_pairwise_of_an_object_with_itself_is_the_identity():
    """An object alone in its component (no embedding) gave all -1 for pairwise(g, g), while
    connected objects and every other method gave the identity."""
    res = synchronize_permutations({(0, 1): np.arange(3)}, sizes=[3, 3, 2], method="matcheig")
    for g, n in enumerate([3, 3, 2]):
        np.testing.assert_array_equal(res.pairwise(g, g), np.arange(n))
    np.testing.assert_array_equal(res.pairwise(2, 0), [-1, -1])       # still no partner
    T = res.to_matrix()
    np.testing.assert_array_equal(T[6:, 6:], np.eye(2))


@pytest.mark.parametrize("fully_corrective", [False, True])
def test_birkhoff_result_carries_a_matching_pickles_and_has_to_matrix(data, fully_corrective):
    X = _soft(data)
    with warnings.catch_warnings():      # about the result's type, not convergence
        warnings.simplefilter("ignore", ConvergenceWarning)
        res = synchronize_doubly_stochastic(X, fully_corrective=fully_corrective, rng=0)
    assert type(res) is BirkhoffSyncResult and isinstance(res.matching, MultiMatching)
    back = pickle.loads(pickle.dumps(res))
    assert back.matching == res.matching
    np.testing.assert_array_equal(back.weights, res.weights)
    T = res.to_matrix()
    off = np.concatenate([[0], np.cumsum(res.sizes)])
    assert T.shape == (off[-1], off[-1])
    for (i, j) in [(0, 1), (3, 2), (4, 4)]:
        np.testing.assert_allclose(T[off[i]:off[i + 1], off[j]:off[j + 1]], res.block(i, j),
                                   atol=1e-12)
    np.testing.assert_allclose(T.sum(1), data.n_objects, atol=1e-9)   # DS blocks, N per row
    assert res.atom(0).n_universe == res.n_universe


def test_linear_map_results_pickle():
    prob = make_noisy_linear_maps(5, 3, noise=0.01, rng=0)
    res = synchronize_linear_maps(prob.observed, mask=prob.mask, robust=True)
    assert type(res) is LinearMapSyncResult
    back = pickle.loads(pickle.dumps(res))
    np.testing.assert_array_equal(back.maps, res.maps)


# ---------------------------------------------------------------------- one meaning of `mask`

def test_mask_selects_pairs_the_same_way_for_every_input_form(data):
    """`mask` selects pair {i, j} when mask[i, j] or mask[j, i]; it only filters."""
    mask = np.ones((7, 7), bool)
    mask[0, 1] = False                                     # one direction is enough
    mask[2, 5] = mask[5, 2] = False                        # pair {2, 5} left out
    ref = synchronize_permutations({k: v for k, v in data.pairwise.items() if k != (2, 5)})
    arr = np.full((7, 7, 5), -1)
    for (i, j), a in data.pairwise.items():
        arr[i, j] = a
        arr[j, i] = np.argsort(a)                          # the inverse (full permutations)
    triples = [(i, j, a) for (i, j), a in data.pairwise.items()]
    for form in (data.pairwise, triples, arr):
        res = synchronize_permutations(form, mask=mask)
        assert res.matching == ref.matching
        assert res.objective == ref.objective


def test_mask_filters_dicts_of_linear_maps_like_arrays():
    """Issue 9: with a dict one filtered by the mask, the other raised."""
    prob = make_noisy_linear_maps(5, 3, noise=0.0, rng=1)
    mask = prob.mask.copy()
    mask[0, 3] = mask[3, 0] = False
    T = {(i, j): prob.observed[i, j] for i, j in zip(*np.nonzero(prob.mask)) if i < j}
    from_dict = synchronize_linear_maps(T, mask=mask)
    from_array = synchronize_linear_maps(prob.observed, mask=mask)
    assert not from_dict.mask[0, 3] and not from_array.mask[0, 3]
    np.testing.assert_array_equal(from_dict.mask, from_array.mask)
    np.testing.assert_allclose(from_dict.maps, from_array.maps, atol=1e-9)


@pytest.mark.parametrize("fn, pw", [
    (synchronize_permutations, {(0, 1): np.array([1, 0])}),
    (synchronize_doubly_stochastic, {(0, 1): np.eye(2)}),
    (synchronize_linear_maps, {(0, 1): np.eye(2)}),
])
def test_empty_mask_is_a_clear_error(fn, pw):
    with pytest.raises(ValueError, match="`mask` selects no"):
        fn(pw, mask=np.zeros((2, 2), bool))
    with pytest.raises(ValueError, match=r"`mask` must be boolean \(or 0/1\)"):
        fn(pw, mask=np.full((2, 2), 2))
    with pytest.raises(ValueError, match="`mask` has shape"):
        fn(pw, mask=np.ones((1, 1), bool))


# ------------------------------------------------------------------------------- bad inputs

@pytest.mark.parametrize("fn", [synchronize_permutations, synchronize_doubly_stochastic])
@pytest.mark.parametrize("arr", [np.zeros((3, 3), int), np.arange(3), np.array(5.0)])
def test_an_array_of_too_few_dimensions_is_named_as_an_array(fn, arr):
    """A (3, 3) int array was read as an iterable of triples: 'must hold (i, j, map) triples,
    got array([0, 0, 0])'."""
    with pytest.raises(ValueError, match=r"`pairwise` as an array must have shape \(N, N, "
                                         r"\.\.\.\), one map per pair of objects, got shape"):
        fn(arr)


@pytest.mark.parametrize("value, exc, match", [
    (np.array([np.nan, 0, 1]), TypeError,
     r"`pairwise\[\(0, 1\)\]` must hold integers \(node indices, -1 = unmatched\), got nan"),
    (np.array(["a", "b"]), TypeError, r"`pairwise\[\(0, 1\)\]` must hold integers"),
    ("ab", TypeError, r"`pairwise\[\(0, 1\)\]` must be an assignment or a dense matrix, got str"),
    (np.array([0.5, 1.0]), TypeError, r"`pairwise\[\(0, 1\)\]` must hold integers.*got 0.5"),
    (np.array([0, 1j]), TypeError, r"`pairwise\[\(0, 1\)\]` must hold integers"),
    (np.array([[1j, 0], [0, 1]]), TypeError, r"`pairwise\[\(0, 1\)\]` must be real"),
    (np.array([0, 0]), ValueError, r"`pairwise\[\(0, 1\)\]` must be injective"),
    (np.array([0, -2]), ValueError, r"`pairwise\[\(0, 1\)\]` entries must be >= -1, got -2"),
    (np.zeros((2, 2, 2)), ValueError, r"`pairwise\[\(0, 1\)\]` must be an assignment \(1-d\)"),
    (np.array([0, 2**63], dtype=np.uint64), ValueError, "must be node indices"),
])
def test_bad_assignment_values_name_the_pair(value, exc, match):
    with pytest.raises(exc, match=match):
        synchronize_permutations({(0, 1): value, (1, 2): np.array([1, 0])})


@pytest.mark.parametrize("value, match", [
    (np.array([0, 0, 1]), r"`pairwise\[\(1, 2\)\]` must be injective"),
    (np.array([0, -1, -1, 2]), None),                    # valid: several unmatched nodes
    (np.array([1, -2, 0]), r"`pairwise\[\(1, 2\)\]` entries must be >= -1, got -2"),
    (np.array([1, 2**62, 0]), r"`pairwise\[\(1, 2\)\]` entries must be node indices"),
])
def test_int_assignments_of_different_lengths_are_checked_together(value, match):
    """Int arrays of different lengths (the kernels' real-node maps) are validated at once:
    the same labels as the same maps given as lists (checked one by one), and an invalid map
    named by its pair."""
    rng = np.random.default_rng(0)
    sizes = np.array([3, 4, 5, 4])
    maps = {}
    for i in range(4):
        for j in range(i + 1, 4):
            a = rng.permutation(5)[: sizes[i]]
            maps[(i, j)] = np.where(a < sizes[j], a, -1)
    maps[(1, 2)] = value if len(value) == sizes[1] else value[: sizes[1]]
    if match is not None:
        with pytest.raises(ValueError, match=match):
            synchronize_permutations(maps, sizes=sizes)
        maps[(2, 3)] = np.array([0, 1, -5, 2])     # a later invalid map: the first is named
        with pytest.raises(ValueError, match=match):
            synchronize_permutations(maps, sizes=sizes)
        return
    fast = synchronize_permutations(maps, sizes=sizes, method="spectral", n_universe=5)
    slow = synchronize_permutations({k: v.tolist() for k, v in maps.items()}, sizes=sizes,
                                    method="spectral", n_universe=5)
    for a, b in zip(fast.labels, slow.labels):
        np.testing.assert_array_equal(a, b)


def test_bad_sizes_keys_and_targets():
    with pytest.raises(ValueError, match=r"`pairwise\[\(1, 2\)\]` targets node 5, beyond object "
                                         r"2's 2 nodes \(mismatched sizes\)"):
        synchronize_permutations({(0, 1): np.array([1, 0]), (1, 2): np.array([0, 5]),
                                  (2, 0): np.array([0, 1])})
    with pytest.raises(ValueError, match=r"`pairwise\[\(1, 2\)\]` targets node 5, beyond object "
                                         r"2's 2 nodes"):
        synchronize_permutations({(0, 1): np.array([1, 0]), (1, 2): np.array([0, 5])},
                                 sizes=np.array([2, 2, 2]))
    with pytest.raises(ValueError, match="mismatched sizes for object 0"):
        synchronize_permutations({(0, 1): np.array([1, 0]), (0, 2): np.array([0, 1, 2])})
    with pytest.raises(ValueError, match=r"cannot infer the size of object\(s\) \[1, 2"):
        synchronize_permutations({(0, 10**9): np.array([0, 1])})
    with pytest.raises(TypeError, match=r"`pairwise` keys must be pairs of ints"):
        synchronize_permutations({(0, 1.5): np.array([0, 1])})
    with pytest.raises(ValueError, match="non-negative object indices"):
        synchronize_permutations({(0, -1): np.array([0, 1])})
    with pytest.raises(TypeError, match="`pairwise` must be a dict"):
        synchronize_permutations(3)
    with pytest.raises(ValueError, match=r"`weights` must be finite and >= 0, got nan"):
        synchronize_permutations({(0, 1): np.array([1, 0])}, weights={(0, 1): np.nan})
    with pytest.raises(TypeError, match="`threshold` must be a finite real number, got str"):
        synchronize_permutations({(0, 1): np.array([1, 0])}, method="matcheig", threshold="0.5")
    with pytest.raises(ValueError, match=r"`weights` are 0 on all 2 observed pair\(s\)"):
        synchronize_permutations({(0, 1): np.array([1, 0]), (1, 2): np.array([0, 1])},
                                 weights={(0, 1): 0.0, (1, 2): 0})
    P = {(0, 1): np.array([1, 0]), (1, 2): np.array([0, 1])}
    W = {(0, 1): 1.0, (1, 2): 1.0}
    for key, exc, match in [((0, 42), ValueError, r"key \(0, 42\) names object 42, but the "
                                                   r"input has 3 objects"),
                            ((-1, 0), ValueError, "non-negative object indices"),
                            ((1, 1), ValueError, "self-pairs"),
                            ("ab", TypeError, "keys must be \\(i, j\\) pairs"),
                            ((0.5, 1), TypeError, "keys must be pairs of ints")]:
        with pytest.raises(exc, match=match):     # a typo in a key was ignored
            synchronize_permutations(P, weights={**W, key: 3.0})
    assert synchronize_permutations(P, weights={**W, (0, 2): 3.0}).n_universe == 2   # unobserved
    for bad in (-0.1, 1.5):       # above 1 no cosine passes: an empty matching, not an answer
        with pytest.raises(ValueError, match=r"`threshold` must lie in \[0, 1\]"):
            synchronize_permutations({(0, 1): np.array([1, 0])}, method="matcheig",
                                     threshold=bad)


def test_universe_is_bounded_by_the_number_of_nodes():
    """Issue 13 item 5: n_universe=10**9 raised MemoryError."""
    pw = {(0, 1): np.array([1, 0, 2])}
    with pytest.raises(ValueError, match=r"`n_universe` must be <= the total number of nodes 6 "
                                         r"\(every universe slot holds at least one node\), "
                                         r"got 1000000000"):
        synchronize_permutations(pw, n_universe=10**9)
    with pytest.raises(ValueError, match=r"`n_universe` must be <= the total number of nodes 6"):
        synchronize_doubly_stochastic({(0, 1): np.eye(3)}, n_universe=10**9)
    res = synchronize_permutations(pw, n_universe=6)       # the largest legal universe
    assert res.n_universe == 6
    # disconnected: a component never gets more slots than it has nodes
    res = synchronize_permutations(pw, n_universe=8, sizes=np.array([3, 3, 2]))
    assert res.n_universe == 8 and res.labels[2].tolist() == [6, 7]


@pytest.mark.parametrize("method", ["spectral", "orthogonal", "matcheig"])
def test_a_given_universe_is_the_results_or_an_error_on_a_disconnected_view_graph(method):
    # the components' universes were returned side by side, larger than the given size (4 slots
    # for n_universe=2, 6 for 3), and nothing said so
    for pw, kw, total in [({(0, 1): np.array([0, 1]), (2, 3): np.array([1, 0])}, {}, 4),
                          ({(0, 1): np.array([0, 1])}, {"sizes": [2, 2, 3]}, 5)]:
        d = total - 2
        with pytest.raises(ValueError, match=rf"`n_universe`={d} cannot hold the 2 groups of "
                                             r"objects that no observed pair links \(\{0, 1\}, "
                                             rf"\{{2.*own universe slots, {total} in all"):
            synchronize_permutations(pw, n_universe=d, method=method, **kw)
        res = synchronize_permutations(pw, n_universe=total, method=method, **kw)
        assert res.n_universe == total
        assert synchronize_permutations(pw, method=method, **kw).n_universe == total
        # room to spare: the components at their own sizes, the last slot empty
        res = synchronize_permutations(pw, n_universe=total + 1, method=method, **kw)
        assert res.n_universe == total + 1
        assert np.all(res.pairwise(0, 1) == pw[(0, 1)])
        used = np.concatenate([lab[lab >= 0] for lab in res.labels])
        assert np.unique(used).size == total and used.max() < total + 1


def test_degenerate_but_legal_permutation_inputs():
    one_node = synchronize_permutations({(0, 1): np.array([0]), (1, 2): np.array([0])})
    assert one_node.n_universe == 1 and one_node.pairwise(0, 2).tolist() == [0]
    single_pair = synchronize_permutations({(0, 1): np.array([2, 0, 1])})
    np.testing.assert_array_equal(single_pair.pairwise(0, 1), [2, 0, 1])
    # nothing observed as matched: with min_score no node is placed, so nothing is matched
    unmatched = synchronize_permutations({(0, 1): np.array([-1, -1])}, sizes=np.array([2, 2]),
                                         min_score=0.5)
    assert np.all(unmatched.pairwise(0, 1) == -1) and unmatched.info["n_unplaced"] == 4
    with pytest.raises(DegenerateInputError, match="disconnected"):
        synchronize_permutations({(0, 1): np.array([1, 0]), (2, 3): np.array([1, 0])},
                                 disconnected="raise")


def test_birkhoff_von_neumann_max_terms():
    """Issue 13 item 16: max_terms=0 returned weights summing to 0."""
    X = np.full((3, 3), 1 / 3)
    with pytest.raises(ValueError, match="`max_terms` must be >= 1, got 0"):
        birkhoff_von_neumann(X, max_terms=0)
    with pytest.raises(ValueError, match=r"`max_terms`=1 is too small for `X`"):
        birkhoff_von_neumann(X, max_terms=1)
    w, P = birkhoff_von_neumann(X, max_terms=3)
    np.testing.assert_allclose(w.sum(), 1.0)
    recon = sum(a * assignment_to_matrix(p, 3) for a, p in zip(w, P))
    np.testing.assert_allclose(recon, X, atol=1e-12)


def test_doubly_stochastic_max_iter_zero_is_the_initial_vertex(data):
    """Issue 13 item 16: max_iter=0 returns the initialization (documented), n_iter=0."""
    X = _soft(data)
    res = synchronize_doubly_stochastic(X, max_iter=0)
    assert res.n_iter == 0 and len(res.weights) == 1 and res.weights[0] == 1.0
    assert data.accuracy(res.matching) == 1.0              # the consistent vertex of the input
    with pytest.raises(ValueError, match="`max_iter` must be >= 0, got -1"):
        synchronize_doubly_stochastic(X, max_iter=-1)


def test_linear_maps_degenerate_inputs():
    """Issue 13 item 4."""
    with pytest.raises(ValueError, match=r"`H\[0, 1\]` must be invertible, got a singular matrix "
                                         r"\(condition number inf\)"):
        synchronize_homographies(np.zeros((3, 3, 3, 3)))       # named as the caller's argument
    with pytest.raises(ValueError, match=r"`T` must hold at least one object, got shape "
                                         r"\(0, 0, 3, 3\)"):
        synchronize_linear_maps(np.zeros((0, 0, 3, 3)))
    with pytest.raises(ValueError, match="`T` must hold at least one observed pair i != j"):
        synchronize_linear_maps(np.zeros((1, 1, 3, 3)))
    with pytest.raises(ValueError, match=r"null-space method factorizes an \(N d\) x \(N d\)"):
        synchronize_linear_maps({(0, 10**9): np.eye(3)})
    with pytest.raises(ValueError, match=r"null-space method factorizes"):
        synchronize_homographies({(0, 10**9): np.eye(3)}, image_size=(10, 10))
    with pytest.raises(TypeError, match="`T` must be real, got complex"):
        synchronize_linear_maps(np.ones((2, 2, 3, 3)) * 1j)
    with pytest.raises(TypeError, match=r"`T\[\(0, 1\)\]` must be real"):
        synchronize_linear_maps({(0, 1): np.eye(3) * 1j})
    res = synchronize_linear_maps({(0, 1): 2 * np.eye(2)})   # a single pair
    np.testing.assert_allclose(res.pairwise(0, 1), 2 * np.eye(2), atol=1e-12)


def test_complex_and_bad_image_sizes_are_refused():
    H = np.broadcast_to(np.eye(3), (3, 3, 3, 3)).copy()
    with pytest.raises(TypeError, match="`image_size` must be real"):
        synchronize_homographies(H, image_size=(640 + 1j, 480))
    with pytest.raises(ValueError, match="`image_size` must be finite"):
        synchronize_homographies(H, image_size=(np.nan, 480))
    with pytest.raises(TypeError, match="`weights` must be real"):
        synchronize_permutations({(0, 1): np.array([1, 0])}, weights=np.ones((2, 2)) * 1j)
    with pytest.raises(TypeError, match="`mask` must be real"):
        synchronize_permutations({(0, 1): np.array([1, 0])}, mask=np.ones((2, 2)) * 1j)


def test_sizes_are_validated_and_bounded():
    pw = {(0, 1): np.array([1, 0])}
    with pytest.raises(ValueError, match="`sizes` must be <= 100000000 nodes per object"):
        synchronize_permutations(pw, sizes=np.array([2, 2, 10**12]))
    with pytest.raises(TypeError, match="`sizes` must hold integers"):
        synchronize_permutations(pw, sizes=np.array([2.0, 2.5]))
    assert synchronize_permutations(pw, sizes=np.array([2.0, 2.0])).n_objects == 2
    with pytest.raises(ValueError, match="`sizes` must be a 1-d array of positive ints"):
        synchronize_permutations(pw, sizes=np.array([2, 0]))
    with pytest.raises(ValueError, match=r"`sizes` must have an entry for every object \(>= 2\)"):
        synchronize_permutations(pw, sizes=np.array([2]))


@pytest.mark.parametrize("method", ["spectral", "orthogonal", "matcheig"])
def test_pairs_that_match_nothing_are_legal(method):
    """An all-zero 0/1 block (nothing matched) made the orthogonal refinement fail with a
    numpy casting error; it is a legal partial permutation."""
    res = synchronize_permutations({(0, 1): np.zeros((1, 3))}, method=method)
    assert res.sizes.tolist() == [1, 3]
    assert res.pairwise(0, 1).shape == (1,)
    back = pickle.loads(pickle.dumps(res))
    np.testing.assert_array_equal(back.pairwise(1, 0), res.pairwise(1, 0))


def test_linear_maps_scale_is_checked_and_sl_is_scale_free():
    prob = make_noisy_linear_maps(4, 3, noise=0.0, rng=2)
    T = prob.observed * 1e150                              # GL: overflow ahead, refused
    with pytest.raises(ValueError, match=r"`T\[0, 1\]` must have singular values within "
                                         r"\[1e-100, 1e\+100\]"):
        synchronize_linear_maps(T)
    H = np.broadcast_to(np.eye(3), (3, 3, 3, 3)) * 1e300    # SL: any scale is the same map
    res = synchronize_homographies(H)
    np.testing.assert_allclose(res.maps, np.broadcast_to(np.eye(3), (3, 3, 3)), atol=1e-12)
    with pytest.raises(ValueError, match="`H` must contain at least one pair, got an empty dict"):
        synchronize_homographies({}, image_size=(640, 480))
    with pytest.raises(ValueError, match="`H` must hold at least one view"):
        synchronize_homographies(np.zeros((0, 0, 3, 3)), image_size=(640, 480))


def test_birkhoff_von_neumann_tol_only_absorbs_round_off():
    X = np.full((4, 4), 0.25)
    with pytest.raises(ValueError, match=r"`tol` must be <= 1e-6 .* got 0.5"):
        birkhoff_von_neumann(X, tol=0.5)       # would have returned no term at all
    w, P = birkhoff_von_neumann(X, tol=1e-6)
    np.testing.assert_allclose(w.sum(), 1.0)


@pytest.mark.parametrize("fn", ["permutations", "soft", "universe", "linear", "homographies"])
def test_weights_that_would_overflow_the_objective_are_refused(data, fn):
    # weights of 1e308 overflowed the objective with a RuntimeWarning; only their ratios matter
    from transync.synchronization import estimate_universe

    N = data.n_objects
    W = np.full((N, N), 1e308)
    maps = make_noisy_linear_maps(4, dim=3, noise=0.0, rng=0)
    calls = {
        "permutations": lambda: synchronize_permutations(data.pairwise, weights=W),
        "soft": lambda: synchronize_doubly_stochastic(_soft(data), weights=W),
        "universe": lambda: estimate_universe(_soft(data), weights=W),
        "linear": lambda: synchronize_linear_maps(maps.observed, mask=maps.mask,
                                                  weights=np.full((4, 4), 1e308)),
        "homographies": lambda: synchronize_homographies(maps.observed, mask=maps.mask,
                                                         weights=np.full((4, 4), 1e308)),
    }
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"`weights` are too large.*rescale them"):
            calls[fn]()


def test_sixth_fuzz_synchronization_contract():
    """What a fuzz of transync.synchronization found (each line failed before): sizes whose
    dense working set cannot exist (MemoryError after allocating, or minutes of it), unchecked
    flags, raw OverflowError / numpy messages for keys and values."""
    from transync.synchronization import estimate_universe

    one = {(0, 1): np.array([1, 0])}
    # 10**5 objects of 2 nodes: a 149 GiB slot table before; now a result
    res = synchronize_permutations(one, sizes=[2] * 10**5)
    assert res.matching.n_objects == 10**5
    with pytest.raises(ValueError, match=r"the embedding \(total nodes x largest object\) would "
                                         r"be a dense array of 1e\+14 entries"):
        synchronize_permutations(one, sizes=[2, 10**7])                   # 728 TiB
    with pytest.raises(ValueError, match="a dense array of 1e\\+16 entries"):
        synchronize_permutations({(0, 1): np.arange(4), (1, 2): np.arange(4)},
                                 sizes=[4] * 4 + [10**8])                 # minutes
    with pytest.raises(ValueError, match="needs a dense 200000 x 200000 eigenproblem"):
        estimate_universe({(0, 1): np.eye(2)}, sizes=[2] * 10**5)         # 298 GiB
    with pytest.raises(TypeError, match="`fully_corrective` must be a bool, got str 'no'"):
        synchronize_doubly_stochastic({(0, 1): np.eye(2)}, fully_corrective="no")
    with pytest.raises(ValueError, match="`max_iter` must be <= 1000000"):
        synchronize_doubly_stochastic({(0, 1): np.eye(2)}, max_iter=10**12)
    with pytest.raises(ValueError, match="`max_iter` must be <= 1000000"):
        synchronize_linear_maps({(0, 1): np.eye(2)}, max_iter=10**12)
    for sync in (synchronize_permutations, synchronize_doubly_stochastic):
        for big in (2**70, 2**62):      # raw OverflowError; "cannot infer the size of ..."
            with pytest.raises(ValueError, match=r"keys must be object indices below 2\*\*62"):
                sync({(0, big): np.array([1, 0])})
        with pytest.raises(ValueError, match=r"`pairwise\[\(0, 1\)\]` must be an assignment "
                                             r"\(1-d\) or a matrix \(2-d\) of one row length"):
            sync({(0, 1): [[1], [0, 1]]})                              # numpy's words
        for bad in (None, sp.eye(2)):
            with pytest.raises(TypeError, match=r"`pairwise\[\(0, 1\)\]` must be an assignment "
                                                "or a dense matrix, got"):
                sync({(0, 1): bad})                                    # "got shape ()"

