"""Reweighted random walks for graph matching (Cho, Lee & Lee, ECCV 2010).

Follows the authors' MATLAB code (``RRWM.m`` v1.22): conflicting entries of ``K`` are dropped,
``Mo = K / max column sum``, and each iteration mixes a random-walk step (weight ``c = 0.2``) with a
reweighted jump (weight ``1 - c = 0.8``) towards the Sinkhorn-normalised, exponentially amplified
current scores.

Examples
--------
>>> import numpy as np
>>> from transync.graphs import Graph
>>> from transync.matching import gaussian_edge_affinity, rrwm
>>> rng = np.random.default_rng(1)
>>> g1 = Graph.from_points(rng.random((10, 2)), edges="full")
>>> perm = rng.permutation(10)
>>> res = rrwm(gaussian_edge_affinity(g1, g1.permute(perm)))
>>> bool(np.all(perm[res.assignment] == np.arange(10))), res.converged
(True, True)
"""

from __future__ import annotations

import numpy as np

from .._validation import check_int, check_positive, check_probability
from ._affinity import as_affinity
from ._linear import _sinkhorn_scaling
from ._result import MatchingResult
from ._stepwise import _BaseStepper, _run

__all__ = ["RRWMStepper", "rrwm"]

_DEFAULTS = {"c": 0.2, "amplification": 30.0, "max_iter": 300, "tol": 1e-25,
             "sinkhorn_tol": 1e-3, "sinkhorn_max_iter": 1000}


class RRWMStepper(_BaseStepper):
    """Step-wise RRWM: one random-walk-with-reweighted-jump iteration per :meth:`step`.

    State: the walk scores ``x`` (sum 1) and the jump distribution ``y``. The public
    :attr:`iterate` is ``y`` before its sum-normalisation, i.e. the Sinkhorn output -- a
    doubly-stochastic matrix (``n1 == n2``) or, with the slack convention, one whose smaller side
    is stochastic and larger side sub-stochastic. :meth:`set_iterate` replaces ``y`` (``x`` is kept).
    The rounding uses the walk scores ``x``, as the original code does.

    Parameters are those of :func:`rrwm`.
    """

    method = "rrwm"

    def __init__(self, affinity, *, n1: int | None = None, n2: int | None = None,
                 c: float = _DEFAULTS["c"], amplification: float = _DEFAULTS["amplification"],
                 max_iter: int = _DEFAULTS["max_iter"], tol: float = _DEFAULTS["tol"],
                 sinkhorn_tol: float = _DEFAULTS["sinkhorn_tol"],
                 sinkhorn_max_iter: int = _DEFAULTS["sinkhorn_max_iter"]):
        aff = as_affinity(affinity, n1=n1, n2=n2)
        super().__init__(aff, max_iter=check_int(max_iter, "max_iter", minimum=1))
        self.c = check_probability(c, "c")
        self.amplification = check_positive(amplification, "amplification")
        self.tol = check_positive(tol, "tol")
        self.sinkhorn_tol = check_positive(sinkhorn_tol, "sinkhorn_tol")
        self.sinkhorn_max_iter = check_int(sinkhorn_max_iter, "sinkhorn_max_iter", minimum=1)
        self._walk = aff.drop_conflicts()
        self.max_degree = self._walk.max_column_sum()
        self._scale = 1.0 / self.max_degree if self.max_degree > 0 else 0.0
        size = self.n1 * self.n2
        self._x = np.full((self.n1, self.n2), 1.0 / size)       # prev_score
        self._x2 = self._x.copy()                                 # prev_score2
        self._y = np.full((self.n1, self.n2), 1.0 / size)         # prev_assign (sum 1)
        # the doubly-stochastic matrix whose normalisation is y (uniform: feasible for the slack)
        self._X = np.full((self.n1, self.n2), 1.0 / max(self.n1, self.n2))
        self.sinkhorn_sweeps = 0

    def set_iterate(self, X) -> None:
        X = self._check_iterate(X)
        total = X.sum()
        if total <= 0:
            raise ValueError("`X` must have a positive sum")
        self._X = X
        self._y = X / total
        self.converged = False

    def step(self) -> bool:
        if self.done:
            return True
        c = self.c
        x = self._walk.matvec(c * self._x + (1.0 - c) * self._y) * self._scale
        s = x.sum()
        if s > 0:
            x /= s
        xmax = x.max()
        amp = self.amplification / xmax if xmax > 0 else 0.0
        A = np.exp(amp * x)
        X, _, sweeps, _ = _sinkhorn_scaling(A, tol=self.sinkhorn_tol,
                                                  max_iter=self.sinkhorn_max_iter)
        self.sinkhorn_sweeps += sweeps
        self._X = X
        sy = X.sum()
        y = X / sy if sy > 0 else X
        diff = min(float(np.sum((x - self._x) ** 2)), float(np.sum((x - self._x2) ** 2)))
        self._x2, self._x, self._y = self._x, x, y
        self.n_iter += 1
        if diff < self.tol:
            self.converged = True
        return self.done

    def _rounding_scores(self) -> np.ndarray:
        return self._x

    def _info(self) -> dict:
        return {"scores": self._x.copy(), "max_degree": self.max_degree,
                "sinkhorn_sweeps": self.sinkhorn_sweeps}


