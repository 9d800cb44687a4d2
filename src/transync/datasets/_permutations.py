"""Synthetic collections of corrupted pairwise permutations with ground truth.

Every object ``g`` sees a subset of a universe of ``d`` nodes; ``labels[g][u]`` is the universe id
of its node ``u``. The true pairwise map ``i -> j`` sends ``u`` to the node of ``j`` with the same
universe id (``-1`` when ``j`` does not see it). Observed pairs are the true maps, except a chosen
fraction that is replaced by random maps.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import as_generator, check_bool, check_int, check_probability
from ..permutations import MultiMatching

__all__ = ["PermutationCollection", "make_permutation_collection"]

_MAX_ENTRIES = 2 * 10**8       # generated assignment entries (about 1.6 GB as int64)


@dataclass(frozen=True)
class PermutationCollection:
    """A collection of pairwise assignments with its ground truth.

    Attributes
    ----------
    pairwise : dict
        ``{(i, j): assignment}`` for the observed pairs, ``i < j``; ``assignment[u] = v`` maps node
        ``u`` of object ``i`` to node ``v`` of object ``j`` (``-1`` = unmatched).
    labels : tuple of ndarray
        Ground truth: ``labels[g][u]`` is the universe id of node ``u`` of object ``g``.
    sizes : ndarray of shape (n_objects,)
        Number of nodes of every object.
    n_universe : int
        Universe size ``d``.
    mask : ndarray of shape (n_objects, n_objects), bool
        Symmetric mask of the observed pairs.
    corrupted : ndarray of shape (n_objects, n_objects), bool
        Symmetric mask of the observed pairs that were replaced by random maps.
    info : dict
        The generation parameters.
    ground_truth : MultiMatching
        The ground truth as a multi-matching (built from ``labels`` and ``n_universe``);
        ``true_pairwise`` and ``accuracy`` delegate to it.

    Examples
    --------
    >>> from transync.datasets import make_permutation_collection
    >>> c = make_permutation_collection(5, 4, corruption=0.5, rng=0)
    >>> len(c.pairwise), c.n_universe, bool(c.corrupted.any())
    (10, 4, True)
    """

    pairwise: Mapping[tuple[int, int], np.ndarray]
    labels: tuple[np.ndarray, ...]
    sizes: np.ndarray
    n_universe: int
    mask: np.ndarray
    corrupted: np.ndarray
    info: Mapping[str, Any] = field(default_factory=dict)
    ground_truth: MultiMatching = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "ground_truth", MultiMatching(self.labels, self.n_universe))

    @property
    def n_objects(self) -> int:
        return len(self.labels)

    def true_pairwise(self, i: int, j: int) -> np.ndarray:
        """The ground-truth assignment from object ``i`` to object ``j``."""
        return self.ground_truth.pairwise(i, j)

    def accuracy(self, labels, *, pairs=None) -> float:
        """Fraction of ground-truth correspondences recovered by a multi-matching.

        A correspondence is a node ``u`` of ``i`` and a node ``v`` of ``j`` (``i != j``) with the
        same true universe id; it is recovered when the prediction also puts ``u`` and ``v``
        together. ``labels`` is a sequence of label arrays, a :class:`MultiMatching`, a result
        carrying one (``.matching``) or a dict of pairwise maps; see
        :meth:`MultiMatching.accuracy`. Evaluated over all pairs ``i < j`` (or the ``(P, 2)``
        array ``pairs``).
        """
        return self.ground_truth.accuracy(labels, pairs=pairs)


def _pad_labels(labels: Sequence[np.ndarray]) -> np.ndarray:
    n_max = max((len(lab) for lab in labels), default=0)
    out = np.full((len(labels), n_max), -1, dtype=np.int64)
    for g, lab in enumerate(labels):
        out[g, : len(lab)] = lab
    return out


def make_permutation_collection(n_objects: int, n_nodes: int, *, corruption: float = 0.0,
                                visibility: float = 1.0, observed: float = 1.0,
                                n_universe: int | None = None, ensure_connected: bool = True,
                                rng=None) -> PermutationCollection:
    """Generate pairwise assignments between objects that share a universe of nodes.

    Every object picks ``n_nodes`` distinct universe nodes (all of them when
    ``n_universe == n_nodes``), keeps each with probability ``visibility`` (at least one) and
    lists them in random order. Each pair ``i < j`` is observed with probability ``observed``;
    with ``ensure_connected`` the pairs of a random path through all objects are always
    observed, so the observation graph is connected. Exactly ``round(corruption * n_observed)``
    observed pairs are replaced by random maps: a uniformly random permutation when both objects
    have all ``d`` nodes, otherwise a random injective map with as many matched nodes as the
    true map.

    Parameters
    ----------
    n_objects : int
        Number of objects ``N`` (>= 2).
    n_nodes : int
        Nodes per object before visibility drops any (>= 1).
    corruption, visibility, observed : float in [0, 1]
        Fraction of corrupted pairs, node keep probability, pair observation probability.
    n_universe : int, optional
        Universe size ``n_nodes <= d <= n_objects * n_nodes``; default ``n_nodes``.
    ensure_connected : bool, default=True
        Always observe a random Hamiltonian path, so the observation graph is connected.
    rng : None, int or numpy.random.Generator
        Source of randomness.

    Returns
    -------
    PermutationCollection
        The corrupted pairwise assignments, the mask of observed pairs and the ground truth.

    Raises
    ------
    ValueError, TypeError
        Fewer than two objects, sizes that are not positive integers, fractions outside [0, 1],
        a universe smaller than ``n_nodes`` or larger than all nodes together, a collection too
        large to generate, a non-bool ``ensure_connected``.

    Examples
    --------
    >>> from transync.datasets import make_permutation_collection
    >>> c = make_permutation_collection(4, 5, corruption=0.0, rng=0)
    >>> len(c.pairwise), c.n_universe
    (6, 5)
    >>> bool((c.pairwise[(0, 1)] == c.true_pairwise(0, 1)).all())
    True
    """
    n_objects = check_int(n_objects, "n_objects", minimum=2)
    n_nodes = check_int(n_nodes, "n_nodes", minimum=1)
    corruption = check_probability(corruption, "corruption")
    visibility = check_probability(visibility, "visibility")
    observed = check_probability(observed, "observed")
    d = n_nodes if n_universe is None else check_int(n_universe, "n_universe", minimum=1)
    if d < n_nodes:
        raise ValueError(f"`n_universe` must be >= n_nodes={n_nodes}, got {d}")
    if d > n_objects * n_nodes:
        raise ValueError(f"`n_universe` must be <= n_objects * n_nodes = {n_objects * n_nodes} "
                         f"(more slots than nodes are never used), got {d}")
    entries = n_objects * (n_objects - 1) // 2 * n_nodes
    if entries > _MAX_ENTRIES:
        raise ValueError(f"`n_objects`={n_objects} and `n_nodes`={n_nodes} would generate "
                         f"{entries:.3g} assignment entries (more than {_MAX_ENTRIES:.0e}); "
                         "use fewer objects or nodes")
    check_bool(ensure_connected, "ensure_connected")
    gen = as_generator(rng)

    # node sets and orders
    if d == n_nodes and visibility == 1.0:
        padded = gen.permuted(np.tile(np.arange(d), (n_objects, 1)), axis=1).astype(np.int64)
        full = True
    else:
        rows = []
        for _ in range(n_objects):
            chosen = gen.choice(d, size=n_nodes, replace=False)
            keep = gen.random(n_nodes) < visibility
            if not keep.any():
                keep[gen.integers(n_nodes)] = True
            rows.append(gen.permutation(chosen[keep]))
        padded = _pad_labels(rows)
        full = bool(np.all(padded >= 0)) and padded.shape[1] == d
    sizes = (padded >= 0).sum(1)
    labels = tuple(padded[g, : sizes[g]].copy() for g in range(n_objects))

    # observed pairs
    iu, ju = np.triu_indices(n_objects, 1)
    obs = gen.random(iu.size) < observed
    if ensure_connected and observed < 1.0:
        path = gen.permutation(n_objects)
        a, b = np.minimum(path[:-1], path[1:]), np.maximum(path[:-1], path[1:])
        # index of pair (a, b) in triu order
        idx = a * n_objects - a * (a + 1) // 2 + (b - a - 1)
        obs[idx] = True
    pairs = np.column_stack([iu[obs], ju[obs]]).astype(np.int64)
    n_pairs = pairs.shape[0]

    truth = MultiMatching(labels, d)
    maps = truth.pairwise_array(pairs).copy()                     # (P, n_max), -1 at padding
    n_bad = int(round(corruption * n_pairs))
    bad = np.zeros(n_pairs, dtype=bool)
    if n_bad:
        bad_idx = gen.choice(n_pairs, size=n_bad, replace=False)
        bad[bad_idx] = True
        if full:
            maps[bad_idx] = gen.permuted(np.tile(np.arange(d), (n_bad, 1)), axis=1)
        else:
            for p in bad_idx:
                i, j = pairs[p]
                m = int((maps[p, : sizes[i]] >= 0).sum())
                new = np.full(maps.shape[1], -1, dtype=np.int64)
                src = gen.choice(sizes[i], size=m, replace=False)
                new[src] = gen.choice(sizes[j], size=m, replace=False)
                maps[p] = new
    pairwise = {(int(i), int(j)): maps[p, : sizes[i]]
                for p, (i, j) in enumerate(pairs.tolist())}
    mask = np.zeros((n_objects, n_objects), dtype=bool)
    mask[pairs[:, 0], pairs[:, 1]] = True
    mask |= mask.T
    corrupted = np.zeros_like(mask)
    corrupted[pairs[bad, 0], pairs[bad, 1]] = True
    corrupted |= corrupted.T
    info = {"n_objects": n_objects, "n_nodes": n_nodes, "corruption": corruption,
            "visibility": visibility, "observed": observed, "n_pairs": n_pairs,
            "n_corrupted": n_bad, "full_permutations": full}
    return PermutationCollection(pairwise=pairwise, labels=labels, sizes=sizes.astype(np.int64),
                                 n_universe=d, mask=mask, corrupted=corrupted, info=info)
