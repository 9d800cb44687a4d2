"""Baseline graph kernels for the transitive assignment kernel (methods page *Synthetic
protocols and evaluation measures*).

* :func:`graphlet3_kernel` -- exact 3-graphlet frequencies (Shervashidze et al., AISTATS 2009),
  from closed formulas on degrees, edge count and triangles (no enumeration, no sampling).
* :func:`hks_oa_kernel` -- the *non-transitive* optimal-assignment kernel on heat kernel
  signatures that the transitive kernel replaces; indefinite in general (Vert 2008; Kriege et
  al. 2016).
* :func:`hks_mean_kernel` -- the mean-embedding kernel on the same node features, its PSD
  counterpart (all node pairs instead of the best assignment).
* :func:`random_walk_kernel` -- labelled geometric random walk, exact and batched over pairs
  (equal to GraKeL's exact-inverse form to rounding, about 30 times faster than GraKeL's
  conjugate-gradient form on MUTAG, and PSD to rounding where GraKeL's is not).
* :func:`grakel_kernel` -- Weisfeiler-Lehman subtree, WL optimal assignment, shortest path and
  labelled geometric random walk through GraKeL (optional dependency, ``transync[bench]``).

Every function returns an ``(N, N)`` float kernel matrix, cosine-normalized by default
(:func:`~transync.kernels.cosine_normalize`, unit diagonal; a graph with zero self-similarity
gets a zero row).
"""

from __future__ import annotations

import warnings
from functools import partial

import numpy as np
from scipy.optimize import linear_sum_assignment

from .._validation import MAX_ITER, check_bool, check_choice, check_int, check_positive
from ..exceptions import ConvergenceWarning
from ..graphs import Graph
from ..parallel import map_chunks, split_chunks
from ._checks import (check_feature_list, check_graph_list, check_node_labels, check_width,
                      expanded_squared_distances)
from ._evaluate import cosine_normalize
from ._pairwise import default_sigma2

__all__ = [
    "GRAKEL_KERNELS",
    "graphlet3_kernel",
    "grakel_kernel",
    "graphlet3_counts",
    "hks_mean_kernel",
    "hks_oa_kernel",
    "random_walk_kernel",
]

GRAKEL_KERNELS = ("wl", "wl-oa", "sp", "rw")
"""Names accepted by :func:`grakel_kernel`."""


# --------------------------------------------------------------------------- input helpers

def _check_graphs(graphs) -> list[np.ndarray]:
    """Binary 0/1 adjacency (zero diagonal) of each graph (Graph or square array), validated."""
    out = []
    for A in check_graph_list(graphs, edges_only=True):
        B = A != 0
        np.fill_diagonal(B, False)
        out.append(B.astype(np.float64))
    return out


