"""The one Sinkhorn of the matching layer (issue 9): every former copy reproduced bit for bit.

The reference functions below are the four Sinkhorn loops that lived in ``_linear``, ``_rrwm`` and
``_ga`` before the consolidation, copied verbatim; the shared implementation must give exactly the
same floating-point results for the domain/slack/stop options each caller now uses.
"""

from __future__ import annotations

import functools
import pickle
import warnings

import numpy as np
import pytest
from scipy.special import logsumexp

from transync.datasets import make_point_matching_problem
from transync.graphs import Graph
from transync.matching import RRWMStepper, ga, gaussian_edge_affinity, ipfp, pf, rrwm, sm
from transync.matching._sinkhorn import sinkhorn_normalize

# --------------------------------------------------------------------------- former copies


def ref_log_sinkhorn(S, tau, max_iter, tol):
    """``matching.sinkhorn``'s loop before issue 9."""
    transposed = S.shape[0] > S.shape[1]
    L = (S.T if transposed else S) / tau
    r, c = L.shape
    slack = float(c - r)
    g = np.zeros(c)
    f = -logsumexp(L + g, axis=1)
    f_slack = np.log(slack) - logsumexp(g) if slack else -np.inf
    err = np.inf
    n_iter = 0
    for n_iter in range(1, max_iter + 1):
        g = -np.logaddexp(logsumexp(L + f[:, None], axis=0), f_slack)
        lse = logsumexp(L + g, axis=1)
        err = float(np.max(np.abs(np.exp(f + lse) - 1.0)))
        f = -lse
        f_slack = np.log(slack) - logsumexp(g) if slack else -np.inf
        if err < tol:
            break
    X = np.exp(f[:, None] + L + g[None, :])
    return (X.T if transposed else X), n_iter, err, err < tol


def ref_sinkhorn_scaling(A, *, tol, max_iter):
    """``_linear._sinkhorn_scaling`` (RRWM original) before issue 9."""
    transposed = A.shape[0] > A.shape[1]
    if transposed:
        A = A.T
    r, c = A.shape
    slack = float(c - r)
    v = np.ones(c)
    u = None
    it = 0
    converged = False
    for it in range(1, max_iter + 1):
        Av = A @ v
        if u is not None and it % 4 == 0 and np.max(np.abs(u * Av - 1.0)) < tol:
            converged = True
            break
        u = 1.0 / Av
        w = slack / v.sum()
        v = 1.0 / (u @ A + w)
    else:
        u = 1.0 / (A @ v)
    X = (u[:, None] * A) * v[None, :]
    return (X.T if transposed else X), it, converged


def ref_half_sweeps_scaling(S, half_sweeps):
    """``_rrwm._sinkhorn_half_sweeps`` (scaling branch) before issue 9."""
    transposed = S.shape[0] > S.shape[1]
    L = S.T if transposed else S
    A = np.exp(L - L.max())
    u = np.ones(A.shape[0])
    v = np.ones(A.shape[1])
    for i in range(half_sweeps):
        if i % 2 == 0:
            u = 1.0 / (A @ v)
        else:
            v = 1.0 / (u @ A)
    X = (u[:, None] * A) * v[None, :]
    return X.T if transposed else X


def ref_slack_sinkhorn(M, *, max_iter, tol):
    """``_ga._slack_sinkhorn`` before issue 9."""
    n1, n2 = M.shape[0] - 1, M.shape[1] - 1
    for _ in range(max_iter):
        old = M[:n1, :n2].copy()
        M[:n1] /= M[:n1].sum(1, keepdims=True)
        M[:, :n2] /= M[:, :n2].sum(0, keepdims=True)
        if np.abs(M[:n1, :n2] - old).sum() < tol:
            break
    return M


