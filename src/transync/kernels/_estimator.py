"""``TransitiveAssignmentKernel``: the transitive assignment kernel, a scikit-learn transformer."""

from __future__ import annotations

import copy
import dataclasses
import numbers
from collections.abc import Sequence

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted

from .._progress import progress_bar
from .._validation import (as_generator, check_bool, check_choice, check_int, check_int_array,
                           check_positive)
from ..graphs import Graph, canonical_node_order
from ._checks import check_label_array, check_sequence, check_width
from ._hks import hks_features
from ._pairwise import PAIRWISE_MATCHERS, default_sigma2, match_pairs
from ._transitive import (
    KERNELS,
    SYNC_METHODS,
    _check_permutation_rows,
    aligned_features,
    assignment_kernel,
    graph_descriptors,
    median_gamma,
    nearest_graphs,
    place_graphs,
    relaxed_features,
    synchronize_alignments,
    view_graph,
)

__all__ = ["TransitiveAssignmentKernel"]


def _check_graphs(X, name: str = "X") -> list[Graph]:
    """A non-empty sequence of :class:`~transync.graphs.Graph` (a TU data set's ``.graphs``)."""
    if not isinstance(X, (Sequence, np.ndarray)) and isinstance(getattr(X, "graphs", None),
                                                                Sequence):
        X = X.graphs                                        # e.g. a TUDataset
    if isinstance(X, np.ndarray) and (X.dtype != object or X.ndim != 1):
        raise TypeError(f"`{name}` must be a sequence of Graph objects, got an array of shape "
                        f"{X.shape} and dtype {X.dtype}")
    graphs = check_sequence(X, name, "a sequence of Graph objects", arrays=True)
    for k, g in enumerate(graphs):
        if not isinstance(g, Graph):
            raise TypeError(f"`{name}[{k}]` must be a transync.graphs.Graph, got "
                            f"{type(g).__name__}")
        if g.adjacency.shape[0] == 0:
            raise ValueError(f"`{name}[{k}]` has no nodes; every graph needs at least one")
        if g.directed:          # checked here so that the message names `X`, not hks' input
            raise ValueError(f"`{name}[{k}]` must be an undirected graph (the heat kernel "
                             "signature needs a symmetric Laplacian)")
        if g.node_labels is not None:
            check_label_array(g.node_labels, f"{name}[{k}].node_labels")
    return graphs


def _int_labels(g: Graph) -> np.ndarray:
    """A graph's node labels as int64 (bool labels as 0 / 1; checked by :func:`_check_graphs`)."""
    return np.asarray(g.node_labels).astype(np.int64)


