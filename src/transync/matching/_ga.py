"""Graduated assignment (Gold & Rangarajan, TPAMI 1996).

Examples
--------
>>> import numpy as np
>>> from transync.graphs import Graph
>>> from transync.matching import gaussian_edge_affinity, ga
>>> rng = np.random.default_rng(0)
>>> g1 = Graph.from_points(rng.random((8, 2)), edges="full")
>>> perm = rng.permutation(8)
>>> res = ga(gaussian_edge_affinity(g1, g1.permute(perm)))
>>> bool(np.all(perm[res.assignment] == np.arange(8)))
True
"""

from __future__ import annotations

import numpy as np

from .._validation import MAX_ITER, check_affinity_scale, check_int, check_positive
from ._affinity import as_affinity
from ._result import MatchingResult
from ._sinkhorn import sinkhorn_normalize
from ._stepwise import _BaseStepper, _run, _symmetric

__all__ = ["GAStepper", "default_beta_max", "ga"]

_DEFAULTS = {"beta0": 0.5, "beta_max": 10.0, "beta_rate": 1.075, "max_inner": 4,
             "inner_tol": 0.5, "sinkhorn_max_iter": 30, "sinkhorn_tol": 0.05}
#: the slack Sinkhorn's budget and tolerance on graphs of different sizes: there the slack
#: fades as beta grows and Gold & Rangarajan's 30 sweeps / 0.05 stop far from the marginals
#: (row sums up to 2, ties broken by node order); on 120 complete-graph problems with
#: n1 < n2 <= n1 + 3 <= 9 (deformation 0.02) GA missed the planted map on 50 with theirs, 29
#: with these (50 sweeps / 1e-2: 36; 300 / 1e-4 on a similar set: 18 against 19), at 3.3x the
#: time on such small graphs, where the Sinkhorn dominates
RECT_SINKHORN = {"sinkhorn_max_iter": 100, "sinkhorn_tol": 1e-3}


def _sinkhorn_defaults(n1: int, n2: int, max_iter, tol) -> tuple:
    """The slack Sinkhorn's options: as given, else Gold & Rangarajan's on equal sizes and
    :data:`RECT_SINKHORN` on different ones."""
    base = _DEFAULTS if n1 == n2 else RECT_SINKHORN
    return (base["sinkhorn_max_iter"] if max_iter is None else max_iter,
            base["sinkhorn_tol"] if tol is None else tol)


def default_beta_max(n1: int, n2: int) -> float:
    """Final inverse temperature when none is given: ``max(10, n1, n2)``.

    Gold & Rangarajan's ``beta_f = 10`` up to 10 nodes. On larger graphs the annealing ended
    with a soft matrix whose rounding is poor: on 12 pairs of complete 30-node graphs
    (deformation 0.1 / 0.15) ``beta_max = 10`` gave accuracy 0.80 / 0.24 (score 0.85 / 0.68 of
    the truth), ``beta_max = 20`` and ``30`` gave 1.0 / 0.64-0.65 (score 1.0 / 0.93); on 20-node
    graphs 0.44 -> 0.75 at deformation 0.15; unchanged at 10 nodes; 30-60 % more time.

    >>> default_beta_max(8, 8), default_beta_max(30, 24)
    (10.0, 30.0)
    """
    n1 = check_int(n1, "n1", minimum=1, maximum=MAX_NODES)
    n2 = check_int(n2, "n2", minimum=1, maximum=MAX_NODES)
    return max(_DEFAULTS["beta_max"], float(max(n1, n2)))


#: most annealing levels a schedule may take (the default schedule takes 43 up to 10 nodes,
#: 106 at 1000): a ``beta_rate`` barely above 1 would otherwise run for days
MAX_LEVELS = 10_000


