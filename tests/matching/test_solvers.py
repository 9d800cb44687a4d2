"""Pairwise QAP/LAP solvers: planted solutions, invariants, brute force, protocol, validation."""

from __future__ import annotations

import dataclasses
import functools
import inspect
import itertools
import re
import warnings

import numpy as np
import pytest

from transync.exceptions import ConvergenceWarning
from transync.graphs import Graph
from transync.metrics import matching_accuracy as accuracy
from transync.matching import (
    GAStepper,
    IPFPStepper,
    MatchingResult,
    PFStepper,
    RRWMStepper,
    SMStepper,
    Stepper,
    default_beta_max,
    ga,
    gaussian_edge_affinity,
    hungarian,
    ipfp,
    match_graphs,
    pf,
    rrwm,
    sinkhorn,
    sm,
)

QAP = {"sm": sm, "rrwm": rrwm, "rrwm-pygmtools": functools.partial(rrwm, variant="pygmtools"),
       "ipfp": ipfp, "ga": ga, "pf": pf}
STEPPERS = {"sm": SMStepper, "rrwm": RRWMStepper,
            "rrwm-pygmtools": functools.partial(RRWMStepper, variant="pygmtools"),
            "ipfp": IPFPStepper, "ga": GAStepper, "pf": PFStepper}


def planted(n_in, rng, *, deformation=0.0, out1=0, out2=0, edges="full"):
    """Points, a rotated + permuted + deformed copy, outliers; truth[i] = node of g2 (or -1)."""
    P = rng.random((n_in, 2))
    th = rng.uniform(0, 2 * np.pi)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    Q = P @ R.T + deformation * rng.standard_normal(P.shape)
    P1 = np.vstack([P, rng.random((out1, 2))])
    Q2 = np.vstack([Q, rng.random((out2, 2)) @ R.T])
    perm = rng.permutation(n_in + out2)            # node u of g2 is point perm[u] of Q2
    inv = np.argsort(perm)
    truth = np.full(n_in + out1, -1)
    truth[:n_in] = inv[:n_in]
    g1 = Graph.from_points(P1, edges=edges)
    g2 = Graph.from_points(Q2[perm], edges=edges)
    return g1, g2, truth


@pytest.fixture
def rng():
    return np.random.default_rng(20240601)


# ------------------------------------------------------------------ planted solutions
@pytest.mark.parametrize("method", list(QAP))
def test_planted_zero_noise_full_accuracy(method, rng):
    for _ in range(2):
        g1, g2, truth = planted(12, rng)
        res = QAP[method](gaussian_edge_affinity(g1, g2))
        assert isinstance(res, MatchingResult)
        assert res.method == method.split("-")[0]
        assert accuracy(res.assignment, truth) == 1.0
        assert res.converged


@pytest.mark.parametrize("method", list(QAP))
def test_planted_through_match_graphs_and_dense_k(method, rng):
    g1, g2, truth = planted(7, rng)
    K = gaussian_edge_affinity(g1, g2, backend="dense").to_dense()
    name, opts = ("rrwm", {"variant": "pygmtools"}) if method == "rrwm-pygmtools" else (method, {})
    a = match_graphs(g1, g2, method=name, **opts)
    b = match_graphs(g1, g2, method=name, affinity=K, **opts)
    c = QAP[method](K, n1=7, n2=7)
    for res in (a, b, c):
        assert accuracy(res.assignment, truth) == 1.0
    np.testing.assert_allclose(a.objective, c.objective, rtol=1e-8)


@pytest.mark.parametrize("method", ["rrwm", "rrwm-pygmtools", "ipfp", "ga", "pf"])
def test_unequal_sizes_outliers_in_second_graph(method, rng):
    g1, g2, truth = planted(9, rng, out2=4)
    res = QAP[method](gaussian_edge_affinity(g1, g2))
    assert res.assignment.shape == (9,)
    assert np.all(res.assignment >= 0)
    assert np.unique(res.assignment).size == 9
    # IPFP and GA are local methods: outliers can trap them in a worse optimum; pygmtools' RRWM
    # normalises without a slack column, so the outlier columns keep full mass in its jumps
    floor = {"ipfp": 0.4, "ga": 0.4, "rrwm-pygmtools": 0.75}.get(method, 1.0)
    assert accuracy(res.assignment, truth) >= floor


