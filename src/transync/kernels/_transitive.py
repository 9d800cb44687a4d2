"""Transitive alignments of padded graphs and the kernels built on them (methods page
*Transitive assignment kernels*).

Every graph is padded with isolated dummy nodes to ``n`` nodes (real nodes first), matched to the
others by full permutations of ``range(n)``, and the pairwise permutations are synchronized onto
one universe of ``n`` slots: ``labels[i, u]`` is the slot of padded node ``u`` of graph ``i``.
Because every graph now has one place per slot, a kernel that sums a PSD base kernel over slots
is an inner product in a fixed feature space, hence positive semidefinite (methods page
*Transitive assignment kernels*).

Stages: :func:`view_graph` (which pairs are matched: all, or each graph's nearest graphs plus a
spanning tree), :func:`synchronize_alignments` (pairwise permutations -> :class:`Alignment`),
:func:`aligned_features` (slot-ordered node features with a real-node indicator) or
:func:`relaxed_features` (``Q_i^T F_i`` from the relaxed embedding), :func:`assignment_kernel`
(linear, per-slot Gaussian, relaxed; cosine-normalized), and :func:`prune_by_size`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import (
    as_generator,
    check_array,
    check_bool,
    check_choice,
    check_index_pairs,
    check_int,
    check_positive,
)
from ..exceptions import DegenerateInputError
from ..permutations import solve_lap
from ..synchronization import synchronize_permutations
from ._checks import (check_feature_list, check_int_array, check_node_labels, check_width,
                      class_labels, expanded_squared_distances, median_width,
                      squared_distances)
from ._evaluate import cosine_normalize

__all__ = [
    "Alignment",
    "KERNELS",
    "SYNC_METHODS",
    "aligned_features",
    "assignment_kernel",
    "graph_descriptors",
    "median_gamma",
    "nearest_graphs",
    "pairwise_assignment_kernel",
    "place_graphs",
    "prune_by_size",
    "relaxed_features",
    "synchronize_alignments",
    "view_graph",
]

SYNC_METHODS = ("orthogonal", "spectral")
KERNELS = ("linear", "gaussian", "relaxed")
_GAMMA_SAMPLE_PAIRS = 2000          # graph pairs sampled for the default Gaussian width
_SLOT_BLOCK_ELEMENTS = 4_000_000    # (slots x N x M) entries per block of the Gaussian kernel


@dataclass(frozen=True, eq=False)
class Alignment:
    """Graphs padded to ``n`` nodes and placed in one universe of ``n`` slots.

    Attributes
    ----------
    labels : ndarray of shape (N, n), int64
        ``labels[i, u]``: the slot of padded node ``u`` of graph ``i`` (real nodes first, dummies
        after); every row is a permutation of ``range(n)``. The transitive pairwise maps are
        ``u -> v`` with ``labels[j, v] == labels[i, u]``.
    embedding : ndarray of shape (N, n, d) or None
        The relaxed solution ``Q_i`` before rounding (orthogonal: the polar end point, rows
        orthonormal; spectral: the leading eigenvectors of the normalized block matrix), kept
        when asked for (``keep_embedding=True``); ``Q_i Q_j^T`` approximates ``P_ij``. ``d =
        n``, except for real-node synchronizations (``sizes``) of a universe larger than the
        graphs' total node count: ``d = sum n_i`` columns, the slots real nodes can take (the
        dummies' rows are zero).
    objective : float
        Number of observed pairwise correspondences that the transitive maps keep.
    info : dict
        The synchronization's report (``transync.synchronization.synchronize_permutations``'s
        ``info``, e.g. ``"relaxed_objective_history"``, ``"input_consistency"``,
        ``"seconds_total"``, ``"eigenvalues"``), plus ``"seconds_input"`` (building its input)
        and ``"degrees"`` ((N, n): row sums of the synchronized block matrix, 1 + the node's
        kept correspondences; 0 on dummies left out), which with ``"eigenvalues"`` places the
        spectral embedding of new graphs (:func:`place_graphs`).

    Examples
    --------
    >>> import numpy as np
    >>> from transync.kernels import synchronize_alignments
    >>> pairs = np.array([[0, 1], [0, 2], [1, 2]])
    >>> P = np.array([[1, 0, 2], [1, 2, 0], [2, 1, 0]])   # consistent: P_02 = P_12 o P_01
    >>> al = synchronize_alignments(P, pairs, 3, n=3)
    >>> al.n_graphs, al.n_universe, al.pairwise(0, 1).tolist(), al.embedding is None
    (3, 3, [1, 0, 2], True)
    """

    labels: np.ndarray
    embedding: np.ndarray | None
    objective: float
    info: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        labels = check_int_array(self.labels, "labels", ndim=2)
        N, n = labels.shape
        wrong = np.flatnonzero(np.any(np.sort(labels, axis=1) != np.arange(n), axis=1))
        if wrong.size:
            raise ValueError(f"`labels` must hold a permutation of range({n}) in every row, "
                             f"row {int(wrong[0])} is not one")
        object.__setattr__(self, "labels", labels)
        if self.embedding is not None:
            emb = check_array(self.embedding, "embedding", ndim=3)
            if emb.shape[:2] != (N, n):
                raise ValueError(f"`embedding` must have shape ({N}, {n}, k) as `labels`, got "
                                 f"{emb.shape}")
            object.__setattr__(self, "embedding", emb)

    @property
    def n_graphs(self) -> int:
        return int(self.labels.shape[0])

    @property
    def n_universe(self) -> int:
        return int(self.labels.shape[1])

    def pairwise(self, i: int, j: int) -> np.ndarray:
        """The transitive permutation ``i -> j`` of the padded graphs (``a[u] = v``)."""
        i = check_int(i, "i", minimum=0, maximum=self.n_graphs - 1)
        j = check_int(j, "j", minimum=0, maximum=self.n_graphs - 1)
        inv = np.argsort(self.labels[j])
        return inv[self.labels[i]]


# --------------------------------------------------------------------------------------------
# view graph
# --------------------------------------------------------------------------------------------

def _check_descriptors(descriptors) -> np.ndarray:
    D = check_array(descriptors, "descriptors", ndim=2)
    if D.shape[0] == 0:
        raise ValueError("`descriptors` must hold at least one graph (one row per graph), got "
                         "shape (0, ...)")
    return D


def _sq_distances(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """(len(X), len(Y)) squared Euclidean distances from coordinate differences (no
    ``|x|^2 + |y|^2 - 2 x.y`` cancellation: equal rows are at distance 0 exactly). Callers pass
    descriptors through :func:`_scaled` so that squares cannot overflow."""
    from scipy.spatial.distance import cdist

    return cdist(X, Y, "sqeuclidean")


def _scaled(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """The arrays divided by one power of two (exact: neighbours and ties unchanged) that
    brings their largest absolute entry to [0.5, 1), so that squared distances stay finite."""
    top = max((float(np.max(np.abs(a))) if a.size else 0.0) for a in arrays)
    if top == 0.0:
        return arrays
    exponent = int(np.frexp(top)[1])
    return tuple(np.ldexp(a, -exponent) for a in arrays)     # no 2**1024 overflow


def nearest_graphs(descriptors, queries, n_neighbors: int) -> np.ndarray:
    """The ``k`` graphs of ``descriptors`` nearest each row of ``queries`` (inductive view
    graph: which fitted graphs a new graph is matched to).

    Parameters
    ----------
    descriptors : array_like of shape (N, d)
        Descriptors of the fitted graphs (:func:`graph_descriptors`).
    queries : array_like of shape (M, d)
        Descriptors of the new graphs.
    n_neighbors : int >= 1
        ``k``; at most ``N`` are returned.

    Returns
    -------
    ndarray of shape (M, min(k, N)), int64
        Row indices of ``descriptors``, nearest first (Euclidean; ties by index).

    Examples
    --------
    >>> import numpy as np
    >>> nearest_graphs(np.array([[0.0], [1.0], [3.0]]), np.array([[2.9], [0.4]]), 2).tolist()
    [[2, 1], [0, 1]]
    """
    D = _check_descriptors(descriptors)
    Q = check_array(queries, "queries", ndim=2)
    if Q.shape[1] != D.shape[1]:
        raise ValueError(f"`queries` must have {D.shape[1]} columns like `descriptors`, got "
                         f"shape {Q.shape}")
    k = min(check_int(n_neighbors, "n_neighbors", minimum=1), D.shape[0])
    return _k_nearest(*_scaled(D, Q), k)


def _k_nearest(D: np.ndarray, Q: np.ndarray, k: int, *, exclude_self: bool = False):
    """(len(Q), k) indices of the rows of ``D`` nearest each row of ``Q`` (stable: ties by
    index), in blocks of queries that bound memory; ``exclude_self``: ``Q`` is ``D`` and a row
    is not its own neighbour."""
    out = np.empty((Q.shape[0], k), dtype=np.int64)
    step = max(1, _SLOT_BLOCK_ELEMENTS // max(D.shape[0], 1))
    for s in range(0, Q.shape[0], step):
        d = _sq_distances(Q[s:s + step], D)
        if exclude_self:
            d[np.arange(d.shape[0]), np.arange(s, s + d.shape[0])] = np.inf
        out[s:s + step] = np.argsort(d, axis=1, kind="stable")[:, :k]
    return out


def _spanning_tree(D: np.ndarray) -> np.ndarray:
    """Edges (N - 1, 2) of a minimum spanning tree of the complete graph on the rows of ``D``
    under Euclidean distance (Prim, dense, O(N^2) time and O(N) memory; ties by index)."""
    N = D.shape[0]
    in_tree = np.zeros(N, dtype=bool)
    in_tree[0] = True
    best = _sq_distances(D[:1], D)[0]                     # squared distance to the tree
    parent = np.zeros(N, dtype=np.int64)
    edges = np.empty((max(N - 1, 0), 2), dtype=np.int64)
    for e in range(N - 1):
        cand = np.where(in_tree, np.inf, best)
        v = int(np.argmin(cand))
        edges[e] = (parent[v], v)
        in_tree[v] = True
        d = _sq_distances(D[v:v + 1], D)[0]
        closer = d < best
        best = np.where(closer, d, best)
        parent[closer] = v
    return edges


def view_graph(descriptors, n_neighbors: int | None = None) -> np.ndarray:
    """The pairs of graphs to match: all pairs, or a sparse connected *view graph*.

    With ``n_neighbors = k``, every graph is paired with its ``k`` nearest graphs under the
    Euclidean distance of ``descriptors`` (ties by index; the relation is symmetrized), and the
    edges of a minimum spanning tree of the same distances are added, so the view graph is
    always connected (a requirement of the synchronization) with at most ``N k + N - 1`` pairs
    instead of ``N (N - 1) / 2``. The synchronization then makes the sparse matches transitive,
    and the kernel still compares *all* pairs through the aligned features.

    Parameters
    ----------
    descriptors : array_like of shape (N, d)
        One cheap descriptor per graph (the kernel uses :func:`graph_descriptors`).
    n_neighbors : int >= 1, optional
        ``k``; None, or ``k >= N - 1``: all pairs.

    Returns
    -------
    ndarray of shape (P, 2), int64
        Pairs ``(i, j)``, ``i < j``, in lexicographic order (for ``None``: the order of
        ``numpy.triu_indices``).

    Raises
    ------
    ValueError
        ``descriptors`` not a finite 2-d array with a row per graph, ``n_neighbors`` < 1.
    TypeError
        ``n_neighbors`` not an integer.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([[0.0], [0.1], [5.0], [5.2], [9.0]])
    >>> view_graph(x, 1).tolist()       # 1-NN pairs {01, 23, 34} + spanning tree {12}
    [[0, 1], [1, 2], [2, 3], [3, 4]]
    >>> len(view_graph(x)) == len(view_graph(x, 4)) == 10
    True
    """
    D = _check_descriptors(descriptors)
    N = D.shape[0]
    D, = _scaled(D)
    if n_neighbors is not None:
        n_neighbors = check_int(n_neighbors, "n_neighbors", minimum=1)
    if n_neighbors is None or n_neighbors >= N - 1:
        iu, ju = np.triu_indices(N, 1)
        return np.column_stack([iu, ju]).astype(np.int64)
    near = _k_nearest(D, D, n_neighbors, exclude_self=True)   # k < N - 1: never itself
    edges = np.concatenate([np.column_stack([np.repeat(np.arange(N), n_neighbors),
                                             near.ravel()]), _spanning_tree(D)])
    return np.unique(np.sort(edges, axis=1), axis=0)


def graph_descriptors(features, node_labels=None, label_values=None) -> np.ndarray:
    """The view graph's cheap per-graph descriptor: mean HKS, plus the node-label histogram.

    ``[mean_u f_i(u), share of the nodes of each label]``: the heat kernel signature's mean
    embedding (the HKS mean-embedding kernel's feature vector) and, when labels are used, the
    fraction of graph ``i``'s nodes that carry each value of ``label_values`` (labels not listed
    count nowhere). Both parts lie in [0, 1], so they are concatenated without weights.

    Parameters
    ----------
    features : sequence of N arrays of shape (n_i, T)
        Node features (HKS) of each graph.
    node_labels : sequence of N int arrays of shape (n_i,), optional
    label_values : array of int, optional
        The label values with a histogram bin (sorted); needed with ``node_labels``.

    Returns
    -------
    ndarray of shape (N, T + len(label_values))

    Examples
    --------
    >>> import numpy as np
    >>> graph_descriptors([np.array([[1.0], [0.0]])], [np.array([3, 5])], np.array([3, 5, 7]))
    array([[0.5, 0.5, 0.5, 0. ]])
    """
    feats = check_feature_list(features)
    out = np.stack([F.mean(0) for F in feats])
    if node_labels is None:
        if label_values is not None:
            raise ValueError("`label_values` needs `node_labels` (the label fractions are "
                             "counted from them), got label_values without node_labels")
        return out
    if label_values is None:
        raise ValueError("`label_values` must be given with `node_labels`")
    vals = check_int_array(label_values, "label_values")
    if vals.ndim != 1 or vals.size == 0 or (vals.size > 1 and np.any(vals[1:] <= vals[:-1])):
        raise ValueError(f"`label_values` must be a non-empty 1-d array of strictly increasing "
                         f"label values (one histogram bin each), got "
                         f"{np.asarray(label_values).tolist()!r:.80}")
    labels = check_node_labels(node_labels, [F.shape[0] for F in feats])
    hist = np.zeros((len(feats), vals.size))
    for g, lab in enumerate(labels):                      # one bincount per graph
        idx = np.minimum(np.searchsorted(vals, lab), vals.size - 1)
        ok = vals[idx] == lab
        hist[g] = np.bincount(idx[ok], minlength=vals.size) / max(lab.size, 1)
    return np.hstack([out, hist])


# --------------------------------------------------------------------------------------------
# synchronization
# --------------------------------------------------------------------------------------------

def _check_permutation_rows(a: np.ndarray, name: str) -> None:
    """Every row of ``a`` (..., n) is a permutation of ``range(n)``."""
    n = a.shape[-1]
    flat = a.reshape(-1, n)
    if flat.size and (flat.min() < 0 or flat.max() >= n):
        raise ValueError(f"`{name}` must hold permutations of range({n}) (padded graphs), got "
                         f"values in [{int(flat.min())}, {int(flat.max())}]")
    bad = np.flatnonzero((np.sort(flat, axis=1) != np.arange(n)).any(1))
    if bad.size:
        raise ValueError(f"`{name}` must hold permutations of range({n}) (padded graphs), row "
                         f"{int(bad[0])} is not one: {flat[bad[0]].tolist()!r:.80}")


def _padded_node_labels(node_labels, sizes: np.ndarray, n: int, name: str) -> np.ndarray:
    """(N, n) int64 labels of the real nodes, ``-1`` on the dummies (validated per graph)."""
    out = np.full((sizes.size, n), -1, dtype=np.int64)
    for g, lab in enumerate(check_node_labels(node_labels, sizes, name)):
        out[g, : lab.shape[0]] = lab
    return out


def synchronize_alignments(assignments, pairs, n_graphs: int, *, n: int,
                           sizes=None, node_labels=None, method: str = "orthogonal",
                           keep_embedding: bool = False, max_iter: int = 100, tol: float = 1e-6,
                           refine: int | None = None, rng=None) -> Alignment:
    r"""Project pairwise permutations of padded graphs onto the transitive space.

    Solves (the methods page *Transitive assignment kernels*, step 4)

    .. math:: \max_{P_1..P_N \in \Pi_n} \sum_{(i,j)} \langle P_{ij}, P_i P_j^\top \rangle

    with :func:`transync.synchronization.synchronize_permutations` on the full permutations
    (universe size ``n``): ``"orthogonal"`` (spectral start, Gauss-Seidel polar sweeps over
    ``O(n)``, rounding and discrete refinement) or ``"spectral"`` (Pachauri et al.). The pairs
    go in as one dict of int-keyed assignment rows, the parser's vectorized path (ENZYMES'
    179 700 pairs in about a second); above ``sum n_i = 2000`` the eigensolver is matrix-free.

    Parameters
    ----------
    assignments : ndarray of shape (P, n), int
        ``assignments[p][u] = v``: padded node ``u`` of graph ``pairs[p, 0]`` matched to padded
        node ``v`` of graph ``pairs[p, 1]``; each row a permutation of ``range(n)`` (the output
        of :func:`transync.kernels.match_pairs`).
    pairs : ndarray of shape (P, 2), int
        Graph indices, ``0 <= i, j < n_graphs``, ``i != j``.
    n_graphs : int
        Number of graphs ``N``; with ``N = 1`` no pair is needed (identity alignment).
    n : int
        Padded size = universe size.
    sizes : array of shape (N,), int, optional
        Real node counts ``n_i <= n``. When given, only real-to-real correspondences enter the
        synchronization (partial permutations ``u -> v`` for ``u < n_i``, ``v < n_j``; a real
        node matched to a dummy is unmatched) and the dummies of each graph fill its free slots
        in order: the dummies' arbitrary matches among themselves are not fed to the
        synchronization as if they were observations. Default: full padded permutations.
    node_labels : sequence of N int arrays of shape (n_i,), optional
        Categorical node labels (requires ``sizes``): a correspondence between two real nodes
        with different labels is dropped (unmatched) as well. A matcher that multiplies the node
        affinity by label equality gives such pairs affinity 0, so which node takes which is a
        tie broken by index, not an observation.
    method : {"orthogonal", "spectral"}, default="orthogonal"
    keep_embedding : bool, default=False
        Keep the relaxed solution as ``Alignment.embedding`` (needed by the relaxed kernel).
        With ``sizes``, a real node that no kept correspondence reaches (``"spectral"`` gives
        it a zero row) gets the direction of its rounded slot at the median row norm.
    max_iter, tol : int, float
        Polar sweeps of ``"orthogonal"`` and their relative tolerance, passed on to
        ``synchronize_permutations``.
    refine : int, optional
        Projected-power sweeps on the discrete objective after rounding; default ``max_iter``
        for *both* methods, so that the labels are a fixed point of the rule
        ``P_t = Hungarian(sum_j P_tj P_j)`` with which :func:`place_graphs` places new graphs
        (0: plain Pachauri et al. for ``"spectral"``).
    rng : None, int or numpy.random.Generator
        Seeds the matrix-free eigensolver.

    Returns
    -------
    Alignment
        The labels of the synchronized universe, the number of kept correspondences, the
        relaxed embedding when asked for, and the synchronization's report.

    Raises
    ------
    ValueError
        Rows that are not permutations of ``range(n)``, pairs out of range or with ``i == j``,
        mismatched lengths, a bad ``method``; pairs that leave the graphs in several connected
        groups (:class:`~transync.exceptions.DegenerateInputError`, a ``ValueError``).
    TypeError
        Non-integer assignments or pairs.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.kernels import synchronize_alignments
    >>> pairs = np.array([[0, 1], [0, 2], [1, 2]])
    >>> P = np.array([[1, 0, 2], [1, 2, 0], [2, 1, 0]])   # consistent: P_02 = P_12 o P_01
    >>> al = synchronize_alignments(P, pairs, 3, n=3)
    >>> [bool((al.pairwise(int(i), int(j)) == p).all()) for (i, j), p in zip(pairs, P)]
    [True, True, True]
    """
    N = check_int(n_graphs, "n_graphs", minimum=1)
    n = check_int(n, "n", minimum=1)
    check_choice(method, "method", SYNC_METHODS)
    check_bool(keep_embedding, "keep_embedding")
    A = check_int_array(assignments, "assignments", 2)
    pr = check_index_pairs(pairs, N, what="graph indices", distinct=True)
    if A.size == 0:
        A = A.reshape(0, n)
    if A.shape != (pr.shape[0], n):
        raise ValueError(f"`assignments` must have shape (P, n) = ({pr.shape[0]}, {n}) to match "
                         f"`pairs` and `n`, got shape {A.shape}")
    _check_permutation_rows(A, "assignments")
    real = None
    if sizes is not None:
        real = check_int_array(sizes, "sizes", 1)
        if real.shape != (N,) or real.min() < 1 or real.max() > n:
            raise ValueError(f"`sizes` must hold {N} node counts in [1, {n}], got "
                             f"{real.tolist()!r:.80}")
    L = None
    if node_labels is not None:
        if real is None:
            raise ValueError("`node_labels` needs `sizes` (dropped correspondences leave partial "
                             "maps; full padded permutations cannot hold them)")
        L = _padded_node_labels(node_labels, real, n, "node_labels")
    refine = max_iter if refine is None else check_int(refine, "refine", minimum=0)
    if N == 1:
        labels = np.arange(n, dtype=np.int64)[None]
        emb = np.eye(n)[None] if keep_embedding else None
        if emb is not None and real is not None:
            emb[0, int(real[0]):] = 0.0
        deg = np.ones((1, n)) if real is None else (np.arange(n) < real[0])[None] * 1.0
        return Alignment(labels=labels, embedding=emb, objective=0.0,
                         info={"method": method, "note": "one graph: identity alignment",
                               "degrees": deg, "eigenvalues": np.ones(n)})
    if pr.shape[0] == 0:
        raise ValueError(f"`pairs` must contain at least one pair for n_graphs={N}")
    _check_connected(pr, N)
    t0 = time.perf_counter()
    keys = map(tuple, pr.tolist())
    if real is None:
        # the parser's fast path: int tuple keys and int64 rows of one length
        observed = dict(zip(keys, list(A)))
    else:
        keep = A < real[pr[:, 1]][:, None]
        if L is not None:                                  # different labels: a tie, no match
            keep &= L[pr[:, 0]] == L[pr[:, 1][:, None], A]
        A = np.where(keep, A, -1)
        observed = dict(zip(keys, [a[:k] for a, k in zip(A, real[pr[:, 0]].tolist())]))
    seconds_input = time.perf_counter() - t0
    # real nodes fill at most sum n_i slots (the synchronization's own bound); the dummies fill
    # the rest of the n: a universe beyond the fitted graphs' total (a small fit, placed for
    # larger graphs) was refused
    d = n if real is None else min(n, int(real.sum()))
    res = synchronize_permutations(observed, n_universe=d, method=method,
                                   sizes=np.full(N, n, dtype=np.int64) if real is None else real,
                                   disconnected="raise",
                                   keep_embedding=bool(keep_embedding), max_iter=max_iter,
                                   tol=tol, refine=refine, rng=rng)
    info = dict(res.info)
    emb = info.pop("embedding", None)
    info["seconds_input"] = seconds_input
    info["degrees"] = _degrees(A, pr, N, n, real)
    if real is None:
        labels = np.stack(res.labels).astype(np.int64)
        if emb is not None:
            emb = emb.reshape(N, n, n)
    else:
        labels = _fill_dummies(res.labels, n)
        if emb is not None:
            full = np.zeros((N, n, emb.shape[1]))         # d = min(n, sum n_i) columns
            is_real = np.arange(n)[None, :] < real[:, None]
            full[is_real] = emb                                 # real rows, graph order
            emb = _fill_unreached_rows(full, labels, is_real)
    return Alignment(labels=labels, embedding=emb, objective=float(res.objective), info=info)


def _fill_unreached_rows(emb: np.ndarray, labels: np.ndarray, is_real: np.ndarray):
    """Real nodes that no kept correspondence reached (all their matches dropped, e.g. as label
    mismatches) have a zero row in the spectral embedding, which would give their graph a zero
    relaxed feature (self-similarity 0): they get the direction of their rounded slot instead,
    at the median norm of the reached rows."""
    norms = np.linalg.norm(emb, axis=2)
    empty = is_real & (norms == 0)
    # the real nodes' slots (the dummies' lie beyond the d columns when n > sum n_i)
    if not empty.any() or emb.shape[2] <= labels[is_real].max():
        return emb
    reached = norms[is_real & (norms > 0)]
    scale = float(np.median(reached)) if reached.size else 1.0
    g, u = np.nonzero(empty)
    emb[g, u, labels[g, u]] = scale
    return emb


def _degrees(A: np.ndarray, pr: np.ndarray, N: int, n: int, real) -> np.ndarray:
    """(N, n) row sums of the synchronized block matrix (identity diagonal blocks, one entry per
    kept correspondence, both directions); 0 on the dummies of a real-only synchronization."""
    valid = A >= 0
    if real is not None:
        valid &= np.arange(n)[None, :] < real[pr[:, 0]][:, None]
    src = (pr[:, 0][:, None] * n + np.arange(n)[None, :])[valid]
    dst = (pr[:, 1][:, None] * n + A)[valid]
    deg = np.bincount(np.concatenate([src, dst]), minlength=N * n).reshape(N, n) + 1.0
    if real is not None:
        deg[np.arange(n)[None, :] >= real[:, None]] = 0.0
    return deg


def _fill_dummies(real_labels, n: int) -> np.ndarray:
    """(N, n) labels: the real nodes' slots, then the free slots in increasing order."""
    out = np.empty((len(real_labels), n), dtype=np.int64)
    for g, lab in enumerate(real_labels):                  # one setdiff per graph
        out[g, : lab.size] = lab
        out[g, lab.size:] = np.setdiff1d(np.arange(n), lab)
    return out