SHAPES = [(6, 6), (4, 9), (9, 4), (1, 5), (5, 1)]


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("max_iter, tol", [(1000, 1e-6), (3, 1e-9), (50, 1e-12)])
def test_log_domain_is_the_former_public_sinkhorn(shape, max_iter, tol, rng):
    S = rng.random(shape)
    X0, n0, e0, c0 = ref_log_sinkhorn(S, 0.05, max_iter, tol)
    out = sinkhorn_normalize(S / 0.05, domain="log", slack="mass", tol=tol, max_iter=max_iter)
    assert np.array_equal(out.X, X0)
    assert (out.n_sweeps, out.error, out.converged) == (n0, e0, c0)


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("max_iter, tol", [(1000, 1e-3), (7, 1e-3), (3, 0.5), (11, 1e-14)])
def test_scaling_domain_is_the_former_rrwm_sinkhorn(shape, max_iter, tol, rng):
    x = rng.random(shape)
    A = np.exp(30.0 * x / x.max())
    X0, it0, c0 = ref_sinkhorn_scaling(A, tol=tol, max_iter=max_iter)
    out = sinkhorn_normalize(A, domain="scaling", slack="mass", tol=tol, max_iter=max_iter,
                             check_every=4)
    assert np.array_equal(out.X, X0)
    assert out.converged == c0
    assert out.n_sweeps + int(out.converged) == it0


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("half_sweeps", [1, 2, 7, 20])
def test_fixed_half_sweeps_are_the_former_pygmtools_sinkhorn(shape, half_sweeps, rng):
    S = 30.0 * rng.random(shape)
    out = sinkhorn_normalize(np.exp(S - S.max()), domain="scaling", slack="none",
                             half_sweeps=half_sweeps)
    assert np.array_equal(out.X, ref_half_sweeps_scaling(S, half_sweeps))
    # the log domain computes the same normalisations (to rounding)
    L = sinkhorn_normalize(S, domain="log", slack="none", half_sweeps=half_sweeps).X
    np.testing.assert_allclose(L, out.X, rtol=1e-10, atol=1e-300)


@pytest.mark.parametrize("shape", [(5, 5), (3, 8), (8, 3)])
@pytest.mark.parametrize("max_iter, tol", [(30, 0.05), (2, 1e-9), (200, 1e-12)])
def test_augmented_domain_is_the_former_ga_sinkhorn(shape, max_iter, tol, rng):
    M0 = rng.random((shape[0] + 1, shape[1] + 1)) + 1e-3
    M_ref = ref_slack_sinkhorn(M0.copy(), max_iter=max_iter, tol=tol)
    M = M0.copy()
    out = sinkhorn_normalize(M, domain="augmented", slack="augmented", tol=tol, max_iter=max_iter)
    assert out.X is M                      # in place, as GA relies on
    assert np.array_equal(M, M_ref)


@pytest.mark.parametrize("shape", SHAPES)
def test_slack_marginals_log_and_scaling_agree(shape, rng):
    S = rng.random(shape)
    lo = sinkhorn_normalize(S / 0.2, domain="log", slack="mass", tol=1e-12, max_iter=5000)
    sc = sinkhorn_normalize(np.exp(S / 0.2), domain="scaling", slack="mass", tol=1e-12,
                            max_iter=5000)
    assert lo.converged and sc.converged
    np.testing.assert_allclose(lo.X, sc.X, atol=1e-10)
    small, large = (1, 0) if shape[0] <= shape[1] else (0, 1)
    np.testing.assert_allclose(lo.X.sum(axis=small), 1.0, atol=1e-10)   # smaller side stochastic
    assert np.all(lo.X.sum(axis=large) <= 1.0 + 1e-10)                  # larger sub-stochastic
    np.testing.assert_allclose(lo.X.sum(), min(shape), rtol=1e-10)


def test_sinkhorn_normalize_option_errors():
    with pytest.raises(ValueError, match="`slack='augmented'` goes with `domain='augmented'`"):
        sinkhorn_normalize(np.ones((3, 3)), domain="log", slack="augmented")
    with pytest.raises(ValueError, match="`domain` must be one of"):
        sinkhorn_normalize(np.ones((3, 3)), domain="cubic", slack="mass")


# --------------------------------------------------------------------------- RRWM variants


def _aff(rng, n=8):
    g1 = Graph.from_points(rng.random((n, 2)), edges="full")
    return gaussian_edge_affinity(g1, g1.permute(rng.permutation(n)))


@pytest.mark.parametrize("variant", ["original", "pygmtools"])
def test_rrwm_stepper_is_one_class_per_variant(variant, rng):
    st = RRWMStepper(_aff(rng), variant=variant)
    assert isinstance(st, RRWMStepper) and type(st) is not RRWMStepper
    assert st.variant == variant
    while not st.done:
        st.step()
    clone = pickle.loads(pickle.dumps(st))
    assert type(clone) is type(st)
    np.testing.assert_array_equal(clone.result().assignment, st.result().assignment)
    assert st.result().info["variant"] == variant


def test_rrwm_stepper_unknown_variant(rng):
    with pytest.raises(ValueError, match="`variant` must be one of 'original', 'pygmtools', "
                                         "got 'matlab'"):
        RRWMStepper(_aff(rng), variant="matlab")
    with pytest.raises(ValueError, match="`sinkhorn_tol` is not used by variant='pygmtools'"):
        rrwm(_aff(rng), variant="pygmtools", sinkhorn_tol=1e-3)