@pytest.mark.parametrize("method", list(QAP))
def test_unequal_sizes_more_nodes_in_first_graph(method, rng):
    g1, g2, truth = planted(8, rng, out1=3)
    res = QAP[method](gaussian_edge_affinity(g1, g2))
    assert res.assignment.shape == (11,)
    assert np.count_nonzero(res.assignment == -1) == 3
    matched = res.assignment[res.assignment >= 0]
    assert np.unique(matched).size == 8
    assert res.to_matrix().shape == (11, 8)
    if method != "sm":
        assert accuracy(res.assignment, truth) >= 0.75


@pytest.mark.parametrize("method", ["rrwm", "rrwm-pygmtools", "ga"])
def test_outliers_in_both_graphs(method, rng):
    # outliers drawn like the inliers make full-graph problems genuinely ambiguous; chance is ~1/12
    accs = []
    for _ in range(3):
        g1, g2, truth = planted(10, rng, out1=2, out2=2)
        res = _quiet(QAP[method], gaussian_edge_affinity(g1, g2))
        assert res.assignment.shape == (12,) and np.all(res.assignment >= 0)
        accs.append(accuracy(res.assignment, truth))
    assert np.mean(accs) >= 0.5


# ------------------------------------------------------------------ invariants
@pytest.mark.parametrize("method", list(QAP))
def test_relabelling_equivariance(method, rng):
    g1, g2, _ = planted(9, rng, deformation=0.03)
    s1, s2 = rng.permutation(9), rng.permutation(9)
    res = QAP[method](gaussian_edge_affinity(g1, g2))
    res2 = QAP[method](gaussian_edge_affinity(g1.permute(s1), g2.permute(s2)))
    # node u of g1' is node s1[u] of g1, node v of g2' is node s2[v] of g2
    expected = np.argsort(s2)[res.assignment[s1]]
    np.testing.assert_array_equal(res2.assignment, expected)
    np.testing.assert_allclose(res2.objective, res.objective, rtol=1e-9)


def _brute_force(K, n):
    best, arg = -np.inf, None
    for p in itertools.permutations(range(n)):
        X = np.zeros((n, n))
        X[np.arange(n), p] = 1
        x = X.ravel(order="F")
        v = x @ K @ x
        if v > best:
            best, arg = v, np.array(p)
    return best, arg


@pytest.mark.parametrize("n", [4, 6])
def test_exhaustive_qap_optimum(n, rng):
    for trial in range(2):
        g1, g2, _ = planted(n, rng, deformation=0.01)
        K = gaussian_edge_affinity(g1, g2, backend="dense").to_dense()
        opt, _ = _brute_force(K, n)
        for name, solver in QAP.items():
            res = solver(K, n1=n, n2=n)
            assert res.objective <= opt * (1 + 1e-12), name
            np.testing.assert_allclose(res.objective, opt, rtol=1e-10, err_msg=name)
        # random (hard) affinities: never above the optimum, objective consistent with K
        Kr = rng.random((n * n, n * n))
        Kr = Kr + Kr.T
        opt_r, _ = _brute_force(Kr, n)
        for name, solver in QAP.items():
            res = _quiet(solver, Kr, n1=n, n2=n)
            X = res.to_matrix().ravel(order="F")
            np.testing.assert_allclose(res.objective, X @ Kr @ X, rtol=1e-10)
            assert res.objective <= opt_r * (1 + 1e-12), name


def _quiet(solver, *args, **kwargs):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return solver(*args, **kwargs)


# ------------------------------------------------------------------ linear solvers
def test_hungarian_score_matrix_and_affinity(rng):
    S = rng.random((5, 7))
    res = hungarian(S)
    assert res.soft is None and res.n_iter == 0 and res.converged
    best = max(sum(S[i, p[i]] for i in range(5)) for p in itertools.permutations(range(7), 5))
    np.testing.assert_allclose(res.objective, best)
    np.testing.assert_array_equal(hungarian(-S, maximize=False).assignment, res.assignment)
    # an affinity uses its diagonal (node term)
    g1, g2, _ = planted(4, rng)
    node = rng.random((4, 4))
    aff = gaussian_edge_affinity(g1, g2, node_affinity=node)
    np.testing.assert_array_equal(hungarian(aff).assignment, hungarian(node).assignment)
    K = aff.to_dense()
    np.testing.assert_array_equal(hungarian(K, n1=4, n2=4).assignment, hungarian(node).assignment)


