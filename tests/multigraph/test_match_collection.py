"""The multi-graph front door: planted recovery, invariants, consistency and the input contract."""

import functools
import pickle
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from transync import match_collection
from transync.datasets import make_graph_collection
from transync.exceptions import ConvergenceWarning
from transync.graphs import Graph
from transync.matching import gaussian_edge_affinity
from transync.metrics import multimatching_accuracy
from transync.multigraph import MultiMatchingResult
from transync.permutations import cycle_inconsistency

AFF = functools.partial(gaussian_edge_affinity, sigma2=0.05)
# RRWM (pygmtools' variant, 50 iterations) often stops at its budget on noisy problems; the
# warning is tested on its own below
pytestmark = pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")

METHODS = [
    dict(solver="rrwm", sync="birkhoff", mode="online"),
    dict(solver="ga", sync="birkhoff", mode="online"),
    dict(solver="pf", sync="birkhoff", mode="online"),
    dict(solver="rrwm", sync="spectral", mode="online"),
    dict(solver="rrwm", sync="birkhoff", mode="offline"),
    dict(solver="ga", sync="spectral", mode="offline"),
    dict(solver="pf", sync="orthogonal", mode="offline"),
    dict(solver="sm", sync="spectral", mode="offline"),
    dict(solver="ipfp", sync="birkhoff", mode="offline"),
    dict(solver="rrwm", sync=None),
    dict(solver="ga", sync=None),
    dict(solver="cao"),
    dict(solver="cao-pc"),
    dict(solver="cao-c"),
]


def _ids(m):
    return "-".join(str(v) for v in m.values())


@pytest.fixture(scope="module")
def planted():
    return make_graph_collection(n_graphs=5, n_inliers=8, deformation=0.0, rng=3)


@pytest.fixture(scope="module")
def noisy():
    return make_graph_collection(n_graphs=8, n_inliers=10, deformation=0.15, rng=11)


@pytest.mark.parametrize("method", METHODS, ids=_ids)
def test_planted_solution_recovered_exactly(planted, method):
    res = match_collection(planted.graphs, affinity=AFF, progress=False, **method)
    assert isinstance(res, MultiMatchingResult)
    assert res.accuracy(planted.ground_truth) == 1.0
    assert res.consistency == 1.0
    assert res.assignments.shape == (10, 8)
    truth_scores = [AFF(planted.graphs[i], planted.graphs[j]).score(
        np.eye(8)[planted.truth(i, j)]) for i, j in res.pairs]
    np.testing.assert_allclose(res.scores, truth_scores, rtol=1e-9)
    assert (res.matching is not None) == (method.get("sync", "auto") not in (None, "auto")
                                          or method["solver"] in ("rrwm", "ga", "pf")
                                          and method.get("sync", "auto") == "auto")


@pytest.mark.parametrize("method", [METHODS[0], METHODS[4], METHODS[10], METHODS[12]], ids=_ids)
def test_result_contract(noisy, method):
    res = match_collection(noisy.graphs, affinity=AFF, progress=False, rng=0, **method)
    N, n = 8, 10
    # accuracy: one number, whichever way it is computed
    assert res.accuracy(noisy.ground_truth) == pytest.approx(
        multimatching_accuracy(res.pairwise_dict(), noisy.ground_truth))
    # every map is a permutation; (j, i) inverts (i, j)
    for i, j in [(0, 1), (2, 7), (5, 3)]:
        a, b = res.pairwise(i, j), res.pairwise(j, i)
        assert sorted(a.tolist()) == list(range(n))
        np.testing.assert_array_equal(b[a], np.arange(n))
    T = res.to_matrix()
    np.testing.assert_array_equal(T, T.T)
    rep = cycle_inconsistency(res.pairwise_dict())
    assert res.consistency == pytest.approx(1 - rep["cycle_error"])
    if res.matching is not None:
        assert rep["inconsistent_triangles"] == 0.0
        np.testing.assert_allclose(T @ T, N * T)          # T = U U^T with U^T U = N I
    assert res.total_score == pytest.approx(res.scores.sum())
    again = pickle.loads(pickle.dumps(res))
    np.testing.assert_array_equal(again.assignments, res.assignments)
    assert set(res.timings) >= {"affinity", "pairwise", "total"}


