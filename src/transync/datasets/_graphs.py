"""Synthetic graph-matching problems with ground truth.

Two protocols:

* :func:`make_pairwise_problem` — Cho, Lee & Lee (ECCV 2010): a random graph with ``U(0, 1)`` edge
  attributes kept with probability ``density``, a permuted copy whose attributes get Gaussian
  deformation noise, and outlier nodes added to both graphs.
* :func:`make_graph_collection` — Yan et al. (TIP 2015, TPAMI 2016) for multi-graph matching: one
  base attribute matrix, every graph a noisy, independently sparsified, optionally topologically
  perturbed (edge flips) and shuffled copy with its own outliers.

Examples
--------
>>> from transync.datasets import make_pairwise_problem
>>> p = make_pairwise_problem(n_inliers=8, n_outliers=2, deformation=0.0, rng=0)
>>> p.g1.n_nodes, p.g2.n_nodes
(10, 10)
>>> int((p.truth >= 0).sum())
8
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validation import as_generator, check_bool, check_int, check_positive, check_probability
from ..graphs import Graph
from ..permutations import MultiMatching

__all__ = [
    "GraphCollectionProblem",
    "PairwiseProblem",
    "make_graph_collection",
    "make_pairwise_problem",
    "make_point_matching_problem",
]


@dataclass(frozen=True)
class PairwiseProblem:
    """Two graphs and the true assignment ``truth`` (node ``u`` of g1 -> ``truth[u]`` of g2).

    Attributes
    ----------
    g1, g2 : Graph
        The graphs.
    truth : ndarray of shape (n1,), int
        True partner in ``g2`` of every node of ``g1``, ``-1`` for outliers.
    params : dict
        The generator's parameters.

    Examples
    --------
    >>> p = make_pairwise_problem(n_inliers=5, n_outliers=1, rng=0)
    >>> p.g1.n_nodes, p.truth.shape, int((p.truth == -1).sum())
    (6, (6,), 1)
    """

    g1: Graph
    g2: Graph
    truth: np.ndarray
    params: dict = field(default_factory=dict)


@dataclass(frozen=True)
class GraphCollectionProblem:
    """Graphs and their ground-truth ``labels[g]`` into a universe of inliers (-1 = outlier).

    ``ground_truth`` is the same ground truth as a :class:`~transync.permutations.MultiMatching`;
    ``truth(i, j)`` gives the true pairwise assignment between graphs ``i`` and ``j``.

    Attributes
    ----------
    graphs : list of Graph
        The graphs.
    labels : list of ndarray of int
        ``labels[g][u]``: universe id of node ``u`` of graph ``g`` (``-1``: outlier).
    n_universe : int
        Number of universe ids (the inliers).
    params : dict
        The generator's parameters.
    ground_truth : MultiMatching
        The labels as a multi-matching (derived).

    Examples
    --------
    >>> c = make_graph_collection(n_graphs=3, n_inliers=4, rng=0)
    >>> len(c.graphs), c.n_universe, c.truth(0, 1).shape
    (3, 4, (4,))
    """

    graphs: list
    labels: list
    n_universe: int
    params: dict = field(default_factory=dict)
    ground_truth: MultiMatching = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "ground_truth", MultiMatching(self.labels, self.n_universe))

    def truth(self, i: int, j: int) -> np.ndarray:
        """The true assignment from graph ``i`` to graph ``j`` (``-1`` for outliers)."""
        return self.ground_truth.pairwise(i, j)


_MAX_ENTRIES = 2 * 10**8     # dense (n, n) arrays generated, summed over graphs


def _check_size(n_graphs: int, n_nodes: int,
                sizes: str = "`n_inliers` + `n_outliers`") -> None:
    """Refuse collections whose dense adjacencies would not fit (``sizes``: the arguments that
    make ``n_nodes``, named in the message)."""
    if n_graphs * n_nodes * n_nodes > _MAX_ENTRIES:
        raise ValueError(f"{sizes} = {n_nodes} nodes in each of {n_graphs} graph(s) would need "
                         f"{n_graphs * n_nodes * n_nodes:.3g} dense adjacency entries (more than "
                         f"{_MAX_ENTRIES:.0e}); use fewer nodes or graphs")


def _sym_uniform(rng, n):
    A = rng.random((n, n))
    A = np.triu(A, 1)
    return A + A.T


def _sym_mask(rng, n, p):
    M = np.triu(rng.random((n, n)) < p, 1)
    return M | M.T


#: largest noise level (``deformation``, ``noise``) the generators take: noise this large
#: carries no structure, and beyond it the attributes, points or maps (and their sums and
#: products) could overflow float64
MAX_DEFORMATION = 1e100


def check_deformation(deformation, name: str = "deformation") -> float:
    """``deformation`` (a noise level, the argument ``name``) as a float in ``[0,
    MAX_DEFORMATION]``; names it otherwise (1e308 was refused later as "`edge_features` must be
    finite", or as a point magnitude; the map generators' ``noise=1e300`` overflowed into maps
    of infinite condition)."""
    sigma = check_positive(deformation, name, allow_zero=True)
    if sigma > MAX_DEFORMATION:
        raise ValueError(f"`{name}` must be at most {MAX_DEFORMATION:g} (noise this large "
                         f"leaves no structure, and the generated values would overflow), got "
                         f"{sigma:g}")
    return sigma


def _check_pair_sizes(n_inliers, n_outliers, deformation):
    """The sizes and deformation of a two-graph problem, validated."""
    n_in = check_int(n_inliers, "n_inliers", minimum=1)
    n_out = check_int(n_outliers, "n_outliers", minimum=0)
    sigma = check_deformation(deformation)
    _check_size(2, n_in + n_out)
    return n_in, n_out, sigma


def make_pairwise_problem(n_inliers: int = 20, n_outliers: int = 0, deformation: float = 0.0,
                          density: float = 1.0, *, shuffle: bool = True,
                          rng=None) -> PairwiseProblem:
    """Cho et al. (2010) synthetic pair: random attributed graph and a deformed, permuted copy.

    Parameters
    ----------
    n_inliers : int, default=20
        Nodes common to both graphs.
    n_outliers : int, default=0
        Outlier nodes added to *both* graphs (random attributes and edges).
    deformation : float, default=0.0
        Standard deviation of the Gaussian noise added to every inlier edge attribute of ``g2``.
    density : float, default=1.0
        Probability of keeping each edge (the same inlier edges in both graphs).
    shuffle : bool, default=True
        Randomly relabel the nodes of ``g2``.
    rng : None, int or Generator
        Source of randomness.

    Returns
    -------
    PairwiseProblem
        Graphs carry their attributes as ``edge_features``; the Cho affinity is
        ``gaussian_edge_affinity(g1, g2, sigma2=0.15)``.

    Raises
    ------
    ValueError, TypeError
        Sizes that are not positive integers, negative ``deformation``, ``density`` outside
        [0, 1], problems too large to generate.

    Examples
    --------
    >>> p = make_pairwise_problem(n_inliers=6, deformation=0.0, rng=0)
    >>> import transync
    >>> res = transync.match_graphs(p.g1, p.g2)
    >>> bool((res.assignment == p.truth).all())                 # exact at zero noise
    True
    """
    n_in, n_out, sigma = _check_pair_sizes(n_inliers, n_outliers, deformation)
    rho = check_probability(density, "density")
    shuffle = check_bool(shuffle, "shuffle")
    rng = as_generator(rng)
    n = n_in + n_out
    base = _sym_uniform(rng, n_in)
    mask_in = _sym_mask(rng, n_in, rho) if rho < 1 else ~np.eye(n_in, dtype=bool)

    def one_graph(noise: float):
        E = _sym_uniform(rng, n)
        E[:n_in, :n_in] = base
        if noise > 0:
            N = np.triu(rng.normal(0.0, noise, (n_in, n_in)), 1)
            E[:n_in, :n_in] += N + N.T
        M = _sym_mask(rng, n, rho) if rho < 1 else ~np.eye(n, dtype=bool)
        M[:n_in, :n_in] = mask_in
        np.fill_diagonal(M, False)
        return M.astype(float), E * M

    A1, E1 = one_graph(0.0)
    A2, E2 = one_graph(sigma)
    perm = rng.permutation(n) if shuffle else np.arange(n)
    # node u of g2 is node perm[u] of the unshuffled copy
    g1 = Graph(A1, edge_features=E1)
    g2 = Graph(A2, edge_features=E2).permute(perm)
    inv = np.argsort(perm)
    truth = np.full(n, -1, dtype=np.int64)
    truth[:n_in] = inv[:n_in]
    return PairwiseProblem(g1, g2, truth, params=dict(n_inliers=n_in, n_outliers=n_out,
                                                      deformation=sigma, density=rho))


def make_point_matching_problem(n_inliers: int = 20, n_outliers: int = 0,
                                deformation: float = 0.0, *, edges: str = "full",
                                rotate: bool = True, shuffle: bool = True,
                                rng=None) -> PairwiseProblem:
    """Point sets in the unit square, the second a rotated, jittered, shuffled copy.

    Both graphs are built with :meth:`Graph.from_points` (``edges``); ``deformation`` is the
    standard deviation of the Gaussian jitter added to each point of the copy; ``n_outliers``
    uniform random points are added to both sets.

    Parameters
    ----------
    n_inliers : int, default=20
        Points common to both sets.
    n_outliers : int, default=0
        Random points added to each set.
    deformation : float, default=0.0
        Standard deviation of the jitter of the copy (unit-square units).
    edges : str, default="full"
        Graph construction of :meth:`transync.graphs.Graph.from_points` (e.g. ``"full"``,
        ``"delaunay"``).
    rotate : bool, default=True
        Rotate the copy by a random angle about the square's centre.
    shuffle : bool, default=True
        Randomly relabel the nodes of the copy.
    rng : None, int or Generator
        Source of randomness.

    Returns
    -------
    PairwiseProblem
        Graphs with ``points``; ``truth`` maps the inliers (outliers ``-1``).

    Raises
    ------
    ValueError, TypeError
        Invalid sizes, ``deformation`` or ``edges``.

    Examples
    --------
    >>> p = make_point_matching_problem(n_inliers=8, rng=0)
    >>> p.g1.points.shape, p.g2.points.shape
    ((8, 2), (8, 2))
    """
    n_in, n_out, sigma = _check_pair_sizes(n_inliers, n_outliers, deformation)
    rotate = check_bool(rotate, "rotate")
    shuffle = check_bool(shuffle, "shuffle")
    rng = as_generator(rng)
    P = rng.random((n_in, 2))
    theta = rng.uniform(0, 2 * np.pi) if rotate else 0.0
    c, s = np.cos(theta), np.sin(theta)
    Q = (P - 0.5) @ np.array([[c, s], [-s, c]]) + 0.5 + rng.normal(0.0, sigma, P.shape)
    P1 = np.vstack([P, rng.random((n_out, 2))])
    P2 = np.vstack([Q, rng.random((n_out, 2))])
    n = n_in + n_out
    perm = rng.permutation(n) if shuffle else np.arange(n)
    P2 = P2[perm]
    inv = np.argsort(perm)
    truth = np.full(n, -1, dtype=np.int64)
    truth[:n_in] = inv[:n_in]
    g1 = Graph.from_points(P1, edges=edges)
    g2 = Graph.from_points(P2, edges=edges)
    return PairwiseProblem(g1, g2, truth, params=dict(n_inliers=n_in, n_outliers=n_out,
                                                      deformation=sigma, edges=edges))


def make_graph_collection(n_graphs: int = 8, n_inliers: int = 10, n_outliers: int = 0,
                          deformation: float = 0.05, density: float = 1.0, flip: float = 0.0, *,
                          shuffle: bool = True, rng=None) -> GraphCollectionProblem:
    """Yan et al.'s multi-graph generator with the thesis's topological noise.

    Every graph has the ``n_inliers`` common nodes (base attributes ``U(0, 1)`` plus symmetric
    Gaussian noise ``deformation * N(0, 1)``), ``n_outliers`` nodes of its own, edges kept
    independently with probability ``density``; with ``flip > 0`` every inlier node pair is toggled
    (edge added or removed) with that probability. Nodes are shuffled per graph; ``labels[g][u]``
    is the universe id of node ``u`` (``-1`` for outliers). Use ``sigma2=0.05`` in the affinity.

    Parameters
    ----------
    n_graphs : int, default=8
        Number of graphs ``N`` (>= 2).
    n_inliers : int, default=10
        Common nodes of every graph.
    n_outliers : int, default=0
        Nodes of each graph's own.
    deformation : float, default=0.05
        Standard deviation of the noise on the inlier edge attributes.
    density : float, default=1.0
        Probability of keeping each edge.
    flip : float, default=0.0
        Probability of toggling each inlier node pair's edge (topological noise).
    shuffle : bool, default=True
        Randomly relabel the nodes of every graph.
    rng : None, int or Generator
        Source of randomness.

    Returns
    -------
    GraphCollectionProblem
        The graphs (attributes as ``edge_features``) and their ground truth.

    Raises
    ------
    ValueError, TypeError
        Invalid sizes or probabilities, problems too large to generate.

    Examples
    --------
    >>> c = make_graph_collection(n_graphs=4, n_inliers=6, deformation=0.0, rng=0)
    >>> [g.n_nodes for g in c.graphs], c.ground_truth.n_universe
    ([6, 6, 6, 6], 6)
    """
    N = check_int(n_graphs, "n_graphs", minimum=2)
    n_in = check_int(n_inliers, "n_inliers", minimum=1)
    n_out = check_int(n_outliers, "n_outliers", minimum=0)
    sigma = check_deformation(deformation)
    rho = check_probability(density, "density")
    p_flip = check_probability(flip, "flip")
    shuffle = check_bool(shuffle, "shuffle")
    _check_size(N, n_in + n_out)
    rng = as_generator(rng)
    n = n_in + n_out
    base = _sym_uniform(rng, n_in)
    graphs, labels = [], []
    for _ in range(N):
        E = _sym_uniform(rng, n)
        noise = np.triu(rng.normal(0.0, 1.0, (n_in, n_in)), 1) * sigma
        E[:n_in, :n_in] = base + noise + noise.T
        M = _sym_mask(rng, n, rho) if rho < 1 else ~np.eye(n, dtype=bool)
        if p_flip > 0:
            F = _sym_mask(rng, n_in, p_flip)
            M[:n_in, :n_in] ^= F
        np.fill_diagonal(M, False)
        lab = np.concatenate([np.arange(n_in), np.full(n_out, -1)]).astype(np.int64)
        perm = rng.permutation(n) if shuffle else np.arange(n)
        ix = np.ix_(perm, perm)         # relabel the arrays: one Graph validation, not two
        graphs.append(Graph(M[ix].astype(float), edge_features=(E * M)[ix]))
        labels.append(lab[perm])
    return GraphCollectionProblem(graphs, labels, n_in,
                                  params=dict(n_graphs=N, n_inliers=n_in, n_outliers=n_out,
                                              deformation=sigma, density=rho, flip=p_flip))