@pytest.mark.parametrize("shape", [(5, 5), (4, 7), (7, 4)])
def test_sinkhorn_marginals_and_rounding(shape, rng):
    S = rng.random(shape)
    res = sinkhorn(S, tau=0.05)
    X = res.soft
    small, large = (1, 0) if shape[0] <= shape[1] else (0, 1)
    np.testing.assert_allclose(X.sum(small), 1.0, atol=1e-6)
    assert np.all(X.sum(large) <= 1.0 + 1e-5)
    np.testing.assert_allclose(X.sum(), min(shape), rtol=1e-5)
    np.testing.assert_array_equal(res.assignment, hungarian(S).assignment)
    # huge scores do not overflow in the log domain (convergence is slow there: not asserted)
    res_big = _quiet(sinkhorn, 1e4 * S, tau=1.0, max_iter=50)
    assert np.all(np.isfinite(res_big.soft))


def test_sinkhorn_nonconvergence_warns(rng):
    with pytest.warns(ConvergenceWarning, match="sinkhorn"):
        res = sinkhorn(rng.random((6, 6)), tau=0.01, max_iter=1, tol=1e-12)
    assert not res.converged


def test_match_graphs_linear_methods(rng):
    g1, g2, truth = planted(6, rng)
    feats = rng.random((6, 3))
    h1 = Graph(g1.adjacency, points=g1.points, node_features=feats)
    h2 = Graph(g2.adjacency, points=g2.points, node_features=feats[np.argsort(truth)])
    for method in ("hungarian", "sinkhorn"):
        res = match_graphs(h1, h2, method=method)
        np.testing.assert_array_equal(res.assignment, truth)
    with pytest.raises(ValueError, match="needs a unary term"):
        match_graphs(g1, g2, method="hungarian")


# ------------------------------------------------------------------ step-wise protocol
@pytest.mark.parametrize("method", list(STEPPERS))
def test_stepper_protocol_matches_function(method, rng):
    g1, g2, _ = planted(8, rng, deformation=0.02)
    aff = gaussian_edge_affinity(g1, g2)
    st = STEPPERS[method](aff)
    assert isinstance(st, Stepper)
    while not st.done:
        assert st.step() == st.done
    res = st.result()
    ref = QAP[method](aff)
    np.testing.assert_array_equal(res.assignment, ref.assignment)
    assert res.n_iter == ref.n_iter
    assert st.step() is True            # no-op once done


@pytest.mark.parametrize("method", ["rrwm", "ga", "pf"])
def test_stepper_iterate_is_doubly_stochastic(method, rng):
    for out2 in (0, 3):
        g1, g2, _ = planted(7, rng, deformation=0.02, out2=out2)
        st = STEPPERS[method](gaussian_edge_affinity(g1, g2))
        for _ in range(3):
            st.step()
        X = st.iterate
        assert X.shape == (7, 7 + out2) and X.min() >= 0
        # RRWM's inner Sinkhorn stops at row error 1e-3; GA's at an L1 change of 0.05
        atol = {"rrwm": 2e-3, "ga": 5e-2, "pf": 1e-9}[method]
        if method == "ga":      # slack row and column: sub-doubly-stochastic
            assert np.all(X.sum(1) <= 1 + atol) and np.all(X.sum(0) <= 1 + atol)
        else:
            np.testing.assert_allclose(X.sum(1), 1.0, atol=atol)
            assert np.all(X.sum(0) <= 1 + atol)


