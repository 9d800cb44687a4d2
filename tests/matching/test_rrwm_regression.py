"""RRWM's ``variant="original"``: the authors' loop kept exactly, and its warm-started default.

``ReferenceRRWM`` below is the stepper and the scaling-domain Sinkhorn as they were before the
speed work of issue 10, written out plainly (one generic half-sweep loop, fresh arrays
everywhere). On a dozen seeded problems -- complete, Delaunay, k-NN and random sparse graphs,
outliers, ``n1 != n2`` both ways, dense and sparse ``K``, non-default options, runs that stop at
``max_iter`` -- the library's stepper with ``warm_start=False`` must produce the same iterates at
every step (to 1e-12), the same number of Sinkhorn sweeps, the same stop, and the assignments
recorded before the change. With ``warm=True`` the reference carries the Sinkhorn scaling from
one step to the next and also waits for the Sinkhorn tolerance before stopping: the default
stepper must follow it step for step, and end on the authors' assignments.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from transync.datasets import make_point_matching_problem
from transync.graphs import Graph
from transync.matching import RRWMStepper, as_affinity, gaussian_edge_affinity, rrwm
from transync.matching._sinkhorn import sinkhorn_normalize
from transync.permutations import solve_lap

# --------------------------------------------------------------------------- reference


def ref_sinkhorn_scaling(A, *, tol, max_iter, check_every, v0=None):
    """Scaling-domain Sinkhorn with slack mass (``sinkhorn_normalize`` before issue 10)."""
    transposed = A.shape[0] > A.shape[1]
    K = A.T if transposed else A
    slack = float(K.shape[1] - K.shape[0])
    v = np.ones(K.shape[1]) if v0 is None else v0
    u = None
    n_half = 2 * max_iter + 1
    n_sweeps, err, converged = 0, np.inf, False
    for i in range(n_half):
        if i % 2:
            uA = u @ K
            v = 1.0 / (uA + slack / v.sum()) if slack else 1.0 / uA
            n_sweeps += 1
            continue
        Av = K @ v
        if i and (n_sweeps + 1) % check_every == 0 and i != n_half - 1:
            err = float(np.max(np.abs(u * Av - 1.0)))
            if err < tol:
                converged = True
                break
        u = 1.0 / Av
    X = (u[:, None] * K) * v[None, :]
    return (X.T if transposed else X), n_sweeps, err, converged, v


class ReferenceRRWM:
    """``_OriginalRRWMStepper`` before issue 10 (same state, same arithmetic)."""

    def __init__(self, aff, *, c=0.2, amplification=30.0, max_iter=300, tol=None,
                 sinkhorn_tol=1e-3, sinkhorn_max_iter=None, warm=False):
        self.warm, self.v, self.roundings = warm, None, []
        tol = (1e-12 if warm else 1e-25) if tol is None else tol
        sinkhorn_max_iter = (100 if warm else 1000) if sinkhorn_max_iter is None \
            else sinkhorn_max_iter
        self.c, self.amplification, self.max_iter, self.tol = c, amplification, max_iter, tol
        self.sinkhorn_tol, self.sinkhorn_max_iter = sinkhorn_tol, sinkhorn_max_iter
        self.walk = aff.drop_conflicts()
        top = self.walk.max_column_sum()
        self.scale = 1.0 / top if top > 0 else 0.0
        n1, n2 = aff.n1, aff.n2
        self.x = np.full((n1, n2), 1.0 / (n1 * n2))
        self.x2 = self.x.copy()
        self.y = np.full((n1, n2), 1.0 / (n1 * n2))
        self.X = np.full((n1, n2), 1.0 / max(n1, n2))
        self.n_iter, self.converged, self.sinkhorn_sweeps = 0, False, 0

    @property
    def done(self):
        return self.converged or self.n_iter >= self.max_iter

    def set_iterate(self, X):
        self.X = np.array(X, dtype=float)
        self.y = self.X / self.X.sum()
        self.converged, self.roundings = False, []

    def step(self):
        c = self.c
        x = self.walk.matvec(c * self.x + (1.0 - c) * self.y) * self.scale
        s = x.sum()
        if s > 0:
            x /= s
        xmax = x.max()
        amp = self.amplification / xmax if xmax > 0 else 0.0
        X, n_sweeps, _, conv, v = ref_sinkhorn_scaling(np.exp(amp * x), tol=self.sinkhorn_tol,
                                                       max_iter=self.sinkhorn_max_iter,
                                                       check_every=4, v0=self.v)
        if self.warm:
            self.v = v
        self.sinkhorn_sweeps += n_sweeps + int(conv)
        self.X = X
        sy = X.sum()
        y = X / sy if sy > 0 else X
        diff = min(float(np.sum((x - self.x) ** 2)), float(np.sum((x - self.x2) ** 2)))
        self.x2, self.x, self.y = self.x, x, y
        if diff < self.tol and (conv or not self.warm):
            self.converged = True
        elif self.warm and (self.n_iter + 1) % 10 == 0:      # the rounding is stable: 3 checks
            self.roundings = (self.roundings + [solve_lap(x).tolist()])[-3:]
            if len(self.roundings) == 3 and self.roundings.count(self.roundings[0]) == 3:
                self.converged = True
        self.n_iter += 1


# --------------------------------------------------------------------------- problems


def _random_sparse_graph(points, density, rng):
    n = len(points)
    A = np.triu(rng.random((n, n)) < density, 1)
    return Graph((A | A.T).astype(float), points=points)


def _problem(case):
    """(affinity, options) of seeded problem ``case``."""
    kind, n_in, n_out, deform, sigma2, opts = CASES[case]
    rng = np.random.default_rng(1000 + case)
    if kind == "dense":
        n = n_in
        K = rng.random((n * n, n * n)) ** 4
        K = K + K.T
        return as_affinity(K, n1=n, n2=n), opts
    edges = {"full": "full", "delaunay": "delaunay", "knn": "knn", "random": "full",
             "rect": "full", "rect-t": "full", "sparse": "delaunay"}[kind]
    p = make_point_matching_problem(n_in, n_out, deform, edges=edges, rng=rng)
    g1, g2 = p.g1, p.g2
    if kind == "random":
        g1 = _random_sparse_graph(g1.points, 0.3, rng)
        g2 = _random_sparse_graph(g2.points, 0.3, rng)
    elif kind == "rect":          # n1 > n2: the Sinkhorn works on the transpose
        g2 = Graph.from_points(g2.points[:-3], edges="full")
    elif kind == "rect-t":        # n1 < n2
        g1 = Graph.from_points(g1.points[:-4], edges="full")
    backend = "sparse" if kind == "sparse" else "auto"
    return gaussian_edge_affinity(g1, g2, sigma2=sigma2, backend=backend), opts


# kind, inliers, outliers, deformation, sigma2, rrwm options
CASES = [
    ("full", 12, 0, 0.02, 0.15, {}),
    ("full", 15, 0, 0.04, 0.02, {}),
    ("full", 12, 5, 0.02, 0.05, {}),
    ("delaunay", 20, 0, 0.02, 0.05, {}),
    ("delaunay", 14, 6, 0.03, 0.15, {"max_iter": 40}),
    ("random", 16, 0, 0.02, 0.05, {"max_iter": 40}),
    ("knn", 18, 0, 0.03, 0.02, {}),
    ("rect", 12, 0, 0.02, 0.15, {}),
    ("rect-t", 10, 3, 0.02, 0.05, {}),
    ("dense", 5, 0, 0.0, 0.0, {}),
    ("sparse", 10, 3, 0.02, 0.05, {"sinkhorn_tol": 1e-6, "c": 0.5}),
    ("full", 10, 4, 0.03, 0.02, {"sinkhorn_max_iter": 7, "amplification": 10.0,
                                  "max_iter": 40}),
]

# recorded with the implementation before issue 10: assignment, n_iter, converged, sweeps
RECORDED = [
    ([10, 5, 7, 3, 1, 2, 0, 6, 9, 11, 4, 8], 36, True, 10564),
    ([7, 5, 8, 9, 6, 10, 4, 13, 11, 0, 12, 14, 2, 3, 1], 63, True, 25088),
    ([14, 5, 16, 12, 10, 3, 13, 4, 8, 9, 7, 11, 2, 6, 0, 1, 15], 44, True, 19368),
    ([15, 19, 17, 6, 11, 0, 3, 4, 8, 2, 5, 16, 9, 13, 18, 1, 12, 14, 10, 7], 22, True, 20228),
    ([8, 18, 15, 1, 6, 7, 10, 17, 14, 16, 11, 12, 9, 4, 0, 3, 2, 19, 13, 5], 24, True, 20608),
    ([9, 10, 12, 11, 3, 6, 14, 15, 5, 4, 2, 0, 7, 13, 8, 1], 40, False, 23720),
    ([8, 16, 12, 4, 5, 11, 14, 1, 9, 15, 10, 0, 3, 2, 6, 17, 7, 13], 17, True, 14724),
    ([5, 0, 8, 2, -1, -1, 1, -1, 6, 3, 4, 7], 45, True, 6964),
    ([5, 11, 8, 1, 6, 9, 4, 10, 3], 26, True, 20088),
    ([1, 3, 2, 0, 4], 12, True, 7056),
    ([2, 11, 1, 8, 10, 7, 4, 9, 5, 6, 0, 12, 3], 31, True, 29512),
    ([5, 1, 2, 9, 0, 8, 11, 6, 4, 7, 10, 12, 3, 13], 27, True, 189),
]


def _close(a, b):
    scale = max(float(np.abs(b).max()), 1e-300)
    return float(np.abs(a - b).max()) <= 1e-12 * scale


@pytest.mark.parametrize("warm", [False, True])
@pytest.mark.parametrize("case", range(len(CASES)))
def test_rrwm_iterates_as_the_reference(case, warm):
    """The first steps against the reference (whole runs: the recorded stops below)."""
    aff, opts = _problem(case)
    opts = {**opts, "max_iter": min(opts.get("max_iter", 300), 8)}
    st = RRWMStepper(aff, **opts) if warm else RRWMStepper(aff, warm_start=False, **opts)
    ref = ReferenceRRWM(aff, warm=warm, **opts)
    while not ref.done:
        assert not st.done
        st.step()
        ref.step()
        assert _close(st._x, ref.x), f"walk scores differ at iteration {ref.n_iter}"
        assert _close(st.iterate, ref.X), f"Sinkhorn output differs at iteration {ref.n_iter}"
        assert st.sinkhorn_sweeps == ref.sinkhorn_sweeps
        assert st.converged == ref.converged
    assert st.done and st.n_iter == ref.n_iter
    np.testing.assert_array_equal(st.result().assignment, solve_lap(ref.x))


@pytest.mark.parametrize("case", range(len(CASES)))
def test_authors_loop_assignments_as_recorded(case):
    aff, opts = _problem(case)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = rrwm(aff, warm_start=False, **opts)
    assignment, n_iter, converged, sweeps = RECORDED[case]
    assert res.assignment.tolist() == assignment
    assert (res.n_iter, res.converged, res.info["sinkhorn_sweeps"]) == (n_iter, converged, sweeps)


@pytest.mark.parametrize("case", range(len(CASES)))
def test_warm_default_ends_on_the_authors_assignment_in_fewer_sweeps(case):
    aff, opts = _problem(case)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = rrwm(aff, **opts)
    assignment, n_iter, converged, sweeps = RECORDED[case]
    assert res.info["warm_start"] is True
    assert res.assignment.tolist() == assignment
    assert res.converged or not converged     # (case 5: converged at 36 of its 40 iterations)
    if "sinkhorn_max_iter" not in opts:     # (case 11 caps the cold Sinkhorn at 7 sweeps)
        assert res.info["sinkhorn_sweeps"] < sweeps / 3


@pytest.mark.parametrize("warm", [False, True])
def test_set_iterate_between_steps_as_the_reference(warm):
    """The stepper protocol (online solvers overwrite the iterate between steps)."""
    aff, _ = _problem(2)
    st, ref = RRWMStepper(aff, warm_start=warm), ReferenceRRWM(aff, warm=warm)
    rng = np.random.default_rng(7)
    for k in range(8):
        if k % 3 == 2:
            X = st.iterate * rng.uniform(0.5, 1.5, st.iterate.shape)
            st.set_iterate(X)
            ref.set_iterate(X)
        st.step()
        ref.step()
        assert _close(st._x, ref.x) and _close(st.iterate, ref.X)
        assert st.sinkhorn_sweeps == ref.sinkhorn_sweeps


@pytest.mark.parametrize("shape", [(7, 7), (5, 9), (9, 5), (1, 4)])
@pytest.mark.parametrize("tol,max_iter,check_every", [(1e-3, 1000, 4), (1e-9, 30, 1),
                                                      (1e-2, 3, 2), (1e-12, 1, 1)])
def test_scaling_sinkhorn_unchanged(shape, tol, max_iter, check_every):
    rng = np.random.default_rng(sum(shape) + max_iter)
    x = rng.random(shape) ** 3
    A = np.exp(30.0 * x / x.max())
    out = sinkhorn_normalize(A, domain="scaling", slack="mass", tol=tol, max_iter=max_iter,
                             check_every=check_every)
    X, n_sweeps, err, converged, _ = ref_sinkhorn_scaling(A, tol=tol, max_iter=max_iter,
                                                          check_every=check_every)
    assert (out.n_sweeps, out.converged) == (n_sweeps, converged)
    assert out.error == err or (np.isinf(err) and np.isinf(out.error))
    assert _close(out.X, X)


def test_scaling_sinkhorn_warm_start_unchanged():
    rng = np.random.default_rng(3)
    A = np.exp(30.0 * rng.random((6, 9)) ** 3)
    v0 = rng.uniform(0.5, 2.0, 9)
    keep = v0.copy()
    out = sinkhorn_normalize(A, domain="scaling", slack="mass", tol=1e-6, max_iter=200,
                             warm_start=v0)
    X, n_sweeps, _, converged, _ = ref_sinkhorn_scaling(A, tol=1e-6, max_iter=200,
                                                        check_every=1, v0=keep.copy())
    np.testing.assert_array_equal(v0, keep)          # the caller's array is not modified
    assert (out.n_sweeps, out.converged) == (n_sweeps, converged) and _close(out.X, X)
    assert out.col_scaling is not v0 and out.col_scaling.shape == (9,)


@pytest.mark.parametrize("case", range(len(CASES)))
def test_warm_default_whole_run_as_the_reference(case):
    """Whole runs, both stops (the tolerance, and the rounding stable over three checks)."""
    aff, opts = _problem(case)
    st, ref = RRWMStepper(aff, **opts), ReferenceRRWM(aff, warm=True, **opts)
    while not ref.done:
        st.step()
        ref.step()
    assert st.done and (st.n_iter, st.converged) == (ref.n_iter, ref.converged)
    np.testing.assert_array_equal(st.result().assignment, solve_lap(ref.x))
    assert st.result().info["stop"] == STOPS[case]


# how the warm-started default stops on each case (recorded; case 10 on the stable rounding)
STOPS = ["tolerance"] * 10 + ["stable rounding", "tolerance"]
