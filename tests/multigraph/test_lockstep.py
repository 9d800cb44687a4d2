"""Lock-step solvers: each pair reproduces the pairwise solver; synchronization hooks; options."""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest

from transync.datasets import make_graph_collection
from transync.exceptions import ConvergenceWarning
from transync.graphs import Graph
from transync.matching import RRWMStepper, ga, gaussian_edge_affinity, pf, rrwm
from transync.matching._sinkhorn import (
    sinkhorn_augmented_batch,
    sinkhorn_batch,
    sinkhorn_normalize,
)
from transync.multigraph._affinity import PairAffinities, all_pairs
from transync.multigraph._lockstep import (
    LockstepOutcome,
    doubly_stochastic_iterates,
    lockstep_options,
    run_lockstep,
)

AFF = functools.partial(gaussian_edge_affinity, sigma2=0.05)

PAIRWISE = {
    "rrwm-original": (functools.partial(rrwm, variant="original", max_iter=25), "rrwm",
                      {"variant": "original", "max_iter": 25}),
    "rrwm-authors": (functools.partial(rrwm, variant="original", warm_start=False, max_iter=25),
                     "rrwm", {"variant": "original", "warm_start": False, "max_iter": 25}),
    "rrwm-pygmtools": (functools.partial(rrwm, variant="pygmtools"), "rrwm",
                       {"variant": "pygmtools"}),
    "ga": (ga, "ga", {}),
    "pf": (pf, "pf", {}),
}


@pytest.fixture(scope="module")
def hard():
    """A noisy collection with an outlier per graph: the solvers disagree between pairs."""
    prob = make_graph_collection(n_graphs=4, n_inliers=7, n_outliers=1, deformation=0.15, rng=5)
    pairs = all_pairs(4)
    affs = [AFF(prob.graphs[i], prob.graphs[j]) for i, j in pairs]
    return affs, PairAffinities.from_affinities(affs, pairs)


@pytest.mark.parametrize("name", list(PAIRWISE))
def test_each_pair_reproduces_the_pairwise_solver(name, hard):
    fn, solver, opts = PAIRWISE[name]
    affs, A = hard
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        ref = [fn(a) for a in affs]
    out = run_lockstep(A, solver=solver, options=opts)
    assert isinstance(out, LockstepOutcome) and out.n_sync == 0 and out.seconds_sync == 0
    for p, r in enumerate(ref):
        np.testing.assert_array_equal(out.assignments[p], r.assignment)
        np.testing.assert_allclose(out.soft[p], r.soft, atol=1e-10, rtol=0)
        assert out.converged[p] == r.converged
        assert out.info["steps_per_pair"][p] == r.n_iter
    assert out.n_iter == max(r.n_iter for r in ref)


def test_warm_rrwm_original_stops_per_pair_as_the_pairwise_solver():
    """Whole runs of the warm-started original variant: some pairs stop on the tolerance,
    some on their rounding being stable over three checks, each as its pairwise run."""
    prob = make_graph_collection(n_graphs=4, n_inliers=7, n_outliers=1, deformation=0.15, rng=6)
    pairs = all_pairs(4)
    affs = [AFF(prob.graphs[i], prob.graphs[j]) for i, j in pairs]
    ref = [rrwm(a) for a in affs]
    assert {r.info["stop"] for r in ref} == {"tolerance", "stable rounding"}
    out = run_lockstep(PairAffinities.from_affinities(affs, pairs), solver="rrwm",
                       options={"variant": "original"})
    for p, r in enumerate(ref):
        np.testing.assert_array_equal(out.assignments[p], r.assignment)
        assert out.converged[p] and out.info["steps_per_pair"][p] == r.n_iter


def test_unequal_sizes_rrwm_original_slack():
    """n1 != n2: the slack-mass Sinkhorn, per pair as the pairwise solver."""
    rng = np.random.default_rng(2)
    g1 = [Graph.from_points(rng.random((5, 2)), edges="full") for _ in range(3)]
    g2 = [Graph.from_points(rng.random((7, 2)), edges="full") for _ in range(3)]
    affs = [gaussian_edge_affinity(a, b, sigma2=0.1) for a, b in zip(g1, g2)]
    A = PairAffinities.from_affinities(affs, [(0, 1), (0, 2), (1, 2)])
    out = run_lockstep(A, solver="rrwm", options={"variant": "original", "max_iter": 15})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        ref = [rrwm(a, max_iter=15) for a in affs]
    for p, r in enumerate(ref):
        np.testing.assert_array_equal(out.assignments[p], r.assignment)
        np.testing.assert_allclose(out.soft[p], r.soft, atol=1e-10, rtol=0)


