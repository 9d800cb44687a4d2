"""Linear assignment: Hungarian rounding and log-domain Sinkhorn with slack.

Examples
--------
>>> import numpy as np
>>> from transync.matching import hungarian, sinkhorn
>>> S = np.array([[0.9, 0.1, 0.0], [0.2, 0.7, 0.1]])
>>> hungarian(S).assignment
array([0, 1])
>>> res = sinkhorn(S, tau=0.1)
>>> res.assignment, np.round(res.soft.sum(1), 6)
(array([0, 1]), array([1., 1.]))
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp

from .._validation import (MAX_ITER, check_affinity_magnitude, check_array, check_bool, check_int,
                           check_positive)
from ..exceptions import ConvergenceWarning
from ..permutations import assignment_to_matrix, solve_lap
from ._affinity import Affinity, as_affinity
from ._result import MatchingResult
from ._sinkhorn import sinkhorn_normalize

__all__ = ["hungarian", "sinkhorn"]


def _score_matrix(scores, n1, n2, name: str = "scores"):
    """``(S, affinity)``: a score matrix, and the Affinity it came from (or None).

    An :class:`Affinity`, or a matrix of shape ``(n1 n2, n1 n2)`` with ``n1``/``n2`` given, is a
    Lawler ``K``; its diagonal (the unary term) is the score matrix.
    """
    n1 = None if n1 is None else check_int(n1, "n1", minimum=1)
    n2 = None if n2 is None else check_int(n2, "n2", minimum=1)
    if isinstance(scores, Affinity):
        aff = as_affinity(scores, n1=n1, n2=n2, name=name)
        return aff.diag(), aff
    if sp.issparse(scores) or (n1 is not None and n2 is not None
                               and np.shape(scores) == (n1 * n2, n1 * n2) and (n1, n2) != (1, 1)):
        aff = as_affinity(scores, n1=n1, n2=n2, name=name)
        return aff.diag(), aff
    S = check_array(scores, name, ndim=2)
    if (n1 is not None and S.shape[0] != n1) or (n2 is not None and S.shape[1] != n2):
        raise ValueError(f"`{name}` must have shape (n1, n2) = ({n1}, {n2}) or be a Lawler K of "
                         f"shape (n1*n2, n1*n2), got {S.shape}")
    if S.shape[0] == 0 or S.shape[1] == 0:
        raise ValueError(f"`{name}` must be non-empty, got shape {S.shape}")
    check_affinity_magnitude(np.max(np.abs(S)), S.size, name)     # objectives stay finite
    return S, None


def _linear_objective(S, aff, assignment) -> float:
    if aff is not None:
        return aff.score(assignment_to_matrix(assignment, aff.n2))
    rows = np.flatnonzero(assignment >= 0)
    return float(S[rows, assignment[rows]].sum())


def hungarian(scores, *, n1: int | None = None, n2: int | None = None,
              maximize: bool = True) -> MatchingResult:
    """Optimal linear assignment (rectangular Hungarian algorithm).

    .. math:: \\max_X \\sum_{ia} S_{ia} X_{ia} \\quad \\text{over partial permutations } X
              \\text{ matching } \\min(n_1, n_2) \\text{ nodes.}

    Parameters
    ----------
    scores : array_like of shape (n1, n2), Affinity, or Lawler K of shape (n1 n2, n1 n2)
        Score matrix. Given an :class:`Affinity` (or a matrix ``K`` with ``n1`` and ``n2``), its
        diagonal, the unary term, is used.
    n1, n2 : int, optional
        Graph sizes; required when ``scores`` is a Lawler ``K`` matrix.
    maximize : bool, default=True
        Maximize the total score (``False``: minimize a cost).

    Returns
    -------
    MatchingResult
        ``soft`` is None; ``objective`` is the linear score (for an affinity:
        ``vec(X)^T K vec(X)``).
        When ``n1 > n2`` the ``n1 - n2`` left-over rows are ``-1``.

    Raises
    ------
    ValueError
        Empty, non-finite or mis-shaped input.

    Examples
    --------
    >>> import numpy as np
    >>> hungarian(np.array([[1.0, 5.0], [4.0, 2.0]])).assignment
    array([1, 0])
    """
    check_bool(maximize, "maximize")
    S, aff = _score_matrix(scores, n1, n2)
    assignment = solve_lap(S, maximize=bool(maximize))
    return MatchingResult(assignment=assignment, soft=None,
                          objective=_linear_objective(S, aff, assignment), n_iter=0,
                          converged=True, method="hungarian", n2=S.shape[1])


def sinkhorn(scores, *, n1: int | None = None, n2: int | None = None, tau: float = 1.0,
             max_iter: int = 1000, tol: float = 1e-6) -> MatchingResult:
    """Entropic linear assignment by log-domain Sinkhorn iterations, then Hungarian rounding.

    Computes ``X = diag(exp f) exp(S / tau) diag(exp g)`` with unit row and column sums. When
    ``n1 != n2`` a slack row (``n1 < n2``) or slack column (``n1 > n2``) with mass ``|n2 - n1|`` and
    neutral score absorbs the surplus, so the larger side is sub-stochastic (sums <= 1), the smaller
    side stochastic -- the convention of Cho et al.'s RRWM code.

    Parameters
    ----------
    scores : array_like of shape (n1, n2), Affinity, or Lawler K of shape (n1 n2, n1 n2)
        Score matrix (an affinity's diagonal is used, as in :func:`hungarian`).
    n1, n2 : int, optional
        Graph sizes; required when ``scores`` is a Lawler ``K`` matrix.
    tau : float, default=1.0
        Temperature; smaller is closer to the Hungarian solution.
    max_iter : int, default=1000
        Maximum number of (row + column) normalisation sweeps.
    tol : float, default=1e-6
        Stop when every row sum is within ``tol`` of its target (columns are exact after a sweep).

    Returns
    -------
    MatchingResult
        ``soft`` is the (sub-)doubly-stochastic matrix, ``assignment`` its Hungarian rounding,
        ``info["marginal_error"]`` the final row-sum error.

    Warns
    -----
    ConvergenceWarning
        When ``max_iter`` sweeps do not reach ``tol`` (``converged=False``).

    Examples
    --------
    >>> import numpy as np
    >>> res = sinkhorn(np.array([[2.0, 0.0], [0.0, 2.0], [1.0, 1.0]]))
    >>> res.assignment, np.round(res.soft.sum(0), 6)
    (array([ 0,  1, -1]), array([1., 1.]))
    """
    S, aff = _score_matrix(scores, n1, n2)
    tau = check_positive(tau, "tau")
    max_iter = check_int(max_iter, "max_iter", minimum=1, maximum=MAX_ITER)
    tol = check_positive(tol, "tol")
    with np.errstate(over="ignore"):
        L = S / tau
    if not np.all(np.isfinite(L)):
        raise ValueError(f"`tau`={tau!r} makes scores / tau overflow (largest |score| "
                         f"{np.max(np.abs(S)):.3g}): pass a larger `tau`")
    out = sinkhorn_normalize(L, domain="log", slack="mass", tol=tol, max_iter=max_iter)
    X, n_iter, err, converged = out.X, out.n_sweeps, out.error, out.converged
    if not converged:
        span = float(np.ptp(L)) if L.size else 0.0
        reachable = 64 * np.finfo(float).eps * max(S.shape)   # rounding of a row sum
        why = (f"after max_iter={max_iter} sweeps" if n_iter >= max_iter else
               f"after {n_iter} sweeps: tol={tol:g} is below what float64 row sums reach "
               f"(about {reachable:.1g} here); pass a larger `tol`" if tol < reachable else
               f"after {n_iter} sweeps: scores / tau span {span:.3g}, beyond float64's "
               f"precision; pass a larger `tau`")
        warnings.warn(f"sinkhorn: row sums off by {err:.3g} > tol={tol:g} {why}",
                      ConvergenceWarning, stacklevel=2)
    assignment = solve_lap(X)
    return MatchingResult(assignment=assignment, soft=X,
                          objective=_linear_objective(S, aff, assignment), n_iter=n_iter,
                          converged=bool(converged), method="sinkhorn", n2=S.shape[1],
                          info={"marginal_error": err, "tau": tau})