def rrwm(K, *, n1: int | None = None, n2: int | None = None, c: float = _DEFAULTS["c"],
         amplification: float = _DEFAULTS["amplification"], max_iter: int = _DEFAULTS["max_iter"],
         tol: float = _DEFAULTS["tol"], sinkhorn_tol: float = _DEFAULTS["sinkhorn_tol"],
         sinkhorn_max_iter: int = _DEFAULTS["sinkhorn_max_iter"]) -> MatchingResult:
    """Reweighted random walks (RRWM) with the original authors' defaults.

    With ``Mo`` the conflict-free ``K`` divided by its largest column sum, iterate

    .. math:: x \\leftarrow \\frac{M_o (c\\,x + (1 - c)\\,y)}{\\mathbf 1^\\top(\\cdot)}, \\qquad
              y \\leftarrow \\frac{\\mathrm{Sinkhorn}(\\exp(\\beta x / \\max x))}{\\mathbf 1^\\top(\\cdot)}

    until ``min(||x - x_prev||^2, ||x - x_prev2||^2) < tol``, and round ``x`` with the Hungarian
    algorithm. Sinkhorn uses a slack row/column of mass ``|n2 - n1|`` when the sizes differ.

    Parameters
    ----------
    K : Affinity or array_like/sparse of shape (n1 n2, n1 n2)
        Affinity (pygmtools layout when a matrix).
    n1, n2 : int, optional
        Graph sizes; required when ``K`` is a matrix.
    c : float, default=0.2
        Weight of the random walk; ``1 - c`` weights the reweighted jump. (pygmtools' ``alpha``
        weights the jump instead: ``c = 1 - alpha``.)
    amplification : float, default=30.0
        ``beta``: the largest score is amplified to ``exp(beta)`` before Sinkhorn.
    max_iter : int, default=300
        Maximum number of iterations.
    tol : float, default=1e-25
        Convergence threshold on the squared change of the scores.
    sinkhorn_tol : float, default=1e-3
        Row-sum tolerance of the inner Sinkhorn normalisation.
    sinkhorn_max_iter : int, default=1000
        Maximum sweeps of the inner Sinkhorn normalisation.

    Returns
    -------
    MatchingResult
        ``soft`` is the last Sinkhorn output (doubly stochastic up to the slack);
        ``info["scores"]`` the walk scores that were rounded.

    Raises
    ------
    ValueError, TypeError
        Invalid ``K`` or parameters.

    Warns
    -----
    ConvergenceWarning
        When ``max_iter`` is reached (``converged=False``).

    References
    ----------
    M. Cho, J. Lee and K. M. Lee, "Reweighted random walks for graph matching", ECCV 2010.

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> rrwm(K, n1=2, n2=2).assignment
    array([0, 1])
    """
    return _run(RRWMStepper(K, n1=n1, n2=n2, c=c, amplification=amplification,
                            max_iter=max_iter, tol=tol, sinkhorn_tol=sinkhorn_tol,
                            sinkhorn_max_iter=sinkhorn_max_iter))