@pytest.mark.parametrize("solver", ["rrwm", "ga", "pf"])
def test_planted_recovery_at_zero_noise(solver):
    prob = make_graph_collection(n_graphs=4, n_inliers=8, deformation=0.0, rng=1)
    A = PairAffinities.from_graphs(prob.graphs, affinity=AFF)
    out = run_lockstep(A, solver=solver)
    L = prob.labels
    for p, (i, j) in enumerate(A.pairs):
        np.testing.assert_array_equal(L[j][out.assignments[p]], L[i])


def _truth_blocks(prob, pairs):
    n = len(prob.labels[0])
    Y = np.zeros((len(pairs), n, n))
    for p, (i, j) in enumerate(pairs):
        Li, Lj = prob.labels[i], prob.labels[j]
        Y[p] = (Li[:, None] == Lj[None, :]).astype(float)
    return Y


def _accuracy(prob, pairs, assignments):
    return np.mean([np.mean(prob.labels[j][a] == prob.labels[i])
                    for (i, j), a in zip(pairs, assignments)])


def test_sync_point_reads_every_pairs_own_iterate():
    """Pairs settle at different steps (the batch keeps working copies of the active pairs
    between steps): a sync point reads, for every pair, the iterate of its own pairwise run
    after that many steps (a settled pair: its last one), and the run goes on from it."""
    prob = make_graph_collection(n_graphs=5, n_inliers=7, n_outliers=1, deformation=0.15, rng=5)
    pairs = all_pairs(5)
    affs = [AFF(prob.graphs[i], prob.graphs[j]) for i, j in pairs]
    A = PairAffinities.from_affinities(affs, pairs)
    opts, every = {"variant": "pygmtools"}, 15
    steps = run_lockstep(A, solver="rrwm", options=opts).info["steps_per_pair"]
    assert (steps < every).any() and (steps > every).any()
    seen = []

    def sync(X):
        seen.append(X.copy())
        return X

    out = run_lockstep(A, solver="rrwm", sync=sync, sync_every=every, options=opts)
    ref = []
    for a in affs:
        st = RRWMStepper(a, variant="pygmtools")
        for _ in range(every):
            if not st.done:
                st.step()
        ref.append(st.iterate)
    assert out.n_sync >= 1
    np.testing.assert_allclose(seen[0], doubly_stochastic_iterates(np.stack(ref)), rtol=0,
                               atol=1e-12)
    # a sync point restarts every pair, settled ones included
    assert np.all(out.info["steps_per_pair"] > np.minimum(steps, every))


@pytest.mark.parametrize("solver,every,opts", [("rrwm", 2, {}), ("ga", None, {}),
                                               ("pf", None, {})])
def test_sync_steers_towards_the_synchronized_blocks(solver, every, opts):
    """A synchronizer that returns the ground truth: it is called at the documented points with
    (P, n, n) non-negative iterates, and it steers the solver (more accurate than without)."""
    prob = make_graph_collection(n_graphs=4, n_inliers=7, deformation=0.25, rng=4)
    A = PairAffinities.from_graphs(prob.graphs, affinity=AFF)
    truth = _truth_blocks(prob, A.pairs)
    seen = []

    def sync(X):
        seen.append(X.copy())
        return truth

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        out = run_lockstep(A, solver=solver, sync=sync, sync_every=every, options=opts)
        plain = run_lockstep(A, solver=solver, options=opts)
    assert out.n_sync == len(seen) >= 1
    assert all(X.shape == truth.shape and X.min() >= 0 for X in seen)
    for X in seen:              # doubly stochastic (what synchronize_doubly_stochastic wants)
        np.testing.assert_allclose(X.sum(1), 1.0, atol=1e-9)
        np.testing.assert_allclose(X.sum(2), 1.0, atol=1e-9)
    assert out.n_sync <= out.n_iter // (every or 1)
    before = _accuracy(prob, A.pairs, plain.assignments)
    assert before < 1.0
    assert _accuracy(prob, A.pairs, out.assignments) > before
    assert out.seconds_sync > 0 and out.seconds_solve > 0
    if solver == "pf":          # syncs do not stall the lambda schedule: as many rounds as plain
        assert out.n_iter <= plain.n_iter + 5 and np.all(out.info["lam"] == 1.0)


def test_damping_blends():
    prob = make_graph_collection(n_graphs=3, n_inliers=6, deformation=0.1, rng=0)
    A = PairAffinities.from_graphs(prob.graphs, affinity=AFF)
    got = {}

    def sync(X):
        got.setdefault("X", X.copy())
        return np.full_like(X, 1.0 / X.shape[1])

    out = run_lockstep(A, solver="ga", sync=sync, sync_every=1, damping=0.5,
                       options={"beta_max": 0.6})
    assert out.n_sync == 2      # three beta levels; no sync after the last one
    assert out.n_iter == 3
    assert out.soft.shape == (3, 6, 6)


