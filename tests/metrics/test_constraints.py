import itertools

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from transync.datasets import make_subgraph_collection
from transync.metrics import (
    ConstraintStats,
    ConstraintViolations,
    constraint_violations,
)
from transync.permutations import MultiMatching


# ------------------------------------------------------------------ brute force reference
def _stats(values, tol=1e-9):
    g = np.asarray(values, dtype=float)
    ex = g - 1
    bad = ex > tol
    return int(g.size), int(bad.sum()), float(ex[bad].sum()), float(np.abs(g).sum())


def brute_force(blocks, sizes):
    """``blocks[(i, j)]`` dense (n_i, n_j) for i < j (missing = unobserved): plain loops."""
    def get(a, b):
        if (a, b) in blocks:
            return blocks[(a, b)]
        if (b, a) in blocks:
            return blocks[(b, a)].T
        return None
    cap = []
    for (i, j), M in blocks.items():
        cap += list(M.sum(1)) + list(M.sum(0))
    trans = []
    N = len(sizes)
    for i, j, k in itertools.permutations(range(N), 3):
        if i > k:
            continue
        A, B, C = get(i, j), get(j, k), get(i, k)
        if A is None or B is None or C is None:
            continue
        for u in range(sizes[i]):
            for v in range(sizes[j]):
                for w in range(sizes[k]):
                    trans.append(A[u, v] + B[v, w] - C[u, w])
    return _stats(cap), _stats(trans)


def _check_against(result, ref):
    (c_n, c_bad, c_v, c_m), (t_n, t_bad, t_v, t_m) = ref
    cap, tr = result.capacity, result.transitivity
    assert (cap.n_constraints, cap.n_violated) == (c_n, c_bad)
    np.testing.assert_allclose([cap.violation, cap.magnitude], [c_v, c_m], rtol=1e-12, atol=1e-9)
    assert (tr.n_constraints, tr.n_evaluated, tr.n_violated) == (t_n, t_n, t_bad)
    np.testing.assert_allclose([tr.violation, tr.magnitude], [t_v, t_m], rtol=1e-12, atol=1e-9)


def _random_assignment(rng, n1, n2, p_match=0.8):
    perm = rng.permutation(n2)[:n1] if n2 >= n1 else np.concatenate(
        [rng.permutation(n2), np.full(n1 - n2, -1)])
    a = np.where(rng.random(n1) < p_match, perm, -1)
    return rng.permutation(a)


def _to_matrix(a, n2):
    M = np.zeros((a.size, n2))
    u = np.flatnonzero(a >= 0)
    M[u, a[u]] = 1
    return M


SIZES = [3, 1, 4, 2, 3]


@pytest.mark.parametrize("seed", range(3))
def test_partial_permutations_match_brute_force(seed):
    rng = np.random.default_rng(seed)
    X, blocks = {}, {}
    for i, j in itertools.combinations(range(5), 2):
        if (i, j) == (1, 3):
            continue                                  # one unobserved pair
        a = _random_assignment(rng, SIZES[i], SIZES[j])
        blocks[(i, j)] = _to_matrix(a, SIZES[j])
        if (i + j) % 2:                               # some given in the other direction
            X[(j, i)] = np.array([np.flatnonzero(r)[0] if r.any() else -1
                                  for r in blocks[(i, j)].T])
        else:
            X[(i, j)] = a
    r = constraint_violations(X, sizes=SIZES)
    assert r.info["transitivity_mode"] == "exact" and r.info["input"] == "pairwise"
    _check_against(r, brute_force(blocks, SIZES))
    # the same blocks as 0/1 matrices give the same numbers
    r2 = constraint_violations({k: blocks[k] for k in blocks})
    _check_against(r2, brute_force(blocks, SIZES))


@pytest.mark.parametrize("kind", ["soft", "binary"])
def test_dense_blocks_match_brute_force(kind, rng):
    blocks = {}
    for i, j in itertools.combinations(range(5), 2):
        M = rng.random((SIZES[i], SIZES[j]))
        blocks[(i, j)] = (M / M.sum(1, keepdims=True)) if kind == "soft" else (M > 0.6) * 1.0
    if kind == "binary":
        blocks[(0, 2)] = np.ones((3, 4))                      # certainly not injective
    r = constraint_violations(blocks)
    assert r.info["transitivity_mode"] == "exhaustive"
    ref = brute_force(blocks, SIZES)
    _check_against(r, ref)
    assert ref[1][1] > 0 and r.transitivity.cvr == ref[1][1] / ref[1][0]


