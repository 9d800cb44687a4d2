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

from .._validation import (MAX_AFFINITY_SCALE, MAX_ITER, MIN_AFFINITY_SCALE, check_array,
                           check_choice, check_int, check_int_array, check_positive)
from ..exceptions import DegenerateInputError

__all__ = ["SinkhornBatchOutput", "SinkhornOutput", "sinkhorn_augmented_batch", "sinkhorn_batch",
           "sinkhorn_normalize"]

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


class SinkhornBatchOutput(NamedTuple):
    """Result of :func:`sinkhorn_batch`.

    Attributes
    ----------
    X : ndarray of shape (b, n1, n2)
        The normalised matrices.
    n_sweeps : ndarray of shape (b,)
        Sweeps each matrix took.
    converged : ndarray of shape (b,) of bool
        Whether each matrix met ``tol``.
    scaling : ndarray of shape (b, max(n1, n2)) or None
        The scaling of each matrix's longer side (its columns when ``n1 <= n2``, else its rows),
        to pass back as ``warm_start`` on the next kernels of the same shape; ``None`` in the
        log domain.
    """

    X: np.ndarray
    n_sweeps: np.ndarray
    converged: np.ndarray
    scaling: np.ndarray | None


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
        dom = None
    elif domain == "augmented":
        dom = _AugmentedDomain(M)
    else:
        raise ValueError(f"`domain` must be one of {DOMAINS}, got {domain!r}")
    if half_sweeps is not None:
        n_half, tol = int(half_sweeps), None
    else:
        n_half = 2 * int(max_iter) + (domain != "augmented")
    if dom is None:
        v0 = warm_start if warm_start is not None and warm_start.shape == (K.shape[1],) else None
        X, v, n_sweeps, err, converged = _scaling_loop(K, mass, v0, n_half=n_half, tol=tol,
                                                       check_every=check_every)
    else:
        n_sweeps, err, converged = _alternate(dom, n_half=n_half, tol=tol,
                                              check_every=check_every)
        X, v = dom.matrix(), None
        if converged and domain == "log":
            # The potentials' test exp(f + lse) - 1 cancels to 0 once they reach ~1e16 (a log-
            # kernel of that range, e.g. scores / tau with tau = 1e-20): check the matrix itself
            real = float(np.max(np.abs(X.sum(1) - 1.0), initial=0.0))
            if not real < tol:
                err, converged = real, False
    return SinkhornOutput(X.T if transposed else X, n_sweeps, err, converged, v)


def _scaling_loop(A, slack: float, v0, *, n_half: int, tol: float | None, check_every: int):
    """The scaling domain: scalings ``u`` (rows) and ``v`` (columns) of ``A`` with rows <= cols.

    The half-sweeps of :func:`_alternate` (rows even, columns odd; the tolerance tested before a
    row update, never before the final one; when met, the last accepted sweep is kept, columns
    exact), written out for speed: RRWM runs thousands of sweeps on small matrices per solve,
    where the cost is the calls, not the arithmetic. The vectors live in preallocated buffers and
    every operation is the one of the plain formulation (``np.dot(A, v, out=)`` is ``A @ v`` bit
    for bit, ``reciprocal`` is ``1.0 / x``), so the iterates are the same to the last bit.
    Returns ``(X, v, n_sweeps, error, converged)``.
    """
    dot, recip, mul = np.dot, np.reciprocal, np.multiply
    A = np.asarray(A, dtype=float)      # (``out=`` buffers need the operands' dtype)
    n1, n2 = A.shape
    v = np.ones(n2) if v0 is None else np.array(v0, dtype=float)
    if v0 is not None and not slack and v.size:
        # without slack the loop is invariant under (u c, v / c), so a warm start handed from
        # solve to solve drifts in scale until it overflows (RRWM, 3000 warm-started steps);
        # a power of two brings max v to [0.5, 1) exactly: the same iterates to the last bit
        top = float(v.max())
        if 0 < top < np.inf:
            v = np.ldexp(v, -int(np.frexp(top)[1]))
    Av, u, uA, t = np.empty(n1), np.empty(n1), np.empty(n2), np.empty(n1)
    n_sweeps, err, converged = 0, np.inf, False
    check = tol is not None
    # half-sweep 0 (rows; never tested), then pairs (columns i, rows i + 1)
    if n_half > 0:
        dot(A, v, out=Av)
        recip(Av, out=u)
    for i in range(1, n_half, 2):
        dot(u, A, out=uA)
        if slack:
            uA += slack / v.sum()
        recip(uA, out=v)
        n_sweeps += 1
        if i + 1 == n_half:
            break
        dot(A, v, out=Av)
        if check and (n_sweeps + 1) % check_every == 0 and i + 2 != n_half:
            mul(u, Av, out=t)
            # max |t - 1| exactly: rounding of t - 1 is monotone in t
            err = float(max(t.max() - 1.0, 1.0 - t.min()))
            if err < tol:
                converged = True
                break
        recip(Av, out=u)
    X = (u[:, None] * A) * v[None, :]
    return X, v, n_sweeps, err, converged


