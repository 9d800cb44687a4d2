"""Result of permutation synchronization (multi-matching stored as universe labels)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["PermutationSyncResult"]


@dataclass(frozen=True)
class PermutationSyncResult:
    """Synchronized multi-matching.

    Attributes
    ----------
    labels : tuple of ndarray
        ``labels[g][u]`` is the universe id (``0 .. n_universe - 1``) of node ``u`` of object ``g``
        (``-1`` = not placed). The maps derived from it are cycle-consistent by construction.
    n_universe : int
        Universe size ``d`` (summed over components when the observation graph is disconnected).
    objective : float
        ``sum over observed pairs of w_ij * <P_ij^obs, X_i X_j^T>``: the weighted number of observed
        correspondences that the output keeps.
    n_iter : int
        Iterations of the method (eigensolver products, polar sweeps, ...; see ``info``).
    converged : bool
    cycle_consistent : bool
        ``True`` for every method except ``"matcheig"``, whose ``pairwise(i, j)`` are rounded
        block by block and need not be consistent; ``labels`` is then the consistent rounding of
        the same eigenvectors (what ``method="spectral"`` would return).
    info : dict
        Method details: ``"method"``, ``"solver"`` (dense / matrix_free), ``"components"``,
        ``"n_universe_estimate"``, ``"n_universe_rule"``, ``"n_universe_candidates"``,
        ``"eigenvalues"``, ``"candidates"``/``"chosen"`` (``"orthogonal"``: objectives of the
        refined spectral and polar roundings), ``"discrete_objective_history*"``,
        ``"node_scores"``/``"n_unplaced"`` (with ``min_score``), ``"input_consistency"``
        (the triangle report
        of :func:`transync.permutations.cycle_inconsistency`), ``"input_disagreement"`` (fraction of
        observed correspondences the output drops), timings.
    """

    labels: tuple[np.ndarray, ...]
    n_universe: int
    objective: float
    n_iter: int
    converged: bool
    cycle_consistent: bool = True
    info: Mapping[str, Any] = field(default_factory=dict)
    _pairwise_fn: Callable[[int, int], np.ndarray] | None = field(default=None, repr=False,
                                                                   compare=False)

    @property
    def n_objects(self) -> int:
        return len(self.labels)

    @property
    def sizes(self) -> np.ndarray:
        return np.array([lab.size for lab in self.labels], dtype=np.int64)

    def _check(self, g: int, name: str) -> int:
        if not (0 <= int(g) < self.n_objects):
            raise ValueError(f"`{name}` must be an object index in [0, {self.n_objects}), got {g}")
        return int(g)

    def pairwise(self, i: int, j: int) -> np.ndarray:
        """Assignment from object ``i`` to object ``j`` (``-1`` = no partner in ``j``)."""
        i = self._check(i, "i")
        j = self._check(j, "j")
        if self._pairwise_fn is not None:
            return self._pairwise_fn(i, j)
        inv = np.full(self.n_universe + 1, -1, dtype=np.int64)
        lab_j = self.labels[j]
        placed = lab_j >= 0
        inv[lab_j[placed]] = np.flatnonzero(placed)
        return inv[self.labels[i]]           # label -1 -> inv[-1] = -1

    def pairwise_dict(self, pairs=None) -> dict[tuple[int, int], np.ndarray]:
        """``{(i, j): pairwise(i, j)}`` for ``pairs`` (default: every ``i < j``)."""
        if pairs is None:
            pairs = zip(*np.triu_indices(self.n_objects, 1))
        return {(int(i), int(j)): self.pairwise(int(i), int(j)) for i, j in pairs}

    def absolute(self, g: int) -> np.ndarray:
        """The ``(n_g, n_universe)`` 0/1 matrix ``X_g`` (node -> universe slot)."""
        g = self._check(g, "g")
        lab = self.labels[g]
        X = np.zeros((lab.size, self.n_universe))
        rows = np.flatnonzero(lab >= 0)
        X[rows, lab[rows]] = 1.0
        return X

    def to_matrix(self) -> np.ndarray:
        """The ``(sum n_g, sum n_g)`` block matrix with blocks ``P_ij`` (identity on the diagonal).

        For ``cycle_consistent`` results it equals ``X X^T`` with ``X`` the stacked absolute maps.
        Meant for small problems.
        """
        sizes = self.sizes
        off = np.concatenate([[0], np.cumsum(sizes)])
        total = int(off[-1])
        if total > 20000:
            raise ValueError(f"to_matrix() would build a {total} x {total} matrix; use "
                             "pairwise(i, j) for large problems")
        if self._pairwise_fn is None:
            X = np.vstack([self.absolute(g) for g in range(self.n_objects)])
            T = X @ X.T
            np.fill_diagonal(T, 1.0)
            return T
        T = np.eye(total)
        for i in range(self.n_objects):
            for j in range(self.n_objects):
                if i == j:
                    continue
                a = self.pairwise(i, j)
                r = np.flatnonzero(a >= 0)
                T[off[i] + r, off[j] + a[r]] = 1.0
        return T