def test_batched_sinkhorn_matches_sinkhorn_normalize():
    rng = np.random.default_rng(0)
    for shape, slack in [((6, 5, 5), "mass"), ((6, 4, 7), "mass"), ((6, 7, 4), "mass"),
                         ((6, 5, 5), "none")]:
        A = np.exp(4 * rng.random(shape))
        X, sweeps, conv, _ = sinkhorn_batch(A, slack=slack, tol=1e-6, max_iter=50,
                                             check_every=3)
        for k in range(len(A)):
            ref = sinkhorn_normalize(A[k], domain="scaling", slack=slack, tol=1e-6, max_iter=50,
                                     check_every=3)
            np.testing.assert_allclose(X[k], ref.X, atol=1e-12, rtol=0)
            assert sweeps[k] == ref.n_sweeps and conv[k] == ref.converged
        X = sinkhorn_batch(A, slack=slack, tol=None, half_sweeps=7)[0]
        for k in range(len(A)):
            ref = sinkhorn_normalize(A[k], domain="scaling", slack=slack, half_sweeps=7)
            np.testing.assert_allclose(X[k], ref.X, atol=1e-12, rtol=0)
    M = np.exp(3 * rng.random((5, 6, 7)))
    M2 = M.copy()
    sinkhorn_augmented_batch(M2, tol=0.05, max_iter=30)
    for k in range(len(M)):
        ref = sinkhorn_normalize(M[k].copy(), domain="augmented", slack="augmented", tol=0.05,
                                 max_iter=30)
        np.testing.assert_allclose(M2[k], ref.X, atol=1e-12, rtol=0)


def test_options_validated_and_defaults():
    prob = make_graph_collection(n_graphs=3, n_inliers=5, rng=0)
    A = PairAffinities.from_graphs(prob.graphs, affinity=AFF)
    assert "variant" in lockstep_options("rrwm") and "fw_tol" in lockstep_options("pf")
    with pytest.raises(TypeError, match=r"unknown option\(s\) 'bogus'; valid options: .*beta0"):
        run_lockstep(A, solver="ga", options={"bogus": 1})
    with pytest.raises(ValueError, match="beta_rate"):
        run_lockstep(A, solver="ga", options={"beta_rate": 0.5})
    with pytest.raises(ValueError, match="more than 10000"):
        run_lockstep(A, solver="ga", options={"beta_rate": 1.0002})
    with pytest.raises(ValueError, match="variant"):
        run_lockstep(A, solver="rrwm", options={"variant": "fast"})
    with pytest.raises(ValueError, match="`solver` must be one of"):
        run_lockstep(A, solver="sm")
    with pytest.raises(TypeError, match="PairAffinities"):
        run_lockstep([A], solver="rrwm")
    with pytest.raises(ValueError, match="damping"):
        run_lockstep(A, solver="rrwm", damping=1.5)
    with pytest.raises(ValueError, match="sync_every"):
        run_lockstep(A, solver="rrwm", sync=lambda X: X, sync_every=0)
    with pytest.raises(TypeError, match="`sync` must be None or a callable"):
        run_lockstep(A, solver="rrwm", sync="birkhoff")
    with pytest.raises(ValueError, match=r"must return an array of shape \(3, 5, 5\)"):
        run_lockstep(A, solver="ga", sync=lambda X: X[:2])
    for solver in ("pf", "rrwm", "ga"):     # PF met NaN in its Frank-Wolfe LAP at 1e300
        with pytest.raises(ValueError, match=r"entries in \[0, 1\].*maximum \d.*e\+29\d"):
            run_lockstep(A, solver=solver, sync=lambda X: X * 1e300, sync_every=1)
    out = run_lockstep(A, solver="rrwm", options={"max_iter": 3})
    assert out.info["options"]["variant"] == "pygmtools" and out.n_iter <= 3


def test_progress_bar_runs(capsys):
    prob = make_graph_collection(n_graphs=3, n_inliers=5, rng=0)
    A = PairAffinities.from_graphs(prob.graphs, affinity=AFF)
    out = run_lockstep(A, solver="rrwm", progress=True)
    assert out.converged.all()


