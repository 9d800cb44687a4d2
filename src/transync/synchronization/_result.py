"""Result of permutation synchronization (multi-matching stored as a :class:`MultiMatching`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..permutations import MultiMatching, solve_lap

__all__ = ["PermutationSyncResult"]


class CarriesMatching:
    """Mixin (private) for results that hold a ``matching: MultiMatching``: its shape attributes."""

    __slots__ = ()

    @property
    def labels(self) -> tuple[np.ndarray, ...]:
        """``labels[g][u]``: universe slot of node ``u`` of object ``g`` (``-1`` = not placed)."""
        return self.matching.labels

    @property
    def n_universe(self) -> int:
        """Universe size ``d`` (summed over components when the observation graph is
        disconnected)."""
        return self.matching.n_universe

    @property
    def n_objects(self) -> int:
        return self.matching.n_objects

    @property
    def sizes(self) -> np.ndarray:
        return self.matching.sizes


@dataclass(frozen=True)
class BlockRounding:
    """MatchEIG pairwise maps (private): Hungarian on ``V_i V_j^T`` of row-normalized embeddings.

    Plain data (picklable): ``embeddings[c]`` holds the row-normalized eigenvectors of connected
    component ``c`` (``None`` for a single object), ``component[g]`` / ``local[g]`` place object
    ``g`` in its component, ``offsets[c]`` are the row offsets of the component's objects.
    Matches scoring below ``threshold`` are dropped, and so are the nodes of ``dropped[g]``
    (those ``min_score`` left unplaced; empty without it).
    """

    embeddings: tuple
    offsets: tuple
    component: np.ndarray
    local: np.ndarray
    sizes: np.ndarray
    threshold: float
    dropped: tuple = ()

    def __call__(self, i: int, j: int) -> np.ndarray:
        if i == j:
            # every node is its own partner (as in to_matrix), unless min_score left it
            # unplaced (as in MultiMatching.pairwise)
            out = np.arange(int(self.sizes[i]), dtype=np.int64)
            if self.dropped:
                out[self.dropped[i]] = -1
            return out
        ci, cj = int(self.component[i]), int(self.component[j])
        V = self.embeddings[ci]
        if ci != cj or V is None:
            return np.full(int(self.sizes[i]), -1, dtype=np.int64)
        off = self.offsets[ci]
        li, lj = int(self.local[i]), int(self.local[j])
        out = solve_lap(V[off[li]:off[li + 1]] @ V[off[lj]:off[lj + 1]].T,
                        min_score=self.threshold)
        if self.dropped:
            out[self.dropped[i]] = -1
            out[(out >= 0) & self.dropped[j][np.maximum(out, 0)]] = -1
        return out


@dataclass(frozen=True)
class PermutationSyncResult(CarriesMatching):
    """Synchronized multi-matching.

    Attributes
    ----------
    matching : MultiMatching
        The consistent multi-matching: ``matching.labels[g][u]`` is the universe id of node ``u``
        of object ``g`` (``-1`` = not placed). ``labels``, ``n_universe``, ``sizes``,
        ``absolute`` delegate to it.
    objective : float
        ``sum over observed pairs of w_ij * <P_ij^obs, X_i X_j^T>``: the weighted number of observed
        correspondences that the output keeps.
    n_iter : int
        Iterations of the method (eigensolver products, polar sweeps, ...; see ``info``).
    converged : bool
    cycle_consistent : bool
        ``True`` for every method except ``"matcheig"``, whose ``pairwise(i, j)`` are rounded
        block by block and need not be consistent; ``matching`` is then the consistent rounding
        of the same eigenvectors (what ``method="spectral"`` would return).
    info : dict
        Method details: ``"method"``, ``"solver"`` (dense / matrix_free), ``"components"``,
        ``"n_universe_estimate"``, ``"n_universe_rule"``, ``"n_universe_candidates"``,
        ``"eigenvalues"``, ``"candidates"``/``"chosen"`` (``"orthogonal"``: objectives of the
        refined spectral and polar roundings), ``"discrete_objective_history*"``,
        ``"node_scores"``/``"n_unplaced"`` (with ``min_score``), ``"input_consistency"``
        (the triangle report
        of :func:`transync.permutations.cycle_inconsistency`), ``"input_disagreement"`` (fraction of
        observed correspondences the output drops), timings.

    The result pickles (every method), so it can cross process and Dask executors.

    Examples
    --------
    >>> from transync.datasets import make_permutation_collection
    >>> from transync.synchronization import synchronize_permutations
    >>> res = synchronize_permutations(make_permutation_collection(4, 5, rng=0).pairwise)
    >>> res.n_universe, res.cycle_consistent, res.pairwise(0, 1).shape
    (5, True, (5,))
    """

    matching: MultiMatching
    objective: float
    n_iter: int
    converged: bool
    cycle_consistent: bool = True
    info: Mapping[str, Any] = field(default_factory=dict)
    _block_rounding: BlockRounding | None = field(default=None, repr=False, compare=False)

    def pairwise(self, i: int, j: int) -> np.ndarray:
        """Assignment from object ``i`` to object ``j`` (``-1`` = no partner in ``j``)."""
        if self._block_rounding is None:
            return self.matching.pairwise(i, j)
        self.matching.pairwise(i, j)                      # validates i and j
        return self._block_rounding(int(i), int(j))

    def pairwise_dict(self, pairs=None) -> dict[tuple[int, int], np.ndarray]:
        """``{(i, j): pairwise(i, j)}`` for ``pairs`` (default: every ``i < j``)."""
        if self._block_rounding is None:
            return self.matching.pairwise_dict(pairs)
        keys = self.matching.pairwise_dict(pairs)         # validates pairs
        return {(i, j): self._block_rounding(i, j) for i, j in keys}

    def absolute(self, g: int) -> np.ndarray:
        """The ``(n_g, n_universe)`` 0/1 matrix ``X_g`` (node -> universe slot)."""
        return self.matching.absolute(g)

    def to_matrix(self) -> np.ndarray:
        """The ``(sum n_g, sum n_g)`` block matrix with blocks ``P_ij`` (identity on the diagonal).

        For ``cycle_consistent`` results it equals ``X X^T`` with ``X`` the stacked absolute maps
        (:meth:`MultiMatching.to_matrix`); for ``"matcheig"`` the blocks are its block-wise
        roundings. Meant for small problems.
        """
        if self._block_rounding is None:
            return self.matching.to_matrix()
        sizes = self.sizes
        off = np.concatenate([[0], np.cumsum(sizes)])
        total = int(off[-1])
        if total > 20000:
            raise ValueError(f"to_matrix() would build a {total} x {total} matrix; use "
                             "pairwise(i, j) for large problems")
        T = np.eye(total)
        for i in range(self.n_objects):
            for j in range(self.n_objects):
                if i == j:
                    continue
                a = self.pairwise(i, j)
                r = np.flatnonzero(a >= 0)
                T[off[i] + r, off[j] + a[r]] = 1.0
        return T