#: largest ``beta_max`` and ``beta_rate``: ``beta`` times the scaled gradient (at most
#: ``max(n1, n2)``) must stay far from float64's overflow
MAX_BETA = 1e100
#: largest graph size :func:`default_beta_max` takes (far beyond what fits in memory)
MAX_NODES = 10**12


def _check_schedule(beta0, beta_max, beta_rate) -> tuple[float, float, float]:
    """The annealing schedule's three numbers, checked: ``0 < beta0 <= beta_max <= MAX_BETA``,
    ``1 < beta_rate <= MAX_BETA``."""
    beta0 = check_positive(beta0, "beta0")
    beta_max = check_positive(beta_max, "beta_max")
    beta_rate = check_positive(beta_rate, "beta_rate")
    if beta_rate <= 1:
        raise ValueError(f"`beta_rate` must be > 1, got {beta_rate!r}")
    for name, value in (("beta_max", beta_max), ("beta_rate", beta_rate)):
        if value > MAX_BETA:
            raise ValueError(f"`{name}` must be <= {MAX_BETA:g} (beta times the gradient would "
                             f"overflow), got {value!r}")
    if beta_max < beta0:
        raise ValueError(f"`beta_max` must be >= beta0={beta0!r}, got {beta_max!r}")
    return beta0, beta_max, beta_rate


def annealing_levels(beta0: float, beta_max: float, beta_rate: float) -> int:
    """Levels of the schedule ``beta0, beta0 * beta_rate, ...`` up to ``beta_max`` (both
    included), refused above :data:`MAX_LEVELS`.

    >>> annealing_levels(0.5, 10.0, 1.075)
    43
    """
    return _levels(*_check_schedule(beta0, beta_max, beta_rate))


def _levels(beta0: float, beta_max: float, beta_rate: float) -> int:
    """:func:`annealing_levels` of a schedule already checked by :func:`_check_schedule`."""
    # logs taken apart: the ratio of a huge beta_max and a tiny beta0 overflows to inf
    span = (np.log(beta_max) - np.log(beta0)) / np.log(beta_rate)
    levels = int(np.ceil(span)) + 1 if span <= MAX_LEVELS else MAX_LEVELS + 1
    if levels > MAX_LEVELS:
        raise ValueError(f"`beta_rate`={beta_rate!r} anneals from beta0={beta0!r} to "
                         f"beta_max={beta_max!r} in {span + 1:.4g} levels, more than "
                         f"{MAX_LEVELS}: pass a larger `beta_rate` (default "
                         f"{_DEFAULTS['beta_rate']})")
    return levels


def _slack_sinkhorn(M: np.ndarray, *, max_iter: int, tol: float) -> np.ndarray:
    """Gold & Rangarajan's slack Sinkhorn of ``M`` (shape ``(n1 + 1, n2 + 1)``), in place."""
    return sinkhorn_normalize(M, domain="augmented", slack="augmented", tol=tol,
                              max_iter=max_iter).X


