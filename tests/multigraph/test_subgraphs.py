"""match_collection on graphs of different sizes through a universe (thesis ch. 7)."""

import functools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from transync import match_collection
from transync.datasets import make_subgraph_collection
from transync.graphs import Graph
from transync.matching import Affinity, DenseAffinity, SeparableAffinity, gaussian_edge_affinity
from transync.metrics import constraint_violations, multimatching_precision_recall
from transync.multigraph import PairAffinities
from transync.permutations import cycle_inconsistency_arrays

QUIET = pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
AFF = functools.partial(gaussian_edge_affinity, sigma2=0.005)   # sharp: a unique optimum


def _problem(seed=0, n_graphs=6, d=12, p_keep=(0.6, 1.0), **kw):
    return make_subgraph_collection(n_graphs=n_graphs, n_universe=d, p_keep=p_keep, rng=seed,
                                    **kw)


def _check_valid(res, sizes):
    """The output contract: maps in range, injective, -1 padding beyond n_i, consistent."""
    sizes = np.asarray(sizes)
    A = res.assignments
    assert A.shape == (len(res.pairs), sizes.max())
    for p, (i, j) in enumerate(res.pairs.tolist()):
        row = A[p]
        assert np.all(row[sizes[i]:] == -1)
        real = row[:sizes[i]]
        hit = real[real >= 0]
        assert np.all(hit < sizes[j])
        assert len(np.unique(hit)) == len(hit)
        assert res.pairwise(i, j).shape == (sizes[i],)
        assert res.pairwise(j, i).shape == (sizes[j],)
    soft = res.info.get("soft")
    if soft is not None:                    # real blocks only: nothing beyond n_i x n_j
        assert soft.shape == (len(res.pairs), sizes.max(), sizes.max())
        for p, (i, j) in enumerate(res.pairs.tolist()):
            assert np.all(soft[p, sizes[i]:] == 0) and np.all(soft[p, :, sizes[j]:] == 0)
            assert np.all(soft[p].sum(1) <= 1 + 1e-6) and np.all(soft[p].sum(0) <= 1 + 1e-6)
    if res.matching is not None:
        assert res.consistency == 1.0
        assert np.array_equal(res.matching.sizes, sizes)
        rep = cycle_inconsistency_arrays(res.pairs, A, sizes)
        assert rep["cycle_error"] == 0.0


# --------------------------------------------------------------------------- planted solutions

@pytest.mark.parametrize("kw", [
    {},                                                      # S-RRWM, universe estimated
    {"mode": "offline"},                                     # RRWM + Birkhoff
    {"mode": "offline", "sync": "spectral"},
    {"mode": "offline", "sync": "orthogonal"},
    {"sync": "spectral"},
    {"sync": "orthogonal"},
    {"solver": "ga", "n_universe": 12},
    {"solver": "pf", "n_universe": 12},
])
@QUIET       # an offline pair may stop at its budget (warned); the result is what is tested
def test_planted_universe_recovered_exactly_at_zero_noise(kw):
    c = _problem()
    assert len(set(c.sizes.tolist())) > 1
    res = match_collection(c.graphs, affinity=AFF, progress=False, rng=0, **kw)
    _check_valid(res, c.sizes)
    assert res.n_universe == 12
    m = multimatching_precision_recall(res, c.ground_truth)
    assert m["f1"] == 1.0
    assert res.accuracy(c.ground_truth) == 1.0


def test_default_estimates_the_universe_and_reports_the_rule():
    c = _problem(seed=3)
    res = match_collection(c.graphs, affinity=AFF, progress=False, rng=0)
    assert res.n_universe == 12
    assert "eigengap" in res.info["n_universe_rule"]
    assert "soft solutions" in res.info["n_universe_rule"]        # the solver's soft matrices
    offline = match_collection(c.graphs, affinity=AFF, progress=False, rng=0, mode="offline",
                               sync="spectral")
    assert offline.n_universe == 12 and "soft" in offline.info["n_universe_rule"]
    given_ = match_collection(c.graphs, affinity=AFF, progress=False, rng=0, n_universe=12)
    assert given_.info["n_universe_rule"].startswith("given")