# --------------------------------------------------------------------------- regression
# Assignments and objectives recorded before the consolidation (issue 9) on problems where the
# solvers disagree: fully connected point sets with deformation 0.05 and outliers.
# (GA with the final temperature of that time: its default now grows beyond 10 nodes)
QAP = {"sm": sm, "rrwm": rrwm, "rrwm-pygmtools": functools.partial(rrwm, variant="pygmtools"),
       "ipfp": ipfp, "ga": functools.partial(ga, beta_max=10.0), "pf": pf}
RECORDED = [
    {"sm": ([11, 0, 5, 10, 2, 6, 7, 4, 1, 8, 14, 3, 12, 9, 13], 168.286164948),
     "rrwm": ([11, 12, 9, 10, 1, 0, 13, 4, 5, 8, 6, 3, 14, 2, 7], 176.484395419),
     "rrwm-pygmtools": ([8, 12, 9, 10, 1, 2, 13, 4, 5, 7, 6, 11, 14, 3, 0], 177.375027986),
     "ipfp": ([11, 12, 9, 10, 6, 2, 13, 4, 5, 8, 1, 3, 14, 0, 7], 175.063877774),
     "ga": ([8, 12, 9, 10, 1, 2, 7, 4, 5, 13, 6, 11, 0, 3, 14], 174.730634814),
     "pf": ([11, 12, 9, 5, 1, 14, 7, 4, 10, 8, 6, 3, 0, 2, 13], 176.239392368)},
    {"sm": ([-1, 6, 7, -1, 8, 2, 0, 3, 4, 10, 11, 12, 5, -1, 1, 9], 117.689499817),
     "rrwm": ([8, 10, 9, 2, 1, 6, 7, -1, 4, -1, 11, 12, 5, 3, -1, 0], 132.20450842),
     "rrwm-pygmtools": ([8, 10, 9, 2, -1, 6, 7, -1, 4, -1, 11, 12, 5, 3, 1, 0], 129.213176582),
     "ipfp": ([2, 10, 9, -1, 8, -1, 7, 3, 4, -1, 11, 12, 5, 6, 1, 0], 130.538468767),
     "ga": ([2, -1, 9, -1, 8, -1, 0, 6, 4, 10, 11, 12, 5, 3, 1, 7], 125.955832179),
     "pf": ([2, 10, 9, -1, 1, 6, 7, 3, 4, -1, 11, 12, 5, 8, -1, 0], 133.42054845)},
]


@pytest.mark.parametrize("case", [0, 1])
@pytest.mark.parametrize("method", list(QAP))
def test_assignments_unchanged_by_consolidation(case, method):
    n_in, n_out, rect = [(10, 5, False), (12, 4, True)][case]
    p = make_point_matching_problem(n_in, n_out, 0.05, edges="full", rng=100 + case)
    g2 = p.g2 if not rect else Graph.from_points(p.g2.points[:-3], edges="full")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = QAP[method](gaussian_edge_affinity(p.g1, g2))
    assignment, objective = RECORDED[case][method]
    assert res.assignment.tolist() == assignment
    assert res.objective == pytest.approx(objective, abs=1e-8)


@pytest.mark.parametrize("kwargs, exc, match", [
    ({"half_sweeps": 0}, ValueError, "half_sweeps"),
    ({"slack": "bogus"}, ValueError, "slack"),
    ({"domain": "augmented"}, ValueError, "domain"),
    ({"tol": -1.0}, ValueError, "tol"),
    ({"warm_start": np.ones((2, 2))}, ValueError, "warm_start"),
    ({"warm_start": np.zeros((2, 3))}, ValueError, "warm_start"),
    ({"warm_start": np.ones((2, 3)), "domain": "log"}, ValueError, "warm_start"),
    ({"warm_start": "ones"}, TypeError, "warm_start"),
])
def test_sinkhorn_batch_refuses_bad_options(kwargs, exc, match):
    from transync.matching import sinkhorn_batch

    with pytest.raises(exc, match=match):
        sinkhorn_batch(np.ones((2, 3, 3)), **kwargs)


def test_sinkhorn_batch_refuses_kernels_it_cannot_normalise():
    from transync.matching import sinkhorn_augmented_batch, sinkhorn_batch

    with pytest.raises(ValueError, match="all-zero row or column"):
        sinkhorn_batch(np.zeros((1, 2, 2)), slack="none", tol=1e-6)
    with pytest.raises(ValueError, match="non-negative"):
        sinkhorn_batch(-np.ones((1, 2, 2)))
    with pytest.raises(ValueError, match="shape"):
        sinkhorn_batch(np.ones((2, 2)))
    with pytest.raises(ValueError, match="writable float ndarray"):
        sinkhorn_augmented_batch(np.ones((2, 3)), tol=1e-3, max_iter=10)
    # one non-finite entry anywhere, in either domain: named, with how many
    for bad in (np.nan, np.inf, -np.inf):
        for domain in ("scaling", "log"):
            A = np.ones((3, 4, 4))
            A[2, 1, 3] = bad
            with pytest.raises(ValueError, match=r"`A` must be finite, got 1 NaN or infinite"):
                sinkhorn_batch(A, domain=domain)
        M = np.ones((2, 3, 3))
        M[1, 0, 1] = bad
        with pytest.raises(ValueError, match="`M` must be finite and non-negative"):
            sinkhorn_augmented_batch(M, tol=1e-3, max_iter=10)