def _alternate(dom, *, n_half: int, tol: float | None, check_every: int):
    """The loop of the log and augmented domains: half-sweep ``i`` normalises rows (even) or
    columns (odd). The scaling domain runs the same schedule in :func:`_scaling_loop`."""
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


# --------------------------------------------------------------------------- batched Sinkhorn
# Stacks of matrices for the lock-step multi-graph solvers: a batched transcription of
# `_alternate` (scaling and augmented domains), each matrix frozen once its own test passes so
# that it gets exactly the iterate of the 2-D `sinkhorn_normalize` call.


def _batch_scaling(A, *, slack_mass: float, tol, max_iter: int = 1000,
                      half_sweeps: int | None = None, check_every: int = 1, v0=None):
    """``diag(u) A diag(v)`` for a stack ``A`` of shape (b, r, c), ``r <= c``, ``v`` from ``v0``
    (b, c) or ones.

    Returns ``(X, n_sweeps (b,), converged (b,), v (b, c))``.
    """
    b, r, c = A.shape
    v = np.ones((b, c)) if v0 is None else np.array(v0, dtype=float)
    u = np.empty((b, r))
    n_sweeps = np.zeros(b, np.int64)
    converged = np.zeros(b, bool)
    if half_sweeps is not None:
        n_half, tol = int(half_sweeps), None
    else:
        n_half = 2 * int(max_iter) + 1
    act = np.arange(b)
    Aa, ua, va = A, u, v                       # compacted views of the active matrices
    sweeps = 0
    for i in range(n_half):
        if i % 2:
            uA = np.matmul(ua[:, None, :], Aa)[:, 0, :]
            if slack_mass:
                va = 1.0 / (uA + slack_mass / va.sum(1, keepdims=True))
            else:
                va = 1.0 / uA
            sweeps += 1
            continue
        Av = np.matmul(Aa, va[:, :, None])[:, :, 0]
        last = i == n_half - 1
        if tol is not None and i and (sweeps + 1) % check_every == 0 and not last:
            err = np.abs(ua * Av - 1.0).max(1)
            done = err < tol
            if done.any():
                idx = act[done]
                u[idx], v[idx] = ua[done], va[done]
                n_sweeps[idx] = sweeps
                converged[idx] = True
                keep = ~done
                act, Aa, ua, va, Av = act[keep], Aa[keep], ua[keep], va[keep], Av[keep]
                if not len(act):
                    break
        ua = 1.0 / Av
    if len(act):
        u[act], v[act] = ua, va
        n_sweeps[act] = sweeps
    return (u[:, :, None] * A) * v[:, None, :], n_sweeps, converged, v


def _batch_slack(A, *, slack: str, **kw) -> SinkhornBatchOutput:
    """Scaling-domain Sinkhorn of a stack of kernels (trusted input); transposes when n1 > n2."""
    transposed = A.shape[1] > A.shape[2]
    K = np.swapaxes(A, 1, 2) if transposed else A
    mass = float(K.shape[2] - K.shape[1]) if slack == "mass" else 0.0
    X, n_sweeps, conv, v = _batch_scaling(np.ascontiguousarray(K), slack_mass=mass, **kw)
    return SinkhornBatchOutput(np.swapaxes(X, 1, 2) if transposed else X, n_sweeps, conv, v)


