"""Spectral matching (Leordeanu & Hebert, ICCV 2005).

Examples
--------
>>> import numpy as np
>>> from transync.graphs import Graph
>>> from transync.matching import gaussian_edge_affinity, sm
>>> rng = np.random.default_rng(0)
>>> g1 = Graph.from_points(rng.random((8, 2)), edges="full")
>>> perm = rng.permutation(8)
>>> res = sm(gaussian_edge_affinity(g1, g1.permute(perm)))
>>> bool(np.all(perm[res.assignment] == np.arange(8)))
True
"""

from __future__ import annotations

import numpy as np

from .._validation import MAX_ITER, check_int, check_positive
from ._affinity import as_affinity
from ._result import MatchingResult
from ._stepwise import _BaseStepper, _moderate, _run, _symmetric

__all__ = ["SMStepper", "sm"]

_DEFAULTS = {"max_iter": 100, "tol": 1e-5}


class SMStepper(_BaseStepper):
    """Step-wise spectral matching: one power iteration per :meth:`step`.

    The iterate is the current unit-norm eigenvector estimate, reshaped to ``(n1, n2)``. The first
    step starts from the uniform vector ``1 / (n1 n2)`` exactly as pygmtools does, so that the two
    produce the same iterates on the same ``K``.

    Parameters
    ----------
    affinity : Affinity or array_like/sparse of shape (n1 n2, n1 n2)
        The affinity ``K``.
    n1, n2 : int, optional
        Graph sizes; required when ``affinity`` is a matrix.
    max_iter, tol
        As in :func:`sm`.

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)              # n1 = n2 = 2
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> s = SMStepper(K, n1=2, n2=2)
    >>> while not s.step():
    ...     pass
    >>> s.result().assignment
    array([0, 1])
    """

    method = "sm"

    def __init__(self, affinity, *, n1: int | None = None, n2: int | None = None,
                 max_iter: int = _DEFAULTS["max_iter"], tol: float = _DEFAULTS["tol"]):
        aff = as_affinity(affinity, n1=n1, n2=n2)
        super().__init__(aff, max_iter=check_int(max_iter, "max_iter", minimum=1, maximum=MAX_ITER))
        self.tol = check_positive(tol, "tol")
        self._X = np.full((self.n1, self.n2), 1.0 / (self.n1 * self.n2))
        self.eigenvalue = 0.0
        # x^T K x only sees the symmetric part: the eigenvector of (K + K^T) / 2 is the maximizer
        # (aff itself when symmetric, and unless its scale would overflow)
        self._K = _moderate(_symmetric(aff))

    def step(self) -> bool:
        if self.done:
            return True
        w = self._K.matvec(self._X)
        nrm = float(np.linalg.norm(w))
        self.n_iter += 1
        if nrm == 0.0:                      # K vec(X) = 0: nothing to learn, stop here
            self.converged = True
            return True
        self.eigenvalue = float(np.vdot(self._X, w) / np.vdot(self._X, self._X)
                                / getattr(self._K, "factor", 1.0))
        w /= nrm
        if np.linalg.norm(w - self._X) < self.tol:
            self.converged = True
        self._X = w
        return self.done

    def _info(self) -> dict:
        return {"eigenvalue": self.eigenvalue}


def sm(K, *, n1: int | None = None, n2: int | None = None, max_iter: int = _DEFAULTS["max_iter"],
       tol: float = _DEFAULTS["tol"]) -> MatchingResult:
    """Spectral matching: principal eigenvector of ``K``, rounded with the Hungarian algorithm.

    .. math:: x^\\star = \\arg\\max_{\\|x\\|_2 = 1} x^\\top K x, \\qquad
              X = \\mathrm{Hungarian}(\\mathrm{reshape}(x^\\star))

    Power iteration ``v <- K v / ||K v||`` from the uniform vector (as in pygmtools), stopped when
    ``||v_new - v|| < tol``. A non-symmetric ``K`` (directed graphs) is iterated as its symmetric
    part ``(K + K^T) / 2``, which has the same ``x^T K x``: its eigenvector is the maximizer
    above (pygmtools iterates ``K`` itself and differs there; ipfp, ga and pf symmetrize too).

    Parameters
    ----------
    K : Affinity or array_like/sparse of shape (n1 n2, n1 n2)
        Affinity (pygmtools layout when a matrix: candidate ``(i, a)`` has index ``a n1 + i``).
    n1, n2 : int, optional
        Graph sizes; required when ``K`` is a matrix.
    max_iter : int, default=100
        Maximum number of power iterations.
    tol : float, default=1e-5
        Convergence tolerance on the change of the unit eigenvector.

    Returns
    -------
    MatchingResult
        ``soft`` is the eigenvector as an ``(n1, n2)`` matrix; ``info["eigenvalue"]`` the Rayleigh
        quotient.

    Raises
    ------
    ValueError, TypeError
        Invalid ``K`` (shape, NaN/inf, negative entries) or parameters.

    Warns
    -----
    ConvergenceWarning
        When the power iteration does not converge within ``max_iter`` (``converged=False``).

    References
    ----------
    M. Leordeanu and M. Hebert, "A spectral technique for correspondence problems using pairwise
    constraints", ICCV 2005.

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)            # n1 = n2 = 2
    >>> K[1, 2] = K[2, 1] = 0.0                        # (1,0)-(0,1) conflict-free pair is weaker
    >>> sm(K, n1=2, n2=2).assignment
    array([0, 1])
    """
    return _run(SMStepper(K, n1=n1, n2=n2, max_iter=max_iter, tol=tol))