@pytest.mark.parametrize("method", list(STEPPERS))
def test_set_iterate_to_truth_keeps_truth(method, rng):
    g1, g2, truth = planted(8, rng, deformation=0.02)
    st = STEPPERS[method](gaussian_edge_affinity(g1, g2))
    st.step()
    T = np.zeros((8, 8))
    T[np.arange(8), truth] = 1.0
    st.set_iterate(0.9 * T + 0.1 / 8)
    assert not st.converged
    np.testing.assert_allclose(st.iterate.sum(), 8.0, rtol=1e-12)
    while not st.done:
        st.step()
    assert accuracy(st.result().assignment, truth) == 1.0
    with pytest.raises(ValueError, match="`X` must have shape"):
        st.set_iterate(np.ones((3, 3)))
    with pytest.raises(ValueError, match="non-negative"):
        st.set_iterate(-np.ones((8, 8)))


# ------------------------------------------------------------------ non-convergence
@pytest.mark.parametrize("method,kwargs", [("sm", {"max_iter": 1}), ("rrwm", {"max_iter": 2}),
                                           ("ipfp", {"max_iter": 1}),
                                           ("pf", {"max_iter": 2})])
def test_nonconvergence_warns(method, kwargs, rng):
    g1, g2, _ = planted(8, rng, deformation=0.05)
    with pytest.warns(ConvergenceWarning, match=method):
        res = QAP[method](gaussian_edge_affinity(g1, g2), **kwargs)
    assert res.converged is False


# ------------------------------------------------------------------ validation
def test_validation_errors(rng):
    g1, g2, _ = planted(4, rng)
    K = gaussian_edge_affinity(g1, g2, backend="dense").to_dense()
    for solver in QAP.values():
        with pytest.raises(TypeError, match="`n1` and `n2` are required"):
            solver(K)
        with pytest.raises(ValueError, match=r"must have shape \(n1\*n2, n1\*n2\) = \(12, 12\)"):
            solver(K, n1=3, n2=4)
        bad = K.copy()
        bad[0, 1] = np.nan
        with pytest.raises(ValueError, match="`K` must be finite"):
            solver(bad, n1=4, n2=4)
        bad[0, 1] = -1.0
        with pytest.raises(ValueError, match="`K` must be non-negative"):
            solver(bad, n1=4, n2=4)
        with pytest.raises(ValueError, match="`n1` must be >= 1"):
            solver(np.zeros((0, 0)), n1=0, n2=4)
    with pytest.raises(ValueError, match="`max_iter` must be >= 1, got 0"):
        rrwm(K, n1=4, n2=4, max_iter=0)
    with pytest.raises(ValueError, match="`tol` must be finite and > 0"):
        sm(K, n1=4, n2=4, tol=-1.0)
    with pytest.raises(TypeError, match="`max_iter` must be an int"):
        ipfp(K, n1=4, n2=4, max_iter=2.5)
    with pytest.raises(ValueError, match="`c` must lie in"):
        rrwm(K, n1=4, n2=4, c=1.5)
    with pytest.raises(ValueError, match="`variant` must be one of 'original', 'pygmtools'"):
        rrwm(K, n1=4, n2=4, variant="matlab")
    with pytest.raises(ValueError, match="`sinkhorn_tol` is not used by variant='pygmtools'"):
        rrwm(K, n1=4, n2=4, variant="pygmtools", sinkhorn_tol=1e-3)
    with pytest.raises(ValueError, match="`warm_start` is not used by variant='pygmtools'"):
        rrwm(K, n1=4, n2=4, variant="pygmtools", warm_start=True)
    with pytest.raises(TypeError, match="`warm_start` must be a bool or None, got int 1"):
        rrwm(K, n1=4, n2=4, warm_start=1)
    assert rrwm(K, n1=4, n2=4, variant="pygmtools", warm_start=False).info["warm_start"] is False
    with pytest.raises(ValueError, match="`init` must be one of"):
        ipfp(K, n1=4, n2=4, init="random")
    with pytest.raises(ValueError, match="`beta_rate` must be > 1"):
        ga(K, n1=4, n2=4, beta_rate=1.0)
    with pytest.raises(ValueError, match=r"`beta_rate`=1.000000001 anneals .* more than 10000"):
        ga(K, n1=4, n2=4, beta_rate=1 + 1e-9)                 # ~3e9 levels: refused, no hang
    # a huge beta_max over a tiny beta0: the ratio overflowed (raw OverflowError from int(inf))
    with pytest.raises(ValueError, match=r"`beta_rate`=1.075 anneals from beta0=1e-300 to "
                                         r"beta_max=1e\+100 in 1.27\d+e\+04 levels"):
        ga(K, n1=4, n2=4, beta0=1e-300, beta_max=1e100)
    # beta times the gradient overflowed beyond 1e100 (NaN iterate, an error naming `score`)
    with pytest.raises(ValueError, match=r"`beta_max` must be <= 1e\+100 .* got 1e\+300"):
        ga(K, n1=4, n2=4, beta_max=1e300, beta_rate=10.0)
    with pytest.raises(ValueError, match=r"`max_inner` must be <= 1000000"):
        ga(K, n1=4, n2=4, max_inner=10**12)                   # ran for minutes
    with pytest.raises(ValueError, match="`min_step` must be <="):
        pf(K, n1=4, n2=4, step=0.01, min_step=0.1)
    with pytest.raises(ValueError, match="`method` must be one of"):
        match_graphs(g1, g2, method="magic")
    with pytest.raises(TypeError, match="`g1` and `g2` must be Graph"):
        match_graphs(np.eye(3), g2)
    with pytest.raises(ValueError, match=r"`affinity` must have shape \(n1\*n2, n1\*n2\)"):
        match_graphs(g1, g2, affinity=np.ones((9, 9)))
    with pytest.raises(ValueError, match="but n1=4, n2=5"):
        sm(gaussian_edge_affinity(g1, g2), n1=4, n2=5)
    with pytest.raises(ValueError, match="`scores` must be non-empty"):
        hungarian(np.zeros((0, 3)))
    with pytest.raises(ValueError, match="`scores` must be finite"):
        hungarian(np.array([[np.inf, 0.0]]))
    with pytest.raises(ValueError, match="`scores` must have 2 dimensions"):
        sinkhorn(np.ones(3))
    with pytest.raises(ValueError, match="`tau` must be finite and > 0"):
        sinkhorn(np.ones((2, 2)), tau=0.0)
    with pytest.raises(ValueError, match="`scores` must have shape"):
        hungarian(np.ones((2, 3)), n1=3, n2=3)
    with pytest.raises(ValueError, match="empty graph|non-empty"):
        Graph(np.zeros((0, 0)))