def _batch_augmented(M, *, tol: float, max_iter: int, which=None) -> None:
    """Gold & Rangarajan's slack Sinkhorn of ``M[which]`` (b, n1 + 1, n2 + 1), in place."""
    idx = np.arange(len(M)) if which is None else np.asarray(which)
    if not len(idx):
        return
    n1, n2 = M.shape[1] - 1, M.shape[2] - 1
    Ma = M[idx]
    old = None
    for i in range(2 * int(max_iter)):
        if i % 2:
            Ma[:, :, :n2] /= Ma[:, :, :n2].sum(1, keepdims=True)
            continue
        if i:
            err = np.abs(Ma[:, :n1, :n2] - old).sum((1, 2))
            done = err < tol
            if done.any():
                M[idx[done]] = Ma[done]
                keep = ~done
                idx, Ma = idx[keep], Ma[keep]
                if not len(idx):
                    return
        old = Ma[:, :n1, :n2].copy()
        Ma[:, :n1] /= Ma[:, :n1].sum(2, keepdims=True)
    M[idx] = Ma


def sinkhorn_batch(A, *, slack: str = "mass", domain: str = "scaling", tol: float | None = None,
                   max_iter: int = 1000, half_sweeps: int | None = None,
                   check_every: int = 1, warm_start=None) -> SinkhornBatchOutput:
    """Sinkhorn normalisation of a stack of ``b`` kernels, each as its own 2-D call would give.

    The lock-step multi-graph solvers normalise all pairs at once with it. Each matrix stops on
    its own test (then frozen), so every matrix gets exactly the iterate of the 2-D call.

    Parameters
    ----------
    A : ndarray of shape (b, n1, n2)
        ``domain="scaling"``: non-negative kernels with a positive entry in every row and column;
        ``"log"``: log-kernels (finite), normalised pair by pair in the log domain.
    slack : {"mass", "none"}, default="mass"
        Marginals when ``n1 != n2``: the smaller side sums to one and the larger side's slack
        mass ``|n1 - n2|`` is spread (``"mass"``), or the sides alternate (``"none"``).
    domain : {"scaling", "log"}, default="scaling"
        Whether ``A`` holds kernels or log-kernels.
    tol : float, optional
        Stop a matrix when its row-sum error falls below ``tol`` (tested every
        ``check_every`` sweeps); ``None``: no test.
    max_iter : int, default=1000
        Maximum sweeps (each a column and a row normalisation).
    half_sweeps : int, optional
        Instead of ``tol``/``max_iter``: exactly this many half-sweeps (>= 1), rows first.
    check_every : int, default=1
        Test the tolerance every this many sweeps.
    warm_start : ndarray of shape (b, max(n1, n2)), optional
        Scaling domain: start each matrix from this scaling of its longer side (the ``scaling``
        of an earlier call on kernels of the same shape) instead of ones. A kernel that changed
        little since then needs few sweeps.

    Returns
    -------
    SinkhornBatchOutput
        ``(X, n_sweeps, converged, scaling)``.

    Raises
    ------
    ValueError, TypeError
        ``A`` not a non-empty 3-d stack (negative, non-finite, with an all-zero row or column
        or with entries so large that a row or column sum overflows, in the scaling domain), unknown ``slack`` or ``domain``, bad counts or tolerances, a
        ``warm_start`` of the wrong shape, not positive and finite, or given in the log domain.
    DegenerateInputError
        Scaling domain: the scalings overflowed (entries of ``A`` spanning too many orders of
        magnitude within a matrix; the log domain takes such kernels).

    Examples
    --------
    >>> import numpy as np
    >>> from transync.matching import sinkhorn_batch
    >>> A = np.random.default_rng(0).random((4, 3, 3)) + 0.1
    >>> X, sweeps, ok, scaling = sinkhorn_batch(A, tol=1e-9)
    >>> bool(np.allclose(X.sum(1), 1) and np.allclose(X.sum(2), 1)), bool(ok.all())
    (True, True)
    >>> again = sinkhorn_batch(A * 1.01, tol=1e-9, warm_start=scaling)
    >>> bool(np.all(again.n_sweeps < sweeps))
    True
    """
    check_choice(slack, "slack", ("mass", "none"))
    check_choice(domain, "domain", ("scaling", "log"))
    # the lock-step solvers call this at every step on large stacks: finiteness comes from the
    # reductions that _check_kernels reuses, not from a pass of its own
    A = check_array(A, "A", ndim=3, finite=False)
    stats = _kernel_stats(A) if A.size else None
    if stats is not None and not stats[2]:
        check_array(A, "A", ndim=3)                 # raises its message: NaN or inf entries
    if 0 in A.shape:
        raise ValueError(f"`A` must have shape (b, n1, n2) with every size >= 1, got {A.shape}")
    if half_sweeps is not None:
        half_sweeps = check_int(half_sweeps, "half_sweeps", minimum=1, maximum=MAX_ITER)
    max_iter = check_int(max_iter, "max_iter", minimum=1, maximum=MAX_ITER)
    check_every = check_int(check_every, "check_every", minimum=1)
    if tol is not None:
        tol = check_positive(tol, "tol")
    if warm_start is not None:
        if domain == "log":
            raise ValueError("`warm_start` is a scaling of the scaling domain; it is not used "
                             "with domain='log'")
        warm_start = check_array(warm_start, "warm_start", ndim=2)
        if warm_start.shape != (A.shape[0], max(A.shape[1:])):
            raise ValueError(f"`warm_start` must have shape (b, max(n1, n2)) = "
                             f"{(A.shape[0], max(A.shape[1:]))}, got {warm_start.shape}")
        if not np.all(np.isfinite(warm_start) & (warm_start > 0)):
            raise ValueError("`warm_start` must be positive and finite")
        # a scaling's overall size is free (u absorbs it): bring huge or tiny ones near 1 by a
        # power of two, which leaves every later iterate bit for bit as it was
        warm_start = np.ldexp(warm_start, -np.frexp(warm_start.max(1, keepdims=True))[1])
    if domain == "log":
        outs = [sinkhorn_normalize(a, domain="log", slack=slack, tol=tol, max_iter=max_iter,
                                   half_sweeps=half_sweeps, check_every=check_every) for a in A]
        return SinkhornBatchOutput(np.stack([o.X for o in outs]),
                                   np.array([o.n_sweeps for o in outs]),
                                   np.array([o.converged for o in outs]), None)
    _check_kernels(A, "A", "pass log-kernels with domain='log'", stats=stats)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore", under="ignore"):
        out = _batch_slack(A, slack=slack, tol=tol, max_iter=max_iter, half_sweeps=half_sweeps,
                           check_every=check_every, v0=warm_start)
        bad = np.flatnonzero(~np.isfinite(out.X.sum((1, 2))))
    if bad.size:                # one pass over X: a few per cent of the sweeps' cost
        what = "`A` or of `warm_start`" if warm_start is not None else "`A`"
        raise DegenerateInputError(
            f"Sinkhorn's scalings overflowed on {bad.size} of {len(A)} matrices (first: "
            f"{bad[0]}): the entries of {what} span too many orders of magnitude for the "
            "scaling domain; pass log-kernels with domain='log'")
    return out


