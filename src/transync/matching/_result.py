"""The result of a pairwise matching solver.

Examples
--------
>>> import numpy as np
>>> from transync.matching import hungarian
>>> res = hungarian(np.array([[0.1, 0.9], [0.8, 0.2], [0.0, 0.3]]))
>>> res.assignment
array([ 1,  0, -1])
>>> res.to_matrix().astype(int)
array([[0, 1],
       [1, 0],
       [0, 0]])
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..permutations import assignment_to_matrix

__all__ = ["MatchingResult"]


@dataclass(frozen=True, slots=True)
class MatchingResult:
    """Output of every pairwise matching solver.

    Attributes
    ----------
    assignment : ndarray of shape (n1,), int
        ``assignment[i] = a`` matches node ``i`` of the first graph to node ``a`` of the second;
        ``-1`` marks an unmatched node.
    soft : ndarray of shape (n1, n2) or None
        The relaxed (continuous) solution the assignment was rounded from, where the method has
        one (for the iterative QAP solvers: the final (sub-)doubly-stochastic iterate).
    objective : float
        Objective of the *discrete* assignment: ``vec(X)^T K vec(X)`` for the quadratic solvers,
        ``sum_i S[i, assignment[i]]`` for the linear ones.
    n_iter : int
        Outer iterations performed (0 for closed-form methods).
    converged : bool
        Whether the stopping tolerance was met before the iteration limit.
    method : str
        Name of the solver.
    n2 : int or None
        Number of nodes of the second graph (used by :meth:`to_matrix`).
    info : dict
        Method-specific details (iteration counts of inner loops, normalisation constants, ...).

    Examples
    --------
    >>> import numpy as np
    >>> from transync.matching import sm
    >>> res = sm(np.ones((4, 4)) + 3 * np.eye(4), n1=2, n2=2)
    >>> res.assignment.shape, res.soft.shape, res.method
    ((2,), (2, 2), 'sm')
    >>> int(res.to_matrix(2).sum())
    2
    """

    assignment: np.ndarray
    soft: np.ndarray | None
    objective: float
    n_iter: int
    converged: bool
    method: str = ""
    n2: int | None = None
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def n1(self) -> int:
        return int(self.assignment.shape[0])

    def to_matrix(self, n2: int | None = None) -> np.ndarray:
        """The 0/1 matching matrix of shape ``(n1, n2)``."""
        if n2 is None:
            n2 = self.n2
        if n2 is None and self.soft is not None:
            n2 = self.soft.shape[1]
        if n2 is None:
            n2 = int(self.assignment.max(initial=-1)) + 1
        return assignment_to_matrix(self.assignment, n2)

    def __repr__(self) -> str:
        return (f"MatchingResult(method={self.method!r}, n1={self.n1}, n2={self.n2}, "
                f"objective={self.objective:.6g}, n_iter={self.n_iter}, "
                f"converged={self.converged})")