class GAStepper(_BaseStepper):
    """Step-wise graduated assignment: one annealing level (fixed ``beta``) per :meth:`step`.

    Each step runs the inner loop (gradient, softassign, slack Sinkhorn) up to ``max_inner`` times
    or until the matrix changes by less than ``inner_tol``, then multiplies ``beta`` by
    ``beta_rate``. The iterate is the real block of the slack-augmented matrix: non-negative with
    row and column sums at most 1 once the slack Sinkhorn has converged (with ``n1 != n2`` it
    converges slowly, hence the larger default budget there: :data:`RECT_SINKHORN`).
    :meth:`set_iterate` sets that block and fills the slack row and column with the missing
    mass.

    Parameters
    ----------
    affinity : Affinity or array_like/sparse of shape (n1 n2, n1 n2)
        The affinity ``K``.
    n1, n2 : int, optional
        Graph sizes; required when ``affinity`` is a matrix.
    beta0, beta_max, beta_rate, max_inner, inner_tol, sinkhorn_max_iter, sinkhorn_tol
        As in :func:`ga`.

    Raises
    ------
    ValueError, TypeError
        Invalid ``affinity`` or options (as :func:`ga`).

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)              # n1 = n2 = 2
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> s = GAStepper(K, n1=2, n2=2)
    >>> while not s.step():
    ...     pass
    >>> s.result().assignment
    array([0, 1])
    """

    method = "ga"
    unit_iterate = True

    def __init__(self, affinity, *, n1: int | None = None, n2: int | None = None,
                 beta0: float = _DEFAULTS["beta0"], beta_max: float | None = None,
                 beta_rate: float = _DEFAULTS["beta_rate"], max_inner: int = _DEFAULTS["max_inner"],
                 inner_tol: float = _DEFAULTS["inner_tol"],
                 sinkhorn_max_iter: int | None = None, sinkhorn_tol: float | None = None):
        aff = as_affinity(affinity, n1=n1, n2=n2)
        sinkhorn_max_iter, sinkhorn_tol = _sinkhorn_defaults(aff.n1, aff.n2, sinkhorn_max_iter,
                                                             sinkhorn_tol)
        if beta_max is None:
            beta_max = default_beta_max(aff.n1, aff.n2)
        self.beta0, self.beta_max, self.beta_rate = _check_schedule(beta0, beta_max, beta_rate)
        levels = _levels(self.beta0, self.beta_max, self.beta_rate)
        super().__init__(aff, max_iter=levels)
        self.max_inner = check_int(max_inner, "max_inner", minimum=1, maximum=MAX_ITER)
        self.inner_tol = check_positive(inner_tol, "inner_tol")
        self.sinkhorn_max_iter = check_int(sinkhorn_max_iter, "sinkhorn_max_iter", minimum=1,
                                           maximum=MAX_ITER)
        self.sinkhorn_tol = check_positive(sinkhorn_tol, "sinkhorn_tol")
        K = _symmetric(aff)
        top = K.max_column_sum()
        check_affinity_scale(top)
        # gradient at the uniform matrix at most 1: beta's schedule then acts on an O(1) scale
        self.scale = max(self.n1, self.n2) / top if top > 0 else 1.0
        self._K = K
        self.beta = self.beta0
        self._M = np.ones((self.n1 + 1, self.n2 + 1))
        _slack_sinkhorn(self._M, max_iter=self.sinkhorn_max_iter, tol=self.sinkhorn_tol)
        self._X = self._M[:self.n1, :self.n2]
        self.inner_converged = False

    @property
    def done(self) -> bool:
        return self.beta >= self.beta_max or self.n_iter >= self.max_iter

    def set_iterate(self, X) -> None:
        X = self._check_iterate(X)
        n1, n2 = self.n1, self.n2
        M = np.empty((n1 + 1, n2 + 1))
        M[:n1, :n2] = X
        M[:n1, n2] = np.clip(1.0 - X.sum(1), 1e-12, None)
        M[n1, :n2] = np.clip(1.0 - X.sum(0), 1e-12, None)
        M[n1, n2] = 1e-12
        self._M = M
        self._X = M[:n1, :n2]
        self.converged = False

    def step(self) -> bool:
        if self.done:
            return True
        n1, n2 = self.n1, self.n2
        M = self._M
        self.inner_converged = False
        for _ in range(self.max_inner):
            old = M[:n1, :n2].copy()
            Q = self._K.matvec(M[:n1, :n2]) * (self.scale * self.beta)
            shift = Q.max()
            M[:n1, :n2] = np.exp(Q - shift)
            M[:n1, n2] *= np.exp(-shift)      # same common factor on the slack entries
            M[n1, :] *= np.exp(-shift)
            np.maximum(M[:n1, n2], 1e-300, out=M[:n1, n2])
            np.maximum(M[n1, :], 1e-300, out=M[n1, :])
            _slack_sinkhorn(M, max_iter=self.sinkhorn_max_iter, tol=self.sinkhorn_tol)
            if np.abs(M[:n1, :n2] - old).sum() < self.inner_tol:
                self.inner_converged = True
                break
        self._X = M[:n1, :n2]
        self.n_iter += 1
        self.beta *= self.beta_rate
        if self.beta >= self.beta_max:
            self.converged = self.inner_converged
        return self.done

    @property
    def iterate(self) -> np.ndarray:
        return self._M[:self.n1, :self.n2].copy()

    def _info(self) -> dict:
        return {"beta": self.beta, "scale": self.scale}