@pytest.mark.parametrize("sync", ["birkhoff", "spectral", "orthogonal"])
@pytest.mark.parametrize("mode", ["online", "offline"])
def test_every_synchronization_honours_a_given_universe(sync, mode):
    c = _problem(seed=1)
    res = match_collection(c.graphs, affinity=AFF, progress=False, rng=0, sync=sync, mode=mode,
                           n_universe=15)
    _check_valid(res, c.sizes)
    assert res.n_universe == 15
    assert res.matching.n_universe == 15


@QUIET
@pytest.mark.parametrize("kw", [{}, {"mode": "offline"}, {"mode": "offline", "sync": "spectral"},
                                {"mode": "offline", "sync": "orthogonal"}, {"sync": "orthogonal"}])
def test_a_universe_larger_than_needed_leaves_slots_empty(kw):
    """Exact problems, d = 20 for a true universe of 12: nothing is split or lost."""
    c = _problem()
    res = match_collection(c.graphs, affinity=AFF, progress=False, rng=0, n_universe=20, **kw)
    assert res.n_universe == 20
    assert multimatching_precision_recall(res, c.ground_truth)["f1"] == 1.0


@QUIET
def test_synchronized_output_violates_no_constraint():
    c = _problem(seed=2, deformation=0.1, n_outliers=1)
    res = match_collection(c.graphs, affinity=AFF, progress=False, rng=0)
    _check_valid(res, c.sizes)
    cv = constraint_violations(res.pairwise_dict(), sizes=c.sizes)
    assert cv.capacity.cvr == 0.0 and cv.transitivity.cvr == 0.0
    # the unsynchronized pairwise maps of the same problem do violate transitivity
    raw = match_collection(c.graphs, affinity=AFF, progress=False, sync=None)
    _check_valid(raw, c.sizes)
    assert raw.matching is None and raw.n_universe is None
    assert constraint_violations(raw.pairwise_dict(), sizes=c.sizes).transitivity.cvr > 0.0


def test_relabelling_a_graph_relabels_the_output():
    c = _problem(seed=4)
    rng = np.random.default_rng(0)
    g = 2
    perm = rng.permutation(c.sizes[g])            # new node k is old node perm[k]
    graphs = list(c.graphs)
    graphs[g] = c.graphs[g].permute(perm)
    a = match_collection(c.graphs, affinity=AFF, progress=False, rng=0, n_universe=12)
    b = match_collection(graphs, affinity=AFF, progress=False, rng=0, n_universe=12)
    inv = np.argsort(perm)
    for j in range(len(graphs)):
        if j == g:
            continue
        assert np.array_equal(b.pairwise(g, j), a.pairwise(g, j)[perm])
        old = a.pairwise(j, g)
        assert np.array_equal(b.pairwise(j, g), np.where(old >= 0, inv[np.maximum(old, 0)], -1))


def test_one_node_graph_is_matched():
    c = _problem(seed=5, n_graphs=4, d=6)
    rng = np.random.default_rng(1)
    lone = Graph(adjacency=np.zeros((1, 1)), points=rng.random((1, 2)))
    graphs = [*c.graphs, lone]
    res = match_collection(graphs, affinity=AFF, progress=False, rng=0)
    sizes = [*c.sizes.tolist(), 1]
    _check_valid(res, sizes)
    assert res.pairwise(4, 0).shape == (1,)


# --------------------------------------------------------------------------- dummy-node baseline