def sinkhorn_augmented_batch(M, *, tol: float, max_iter: int, which=None) -> None:
    """Gold & Rangarajan's slack Sinkhorn of a stack ``M`` (b, n1 + 1, n2 + 1), **in place**.

    The real block's rows and columns are normalised against the slack row and column (which
    are never normalised themselves) until the real block changes by less than ``tol`` (L1) over
    a sweep, or ``max_iter`` sweeps; ``which`` restricts the work to some matrices. Every matrix
    gets exactly the iterate of ``sinkhorn_normalize(M[k], domain="augmented", ...)``.

    Parameters
    ----------
    M : ndarray of shape (b, n1 + 1, n2 + 1), float
        Non-negative kernels with their slack row and column (last); overwritten.
    tol : float
        Stop when the real block changes by less than this (entrywise L1) over a sweep.
    max_iter : int
        Maximum sweeps.
    which : array_like of int or bool, optional
        The matrices of the stack to normalize (default: all): indices in ``[0, b)`` or a
        boolean mask of length ``b``.

    Returns
    -------
    None
        ``M`` is normalized in place.

    Raises
    ------
    ValueError
        ``M`` not a writable float stack of that shape, negative or non-finite entries, an
        all-zero row or column, entries so large that a row or column sum overflows, bad
        ``tol``, ``max_iter`` or ``which``.
    TypeError
        ``which`` not integers or booleans.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.matching import sinkhorn_augmented_batch
    >>> M = np.ones((2, 3, 3))
    >>> sinkhorn_augmented_batch(M, tol=1e-9, max_iter=100)
    >>> bool(np.all(M[:, :2, :2].sum(1) <= 1 + 1e-9))
    True
    """
    if not isinstance(M, np.ndarray) or M.ndim != 3 or M.dtype.kind != "f" \
            or min(M.shape[1:], default=0) < 2 or not M.flags.writeable:
        raise ValueError("`M` must be a writable float ndarray of shape (b, n1 + 1, n2 + 1) "
                         f"with n1, n2 >= 1 (normalised in place), got "
                         f"{getattr(M, 'shape', type(M).__name__)}")
    tol = check_positive(tol, "tol")
    max_iter = check_int(max_iter, "max_iter", minimum=1, maximum=MAX_ITER)
    _check_kernels(M, "M")
    if which is not None:
        which = _check_which(which, len(M))
    _batch_augmented(M, tol=tol, max_iter=max_iter, which=which)