def _bagged_pairs(pairs: np.ndarray, n_graphs: int, fraction: float,
                  rng: np.random.Generator) -> np.ndarray:
    """Mask of a bootstrap-like subsample of the matched pairs: each pair kept with probability
    ``fraction``, plus the pairs of a uniformly random-weighted minimum spanning forest of the
    pair graph, so that the subsample connects every graph the full pair set connects (the
    synchronization needs a connected view graph). ``pairs``: distinct ``(i, j)``, ``i < j``,
    as :func:`view_graph` returns them."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import minimum_spanning_tree

    P = pairs.shape[0]
    keep = rng.random(P) < fraction
    if P:
        shape = (n_graphs, n_graphs)
        weights = csr_matrix((1.0 + rng.random(P), (pairs[:, 0], pairs[:, 1])), shape=shape)
        index = csr_matrix((np.arange(1, P + 1, dtype=np.float64), (pairs[:, 0], pairs[:, 1])),
                           shape=shape)
        tree = minimum_spanning_tree(weights).tocoo()
        i, j = np.minimum(tree.row, tree.col), np.maximum(tree.row, tree.col)
        keep[np.asarray(index[i, j]).ravel().astype(np.int64) - 1] = True
    return keep


def _plain_executor(executor) -> bool:
    """None, a name or a worker count: a description that copies and pickles as it is."""
    return executor is None or isinstance(executor, (str, numbers.Integral))


def _node_orders(graphs: list[Graph], use_labels: bool) -> list[np.ndarray]:
    """Each graph's :func:`~transync.graphs.canonical_node_order` (on its node labels when the
    kernel uses them): the estimator computes on the graphs in this order, so that its ties
    (equal node affinities, equal eigenvalues) fall the same way however the nodes were
    numbered."""
    return [canonical_node_order(g.adjacency, _int_labels(g) if use_labels else None)
            for g in graphs]


def _padded_orders(orders, n: int) -> np.ndarray:
    """(N, n) int64: row ``g`` is ``orders[g]`` followed by the dummies ``n_g..n-1`` in place
    (canonical padded node ``k`` is the caller's padded node ``[g, k]``)."""
    out = np.tile(np.arange(n, dtype=np.int64), (len(orders), 1))
    for g, o in enumerate(orders):
        out[g, :len(o)] = o
    return out


def _inverse_rows(P: np.ndarray) -> np.ndarray:
    """Row-wise inverse permutations of the (N, n) array ``P``."""
    inv = np.empty_like(P)
    np.put_along_axis(inv, P, np.arange(P.shape[1], dtype=P.dtype)[None, :], axis=1)
    return inv


def _renumber_maps(A: np.ndarray, pairs: np.ndarray, source: np.ndarray,
                   target: np.ndarray) -> np.ndarray:
    """Pairwise maps ``A[r]`` (node ``u`` of ``pairs[r, 0]`` -> node ``A[r, u]`` of
    ``pairs[r, 1]``) in another numbering: ``source[g, k]`` is the old number of new node
    ``k`` of graph ``g`` and ``target`` its inverse (both (N, n))."""
    if not len(A):
        return A
    moved = np.take_along_axis(A, source[pairs[:, 0]].astype(A.dtype, copy=False), axis=1)
    return np.take_along_axis(target[pairs[:, 1]], moved.astype(np.int64, copy=False),
                              axis=1).astype(A.dtype, copy=False)


def _fitted_twins(new_adjacency, new_features, new_labels, fit_adjacency, fit_features,
                  fit_labels) -> np.ndarray:
    """For every new graph, the first fitted graph it equals in canonical node order (the same
    adjacency, node labels and HKS features, the features to 1e-12), or -1.

    Such a copy is placed where the fit put its twin: the identity is its exact map to the
    twin, and the twin's labels compose it consistently. The vote over its matches to all
    fitted graphs can land elsewhere when the votes tie (symmetric graphs: which of two
    automorphic nodes a match picks decides them, and floating-point order decides that).
    """
    def key(A, labels):
        A = np.ascontiguousarray(A, dtype=float) + 0.0          # -0.0 -> 0.0: the same bytes
        return A.shape[0], A.tobytes(), None if labels is None else labels.tobytes()

    index: dict = {}
    for j, A in enumerate(fit_adjacency):
        index.setdefault(key(A, None if fit_labels is None else fit_labels[j]), []).append(j)
    twins = np.full(len(new_adjacency), -1, dtype=np.int64)
    for t, A in enumerate(new_adjacency):
        for j in index.get(key(A, None if new_labels is None else new_labels[t]), ()):
            if np.allclose(new_features[t], fit_features[j], rtol=0.0, atol=1e-12):
                twins[t] = j
                break
    return twins


def _renumber_alignment(alignment, index: np.ndarray):
    """The :class:`~transync.kernels.Alignment` with its node rows (labels, embedding,
    ``info["degrees"]``) taken at ``index`` ((N, n): new node ``k`` of graph ``g`` is old node
    ``index[g, k]``)."""
    emb = alignment.embedding
    if emb is not None:
        emb = np.take_along_axis(emb, index[:, :, None], axis=1)
    info = dict(alignment.info)
    if "degrees" in info:
        info["degrees"] = np.take_along_axis(np.asarray(info["degrees"]), index, axis=1)
    return dataclasses.replace(alignment, labels=np.take_along_axis(alignment.labels, index,
                                                                    axis=1),
                               embedding=emb, info=info)


class TransitiveAssignmentKernel(TransformerMixin, BaseEstimator):
    r"""Transitive assignment kernel (TAK; Schiavinato, Gasparetto, Torsello, SIMBAD 2015).

    A PSD graph kernel built on node alignments made transitive (methods page *Transitive
    assignment kernels*): every graph
    is padded with dummy nodes to ``n`` nodes, matched to every other one (``matcher``), the
    pairwise permutations are synchronized onto one universe of ``n`` slots (``sync``), and
    graphs are compared slot by slot on their node features (heat kernel signature, plus
    node-label one-hots), then cosine-normalized:

    .. math:: k(G_i, G_j) = \sum_{a=1}^{n} \kappa(\tilde F_i[a], \tilde F_j[a]),
              \qquad \tilde F_i = P_i^\top F_i .

    The output feeds ``sklearn.svm.SVC(kernel="precomputed")``.

    **Transductive vs inductive.** :meth:`fit` synchronizes all the graphs it is given, so when
    the test graphs are among them (e.g. ``fit_transform`` on a whole data set before
    cross-validation) the alignment is *transductive*: it uses the test graphs' structure, never
    their labels. :meth:`transform` on new graphs is *inductive*: the fitted universe stays
    fixed, each new graph is matched to every fitted graph and placed by
    ``P_t = Hungarian(sum_j P_tj P_j)`` (methods page *Transitive assignment kernels*,
    *Transductive and inductive use*; for ``kernel="relaxed"`` also
    ``Q_t = polar(sum_j P_tj Q_j)``), then compared with the fitted graphs; in a ``Pipeline``
    / ``GridSearchCV`` the test folds are handled this way. ``transform`` of the very objects
    passed to ``fit`` (the same list of the same ``Graph`` objects) returns ``gram_`` (the
    transductive rows) rather than re-placing them.

    The inductive rows approximate the transductive ones. A new graph equal to a fitted one in
    canonical node order (:func:`transync.graphs.canonical_node_order`: the same adjacency, node
    labels and HKS features) is placed where the fit put that graph (the first such, when the
    fit held duplicates), so it gets that graph's row of ``gram_``: the vote would give it only
    when the matches are consistent and no votes tie (symmetric graphs tie them, and
    floating-point order then decides). The canonical order is not a full canonical labelling
    (graphs that colour refinement cannot split, e.g. a triangle beside a 4-cycle, can have
    several forms): a copy of such a graph in another form is placed by the vote.

    **View graph for large sets** (``n_neighbors = k``). Matching all ``N (N - 1) / 2`` pairs
    does not scale (NCI1: 7.6 million pairs). With ``k``, each graph is matched only to its
    ``k`` nearest graphs under a cheap descriptor (:func:`transync.kernels.graph_descriptors`:
    mean HKS, plus the node-label histogram when labels are used), and the pairs of a minimum
    spanning tree of the same descriptor distances are added so that the view graph is
    connected (:func:`transync.kernels.view_graph`; at most ``N k + N - 1`` pairs). The
    synchronization makes these sparse matches transitive, and the kernel is still computed on
    *all* pairs from the aligned features -- which is the point of transitivity: two graphs
    that were never matched are compared through the universe. ``transform`` places a new
    graph through matches to its ``k`` nearest fitted graphs only. ``k >= N - 1`` is the same
    as ``None`` (all pairs).

    **Options fixed at fit.** :meth:`transform` uses the options in force at :meth:`fit`
    (``kernel_``, ``matcher_``, ``sync_``, ``times_``, ``sync_dummies_``, ``normalize_``,
    ``label_values_``, ``sigma2_``, ``gamma_``), not parameters changed afterwards by
    ``set_params``; refit to apply those.

    **Node numbering does not matter.** Every graph is matched, synchronized and placed in its
    canonical node order (:func:`transync.graphs.canonical_node_order` on its adjacency and,
    when used, node labels; ``node_order_``), so the many exact ties of the pipeline (nodes
    with equal features, equal node affinities, equal eigenvalues) are broken the same way
    however the nodes of the input were numbered: renumbering the nodes of any graph leaves
    ``gram_`` and :meth:`transform` unchanged (exactly, whenever the canonical order is
    canonical: on the five TU sets of the ``kernels`` experiment, every graph). Before
    2026-11-28 the ties fell by node index, and five renumberings of MUTAG moved
    TAK-node-gauss's 10 x 10-fold accuracy over 88.6-89.9 (docs/kernels.md). The node-indexed
    attributes (``features_``, ``kernel_features_``, ``assignments_``, ``labels_``, the
    alignments' labels, embedding and degrees) are given in the caller's numbering.

    **Node labels.** When labels are used, a correspondence between two nodes of different
    labels (node affinity 0, an arbitrary tie) is not synchronized and does not vote in the
    placement (``drop_label_mismatches``, with ``sync_dummies=False``).

    **Universe size in cross-validation.** ``transform`` cannot place a graph larger than the
    fitted universe (``n_universe_``, by default the largest *fitted* graph); inside
    ``GridSearchCV`` pass ``n_universe`` = the largest graph of the whole data set (after
    :func:`transync.kernels.prune_by_size`), so every test fold fits.

    Parameters
    ----------
    matcher : {"rrwm", "sm", "node"}, default="rrwm"
        Pairwise matcher (:func:`transync.kernels.match_pairs`): reweighted random walks or
        spectral matching on the HKS + structure affinity, or the node-only assignment (fast).
        In the ``kernels`` experiment (docs/kernels.md) ``matcher="node"`` with
        ``kernel="gaussian"`` was the most accurate variant on every set but PTC_MR and 2-3.5x
        faster than RRWM; the defaults are the thesis's pipeline.
    sync : {"orthogonal", "spectral"}, default="orthogonal"
        Synchronization (:func:`transync.kernels.synchronize_alignments`).
    kernel : {"linear", "gaussian", "relaxed"}, default="linear"
        Slot kernel (:func:`transync.kernels.assignment_kernel`); ``"relaxed"`` uses the
        unrounded ``Q_i``.
    times : array_like of shape (T,), optional
        HKS times; default :data:`transync.kernels.HKS_TIMES`.
    sigma2 : float, optional
        Width of the matcher's node affinity; default: the matcher's rule, fixed at ``fit`` and
        reused by ``transform`` (``sigma2_``).
    gamma : float, optional
        Width of the Gaussian slot kernel; default :func:`transync.kernels.median_gamma` of the
        fitted aligned features (``gamma_``). Used by ``kernel="gaussian"`` only.
    node_labels : {"auto", True, False}, default="auto"
        Use integer node labels (in the matcher's affinity and as one-hot kernel features);
        ``"auto"``: when every fitted graph has them. Labels unseen at fit get a zero one-hot.
    n_universe : int, optional
        Padded size / universe; default the largest fitted graph. Larger graphs cannot be
        transformed.
    n_neighbors : int, optional
        View graph (see above): match each graph to its ``n_neighbors`` nearest graphs (plus a
        spanning tree) instead of all pairs, and place new graphs through their
        ``n_neighbors`` nearest fitted graphs. None (default): all pairs.
    sync_dummies : bool, default=False
        Feed the dummy nodes' matches to the synchronization too (full padded permutations, the
        outline's literal form). Default: only real-to-real correspondences are synchronized
        and each graph's dummies fill its free slots, since the dummies' matches among
        themselves are arbitrary (all dummies look alike) and only add noise. On MUTAG (3 x
        10-fold CV) this helped the node matcher's linear kernel (82 -> 84-88) and left the
        others within about 1-2 points; it makes ``sync="spectral"`` faster (smaller block
        matrix) but ``"orthogonal"`` needs more polar sweeps.
    drop_label_mismatches : bool, default=True
        With node labels (and ``sync_dummies=False``), leave the matches between nodes of
        different labels out of the synchronization and of the placement vote: their node
        affinity is 0, so with the node matcher they are ties broken by index. Measured with
        ``matcher="node"``, transductive 3 x 10-fold CV (indicative): the hard kernels gain
        on PTC_MR with ``"orthogonal"`` (linear 56.1 -> 59.7, gaussian 55.4 -> 57.6), the
        relaxed kernel loses (PTC_MR 64.9 -> 59.1 orthogonal, 63.1 -> 59.9 spectral; MUTAG
        86.5 -> 83.7 orthogonal), the rest moves by about 1 point.
    normalize : bool, default=True
        Cosine normalization (each graph's own self-similarity, new graphs included).
    n_alignments : int, default=1
        Ensemble size ``R`` (1 to 1000): the Gram matrix is the mean of the kernels of ``R``
        synchronizations of the same pairwise matches -- the first on all matched pairs (the
        single-alignment kernel: ``n_alignments=1`` is exactly it), the others each on a random
        subsample of the pairs (bagging, ``pair_fraction``). A mean of PSD matrices is PSD
        (with unit diagonal when ``normalize``). The synchronization settles in one of many
        nearly-equal local optima, and averaging over several smooths that arbitrary choice
        (ENZYMES, node matcher, Gaussian kernel, 10 x 10-fold CV: 49.2 -> 51.0 with ``R = 5``;
        docs/kernels.md). Costs ``R`` synchronizations; the matching is shared.
        :meth:`transform` places new graphs in every member's universe and averages likewise.
    pair_fraction : float in (0, 1], default=0.7
        Share of the matched pairs each member after the first synchronizes: each pair is kept
        with this probability, and the pairs of a random spanning forest of the matched pairs
        are always kept, so the subsample connects the graphs as the full set does. With 1.0
        the members differ only through the eigensolver's random start, which small problems
        (the dense path) do not have: there they coincide.
    executor : None, "serial", "processes", int or executor, optional
        Runs the pairwise matching (:func:`transync.parallel.map_chunks`). An executor *object*
        (``concurrent.futures`` pool, ``dask.distributed.Client``) is shared, not copied, by
        :func:`sklearn.base.clone` (so ``GridSearchCV`` and ``Pipeline`` work with it), and is
        dropped to ``None`` (serial) when the estimator is pickled: a pool cannot be pickled.
    progress : bool, default=False
        Progress bars over the pairwise matching and, with ``n_alignments > 1``, over the
        ensemble's synchronizations.
    random_state : None, int or numpy.random.Generator
        Seeds the matcher, the eigensolver and the ensemble's pair subsamples.

    Attributes
    ----------
    kernel_, matcher_, sync_ : str
        The options of the fit (used by :meth:`transform`).
    times_ : ndarray or None
        HKS times of the fit (None: the default grid).
    sync_dummies_, drop_label_mismatches_, normalize_ : bool
    n_universe_ : int
    graphs_ : tuple of Graph
        The fitted graphs.
    node_order_ : tuple of ndarray
        The canonical node order the fit computed in, per graph
        (:func:`transync.graphs.canonical_node_order`): its node ``k`` is the caller's node
        ``node_order_[i][k]``.
    features_ : list of ndarray
        HKS of the fitted graphs, ``(n_i, T)``.
    kernel_features_ : list of ndarray
        Node features the kernel compares (HKS and label one-hots).
    label_values_ : ndarray or None
        Node labels with a one-hot column (None: labels not used).
    alignment_ : Alignment
        The synchronization result (of all matched pairs: the ensemble's first member).
    labels_ : ndarray of shape (N, n)
        Slot of every padded node of every fitted graph (in ``alignment_``).
    aligned_ : ndarray of shape (N, n, f + 1)
        Aligned (or relaxed) features of the fitted graphs (in ``alignment_``).
    alignments_ : tuple of Alignment
        Every member's synchronization, ``n_alignments`` of them (``alignments_[0]`` is
        ``alignment_``).
    member_aligned_, member_gamma_ : tuple
        Every member's aligned features and Gaussian width (``[0]``: ``aligned_``, ``gamma_``).
    member_pairs_ : ndarray of shape (n_alignments, P), bool
        The matched pairs (rows of ``pairs_``) each member synchronized.
    gram_ : ndarray of shape (N, N)
        Fitted (transductive) Gram matrix: the mean of the members' kernels.
    sigma2_ : float or None
    gamma_ : float or None
    assignments_ : ndarray of shape (P, n)
        The pairwise permutations of all fitted pairs (``pairs_``).
    pairs_ : ndarray of shape (P, 2)
        The matched pairs: all pairs, or the view graph's (``n_neighbors``).
    n_neighbors_ : int or None
        The view graph's ``k`` of the fit (None: all pairs).
    descriptors_ : ndarray of shape (N, d)
        The fitted graphs' view-graph descriptors (:func:`transync.kernels.graph_descriptors`).

    Examples
    --------
    >>> import numpy as np
    >>> from transync.graphs import Graph
    >>> from transync.kernels import TransitiveAssignmentKernel
    >>> path = np.diag(np.ones(3), 1); path = path + path.T
    >>> star = np.zeros((4, 4)); star[0, 1:] = star[1:, 0] = 1
    >>> graphs = [Graph(path), Graph(star), Graph(path[::-1, ::-1].copy()), Graph(star)]
    >>> tak = TransitiveAssignmentKernel(matcher="node", random_state=0)
    >>> K = tak.fit_transform(graphs)
    >>> K.shape, bool(np.allclose(K, K.T)), bool(np.allclose(K[0, 2], 1.0))
    ((4, 4), True, True)
    >>> bool(np.linalg.eigvalsh(K).min() >= -1e-9)
    True
    >>> tak.transform([Graph(star)]).round(6).tolist() == [K[1].round(6).tolist()]
    True
    """

    def __init__(self, matcher: str = "rrwm", sync: str = "orthogonal", kernel: str = "linear",
                 times=None, sigma2=None, gamma=None, node_labels="auto", n_universe=None,
                 n_neighbors=None, sync_dummies: bool = False, drop_label_mismatches: bool = True,
                 normalize: bool = True, n_alignments: int = 1, pair_fraction: float = 0.7,
                 executor=None, progress: bool = False, random_state=None):
        self.matcher = matcher
        self.sync = sync
        self.kernel = kernel
        self.times = times
        self.sigma2 = sigma2
        self.gamma = gamma
        self.node_labels = node_labels
        self.n_universe = n_universe
        self.n_neighbors = n_neighbors
        self.sync_dummies = sync_dummies
        self.drop_label_mismatches = drop_label_mismatches
        self.normalize = normalize
        self.n_alignments = n_alignments
        self.pair_fraction = pair_fraction
        self.executor = executor
        self.progress = progress
        self.random_state = random_state

    def __sklearn_clone__(self):
        """:func:`sklearn.base.clone` that shares an executor object instead of deep-copying it
        (a thread pool or a Dask client cannot be copied)."""
        executor = self.executor
        if _plain_executor(executor):
            return super().__sklearn_clone__()
        proxy = copy.copy(self)                      # shallow: self is left untouched
        proxy.executor = None
        new = proxy.__sklearn_clone__()
        new.executor = executor
        return new

    def __getstate__(self):
        state = super().__getstate__()
        if not _plain_executor(state.get("executor")):
            state = dict(state, executor=None)     # a pool cannot be pickled: run serially
        return state

    def __setstate__(self, state):
        """Estimators pickled before the ensemble (``n_alignments``) load as one-member
        ensembles; those pickled before the canonical node order keep computing in the given
        order (their transform gives what it gave, but for copies of fitted graphs in the
        fitted numbering, which now get their fitted rows; refit to make it numbering-free)."""
        state = dict(state)
        state.setdefault("n_alignments", 1)
        state.setdefault("pair_fraction", 0.7)
        if "gram_" in state and "node_order_" not in state:     # fitted in the given order
            state["node_order_"] = tuple(np.arange(g.n_nodes, dtype=np.int64)
                                         for g in state["graphs_"])
            state["_given_order"] = True
        if "gram_" in state and "alignments_" not in state:
            state["alignments_"] = (state["alignment_"],)
            state["member_aligned_"] = (state["aligned_"],)
            state["member_gamma_"] = (state["gamma_"],)
            state["member_pairs_"] = np.ones((1, len(state["pairs_"])), dtype=bool)
        super().__setstate__(state)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False          # X is a sequence of graphs
        tags.requires_fit = True
        return tags

    # ----------------------------------------------------------------------------------------
    def _check_params(self) -> None:
        check_choice(self.matcher, "matcher", PAIRWISE_MATCHERS)
        check_choice(self.sync, "sync", SYNC_METHODS)
        check_choice(self.kernel, "kernel", KERNELS)
        if self.sigma2 is not None:
            check_width(self.sigma2, "sigma2")
        if self.gamma is not None:
            check_width(self.gamma, "gamma", inverse=True)
        if not (isinstance(self.node_labels, (bool, np.bool_))
                or (isinstance(self.node_labels, str) and self.node_labels == "auto")):
            raise ValueError(f"`node_labels` must be 'auto', True or False, got "
                             f"{self.node_labels!r}")
        if self.n_universe is not None:
            check_int(self.n_universe, "n_universe", minimum=1, maximum=10**6)
        if self.n_neighbors is not None:
            check_int(self.n_neighbors, "n_neighbors", minimum=1)
        check_int(self.n_alignments, "n_alignments", minimum=1, maximum=1000)
        if check_positive(self.pair_fraction, "pair_fraction") > 1:
            raise ValueError(f"`pair_fraction` must lie in (0, 1], got {self.pair_fraction!r}")
        for name in ("normalize", "progress", "sync_dummies", "drop_label_mismatches"):
            check_bool(getattr(self, name), name)
        if not isinstance(self.random_state, np.random.RandomState):   # (draws from it)
            as_generator(self.random_state, "random_state")             # before any work

    @staticmethod
    def _kernel_features(hks: list[np.ndarray], graphs: list[Graph],
                         vals: np.ndarray | None) -> list[np.ndarray]:
        """HKS, plus one-hots of the node labels seen at fit (unseen labels: all zeros)."""
        if vals is None:
            return hks
        out = []
        for h, g in zip(hks, graphs):
            lab = _int_labels(g)
            idx = np.searchsorted(vals, lab)
            idx = np.minimum(idx, vals.size - 1)
            onehot = (vals[idx] == lab)[:, None] & (np.arange(vals.size) == idx[:, None])
            out.append(np.hstack([h, onehot.astype(float)]))
        return out

    def _member_rng(self, r: int):
        """The ``rng`` of ensemble member ``r``: ``random_state`` itself for the first (so that
        ``n_alignments=1`` is the single-alignment kernel); then, for an int seed ``s``,
        ``default_rng([s, r])``; a Generator draws each member's seed when the member starts
        (after the first member's synchronization, which it seeds unchanged); None: fresh
        entropy."""
        rs = self.random_state
        if r == 0:
            return rs
        if isinstance(rs, numbers.Integral) and not isinstance(rs, (bool, np.bool_)):
            return np.random.default_rng([int(rs), r])
        return np.random.default_rng(as_generator(rs).integers(2**63))

    @staticmethod
    def _align(kernel: str, feats: list[np.ndarray], labels, embedding, n: int) -> np.ndarray:
        if kernel == "relaxed":
            return relaxed_features(feats, embedding)
        return aligned_features(feats, labels, n)

    # ----------------------------------------------------------------------------------------
    def fit(self, X, y=None, *, assignments=None):
        """Match the pairs of ``X`` (all, or the view graph's), synchronize them and compute
        the Gram matrix ``gram_`` of all pairs.

        Parameters
        ----------
        X : sequence of Graph
            Undirected graphs (a TU data set's ``.graphs``, or the data set itself).
        y : ignored
        assignments : ndarray of shape (P, n), int, optional
            Precomputed pairwise permutations of the pairs this fit matches (``pairs_`` of an
            earlier fit with the same graphs, ``matcher``, ``times``, ``node_labels``,
            ``n_universe`` and ``n_neighbors``: they decide the pairs and the matches), e.g. to
            synchronize one matching with both ``sync`` methods; the matcher is not run. Only
            the shape and that every row is a permutation are checked.

        Returns
        -------
        self

        Raises
        ------
        TypeError
            ``X`` not a sequence of graphs, ``assignments`` not of an integer dtype.
        ValueError
            An empty ``X``, a graph with no nodes, ``n_universe`` below the largest graph,
            ``node_labels=True`` with a graph that has none, ``assignments`` of the wrong
            shape or with a row that is not a permutation, bad parameters.
        """
        self._check_params()
        graphs = _check_graphs(X)
        N = len(graphs)
        sizes = np.array([g.n_nodes for g in graphs], dtype=np.int64)
        n = int(sizes.max())
        if self.n_universe is not None:
            if self.n_universe < n:
                k = int(np.argmax(sizes))
                raise ValueError(f"`n_universe` must be >= the largest graph (X[{k}] has {n} "
                                 f"nodes), got {self.n_universe}")
            n = int(self.n_universe)
        has_labels = [g.node_labels is not None for g in graphs]
        # True or np.True_ (validated: a bool or "auto")
        if not isinstance(self.node_labels, str) and self.node_labels and not all(has_labels):
            k = has_labels.index(False)
            raise ValueError(f"node_labels=True but `X[{k}]` has no node labels")
        use_labels = (bool(all(has_labels)) if isinstance(self.node_labels, str)
                      else bool(self.node_labels))
        # the work runs on each graph in its canonical node order (results mapped back below)
        orders = _node_orders(graphs, use_labels)
        work = [g.permute(o) for g, o in zip(graphs, orders)]
        order_n = _padded_orders(orders, n)
        inverse_n = _inverse_rows(order_n)
        node_labels = [_int_labels(g) for g in work] if use_labels else None
        label_values = np.unique(np.concatenate(node_labels)) if use_labels else None
        kernel, sync_dummies = self.kernel, bool(self.sync_dummies)
        drop = bool(self.drop_label_mismatches) and not sync_dummies
        hks = hks_features(work, self.times)                    # validates `times`
        times = None if self.times is None else np.array(self.times, dtype=float)
        descriptors = graph_descriptors(hks, node_labels, label_values)
        k = None if self.n_neighbors is None or self.n_neighbors >= N - 1 else int(
            self.n_neighbors)
        pairs = view_graph(descriptors, k)
        sigma2 = self._sigma2(hks)
        if assignments is not None:
            assignments = check_int_array(assignments, "assignments", keep_dtype=True)
            if assignments.shape != (pairs.shape[0], n):
                raise ValueError(f"`assignments` must have shape (P, n) = ({pairs.shape[0]}, "
                                 f"{n}), one row per matched pair, got shape "
                                 f"{assignments.shape}")
            _check_permutation_rows(assignments, "assignments")
            assignments = _renumber_maps(assignments, pairs, order_n, inverse_n)
        elif pairs.shape[0]:
            assignments = match_pairs(hks, [g.adjacency for g in work], pairs, n=n,
                                      matcher=self.matcher, sigma2=sigma2,
                                      node_labels=node_labels, executor=self.executor,
                                      progress=self.progress, rng=self.random_state)
        else:
            assignments = np.zeros((0, n), dtype=np.int32)
        kernel_features = self._kernel_features(hks, work, label_values)
        members, gram = [], None
        R = int(self.n_alignments)
        with progress_bar(R, "synchronizations", enabled=bool(self.progress) and R > 1,
                          unit="alignment") as bar:
            for r in range(R):
                # member 0: all pairs (the single-alignment kernel); then bagged pair subsets
                rng = self._member_rng(r)
                keep = (np.ones(pairs.shape[0], dtype=bool) if r == 0
                        else _bagged_pairs(pairs, N, float(self.pair_fraction), rng))
                alignment = synchronize_alignments(
                    assignments[keep], pairs[keep], N, n=n, sizes=None if sync_dummies else sizes,
                    node_labels=node_labels if drop else None, method=self.sync,
                    keep_embedding=kernel == "relaxed", rng=rng)
                aligned = self._align(kernel, kernel_features, alignment.labels,
                                      alignment.embedding, n)
                gamma = None
                if kernel == "gaussian":
                    gamma = float(self.gamma) if self.gamma is not None else median_gamma(aligned)
                K = assignment_kernel(aligned, kernel=kernel, gamma=gamma,
                                      normalize=bool(self.normalize))
                gram = K if gram is None else gram + K
                members.append((keep, alignment, aligned, gamma))
                bar.update()
        if len(members) > 1:
            gram /= len(members)
        # fitted attributes only now: a failed fit leaves no partly fitted estimator
        self.kernel_, self.matcher_, self.sync_ = kernel, self.matcher, self.sync
        self.times_, self.sync_dummies_, self.normalize_ = times, sync_dummies, bool(
            self.normalize)
        self.drop_label_mismatches_ = drop
        self.label_values_ = label_values
        self.sigma2_ = sigma2
        self.n_universe_ = n
        self.graphs_ = tuple(graphs)
        # node-indexed results in the caller's numbering
        back = [np.argsort(o) for o in orders]
        self.node_order_ = tuple(orders)
        self._given_order = False
        self.features_ = [h[b] for h, b in zip(hks, back)]
        self.kernel_features_ = [f[b] for f, b in zip(kernel_features, back)]
        self.pairs_ = pairs
        self.n_neighbors_ = k
        self.descriptors_ = descriptors
        self.assignments_ = _renumber_maps(assignments, pairs, inverse_n, order_n)
        self.member_pairs_ = np.array([m[0] for m in members]).reshape(len(members), -1)
        self.alignments_ = tuple(_renumber_alignment(m[1], inverse_n) for m in members)
        self.member_aligned_ = tuple(m[2] for m in members)
        self.member_gamma_ = tuple(m[3] for m in members)
        self.aligned_, self.gamma_ = members[0][2:]
        self.alignment_ = self.alignments_[0]
        self.labels_ = self.alignment_.labels
        self.gram_ = gram
        return self

    def _sigma2(self, hks: list[np.ndarray]) -> float:
        """The matcher's node-affinity width, fixed at fit so that transform uses the same."""
        if self.sigma2 is not None:
            return float(self.sigma2)
        return float(default_sigma2(hks, rng=self.random_state))

    def fit_transform(self, X, y=None, **fit_params):
        """Fit and return the (transductive) Gram matrix ``gram_`` of ``X``, shape (N, N)."""
        return self.fit(X, y, **fit_params).gram_.copy()

    def transform(self, X):
        """Gram matrix of ``X`` against the fitted graphs, shape ``(len(X), N)``.

        New graphs are placed inductively in the fitted universe (see the class docstring) and
        normalized by their own self-similarity; a graph equal to a fitted one up to its node
        numbering gets that graph's row of ``gram_``. ``X`` that is the fitted sequence itself
        (the same ``Graph`` objects, in order) returns a copy of ``gram_``.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            Before :meth:`fit`.
        TypeError
            ``X`` not a sequence of graphs.
        ValueError
            A graph larger than the fitted universe, a graph with no nodes, or missing node
            labels when the fit used them.
        """
        check_is_fitted(self, "gram_")
        graphs = _check_graphs(X)
        if len(graphs) == len(self.graphs_) and all(
                a is b for a, b in zip(graphs, self.graphs_)):
            return self.gram_.copy()
        n = self.n_universe_
        for k, g in enumerate(graphs):
            if g.n_nodes > n:
                raise ValueError(f"`X[{k}]` has {g.n_nodes} nodes, more than the fitted "
                                 f"universe size n_universe_={n}; refit with a larger "
                                 "`n_universe` or prune the large graphs")
        node_labels = None
        use_labels = self.label_values_ is not None
        if use_labels:
            missing = [k for k, g in enumerate(graphs) if g.node_labels is None]
            if missing:
                raise ValueError(f"`X[{missing[0]}]` has no node labels, but the kernel was "
                                 "fitted with node labels")
        # new and fitted graphs in their canonical node order, as at fit (a pickle from before
        # the canonical order keeps the given order)
        if not getattr(self, "_given_order", False):
            graphs = [g.permute(o) for g, o in zip(graphs, _node_orders(graphs, use_labels))]
        orders = self.node_order_
        order_n = _padded_orders(orders, n)
        if use_labels:
            node_labels = [_int_labels(g) for g in graphs]
        fitted_labels = (None if node_labels is None
                         else [_int_labels(g)[o] for g, o in zip(self.graphs_, orders)])
        hks = hks_features(graphs, self.times_)
        N, M = len(self.graphs_), len(graphs)
        nearest = None
        if self.n_neighbors_ is not None:                 # the k nearest fitted graphs only
            nearest = nearest_graphs(self.descriptors_, graph_descriptors(
                hks, node_labels, self.label_values_), self.n_neighbors_)
            t_idx = np.repeat(np.arange(M, dtype=np.int64), nearest.shape[1])
            j_idx = nearest.ravel()
        else:
            t_idx, j_idx = np.divmod(np.arange(M * N, dtype=np.int64), N)
        pairs = np.column_stack([N + t_idx, j_idx])
        adjacency = ([g.adjacency[np.ix_(o, o)] for g, o in zip(self.graphs_, orders)]
                     + [g.adjacency for g in graphs])
        fitted_features = [f[o] for f, o in zip(self.features_, orders)]
        assign = match_pairs(fitted_features + hks, adjacency, pairs, n=n,
                             matcher=self.matcher_, sigma2=self.sigma2_,
                             node_labels=None if node_labels is None else fitted_labels
                             + node_labels, executor=self.executor, progress=self.progress,
                             rng=self.random_state)
        assign = assign.reshape(M, -1, n)                  # int32: (M, N, n) can be large
        twins = _fitted_twins(adjacency[N:], hks, node_labels, adjacency[:N], fitted_features,
                              fitted_labels)
        t_twin = np.flatnonzero(twins >= 0)
        opts = {}
        if not self.sync_dummies_:                        # real-to-real, same-label votes only
            opts = {"sizes": np.array([g.n_nodes for g in graphs]),
                    "fitted_sizes": np.array([g.n_nodes for g in self.graphs_]),
                    "node_labels": node_labels if self.drop_label_mismatches_ else None,
                    "fitted_node_labels": fitted_labels if self.drop_label_mismatches_ else None}
        feats = self._kernel_features(hks, graphs, self.label_values_)
        out = None
        for alignment, fitted, gamma in zip(self.alignments_, self.member_aligned_,
                                            self.member_gamma_):
            alignment = _renumber_alignment(alignment, order_n)
            # placed in every fitted universe, kernels averaged as at fit
            emb = alignment.embedding if self.kernel_ == "relaxed" else None
            spectral = {}
            if emb is not None and self.sync_ == "spectral":
                spectral = {"degrees": alignment.info["degrees"],
                            "eigenvalues": alignment.info["eigenvalues"]}
            labels, Q = place_graphs(assign, alignment.labels, embedding=emb,
                                     method=self.sync_, fitted=nearest, **opts, **spectral)
            if t_twin.size:                  # copies of fitted graphs: where their twin is
                labels[t_twin] = alignment.labels[twins[t_twin]]
                if Q is not None:
                    Q[t_twin] = alignment.embedding[twins[t_twin]]
            K = assignment_kernel(self._align(self.kernel_, feats, labels, Q, n), fitted,
                                  kernel=self.kernel_, gamma=gamma, normalize=self.normalize_)
            out = K if out is None else out + K
        return out / len(self.alignments_) if len(self.alignments_) > 1 else out
