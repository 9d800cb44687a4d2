"""Path following for a general affinity (convex-to-concave, after Zaslavskiy et al. 2009).

The form for a general affinity K (methods page *Pairwise quadratic assignment* of the
documentation): maximize

.. math:: f_\\lambda(x) = x^\\top K x - (1 - 2\\lambda)\\,\\mu\\,\\|x\\|^2,
          \\qquad \\mu \\ge \\lambda_{\\max}(K),

over the (rectangular) Birkhoff polytope while ``lambda`` goes from 0 (``f`` concave: a convex
problem with a unique optimum) to 1 (``f`` convex: maxima at vertices). Every ``f_lambda`` ranks
permutations exactly as the QAP does, because ``||x||^2 = min(n1, n2)`` on them.

Examples
--------
>>> import numpy as np
>>> from transync.graphs import Graph
>>> from transync.matching import gaussian_edge_affinity, pf
>>> rng = np.random.default_rng(0)
>>> g1 = Graph.from_points(rng.random((8, 2)), edges="full")
>>> perm = rng.permutation(8)
>>> res = pf(gaussian_edge_affinity(g1, g1.permute(perm)))
>>> bool(np.all(perm[res.assignment] == np.arange(8)))
True
"""

from __future__ import annotations

import numpy as np

from .._validation import MAX_ITER, check_int, check_positive
from ..permutations import assignment_to_matrix, solve_lap
from ._affinity import as_affinity
from ._result import MatchingResult
from ._stepwise import _BaseStepper, _moderate, _power_iteration, _run, _symmetric

__all__ = ["PFStepper", "pf"]

_DEFAULTS = {"max_iter": 1000, "step": 0.1, "min_step": 1e-3, "jump_tol": 0.3,
             "fw_max_iter": 30, "fw_tol": 1e-3}


