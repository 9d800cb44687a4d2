"""Synthetic multi-subgraph matching problems: graphs of different sizes over a common universe.

The generator of thesis ch. 7 (methods page *Synthetic protocols and evaluation measures*): a
universe of ``d`` nodes with ``U(0, 1)`` edge attributes (Yan et al.'s protocol, §1.8); every graph
keeps each universe node independently with its own probability ``p``, adds outliers of its own,
deforms, sparsifies and optionally flips its edges, and shuffles its nodes. The ground truth is a
:class:`~transync.permutations.MultiMatching` into the universe (outliers ``-1``).

Examples
--------
>>> from transync.datasets import make_subgraph_collection
>>> c = make_subgraph_collection(n_graphs=4, n_universe=10, p_keep=(0.5, 1.0), n_outliers=1,
...                              rng=0)
>>> c.sizes.tolist()
[10, 6, 10, 11]
>>> c.ground_truth.n_universe
10
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .._validation import as_generator, check_bool, check_int, check_probability
from ..graphs import Graph
from ._graphs import (GraphCollectionProblem, _check_size, _sym_mask, _sym_uniform,
                      check_deformation)

__all__ = ["SubgraphCollectionProblem", "make_subgraph_collection"]


@dataclass(frozen=True)
class SubgraphCollectionProblem(GraphCollectionProblem):
    """Graphs of different sizes and their ground truth in a universe of ``n_universe`` nodes.

    A :class:`~transync.datasets.GraphCollectionProblem` whose graphs keep only part of the
    universe: ``labels[g][u]`` is the universe id of node ``u`` of graph ``g`` (``-1`` for an
    outlier), ``ground_truth`` the same as a :class:`~transync.permutations.MultiMatching` of
    universe size ``n_universe`` and ``truth(i, j)`` the true assignment ``i -> j`` (``-1`` where
    node ``u`` has no partner in ``j``). ``params["keep_probabilities"]`` holds the probability
    ``p`` drawn for every graph.

    Attributes
    ----------
    graphs : list of Graph
        The graphs.
    labels : list of ndarray of int
        ``labels[g][u]``: universe id of node ``u`` of graph ``g`` (``-1``: outlier).
    n_universe : int
        Universe size.
    params : dict
        The generator's parameters.

    Examples
    --------
    >>> from transync.datasets import make_subgraph_collection
    >>> c = make_subgraph_collection(n_graphs=3, n_universe=6, p_keep=0.5, rng=0)
    >>> c.sizes.tolist(), c.truth(0, 1).shape
    ([3, 3, 2], (3,))
    """

    @property
    def sizes(self) -> np.ndarray:
        """Number of nodes (kept universe nodes + outliers) of every graph, ``(n_graphs,)`` int."""
        return self.ground_truth.sizes

    @property
    def n_graphs(self) -> int:
        return len(self.graphs)

    def accuracy(self, prediction, *, pairs=None) -> float:
        """Fraction of the true correspondences that ``prediction`` recovers.

        ``prediction`` is anything :meth:`MultiMatching.accuracy
        <transync.permutations.MultiMatching.accuracy>` accepts (a ``MultiMatching``, labels, a
        result with ``.matching`` or a dict ``{(i, j): assignment}``).
        """
        return self.ground_truth.accuracy(prediction, pairs=pairs)


def _check_p_keep(p_keep) -> tuple[float, float]:
    """``p_keep`` as a ``(low, high)`` range in ``(0, 1]`` (a number is the range ``(p, p)``)."""
    if isinstance(p_keep, numbers.Real) and not isinstance(p_keep, bool):
        low = high = check_probability(p_keep, "p_keep", allow_zero=False)
    elif (isinstance(p_keep, (Sequence, np.ndarray)) and not isinstance(p_keep, (str, bytes))
          and len(p_keep) == 2):
        low = check_probability(p_keep[0], "p_keep[0]", allow_zero=False)
        high = check_probability(p_keep[1], "p_keep[1]", allow_zero=False)
        if low > high:
            raise ValueError(f"`p_keep` must be a range (low, high) with low <= high, got "
                             f"({low!r}, {high!r})")
    else:
        raise TypeError("`p_keep` must be a probability in (0, 1] or a (low, high) range, got "
                        f"{type(p_keep).__name__} {p_keep!r:.60}")
    return low, high


def make_subgraph_collection(n_graphs: int = 8, n_universe: int = 20, p_keep=(0.6, 1.0),
                             n_outliers: int = 0, deformation: float = 0.0, density: float = 1.0,
                             flip: float = 0.0, *, shuffle: bool = True,
                             rng=None) -> SubgraphCollectionProblem:
    """Graphs of different sizes drawn from one universe (thesis ch. 7), with ground truth.

    The universe has ``n_universe`` nodes and symmetric edge attributes ``U(0, 1)``. Graph ``g``
    draws ``p ~ U(low, high)`` (or uses ``p = p_keep``) and keeps every universe node
    independently with probability ``p``; when it keeps none and has no outliers, one universe
    node drawn uniformly is kept, so every graph has at least one node (a one-node graph is
    possible). Its kept nodes carry the universe attributes plus symmetric Gaussian noise
    ``deformation * N(0, 1)``; ``n_outliers`` nodes of its own get ``U(0, 1)`` attributes. As in
    :func:`~transync.datasets.make_graph_collection`, every edge is kept independently with
    probability ``density``, with ``flip > 0`` every pair of kept universe nodes is toggled (edge
    added or removed) with that probability, and node orders are shuffled per graph.

    Parameters
    ----------
    n_graphs : int, default=8
        Number of graphs ``N`` (at least 2).
    n_universe : int, default=20
        Universe size ``d`` (at least 1).
    p_keep : float or (float, float), default=(0.6, 1.0)
        Probability of keeping a universe node, in ``(0, 1]``; a ``(low, high)`` range draws one
        probability per graph uniformly in it.
    n_outliers : int, default=0
        Outlier nodes per graph (no universe id).
    deformation : float, default=0.0
        Standard deviation of the Gaussian noise on the kept nodes' edge attributes.
    density : float, default=1.0
        Probability of keeping each edge.
    flip : float, default=0.0
        Probability of toggling each pair of kept universe nodes (topological noise).
    shuffle : bool, default=True
        Randomly reorder the nodes of every graph.
    rng : None, int or Generator
        Source of randomness.

    Returns
    -------
    SubgraphCollectionProblem
        ``graphs`` carry their attributes as ``edge_features`` (use ``sigma2=0.05`` in the
        affinity, as for :func:`~transync.datasets.make_graph_collection`); ``ground_truth`` is a
        :class:`~transync.permutations.MultiMatching` with ``n_universe`` slots.

    Raises
    ------
    ValueError, TypeError
        ``n_graphs < 2``, ``n_universe < 1`` or not an int, ``p_keep`` outside ``(0, 1]`` or a
        range with ``low > high``, negative ``n_outliers`` or ``deformation``, ``density`` or
        ``flip`` outside ``[0, 1]``.

    Examples
    --------
    >>> import numpy as np
    >>> c = make_subgraph_collection(n_graphs=3, n_universe=6, p_keep=0.5, rng=1)
    >>> [lab.tolist() for lab in c.labels]
    [[2, 0, 3], [4, 5, 0], [2, 5, 1, 3]]
    >>> c.truth(1, 2)                       # universe node 5 is the only one both graphs keep
    array([-1,  1, -1])
    """
    N = check_int(n_graphs, "n_graphs", minimum=2)
    d = check_int(n_universe, "n_universe", minimum=1)
    low, high = _check_p_keep(p_keep)
    n_out = check_int(n_outliers, "n_outliers", minimum=0)
    sigma = check_deformation(deformation)
    rho = check_probability(density, "density")
    p_flip = check_probability(flip, "flip")
    shuffle = check_bool(shuffle, "shuffle")
    _check_size(N, d + n_out, "`n_universe` + `n_outliers`")
    rng = as_generator(rng)
    base = _sym_uniform(rng, d)
    probs = rng.uniform(low, high, N) if high > low else np.full(N, low)
    graphs, labels = [], []
    for p in probs:
        keep = rng.random(d) < p
        if not keep.any() and n_out == 0:
            keep[rng.integers(d)] = True
        ids = np.flatnonzero(keep)
        m = ids.size
        n = m + n_out
        E = _sym_uniform(rng, n)
        noise = np.triu(rng.normal(0.0, 1.0, (m, m)), 1) * sigma
        E[:m, :m] = base[np.ix_(ids, ids)] + noise + noise.T
        M = _sym_mask(rng, n, rho) if rho < 1 else ~np.eye(n, dtype=bool)
        if p_flip > 0:
            M[:m, :m] ^= _sym_mask(rng, m, p_flip)
        np.fill_diagonal(M, False)
        lab = np.concatenate([ids, np.full(n_out, -1)]).astype(np.int64)
        perm = rng.permutation(n) if shuffle else np.arange(n)
        ix = np.ix_(perm, perm)         # relabel the arrays: one Graph validation, not two
        graphs.append(Graph(M[ix].astype(float), edge_features=(E * M)[ix]))
        labels.append(lab[perm])
    p_param = low if low == high else (low, high)
    return SubgraphCollectionProblem(
        graphs, labels, d,
        params=dict(n_graphs=N, n_universe=d, p_keep=p_param, n_outliers=n_out,
                    deformation=sigma, density=rho, flip=p_flip,
                    keep_probabilities=tuple(float(p) for p in probs)))