def test_sinkhorn_batch_refuses_kernels_whose_sums_overflow():
    from transync.matching import sinkhorn_augmented_batch, sinkhorn_batch

    # a row sum of two entries of 1e308 is inf: the result was all NaN, with no error
    with pytest.raises(ValueError, match=r"`A` has an entry 1e\+308.*overflow"):
        sinkhorn_batch(np.full((1, 2, 2), 1e308), tol=1e-9)
    with pytest.raises(ValueError, match=r"`M` has an entry 1e\+308.*overflow"):
        sinkhorn_augmented_batch(np.full((1, 3, 3), 1e308), tol=1e-9, max_iter=20)
    # large but safe: the same result as the kernel scaled down
    A = np.random.default_rng(0).random((3, 4, 5)) + 0.1
    big = sinkhorn_batch(A * 1e295, tol=1e-12).X
    assert np.all(np.isfinite(big))
    np.testing.assert_allclose(big, sinkhorn_batch(A, tol=1e-12).X, rtol=1e-9)


@pytest.mark.parametrize("which, exc, match", [
    ([2], ValueError, r"`which` must hold indices in \[0, 2\).*got 2"),
    ([-1], ValueError, r"`which` must hold indices in \[0, 2\).*got -1"),
    ([True], ValueError, r"`which` as a boolean mask must have shape \(2,\)"),
    ([0.0], TypeError, "`which` must hold matrix indices"),
    ("0", TypeError, "`which`"),
    ([[0]], ValueError, "`which` must have 1 dimensions"),
])
def test_sinkhorn_augmented_batch_checks_which(which, exc, match):
    from transync.matching import sinkhorn_augmented_batch

    M = np.ones((2, 3, 3))
    with pytest.raises(exc, match=match):
        sinkhorn_augmented_batch(M, tol=1e-9, max_iter=5, which=which)
    assert np.all(M == 1.0)                     # refused before any work


def test_sinkhorn_augmented_batch_which_as_indices_or_mask():
    from transync.matching import sinkhorn_augmented_batch

    base = np.random.default_rng(1).random((3, 4, 4)) + 0.1
    full = base.copy()
    sinkhorn_augmented_batch(full, tol=1e-9, max_iter=50)
    for which in ([0, 2], np.array([True, False, True])):
        M = base.copy()
        sinkhorn_augmented_batch(M, tol=1e-9, max_iter=50, which=which)
        np.testing.assert_array_equal(M[[0, 2]], full[[0, 2]])
        np.testing.assert_array_equal(M[1], base[1])


def test_sinkhorn_batch_equals_the_two_dimensional_call():
    from transync.matching import sinkhorn_batch

    A = np.random.default_rng(1).random((5, 4, 6)) + 0.05
    X, sweeps, ok, scaling = sinkhorn_batch(A, tol=1e-8, check_every=2)
    for k in range(5):
        ref = sinkhorn_normalize(A[k], domain="scaling", tol=1e-8, check_every=2)
        np.testing.assert_allclose(X[k], ref.X, atol=1e-12)
        assert sweeps[k] == ref.n_sweeps and ok[k] == ref.converged
        np.testing.assert_allclose(scaling[k], ref.col_scaling, rtol=1e-12)
    # warm-started, both orientations (the scaling is the longer side's)
    for B in (A * 1.3, np.swapaxes(A, 1, 2) * 1.3):
        V = scaling if B.shape[2] == 6 else scaling * 2.0
        out = sinkhorn_batch(B, tol=1e-8, check_every=2, warm_start=V)
        for k in range(5):
            ref = sinkhorn_normalize(B[k], domain="scaling", tol=1e-8, check_every=2,
                                     warm_start=V[k])
            np.testing.assert_allclose(out.X[k], ref.X, atol=1e-12)
            assert out.n_sweeps[k] == ref.n_sweeps and out.converged[k] == ref.converged
            assert out.n_sweeps[k] < sweeps[k]
    L = np.log(A)
    Xl, _, _, none = sinkhorn_batch(L, domain="log", half_sweeps=9)
    assert none is None
    for k in range(5):
        ref = sinkhorn_normalize(L[k], domain="log", half_sweeps=9)
        np.testing.assert_allclose(Xl[k], ref.X, atol=1e-12)