class PFStepper(_BaseStepper):
    """Step-wise path following: one accepted ``lambda`` step per :meth:`step`.

    The first step solves the concave problem at ``lambda = 0``; each later step tries
    ``lambda + dlambda``, runs Frank-Wolfe from the current iterate and, if the iterate jumped by
    more than ``jump_tol`` (Frobenius distance divided by ``sqrt(min(n1, n2))``), halves
    ``dlambda`` (down to ``min_step``) and retries; small moves double ``dlambda`` (up to ``step``).
    The iterate is the Frank-Wolfe point: in the Birkhoff polytope (``n1 == n2``) or, for unequal
    sizes, in the polytope whose smaller side is stochastic and larger side sub-stochastic.

    Parameters
    ----------
    affinity : Affinity or array_like/sparse of shape (n1 n2, n1 n2)
        The affinity ``K``.
    n1, n2 : int, optional
        Graph sizes; required when ``affinity`` is a matrix.
    max_iter, step, min_step, jump_tol, fw_max_iter, fw_tol
        As in :func:`pf`.

    Raises
    ------
    ValueError, TypeError
        Invalid ``affinity`` or options (as :func:`pf`).

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)              # n1 = n2 = 2
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> s = PFStepper(K, n1=2, n2=2)
    >>> while not s.step():
    ...     pass
    >>> s.result().assignment
    array([0, 1])
    """

    method = "pf"
    unit_iterate = True

    def __init__(self, affinity, *, n1: int | None = None, n2: int | None = None,
                 max_iter: int = _DEFAULTS["max_iter"], step: float = _DEFAULTS["step"],
                 min_step: float = _DEFAULTS["min_step"], jump_tol: float = _DEFAULTS["jump_tol"],
                 fw_max_iter: int = _DEFAULTS["fw_max_iter"], fw_tol: float = _DEFAULTS["fw_tol"]):
        aff = as_affinity(affinity, n1=n1, n2=n2)
        super().__init__(aff, max_iter=check_int(max_iter, "max_iter", minimum=1, maximum=MAX_ITER))
        self.max_step = check_positive(step, "step")
        self.min_step = check_positive(min_step, "min_step")
        if self.min_step > self.max_step:
            raise ValueError(f"`min_step` must be <= step={self.max_step!r}, got {self.min_step!r}")
        self.jump_tol = check_positive(jump_tol, "jump_tol")
        self.fw_max_iter = check_int(fw_max_iter, "fw_max_iter", minimum=1, maximum=MAX_ITER)
        self.fw_tol = check_positive(fw_tol, "fw_tol")
        self._K = _moderate(_symmetric(aff))   # rescaled only if its scale would overflow
        lam, v, _, _ = _power_iteration(self._K.matvec, self.n1, self.n2, max_iter=200, tol=1e-8)
        # Collatz-Wielandt: max (Kv)_i / v_i bounds lambda_max from above for v > 0, K >= 0
        Kv = self._K.matvec(v)
        pos = v > 1e-12 * v.max() if v.max() > 0 else np.zeros(v.shape, bool)
        if pos.all():
            self.mu = float(np.max(Kv / v))
        else:
            # zero entries in v: a reducible K (isolated nodes), or a bipartite one (both graphs
            # trees, paths, grids...) whose power iteration oscillates between +-lambda_max and
            # stops far from the Perron vector. 1.05 |Rayleigh quotient| was no bound there (24 %
            # low on two 8-node trees). The shifted operator K + |lam| I has a dominant Perron
            # root, and Collatz-Wielandt on any positive w bounds lambda_max, as does the largest
            # column sum. 1.05 |lam| is kept where it is at least that bound (a converged
            # iteration on a reducible K: the same path as before)
            shift = abs(lam) if lam else 1.0
            _, v, _, _ = _power_iteration(lambda X: self._K.matvec(X) + shift * X, self.n1,
                                          self.n2, max_iter=200, tol=1e-8)
            w = np.maximum(np.abs(v), 1e-3 * float(np.abs(v).max(initial=0.0))) + 1e-300
            bound = min(float(np.max(self._K.matvec(w) / w)), self._K.max_column_sum())
            self.mu = max(1.05 * abs(lam) + 1e-12, bound)
        self.mu = max(self.mu, lam)
        self.lam = 0.0
        self.dlam = self.max_step
        self._scale = np.sqrt(min(self.n1, self.n2))
        self._Kx = self._K.matvec(self._X)
        self._started = False
        self.fw_iterations = 0
        self.fw_converged = True

    def set_iterate(self, X) -> None:
        super().set_iterate(X)
        self._Kx = self._K.matvec(self._X)

    def _frank_wolfe(self, x, Kx, lam):
        gamma = (1.0 - 2.0 * lam) * self.mu
        converged = False
        for _ in range(self.fw_max_iter):
            self.fw_iterations += 1
            grad = Kx - gamma * x                   # half the gradient
            b = solve_lap(grad)
            d = assignment_to_matrix(b, self.n2) - x
            gap = float(np.vdot(grad, d))
            scale = abs(float(np.vdot(x, Kx))) + abs(gamma) * float(np.vdot(x, x))
            if gap <= self.fw_tol * max(scale, 1e-300):
                converged = True
                break
            Kd = self._K.matvec(d + x) - Kx
            q = float(np.vdot(d, Kd)) - gamma * float(np.vdot(d, d))
            t = 1.0 if q >= 0 else min(1.0, gap / (-q))
            x = x + t * d
            Kx = Kx + t * Kd
        return x, Kx, converged

    def step(self) -> bool:
        if self.done:
            return True
        if not self._started:
            self._X, self._Kx, self.fw_converged = self._frank_wolfe(self._X, self._Kx, 0.0)
            self._started = True
            self.n_iter += 1
            return self.done
        while True:
            lam = min(1.0, self.lam + self.dlam)
            x, Kx, ok = self._frank_wolfe(self._X, self._Kx, lam)
            move = float(np.linalg.norm(x - self._X)) / self._scale
            if move > self.jump_tol and self.dlam > self.min_step:
                self.dlam = max(self.dlam / 2.0, self.min_step)
                continue
            break
        if move < self.jump_tol / 4:
            self.dlam = min(2.0 * self.dlam, self.max_step)
        self._X, self._Kx, self.fw_converged, self.lam = x, Kx, ok, lam
        self.n_iter += 1
        if self.lam >= 1.0 and self.fw_converged:
            self.converged = True
        return self.done

    @property
    def done(self) -> bool:
        return self.converged or self.n_iter >= self.max_iter

    def _info(self) -> dict:
        return {"lambda": self.lam, "mu": self.mu / getattr(self._K, "factor", 1.0),
                "fw_iterations": self.fw_iterations}