def test_dummy_baseline_drops_dummies_and_stays_consistent():
    c = _problem(seed=6, deformation=0.1)
    res = match_collection(c.graphs, affinity=AFF, progress=False, rng=0, partial="dummies")
    _check_valid(res, c.sizes)
    assert res.n_universe == c.sizes.max()
    assert "dummy" in res.info["n_universe_rule"]
    big = match_collection(c.graphs, affinity=AFF, progress=False, rng=0, partial="dummies",
                           n_universe=14)
    _check_valid(big, c.sizes)
    assert big.n_universe == 14


def test_dummy_baseline_cao_and_unsynchronized_outputs_are_real_maps():
    c = _problem(seed=7, n_graphs=4, d=8)
    for kw in ({"solver": "cao"}, {"sync": None}):
        res = match_collection(c.graphs, affinity=AFF, progress=False, partial="dummies",
                               n_universe=9, **kw)
        _check_valid(res, c.sizes)


def test_equal_sizes_default_is_the_full_permutation_method():
    c = _problem(seed=8, p_keep=1.0, deformation=0.05)
    assert len(set(c.sizes.tolist())) == 1
    a = match_collection(c.graphs, affinity=AFF, progress=False, rng=0)
    b = match_collection(c.graphs, affinity=AFF, progress=False, rng=0, partial="dummies")
    assert np.array_equal(a.assignments, b.assignments)
    assert a.info["n_universe_rule"].startswith("equal sizes")