def _centered(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(X - mean, squared norms)``: the rows ready for :func:`expanded_squared_distances`
    (centered once: the expansion's rounding grows with the norms, not with the distances)."""
    Xc = X - X.mean(0)
    return Xc, (Xc * Xc).sum(1)


# --------------------------------------------------------------------------- 3-graphlets

def graphlet3_counts(graphs) -> np.ndarray:
    r"""Exact counts of the four 3-node graphlets of each graph.

    For ``n`` nodes, ``m`` edges, degrees ``d`` and ``t = trace(A^3) / 6`` triangles, the node
    triples inducing 3, 2, 1 and 0 edges number

    .. math::
        g_3 = t, \quad g_2 = \sum_v \binom{d_v}{2} - 3t, \quad
        g_1 = m (n - 2) - 2 g_2 - 3 g_3, \quad g_0 = \binom{n}{3} - g_1 - g_2 - g_3 .

    (Each triple with ``k`` edges is counted ``k`` times by ``m (n - 2)``, and each 2-path
    once by its centre, each triangle three times by ``sum_v C(d_v, 2)``.) Graphs of one size
    are stacked for one batched product.

    Parameters
    ----------
    graphs : sequence of Graph or (n_g, n_g) arrays
        Undirected graphs; any non-zero entry is an edge.

    Returns
    -------
    ndarray of shape (N, 4)
        ``[empty, one edge, path, triangle]`` counts (float), summing to ``C(n_g, 3)``.

    Examples
    --------
    >>> tri = np.ones((3, 3)) - np.eye(3)
    >>> graphlet3_counts([tri, np.zeros((4, 4))])
    array([[0., 0., 0., 1.],
           [4., 0., 0., 0.]])
    """
    adj = _check_graphs(graphs)
    sizes = np.array([A.shape[0] for A in adj])
    out = np.empty((len(adj), 4))
    for n in np.unique(sizes):
        idx = np.flatnonzero(sizes == n)
        A = np.stack([adj[k] for k in idx])                       # (b, n, n)
        deg = A.sum(2)
        t = np.einsum("bij,bij->b", A @ A, A) / 6.0               # trace(A^3) / 6
        m = deg.sum(1) / 2.0
        g3 = t
        g2 = (deg * (deg - 1) / 2.0).sum(1) - 3.0 * t
        g1 = m * (n - 2) - 2.0 * g2 - 3.0 * g3
        g0 = n * (n - 1) * (n - 2) / 6.0 - g1 - g2 - g3
        out[idx] = np.stack([g0, g1, g2, g3], axis=1)
    return np.rint(out)


def graphlet3_kernel(graphs, *, normalize: bool = True) -> np.ndarray:
    """Exact 3-graphlet kernel: linear kernel on graphlet frequencies.

    Each graph is represented by the frequencies of the four graphs on 3 nodes (empty, one
    edge, path, triangle) among its node triples, counted exactly by
    :func:`graphlet3_counts`; the kernel is their dot product. A graph with fewer than 3 nodes
    has no triple and a zero vector (zero row in the kernel).

    GraKeL 0.1.11's ``GraphletSampling(k=3, sampling=None)`` is not used: its "exhaustive"
    counts do not give this kernel: on MUTAG its Gram matrix has rank 1 (all ones once
    normalized; this kernel's has rank 3, MUTAG having no triangles), so the counts are computed
    here in closed form.

    Parameters
    ----------
    graphs : sequence of Graph or (n_g, n_g) arrays
        Undirected graphs; any non-zero entry is an edge (as in :func:`graphlet3_counts`).
    normalize : bool, default=True
        Cosine-normalize the result (unit diagonal).

    Returns
    -------
    ndarray of shape (N, N)
        Symmetric PSD kernel.

    Examples
    --------
    >>> tri = np.ones((3, 3)) - np.eye(3)
    >>> path = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]])
    >>> graphlet3_kernel([tri, path, tri])
    array([[1., 0., 1.],
           [0., 1., 0.],
           [1., 0., 1.]])
    """
    normalize = check_bool(normalize, "normalize")
    counts = graphlet3_counts(graphs)
    total = counts.sum(1, keepdims=True)
    freq = np.divide(counts, total, out=np.zeros_like(counts), where=total > 0)
    K = freq @ freq.T
    return cosine_normalize(K) if normalize else K


# --------------------------------------------------------------------------- HKS kernels

def _oa_chunk(pair_idx: np.ndarray, *, pairs: np.ndarray, features: list, offsets: np.ndarray,
              labels: np.ndarray | None, sigma2: float) -> np.ndarray:
    """Optimal-assignment values of the pairs ``pairs[pair_idx]`` (one LAP per pair)."""
    Xc, xx = _centered(np.concatenate(features, axis=0))
    out = np.empty(pair_idx.shape[0])
    P = pairs[pair_idx]
    for i in np.unique(P[:, 0]):
        rows = np.flatnonzero(P[:, 0] == i)
        js = P[rows, 1]
        cols = np.concatenate([np.arange(offsets[j], offsets[j + 1]) for j in js])
        own = slice(offsets[i], offsets[i + 1])                 # features[i]'s rows
        d2 = expanded_squared_distances(xx[own, None], xx[None, cols], Xc[own] @ Xc[cols].T)
        with np.errstate(over="ignore", under="ignore"):        # far nodes: exactly 0
            S = np.exp(-d2 / sigma2)
        if labels is not None:
            S *= labels[offsets[i]:offsets[i + 1], None] == labels[None, cols]
        starts = np.concatenate([[0], np.cumsum(offsets[js + 1] - offsets[js])])
        for r, a, b in zip(rows, starts[:-1], starts[1:]):
            block = S[:, a:b]
            ri, ci = linear_sum_assignment(block, maximize=True)
            out[r] = block[ri, ci].sum()
    return out


def hks_oa_kernel(features, *, sigma2: float | None = None, node_labels=None,
                  normalize: bool = True, executor=None, progress: bool = False) -> np.ndarray:
    r"""Non-transitive optimal-assignment kernel on node features (e.g. heat kernel signatures).

    .. math::
        k(G, H) = \max_{\pi} \sum_{u} \exp(-\lVert h_u - h_{\pi(u)} \rVert^2 / \sigma^2)

    over the bijections between the two graphs padded to equal size with dummy nodes of zero
    affinity (so every node of the smaller graph is matched to a real node). One Hungarian
    problem per pair, with the affinity blocks of one row graph computed in one product. This
    is the kernel the transitive kernel replaces: the optimal bijections of different pairs are
    not mutually consistent and the matrix is **indefinite in general** (Vert 2008; Kriege et
    al., NeurIPS 2016) -- see :func:`~transync.kernels.min_eigenvalue_ratio`.

    Parameters
    ----------
    features : list of ndarray of shape (n_g, f)
        Node features of each graph (real nodes only), e.g. :func:`hks_features`.
    sigma2 : float, optional
        Width of the Gaussian node kernel; default :func:`~transync.kernels.default_sigma2`
        (median squared distance between node features over the data set, the rule
        :func:`match_pairs` uses), one width for all pairs.
    node_labels : list of int arrays of shape (n_g,), optional
        Categorical node labels: the node kernel is multiplied by ``[label_u == label_a]``.
    normalize : bool, default=True
        Cosine-normalize (the raw self-similarity of a graph is its number of nodes).
    executor : optional
        Where the pair chunks run (:func:`transync.parallel.map_chunks`).
    progress : bool, default=False
        Progress bar over the pair chunks.

    Returns
    -------
    ndarray of shape (N, N)
        Symmetric kernel matrix.

    Examples
    --------
    >>> F = [np.array([[0.0], [1.0]]), np.array([[0.0], [1.0], [5.0]])]
    >>> K = hks_oa_kernel(F, sigma2=1.0, normalize=False)
    >>> K
    array([[2., 2.],
           [2., 3.]])
    """
    normalize = check_bool(normalize, "normalize")
    feats = check_feature_list(features)
    sizes = np.array([F.shape[0] for F in feats])
    labels = None if node_labels is None else check_node_labels(node_labels, sizes)
    sigma2 = default_sigma2(feats) if sigma2 is None else check_width(sigma2, "sigma2")
    N = len(feats)
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    pairs = np.stack(np.triu_indices(N, 1), axis=1)
    fn = partial(_oa_chunk, pairs=pairs, features=feats, offsets=offsets, sigma2=sigma2,
                 labels=None if labels is None else np.concatenate(labels))
    chunks = split_chunks(pairs.shape[0], executor, min_chunk=256, chunks_per_worker=16)
    values = map_chunks(fn, chunks, executor=executor, progress=progress, desc="HKS-OA pairs")
    K = np.zeros((N, N))
    if pairs.shape[0]:
        K[pairs[:, 0], pairs[:, 1]] = np.concatenate(values)
    K = K + K.T
    K[np.diag_indices(N)] = sizes               # each node matched to itself: sum of ones
    return cosine_normalize(K) if normalize else K


def hks_mean_kernel(features, *, kernel: str = "linear", gamma: float | None = None,
                    node_labels=None, normalize: bool = True,
                    block_nodes: int = 4096) -> np.ndarray:
    r"""Mean-embedding kernel on node features, the PSD counterpart of :func:`hks_oa_kernel`.

    Each graph is the mean of its node embeddings, and the kernel is their inner product:

    .. math::
        k(G, H) = \frac{1}{n_G n_H} \sum_{u \in G} \sum_{a \in H} \kappa(h_u, h_a)

    with ``kappa`` linear (``<h_u, h_a>``, the dot product of the mean features) or Gaussian
    (``exp(-gamma ||h_u - h_a||^2)``, the kernel mean embedding in the Gaussian RKHS). It sums
    over *all* node pairs where the OA kernel takes the best bijection, hence is PSD.

    Parameters
    ----------
    features : list of ndarray of shape (n_g, f)
        Node features of each graph (real nodes only).
    kernel : {"linear", "rbf"}, default="linear"
        Node kernel ``kappa``.
    gamma : float, optional
        ``rbf`` width; default ``1 / default_sigma2(features)``, the width of
        :func:`hks_oa_kernel`, so the two kernels share their node kernel.
    node_labels : list of int arrays, optional
        Multiply ``kappa`` by ``[label_u == label_a]`` (still PSD).
    normalize : bool, default=True
        Cosine-normalize.
    block_nodes : int, default=4096
        Nodes per block of the ``rbf`` sum (memory ``8 * block_nodes * total_nodes`` bytes).

    Returns
    -------
    ndarray of shape (N, N)
        Symmetric PSD kernel matrix.

    Examples
    --------
    >>> F = [np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([[2.0, 2.0]])]
    >>> hks_mean_kernel(F, normalize=False)
    array([[0.5, 2. ],
           [2. , 8. ]])
    """
    normalize = check_bool(normalize, "normalize")
    feats = check_feature_list(features)
    kernel = check_choice(kernel, "kernel", ("linear", "rbf"))
    if gamma is not None and kernel != "rbf":     # as assignment_kernel: not silently ignored
        raise ValueError(f"`gamma` applies to kernel='rbf' only, got gamma={gamma!r} with "
                         f"kernel={kernel!r}")
    block_nodes = check_int(block_nodes, "block_nodes", minimum=1)
    sizes = np.array([F.shape[0] for F in feats])
    labels = None if node_labels is None else check_node_labels(node_labels, sizes)
    N = len(feats)
    owner = np.repeat(np.arange(N), sizes)
    X = np.concatenate(feats, axis=0)
    if kernel == "linear":
        if labels is None:
            Phi = np.stack([F.mean(0) for F in feats])
        else:                                   # per-label mean embedding, concatenated
            lab = np.concatenate(labels)
            uniq, code = np.unique(lab, return_inverse=True)
            Phi = np.zeros((N, uniq.shape[0], X.shape[1]))
            np.add.at(Phi, (owner, code), X)
            Phi = Phi.reshape(N, -1) / sizes[:, None]
        if normalize:       # the cosine ignores row scales: bring each row to max |.| = 1 first,
            top = np.abs(Phi).max(1, keepdims=True)      # so tiny embeddings keep their digits
            Phi = Phi / np.where(top > 0, top, 1.0)
        K = Phi @ Phi.T
    else:
        g = (1.0 / default_sigma2(feats) if gamma is None
             else check_width(gamma, "gamma", inverse=True))
        lab = None if labels is None else np.concatenate(labels)
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        K = np.zeros((N, N))
        Xc, xx = _centered(X)
        for s in range(0, X.shape[0], block_nodes):
            blk = slice(s, min(s + block_nodes, X.shape[0]))
            d2 = expanded_squared_distances(xx[blk, None], xx[None, :], Xc[blk] @ Xc.T)
            with np.errstate(over="ignore", under="ignore"):    # far nodes: exactly 0
                S = np.exp(-g * d2)
            if lab is not None:
                S *= lab[blk, None] == lab[None, :]
            col_sums = np.add.reduceat(S, starts, axis=1)          # (block, N)
            np.add.at(K, owner[blk], col_sums)
        K = 0.5 * (K + K.T) / np.outer(sizes, sizes)
    return cosine_normalize(K) if normalize else K


# --------------------------------------------------------------------------- random walk

def _size_blocks(rows: np.ndarray, sizes: np.ndarray, block: int) -> list[np.ndarray]:
    """Split ``rows`` (sorted by ``sizes``) into batches of at most ``block`` rows whose
    largest size is at most 1.25 times the smallest plus 2 (little padding per batch)."""
    out, start = [], 0
    for k in range(1, rows.shape[0] + 1):
        if k == rows.shape[0] or k - start == block or sizes[k] > 1.25 * sizes[start] + 2:
            out.append(rows[start:k])
            start = k
    return out


def _rw_chunk(pair_idx: np.ndarray, *, pairs: np.ndarray, adj: list, labels: list,
              sizes: np.ndarray, lamda: float, tol: float,
              max_iter: int, block: int) -> tuple[np.ndarray, int]:
    """Geometric random-walk values of ``pairs[pair_idx]``; returns (values, worst n_iter)."""
    out = np.empty(pair_idx.shape[0])
    P = pairs[pair_idx]
    worst = 0
    for i in np.unique(P[:, 0]):
        rows = np.flatnonzero(P[:, 0] == i)
        Ai, li = adj[i], labels[i]
        for r in _size_blocks(rows, sizes[P[rows, 1]], block):
            js = P[r, 1]
            m = max(adj[j].shape[0] for j in js)
            B = np.zeros((r.shape[0], m, m))
            M = np.zeros((r.shape[0], Ai.shape[0], m))        # label match of product nodes
            V = np.zeros_like(M)                              # real product nodes
            for b, j in enumerate(js):
                nj = adj[j].shape[0]
                B[b, :nj, :nj] = adj[j]
                M[b, :, :nj] = li[:, None] == labels[j][None, :]
                V[b, :, :nj] = 1.0
            X = V.copy()
            for it in range(1, max_iter + 1):
                X_new = V + lamda * M * (Ai @ (M * X) @ B)
                done = np.abs(X_new - X).max() <= tol * np.abs(X_new).max()
                X = X_new
                if done:
                    break
            worst = max(worst, it)
            out[r] = X.sum(axis=(1, 2))
    return out, worst


def random_walk_kernel(graphs, *, lamda: float = 1e-2, node_labels=None, normalize: bool = True,
                       tol: float = 1e-12, max_iter: int = 500, executor=None,
                       progress: bool = False) -> np.ndarray:
    r"""Labelled geometric random-walk kernel, solved exactly and batched over pairs.

    On the direct product graph of ``G`` and ``H`` -- nodes ``(u, a)``, edges between
    ``(u, a)`` and ``(v, b)`` when ``uv`` and ``ab`` are edges and the labels agree at both
    ends -- the kernel counts walks of every length with weight ``lamda^k`` (Gärtner et al.
    2003; the labelled form of GraKeL's ``RandomWalkLabeled``):

    .. math::
        k(G, H) = \mathbf 1^\top (I - \lambda W_\times)^{-1} \mathbf 1, \qquad
        (W_\times X)_{ua} = M_{ua} \, (A_G (M \odot X) A_H)_{ua},

    with ``M[u, a] = [label_u == label_a]``. The fixed point ``X = 1 + lamda W X`` is iterated
    on all pairs of a batch at once (two batched products per step) to relative change
    ``tol``; it converges geometrically at rate ``lamda * rho(A_G) * rho(A_H)``. Unlike
    GraKeL's per-pair conjugate gradients (relative tolerance 1e-6, at most 20 steps), the
    result is exact to rounding, hence PSD to rounding.

    Parameters
    ----------
    graphs : sequence of Graph or (n_g, n_g) arrays
        Undirected graphs; labels from ``node_labels``, else ``Graph.node_labels``, else the
        degree (as :func:`grakel_kernel`).
    lamda : float, default=1e-2
        Walk decay, ``0 < lamda < 1 / rho_max^2`` (``rho_max`` the largest spectral radius
        of the adjacencies) so that the series converges.
    node_labels : list of int arrays, optional
        Overrides the graphs' labels.
    normalize : bool, default=True
        Cosine-normalize.
    tol : float, default=1e-12
        Relative change that stops the fixed-point iteration.
    max_iter : int, default=500
        Iteration cap (a :class:`~transync.exceptions.ConvergenceWarning` when reached).
    executor : optional
        Where the pair chunks run (:func:`transync.parallel.map_chunks`).
    progress : bool, default=False
        Progress bar over the pair chunks.

    Returns
    -------
    ndarray of shape (N, N)
        Symmetric PSD kernel.

    Raises
    ------
    TypeError
        ``graphs`` or ``node_labels`` not a sequence, non-integer labels.
    ValueError
        ``lamda`` outside ``(0, 1 / rho_max^2)``, invalid graphs or labels.

    Examples
    --------
    >>> edge = np.array([[0.0, 1.0], [1.0, 0.0]])
    >>> K = random_walk_kernel([edge], lamda=0.1, normalize=False)
    >>> float(K[0, 0])                        # 4 / (1 - 0.1): walks 1 -> 2 -> 1 ... on K2 x K2
    4.444...
    """
    normalize = check_bool(normalize, "normalize")
    X = _grakel_input(graphs, node_labels)
    adj = [x[0].astype(np.float64) for x in X]
    labels = [np.array([x[1][i] for i in range(len(x[1]))], dtype=np.int64) for x in X]
    lamda = check_positive(lamda, "lamda")
    tol = check_positive(tol, "tol")
    max_iter = check_int(max_iter, "max_iter", minimum=1, maximum=MAX_ITER)
    sizes = np.array([A.shape[0] for A in adj])
    rho = 0.0
    for n in np.unique(sizes):
        idx = np.flatnonzero(sizes == n)
        w = np.linalg.eigvalsh(np.stack([adj[k] for k in idx]))
        rho = max(rho, float(np.abs(w).max()))
    if rho > 0 and lamda * rho * rho >= 1:
        raise ValueError(f"`lamda` must be below 1 / rho_max^2 = {1 / rho ** 2:.4g} for the walk "
                         f"series to converge on these graphs, got {lamda!r}")
    N = len(adj)
    order = np.argsort(sizes, kind="stable")            # similar sizes share a padded batch
    pi, pj = np.triu_indices(N, 1)
    pairs = np.stack([order[pi], order[pj]], axis=1)
    diag = np.stack([order, order], axis=1)           # diagonal first: rows stay size-sorted
    pairs = np.concatenate([diag, pairs])
    fn = partial(_rw_chunk, pairs=pairs, adj=adj, labels=labels, sizes=sizes, lamda=lamda,
                 tol=tol, max_iter=max_iter, block=256)
    chunks = split_chunks(pairs.shape[0], executor, min_chunk=512, chunks_per_worker=16)
    res = map_chunks(fn, chunks, executor=executor, progress=progress, desc="random-walk pairs")
    if res and max(r[1] for r in res) >= max_iter:
        warnings.warn(f"random_walk_kernel: the walk series did not reach tol={tol:g} within "
                      f"max_iter={max_iter} iterations", ConvergenceWarning, stacklevel=2)
    K = np.zeros((N, N))
    values = np.concatenate([r[0] for r in res])
    K[pairs[:, 0], pairs[:, 1]] = values
    K[pairs[:, 1], pairs[:, 0]] = values
    return cosine_normalize(K) if normalize else K


# --------------------------------------------------------------------------- GraKeL

def _grakel_input(graphs, node_labels) -> list:
    """GraKeL's ``[adjacency, {node: label}]`` form; degree labels when a graph has none.

    Adjacency matrices (not edge dictionaries) are passed on purpose: GraKeL 0.1.11 builds its
    node set from the edge dictionary's keys, so a graph given as an edge dictionary loses its
    isolated nodes and the shortest-path kernel fails with a ``KeyError`` on their labels.
    """
    adj = _check_graphs(graphs)
    if node_labels is None:
        node_labels = [g.node_labels if isinstance(g, Graph) else None for g in graphs]
    labels = check_node_labels(node_labels, [A.shape[0] for A in adj], missing_ok=True)
    out = []
    for A, lab in zip(adj, labels):
        if lab is None:
            lab = A.sum(1).astype(np.int64)            # degree: the field's convention
        out.append([A.astype(np.int64), {i: int(v) for i, v in enumerate(lab)}])
    return out


def grakel_kernel(graphs, name: str, *, node_labels=None, n_iter: int = 5, lamda: float = 1e-2,
                  normalize: bool = True, n_jobs: int | None = None) -> np.ndarray:
    """Classical graph kernels through GraKeL: WL, WL-OA, shortest path, random walk.

    Parameters
    ----------
    graphs : sequence of Graph or (n_g, n_g) arrays
        Undirected graphs. Node labels come from ``node_labels``, else from
        ``Graph.node_labels``, else the node degree (the field's convention for unlabelled
        graphs).
    name : {"wl", "wl-oa", "sp", "rw"}
        ``"wl"``: Weisfeiler-Lehman subtree kernel (Shervashidze et al. 2011);
        ``"wl-oa"``: Weisfeiler-Lehman optimal assignment (Kriege et al. 2016);
        ``"sp"``: shortest-path kernel with node labels (Borgwardt & Kriegel 2005);
        ``"rw"``: labelled geometric random-walk kernel (Gärtner et al. 2003), ``lamda``.
    node_labels : list of int arrays, optional
        Overrides the graphs' labels.
    n_iter : int, default=5
        WL refinement iterations ``h`` (``"wl"``: ``h >= 0``, ``h = 0`` is the label-histogram
        kernel; ``"wl-oa"``: ``h >= 1``). GraKeL's ``n_iter`` counts the same refinements.
    lamda : float, default=1e-2
        Decay of the random walk (``"rw"``), in ``(0, 1)``; GraKeL lowers it when the series
        would diverge on the given graphs. Keep it small (1e-3 .. 1e-2).
    normalize : bool, default=True
        Cosine-normalize the result.
    n_jobs : int, optional
        GraKeL's parallelism for ``"rw"``: a positive number of jobs, or -1 for every core.
        The other kernels run serially (GraKeL's shortest-path kernel has no parallel code and
        only warns about it, so it is not passed on).

    Returns
    -------
    ndarray of shape (N, N)
        The Gram matrix of the graphs (unit diagonal with ``normalize``).

    Raises
    ------
    ImportError
        GraKeL is not installed (``pip install "transync[bench]"``).

    Notes
    -----
    Graphs are handed to GraKeL as adjacency matrices: GraKeL 0.1.11's shortest-path kernel fails
    on graphs with isolated nodes given as edge dictionaries (the node set is read from the
    edges). GraKeL's random-walk kernel solves one linear system per pair of graphs in Python,
    by conjugate gradients stopped at relative tolerance 1e-6 or 20 steps (so its matrix is
    PSD only to about 1e-5): :func:`random_walk_kernel` computes the same kernel exactly and
    much faster.

    Examples
    --------
    >>> tri = np.ones((3, 3)) - np.eye(3)
    >>> K = grakel_kernel([tri, tri, np.zeros((2, 2))], "wl", n_iter=1)
    >>> np.round(K, 6)
    array([[1., 1., 0.],
           [1., 1., 0.],
           [0., 0., 1.]])
    """
    normalize = check_bool(normalize, "normalize")
    name = check_choice(name, "name", GRAKEL_KERNELS)
    n_iter = check_int(n_iter, "n_iter", minimum=0 if name == "wl" else 1)
    lamda = check_positive(lamda, "lamda")
    if lamda >= 1:
        raise ValueError(f"`lamda` must lie in (0, 1), got {lamda!r}")
    if n_jobs is not None:
        n_jobs = check_int(n_jobs, "n_jobs", minimum=-1)
        if n_jobs == 0:                  # joblib's own error named neither it nor the range
            raise ValueError("`n_jobs` must be a positive number of jobs or -1 (every core), "
                             "got 0")
    X = _grakel_input(graphs, node_labels)
    try:
        from grakel import kernels as gk
    except ImportError as exc:                                         # pragma: no cover
        raise ImportError("grakel_kernel needs GraKeL: pip install \"transync[bench]\"") from exc
    if name == "wl":
        if n_iter == 0:
            model = gk.VertexHistogram()
        else:
            model = gk.WeisfeilerLehman(n_iter=n_iter, base_graph_kernel=gk.VertexHistogram)
    elif name == "wl-oa":
        model = gk.WeisfeilerLehmanOptimalAssignment(n_iter=n_iter)
    elif name == "sp":
        model = gk.ShortestPath(with_labels=True)
    else:
        model = gk.RandomWalkLabeled(lamda=lamda, kernel_type="geometric", n_jobs=n_jobs)
    K = np.asarray(model.fit_transform(X), dtype=np.float64)
    K = 0.5 * (K + K.T)
    return cosine_normalize(K) if normalize else K