def test_doubly_stochastic_iterates_exact_and_faithful():
    prob = make_graph_collection(n_graphs=5, n_inliers=8, deformation=0.1, rng=2)
    A = PairAffinities.from_graphs(prob.graphs, affinity=AFF)
    for k in (1, 3):
        X = run_lockstep(A, solver="rrwm", options={"max_iter": k}).soft
        Y = doubly_stochastic_iterates(X)
        np.testing.assert_allclose(Y.sum(1), 1.0, atol=1e-13)
        np.testing.assert_allclose(Y.sum(2), 1.0, atol=1e-13)
        assert Y.min() >= 0 and np.abs(Y - X).max() < 0.25
    rng = np.random.default_rng(0)
    D = np.stack([0.3 * np.eye(6)[rng.permutation(6)] + 0.7 * np.eye(6)[rng.permutation(6)]
                  for _ in range(4)])
    np.testing.assert_allclose(doubly_stochastic_iterates(D), D, atol=1e-12)
    with pytest.raises(ValueError, match="non-negative"):
        doubly_stochastic_iterates(-D)


def test_birkhoff_synchronizer_as_sync_point():
    """The library's Birkhoff synchronization accepts the iterates handed to `sync` (doubly
    stochastic to 1e-6) and S-RRWM is at least as accurate as plain RRWM on a hard problem."""
    from transync.synchronization import synchronize_doubly_stochastic

    prob = make_graph_collection(n_graphs=4, n_inliers=8, n_outliers=1, deformation=0.2, rng=6)
    A = PairAffinities.from_graphs(prob.graphs, affinity=AFF)
    calls = []

    def sync(X):
        blocks = {(int(i), int(j)): X[p] for p, (i, j) in enumerate(A.pairs)}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            res = synchronize_doubly_stochastic(blocks, max_iter=5, rng=0)
        calls.append(1)
        return res.stacked_blocks(A.pairs)

    out = run_lockstep(A, solver="rrwm", sync=sync, options={"max_iter": 20})
    plain = run_lockstep(A, solver="rrwm", options={"max_iter": 20})
    assert out.n_sync == len(calls) >= 1
    assert _accuracy(prob, A.pairs, out.assignments) >= _accuracy(prob, A.pairs, plain.assignments)


def test_ga_final_temperature_follows_the_pair_size():
    """GA's default final temperature grows with the graphs (``default_beta_max``): the batched
    solver must resolve it from the pairs' size as the pairwise GA does (14-node graphs: 14)."""
    prob = make_graph_collection(n_graphs=3, n_inliers=12, n_outliers=2, deformation=0.1,
                                 rng=3)
    pairs = all_pairs(3)
    affs = [AFF(prob.graphs[i], prob.graphs[j]) for i, j in pairs]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        ref = [ga(a) for a in affs]
        out = run_lockstep(PairAffinities.from_affinities(affs, pairs), solver="ga")
    assert all(r.n_iter == ref[0].n_iter for r in ref)
    assert ref[0].n_iter == int(np.ceil(np.log(14 / 0.5) / np.log(1.075)))   # beta 0.5 -> 14
    assert out.info["options"]["beta_max"] == 14.0
    for p, r in enumerate(ref):
        np.testing.assert_array_equal(out.assignments[p], r.assignment)
        np.testing.assert_allclose(out.soft[p], r.soft, atol=1e-10, rtol=0)


def _bipartite_pairs():
    """Paths with an isolated node and trees: bipartite affinities (spectrum symmetric about
    0), whose power iteration oscillates and leaves zeros in its vector."""
    rng = np.random.default_rng(0)
    A = np.zeros((4, 4))
    A[0, 1] = A[1, 0] = A[1, 2] = A[2, 1] = 1
    path = (Graph(A, points=np.array([[0.0, 0], [0.3, 0], [0.3, 0.5], [0.9, 0.9]])),
            Graph(A, points=np.array([[0.0, 0], [0.4, 0.1], [0.5, 0.5], [0.1, 0.8]])))
    T = np.zeros((8, 8))
    for i in range(1, 8):
        j = rng.integers(0, i)
        T[i, j] = T[j, i] = 1
    tree = Graph(T, points=rng.random((8, 2)))
    return [path, (tree, tree.permute(rng.permutation(8)))]


@pytest.mark.parametrize("k", [0, 1])
def test_pf_mu_bounds_the_largest_eigenvalue_on_bipartite_affinities(k):
    # PF needs mu >= lambda_max(K) for its convex start f_0 = x^T (K - mu I) x; 1.05 |Rayleigh
    # quotient| of the oscillating power iteration fell 7-24 % short on these
    g1, g2 = _bipartite_pairs()[k]
    aff = gaussian_edge_affinity(g1, g2)
    top = np.linalg.eigvalsh(aff.to_dense())[-1]
    mu = pf(aff).info["mu"]
    assert top <= mu <= 3.0 * top
    out = run_lockstep(PairAffinities.from_affinities([aff], [(0, 1)]), solver="pf")
    assert top <= out.info["mu"][0] <= 3.0 * top