def test_result_is_frozen_and_to_matrix(rng):
    res = hungarian(rng.random((3, 4)))
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.objective = 0.0
    X = res.to_matrix()
    assert X.shape == (3, 4) and X.sum() == 3
    assert "hungarian" in repr(res)


# ------------------------------------------------------------------ defaults written once
_PUBLIC = [hungarian, sinkhorn, sm, rrwm, ipfp, ga, pf, match_graphs]


@pytest.mark.parametrize("func", _PUBLIC, ids=lambda f: f.__name__)
def test_docstring_defaults_match_signature(func):
    doc = inspect.getdoc(func)
    documented = dict(re.findall(r"^(\w+) : [^\n]*default=([^\n]+)$", doc, flags=re.M))
    sig = inspect.signature(func)
    for name, param in sig.parameters.items():
        if param.default is inspect.Parameter.empty or param.kind is param.VAR_KEYWORD:
            continue
        if param.default is None:
            continue
        assert name in documented, f"{func.__name__}: `{name}` default undocumented"
        text = documented[name].strip().strip('"')
        if isinstance(param.default, (int, float)) and not isinstance(param.default, bool):
            assert float(text) == float(param.default), (func.__name__, name, text)
        else:
            assert text == str(param.default), (func.__name__, name, text, param.default)


@pytest.mark.parametrize("shape", [(5, 5), (4, 7), (7, 4)])
def test_rrwm_pygmtools_sinkhorn_half_sweeps(shape, rng):
    from scipy.special import logsumexp

    from transync.matching._rrwm import _sinkhorn_half_sweeps

    for spread in (30.0, 2000.0):          # scaling-domain and log-domain branches
        S = spread * rng.random(shape)
        L = S.T if shape[0] > shape[1] else S
        for i in range(7):                 # pygmtools: smaller side first, alternate
            L = L - logsumexp(L, axis=1 if i % 2 == 0 else 0, keepdims=True)
        ref = np.exp(L.T if shape[0] > shape[1] else L)
        X = _sinkhorn_half_sweeps(S, 7)
        np.testing.assert_allclose(X, ref, rtol=1e-9, atol=1e-300)
        small_axis = 1 if shape[0] <= shape[1] else 0     # the last (7th) sweep normalised it
        np.testing.assert_allclose(X.sum(axis=small_axis), 1.0, rtol=1e-12)