@pytest.mark.parametrize("solver", ["rrwm", "ga", "pf"])
def test_synchronized_at_least_as_accurate_as_pairwise(solver):
    """Mean over three hard problems (deformation 0.15): pairwise accuracy 0.36-0.69."""
    acc0, acc1 = [], []
    for seed in (11, 12, 13):
        p = make_graph_collection(n_graphs=8, n_inliers=10, deformation=0.15, rng=seed)
        base = match_collection(p.graphs, solver=solver, sync=None, affinity=AFF,
                                progress=False)
        synced = match_collection(p.graphs, solver=solver, affinity=AFF, progress=False, rng=0)
        acc0.append(base.accuracy(p.ground_truth))
        acc1.append(synced.accuracy(p.ground_truth))
        assert synced.consistency == 1.0 and base.consistency < 1.0
        hist = synced.info["refine"]["score_history"]
        assert np.all(np.diff(hist) >= 0) and synced.total_score == pytest.approx(hist[-1])
        moves = synced.info["refine"]["moves"]
        assert set(moves) == {"anchor", "swap"} and min(moves.values()) >= 0
    assert np.mean(acc0) < 0.8                     # hard enough to need synchronization
    assert np.mean(acc1) >= np.mean(acc0) + 0.05


def test_relabelling_a_graph_relabels_the_maps(noisy):
    rng = np.random.default_rng(5)
    perm = rng.permutation(10)
    graphs = list(noisy.graphs)
    graphs[2] = graphs[2].permute(perm)            # new node u of graph 2 = old node perm[u]
    a = match_collection(noisy.graphs, solver="rrwm", sync=None, affinity=AFF, progress=False)
    b = match_collection(graphs, solver="rrwm", sync=None, affinity=AFF, progress=False)
    inv = np.argsort(perm)
    np.testing.assert_array_equal(b.pairwise(0, 2), inv[a.pairwise(0, 2)])
    np.testing.assert_array_equal(b.pairwise(2, 5), a.pairwise(2, 5)[perm])


def test_precomputed_K_blocks_give_the_callable_result(planted):
    N, n = 5, 8
    K = np.zeros((N, N, n * n, n * n))
    for i in range(N):
        for j in range(N):
            if i != j:
                K[i, j] = AFF(planted.graphs[i], planted.graphs[j]).to_dense()
    a = match_collection(planted.graphs, solver="rrwm", sync=None, affinity=AFF,
                         progress=False)
    b = match_collection(planted.graphs, solver="rrwm", sync=None, affinity=K, progress=False)
    np.testing.assert_array_equal(a.assignments, b.assignments)
    np.testing.assert_allclose(a.scores, b.scores, rtol=1e-9)


def test_sparse_view_graph_offline(noisy):
    N = 8
    ring = [(i, (i + 1) % N) for i in range(N)] + [(0, 4), (2, 6)]
    res = match_collection(noisy.graphs, solver="rrwm", sync="spectral", mode="offline",
                           affinity=AFF, pairs=ring, progress=False, rng=0)
    assert len(res.pairs) == len(ring) and res.consistency == 1.0
    assert sorted(res.pairwise(1, 5).tolist()) == list(range(10))   # not observed, derived


@pytest.mark.parametrize("executor", ["processes", 2, "threads"])
def test_executors_give_the_serial_result(noisy, executor):
    serial = match_collection(noisy.graphs, solver="rrwm", sync="spectral", mode="offline",
                              affinity=AFF, progress=False, rng=1)
    if executor == "threads":
        with ThreadPoolExecutor(2) as ex:
            other = match_collection(noisy.graphs, solver="rrwm", sync="spectral",
                                     mode="offline", affinity=AFF, progress=False, rng=1,
                                     executor=ex)
    else:
        other = match_collection(noisy.graphs, solver="rrwm", sync="spectral", mode="offline",
                                 affinity=AFF, progress=False, rng=1, executor=executor)
    np.testing.assert_array_equal(serial.assignments, other.assignments)


def test_dask_local_cluster_gives_the_serial_result(planted):
    distributed = pytest.importorskip("distributed")
    serial = match_collection(planted.graphs, solver="ga", sync="birkhoff", mode="offline",
                              affinity=AFF, progress=False, rng=2)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None,
                                  scheduler_kwargs={"dashboard_address": ":0"}) as cluster, \
            distributed.Client(cluster) as client:
        other = match_collection(planted.graphs, solver="ga", sync="birkhoff", mode="offline",
                                 affinity=AFF, progress=False, rng=2, executor=client)
    np.testing.assert_array_equal(serial.assignments, other.assignments)


