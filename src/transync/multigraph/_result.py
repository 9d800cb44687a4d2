"""Result of multi-graph matching: every pair's final map, universe labels when consistent."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..permutations import MultiMatching, assignment_to_matrix

__all__ = ["MultiMatchingResult"]


@dataclass(frozen=True)
class MultiMatchingResult:
    """Node correspondences among ``N`` graphs of ``n`` nodes, from :func:`match_collection`.

    Attributes
    ----------
    pairs : ndarray of shape (P, 2)
        The matched pairs ``(i, j)``, ``i < j``.
    assignments : ndarray of shape (P, n_max)
        ``assignments[p][u]`` is the node of graph ``pairs[p, 1]`` matched to node ``u`` of graph
        ``pairs[p, 0]`` (``-1``: unmatched; graphs of different sizes: row ``p`` holds
        ``sizes[pairs[p, 0]]`` entries, then ``-1`` padding).
    matching : MultiMatching or None
        Universe labels when the output is cycle-consistent by construction (every synchronized
        method), else ``None`` (plain pairwise matching, CAO): then only the observed pairs have
        maps. The type of the result never depends on the method.
    scores : ndarray of shape (P,)
        Affinity score ``x^T K x`` of every pair's final map.
    total_score : float
        ``scores.sum()``.
    consistency : float
        ``1 - cycle_error`` of the output maps over the triangles of observed pairs (1.0 for a
        consistent output).
    input_consistency : float
        The same for the maps of the pairwise stage, before synchronization or CAO. For the
        online solvers: of the per-pair roundings of the iterates at the first synchronization
        point (so it depends on ``sync_every``; not comparable with the offline value).
    timings : dict
        Seconds per stage (``"affinity"``, ``"pairwise"``, ``"sync"``, ``"refine"``, ``"cao"``,
        ``"total"``; the stages that ran).
    solver, sync, mode : str or None
        The method, as run (``mode="offline"`` whenever the pairs were solved independently:
        ``sync=None``, CAO, ``sm``/``ipfp``).
    n_iter : int
        Outer iterations of the pairwise (lock-step) stage.
    converged : bool
        Whether every pairwise solver met its stopping criterion (else a
        ``ConvergenceWarning`` was issued).
    n_graphs : int
        ``N``.
    info : dict
        Details per stage (number of synchronization calls, CAO history, ``"n_universe_rule"``
        when synchronized, ``"soft"``: the pairwise stage's final soft blocks ``(P, n_max,
        n_max)`` (the solvers' last iterates, online the synchronized ones, made exactly doubly
        stochastic between the padded graphs, then cut to the real nodes: block ``p`` is
        sub-doubly stochastic and zero beyond ``n_i x n_j``; 0/1 for ``sm`` / ``ipfp``; absent
        for CAO) ...).
    sizes : ndarray of shape (N,), int
        Number of nodes of every graph (default: ``n`` for all, the width of ``assignments``).

    Examples
    --------
    >>> import functools
    >>> from transync import match_collection
    >>> from transync.datasets import make_graph_collection
    >>> from transync.matching import gaussian_edge_affinity
    >>> p = make_graph_collection(n_graphs=3, n_inliers=5, deformation=0.0, rng=0)
    >>> res = match_collection(p.graphs, affinity=functools.partial(gaussian_edge_affinity,
    ...                                                             sigma2=0.05), progress=False)
    >>> res.accuracy(p.ground_truth), res.pairwise(0, 1).shape
    (1.0, (5,))
    """

    pairs: np.ndarray
    assignments: np.ndarray
    matching: MultiMatching | None
    scores: np.ndarray
    total_score: float
    consistency: float
    input_consistency: float
    timings: dict
    solver: str
    sync: str | None
    mode: str
    n_iter: int
    converged: bool
    n_graphs: int
    info: dict[str, Any] = field(default_factory=dict)
    sizes: np.ndarray | None = None

    def __post_init__(self):
        if self.sizes is None:
            object.__setattr__(self, "sizes", np.full(self.n_graphs,
                                                      np.shape(self.assignments)[1]))
        for name in ("pairs", "assignments", "scores", "sizes"):   # read-only, like MultiMatching
            arr = np.array(getattr(self, name))
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    @property
    def n_nodes(self) -> int:
        """The largest graph's number of nodes (the width of ``assignments``)."""
        return int(self.assignments.shape[1])

    @property
    def n_universe(self) -> int | None:
        """Universe size of a consistent output (``None`` when nothing was synchronized)."""
        return None if self.matching is None else int(self.matching.n_universe)

    def _index(self) -> dict[tuple[int, int], int]:
        return {(int(i), int(j)): p for p, (i, j) in enumerate(self.pairs.tolist())}

    def pairwise(self, i: int, j: int) -> np.ndarray:
        """The map from graph ``i`` to graph ``j``: ``(n_i,)`` node indices of ``j`` (-1:
        unmatched).

        From the universe labels when the output is consistent (every pair, observed or not),
        otherwise from the observed pair (inverted for ``i > j``).
        """
        N = self.n_graphs
        for name, g in (("i", i), ("j", j)):
            if isinstance(g, bool) or not isinstance(g, (int, np.integer)) or not 0 <= g < N:
                raise ValueError(f"`{name}` must be a graph index in [0, {N}), got {g!r}")
        if i == j:
            return np.arange(int(self.sizes[i]))
        if self.matching is not None:
            return self.matching.pairwise(int(i), int(j))
        a, b = (int(i), int(j)) if i < j else (int(j), int(i))
        p = self._index().get((a, b))
        if p is None:
            raise ValueError(f"pair ({i}, {j}) was not matched: the output is not consistent "
                             "(no universe labels), so only the pairs in `pairs` have maps")
        m = self.assignments[p, :self.sizes[a]]
        if i < j:
            return m.copy()
        inv = np.full(int(self.sizes[b]), -1, dtype=np.int64)
        ok = m >= 0
        inv[m[ok]] = np.flatnonzero(ok)
        return inv

    def pairwise_dict(self) -> dict[tuple[int, int], np.ndarray]:
        """``{(i, j): assignment}`` over the matched pairs (the input of the metrics)."""
        return {(int(i), int(j)): self.assignments[p, :self.sizes[i]].copy()
                for p, (i, j) in enumerate(self.pairs.tolist())}

    def to_matrix(self) -> np.ndarray:
        """``(sum n_i, sum n_i)`` 0/1 block matrix of all pairwise maps (identity blocks on the
        diagonal; blocks of unmatched pairs are zero when the output is not consistent)."""
        if self.matching is not None:
            return self.matching.to_matrix()
        sizes = self.sizes.tolist()
        off = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        M = np.zeros((off[-1], off[-1]))
        for g, k in enumerate(sizes):
            M[off[g]:off[g + 1], off[g]:off[g + 1]] = np.eye(k)
        for p, (i, j) in enumerate(self.pairs.tolist()):
            B = assignment_to_matrix(self.assignments[p, :sizes[i]], sizes[j])
            M[off[i]:off[i + 1], off[j]:off[j + 1]] = B
            M[off[j]:off[j + 1], off[i]:off[i + 1]] = B.T
        return M

    def accuracy(self, truth) -> float:
        """Fraction of the true correspondences recovered, over the matched pairs.

        ``truth``: a :class:`~transync.permutations.MultiMatching` (or labels, or a generator's
        ``.ground_truth``). The same number as
        ``transync.metrics.multimatching_accuracy(self.pairwise_dict(), truth, pairs=self.pairs)``.
        """
        truth = getattr(truth, "ground_truth", truth)
        try:
            m = MultiMatching.from_labels(truth)
        except (TypeError, ValueError) as exc:
            raise type(exc)(f"`truth` must be a MultiMatching or universe labels of the "
                            f"{self.n_graphs} graphs: {exc}") from None
        if m.n_objects != self.n_graphs or not np.array_equal(m.sizes, self.sizes):
            raise ValueError(f"`truth` must label the {self.n_graphs} graphs of this result, of "
                             f"{self.sizes.tolist()} nodes, got {m.n_objects} objects of "
                             f"{m.sizes.tolist()} nodes")
        return m.accuracy(self.pairwise_dict(), pairs=self.pairs)

    def __repr__(self) -> str:
        return (f"MultiMatchingResult(solver={self.solver!r}, sync={self.sync!r}, "
                f"mode={self.mode!r}, n_graphs={self.n_graphs}, n_nodes={self.n_nodes}, "
                f"n_pairs={len(self.pairs)}, consistency={self.consistency:.3f}, "
                f"total_score={self.total_score:.4g})")