def place_graphs(assignments, labels, *, sizes=None, fitted_sizes=None, node_labels=None,
                 fitted_node_labels=None, embedding=None, degrees=None, eigenvalues=None,
                 method: str = "orthogonal",
                 fitted=None) -> tuple[np.ndarray, np.ndarray | None]:
    """Place new graphs in a fitted universe (inductive use; methods page *Transitive assignment
    kernels*, *Transductive and inductive use*).

    ``P_t = Hungarian(sum_j P_tj P_j)``: node ``u`` of new graph ``t`` goes to the slot that most
    fitted graphs ``j`` put its partner ``assignments[t, j, u]`` in. With ``embedding``, also the
    relaxed ``Q_t``: ``polar(sum_j P_tj Q_j)`` (``"orthogonal"``; the block update of the polar
    sweeps), or, for ``"spectral"``, the eigenvector equation of the degree-normalized block
    matrix ``D^{-1/2} T D^{-1/2}`` solved for the new rows with the fitted ones fixed,

    .. math:: Q_t[u, k] = \\frac{1}{\\lambda_k \\sqrt{c_t(u)}} \\sum_j \\sum_v P_{tj}[u, v]\\,
              \\frac{U_j[v, k]}{\\sqrt{d_j(v)}},

    ``c_t(u)`` the number of correspondences of ``u`` that vote. A copy of a fitted graph (its
    maps to the others, and the identity to itself) gets that graph's spectral rows back
    exactly, on any input, and its orthogonal rows to the accuracy of the polar sweeps that
    fitted them (a fixed point of ``polar(sum_j P_tj Q_j)`` only at convergence: 2e-3 after
    100 unconverged sweeps, 2e-7 after 5000); its labels come back when they are a fixed point
    of the rule (the refinement of :func:`synchronize_alignments` makes them one).

    Parameters
    ----------
    assignments : ndarray of shape (M, N, n) or (M, k, n), int
        Permutation from each new graph ``t`` to each fitted graph ``j`` (padded), or to the
        fitted graphs ``fitted[t]`` only; int32 is used as it is (no int64 copy).
    labels : ndarray of shape (N, n), int
        The fitted alignment's labels.
    sizes, fitted_sizes : arrays of shape (M,) and (N,), int, optional
        Real node counts (give both or neither): only real-to-real correspondences vote, as in
        :func:`synchronize_alignments` with ``sizes``; the new graphs' dummies fill their free
        slots in order (and get zero rows in the relaxed ``Q_t``).
    node_labels, fitted_node_labels : sequences of int arrays of shapes (n_t,) and (n_j,)
        Node labels of the new and the fitted graphs (give both, with ``sizes``): a
        correspondence between nodes of different labels does not vote, as in
        :func:`synchronize_alignments` with ``node_labels``.
    embedding : ndarray of shape (N, n, d), optional
        The fitted relaxed embedding (:attr:`Alignment.embedding`); given, the new graphs'
        relaxed ``Q_t`` are computed too.
    degrees, eigenvalues : arrays of shapes (N, n) and (>= d,), optional
        ``Alignment.info["degrees"]`` and ``Alignment.info["eigenvalues"]``; needed to place the
        ``"spectral"`` embedding (a column with a non-positive eigenvalue is left at zero).
    method : {"orthogonal", "spectral"}
        The synchronization method of the fitted alignment (how ``Q_t`` is placed).
    fitted : ndarray of shape (M, k), int, optional
        The fitted graphs that ``assignments[t]`` maps new graph ``t`` to (e.g. its ``k``
        nearest fitted graphs, the view graph of
        :class:`~transync.kernels.TransitiveAssignmentKernel` with ``n_neighbors``); only
        they vote. Default: all ``N`` fitted graphs, in order.

    Returns
    -------
    labels : ndarray of shape (M, n), int64
        ``labels[t, u]``: the slot of padded node ``u`` of new graph ``t`` (each row a
        permutation of ``range(n)``).
    embedding : ndarray of shape (M, n, d) or None
        The new graphs' relaxed ``Q_t`` (``None`` without ``embedding``).

    Raises
    ------
    ValueError
        Rows that are not permutations, shapes that do not match, a bad ``method``, labels
        without sizes or one set of labels or sizes without the other.

    Examples
    --------
    >>> import numpy as np
    >>> fitted = np.array([[0, 1, 2], [2, 0, 1]])          # slots of two fitted graphs
    >>> # a new graph whose node u is node u of graph 0, i.e. node (1, 2, 0)[u] of graph 1
    >>> place_graphs(np.array([[[0, 1, 2], [1, 2, 0]]]), fitted)[0]
    array([[0, 1, 2]])
    """
    check_choice(method, "method", SYNC_METHODS)
    A, lab, nbr = _check_placement_maps(assignments, labels, fitted)
    M, K, n = A.shape
    N = lab.shape[0]
    real, fit_real, L_new, L_fit = _check_placement_sizes(sizes, fitted_sizes, node_labels,
                                                          fitted_node_labels, M, N, n)
    E = lam_inv = Q = None
    if embedding is not None:
        E, lam_inv = _placement_embedding(embedding, method, degrees, eigenvalues, N, n)
        Q = np.zeros((M, n, E.shape[2]))
    out = np.empty((M, n), dtype=np.int64)
    step = max(1, _SLOT_BLOCK_ELEMENTS // max(K * n, 1))
    for s in range(0, M, step):                           # blocks of new graphs bound memory
        blk = A[s:s + step]
        b = blk.shape[0]
        jj = (np.arange(K)[None, :, None] if nbr is None
              else nbr[s:s + b, :, None])                 # fitted graph of each vote
        valid = None
        if real is not None:                              # real u -> real partner only
            valid = ((np.arange(n)[None, None, :] < real[s:s + b, None, None])
                     & (blk < fit_real[jj]))
            if L_new is not None:                         # ... of the same label
                valid &= L_new[s:s + b, None, :] == L_fit[jj, blk]
        out[s:s + b] = _vote_slots(lab[jj, blk], valid, None if real is None else real[s:s + b])
        if E is not None:
            Q[s:s + b] = _vote_rows(E, jj, blk, valid, method, lam_inv)
    if E is None:
        return out, None
    return out, _finish_placed_rows(Q, method, real)


def _check_placement_maps(assignments, labels, fitted):
    """place_graphs' maps: ``assignments`` (M, K, n) of permutation rows, ``labels`` (N, n),
    ``fitted`` (M, K) distinct fitted-graph indices or None."""
    A = check_int_array(assignments, "assignments", 3, keep_dtype=True)
    lab = check_int_array(labels, "labels", 2)
    M, K, n = A.shape
    if n < 1:
        raise ValueError(f"`assignments` must have shape (M, N, n) with n >= 1 (padded nodes), "
                         f"got shape {A.shape}")
    N = lab.shape[0]
    if lab.shape[1:] != (n,) or (fitted is None and N != K):
        want = f"(N, n) = ({K}, {n})" if fitted is None else f"(N, {n})"
        raise ValueError(f"`labels` must have shape {want} to match `assignments`, got shape "
                         f"{lab.shape}")
    nbr = None
    if fitted is not None:
        nbr = check_int_array(fitted, "fitted", 2)
        if nbr.shape != (M, K):
            raise ValueError(f"`fitted` must have shape (M, k) = ({M}, {K}) like the first two "
                             f"axes of `assignments`, got shape {nbr.shape}")
        if nbr.size and (nbr.min() < 0 or nbr.max() >= N):
            raise ValueError(f"`fitted` must hold fitted-graph indices in [0, {N}), got values "
                             f"in [{int(nbr.min())}, {int(nbr.max())}]")
        srt = np.sort(nbr, axis=1)
        dup = np.flatnonzero(np.any(srt[:, 1:] == srt[:, :-1], axis=1))
        if dup.size:
            raise ValueError(f"`fitted` must list distinct fitted graphs per new graph (each "
                             f"votes once), row {int(dup[0])} repeats one: "
                             f"{nbr[dup[0]].tolist()!r:.80}")
    _check_permutation_rows(A, "assignments")
    return A, lab, nbr


def _check_placement_sizes(sizes, fitted_sizes, node_labels, fitted_node_labels, M, N, n):
    """place_graphs' real node counts and padded node labels (None where not given)."""
    if (sizes is None) != (fitted_sizes is None):
        raise ValueError("`sizes` and `fitted_sizes` must be given together")
    if (node_labels is None) != (fitted_node_labels is None):
        raise ValueError("`node_labels` and `fitted_node_labels` must be given together")
    real = fit_real = L_new = L_fit = None
    if sizes is not None:
        real = check_int_array(sizes, "sizes", 1)
        fit_real = check_int_array(fitted_sizes, "fitted_sizes", 1)
        for arr, name, k in ((real, "sizes", M), (fit_real, "fitted_sizes", N)):
            if arr.shape != (k,) or (k and (arr.min() < 1 or arr.max() > n)):
                raise ValueError(f"`{name}` must hold {k} node counts in [1, {n}], got "
                                 f"{arr.tolist()!r:.80}")
    if node_labels is not None:
        if real is None:
            raise ValueError("`node_labels` needs `sizes` and `fitted_sizes`")
        L_new = _padded_node_labels(node_labels, real, n, "node_labels")
        L_fit = _padded_node_labels(fitted_node_labels, fit_real, n, "fitted_node_labels")
    return real, fit_real, L_new, L_fit


def _placement_embedding(embedding, method, degrees, eigenvalues, N, n):
    """The fitted embedding as the votes use it: scaled by a power of two (orthogonal) or
    ``D^{-1/2} U`` with the inverse eigenvalues (spectral; ``lam_inv`` None otherwise)."""
    E = check_array(embedding, "embedding", ndim=3)
    if E.shape[:2] != (N, n):
        raise ValueError(f"`embedding` must have shape (N, n, d) = ({N}, {n}, d), got "
                         f"shape {E.shape}")
    if method == "orthogonal":
        # polar(sum_j P_tj Q_j) does not change when E is scaled: a power of two that brings
        # its largest entry to [0.5, 1) keeps the vote sums and the SVD inside float64
        E, = _scaled(E)
        return E, None
    if degrees is None or eigenvalues is None:
        raise ValueError("`degrees` and `eigenvalues` (Alignment.info) are needed to "
                         "place a spectral embedding")
    deg = check_array(degrees, "degrees", ndim=2)
    lam = check_array(eigenvalues, "eigenvalues", ndim=1)
    if deg.shape != (N, n):
        raise ValueError(f"`degrees` must have shape (N, n) = ({N}, {n}), got shape "
                         f"{deg.shape}")
    if lam.shape[0] < E.shape[2]:
        raise ValueError(f"`eigenvalues` must hold the {E.shape[2]} leading "
                         f"eigenvalues of the embedding, got {lam.shape[0]}")
    lam = lam[: E.shape[2]]
    # a column whose eigenvalue is not positive cannot be extended: left at zero
    lam_inv = np.where(lam > 1e-12, 1.0 / np.where(lam > 1e-12, lam, 1.0), 0.0)
    dinv = np.where(deg > 0, 1.0 / np.sqrt(np.where(deg > 0, deg, 1.0)), 0.0)
    with np.errstate(over="ignore", invalid="ignore"):
        E = E * dinv[:, :, None]                  # D^{-1/2} U, once
    return E, lam_inv


def _vote_slots(slots: np.ndarray, valid, real) -> np.ndarray:
    """Labels (b, n) of a block of new graphs from the slots (b, K, n) their correspondences
    vote for (only the ``valid`` ones, if given): one LAP per graph on its real rows, then the
    dummies fill the free slots in order."""
    b, _, n = slots.shape
    code = (np.arange(b)[:, None, None] * n + np.arange(n)[None, None, :]) * n + slots
    votes = None if valid is None else valid.ravel().astype(float)
    S = np.bincount(code.ravel(), weights=votes, minlength=b * n * n).reshape(b, n, n)
    out = np.empty((b, n), dtype=np.int64)
    for t in range(b):                                # one LAP per new graph
        k = n if real is None else int(real[t])
        c = solve_lap(S[t, :k])                       # k <= n rows: all placed
        out[t, :k] = c
        if k < n:
            out[t, k:] = np.setdiff1d(np.arange(n), c)
    return out


def _vote_rows(E, jj, blk, valid, method, lam_inv) -> np.ndarray:
    """Relaxed rows (b, n, d) of a block of new graphs: the sum of their partners' rows
    (orthogonal: the polar factor is taken afterwards), or the spectral eigenvector equation."""
    b, K, n = blk.shape
    Q = np.empty((b, n, E.shape[2]))
    with np.errstate(over="ignore", invalid="ignore"):   # spectral: checked by the caller
        for t in range(b):                            # (K, n, d) gathered per new graph
            rows = E[jj[min(t, jj.shape[0] - 1)], blk[t]]
            if valid is None:
                Q[t] = rows.sum(0)
                cnt = np.full(n, float(K))
            else:
                Q[t] = np.einsum("ju,jud->ud", valid[t], rows)
                cnt = valid[t].sum(0).astype(float)
            if method == "spectral":                  # eigenvector equation, row by row
                c = np.where(cnt > 0, 1.0 / np.sqrt(np.maximum(cnt, 1.0)), 0.0)
                Q[t] *= c[:, None] * lam_inv[None, :]
    return Q


def _finish_placed_rows(Q: np.ndarray, method: str, real) -> np.ndarray:
    """Spectral rows checked finite; orthogonal vote sums replaced by their polar factors (of
    the real rows); dummy rows zero."""
    M, n = Q.shape[:2]
    if method == "spectral" and not np.isfinite(Q).all():
        raise ValueError("the spectral placement overflows float64: `embedding` is too large "
                         "for its `degrees` and `eigenvalues` (the fitted Alignment's own "
                         "values never are)")
    if method == "orthogonal":
        if real is None:
            U, _, Vt = np.linalg.svd(Q, full_matrices=False)   # polar factor, batched
            Q = U @ Vt
        else:
            for t in range(M):                            # polar of the real rows only
                k = int(real[t])
                U, _, Vt = np.linalg.svd(Q[t, :k], full_matrices=False)
                Q[t, :k] = U @ Vt
    if real is not None:
        Q[np.arange(n)[None, :] >= real[:, None]] = 0.0
    return Q


def _padded_features(feats: list[np.ndarray], n: int) -> np.ndarray:
    """(N, n, f + 1): features of the real nodes first, dummies zero; last column = 1 on real."""
    N, f = len(feats), feats[0].shape[1]
    big = [g for g, F in enumerate(feats) if F.shape[0] > n]
    if big:
        raise ValueError(f"`features[{big[0]}]` has {feats[big[0]].shape[0]} nodes, more than "
                         f"the universe size n={n}")
    out = np.zeros((N, n, f + 1))
    for g, F in enumerate(feats):                          # one copy per graph
        out[g, : F.shape[0], :f] = F
        out[g, : F.shape[0], f] = 1.0
    return out


def aligned_features(features, labels, n: int | None = None) -> np.ndarray:
    """Slot-ordered node features: ``F~_i[labels[i, u]] = [f_i(u), 1]``, dummies ``[0, 0]``.

    Parameters
    ----------
    features : sequence of N arrays of shape (n_i, f)
        Node features of the real nodes (e.g. HKS, node-label one-hots).
    labels : ndarray of shape (N, n), int
        Slots of the padded nodes (:attr:`Alignment.labels`); rows are permutations.
    n : int, optional
        Universe size; must equal ``labels.shape[1]`` (default).

    Returns
    -------
    ndarray of shape (N, n, f + 1)
        Rows are slots; the last column is the real-node indicator ``delta_i[a]``.

    Examples
    --------
    >>> import numpy as np
    >>> F = [np.array([[1.0], [2.0]]), np.array([[3.0]])]
    >>> aligned_features(F, np.array([[1, 0], [0, 1]]))[..., 0]
    array([[2., 1.],
           [3., 0.]])
    """
    feats = check_feature_list(features)
    lab = check_int_array(labels, "labels", 2)
    if n is None:
        n = lab.shape[1]
    n = check_int(n, "n", minimum=1)
    if lab.shape != (len(feats), n):
        raise ValueError(f"`labels` must have shape (N, n) = ({len(feats)}, {n}), got shape "
                         f"{lab.shape}")
    _check_permutation_rows(lab, "labels")
    pad = _padded_features(feats, n)
    out = np.empty_like(pad)
    out[np.arange(len(feats))[:, None], lab] = pad
    return out


def relaxed_features(features, embedding) -> np.ndarray:
    """Relaxed aligned features ``Q_i^T [F_i, delta_i]`` (methods page *Transitive assignment
    kernels*, step 6c).

    Parameters
    ----------
    features : sequence of N arrays of shape (n_i, f)
        Node features of each graph (real nodes only; padded with zero rows to ``n``).
    embedding : ndarray of shape (N, n, d)
        :attr:`Alignment.embedding` (padded node ``u`` of graph ``i`` -> row ``Q_i[u]``).

    Returns
    -------
    ndarray of shape (N, d, f + 1)
        Feed to :func:`assignment_kernel` with ``kernel="relaxed"``; the kernel
        ``<Q_i^T F_i, Q_j^T F_j>`` is PSD for any real ``Q_i``.

    Examples
    --------
    >>> import numpy as np
    >>> F = [np.array([[1.0], [2.0]])]
    >>> relaxed_features(F, np.eye(2)[None, ::-1])[0]      # Q swaps the two slots
    array([[2., 1.],
           [1., 1.]])
    """
    feats = check_feature_list(features)
    E = check_array(embedding, "embedding", ndim=3)
    if E.shape[0] != len(feats):
        raise ValueError(f"`embedding` must have one (n, d) block per graph ({len(feats)}), got "
                         f"shape {E.shape}")
    pad = _padded_features(feats, E.shape[1])
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.einsum("gud,guf->gdf", E, pad)
    if not np.isfinite(out).all():
        raise ValueError("the values of `embedding` and `features` are too large: Q_i^T F_i "
                         "overflows float64; rescale them")
    return out


# --------------------------------------------------------------------------------------------
# kernels
# --------------------------------------------------------------------------------------------

def median_gamma(aligned, *, rng=0) -> float:
    """Default width of the per-slot Gaussian: ``1 / median ||F~_i[a] - F~_j[a]||^2``.

    The median runs over slots ``a`` that hold real nodes in both graphs, for distinct graphs
    ``i != j`` (all pairs up to 2000 of them, else 2000 sampled pairs, seeded by ``rng``, so
    the value is reproducible); a zero median falls back to the mean, and no positive distance
    at all to ``1.0``.

    Parameters
    ----------
    aligned : ndarray of shape (N, n, f + 1)
        Aligned features from :func:`aligned_features` (last column: real-node indicator).
    rng : None, int or numpy.random.Generator, default=0
        Seeds the sampling of pairs when there are more than 2000.

    Returns
    -------
    float
        ``gamma`` > 0 for ``assignment_kernel(..., kernel="gaussian")``; 1.0 for fewer than
        two graphs.

    Raises
    ------
    ValueError
        ``aligned`` not a finite 3-d array.

    Examples
    --------
    >>> import numpy as np
    >>> X = aligned_features([np.array([[0.0]]), np.array([[2.0]])], np.zeros((2, 1), int))
    >>> median_gamma(X)                                     # 1 / (2 - 0)^2
    0.25
    """
    X = check_array(aligned, "aligned", ndim=3)
    gen = as_generator(rng)                 # checked whatever the size
    N = X.shape[0]
    if N < 2:
        return 1.0
    n_pairs = N * (N - 1) // 2
    if n_pairs <= _GAMMA_SAMPLE_PAIRS:
        i, j = np.triu_indices(N, 1)
    else:
        i = gen.integers(0, N, _GAMMA_SAMPLE_PAIRS)
        j = (i + gen.integers(1, N, _GAMMA_SAMPLE_PAIRS)) % N
    return _inverse_median(X[i], X[j], "aligned")


def _inverse_median(Xi: np.ndarray, Xj: np.ndarray, name: str) -> float:
    """``1 / median_width`` of ``||Xi[p, u] - Xj[p, u]||^2`` over rows real in both (last
    column)."""
    both = (Xi[..., -1] > 0) & (Xj[..., -1] > 0)
    return 1.0 / median_width(squared_distances(Xi[both], Xj[both], name), name)


def _gaussian_gram(X: np.ndarray, Y: np.ndarray, gamma: float) -> np.ndarray:
    """sum_a d_i[a] d_j[a] exp(-gamma ||X_i[a] - Y_j[a]||^2), blocks of slots in lock-step."""
    N, n, _ = X.shape
    M = Y.shape[0]
    K = np.zeros((N, M))
    dx, dy = X[..., -1], Y[..., -1]
    # per slot, the mean of its real nodes: distances unchanged, the expansion's rounding
    # (which grows with the norms) down to the spread of the features (dummies weigh 0)
    real = (dx != 0).sum(0)[:, None]
    center = np.where(dx[..., None] != 0, X, 0.0).sum(0) / np.maximum(real, 1)
    X, Y = X - center, Y - center
    xx = (X ** 2).sum(-1)                                   # (N, n)
    yy = (Y ** 2).sum(-1)
    step = max(1, _SLOT_BLOCK_ELEMENTS // max(N * M, 1))
    for s in range(0, n, step):                             # blocks of slots, not pairs
        sl = slice(s, min(s + step, n))
        cross = np.matmul(X[:, sl].transpose(1, 0, 2), Y[:, sl].transpose(1, 2, 0))  # (b, N, M)
        d2 = expanded_squared_distances(xx[:, sl].T[:, :, None], yy[:, sl].T[:, None, :],
                                        cross)
        w = dx[:, sl].T[:, :, None] * dy[:, sl].T[:, None, :]
        K += (w * np.exp(-gamma * d2)).sum(0)
    return K


def assignment_kernel(aligned, other=None, *, kernel: str = "linear", gamma=None,
                      normalize: bool = True) -> np.ndarray:
    r"""Transitive assignment kernel on aligned features (methods page *Transitive assignment
    kernels*, step 6).

    * ``"linear"``: :math:`k_{ij} = \langle \mathrm{vec}\,\tilde F_i, \mathrm{vec}\,\tilde F_j
      \rangle = \sum_a \langle \tilde F_i[a], \tilde F_j[a] \rangle`;
    * ``"gaussian"`` (per slot, real-node indicators :math:`\delta` = last column):
      :math:`k_{ij} = \sum_a \delta_i[a]\,\delta_j[a]\,\exp(-\gamma \|\tilde F_i[a] -
      \tilde F_j[a]\|^2)`; ``gamma`` default :func:`median_gamma` of ``aligned`` (pass it
      explicitly to compare different calls on one scale);
    * ``"relaxed"``: the linear kernel on :func:`relaxed_features` (``Q_i^T F_i``).

    Each is a sum over slots of a PSD kernel over fixed points, hence PSD. With ``normalize``,
    cosine normalization :math:`k_{ij} / \sqrt{k_{ii} k_{jj}}` (the self-similarities of
    ``aligned`` and of ``other`` themselves), which keeps PSD.

    Parameters
    ----------
    aligned : ndarray of shape (N, n, f + 1)
        From :func:`aligned_features` (or :func:`relaxed_features` for ``"relaxed"``).
    other : ndarray of shape (M, n, f + 1), optional
        Second set (default ``aligned``): returns the (N, M) cross Gram matrix.
    kernel : {"linear", "gaussian", "relaxed"}, default="linear"
        The kernel (see above).
    gamma : float > 0, optional
        Gaussian width (``"gaussian"`` only).
    normalize : bool, default=True
        Cosine-normalize the kernel (unit diagonal for ``other=None``).

    Returns
    -------
    ndarray of shape (N, M)
        The Gram matrix (``M = N`` and exactly symmetric when ``other`` is ``None``).

    Raises
    ------
    ValueError
        Shapes that do not match, a bad ``kernel``, a non-positive ``gamma``, ``gamma`` with a
        kernel that has none.
    TypeError
        ``normalize`` not a bool.

    Examples
    --------
    >>> import numpy as np
    >>> F = [np.array([[1.0], [2.0]]), np.array([[2.0], [1.0]])]
    >>> X = aligned_features(F, np.array([[0, 1], [1, 0]]))   # the same graph, relabelled
    >>> assignment_kernel(X)
    array([[1., 1.],
           [1., 1.]])
    >>> assignment_kernel(X, kernel="gaussian", normalize=False)
    array([[2., 2.],
           [2., 2.]])
    """
    check_choice(kernel, "kernel", KERNELS)
    X = check_array(aligned, "aligned", ndim=3)
    if 0 in X.shape:
        raise ValueError(f"`aligned` must have shape (N, n, f) with N, n, f >= 1, got shape "
                         f"{X.shape}")
    Y = X if other is None else check_array(other, "other", ndim=3)
    if Y.shape[0] == 0:
        raise ValueError(f"`other` must hold at least one graph, got shape {Y.shape}")
    if Y.shape[1:] != X.shape[1:]:
        raise ValueError(f"`other` must have shape (M, {X.shape[1]}, {X.shape[2]}) like "
                         f"`aligned`, got shape {Y.shape}")
    check_bool(normalize, "normalize")
    if kernel == "gaussian":
        gamma = median_gamma(X) if gamma is None else check_width(gamma, "gamma", inverse=True)
        with np.errstate(over="ignore", invalid="ignore"):
            K = _gaussian_gram(X, Y, gamma)
        dx = (X[..., -1] ** 2).sum(1)
        dy = dx if other is None else (Y[..., -1] ** 2).sum(1)
    else:
        if gamma is not None:
            raise ValueError(f"`gamma` applies to kernel='gaussian' only, got gamma={gamma!r} "
                             f"with kernel={kernel!r}")
        Xf = X.reshape(X.shape[0], -1)
        Yf = Xf if other is None else Y.reshape(Y.shape[0], -1)
        with np.errstate(over="ignore", invalid="ignore"):
            K = Xf @ Yf.T
            dx = np.einsum("ij,ij->i", Xf, Xf)
            dy = dx if other is None else np.einsum("ij,ij->i", Yf, Yf)
    _check_overflow(K, dx, dy, "aligned", "aligned" if other is None else "other")
    if other is not None:
        return cosine_normalize(K, dx, dy) if normalize else K
    if normalize:
        K = cosine_normalize(K)
    return 0.5 * (K + K.T)                                   # exactly symmetric


def _check_connected(pr: np.ndarray, N: int) -> None:
    """Refuse ``pairs`` that leave the graphs in several groups (no universe links them),
    saying how to fix it here; the synchronization's own message offers an option this
    function does not have."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    G = coo_matrix((np.ones(pr.shape[0]), (pr[:, 0], pr[:, 1])), shape=(N, N))
    n_comp, comp = connected_components(G, directed=False)
    if n_comp > 1:
        other = np.flatnonzero(comp != comp[0])
        raise DegenerateInputError(
            f"`pairs` must connect all {N} graphs, got {n_comp} groups (graph 0 is not linked "
            f"to graph {int(other[0])}); add pairs between the groups, e.g. from view_graph()")


def _check_overflow(K: np.ndarray, dx: np.ndarray, dy: np.ndarray, name: str,
                    name_y: str | None = None) -> None:
    """A ``ValueError`` naming the features (``name`` for the rows, ``name_y`` for the
    columns) when the kernel overflowed float64 (huge features)."""
    name_y = name if name_y is None else name_y
    if np.isfinite(K).all() and np.isfinite(dx).all() and np.isfinite(dy).all():
        return
    which = (name if not np.isfinite(dx).all() else name_y if not np.isfinite(dy).all()
             else name if name == name_y else f"{name}` and `{name_y}")
    raise ValueError(f"the values of `{which}` are too large: the kernel overflows float64; "
                     f"rescale the node features")


def _matched_pairs(pairs, N: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows ``(i, j)`` of ``pairs`` checked to cover every unordered pair of ``N`` graphs once."""
    pr = check_index_pairs(pairs, N, what="graph indices", distinct=True, unique=True,
                           complete="the kernel compares every pair through its own map")
    return pr[:, 0], pr[:, 1]


def pairwise_assignment_kernel(features, assignments, pairs, *, kernel: str = "linear",
                               gamma=None, normalize: bool = True) -> np.ndarray:
    r"""The assignment kernel on the *unsynchronized* pairwise maps: the non-transitive
    counterpart of :func:`assignment_kernel` (thesis Table 4.2's "HKS + RRWM" / "HKS + SM"
    kernels, which the transitive ones replace).

    Every pair is compared through its own matched permutation :math:`\pi_{ij}`
    (``assignments``, from :func:`match_pairs`) instead of the universe slots:

    * ``"linear"``: :math:`k_{ij} = \sum_u \langle \bar f_i(u), \bar f_j(\pi_{ij}(u))
      \rangle`;
    * ``"gaussian"``: :math:`k_{ij} = \sum_u \delta_i(u)\,\delta_j(\pi_{ij}(u))\,
      \exp(-\gamma \|\bar f_i(u) - \bar f_j(\pi_{ij}(u))\|^2)`,

    with :math:`\bar f = [f, \delta]` the features of the padded nodes and the real-node
    indicator, exactly the slot features of :func:`aligned_features`; the diagonal is each
    graph matched to itself. When the maps are transitive (``pi_ij = labels_j^{-1} o labels_i``
    for one labelling) this *is* :func:`assignment_kernel` on the aligned features (tested);
    for the maps of a pairwise matcher it is **indefinite in general**, because the maps
    contradict each other around cycles -- the defect the transitive kernel removes.

    Parameters
    ----------
    features : sequence of N arrays of shape (n_i, f)
        Node features of the real nodes (the same as for :func:`aligned_features`).
    assignments : ndarray of shape (P, n), int
        Row ``p`` maps padded node ``u`` of graph ``pairs[p, 0]`` to padded node
        ``assignments[p, u]`` of graph ``pairs[p, 1]`` (the layout of :func:`match_pairs`);
        every row a permutation of ``range(n)``, ``n`` at least the largest graph.
    pairs : array_like of shape (P, 2), int
        The matched pairs: every unordered pair of distinct graphs exactly once, in either
        orientation (``(j, i)`` with the inverse map gives the same kernel).
    kernel : {"linear", "gaussian"}, default="linear"
        The node kernel (``"relaxed"`` has no pairwise counterpart).
    gamma : float > 0, optional
        Gaussian width; default ``1 / median`` of the squared distances of the matched
        real-real nodes (over all pairs up to 2000 of them, else 2000 pairs drawn with a fixed
        seed) -- the rule of :func:`median_gamma` applied to the pairwise maps.
    normalize : bool, default=True
        Cosine-normalize (unit diagonal).

    Returns
    -------
    ndarray of shape (N, N)
        Exactly symmetric kernel matrix.

    Raises
    ------
    ValueError
        ``assignments`` not (P, n) with permutation rows, ``n`` below the largest graph,
        ``pairs`` that miss or repeat a pair of graphs, pair a graph with itself or index
        outside the graphs; a bad ``kernel``, a non-positive ``gamma`` or ``gamma`` with
        ``kernel="linear"``.
    TypeError
        ``normalize`` not a bool; non-integer ``assignments`` or ``pairs``.

    Examples
    --------
    Three one-node-feature graphs whose pairwise maps disagree around the cycle 0 -> 1 -> 2
    -> 0 (the transitive map 0 -> 2 is the identity, the matched one swaps):

    >>> import numpy as np
    >>> F = [np.array([[1.0], [0.0]])] * 3
    >>> pairs = np.array([[0, 1], [0, 2], [1, 2]])
    >>> maps = np.array([[0, 1], [1, 0], [0, 1]])
    >>> pairwise_assignment_kernel(F, maps, pairs, normalize=False)
    array([[3., 3., 2.],
           [3., 3., 3.],
           [2., 3., 3.]])
    """
    check_choice(kernel, "kernel", ("linear", "gaussian"))
    check_bool(normalize, "normalize")
    feats = check_feature_list(features)
    N = len(feats)
    A = check_int_array(assignments, "assignments", 2)
    i, j = _matched_pairs(pairs, N)
    if A.shape[0] != i.size or A.shape[1] < 1:
        raise ValueError(f"`assignments` must have shape (P, n) = ({i.size}, n), one row per "
                         f"pair of `pairs`, got shape {A.shape}")
    n = A.shape[1]
    _check_permutation_rows(A, "assignments")
    X = _padded_features(feats, n)                          # own node order, real first
    if kernel == "gaussian":
        gamma = (_pairwise_median_gamma(X, i, j, A) if gamma is None
                 else check_width(gamma, "gamma", inverse=True))
    elif gamma is not None:
        raise ValueError(f"`gamma` applies to kernel='gaussian' only, got gamma={gamma!r}")
    K = np.zeros((N, N))
    step = max(1, _SLOT_BLOCK_ELEMENTS // (n * X.shape[2]))
    with np.errstate(over="ignore", invalid="ignore"):
        for s in range(0, A.shape[0], step):                # blocks of pairs in lock-step
            e = slice(s, s + step)
            Xi, Xj = X[i[e]], X[j[e][:, None], A[e]]
            if kernel == "linear":
                vals = np.einsum("puf,puf->p", Xi, Xj)
            else:
                d2 = ((Xi - Xj) ** 2).sum(-1)
                vals = (Xi[..., -1] * Xj[..., -1] * np.exp(-gamma * d2)).sum(1)
            K[i[e], j[e]] = vals
            K[j[e], i[e]] = vals
        diag = (np.einsum("guf,guf->g", X, X) if kernel == "linear" else X[..., -1].sum(1))
    _check_overflow(K, diag, diag, "features")
    K[np.diag_indices(N)] = diag
    if normalize:
        K = cosine_normalize(K)
    return 0.5 * (K + K.T)


def _pairwise_median_gamma(X: np.ndarray, i: np.ndarray, j: np.ndarray, A: np.ndarray) -> float:
    """``1 / median`` squared distance of matched real-real nodes (:func:`median_gamma`'s rule)."""
    P = i.size
    if P == 0:
        return 1.0
    if P > _GAMMA_SAMPLE_PAIRS:
        pick = np.sort(np.random.default_rng(0).choice(P, _GAMMA_SAMPLE_PAIRS, replace=False))
        i, j, A = i[pick], j[pick], A[pick]
    return _inverse_median(X[i], X[j[:, None], A], "features")


# --------------------------------------------------------------------------------------------
# pruning
# --------------------------------------------------------------------------------------------

def prune_by_size(sizes, y, *, quantile: float | None = 0.95, max_nodes: int | None = None,
                  min_class_size: int = 10) -> tuple[np.ndarray, str]:
    """Drop graphs much larger than the bulk, then classes left with few graphs (§2.2 step 1).

    Every pairwise problem has the size of the largest graph, so a few big graphs make all of
    them expensive. Kept: graphs with ``n_i <= min(quantile of sizes, max_nodes)``, then the
    classes with at least ``min_class_size`` kept graphs.

    Parameters
    ----------
    sizes : array of shape (G,), int
        Node counts.
    y : array of shape (G,)
        Class labels.
    quantile : float in (0, 1], optional, default=0.95
        Size percentile cap (``numpy.quantile``, linear interpolation); None: no percentile cap.
    max_nodes : int, optional
        Absolute cap.
    min_class_size : int, default=10
        Classes with fewer kept graphs are dropped (0 keeps every class).

    Returns
    -------
    keep : ndarray of int64
        Sorted indices of the kept graphs.
    rule : str
        The thresholds and counts, for the experiment's log.

    Raises
    ------
    ValueError
        Mismatched lengths, bad thresholds, or a rule that keeps no graph.

    Examples
    --------
    >>> keep, rule = prune_by_size([5, 6, 7, 50], [0, 0, 1, 1], quantile=0.75,
    ...                            min_class_size=1)
    >>> keep.tolist()
    [0, 1, 2]
    >>> rule
    'kept 3/4 graphs, 2/2 classes: n_i <= 17 (0.75 size quantile 17.75); ... max 7'
    """
    s = check_int_array(sizes, "sizes", 1)
    if s.size == 0:
        raise ValueError("`sizes` must hold at least one graph size, got none")
    if s.min() < 1:
        raise ValueError(f"`sizes` must be positive node counts, got minimum {int(s.min())}")
    yy = np.asarray(y)
    if yy.ndim != 1 or yy.shape[0] != s.shape[0]:
        raise ValueError(f"`y` must have shape ({s.shape[0]},) like `sizes`, got shape "
                         f"{yy.shape}")
    min_class_size = check_int(min_class_size, "min_class_size", minimum=0)
    cap = np.inf
    parts = []
    if quantile is not None:
        q = check_positive(quantile, "quantile")
        if q > 1:
            raise ValueError(f"`quantile` must lie in (0, 1], got {quantile!r}")
        qv = float(np.quantile(s, q))
        cap = np.floor(qv)
        parts.append(f"{q:g} size quantile {qv:g}")
    if max_nodes is not None:
        mx = check_int(max_nodes, "max_nodes", minimum=1)
        cap = min(cap, min(mx, int(s.max())))       # int64-safe: above the largest, no cap
        parts.append(f"max_nodes {mx}")
    size_ok = s <= cap
    classes, inverse = class_labels(yy, "y")
    counts = np.bincount(inverse[size_ok], minlength=classes.size)
    class_ok = counts >= min_class_size
    keep = np.flatnonzero(size_ok & class_ok[inverse]).astype(np.int64)
    cap_txt = f"n_i <= {int(cap)} ({', '.join(parts)})" if np.isfinite(cap) else "no size cap"
    dropped = classes[~class_ok]
    cls_txt = f"classes with >= {min_class_size} kept graphs"
    if dropped.size:
        cls_txt += f" (dropped classes {dropped.tolist()})"
    if keep.size == 0:
        raise ValueError(f"the size pruning keeps no graph: every class has fewer than "
                         f"{min_class_size} graphs with {cap_txt}")
    kept_classes = int(np.unique(inverse[keep]).size)
    rule = (f"kept {keep.size}/{s.size} graphs, {kept_classes}/{classes.size} classes: "
            f"{cap_txt}; {cls_txt}; kept n mean {s[keep].mean():.1f}, max {int(s[keep].max())}")
    return keep, rule