def test_absolute_soft_maps_match_brute_force(rng):
    d = 4
    maps = [rng.dirichlet(np.ones(d), size=n) for n in SIZES]
    blocks = {(i, j): maps[i] @ maps[j].T for i, j in itertools.combinations(range(5), 2)}
    r = constraint_violations(maps)
    assert r.info["input"] == "absolute"
    _, trans = brute_force(blocks, SIZES)
    cols = np.concatenate([m.sum(0) for m in maps])
    _check_against(r, (_stats(cols), trans))
    assert r.capacity.n_constraints == 5 * d


def test_consistent_multimatching_has_no_violation():
    c = make_subgraph_collection(n_graphs=6, n_universe=9, p_keep=(0.5, 1.0), n_outliers=1,
                                 rng=0)
    gt = c.ground_truth
    onehot = [np.eye(gt.n_universe)[lab] * (lab >= 0)[:, None] for lab in gt.labels]
    for X in (gt, gt.pairwise_dict(), onehot, {k: _to_matrix(a, c.sizes[k[1]])
                                                for k, a in gt.pairwise_dict().items()}):
        kw = dict(sizes=c.sizes) if isinstance(X, dict) else {}
        r = constraint_violations(X, **kw)
        assert r.capacity.cvr == 0.0 and r.transitivity.cvr == 0.0
        assert r.capacity.cvvr == r.capacity.acvv == r.transitivity.cvvr == 0.0
        assert r.transitivity.n_constraints > 0 and r.transitivity.magnitude > 0
    assert r.info["transitivity_mode"] == "exact"


def _noisy_soft(c, noise, rng):
    """Truth blocks plus uniform noise, row-normalized (pairs i < j)."""
    gt = c.ground_truth
    out = {}
    for (i, j), a in gt.pairwise_dict().items():
        M = _to_matrix(a, c.sizes[j]) + noise * rng.random((c.sizes[i], c.sizes[j]))
        out[(i, j)] = M
    return out


def test_independent_pairwise_rounding_violates_transitivity_only(rng):
    c = make_subgraph_collection(n_graphs=6, n_universe=10, p_keep=1.0, rng=1)
    soft = _noisy_soft(c, 1.5, rng)
    rounded = {}
    for key, M in soft.items():
        r_, c_ = linear_sum_assignment(M, maximize=True)
        a = np.full(M.shape[0], -1)
        a[r_] = c_
        rounded[key] = a
    r = constraint_violations(rounded, sizes=c.sizes)
    assert r.capacity.cvr == 0.0
    assert r.transitivity.cvr > 0 and r.transitivity.acvv == 1.0
    assert r.transitivity.cvvr > 0


def test_row_argmax_rounding_violates_capacity_only(rng):
    c = make_subgraph_collection(n_graphs=5, n_universe=10, p_keep=1.0, rng=2)
    d = c.n_universe
    maps = []
    for lab in c.labels:
        soft = np.eye(d)[lab] + 1.5 * rng.random((lab.size, d))
        maps.append(np.eye(d)[np.argmax(soft, 1)])
    r = constraint_violations(maps)
    assert r.capacity.cvr > 0 and r.capacity.acvv >= 1.0
    assert r.transitivity.cvr == 0.0          # node -> slot functions are always transitive


def test_sampled_estimate_is_close_to_exhaustive():
    rng = np.random.default_rng(5)
    c = make_subgraph_collection(n_graphs=8, n_universe=12, p_keep=(0.6, 1.0), rng=3)
    soft = _noisy_soft(c, 0.6, rng)
    full = constraint_violations(soft, sizes=c.sizes)
    assert full.info["transitivity_mode"] == "exhaustive"
    samp = constraint_violations(soft, sizes=c.sizes, max_triples=40_000, rng=0)
    assert samp.info["transitivity_mode"] == "sampled" and samp.transitivity.sampled
    assert samp.transitivity.n_constraints == full.transitivity.n_constraints
    assert samp.transitivity.n_evaluated == 40_000
    p = full.transitivity.cvr
    assert 0.01 < p < 0.5
    assert abs(samp.transitivity.cvr - p) < 4 * np.sqrt(p * (1 - p) / 40_000)
    np.testing.assert_allclose(samp.transitivity.cvvr, full.transitivity.cvvr, rtol=0.1)
    np.testing.assert_allclose(samp.transitivity.acvv, full.transitivity.acvv, rtol=0.1)
    again = constraint_violations(soft, sizes=c.sizes, max_triples=40_000, rng=0)
    assert again == samp
    # capacity is never sampled
    assert samp.capacity == full.capacity