def _graphs(sizes, rng=0):
    rng = np.random.default_rng(rng)
    return [Graph.from_points(rng.random((s, 2)), edges="full") for s in sizes]


@pytest.mark.parametrize("graphs, kwargs, exc, match", [
    (_graphs([5, 5, 6]), {"solver": "cao"}, ValueError, "`partial` must be 'dummies'"),
    (_graphs([5, 5, 6]), {"n_universe": 5}, ValueError, "`n_universe` must be >= .* 6"),
    (_graphs([5, 5, 6]), {"n_universe": 17}, ValueError, "`n_universe` must be <= .* 16"),
    (_graphs([5, 5, 6]), {"n_universe": 7.5}, TypeError, "n_universe"),
    (_graphs([5, 5, 6]), {"n_universe": "7"}, TypeError, "n_universe"),
    (_graphs([5, 5, 6]), {"partial": "pad"}, ValueError, "`partial`"),
    (_graphs([4, 4, 5]), {"affinity": np.ones((3, 3, 16, 16))}, ValueError, "callable"),
    (_graphs([5]), {}, ValueError, "at least 2 graphs"),
    ([], {}, ValueError, "at least 2 graphs"),
    (_graphs([5])[0], {}, TypeError, "sequence"),
    ([_graphs([5])[0], np.eye(5)], {}, TypeError, r"graphs\[1\]"),
    (_graphs([4, 4, 4]), {"solver": "hungarian"}, ValueError, "`solver`"),
    (_graphs([4, 4, 4]), {"sync": "svd"}, ValueError, "`sync`"),
    (_graphs([4, 4, 4]), {"mode": "batch"}, ValueError, "`mode`"),
    (_graphs([4, 4, 4]), {"solver": "sm"}, ValueError, "offline only"),
    (_graphs([4, 4, 4]), {"pairs": [(0, 0), (1, 2)]}, ValueError, "itself"),
    (_graphs([4, 4, 4]), {"pairs": [(0, 1), (1, 0)]}, ValueError,
     r"repeat a pair, got \(1, 0\) at row 1 after \(0, 1\)"),
    (_graphs([4, 4, 4]), {"pairs": [(0, 3)]}, ValueError, r"\[0, 3\)"),
    (_graphs([4, 4, 4]), {"pairs": [[0, 1, 2]]}, ValueError, r"\(P, 2\)"),
    (_graphs([4, 4, 4, 4]), {"pairs": [(0, 1), (2, 3)]}, ValueError, "disconnected"),
    (_graphs([4, 4, 4]), {"solver": "cao", "pairs": [(0, 1), (1, 2)]}, ValueError, "all 3"),
    (_graphs([4, 4, 4]), {"executor": "processes"}, ValueError, "executor"),
    (_graphs([4, 4, 4]), {"damping": 1.5}, ValueError, "damping"),
    (_graphs([4, 4, 4]), {"affinity": 3.0}, TypeError, "affinity"),
    (_graphs([4, 4, 4]), {"affinity": np.zeros((3, 3, 16, 15))}, ValueError,
     r"`affinity` must have shape"),
])
def test_bad_input_is_refused_by_name(graphs, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        match_collection(graphs, progress=False, **kwargs)


def test_disconnected_view_graph_is_fine_without_sync():
    res = match_collection(_graphs([4, 4, 4, 4]), sync=None, pairs=[(0, 1), (2, 3)],
                           progress=False)
    assert len(res.pairs) == 2
    with pytest.raises(ValueError, match="not matched"):
        res.pairwise(0, 2)


@pytest.mark.parametrize("attribute", ["length", "length+angle"])
def test_graphs_without_points_for_a_length_affinity_are_named(attribute):
    p = make_graph_collection(n_graphs=3, n_inliers=5, rng=0)     # edge features, no points
    aff = functools.partial(gaussian_edge_affinity, attribute=attribute)
    with pytest.raises(ValueError, match="needs graphs with `points`") as info:
        match_collection(p.graphs, affinity=aff, progress=False)
    text = str(info.value) + " ".join(getattr(info.value, "__notes__", []))
    assert "graphs[0]" in text


@pytest.mark.parametrize("mode", ["online", "offline"])
def test_a_user_affinity_with_bad_output_is_named_with_its_pair(mode):
    """A user's Affinity subclass whose matvec returns NaN or None: "`score` must be finite",
    "`M` must be finite and non-negative", raw AxisError or "bad operand type for abs()"
    depending on the solver, never naming `affinity` or the pair."""
    from transync.matching import Affinity

    class Faulty(Affinity):
        def __init__(self, n1, n2, bad):
            self.n1, self.n2, self.bad = n1, n2, bad

        def matvec(self, X):
            return None if self.bad else np.ones((self.n1, self.n2))

        def diag(self):
            return np.ones((self.n1, self.n2))

        def to_dense(self):
            return np.ones((self.n1 * self.n2,) * 2)

    p = make_graph_collection(n_graphs=3, n_inliers=4, rng=0)
    aff = lambda a, b: Faulty(a.n_nodes, b.n_nodes, bad=a is p.graphs[1])   # noqa: E731
    for solver in ("rrwm", "ga", "pf"):
        with pytest.raises(TypeError, match=r"`affinity\(graphs\[1\], graphs\[2\]\)`\.matvec"
                                            r"\(\) \(a Faulty\) must return a float array"):
            match_collection(p.graphs, solver=solver, mode=mode, affinity=aff, progress=False)
    good = lambda a, b: Faulty(a.n_nodes, b.n_nodes, bad=False)     # noqa: E731
    res = match_collection(p.graphs, mode=mode, affinity=good, progress=False)
    assert res.consistency == 1.0


def test_affinity_of_the_wrong_kind_is_refused():
    p = make_graph_collection(n_graphs=3, n_inliers=5, rng=0)
    with pytest.raises(TypeError, match="must return a transync.matching.Affinity"):
        match_collection(p.graphs, affinity=lambda a, b: np.ones((25, 25)), progress=False)


def test_default_affinity_on_sparse_and_delaunay_graphs():
    p = make_graph_collection(n_graphs=4, n_inliers=10, density=0.3, deformation=0.0, rng=0)
    res = match_collection(p.graphs, progress=False)    # edges differ per graph: hard, but runs
    assert res.consistency == 1.0
    assert np.all(np.sort(res.assignments, axis=1) == np.arange(10))
    rng = np.random.default_rng(0)
    pts = rng.random((30, 2))
    perms = [rng.permutation(30) for _ in range(4)]
    graphs = [Graph.from_points(pts[q], edges="delaunay") for q in perms]
    res = match_collection(graphs, progress=False)
    assert res.accuracy([np.asarray(q) for q in perms]) == 1.0   # label of node u: point q[u]


def test_unconverged_pairs_warn_once():
    p = make_graph_collection(n_graphs=4, n_inliers=8, deformation=0.2, rng=0)
    with pytest.warns(ConvergenceWarning, match="did not converge.*option 'max_iter'") as rec:
        res = match_collection(p.graphs, sync=None, affinity=AFF, options={"max_iter": 1},
                               progress=False)
    assert len(rec) == 1 and res.converged is False
    # GA's budget is max_inner (the warning named 'max_iter', which GA refuses)
    with pytest.warns(ConvergenceWarning, match="solver 'ga' .*option 'max_inner'"):
        match_collection(p.graphs, solver="ga", sync=None, affinity=AFF,
                         options={"max_inner": 1, "inner_tol": 1e-15}, progress=False)


def test_points_of_different_dimensions_refused_on_every_path():
    """The per-graph (separable) expansion of the default affinity skipped the dimension
    check that the pairwise affinity makes: 2-d and 3-d points were matched on complete
    graphs (refused on Delaunay graphs, which take the pairwise path)."""
    rs = np.random.default_rng(0)
    P = rs.random((12, 2))
    g2 = Graph.from_points(P, edges="full")
    g3 = Graph.from_points(np.c_[P, rs.random(12)], edges="full")
    for kwargs in (dict(), dict(mode="offline", sync="spectral"), dict(sync=None)):
        with pytest.raises(ValueError, match=r"`graphs\[0\]` and `graphs\[1\]` must have "
                                             r"points of the same dimension"):
            match_collection([g2, g3, g2], progress=False, **kwargs)


def test_accuracy_names_a_truth_of_the_wrong_shape():
    p = make_graph_collection(n_graphs=4, n_inliers=5, rng=0)
    res = match_collection(p.graphs, progress=False)
    labels = p.ground_truth.labels
    for bad in ([], labels[:3], [lab[:3] for lab in labels]):
        with pytest.raises(ValueError, match=r"`truth` must label the 4 graphs of this result"):
            res.accuracy(bad)
    with pytest.raises(TypeError, match="`truth` must be a MultiMatching"):
        res.accuracy("x")


@pytest.mark.parametrize("kwargs, exc, match", [
    ({"affinity": np.zeros((5, 5, 16, 16))}, ValueError, "blocks for 5 graphs, but 3"),
    ({"affinity": {(0, 7): np.zeros((16, 16))}}, ValueError, "graph 7, but there are only 3"),
    ({"affinity": {("a", "b"): np.zeros((16, 16))}}, TypeError, "keys"),
    ({"affinity": {(0, 1): np.ones((16, 16))}}, ValueError, r"`affinity` has no block for pair"),
    ({"sync": None, "sync_every": 3}, ValueError, "sync_every"),
    ({"mode": "offline", "damping": 0.5}, ValueError,
     r"`damping` steers .*; solver='rrwm' with sync='birkhoff' and mode='offline' runs none"),
    ({"mode": "offline", "sync_every": 2}, ValueError, r"and mode='offline' runs none"),
    ({"solver": "ga", "options": {"beta0": 1e-300, "beta_max": 1e100}}, ValueError,
     "`beta_rate`=1.075 anneals from beta0=1e-300"),
    ({"refine": "no"}, TypeError, "refine"),
    ({"options": {"maxiter": 3}}, TypeError, "`options` has unknown option.*'maxiter'"),
    ({"options": [1]}, TypeError, "`options` must be a dict"),
])
def test_more_bad_input(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        match_collection(_graphs([4, 4, 4]), progress=False, **kwargs)


def test_result_arrays_are_read_only(planted):
    res = match_collection(planted.graphs, sync=None, affinity=AFF, progress=False)
    with pytest.raises(ValueError):
        res.assignments[0, 0] = 3
    assert res.mode == "offline"                  # sync=None: the pairs were solved alone


def test_online_orthogonal_sync(planted):
    res = match_collection(planted.graphs, sync="orthogonal", affinity=AFF, progress=False,
                           rng=0)
    assert res.accuracy(planted.ground_truth) == 1.0 and res.consistency == 1.0


def test_view_graph_and_block_dict_contract():
    """Bad view-graph rows are reported as what they are (before: "`pairs[0]` pairs graph 7
    with itself" for an index out of range, "graph 0.5" for a fraction); a dict of K blocks
    with a block of a graph with itself is refused, not ignored."""
    graphs = make_graph_collection(n_graphs=3, n_inliers=4, rng=0).graphs
    with pytest.raises(ValueError, match=r"`pairs` must hold graph indices in \[0, 3\)"):
        match_collection(graphs, pairs=[[7, 7], [0, 1], [1, 2]], progress=False)
    with pytest.raises(TypeError, match="`pairs` must hold integer graph indices, got 0.5"):
        match_collection(graphs, pairs=[[0.5, 0.5], [0, 1], [1, 2]], progress=False)
    with pytest.raises(ValueError, match=r"`pairs\[0\]` pairs graph 1 with itself"):
        match_collection(graphs, pairs=[[1, 1], [0, 1], [1, 2]], progress=False)
    K = {(i, j): gaussian_edge_affinity(graphs[i], graphs[j]).to_dense()
         for i in range(3) for j in range(i + 1, 3)}
    with pytest.raises(ValueError, match=r"key \(0, 0\) pairs graph 0 with itself"):
        match_collection(graphs, affinity={**K, (0, 0): "junk"}, progress=False)
    with pytest.raises(ValueError, match="`affinity` is too small to match on"):
        match_collection(graphs, affinity={k: v * 1e-305 for k, v in K.items()},
                         progress=False)


def test_serial_executors_are_accepted_online():
    """executor="serial" and executor=1 mean "in this process", as None does (the parallel
    module's definition); the online solvers refused them."""
    p = make_graph_collection(n_graphs=4, n_inliers=5, rng=0)
    ref = match_collection(p.graphs, progress=False, rng=0)
    for ex in ("serial", 1):
        res = match_collection(p.graphs, executor=ex, progress=False, rng=0)
        np.testing.assert_array_equal(res.assignments, ref.assignments)
    with pytest.raises(ValueError, match="`executor` spreads independent pairwise work"):
        match_collection(p.graphs, executor=2, progress=False)
    with pytest.raises(TypeError, match="`executor` must be None or 'serial'"):
        match_collection(p.graphs, executor=True, progress=False)   # the executors' own check