def _check_which(which, b: int) -> np.ndarray:
    """``which`` as the indices of the matrices of a stack of ``b``: a boolean mask of length
    ``b`` or integers in ``[0, b)``."""
    arr = np.asarray(which) if not isinstance(which, (str, bytes)) else None
    if arr is not None and arr.dtype.kind == "b":
        if arr.shape != (b,):
            raise ValueError(f"`which` as a boolean mask must have shape ({b},), one entry per "
                             f"matrix of `M`, got shape {arr.shape}")
        return np.flatnonzero(arr)
    idx = check_int_array(which, "which", ndim=1, what="matrix indices (or a boolean mask)")
    bad = (idx < 0) | (idx >= b)
    if bad.any():
        raise ValueError(f"`which` must hold indices in [0, {b}) of the matrices of `M`, got "
                         f"{int(idx[bad][0])}")
    return idx


def _kernel_stats(A: np.ndarray):
    """``(A.min(), A.max(2), all entries finite)`` of a non-empty stack: NaN and inf propagate
    through min and max, so two reductions also answer finiteness."""
    lo, rmax = A.min(), A.max(2)
    return lo, rmax, bool(np.isfinite(lo) and np.isfinite(rmax.max()))


def _check_kernels(A: np.ndarray, name: str, hint: str = "rescale it", *, stats=None) -> None:
    """Non-negative, finite, no all-zero row or column (they would give NaN), and no row or
    column whose largest entry is below MIN_AFFINITY_SCALE (its scaling 1 / (A v) would
    overflow: the log domain takes such kernels as log-kernels). ``stats``: the
    :func:`_kernel_stats` of ``A`` when the caller has them."""
    if not A.size:
        return
    lo, rmax, finite = stats if stats is not None else _kernel_stats(A)
    if not finite or lo < 0:
        raise ValueError(f"`{name}` must be finite and non-negative, got minimum {lo:.3g}")
    top = min(float(rmax.min()), float(A.max(1).min()))
    if top <= 0:
        raise ValueError(f"`{name}` has an all-zero row or column in some matrix: Sinkhorn "
                         "cannot normalise it")
    if top < MIN_AFFINITY_SCALE:
        raise ValueError(f"`{name}` has a row or column whose largest entry is {top:.3g}, below "
                         f"{MIN_AFFINITY_SCALE:g}: its scaling overflows; {hint}")
    big, n = float(rmax.max()), max(A.shape[-2:])
    if big > MAX_AFFINITY_SCALE / n:
        raise ValueError(f"`{name}` has an entry {big:.3g}, whose row and column sums (up to "
                         f"{n} entries) can exceed {MAX_AFFINITY_SCALE:g} and overflow; {hint}")