def test_sampled_estimate_on_an_incomplete_view_graph_is_close_to_exhaustive():
    # the triples of an incomplete view graph are listed in chunks and drawn in two passes
    rng = np.random.default_rng(6)
    c = make_subgraph_collection(n_graphs=12, n_universe=12, p_keep=(0.6, 1.0), rng=4)
    soft = {k: v for k, v in _noisy_soft(c, 0.6, rng).items() if (k[0] + k[1]) % 4}
    full = constraint_violations(soft, sizes=c.sizes)
    samp = constraint_violations(soft, sizes=c.sizes, max_triples=20_000, rng=1)
    assert full.info["transitivity_mode"] == "exhaustive"
    assert samp.info["transitivity_mode"] == "sampled"
    assert samp.info["n_object_triples"] == full.info["n_object_triples"] > 0
    assert samp.transitivity.n_constraints == full.transitivity.n_constraints
    p = full.transitivity.cvr
    assert 0.01 < p < 0.5
    assert abs(samp.transitivity.cvr - p) < 4 * np.sqrt(p * (1 - p) / 20_000)


@pytest.mark.parametrize("seed", range(4))
def test_absolute_partial_permutations_in_closed_form_equal_the_listed_triples(seed):
    # a MultiMatching (or 0/1 maps) is counted from its slot counts, not its O(N^3) triples:
    # every statistic equals the exact evaluation of its pairwise maps, triple by triple
    rng = np.random.default_rng(seed)
    N, d = int(rng.integers(3, 9)), int(rng.integers(1, 7))
    labels = []
    for _ in range(N):
        n = int(rng.integers(0, d + 2))
        lab = np.full(n, -1)
        k = min(n, d)
        lab[rng.permutation(n)[:k]] = np.where(rng.random(k) < 0.7, rng.permutation(d)[:k], -1)
        labels.append(lab)
    m = MultiMatching(labels, n_universe=d)
    ref = constraint_violations(m.pairwise_dict(), sizes=m.sizes)
    for X in (m, [_to_matrix(lab, d) for lab in labels]):
        r = constraint_violations(X)
        assert r.transitivity == ref.transitivity
        n_tri = N * (N - 1) * (N - 2) // 2
        assert r.info["n_object_triples"] == ref.info["n_object_triples"] == n_tri
        assert r.info["n_pairs"] == N * (N - 1) // 2


def test_many_objects_are_not_listed_triple_by_triple():
    # N = 2000 objects: 4e9 object triples, which were listed in one array (6 GB at N = 800)
    N = 2000
    r = constraint_violations(MultiMatching([np.array([0])] * N))
    n_tri = N * (N - 1) * (N - 2) // 2
    assert r.info["n_object_triples"] == n_tri and r.transitivity.n_constraints == n_tri
    # g = 1 + 1 - 1 on every constraint: none violated, |g| = 1
    assert r.transitivity.cvr == 0.0 and r.transitivity.magnitude == float(n_tri)
    # soft absolute maps above max_triples: only the sample is drawn, not every triple listed
    s = constraint_violations([np.full((1, 1), 0.5)] * 500, max_triples=1000, rng=0)
    assert s.info["transitivity_mode"] == "sampled" and s.transitivity.n_evaluated == 1000
    assert s.info["n_object_triples"] == 500 * 499 * 498 // 2
    # g = 0.25 + 0.25 - 0.25 on every constraint: none violated, |g| = 0.25
    assert s.transitivity.n_violated == 0 and s.transitivity.magnitude == 250.0


def test_runs_at_n32_n40(rng):
    """Issue #11: N = 32, n = 40 in seconds (soft input is sampled, discrete input is exact)."""
    c = make_subgraph_collection(n_graphs=32, n_universe=40, p_keep=1.0, rng=0)
    soft = _noisy_soft(c, 0.3, rng)
    r = constraint_violations(soft, max_triples=200_000, rng=0)
    assert r.info["transitivity_mode"] == "sampled" and r.info["n_object_triples"] == 14880
    assert r.transitivity.n_constraints == 14880 * 40 ** 3
    exact = constraint_violations(c.ground_truth.pairwise_dict(), sizes=c.sizes)
    assert exact.info["transitivity_mode"] == "exact" and exact.transitivity.cvr == 0.0
    assert exact.transitivity.n_evaluated == 14880 * 40 ** 3


def test_result_objects():
    m = MultiMatching([np.array([0, 1]), np.array([1, 0]), np.array([0])])
    r = constraint_violations(m)
    assert isinstance(r, ConstraintViolations) and isinstance(r.capacity, ConstraintStats)
    row = r.as_dict()
    assert row["capacity_cvr"] == 0.0 and row["transitivity_constraints"] == 3 * 4
    with pytest.raises(AttributeError):
        r.capacity.n_violated = 3                    # frozen


def test_one_node_graphs_and_single_pair():
    r = constraint_violations({(0, 1): np.array([0])}, sizes=[1, 1])
    assert r.capacity.n_constraints == 2 and r.transitivity.n_constraints == 0
    assert r.transitivity.cvr == 0.0