def pf(K, *, n1: int | None = None, n2: int | None = None, max_iter: int = _DEFAULTS["max_iter"],
       step: float = _DEFAULTS["step"], min_step: float = _DEFAULTS["min_step"],
       jump_tol: float = _DEFAULTS["jump_tol"], fw_max_iter: int = _DEFAULTS["fw_max_iter"],
       fw_tol: float = _DEFAULTS["fw_tol"]) -> MatchingResult:
    """Path following from a concave to a convex relaxation of the QAP.

    .. math:: \\max_{X \\in \\mathcal B} f_\\lambda(X) = \\mathrm{vec}(X)^\\top K \\mathrm{vec}(X)
              - (1 - 2\\lambda)\\,\\mu\\,\\|X\\|_F^2, \\qquad \\lambda: 0 \\to 1,

    with ``mu`` an upper bound on the largest eigenvalue of ``K`` (power iteration plus the
    Collatz-Wielandt bound). At each ``lambda``, Frank-Wolfe: the direction is the Hungarian
    solution on the gradient, the step the exact maximizer of the quadratic on the segment.
    ``lambda`` advances adaptively (see :class:`PFStepper`). An asymmetric ``K`` is replaced by its
    symmetric part.

    Parameters
    ----------
    K : Affinity or array_like/sparse of shape (n1 n2, n1 n2)
        Affinity (pygmtools layout when a matrix).
    n1, n2 : int, optional
        Graph sizes; required when ``K`` is a matrix.
    max_iter : int, default=1000
        Maximum number of accepted ``lambda`` steps.
    step : float, default=0.1
        Initial and largest ``lambda`` increment.
    min_step : float, default=1e-3
        Smallest ``lambda`` increment.
    jump_tol : float, default=0.3
        A move larger than this (Frobenius norm / ``sqrt(min(n1, n2))``) halves the increment.
    fw_max_iter : int, default=30
        Maximum Frank-Wolfe iterations per ``lambda``.
    fw_tol : float, default=1e-3
        Frank-Wolfe stops when the duality gap is below ``fw_tol`` times
        ``|x^T K x| + |1 - 2 lambda| mu ||x||^2`` (the size of the two terms of ``f_lambda``).

    Returns
    -------
    MatchingResult
        ``soft`` is the final Frank-Wolfe iterate; ``info["mu"]`` the spectral bound.

    Warns
    -----
    ConvergenceWarning
        When ``lambda = 1`` is not reached within ``max_iter`` steps or the last Frank-Wolfe run
        did not meet ``fw_tol`` (``converged=False``).

    References
    ----------
    M. Zaslavskiy, F. Bach and J.-P. Vert, "A path following algorithm for the graph matching
    problem", TPAMI 2009; F. Zhou and F. De la Torre, "Factorized graph matching", TPAMI 2016.

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> pf(K, n1=2, n2=2).assignment
    array([0, 1])
    """
    return _run(PFStepper(K, n1=n1, n2=n2, max_iter=max_iter, step=step, min_step=min_step,
                          jump_tol=jump_tol, fw_max_iter=fw_max_iter, fw_tol=fw_tol))
