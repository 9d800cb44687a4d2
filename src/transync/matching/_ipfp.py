"""Integer projected fixed point (Leordeanu, Hebert & Sukthankar, NeurIPS 2009).

Examples
--------
>>> import numpy as np
>>> from transync.graphs import Graph
>>> from transync.matching import gaussian_edge_affinity, ipfp
>>> rng = np.random.default_rng(0)
>>> g1 = Graph.from_points(rng.random((8, 2)), edges="full")
>>> perm = rng.permutation(8)
>>> res = ipfp(gaussian_edge_affinity(g1, g1.permute(perm)), init="sm")
>>> bool(np.all(perm[res.assignment] == np.arange(8)))
True
"""

from __future__ import annotations

import numpy as np

from .._validation import MAX_ITER, check_affinity_scale, check_choice, check_int, check_positive
from ..permutations import assignment_to_matrix, solve_lap
from ._affinity import as_affinity
from ._result import MatchingResult
from ._sm import SMStepper
from ._stepwise import _BaseStepper, _run, _symmetric

__all__ = ["IPFPStepper", "ipfp"]

_DEFAULTS = {"init": "uniform", "max_iter": 50, "tol": 1e-6}


class IPFPStepper(_BaseStepper):
    """Step-wise IPFP: one Hungarian direction + exact line search per :meth:`step`.

    The iterate ``x`` stays in the convex hull of the (partial) permutation matrices; the best
    discrete point met so far is kept and returned by :meth:`result`. The affinity's product
    ``K x`` is updated incrementally, so each step costs one product with ``K``.

    Parameters
    ----------
    affinity : Affinity or array_like/sparse of shape (n1 n2, n1 n2)
        The affinity ``K``.
    n1, n2 : int, optional
        Graph sizes; required when ``affinity`` is a matrix.
    init, max_iter, tol
        As in :func:`ipfp`.

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)              # n1 = n2 = 2
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> s = IPFPStepper(K, n1=2, n2=2)
    >>> while not s.step():
    ...     pass
    >>> s.result().assignment
    array([0, 1])
    """

    method = "ipfp"
    unit_iterate = True

    def __init__(self, affinity, *, n1: int | None = None, n2: int | None = None,
                 init=_DEFAULTS["init"], max_iter: int = _DEFAULTS["max_iter"],
                 tol: float = _DEFAULTS["tol"]):
        aff = as_affinity(affinity, n1=n1, n2=n2)
        super().__init__(aff, max_iter=check_int(max_iter, "max_iter", minimum=1, maximum=MAX_ITER))
        self.tol = check_positive(tol, "tol")
        self._K = _symmetric(aff)
        check_affinity_scale(self._K.max_column_sum())
        if isinstance(init, str):
            check_choice(init, "init", ("uniform", "sm"))
            if init == "sm":
                st = SMStepper(self._K)
                while not st.done:
                    st.step()
                self._X = st.iterate
        else:
            self._X = self._check_iterate(init, "init")
        self._best = None
        self._best_score = -np.inf
        self._refresh()

    def _refresh(self):
        self._Kx = self._K.matvec(self._X)
        self._fx = float(np.vdot(self._X, self._Kx))

    def set_iterate(self, X) -> None:
        super().set_iterate(X)
        self._refresh()

    def step(self) -> bool:
        if self.done:
            return True
        x, Kx, fx = self._X, self._Kx, self._fx
        b = solve_lap(Kx)
        B = assignment_to_matrix(b, self.n2)
        Kb = self._K.matvec(B)
        bKb = float(np.vdot(B, Kb))
        if bKb > self._best_score:
            self._best_score, self._best = bKb, b
        xKb = float(np.vdot(Kx, B))
        C = xKb - fx                        # x^T K (b - x)
        D = bKb - 2.0 * xKb + fx            # (b - x)^T K (b - x)
        t = 1.0 if D >= 0 else float(np.clip(-C / D, 0.0, 1.0))
        d = B - x
        self._X = x + t * d
        if t == 1.0:
            self._Kx, self._fx = Kb, bKb
        else:
            self._Kx = Kx + t * (Kb - Kx)
            self._fx = fx + 2.0 * t * C + t * t * D
        self.n_iter += 1
        if t * np.linalg.norm(d) < self.tol:
            self.converged = True
        return self.done

    def result(self) -> MatchingResult:
        res = super().result()
        if self._best is not None and self._best_score > res.objective:
            best = self._best.copy()
            return MatchingResult(assignment=best, soft=res.soft,
                                  objective=self.affinity.score(
                                      assignment_to_matrix(best, self.n2)),
                                  n_iter=res.n_iter, converged=res.converged, method=self.method,
                                  n2=self.n2, info=res.info)
        return res


def ipfp(K, *, n1: int | None = None, n2: int | None = None, init=_DEFAULTS["init"],
         max_iter: int = _DEFAULTS["max_iter"], tol: float = _DEFAULTS["tol"]) -> MatchingResult:
    """Integer projected fixed point (IPFP) for the Lawler QAP.

    From ``x``: ``b = Hungarian(K x)`` (the best discrete point of the linear approximation), then
    the exact maximizer of the quadratic on the segment ``[x, b]``:

    .. math:: t^\\star = \\min\\Bigl(1, -\\frac{x^\\top K (b - x)}{(b - x)^\\top K (b - x)}\\Bigr)
              \\text{ if } (b - x)^\\top K (b - x) < 0, \\text{ else } 1.

    The best discrete ``b`` met is returned. An asymmetric ``K`` is replaced by its symmetric
    part, which has the same objective.

    Parameters
    ----------
    K : Affinity or array_like/sparse of shape (n1 n2, n1 n2)
        Affinity (pygmtools layout when a matrix).
    n1, n2 : int, optional
        Graph sizes; required when ``K`` is a matrix.
    init : {"uniform", "sm"} or array_like of shape (n1, n2), default="uniform"
        Start: the uniform matrix ``1 / max(n1, n2)`` (IPFP-U), the spectral-matching eigenvector
        (IPFP-S), or a given matrix.
    max_iter : int, default=50
        Maximum number of iterations.
    tol : float, default=1e-6
        Stop when the iterate moves less than ``tol`` (Frobenius norm).

    Returns
    -------
    MatchingResult
        ``soft`` is the final continuous iterate.

    Warns
    -----
    ConvergenceWarning
        When ``max_iter`` is reached (``converged=False``).

    References
    ----------
    M. Leordeanu, M. Hebert and R. Sukthankar, "An integer projected fixed point method for graph
    matching and MAP inference", NeurIPS 2009.

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> ipfp(K, n1=2, n2=2).assignment
    array([0, 1])
    """
    return _run(IPFPStepper(K, n1=n1, n2=n2, init=init, max_iter=max_iter, tol=tol))
