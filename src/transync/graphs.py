"""Attributed graphs: adjacency, node points, node and edge features.

A :class:`Graph` stores a square adjacency (dense, symmetric for undirected graphs; entries are
edge weights, 0 = no edge), optional 2-d/3-d node ``points``, optional ``node_features`` of shape
``(n, f)``, optional ``edge_features`` of shape ``(n, n)`` (one scalar attribute per node pair, read
only where an edge exists; may be negative) and optional ``node_labels``. Geometric edge attributes
(lengths, angles) are derived from the points on demand.

Examples
--------
>>> import numpy as np
>>> from transync.graphs import Graph
>>> g = Graph.from_points(np.array([[0, 0], [1, 0], [0, 1], [1, 1]]), edges="full")
>>> g.n_nodes, g.n_edges
(4, 6)
>>> g.edge_index().shape   # directed edge list, both directions
(12, 2)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import Delaunay, QhullError, cKDTree

from ._validation import (
    check_array,
    check_bool,
    check_choice,
    check_int,
    check_int_array,
    check_shape,
    nearly_equal,
)

__all__ = ["Graph", "canonical_node_order"]


@dataclass(frozen=True, eq=False)
class Graph:
    """An attributed graph.

    Parameters
    ----------
    adjacency : ndarray of shape (n, n)
        Edge weights, 0 where there is no edge. Diagonal must be zero (no self-loops). An
        undirected graph's adjacency must be symmetric; one that is so up to rounding
        (``numpy.allclose`` with tolerances relative to the largest weight) is stored as its
        exactly symmetric part.
    points : ndarray of shape (n, dim), optional
        Node coordinates (keypoints, landmarks), at most ``1e300`` in magnitude (so that
        distances between them stay finite).
    node_features : ndarray of shape (n, f), optional
        Node descriptors.
    node_labels : ndarray of shape (n,), optional
        Integer node labels (categorical).
    edge_features : ndarray of shape (n, n), optional
        Scalar edge attribute (e.g. Cho et al.'s random edge attributes), used where
        ``adjacency != 0``.
    directed : bool, default=False
        Undirected graphs must have a symmetric adjacency.
    meta : dict, optional
        Free-form metadata (e.g. the source file); not used by the algorithms.

    Raises
    ------
    ValueError, TypeError
        A non-square, empty, negative or (undirected) asymmetric adjacency, a non-zero diagonal,
        attributes whose first dimension is not ``n``, non-finite values, bad flags.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.graphs import Graph
    >>> g = Graph(adjacency=np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], float),
    ...           node_labels=np.array([0, 1, 0]))
    >>> g.n_nodes, g.n_edges
    (3, 2)
    >>> Graph.from_points(np.random.default_rng(0).random((5, 2)), edges="full").n_edges
    10
    """

    adjacency: np.ndarray
    points: np.ndarray | None = None
    node_features: np.ndarray | None = None
    node_labels: np.ndarray | None = None
    edge_features: np.ndarray | None = None
    directed: bool = False
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        check_bool(self.directed, "directed")
        if not isinstance(self.meta, dict):
            raise TypeError(f"`meta` must be a dict, got {type(self.meta).__name__}")
        A = check_array(self.adjacency, "adjacency", ndim=2)
        if A.shape[0] != A.shape[1]:
            raise ValueError(f"`adjacency` must be square, got shape {A.shape}")
        if A.shape[0] == 0:
            raise ValueError("`adjacency` must describe a non-empty graph, got shape (0, 0)")
        if np.any(np.diag(A) != 0):
            raise ValueError("`adjacency` must have a zero diagonal (no self-loops)")
        if np.min(A) < 0:
            raise ValueError(f"`adjacency` weights must be non-negative, got minimum {A.min():.6g}")
        if not self.directed and not np.array_equal(A, A.T):
            if not nearly_equal(A, A.T):
                raise ValueError("`adjacency` must be symmetric for an undirected graph "
                                 "(pass directed=True otherwise)")
            A = np.where(A == A.T, A, 0.5 * A + 0.5 * A.T)    # rounding noise: exactly symmetric
        object.__setattr__(self, "adjacency", _owned(A, self.adjacency))
        n = A.shape[0]
        if self.points is not None:
            P = _check_coordinates(check_array(self.points, "points", ndim=2))
            check_shape(P, (n, None), "points")
            object.__setattr__(self, "points", _owned(P, self.points))
        if self.node_features is not None:
            F = check_array(self.node_features, "node_features", ndim=(1, 2))
            if F.ndim == 1:
                F = F[:, None]
            check_shape(F, (n, None), "node_features")
            object.__setattr__(self, "node_features", _owned(F, self.node_features))
        if self.edge_features is not None:
            E = check_array(self.edge_features, "edge_features", ndim=2)
            check_shape(E, (n, n), "edge_features")
            if not self.directed and not nearly_equal(E[A != 0], E.T[A != 0]):
                raise ValueError("`edge_features` must be symmetric on the edges of an undirected "
                                 "graph")
            object.__setattr__(self, "edge_features", _owned(E, self.edge_features))
        if self.node_labels is not None:
            L = _check_labels(self.node_labels)
            if L.shape != (n,):
                raise ValueError(f"`node_labels` must have shape ({n},), got {L.shape}")
            object.__setattr__(self, "node_labels", _owned(L, self.node_labels))

    # ------------------------------------------------------------------ basic properties
    @property
    def n_nodes(self) -> int:
        return self.adjacency.shape[0]

    @property
    def n_edges(self) -> int:
        """Number of edges (undirected edges counted once)."""
        nnz = int(np.count_nonzero(self.adjacency))
        return nnz if self.directed else nnz // 2

    @property
    def mask(self) -> np.ndarray:
        """Boolean adjacency (edge present)."""
        return self.adjacency != 0

    def edge_index(self) -> np.ndarray:
        """Directed edge list of shape (m, 2): both directions of every undirected edge."""
        return np.argwhere(self.adjacency != 0)

    def distances(self) -> np.ndarray:
        """Euclidean distance matrix between node points, shape (n, n)."""
        return _distances(self._require_points())

    def angles(self) -> np.ndarray:
        """Angle of each node-to-node vector with the x axis, shape (n, n), radians (the first
        two coordinates)."""
        P = self._require_points()
        if P.shape[1] < 2:
            raise ValueError(f"angles need points of at least 2 coordinates, this Graph's have "
                             f"{P.shape[1]}")
        d = P[None, :, :2] - P[:, None, :2]
        return np.arctan2(d[..., 1], d[..., 0])

    def _require_points(self) -> np.ndarray:
        if self.points is None:
            raise ValueError("this Graph has no `points`; edge lengths and angles need them")
        return self.points

    def permute(self, perm) -> Graph:
        """Relabel nodes: node ``u`` of the result is node ``perm[u]`` of this graph."""
        perm = check_array(perm, "perm", dtype=None)       # not complex, NaN, infinite
        perm = check_int_array(perm, "perm", integral_floats=True,     # 3.0 is an index
                               what="integer node indices")
        if perm.shape != (self.n_nodes,) or not np.array_equal(
                np.sort(perm), np.arange(self.n_nodes)):
            raise ValueError(f"`perm` must be a permutation of range({self.n_nodes}) (integers), "
                             f"got {_describe_array(perm)}")
        take = (lambda x: None if x is None else x[perm])
        E = None if self.edge_features is None else self.edge_features[np.ix_(perm, perm)]
        return Graph(self.adjacency[np.ix_(perm, perm)], points=take(self.points),
                     node_features=take(self.node_features), node_labels=take(self.node_labels),
                     edge_features=E, directed=self.directed, meta=dict(self.meta))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_points(cls, points, *, edges: str = "delaunay", k: int = 5, weighted: bool = False,
                    node_features=None, node_labels=None) -> Graph:
        """Build a graph on a point set.

        Parameters
        ----------
        points : array_like of shape (n, dim)
        edges : {"delaunay", "full", "knn"}, default="delaunay"
            Delaunay triangulation (2-d, n >= 3), complete graph, or symmetric k-nearest neighbours.
        k : int, default=5
            Neighbours per node for ``edges="knn"``.
        weighted : bool, default=False
            Store edge lengths as weights instead of 1.

        Raises
        ------
        ValueError
            No points, non-finite coordinates, ``edges="delaunay"`` on points that are not 2-d
            or that no triangulation covers (e.g. all at one place); with ``weighted``, two
            coincident points joined by an edge (a weight of 0 is no edge).
        """
        P = _check_coordinates(check_array(points, "points", ndim=2))
        n = P.shape[0]
        if n == 0:
            raise ValueError("`points` must hold at least one point, got 0")
        if P.shape[1] == 0:
            raise ValueError(f"`points` must have at least one coordinate, got shape {P.shape}")
        check_choice(edges, "edges", ("delaunay", "full", "knn"))
        M = np.zeros((n, n), dtype=bool)
        if edges == "full" or (edges == "delaunay" and n <= 3):
            M[:] = True
        elif edges == "delaunay":
            if P.shape[1] != 2:
                raise ValueError(f"`edges='delaunay'` needs 2-d points, got dimension {P.shape[1]}")
            simplices = _delaunay(P)
            for a, b in ((0, 1), (1, 2), (0, 2)):
                M[simplices[:, a], simplices[:, b]] = True
        else:
            k = check_int(k, "k", minimum=1)
            kk = min(k + 1, n)
            top = float(np.abs(P).max())        # scale-free neighbours: no overflow at 1e300
            Q = P / top if top > 0 else P
            _, idx = cKDTree(Q).query(Q, k=kk)
            idx = np.atleast_2d(idx)
            found = idx < n                     # (the tree answers n for a missing neighbour)
            M[np.repeat(np.arange(n), kk)[found.ravel()], idx[found]] = True
        M = M | M.T
        np.fill_diagonal(M, False)
        A = M.astype(float)
        if check_bool(weighted, "weighted"):
            D = _distances(P)
            zero = np.argwhere(M & (D == 0))
            if zero.size:        # an edge of length 0 is no edge in a weighted adjacency
                u, v = (int(t) for t in zero[0])
                why = ("coincide" if np.array_equal(P[u], P[v]) else
                       "are closer than float64 resolves at the spread of these points")
                raise ValueError(f"`weighted=True` stores edge lengths as weights, but points "
                                 f"{u} and {v} {why}: their edge would have weight 0 and "
                                 "vanish (merge duplicate points, or use weighted=False)")
            A = A * D
        return cls(A, points=P, node_features=node_features, node_labels=node_labels)

    @classmethod
    def from_networkx(cls, G, *, weight: str | None = "weight", points: str | None = "pos",
                      features: str | None = None, label: str | None = None) -> Graph:
        """Build from a networkx graph; node order is ``list(G.nodes)``."""
        import networkx as nx

        if not isinstance(G, nx.Graph):
            raise TypeError(f"`G` must be a networkx graph, got {type(G).__name__}")
        for arg, key in (("weight", weight), ("points", points), ("features", features),
                         ("label", label)):
            if key is not None and not isinstance(key, str):
                raise TypeError(f"`{arg}` must be an attribute name (str) or None, got "
                                f"{type(key).__name__}")
        nodes = list(G.nodes)
        if not nodes:
            raise ValueError("`G` must have at least one node")
        try:
            A = nx.to_numpy_array(G, nodelist=nodes, weight=weight, dtype=float)
        except (TypeError, ValueError, OverflowError) as exc:    # 10**400: beyond float64
            raise ValueError(f"`G`'s edge attribute {weight!r} (`weight`) must hold numbers: "
                             f"{exc}") from None
        np.fill_diagonal(A, 0.0)

        def collect(key, arg):
            if key is None or not all(key in G.nodes[v] for v in nodes):
                return None
            try:
                return np.asarray([G.nodes[v][key] for v in nodes])
            except (TypeError, ValueError) as exc:      # ragged: "inhomogeneous shape"
                raise ValueError(f"`G`'s node attribute {key!r} (`{arg}`) must have one shape "
                                 f"at every node: {exc}") from None

        return cls(A, points=collect(points, "points"),
                   node_features=collect(features, "features"),
                   node_labels=collect(label, "label"), directed=G.is_directed(),
                   meta={"nodes": nodes})

    def to_networkx(self):
        """Convert to a networkx ``Graph``/``DiGraph`` with ``pos``/``features``/``label`` data."""
        import networkx as nx

        G = nx.from_numpy_array(self.adjacency,
                                create_using=nx.DiGraph if self.directed else nx.Graph)
        for v in range(self.n_nodes):
            if self.points is not None:
                G.nodes[v]["pos"] = tuple(self.points[v])
            if self.node_features is not None:
                G.nodes[v]["features"] = self.node_features[v].copy()
            if self.node_labels is not None:
                lab = self.node_labels[v]
                G.nodes[v]["label"] = lab.item() if isinstance(lab, np.generic) else lab
        return G


def canonical_node_order(adjacency, colors=None) -> np.ndarray:
    """A node order that does not depend on how the nodes were numbered.

    Colour refinement (1-dimensional Weisfeiler-Leman) from the initial ``colors``: a node's
    colour is refined by the multiset of (colour, edge weight) of its neighbours -- out- and
    in-neighbours apart for a directed adjacency; a self-loop's weight is part of the node's
    initial colour -- until the partition is stable; while some
    colour class has several nodes, its first node is individualized (given a colour of its
    own, before the rest of its class) and the partition refined again. The order sorts the
    nodes by their final colours, which are ranks of numbering-free signatures, so
    ``adjacency[np.ix_(order, order)]`` is the same matrix for every numbering of the same
    graph whenever each individualized class is an orbit of the graph's automorphisms (all
    its nodes interchangeable): for trees, cycles, complete graphs and the graphs of the TU
    sets (MUTAG, PTC_MR, ENZYMES, PPI, NCI1: every graph's form is the same under three
    random renumberings). It is not a full canonical labelling (which needs a search over the
    individualization choices): for graphs that colour refinement cannot split into orbits --
    some regular graphs, even asymmetric ones such as the Frucht graph, and graphs with
    regular parts it cannot tell apart, such as a triangle beside a 4-cycle -- the order may
    still depend on the numbering.

    Nodes of tied colour are interchangeable for anything that sees only the adjacency and
    the colours, so computations run in this order (e.g.
    :class:`transync.kernels.TransitiveAssignmentKernel`) break their ties the same way
    however the input was numbered.

    Parameters
    ----------
    adjacency : array_like of shape (n, n)
        Edge weights, 0 = no edge (weights are compared exactly).
    colors : array_like of shape (n,), optional
        Initial node colours (e.g. node labels): integers, strings or booleans, compared
        exactly. The order sorts the nodes by them first. Default: one colour.

    Returns
    -------
    order : ndarray of shape (n,), int64
        A permutation of ``range(n)``: node ``k`` of the reordered graph is node ``order[k]``
        (as :meth:`Graph.permute` takes it).

    Raises
    ------
    ValueError, TypeError
        A non-square or non-finite adjacency, colours of the wrong length, NaN or complex
        colours.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.graphs import canonical_node_order
    >>> path = np.diag(np.ones(3), 1); path = path + path.T        # 0 - 1 - 2 - 3
    >>> perm = np.array([2, 0, 3, 1])                               # the same path, renumbered
    >>> a, b = canonical_node_order(path), canonical_node_order(path[np.ix_(perm, perm)])
    >>> bool(np.array_equal(path[np.ix_(a, a)], path[np.ix_(perm, perm)][np.ix_(b, b)]))
    True
    >>> canonical_node_order(np.zeros((3, 3)), colors=["b", "a", "b"]).tolist()
    [1, 0, 2]
    """
    A = check_array(adjacency, "adjacency", ndim=2)
    n = check_shape(A, ("n", "n"), "adjacency")["n"]
    if colors is None:
        color = np.zeros(n, dtype=np.int64)
    else:
        C = _check_labels(colors, "colors")
        if C.ndim != 1 or C.shape[0] != n:
            raise ValueError(f"`colors` must have shape ({n},) (one colour per node), got "
                             f"shape {C.shape}")
        try:
            color = _ranks(C)
        except TypeError:                      # e.g. an object array of ints and strings
            raise TypeError("`colors` must be values of one comparable kind (integers, "
                            f"strings or booleans), got {_describe_array(C)}") from None
    loops = np.diag(A)
    if np.any(loops != 0):                     # a self-loop's weight is part of a node's colour
        color = np.unique(np.column_stack([color, _ranks(loops)]), axis=0,
                          return_inverse=True)[1].reshape(n).astype(np.int64)
    src, dst = np.nonzero(A)
    src, dst = src[src != dst], dst[src != dst]
    values, code = np.unique(A[src, dst], return_inverse=True)
    code = code.reshape(-1).astype(np.int64)
    sides = [(src, dst)] if np.array_equal(A, A.T) else [(src, dst), (dst, src)]
    color = _refine_colors(color, sides, code, max(values.size, 1), n)
    while n and color.max() + 1 < n:
        cell = int(np.argmax(np.bincount(color) > 1))         # the first class of several nodes
        first = int(np.flatnonzero(color == cell)[0])
        color = 2 * color + 1
        color[first] -= 1                                     # just before the rest of its class
        color = _refine_colors(_ranks(color), sides, code, max(values.size, 1), n)
    return np.argsort(color).astype(np.int64)


def _ranks(x: np.ndarray) -> np.ndarray:
    """Dense ranks of the values of ``x`` (0 = smallest)."""
    return np.unique(x, return_inverse=True)[1].reshape(x.shape).astype(np.int64)


def _refine_colors(color: np.ndarray, sides, code: np.ndarray, n_codes: int,
                   n: int) -> np.ndarray:
    """Colour refinement of :func:`canonical_node_order` to the stable partition: each round a
    node's new colour is the rank of (its colour, the sorted (neighbour colour, edge code) keys
    of each side, padded with -1); the ranks keep the old order between old classes."""
    while True:
        blocks = [color[:, None]]
        for u, v in sides:
            key = color[v] * n_codes + code
            o = np.lexsort((key, u))
            u_sorted = u[o]
            degree = np.bincount(u_sorted, minlength=n)
            keys = np.full((n, int(degree.max(initial=0))), -1, dtype=np.int64)
            start = np.cumsum(degree) - degree
            keys[u_sorted, np.arange(u_sorted.size) - start[u_sorted]] = key[o]
            blocks.append(keys)
        new = np.unique(np.hstack(blocks), axis=0, return_inverse=True)[1].reshape(n)
        if new.max(initial=-1) == color.max(initial=-1):      # no class split: stable
            return new.astype(np.int64)
        color = new.astype(np.int64)


def _owned(arr: np.ndarray, given) -> np.ndarray:
    """``arr`` as the Graph's own read-only array: a copy where it is still the caller's
    ``given`` object or a view of someone's memory (a frozen Graph must not change when the
    caller later edits the array it was built from)."""
    if arr is given or not arr.flags.owndata:
        arr = arr.copy()
    arr.flags.writeable = False
    return arr


_MAX_COORDINATE = 1e300


def _check_coordinates(P: np.ndarray) -> np.ndarray:
    """Refuse coordinates whose differences could overflow (points at -1.7e308 and 1.7e308
    are finite, their distance is not)."""
    top = float(np.abs(P).max(initial=0.0))
    if top > _MAX_COORDINATE:
        raise ValueError(f"`points` must have coordinates of magnitude <= {_MAX_COORDINATE:g} "
                         f"(their distances must be finite), got {top:.6g}")
    return P


def _distances(P: np.ndarray) -> np.ndarray:
    """Euclidean distances between the rows of ``P``, computed on coordinates scaled by a power
    of two (exact) so that differences of 1e-170 do not square to 0 nor of 1e170 to inf."""
    D = P[:, None, :] - P[None, :, :]
    top = float(np.abs(D).max(initial=0.0))
    if not top > 0 or not np.isfinite(top):
        return np.linalg.norm(D, axis=-1)
    e = int(np.frexp(top)[1])       # ldexp, not 2.0 ** -e: that overflows for subnormal tops
    return np.ldexp(np.linalg.norm(np.ldexp(D, -e), axis=-1), e)


def _delaunay(P: np.ndarray) -> np.ndarray:
    """Delaunay simplices; degenerate sets (collinear or repeated points) are joggled (``QJ``);
    a set that not even joggling triangulates (e.g. all points at one place) is refused.

    The points are first moved to the origin of their bounding box and scaled by a power of two
    to about unit size: the triangulation does not depend on the units (Qhull's tolerances are
    absolute: points at 1e80 were refused, at 1e-180 triangulated otherwise). A point that the
    plain triangulation leaves out (a repeated point: Qhull keeps one copy) also joggles, so
    that every node gets edges.
    """
    lo = P.min(axis=0)
    span = float((P.max(axis=0) - lo).max())
    if span == 0:       # all at one place: joggling "triangulated" them at the origin only
        raise ValueError(f"`points` admit no Delaunay triangulation ({P.shape[0]} points, all "
                         f"at one place); use edges='full' or 'knn'")
    if span > 0 and np.isfinite(span):
        P = np.ldexp(P - lo, -int(np.frexp(span)[1]))     # exact; no 2**1024 overflow
    try:
        tri = Delaunay(P)
        if not len(tri.coplanar):
            return tri.simplices
    except QhullError:
        pass
    try:
        return Delaunay(P, qhull_options="QJ").simplices
    except QhullError:
        distinct = np.unique(P, axis=0).shape[0]
        raise ValueError(f"`points` admit no Delaunay triangulation ({P.shape[0]} points, "
                         f"{distinct} distinct); use edges='full' or 'knn'") from None


def _check_labels(labels, name: str = "node_labels") -> np.ndarray:
    """Node labels: integers (or strings/objects), never complex or NaN."""
    if np.iscomplexobj(labels):
        raise TypeError(f"`{name}` must be integer labels, got complex values")
    L = np.asarray(labels)
    if L.dtype.kind == "f" and not np.all(np.isfinite(L)):
        raise ValueError(f"`{name}` must be finite, got NaN or infinite entries")
    return L


def _describe_array(x: np.ndarray) -> str:
    return f"array of shape {x.shape} and dtype {x.dtype}"