def test_ga_default_final_temperature_grows_beyond_ten_nodes():
    from transync.datasets import make_graph_collection

    assert default_beta_max(5, 8) == 10.0 and default_beta_max(10, 10) == 10.0
    assert default_beta_max(30, 12) == 30.0 and default_beta_max(12, 30) == 30.0
    # 30-node complete graphs, deformation 0.1: the original final temperature 10 ends with a
    # soft matrix whose rounding misses (0.80 on 12 such pairs); the size-scaled default is exact
    for seed in (700, 701, 702):
        p = make_graph_collection(2, 30, 0, 0.1, 1.0, shuffle=True, rng=seed)
        aff = gaussian_edge_affinity(*p.graphs, sigma2=0.05)
        truth = p.ground_truth.pairwise(0, 1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = ga(aff)
        assert accuracy(res.assignment, truth) == 1.0


def test_ga_on_graphs_of_different_sizes_finds_the_best_node_whatever_the_order():
    """One node against five, a diagonal K (unary scores only): the optimum is the best-scored
    node. With Gold & Rangarajan's 30 slack-Sinkhorn sweeps the slack faded, the sweeps
    stopped with a row sum of 2.04 and every column near 1, and the rounding picked by node
    order ([1], and [2] after relabelling graph 2; metamorphic test). Different sizes now get
    a budget that converges (RECT_SINKHORN)."""
    from transync.matching import GAStepper, ga

    d = np.array([0.2, 0.75, 0.98, 0.5, 0.3])
    for perm in ([0, 1, 2, 3, 4], [2, 0, 1, 3, 4], [4, 3, 2, 1, 0]):
        perm = np.array(perm)
        res = ga(np.diag(d[perm]), n1=1, n2=5)
        assert perm[res.assignment].tolist() == [2]
        assert res.soft.sum() <= 1.05
    rect = GAStepper(np.eye(2), n1=1, n2=2)
    assert (rect.sinkhorn_max_iter, rect.sinkhorn_tol) == (100, 1e-3)
    # equal sizes keep Gold & Rangarajan's values (the lock-step solvers read their defaults
    # from a 1 x 1 stepper and pad every pair to one size)
    square = GAStepper(np.eye(1), n1=1, n2=1)
    assert (square.sinkhorn_max_iter, square.sinkhorn_tol) == (30, 0.05)


def test_sm_maximizes_the_quadratic_form_on_directed_graphs():
    # reversing every edge of two directed graphs turns K into K^T and changes no x^T K x; sm
    # iterated K itself and gave different maps for K and K^T, its eigenvector short of the
    # maximum of x^T K x on the unit sphere (3.05 vs 2.79 here)
    rng = np.random.default_rng(5)
    n = 6
    P1 = rng.random((n, 2))
    P2 = P1 + 0.05 * rng.standard_normal((n, 2))
    M1 = rng.random((n, n)) < 0.5
    M2 = rng.random((n, n)) < 0.5
    np.fill_diagonal(M1, False)
    np.fill_diagonal(M2, False)
    K = gaussian_edge_affinity(Graph(M1.astype(float), points=P1, directed=True),
                               Graph(M2.astype(float), points=P2, directed=True),
                               backend="dense").to_dense()
    assert not np.allclose(K, K.T)
    a, b = sm(K, n1=n, n2=n), sm(K.T, n1=n, n2=n)
    np.testing.assert_array_equal(a.assignment, b.assignment)
    top = np.linalg.eigvalsh(0.5 * (K + K.T))[-1]
    x = a.soft.ravel(order="F")
    np.testing.assert_allclose(x @ K @ x / (x @ x), top, rtol=1e-6)
