"""The one Sinkhorn normalisation behind every solver of the matching layer.

:func:`sinkhorn_normalize` alternates row and column normalisations ("half-sweeps", rows first)
of a positive kernel. Callers choose

* the **domain** -- ``"log"``: potentials ``f, g`` of the log-kernel ``L``, the result is
  ``exp(f + L + g)`` (never overflows; :func:`~transync.matching.sinkhorn`); ``"scaling"``: vectors
  ``u, v`` of the kernel ``A``, the result is ``diag(u) A diag(v)`` (about 10x cheaper; for kernels
  of bounded dynamic range, as RRWM's ``exp(beta x / max x)``); ``"augmented"``: Gold &
  Rangarajan's explicit slack row and column, normalised in place on the matrix itself (graduated
  assignment);
* the **slack** -- ``"mass"``: with ``n1 != n2`` a slack row (or column) of mass ``|n2 - n1|``
  makes the smaller side stochastic and the larger one sub-stochastic (Cho et al.'s convention);
  ``"none"``: plain alternation, the sides alternate between summing to one (pygmtools without
  ``dummy_row``); ``"augmented"`` goes with the domain of the same name;
* the **stop** -- a tolerance on the row-sum error (checked every ``check_every`` sweeps; in the
  augmented domain on the change of the real block over a sweep), or a fixed number of
  ``half_sweeps`` with no test at all.

The scaling and log domains compute the same iterates in exact arithmetic; they differ in the last
bits, and in one convention kept from the code each replaced: when the tolerance is met, the log
domain applies the row update it has just tested (rows exact), the scaling domain keeps the last
accepted sweep (columns exact).

Examples
--------
>>> import numpy as np
>>> from transync.matching._sinkhorn import sinkhorn_normalize
>>> L = np.log(np.array([[4.0, 1.0, 1.0], [1.0, 4.0, 1.0]]))
>>> out = sinkhorn_normalize(L, domain="log", slack="mass", tol=1e-12, max_iter=500)
>>> np.round(out.X.sum(1), 8), bool(np.all(out.X.sum(0) <= 1 + 1e-8)), out.converged
(array([1., 1.]), True, True)
>>> B = sinkhorn_normalize(np.exp(L), domain="scaling", slack="mass", tol=1e-12, max_iter=500).X
>>> bool(np.allclose(B, out.X, atol=1e-9))
True
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.special import logsumexp

__all__ = ["SinkhornOutput", "sinkhorn_normalize"]

DOMAINS = ("log", "scaling", "augmented")
SLACKS = ("mass", "none", "augmented")


class SinkhornOutput(NamedTuple):
    """Result of :func:`sinkhorn_normalize`.

    ``X`` the normalised matrix (same orientation as the input; the augmented domain returns the
    input array itself, normalised in place); ``n_sweeps`` the column normalisations performed;
    ``error`` the last stopping statistic computed (``inf`` if none); ``converged`` whether the
    tolerance was met; ``col_scaling`` the column scaling ``v`` (scaling domain; warm start).
    """

    X: np.ndarray
    n_sweeps: int
    error: float
    converged: bool
    col_scaling: np.ndarray | None = None


class _LogDomain:
    """Potentials ``f`` (rows) and ``g`` (columns) of ``L`` with ``rows <= cols``."""

    keeps_tested_rows = True
    tests_last_row = True

    def __init__(self, L, slack: float):
        self.L = L
        self.slack = slack
        self.f = None
        self.g = np.zeros(L.shape[1])
        self.f_slack = -np.inf
        self._lse = None

    def row_candidate(self):
        self._lse = logsumexp(self.L + self.g, axis=1)

    def row_error(self) -> float:
        return float(np.max(np.abs(np.exp(self.f + self._lse) - 1.0)))

    def apply_row(self):
        self.f = -self._lse
        self.f_slack = np.log(self.slack) - logsumexp(self.g) if self.slack else -np.inf

    def col(self):
        col_lse = logsumexp(self.L + self.f[:, None], axis=0)
        self.g = -np.logaddexp(col_lse, self.f_slack) if self.slack else -col_lse

    def matrix(self):
        return np.exp(self.f[:, None] + self.L + self.g[None, :])


class _ScalingDomain:
    """Scalings ``u`` (rows) and ``v`` (columns) of ``A`` with ``rows <= cols``."""

    keeps_tested_rows = False
    tests_last_row = False

    def __init__(self, A, slack: float, v0=None):
        self.A = A
        self.slack = slack
        self.v = np.ones(A.shape[1]) if v0 is None or v0.shape != (A.shape[1],) else v0
        self.u = None
        self._Av = None

    def row_candidate(self):
        self._Av = self.A @ self.v

    def row_error(self) -> float:
        return float(np.max(np.abs(self.u * self._Av - 1.0)))

    def apply_row(self):
        self.u = 1.0 / self._Av

    def col(self):
        uA = self.u @ self.A
        self.v = 1.0 / (uA + self.slack / self.v.sum()) if self.slack else 1.0 / uA

    def matrix(self):
        return (self.u[:, None] * self.A) * self.v[None, :]


class _AugmentedDomain:
    """In place on ``M`` of shape ``(n1 + 1, n2 + 1)`` whose last row and column are slack.

    Real rows sum to one over ``n2 + 1`` entries, real columns over ``n1 + 1`` (Gold & Rangarajan);
    the stopping statistic is the entrywise L1 change of the real block over one sweep.
    """

    keeps_tested_rows = False
    tests_last_row = False

    def __init__(self, M):
        self.M = M
        self.n1, self.n2 = M.shape[0] - 1, M.shape[1] - 1
        self._old = None

    def row_candidate(self):
        pass

    def row_error(self) -> float:
        return float(np.abs(self.M[:self.n1, :self.n2] - self._old).sum())

    def apply_row(self):
        M, n1 = self.M, self.n1
        self._old = M[:n1, :self.n2].copy()
        M[:n1] /= M[:n1].sum(1, keepdims=True)

    def col(self):
        M, n2 = self.M, self.n2
        M[:, :n2] /= M[:, :n2].sum(0, keepdims=True)

    def matrix(self):
        return self.M


def sinkhorn_normalize(M: np.ndarray, *, domain: str = "log", slack: str = "mass",
                       tol: float | None = None, max_iter: int = 1000,
                       half_sweeps: int | None = None, check_every: int = 1,
                       warm_start: np.ndarray | None = None) -> SinkhornOutput:
    """Alternate row and column normalisations of a positive kernel (internal; trusted input).

    Parameters
    ----------
    M : ndarray of shape (n1, n2)
        ``domain="log"``: the log-kernel ``L``; ``"scaling"``: the kernel ``A > 0``;
        ``"augmented"``: the slack-augmented kernel of shape ``(n1 + 1, n2 + 1)``, modified in
        place.
    domain : {"log", "scaling", "augmented"}, default="log"
        Arithmetic (see the module docstring).
    slack : {"mass", "none", "augmented"}, default="mass"
        Marginals for ``n1 != n2``; ``"augmented"`` exactly when ``domain="augmented"``.
    tol : float or None, default=None
        Stop when the row-sum error (augmented: the change of the real block over a sweep) falls
        below ``tol``; tested before the row update of sweeps ``k`` with ``(k + 1) % check_every
        == 0`` (the test costs as much as a half-sweep; the scaling domain does not test its
        final row update). ``None``: no test.
    max_iter : int, default=1000
        Maximum column normalisations; the log and scaling domains end with a row update, the
        augmented domain with a column update.
    half_sweeps : int, optional
        Instead of ``tol``/``max_iter``: exactly this many half-sweeps, rows first, no test.
    check_every : int, default=1
        Test the tolerance every this many sweeps.
    warm_start : ndarray, optional
        Column scaling to start from (scaling domain; pass back ``col_scaling``).

    Returns
    -------
    SinkhornOutput
    """
    if (domain == "augmented") != (slack == "augmented"):
        raise ValueError(f"`slack='augmented'` goes with `domain='augmented'`, got "
                         f"domain={domain!r}, slack={slack!r}")
    transposed = domain != "augmented" and M.shape[0] > M.shape[1]
    K = M.T if transposed else M
    mass = float(K.shape[1] - K.shape[0]) if slack == "mass" else 0.0
    if domain == "log":
        dom = _LogDomain(K, mass)
    elif domain == "scaling":
        dom = _ScalingDomain(K, mass, warm_start)
    elif domain == "augmented":
        dom = _AugmentedDomain(M)
    else:
        raise ValueError(f"`domain` must be one of {DOMAINS}, got {domain!r}")
    if half_sweeps is not None:
        n_half, tol = int(half_sweeps), None
    else:
        n_half = 2 * int(max_iter) + (domain != "augmented")
    n_sweeps, err, converged = _alternate(dom, n_half=n_half, tol=tol, check_every=check_every)
    X = dom.matrix()
    v = dom.v if domain == "scaling" else None
    return SinkhornOutput(X.T if transposed else X, n_sweeps, err, converged, v)


def _alternate(dom, *, n_half: int, tol: float | None, check_every: int):
    """The loop shared by every domain: half-sweep ``i`` normalises rows (even) or columns (odd)."""
    n_sweeps, err, converged = 0, np.inf, False
    for i in range(n_half):
        if i % 2:
            dom.col()
            n_sweeps += 1
            continue
        dom.row_candidate()
        last = i == n_half - 1
        if (tol is not None and i and (n_sweeps + 1) % check_every == 0
                and (dom.tests_last_row or not last)):
            err = dom.row_error()
            if err < tol:
                converged = True
                if dom.keeps_tested_rows:
                    dom.apply_row()
                break
        dom.apply_row()
    return n_sweeps, err, converged