def ga(K, *, n1: int | None = None, n2: int | None = None, beta0: float = _DEFAULTS["beta0"],
       beta_max: float | None = None, beta_rate: float = _DEFAULTS["beta_rate"],
       max_inner: int = _DEFAULTS["max_inner"], inner_tol: float = _DEFAULTS["inner_tol"],
       sinkhorn_max_iter: int | None = None,
       sinkhorn_tol: float | None = None) -> MatchingResult:
    """Graduated assignment with slack row and column (Gold & Rangarajan's defaults; the final
    temperature grows with the graphs beyond 10 nodes).

    Deterministic annealing on ``max vec(M)^T K vec(M)``: for ``beta = beta0, beta0 * beta_rate,
    ...`` below ``beta_max``, repeat ``Q = K vec(M)``, ``M = exp(beta Q)`` (softassign) and a slack
    Sinkhorn normalisation. ``K`` is scaled by ``max(n1, n2) / max column sum`` so that the gradient
    at the uniform matrix is at most 1 and the schedule means the same for every problem size and
    affinity scale. An asymmetric ``K`` is replaced by its symmetric part.

    Parameters
    ----------
    K : Affinity or array_like/sparse of shape (n1 n2, n1 n2)
        Affinity (pygmtools layout when a matrix).
    n1, n2 : int, optional
        Graph sizes; required when ``K`` is a matrix.
    beta0 : float, default=0.5
        Initial inverse temperature.
    beta_max : float, optional
        Final inverse temperature. Default :func:`default_beta_max`: ``max(10, n1, n2)``
        (Gold & Rangarajan's 10 up to 10 nodes; larger graphs need a longer annealing).
    beta_rate : float, default=1.075
        Annealing factor (> 1).
    max_inner : int, default=4
        Maximum softassign iterations per temperature (loop "B", ``I0``).
    inner_tol : float, default=0.5
        Loop "B" stops when ``M`` changes by less than this (entrywise L1, ``eps0``).
    sinkhorn_max_iter : int, optional
        Maximum Sinkhorn sweeps (loop "C", ``I1``): default 30 (Gold & Rangarajan) when
        ``n1 == n2``, 100 otherwise (:data:`RECT_SINKHORN`: with different sizes the slack
        fades and 30 sweeps stop far from the marginals).
    sinkhorn_tol : float, optional
        Loop "C" stops when ``M`` changes by less than this (entrywise L1, ``eps1``): default
        0.05 when ``n1 == n2``, 1e-3 otherwise.

    Returns
    -------
    MatchingResult
        ``soft`` is the final (sub-)doubly-stochastic matrix.

    Warns
    -----
    ConvergenceWarning
        When the last temperature's inner loop does not meet ``inner_tol`` (``converged=False``).

    References
    ----------
    S. Gold and A. Rangarajan, "A graduated assignment algorithm for graph matching", TPAMI 1996.

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> ga(K, n1=2, n2=2).assignment
    array([0, 1])
    """
    stepper = GAStepper(K, n1=n1, n2=n2, beta0=beta0, beta_max=beta_max, beta_rate=beta_rate,
                        max_inner=max_inner, inner_tol=inner_tol,
                        sinkhorn_max_iter=sinkhorn_max_iter, sinkhorn_tol=sinkhorn_tol)
    return _run(stepper)