def test_equal_sizes_with_outliers_in_a_larger_universe():
    c = _problem(seed=9, p_keep=1.0, n_outliers=2)
    res = match_collection(c.graphs, affinity=AFF, progress=False, rng=0,
                           n_universe=int(c.sizes.sum()) // 2)
    _check_valid(res, c.sizes)


# --------------------------------------------------------------------------- padded affinities

class _Opaque(Affinity):
    """An affinity type the stacking backends do not know (the padded wrapper's path)."""

    def __init__(self, a):
        self.a, self.n1, self.n2 = a, a.n1, a.n2

    def matvec(self, X):
        return self.a.matvec(X)

    def diag(self):
        return self.a.diag()

    def to_dense(self):
        return self.a.to_dense()


@pytest.mark.parametrize("affinity", [
    None, AFF,
    functools.partial(gaussian_edge_affinity, attribute="length+angle", sigma2=0.1),
    lambda g1, g2: DenseAffinity(np.maximum(AFF(g1, g2).to_dense(), 0), g1.n_nodes, g2.n_nodes),
    lambda g1, g2: _Opaque(AFF(g1, g2)),
])
def test_padded_affinity_real_block_is_the_pair_affinity_and_dummies_are_zero(affinity):
    rng = np.random.default_rng(0)
    graphs = [Graph.from_points(rng.random((k, 2)), edges="full") for k in (3, 5, 4)]
    n = 6
    aff = PairAffinities.from_graphs(graphs, affinity=affinity, n_pad=n)
    assert (aff.n1, aff.n2) == (n, n)
    X = rng.random((len(aff), n, n))
    Y = aff.matvec(X)
    f = affinity or functools.partial(gaussian_edge_affinity, sigma2=0.15)
    for p, (i, j) in enumerate(aff.pairs.tolist()):
        a, b = graphs[i].n_nodes, graphs[j].n_nodes
        ref = f(graphs[i], graphs[j]).matvec(X[p, :a, :b])
        np.testing.assert_allclose(Y[p, :a, :b], ref, atol=1e-6)
        out = np.ones((n, n), bool)
        out[:a, :b] = False
        assert np.all(Y[p][out] == 0.0)
        K = aff.pair(p).to_dense()
        assert K.shape == (n * n, n * n)
    with pytest.raises(ValueError, match="n_pad"):
        PairAffinities.from_graphs(graphs, affinity=affinity, n_pad=4)
    with pytest.raises(ValueError, match="same number of nodes"):
        PairAffinities.from_graphs(graphs, affinity=affinity)


@pytest.mark.parametrize("sizes", [(20, 6, 17, 20), (20, 2, 17, 1, 20)])
@pytest.mark.parametrize("affinity", [None, functools.partial(gaussian_edge_affinity,
                                                                 sigma2=0.05)])
def test_one_small_graph_keeps_the_shared_per_graph_factors(affinity, sizes):
    """Whether every pair is separable is decided on the real sizes, as the per-pair function
    decides it: on the padded size (20) the 6-node graph's pairs looked sparse, and the whole
    collection fell back to one expansion per pair with no factors shared between pairs. Pairs
    with a graph of one or two nodes (factorized in the per-pair rule, tiny either way) do not
    send the collection there either."""
    rng = np.random.default_rng(1)
    graphs = [Graph.from_points(rng.random((k, 2)), edges="full") for k in sizes]
    aff = PairAffinities.from_graphs(graphs, affinity=affinity, n_pad=20)
    assert aff.backend == "separable"
    assert aff._impl.F.shape[0] == len(graphs)          # one factor set per graph, not per pair
    f = affinity or functools.partial(gaussian_edge_affinity, sigma2=0.15)
    X = rng.random((len(aff), 20, 20))
    Y = aff.matvec(X)
    for p, (i, j) in enumerate(aff.pairs.tolist()):
        a, b = graphs[i].n_nodes, graphs[j].n_nodes
        if min(a, b) > 2:
            assert isinstance(f(graphs[i], graphs[j]), SeparableAffinity)  # per-pair choice
        ref = gaussian_edge_affinity(graphs[i], graphs[j], sigma2=f.keywords["sigma2"],
                                     backend="dense").matvec(X[p, :a, :b])
        np.testing.assert_allclose(Y[p, :a, :b], ref, atol=1e-7, rtol=0)
        assert not Y[p, a:].any() and not Y[p, :, b:].any()


# --------------------------------------------------------------------------- input contract

@QUIET
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(sizes=st.lists(st.integers(1, 6), min_size=2, max_size=5),
       seed=st.integers(0, 2**16),
       kw=st.sampled_from([{}, {"mode": "offline"}, {"sync": "spectral", "mode": "offline"},
                           {"sync": None}, {"partial": "dummies"}, {"solver": "ga"}]))
def test_any_sizes_give_a_valid_result(sizes, seed, kw):
    rng = np.random.default_rng(seed)
    graphs = [Graph.from_points(rng.random((k, 2)), edges="full") for k in sizes]
    res = match_collection(graphs, affinity=functools.partial(gaussian_edge_affinity, sigma2=0.05),
                           progress=False, rng=seed, **kw)
    _check_valid(res, sizes)
    assert np.all(np.isfinite(res.scores))
    assert res.to_matrix().shape == (sum(sizes), sum(sizes))


@pytest.mark.parametrize("kw", [{}, {"mode": "offline"}, {"partial": "dummies"}])
def test_precomputed_blocks_of_different_sizes_give_the_callables_result(kw):
    """pygmtools-layout (n_i n_j, n_i n_j) blocks in a dict, some given as (j, i) only."""
    c = _problem(seed=10, n_graphs=4, d=8)
    exact = functools.partial(gaussian_edge_affinity, sigma2=0.005, backend="dense")
    blocks = {}
    for i in range(4):
        for j in range(i + 1, 4):
            if (i + j) % 2:
                blocks[(i, j)] = exact(c.graphs[i], c.graphs[j]).to_dense()
            else:
                blocks[(j, i)] = exact(c.graphs[j], c.graphs[i]).to_dense()
    a = match_collection(c.graphs, affinity=blocks, progress=False, rng=0, **kw)
    b = match_collection(c.graphs, affinity=exact, progress=False, rng=0, **kw)
    _check_valid(a, c.sizes)
    assert np.array_equal(a.assignments, b.assignments)
    np.testing.assert_allclose(a.scores, b.scores, rtol=1e-9, atol=1e-12)
    assert multimatching_precision_recall(a, c.ground_truth)["f1"] == 1.0


@pytest.mark.parametrize("kw", [{"partial": "universe"}, {"partial": "dummies"},
                                {"partial": "dummies", "solver": "cao"}])
def test_one_array_of_blocks_with_a_larger_universe(kw):
    # graphs of one size with n_universe > n: the (N, N, n*n, n*n) array the docstring accepts
    # for graphs of one size was refused (the same blocks in a dict were not)
    from transync.datasets import make_graph_collection

    p = make_graph_collection(n_graphs=3, n_inliers=4, deformation=0.0, rng=0)
    exact = functools.partial(gaussian_edge_affinity, sigma2=0.05, backend="dense")
    arr = np.zeros((3, 3, 16, 16))
    for i in range(3):
        for j in range(3):
            if i != j:
                arr[i, j] = exact(p.graphs[i], p.graphs[j]).to_dense()
    a = match_collection(p.graphs, affinity=arr, n_universe=6, progress=False, rng=0, **kw)
    b = match_collection(p.graphs, affinity=exact, n_universe=6, progress=False, rng=0, **kw)
    assert np.array_equal(a.assignments, b.assignments)
    assert a.accuracy(p) == 1.0


def test_blocks_for_different_sizes_are_checked_by_name():
    c = _problem(seed=10, n_graphs=3, d=8)
    with pytest.raises(ValueError, match=r"affinity\[0\]\[1\]"):
        match_collection(c.graphs, affinity={(0, 1): np.ones((4, 4)), (0, 2): np.ones((4, 4)),
                                             (1, 2): np.ones((4, 4))}, progress=False)
    with pytest.raises(ValueError, match="dict"):
        match_collection(c.graphs, affinity=np.ones((3, 3, 4, 4)), progress=False)


@QUIET
@pytest.mark.parametrize("kw", [{}, {"mode": "offline"}, {"mode": "offline", "sync": "spectral"}])
def test_universe_estimated_on_a_sparse_view_graph(kw):
    """Each graph matched to 4 of 15 others (circulant view graph): the estimate is the true
    universe (the eigengap alone gave about 2.5 d there), and the output is the one the true
    universe gives."""
    c = make_subgraph_collection(n_graphs=16, n_universe=12, p_keep=(0.7, 1.0),
                                 deformation=0.0, shuffle=True, rng=5)
    pairs = sorted({tuple(sorted((i, (i + k) % 16))) for i in range(16) for k in (1, 2)})
    res = match_collection(c.graphs, affinity=AFF, pairs=pairs, progress=False, rng=0, **kw)
    _check_valid(res, c.sizes)
    assert res.n_universe == 12
    assert "incomplete view graph" in res.info["n_universe_rule"]
    told = match_collection(c.graphs, affinity=AFF, pairs=pairs, progress=False, rng=0,
                            n_universe=12, **kw)
    np.testing.assert_array_equal(res.assignments, told.assignments)
    m = multimatching_precision_recall(res, c.ground_truth, pairs=np.asarray(pairs))
    assert m["f1"] > 0.9


def test_n_universe_without_a_synchronization_is_refused_unless_it_pads():
    # partial="universe" with sync=None validated n_universe, then ignored it (no universe)
    c = make_subgraph_collection(n_graphs=4, n_universe=8, rng=1)
    with pytest.raises(ValueError, match=r"`n_universe` sizes the synchronized universe; "
                                         r".*sync=None.* synchronizes nothing, got n_universe=8"):
        match_collection(c.graphs, sync=None, n_universe=8, progress=False)
    r = match_collection(c.graphs, sync=None, n_universe=8, partial="dummies", progress=False)
    assert all(np.asarray(r.pairwise(0, j)).shape == (c.sizes[0],) for j in (1, 2, 3))
    assert match_collection(c.graphs, sync=None, progress=False).matching is None