@pytest.mark.parametrize("X, kw, exc, match", [
    ({(0, 0): np.array([0])}, {}, ValueError, "keys"),
    ({(0, -1): np.array([0])}, {}, ValueError, "keys"),
    ({"ab": np.array([0])}, {}, ValueError, "keys"),
    ({(0, 1): np.array([0, 0])}, {}, ValueError, "injective"),
    ({(0, 1): np.zeros((2, 3)), (1, 2): np.zeros((2, 2))}, {}, ValueError, "object 1"),
    ({(0, 1): np.array([0, 1])}, dict(sizes=[3, 2]), ValueError, "implies 2 nodes"),
    ({(0, 1): np.array([0, 3])}, dict(sizes=[2, 2]), ValueError, "n2"),
    ({(0, 1): np.array([0, 1]), (2, 0): np.array([0, 1])}, dict(sizes=[2, 2]), ValueError,
     "sizes"),
    ({(0, 1): np.full((2, 2), np.nan)}, {}, ValueError, "finite"),
    ([np.ones((2, 3)), np.ones((2, 4))], {}, ValueError, "columns"),
    ([np.ones((2, 3))], dict(sizes=[2]), TypeError, "sizes"),
    ([], {}, ValueError, "at least one"),
    (3.0, {}, TypeError, "`X`"),
    ({(0, 1): np.array([0])}, dict(max_triples=0), ValueError, "max_triples"),
    ({(0, 1): np.array([0])}, dict(tol=-1.0), ValueError, "tol"),
])
def test_bad_input(X, kw, exc, match):
    with pytest.raises(exc, match=match):
        constraint_violations(X, **kw)


def test_object_indices_far_apart_cost_nothing():
    """One key (0, 3000) built an O(N^3) loop over 3001 objects (minutes); only objects in a
    key take part now. Indices beyond 1e7 are refused by name (was numpy's "maximum allowed
    dimension exceeded")."""
    import time

    t0 = time.perf_counter()
    res = constraint_violations({(0, 3000): np.array([0])})
    assert time.perf_counter() - t0 < 5
    assert res.info["n_object_triples"] == 0
    with pytest.raises(ValueError, match=r"`X` keys name object 10+: object indices must stay"):
        constraint_violations({(0, 10**30): np.array([0])})
    # the same triples, numbered densely or sparsely
    a, b = np.array([1, 0]), np.array([0, 1])
    dense = constraint_violations({(0, 1): a, (1, 2): a, (0, 2): b})
    sparse = constraint_violations({(5, 70): a, (70, 900): a, (5, 900): b})
    assert dense.transitivity == sparse.transitivity
    assert dense.info["n_object_triples"] == sparse.info["n_object_triples"] == 3


def test_soft_values_and_sizes_beyond_float_are_refused():
    """1e308 soft entries gave cvvr = NaN and acvv = inf with overflow warnings; sizes = 1e300
    a wrapped int64 in the message; tol = 2**1100 a raw OverflowError."""
    with pytest.raises(ValueError, match=r"`X\[\(0, 1\)\]` has values up to 1e\+308"):
        constraint_violations({(0, 1): [[1e308, 1e308]]})
    with pytest.raises(ValueError, match=r"`X\[0\]` has values up to 1e\+300"):
        constraint_violations([np.full((2, 2), 1e300)] * 2)
    a = np.array
    with pytest.raises(ValueError, match=r"`sizes` must hold integers in \[0, 1e\+08\]"):
        constraint_violations({(0, 1): a([0, 1]), (1, 2): a([0, 1]), (0, 2): a([1, 0])},
                              sizes=[1e300, 2, 2])
    with pytest.raises(ValueError, match=r"`tol` must be finite, got an integer of about 10\^331"):
        constraint_violations({(0, 1): a([0, 1])}, tol=2**1100)


def test_maps_into_an_empty_universe_and_no_triples():
    # (n, 0) maps took the closed form's argmax of an empty row (a raw numpy error)
    r = constraint_violations([np.zeros((2, 0)), np.zeros((1, 0)), np.zeros((2, 0))])
    assert r.info["transitivity_mode"] == "exact" and r.info["n_object_triples"] == 3
    assert r.transitivity.n_constraints == 3 * 2 * 1 * 2 and r.transitivity.cvr == 0.0
    assert r.transitivity.magnitude == 0.0
    # two objects: no triple; the sums are floats, as with triples
    t = constraint_violations({(0, 1): np.array([[0.5, 0.5]])}).transitivity
    assert t.n_constraints == 0 and type(t.violation) is float and type(t.magnitude) is float
