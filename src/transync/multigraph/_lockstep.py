"""Lock-step pairwise solvers: RRWM, GA and PF on all pairs at once, with optional sync.

:func:`run_lockstep` runs one of :func:`transync.matching.rrwm`, :func:`~transync.matching.ga`,
:func:`~transync.matching.pf` on every pair of a :class:`PairAffinities` *in lock-step*: the state
of all pairs lives in stacked ``(P, n1, n2)`` arrays, every outer step is a handful of NumPy calls
on the whole batch (one batched affinity product, one batched Sinkhorn, ...) and pairs that have
met their own stopping test are frozen (masked out), so that with ``sync=None`` every pair
follows exactly the pairwise solver's iterates. At the synchronization points (every
``sync_every`` outer steps: RRWM iterations, GA beta levels, PF lambda steps; synchronizing after
every step commits too early, see ``SYNC_EVERY`` and the methods page *Online synchronized
solvers*) the current doubly-stochastic iterates of all pairs go to ``sync`` and the state is
overwritten with ``(1 - damping) X + damping sync(X)``, as ``Stepper.set_iterate`` does for one
pair; the solvers then continue (S-RRWM, S-GA, S-PF).

Per pair, only two things remain Python loops over pairs: the Hungarian rounding at the end, and
PF's Frank-Wolfe linear minimization oracle (one linear assignment per pair and FW iteration: there
is no batched LAP in SciPy).

Examples
--------
>>> import numpy as np
>>> from transync.datasets import make_graph_collection
>>> from transync.multigraph import PairAffinities, run_lockstep
>>> prob = make_graph_collection(n_graphs=4, n_inliers=8, deformation=0.0, rng=0)
>>> aff = PairAffinities.from_graphs(prob.graphs, affinity=None)
>>> out = run_lockstep(aff, solver="rrwm")
>>> out.soft.shape, out.assignments.shape, bool(out.converged.all())
((6, 8, 8), (6, 8), True)
>>> i, j = aff.pairs[0]
>>> lab_i, lab_j = prob.labels[i], prob.labels[j]
>>> bool(np.all(lab_j[out.assignments[0]] == lab_i))      # zero noise: the planted matching
True
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from .._blas import blas_limit
from .._progress import progress_bar
from .._validation import (
    check_affinity_scale,
    check_array,
    check_bool,
    check_choice,
    check_int,
    check_nonnegative,
    check_positive,
)
from ..matching import (
    GAStepper,
    PFStepper,
    RRWMStepper,
    annealing_levels,
    default_beta_max,
    sinkhorn_augmented_batch,
    sinkhorn_batch,
    solver_options,
)
from ..permutations import solve_lap
from ._affinity import PairAffinities

__all__ = ["LockstepOutcome", "SOLVERS", "doubly_stochastic_iterates", "lockstep_options",
           "round_blocks", "run_lockstep"]

SOLVERS = ("rrwm", "ga", "pf")
# outer steps between synchronization points. Measured (12 problems, N = 8, n = 10,
# deformation 0.15, mean accuracy): GA every 1 / 4 / 8 / 16 beta levels 0.82* / 0.877 / 0.862 /
# 0.854 (*6 problems), PF every 1 / 2 / 4 lambda steps 0.670 / 0.804 / 0.821, RRWM every 5 / 10
# iterations 0.887 / 0.868. Synchronizing every step commits to a configuration too early.
SYNC_EVERY = {"rrwm": 5, "ga": 4, "pf": 4}
# the RRWM variant of the lock-step solver (see run_lockstep's docstring for the measurements)
DEFAULT_RRWM_VARIANT = "pygmtools"


@dataclass(frozen=True)
class LockstepOutcome:
    """Result of :func:`run_lockstep`.

    Attributes
    ----------
    soft : ndarray of shape (P, n1, n2)
        Final (sub-)doubly-stochastic iterates (RRWM: the Sinkhorn output; GA: the real block of
        the slack matrix; PF: the Frank-Wolfe point).
    scores : ndarray of shape (P, n1, n2)
        The matrices rounded into ``assignments``: the pairwise solver's own rounding matrix
        (RRWM original: walk scores ``x``; RRWM pygmtools: the mixture ``v``; GA, PF: ``soft``).
    assignments : int ndarray of shape (P, n1)
        Per-pair Hungarian rounding of ``scores`` (as the pairwise solver's ``result()``).
    n_iter : int
        Lock-step rounds (outer steps) performed.
    converged : bool ndarray of shape (P,)
        Each pair's own stopping test at the end.
    n_sync : int
        Calls of ``sync``.
    seconds_solve, seconds_sync : float
        Time in the solver's steps and in ``sync`` (including the blend), separately.
    info : dict
        Solver details (``variant``, ``options`` used, ``steps_per_pair`` (P,) int, ...).

    Examples
    --------
    >>> import numpy as np
    >>> from transync.multigraph import PairAffinities, run_lockstep
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> aff = PairAffinities.from_blocks({(0, 1): K, (0, 2): K}, [(0, 1), (0, 2)], n=2)
    >>> out = run_lockstep(aff, solver="rrwm")
    >>> out.assignments.tolist(), out.converged.tolist()
    ([[0, 1], [0, 1]], [True, True])
    """

    soft: np.ndarray
    scores: np.ndarray
    assignments: np.ndarray
    n_iter: int
    converged: np.ndarray
    n_sync: int
    seconds_solve: float
    seconds_sync: float
    info: dict


# --------------------------------------------------------------------------- solvers


def _norm1(x):
    return np.abs(x).sum((1, 2))


def _dist(x, y):
    """Frobenius distances ``||x_p - y_p||`` of two stacks."""
    d = x - y
    return np.sqrt(np.square(d, out=d).sum((1, 2)))


class _Batch:
    """Shared bookkeeping: per-pair step counters, convergence, budget."""

    def __init__(self, aff: PairAffinities, max_iter: int):
        self.aff = aff
        self.P, self.n1, self.n2 = len(aff), aff.n1, aff.n2
        self.max_iter = max_iter
        self.n_iter = np.zeros(self.P, np.int64)
        self.converged = np.zeros(self.P, bool)

    @property
    def active(self) -> np.ndarray:
        return ~self.converged & (self.n_iter < self.max_iter)

    # True once the solver's own schedule is over (PF: every lambda at 1): no more syncs
    schedule_done = False

    def scores(self):
        return self.iterate


class _RRWMOriginal(_Batch):
    """Batched ``_OriginalRRWMStepper`` (the authors' code)."""

    def __init__(self, aff, o):
        super().__init__(aff, o["max_iter"])
        self.c, self.beta, self.tol = o["c"], o["amplification"], o["tol"]
        self.sk_tol, self.sk_max = o["sinkhorn_tol"], o["sinkhorn_max_iter"]
        self.warm = o["warm_start"]
        self.walk = aff.drop_conflicts()
        deg = self.walk.column_sums().max((1, 2))
        check_affinity_scale(deg, "affinity")
        self.scale = np.where(deg > 0, 1.0 / np.where(deg > 0, deg, 1.0), 0.0)
        size = self.n1 * self.n2
        self.x = np.full((self.P, self.n1, self.n2), 1.0 / size)
        self.x2 = self.x.copy()
        self.y = self.x.copy()
        self.X = np.full((self.P, self.n1, self.n2), 1.0 / max(self.n1, self.n2))
        self.sinkhorn_sweeps = np.zeros(self.P, np.int64)
        self.scaling = np.ones((self.P, max(self.n1, self.n2)))   # Sinkhorn warm start
        # warm: the rounding-stability stop of the pairwise stepper (last checks per pair)
        self.every, self.checks = RRWMStepper.stable_every, RRWMStepper.stable_checks
        self.roundings = np.full((self.P, self.checks, self.n1), -1, np.int64)
        self.n_roundings = np.zeros(self.P, np.int64)

    @property
    def iterate(self):
        return self.X

    def set_iterate(self, X):
        self.X = X.copy()
        self.y = X / X.sum((1, 2))[:, None, None]
        self.converged[:] = False
        self.n_roundings[:] = 0

    def step(self, a):
        c = self.c
        x = self.walk._product(c * self.x[a] + (1.0 - c) * self.y[a], a)
        x *= self.scale[a, None, None]
        s = x.sum((1, 2))
        x /= np.where(s > 0, s, 1.0)[:, None, None]
        xmax = x.max((1, 2))
        amp = np.where(xmax > 0, self.beta / np.where(xmax > 0, xmax, 1.0), 0.0)
        X, sweeps, conv, scaling = sinkhorn_batch(
            np.exp(amp[:, None, None] * x), slack="mass", tol=self.sk_tol, max_iter=self.sk_max,
            check_every=4, warm_start=self.scaling[a] if self.warm else None)
        if self.warm:
            self.scaling[a] = scaling
        self.sinkhorn_sweeps[a] += sweeps + conv
        sy = X.sum((1, 2))
        y = X / np.where(sy > 0, sy, 1.0)[:, None, None]
        diff = np.minimum(((x - self.x[a]) ** 2).sum((1, 2)), ((x - self.x2[a]) ** 2).sum((1, 2)))
        self.x2[a], self.x[a], self.y[a], self.X[a] = self.x[a], x, y, X
        self.n_iter[a] += 1
        done = (diff < self.tol) & (conv | (not self.warm))
        self.converged[a] = done
        if self.warm:
            check = ~done & (self.n_iter[a] % self.every == 0)
            if check.any():
                self._check_stable(a[check], x[check])

    def _check_stable(self, idx, x):
        """Record the roundings of pairs ``idx``; stop those unchanged over the last checks."""
        r = round_blocks(x)
        self.roundings[idx] = np.roll(self.roundings[idx], -1, axis=1)
        self.roundings[idx, -1] = r
        self.n_roundings[idx] += 1
        same = np.all(self.roundings[idx] == r[:, None, :], axis=(1, 2))
        self.converged[idx[same & (self.n_roundings[idx] >= self.checks)]] = True

    def scores(self):
        return self.x


class _RRWMPygmtools(_Batch):
    """Batched ``_PygmtoolsRRWMStepper`` (pygmtools 0.6's loop)."""

    def __init__(self, aff, o):
        super().__init__(aff, o["max_iter"])
        self.c, self.beta, self.tol = o["c"], o["amplification"], o["tol"]
        self.sk_half = o["sinkhorn_max_iter"]
        rows = aff._product(np.ones((self.P, self.n1, self.n2)))
        top = rows.max((1, 2))
        check_affinity_scale(top, "affinity")
        denom = top + rows.min((1, 2), initial=0.0) * 1e-5
        self.scale = np.where(denom > 0, 1.0 / np.where(denom > 0, denom, 1.0), 0.0)
        self.v = np.full((self.P, self.n1, self.n2), 1.0 / (self.n1 * self.n2))
        self.w = self.v.copy()
        self.X = np.full((self.P, self.n1, self.n2), 1.0 / max(self.n1, self.n2))
        # (pairs, X, w, v) of the active pairs between steps: the arrays of the full stack are
        # written only when a pair settles or the stack is read, not at every step
        self._work = None

    def _flush(self):
        if self._work is not None:
            idx, X, w, v = self._work
            self.X[idx], self.w[idx], self.v[idx] = X, w, v
            self._work = None

    @property
    def iterate(self):
        self._flush()
        return self.X

    def set_iterate(self, X):
        self._flush()
        self.X = X.copy()
        v = (1.0 - self.c) * X + self.c * self.w
        self.v = v / v.sum((1, 2))[:, None, None]
        self.converged[:] = False

    def step(self, a):
        alpha = 1.0 - self.c
        # The temporaries are reused in place; each value is the same expression as in the
        # 2-D stepper, evaluated in the same order (bit-identical results, tested).
        if self._work is not None and np.array_equal(self._work[0], a):
            va = self._work[3]
        else:
            self._flush()
            va = self.v if len(a) == self.P else self.v[a]
        raw = self.aff._product(va, a)
        raw *= self.scale[a, None, None]
        s = _norm1(raw)
        w = raw / np.where(s > 0, s, 1.0)[:, None, None]
        wmax = w.max((1, 2))
        if np.all(wmax > 0):
            scores = w * self.beta
            scores /= wmax[:, None, None]
        else:
            scores = np.where((wmax > 0)[:, None, None],
                              self.beta * w / np.where(wmax > 0, wmax, 1.0)[:, None, None], 0.0)
        top = scores.max((1, 2))
        if np.all(top - scores.min((1, 2)) < 600.0):
            scores -= top[:, None, None]
            S = sinkhorn_batch(np.exp(scores, out=scores), slack="none",
                               tol=None, half_sweeps=self.sk_half).X
        else:       # amplification >= 600: the log domain (pair by pair)
            S = sinkhorn_batch(scores, slack="none", domain="log", half_sweeps=self.sk_half).X
        v = alpha * S
        v += (1.0 - alpha) * w
        v /= _norm1(v)[:, None, None]
        settled = self._settled(v, raw, va, s)
        self.n_iter[a] += 1
        self.converged[a] = settled
        v = np.ascontiguousarray(v)     # next step's input, laid out as a gather of self.v was
        if settled.any():
            done, keep = np.flatnonzero(settled), np.flatnonzero(~settled)
            self.X[a[done]], self.w[a[done]], self.v[a[done]] = S[done], w[done], v[done]
            self._work = (a[keep], S[keep], w[keep], v[keep]) if len(keep) else None
        else:
            self._work = (a, S, w, v)

    def _settled(self, v, raw, va, s):
        """``min(||v - raw||, ||v - va||) < tol`` per pair, as the 2-D stepper tests it.

        ``||v - raw||`` is computed only where it could be below ``tol``: it is at least
        ``| ||v||_1 - ||raw||_1 | / sqrt(n1 n2)`` with ``||v||_1 = 1`` and ``||raw||_1 = s``,
        and pygmtools' un-normalised walk ``raw`` almost never has unit mass (the test on it
        practically never fires), so one of the two distances is usually skipped. Skipped only
        with a margin of two and 1e-10 for the rounding of both masses: the outcome is the
        same as computing both.
        """
        d = _dist(v, va)
        bound = 2.0 * self.tol * np.sqrt(self.n1 * self.n2) + 1e-10
        close = np.flatnonzero(np.abs(1.0 - s) < bound)
        if len(close):
            d[close] = np.minimum(d[close], _dist(v[close], raw[close]))
        return d < self.tol

    def scores(self):
        self._flush()
        return self.v


class _SymOps:
    """Products with the symmetric part of each ``K_p`` (pairs with asymmetric ``K_p`` only)."""

    def __init__(self, aff: PairAffinities):
        self.aff = aff
        self.asym = aff.asymmetric()

    def __call__(self, X, a=None):
        Y = self.aff._product(X, a)
        asym = self.asym if a is None else self.asym[a]
        if asym.any():
            sel = np.flatnonzero(asym)
            idx = sel if a is None else np.asarray(a)[sel]
            Y[sel] = 0.5 * (Y[sel] + self.aff._product(X[sel], idx, True))
        return Y


class _GA(_Batch):
    """Batched ``GAStepper``: all pairs share the annealing schedule."""

    def __init__(self, aff, o):
        self.beta0, self.beta_max, self.beta_rate = o["beta0"], o["beta_max"], o["beta_rate"]
        if self.beta_max is None:
            self.beta_max = default_beta_max(aff.n1, aff.n2)
        super().__init__(aff, annealing_levels(self.beta0, self.beta_max, self.beta_rate))
        self.max_inner, self.inner_tol = o["max_inner"], o["inner_tol"]
        self.sk_max, self.sk_tol = o["sinkhorn_max_iter"], o["sinkhorn_tol"]
        self.K = _SymOps(aff)
        top = self.K(np.ones((self.P, self.n1, self.n2))).max((1, 2))   # column sums
        check_affinity_scale(top, "affinity")
        self.scale = np.where(top > 0, max(self.n1, self.n2) / np.where(top > 0, top, 1.0), 1.0)
        self.beta = self.beta0
        self.M = np.ones((self.P, self.n1 + 1, self.n2 + 1))
        sinkhorn_augmented_batch(self.M, tol=self.sk_tol, max_iter=self.sk_max)
        self.inner_converged = np.zeros(self.P, bool)
        self.rounds = 0

    @property
    def active(self):
        if self.beta >= self.beta_max or self.rounds >= self.max_iter:
            return np.zeros(self.P, bool)
        return np.ones(self.P, bool)

    @property
    def iterate(self):
        return self.M[:, :self.n1, :self.n2]

    def set_iterate(self, X):
        n1, n2 = self.n1, self.n2
        M = np.empty((self.P, n1 + 1, n2 + 1))
        M[:, :n1, :n2] = X
        M[:, :n1, n2] = np.clip(1.0 - X.sum(2), 1e-12, None)
        M[:, n1, :n2] = np.clip(1.0 - X.sum(1), 1e-12, None)
        M[:, n1, n2] = 1e-12
        self.M = M
        self.converged[:] = False

    def step(self, a):
        n1, n2 = self.n1, self.n2
        M = self.M
        self.inner_converged[:] = False
        act = np.asarray(a)
        for _ in range(self.max_inner):
            if not len(act):
                break
            old = M[act, :n1, :n2]
            Q = self.K(old, act) * (self.scale[act] * self.beta)[:, None, None]
            shift = Q.max((1, 2))
            e = np.exp(-shift)
            Ma = M[act]
            Ma[:, :n1, :n2] = np.exp(Q - shift[:, None, None])
            Ma[:, :n1, n2] *= e[:, None]
            Ma[:, n1, :] *= e[:, None]
            np.maximum(Ma[:, :n1, n2], 1e-300, out=Ma[:, :n1, n2])
            np.maximum(Ma[:, n1, :], 1e-300, out=Ma[:, n1, :])
            sinkhorn_augmented_batch(Ma, tol=self.sk_tol, max_iter=self.sk_max)
            M[act] = Ma
            done = np.abs(Ma[:, :n1, :n2] - old).sum((1, 2)) < self.inner_tol
            self.inner_converged[act[done]] = True
            act = act[~done]
        self.n_iter[a] += 1
        self.rounds += 1
        self.beta *= self.beta_rate
        if self.beta >= self.beta_max:
            self.converged[a] = self.inner_converged[a]


class _PF(_Batch):
    """Batched ``PFStepper``: per-pair lambda paths, batched Frank-Wolfe."""

    def __init__(self, aff, o):
        super().__init__(aff, o["max_iter"])
        self.max_step, self.min_step = o["step"], o["min_step"]
        self.jump_tol, self.fw_max, self.fw_tol = o["jump_tol"], o["fw_max_iter"], o["fw_tol"]
        K = _SymOps(aff)
        P, n1, n2 = self.P, self.n1, self.n2
        with np.errstate(over="ignore"):
            top = K(np.ones((P, n1, n2))).max((1, 2))
        check_affinity_scale(top, "affinity")
        factor = np.ones(P)
        bad = (top != 0) & ((top < 1e-100) | (top > 1e100))
        if bad.any():       # _moderate: rescale affinities whose scale would overflow
            fin = bad & np.isfinite(top)
            factor[fin] = 1.0 / top[fin]
            inf = bad & ~np.isfinite(top)
            if inf.any():
                tiny = K(np.full((int(inf.sum()), n1, n2), 1e-200), np.flatnonzero(inf))
                factor[inf] = 1e-200 / tiny.max((1, 2))
        self.factor = factor
        self.K = lambda X, a=None: K(X, a) * (factor if a is None else factor[a])[:, None, None]
        lam, v = self._power(200, 1e-8)
        Kv = self.K(v)
        vmax = v.max((1, 2))
        pos = v > 1e-12 * vmax[:, None, None]
        allpos = pos.all((1, 2)) & (vmax > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            cw = np.where(pos, Kv / np.where(pos, v, 1.0), -np.inf).max((1, 2))
        bad = np.flatnonzero(~allpos)
        if bad.size:
            # as PFStepper: a reducible or bipartite K (trees, paths, isolated nodes) leaves
            # zeros in v, and 1.05 |lam| was no bound on lambda_max where the iteration
            # oscillated; Collatz-Wielandt on the shifted operator's positive vector, or the
            # largest column sum, is (1.05 |lam| kept where it is at least that bound)
            shift = np.where(lam[bad] != 0, np.abs(lam[bad]), 1.0)
            _, vb = self._power(200, 1e-8, idx=bad, shift=shift)
            wb = np.maximum(np.abs(vb), 1e-3 * np.abs(vb).max((1, 2))[:, None, None]) + 1e-300
            colsum = self.K(np.ones((bad.size, n1, n2)), bad).max((1, 2))
            bound = np.minimum((self.K(wb, bad) / wb).max((1, 2)), colsum)
            cw[bad] = np.maximum(1.05 * np.abs(lam[bad]) + 1e-12, bound)
        self.mu = np.maximum(cw, lam)
        self.lam = np.zeros(P)
        self.dlam = np.full(P, self.max_step)
        self.sc = np.sqrt(min(n1, n2))
        self.X = np.full((P, n1, n2), 1.0 / max(n1, n2))
        self.Kx = self.K(self.X)
        self.started = np.zeros(P, bool)
        self.fw_iterations = np.zeros(P, np.int64)
        self.fw_converged = np.ones(P, bool)
        # a synchronization is a deliberate jump: the next lambda step after one is accepted
        # without the jump test and leaves the increment as it is
        self.after_sync = np.zeros(P, bool)

    def _power(self, max_iter, tol, idx=None, shift=None):
        """Leading eigenpairs of the pairs ``idx`` (default all), of ``K + shift I`` when given."""
        n1, n2 = self.n1, self.n2
        idx = np.arange(self.P) if idx is None else np.asarray(idx)
        P = len(idx)
        v = np.full((P, n1, n2), 1.0 / np.sqrt(n1 * n2))
        lam = np.zeros(P)
        act = np.arange(P)
        va = v.copy()
        for _ in range(max_iter):
            w = self.K(va, idx[act])
            if shift is not None:
                w = w + shift[act][:, None, None] * va
            lam[act] = np.einsum("pij,pij->p", va, w)
            nrm = np.sqrt((w * w).sum((1, 2)))
            zero = nrm == 0
            w /= np.where(zero, 1.0, nrm)[:, None, None]
            stop = zero | (np.sqrt(((w - va) ** 2).sum((1, 2))) < tol)
            v[act[stop & ~zero]] = w[stop & ~zero]
            v[act[zero]] = va[zero]
            keep = ~stop
            act, va = act[keep], w[keep]
            if not len(act):
                break
        v[act] = va
        return lam, v

    @property
    def iterate(self):
        return self.X

    def set_iterate(self, X):
        self.X = X.copy()
        self.Kx = self.K(self.X)
        self.converged[:] = False
        self.after_sync[:] = True

    @property
    def schedule_done(self) -> bool:
        return bool(np.all(self.lam >= 1.0))

    def _frank_wolfe(self, a, x, Kx, lam):
        """FW for pairs ``a`` from ``x`` at per-pair ``lam``; returns (x, Kx, converged)."""
        gamma = (1.0 - 2.0 * lam) * self.mu[a]
        x, Kx = x.copy(), Kx.copy()
        conv = np.zeros(len(a), bool)
        act = np.arange(len(a))
        for _ in range(self.fw_max):
            if not len(act):
                break
            self.fw_iterations[a[act]] += 1
            xa, Kxa, g = x[act], Kx[act], gamma[act]
            grad = Kxa - g[:, None, None] * xa
            D = np.zeros_like(xa)
            lmo = [linear_sum_assignment(gk, maximize=True) for gk in grad]   # one LAP per pair
            kk = np.repeat(np.arange(len(act)), [len(r) for r, _ in lmo])
            D[kk, np.concatenate([r for r, _ in lmo]), np.concatenate([c for _, c in lmo])] = 1.0
            d = D - xa
            gap = np.einsum("pij,pij->p", grad, d)
            scale = (np.abs(np.einsum("pij,pij->p", xa, Kxa))
                     + np.abs(g) * np.einsum("pij,pij->p", xa, xa))
            ok = gap <= self.fw_tol * np.maximum(scale, 1e-300)
            conv[act[ok]] = True
            go = ~ok
            act, d, xa, Kxa, g, gap = act[go], d[go], xa[go], Kxa[go], g[go], gap[go]
            if not len(act):
                break
            Kd = self.K(d + xa, a[act]) - Kxa
            q = np.einsum("pij,pij->p", d, Kd) - g * np.einsum("pij,pij->p", d, d)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(q >= 0, 1.0, np.minimum(1.0, gap / np.where(q < 0, -q, 1.0)))
            x[act] = xa + t[:, None, None] * d
            Kx[act] = Kxa + t[:, None, None] * Kd
        return x, Kx, conv

    def step(self, a):
        a = np.asarray(a)
        first = a[~self.started[a]]
        if len(first):
            x, Kx, ok = self._frank_wolfe(first, self.X[first], self.Kx[first],
                                          np.zeros(len(first)))
            self.X[first], self.Kx[first], self.fw_converged[first] = x, Kx, ok
            self.started[first] = True
            self.n_iter[first] += 1
        pend = a[np.isin(a, first, invert=True)]
        while len(pend):
            lam = np.minimum(1.0, self.lam[pend] + self.dlam[pend])
            x, Kx, ok = self._frank_wolfe(pend, self.X[pend], self.Kx[pend], lam)
            move = np.sqrt(((x - self.X[pend]) ** 2).sum((1, 2))) / self.sc
            synced = self.after_sync[pend]
            retry = (move > self.jump_tol) & (self.dlam[pend] > self.min_step) & ~synced
            r = pend[retry]
            self.dlam[r] = np.maximum(self.dlam[r] / 2.0, self.min_step)
            acc, k = pend[~retry], ~retry
            grow = (move[k] < self.jump_tol / 4) & ~synced[k]
            self.dlam[acc[grow]] = np.minimum(2.0 * self.dlam[acc[grow]], self.max_step)
            self.X[acc], self.Kx[acc], self.fw_converged[acc] = x[k], Kx[k], ok[k]
            self.lam[acc] = lam[k]
            self.n_iter[acc] += 1
            self.converged[acc] = (lam[k] >= 1.0) & ok[k]
            pend = r
        self.after_sync[a] = False


# --------------------------------------------------------------------------- options

_STEPPERS = {"rrwm": RRWMStepper, "ga": GAStepper, "pf": PFStepper}


def lockstep_options(solver: str) -> tuple[str, ...]:
    """Option names :func:`run_lockstep` accepts for ``solver`` (the pairwise solver's, as
    :func:`transync.matching.solver_options` lists them).

    >>> lockstep_options("ga")
    ('beta0', 'beta_max', 'beta_rate', 'max_inner', 'inner_tol', 'sinkhorn_max_iter',
     'sinkhorn_tol')
    """
    check_choice(solver, "solver", SOLVERS)
    return solver_options(solver)


def _resolve_options(solver: str, options) -> dict:
    """Validated options with the pairwise solver's defaults filled in.

    The values are checked by building the pairwise stepper on a 1 x 1 problem (its own
    validation, its own messages); the defaults are read back from it.
    """
    options = {} if options is None else options
    if not isinstance(options, dict):
        raise TypeError(f"`options` must be a dict or None, got {type(options).__name__}")
    valid = lockstep_options(solver)
    unknown = [k for k in options if k not in valid]
    if unknown:
        raise TypeError(f"run_lockstep(solver={solver!r}) got unknown option(s) "
                        f"{', '.join(repr(u) for u in unknown)}; valid options: {', '.join(valid)}")
    kw = dict(options)
    if solver == "rrwm":
        kw.setdefault("variant", DEFAULT_RRWM_VARIANT)
    st = _STEPPERS[solver](np.ones((1, 1)), n1=1, n2=1, **kw)
    if solver == "rrwm":
        return {"variant": st.variant, "c": st.c, "amplification": st.amplification,
                "max_iter": st.max_iter, "tol": st.tol, "sinkhorn_tol": st.sinkhorn_tol,
                "sinkhorn_max_iter": st.sinkhorn_max_iter, "warm_start": st.warm_start}
    if solver == "ga":          # beta_max None: the pairs' size decides (default_beta_max)
        return {"beta0": st.beta0, "beta_max": kw.get("beta_max"), "beta_rate": st.beta_rate,
                "max_inner": st.max_inner, "inner_tol": st.inner_tol,
                "sinkhorn_max_iter": st.sinkhorn_max_iter, "sinkhorn_tol": st.sinkhorn_tol}
    return {"max_iter": st.max_iter, "step": st.max_step, "min_step": st.min_step,
            "jump_tol": st.jump_tol, "fw_max_iter": st.fw_max_iter, "fw_tol": st.fw_tol}


# --------------------------------------------------------------------------- driver


def run_lockstep(affinities: PairAffinities, *, solver: str, sync=None,
                 sync_every: int | None = None, damping: float = 1.0, options=None,
                 progress: bool = False) -> LockstepOutcome:
    """Run a pairwise solver on all pairs in lock-step, optionally synchronizing the iterates.

    Parameters
    ----------
    affinities : PairAffinities
        The ``P`` pairs' affinities.
    solver : {"rrwm", "ga", "pf"}
        Batched versions of :func:`transync.matching.rrwm`, :func:`~transync.matching.ga`,
        :func:`~transync.matching.pf` (same updates, same stopping tests, per pair).
    sync : callable, optional
        ``Y = sync(X)``: ``X`` the ``(P, n1, n2)`` current iterates made doubly stochastic (to
        rounding: RRWM's and GA's iterates are only approximately so, see
        :func:`doubly_stochastic_iterates`), ``Y`` the synchronized ``(P, n1, n2)`` blocks,
        entries in [0, 1] (to 1e-6; a doubly stochastic or sub-stochastic block is).
        ``None``: plain pairwise matching of every pair (each reproduces the pairwise solver).
    sync_every : int, optional
        Synchronize after every ``sync_every`` outer steps. Default: RRWM 5 iterations, GA 4
        beta levels, PF 4 lambda steps (synchronizing after every level/step commits too early;
        measured, that commits too early: see ``SYNC_EVERY``). No
        synchronization follows the step in which every pair has finished (the caller discretizes
        the final iterates), nor, for PF, any step once every pair's lambda has reached 1. PF's
        lambda step right after a synchronization is accepted without the jump test (a sync is a
        deliberate jump; otherwise the increment collapses to ``min_step`` and S-PF crawls).
    damping : float in (0, 1], default=1.0
        The state becomes ``(1 - damping) X + damping Y``, ``X`` as handed to ``sync``
        (``Stepper.set_iterate`` semantics: the
        pairs' convergence flags are reset, so every pair steps again).
    options : dict, optional
        Solver options, the pairwise solver's keyword arguments (:func:`lockstep_options`);
        unknown names raise ``TypeError`` listing the valid ones. Defaults are the pairwise
        solver's, except RRWM's ``variant``: ``"pygmtools"`` here (``c=0.8``, 20 Sinkhorn
        half-sweeps, at most 50 iterations, stop when the mixture moves by less than 1e-5). The
        authors' ``"original"`` variant (at most 300 iterations, Sinkhorn to 1e-3,
        warm-started unless ``"warm_start": False`` as in :func:`~transync.matching.rrwm`) is
        available with ``options={"variant": "original"}``; batched on the Yan preset (N = 32,
        n = 20, 496 pairs) it needed several times more products for the same accuracy
        (measured with the authors' cold-started loop; docs/multigraph.md).
    progress : bool, default=False
        Show a tqdm bar over the outer steps.

    Returns
    -------
    LockstepOutcome
        Final soft iterates, rounding scores and Hungarian assignments of every pair, with
        per-pair iterations and convergence flags.

    Raises
    ------
    TypeError, ValueError
        Not a :class:`PairAffinities`, unknown solver or option, invalid option values,
        ``sync`` not callable or returning the wrong shape or values outside [0, 1],
        ``damping`` outside (0, 1].

    Examples
    --------
    Two pairs of the same 2-node problem, plain (``sync=None``) and with a toy
    synchronization that averages the two pairs' iterates:

    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> aff = PairAffinities.from_blocks({(0, 1): K, (0, 2): K}, [(0, 1), (0, 2)], n=2)
    >>> run_lockstep(aff, solver="ga").assignments.tolist()
    [[0, 1], [0, 1]]
    >>> mean = lambda X: np.broadcast_to(X.mean(0), X.shape).copy()
    >>> out = run_lockstep(aff, solver="rrwm", sync=mean, sync_every=1)
    >>> out.assignments.tolist(), out.n_sync > 0
    ([[0, 1], [0, 1]], True)
    """
    if not isinstance(affinities, PairAffinities):
        raise TypeError(f"`affinities` must be a PairAffinities, got {type(affinities).__name__}")
    check_choice(solver, "solver", SOLVERS)
    opts = _resolve_options(solver, options)
    if sync is not None and not callable(sync):
        raise TypeError(f"`sync` must be None or a callable X -> Y, got {type(sync).__name__}")
    sync_every = SYNC_EVERY[solver] if sync_every is None else check_int(sync_every,
                                                                           "sync_every", minimum=1)
    damping = check_positive(damping, "damping")
    if damping > 1:
        raise ValueError(f"`damping` must lie in (0, 1], got {damping!r}")
    check_bool(progress, "progress")
    aff = affinities
    n1, n2 = aff.n1, aff.n2
    t_solve = t_sync = 0.0
    n_sync = rounds = 0
    with blas_limit(n1 * n2):
        t0 = time.perf_counter()
        if solver == "rrwm":
            cls = _RRWMOriginal if opts["variant"] == "original" else _RRWMPygmtools
            st = cls(aff, opts)
            budget = opts["max_iter"]
        elif solver == "ga":
            st = _GA(aff, opts)
            budget = st.max_iter
        else:
            st = _PF(aff, opts)
            budget = opts["max_iter"]
        t_solve += time.perf_counter() - t0
        bar = progress_bar(budget, f"lock-step {solver}", enabled=bool(progress), unit="step")
        try:
            while rounds < budget:
                act = np.flatnonzero(st.active)
                if not len(act):
                    break
                t0 = time.perf_counter()
                st.step(act)
                t_solve += time.perf_counter() - t0
                rounds += 1
                bar.update(1)
                bar.set_postfix_str(f"active={len(act)}")
                if sync is None or rounds % sync_every or not st.active.any() \
                        or st.schedule_done:
                    continue
                t0 = time.perf_counter()
                X = doubly_stochastic_iterates(st.iterate)
                Y = _check_sync_output(sync(X.copy()), X.shape)
                st.set_iterate(Y if damping == 1.0 else (1.0 - damping) * X + damping * Y)
                n_sync += 1
                t_sync += time.perf_counter() - t0
        finally:
            bar.close()
        t0 = time.perf_counter()
        soft = np.array(st.iterate, dtype=float)
        scores = np.array(st.scores(), dtype=float)
        assignments = round_blocks(scores)
        t_solve += time.perf_counter() - t0
    info = {"solver": solver, "options": opts, "steps_per_pair": st.n_iter.copy(),
            "sync_every": sync_every, "damping": damping}
    if solver == "rrwm" and opts["variant"] == "original":
        info["sinkhorn_sweeps"] = st.sinkhorn_sweeps.copy()
    if solver == "pf":
        info.update(lam=st.lam.copy(), mu=st.mu / st.factor, fw_iterations=st.fw_iterations.copy())
    if solver == "ga":
        info["beta"] = st.beta
        info["options"] = {**opts, "beta_max": st.beta_max}      # as resolved for these pairs
    return LockstepOutcome(soft=soft, scores=scores, assignments=assignments, n_iter=rounds,
                           converged=st.converged.copy(), n_sync=n_sync, seconds_solve=t_solve,
                           seconds_sync=t_sync, info=info)


def round_blocks(X: np.ndarray) -> np.ndarray:
    """Per-pair Hungarian rounding (maximizing) of blocks ``(P, n1, n2)`` -> ``(P, n1)``."""
    return np.stack([solve_lap(x) for x in X])


def doubly_stochastic_iterates(X, tol: float = 1e-10, max_iter: int = 200):
    """The iterates handed to ``sync``, made doubly stochastic (to rounding, n1 == n2).

    RRWM's iterates are Sinkhorn outputs stopped early (original: row sums to 1e-3; pygmtools: 20
    half-sweeps, rows off by up to a few 1e-3), GA's the real block of its slack matrix; the
    synchronizers want doubly-stochastic blocks (``synchronize_doubly_stochastic`` refuses a
    deviation above 1e-6). Sinkhorn alone can take thousands of sweeps on RRWM's nearly
    0/1 iterates (measured: 4e-5 left after 10^4 sweeps), so: at most ``max_iter`` sweeps to
    ``tol``, an exact row normalization, then the remaining column deviation ``d`` (which sums to
    0) is moved exactly: every over-full column ``j`` gives up the fraction ``|d_j| / c_j`` of
    each entry, and each row puts what it gave up into the under-full columns in proportion to
    their deficits. Rows stay exact, columns become exact, entries stay non-negative. PF's
    iterates are already doubly stochastic and come back unchanged to rounding. With
    ``n1 != n2`` only the Sinkhorn part (slack-mass convention) is applied.

    >>> X = np.array([[[0.9, 0.2], [0.1, 0.8]]])
    >>> Y = doubly_stochastic_iterates(X)
    >>> bool(np.allclose(Y.sum(1), 1, atol=1e-14) and np.allclose(Y.sum(2), 1, atol=1e-14))
    True
    """
    X = check_array(X, "X", ndim=3)
    check_nonnegative(X, "X")
    X = np.maximum(X, 1e-300)
    Y = sinkhorn_batch(X, slack="mass", tol=tol, max_iter=max_iter)[0]
    if Y.shape[1] != Y.shape[2]:
        return Y
    Y /= Y.sum(2, keepdims=True)
    c = Y.sum(1)                                        # (P, n) column sums
    d = 1.0 - c                                         # > 0: deficit, < 0: excess
    frac = np.where(d < 0, -d / c, 0.0)                 # share of each over-full column removed
    given = Y * frac[:, None, :]                        # (P, n, n)
    lost = given.sum(2)                                 # (P, n) per row
    deficit = np.where(d > 0, d, 0.0)
    D = deficit.sum(1, keepdims=True)
    w = np.divide(deficit, D, out=np.zeros_like(deficit), where=D > 0)
    return Y - given + lost[:, :, None] * w[:, None, :]


def _check_sync_output(Y, shape):
    try:
        Y = np.asarray(Y, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"`sync` must return a float array of shape {shape}: {exc}") from None
    if Y.shape != shape:
        raise ValueError(f"`sync` must return an array of shape {shape} (the iterates' shape), "
                         f"got {Y.shape}")
    if not np.all(np.isfinite(Y)):
        raise ValueError("`sync` returned NaN or infinite entries")
    if Y.size and Y.min() < -1e-9:
        raise ValueError(f"`sync` must return non-negative blocks, got minimum {Y.min():.6g}")
    if Y.size and Y.max() > 1.0 + 1e-6:
        # a doubly stochastic (or sub-stochastic) block has entries <= 1; scaled blocks
        # overflow the solvers' products (PF's Frank-Wolfe LAP met NaN at 1e300)
        raise ValueError(f"`sync` must return blocks with entries in [0, 1] (doubly stochastic "
                         f"or sub-stochastic), got maximum {Y.max():.6g}")
    return np.clip(Y, 0.0, 1.0)
