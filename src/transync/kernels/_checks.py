"""Input checks shared by the kernels' modules.

One home for the checks that several modules need: a sequence with one entry per graph
(:func:`check_sequence`), node features (:func:`check_feature_list`), adjacencies
(:func:`check_adjacency`, :func:`check_graph_list`), integer node labels
(:func:`check_label_array`, :func:`check_node_labels`) and integer arrays
(:func:`check_int_array`, the kernels' policy over :func:`transync._validation.check_int_array`).
A wrong type raises ``TypeError``, a wrong value ``ValueError``; the message names the argument,
what was expected and what arrived.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._validation import check_array, check_nonnegative, check_positive, nearly_equal
from .._validation import check_int_array as _check_int_array
from ..graphs import Graph

__all__ = [
    "check_adjacency",
    "check_feature_list",
    "check_graph_list",
    "check_int_array",
    "check_label_array",
    "check_node_labels",
    "check_sequence",
    "class_labels",
]


def check_sequence(x, name: str, expected: str, *, allow_empty: bool = False,
                   arrays: bool = False) -> list:
    """One entry per graph: a list or tuple (never a str, bytes or a single Graph), as a list.

    Parameters
    ----------
    x : object
        The argument to check.
    name : str
        Its name, for the messages.
    expected : str
        What it must be, as the ``TypeError`` says it (``"a list or tuple of ..."``).
    allow_empty : bool, default=False
        Accept an empty sequence; otherwise it raises ``ValueError``.
    arrays : bool, default=False
        Accept a numpy array too (its rows are the entries). Off by default: the rows of a
        padded ``(N, n, ...)`` array would all count as real nodes.

    Returns
    -------
    list
    """
    if isinstance(x, Graph):
        raise TypeError(f"`{name}` must be {expected}, got a single Graph (wrap it in a list)")
    if isinstance(x, (str, bytes)) or not (isinstance(x, Sequence)
                                           or (arrays and isinstance(x, np.ndarray))):
        raise TypeError(f"`{name}` must be {expected}, got {type(x).__name__}")
    if len(x) == 0 and not allow_empty:
        raise ValueError(f"`{name}` must hold at least one graph, got an empty sequence")
    return list(x)


#: smallest Gaussian width sigma2 (largest inverse width gamma = 1 / SIGMA2_MIN) the kernels
#: accept: 1 / sigma2 must stay finite
SIGMA2_MIN = 1e-300


def check_width(value, name: str, *, inverse: bool = False) -> float:
    """A Gaussian width ``sigma2`` (>= :data:`SIGMA2_MIN`) or, with ``inverse``, a ``gamma``
    (<= 1 / :data:`SIGMA2_MIN`): positive, finite and with a finite inverse."""
    v = check_positive(value, name)
    # the literal bound: 1 / SIGMA2_MIN rounds one ulp below 1e300, so gamma = 1e300 was
    # refused as "at most 1e+300, got 1e+300" (1 / 1e300 is still a positive float64)
    if (v > 1e300) if inverse else (v < SIGMA2_MIN):
        bound = "at most 1e+300" if inverse else f"at least {SIGMA2_MIN:g}"
        raise ValueError(f"`{name}` must be {bound} (its inverse must be a finite float64), "
                         f"got {v!r}")
    return v


#: largest absolute node-feature value the kernels accept: their squares, summed over the
#: features of a node, must stay far inside float64
FEATURE_LIMIT = 1e100


def check_feature_list(features, name: str = "features", *,
                       ndim: int | tuple[int, ...] = 2) -> list[np.ndarray]:
    """One ``(n_i, f)`` float array per graph (``n_i >= 1``, one ``f`` for all), validated.

    A padded ``(N, n, f)`` array is refused: its rows would all count as real nodes. With
    ``ndim=(1, 2)`` a 1-d array of ``n_i`` values is one feature column.
    """
    seq = check_sequence(features, name, "a list or tuple (a sequence) of (n_i, f) arrays, one "
                                         "per graph")
    out = []
    for g, F in enumerate(seq):
        F = check_array(F, f"{name}[{g}]", ndim=ndim)
        out.append(F[:, None] if F.ndim == 1 else F)
    f = out[0].shape[1]
    if f == 0:
        raise ValueError(f"`{name}[0]` must have at least one feature column, got shape "
                         f"{out[0].shape}")
    for g, F in enumerate(out):
        if F.shape[1] != f:
            raise ValueError(f"`{name}[{g}]` must have {f} columns like `{name}[0]`, got shape "
                             f"{F.shape}")
        if F.shape[0] == 0:
            raise ValueError(f"`{name}[{g}]` must describe at least one node, got shape "
                             f"{F.shape}")
        big = float(np.abs(F).max())
        if big > FEATURE_LIMIT:
            raise ValueError(f"`{name}[{g}]` has values up to {big:.3g}: node features must "
                             f"stay within +-{FEATURE_LIMIT:g} (kernels square them; beyond "
                             f"that float64 overflows), rescale them")
    return out


def check_adjacency(graph, name: str, *, n: int | None = None,
                    edges_only: bool = False) -> np.ndarray:
    """The adjacency of an undirected Graph or a square, non-negative, symmetric, finite array.

    Parameters
    ----------
    graph : Graph or array_like of shape (n, n)
        A directed Graph is refused.
    name : str
        The argument's name, for the messages.
    n : int, optional
        The required node count (``n >= 1``); default any ``n >= 1``.
    edges_only : bool, default=False
        Only the edge pattern (``!= 0``) must be symmetric (the caller uses nothing else);
        otherwise the weights must be, up to rounding (relative to the largest weight), and an
        array that is symmetric only up to rounding comes back symmetrized.

    Returns
    -------
    ndarray of shape (n, n)
    """
    if isinstance(graph, Graph):
        if graph.directed:
            raise ValueError(f"`{name}` must be an undirected graph (symmetric adjacency), got a "
                             "directed Graph")
        A = graph.adjacency
    else:
        A = check_array(graph, name, ndim=2)
    if n is not None and A.shape != (n, n):
        raise ValueError(f"`{name}` must have shape ({n}, {n}) (one row and column per node of "
                         f"the graph), got shape {A.shape}")
    if A.shape[0] != A.shape[1] or A.shape[0] == 0:
        raise ValueError(f"`{name}` must be a square (n, n) adjacency with n >= 1, got shape "
                         f"{A.shape}")
    check_nonnegative(A, name)
    E = A != 0
    if not (np.array_equal(E, E.T) if edges_only else np.array_equal(A, A.T)):
        if edges_only or not nearly_equal(A, A.T):
            raise ValueError(f"`{name}` must be symmetric (an undirected graph), got an "
                             f"asymmetric matrix of shape {A.shape}")
        A = 0.5 * (A + A.T)
    return A


def check_graph_list(graphs, name: str = "graphs", *, allow_empty: bool = False,
                     edges_only: bool = False) -> list[np.ndarray]:
    """The adjacency of each graph of a sequence of Graphs or adjacency arrays, validated.

    Each entry goes through :func:`check_adjacency` (named ``graphs[k]``); ``allow_empty`` and
    ``edges_only`` as in :func:`check_sequence` and :func:`check_adjacency`.
    """
    seq = check_sequence(graphs, name, "a sequence (list or tuple) of Graphs or adjacency arrays",
                         allow_empty=allow_empty)
    return [check_adjacency(g, f"{name}[{k}]", edges_only=edges_only) for k, g in enumerate(seq)]


def check_label_array(labels, name: str, n: int | None = None) -> np.ndarray:
    """The integer (or bool) node labels of one graph, as int64; ``n`` labels when given.

    A non-integer dtype (float, NaN included, string, object) raises ``TypeError``.
    """
    lab = _check_int_array(labels, name, ndim=1, allow_bool=True, what="integer labels")
    if n is not None and lab.shape[0] != n:
        raise ValueError(f"`{name}` must have length {n} (the graph's node count), got "
                         f"{lab.shape[0]}")
    return lab


def check_node_labels(node_labels, sizes, name: str = "node_labels", *,
                      missing_ok: bool = False) -> list:
    """One int64 label array of length ``sizes[g]`` per graph (:func:`check_label_array`).

    Parameters
    ----------
    node_labels : sequence of array_like of shape (n_g,)
        A list, tuple or array with one entry per graph.
    sizes : sequence of int
        The node count of each graph.
    name : str, default="node_labels"
        The argument's name, for the messages.
    missing_ok : bool, default=False
        A ``None`` entry (a graph without labels) stays ``None``.

    Returns
    -------
    list of ndarray (or None where ``missing_ok``)
    """
    labs = check_sequence(node_labels, name, "a sequence (list, tuple or array) of integer "
                                             "arrays, one per graph", allow_empty=True, arrays=True)
    if len(labs) != len(sizes):
        raise ValueError(f"`{name}` must have one entry per graph ({len(sizes)}), got "
                         f"{len(labs)}")
    return [None if lab is None and missing_ok else
            check_label_array(lab, f"{name}[{g}]", int(sizes[g])) for g, lab in enumerate(labs)]


def check_int_array(x, name: str, ndim: int | None = None,
                    keep_dtype: bool = False) -> np.ndarray:
    """Integer array (of ``ndim`` dims when given), as int64; an empty one of any dtype too.

    :func:`transync._validation.check_int_array` with the kernels' policy: no float dtype (not
    even integral floats), NaN or infinite entries a ``ValueError``. With ``keep_dtype`` a signed
    integer array keeps its own dtype (no int64 copy of a large int32 assignment array).
    """
    return _check_int_array(x, name, ndim=ndim, finite=True, keep_dtype=keep_dtype)


def class_labels(y: np.ndarray, name: str = "y") -> tuple[np.ndarray, np.ndarray]:
    """``numpy.unique(y, return_inverse=True)`` of 1-d class labels, refusing labels that do
    not sort (``None``, mixed types in an object array) with a ``TypeError`` naming ``name``,
    and NaN labels (each NaN would be a class of its own) with a ``ValueError``."""
    if np.asarray(y).dtype.kind in "fc" and not np.all(np.isfinite(y)):
        raise ValueError(f"`{name}` must hold class labels, got NaN or infinite entries")
    try:
        return np.unique(y, return_inverse=True)
    except TypeError as exc:                   # the sort compares incomparable objects
        raise TypeError(f"`{name}` must hold class labels of one sortable type (integers or "
                        f"strings), got {exc}") from None


def median_width(d2: np.ndarray, name: str) -> float:
    """The kernels' default Gaussian width from squared distances ``d2``: their median, the mean
    of the positive ones when the median is 0, 1.0 when none is positive; a width below
    :data:`SIGMA2_MIN` (no finite inverse) is refused, naming ``name``."""
    med = float(np.median(d2)) if d2.size else 0.0
    if med <= 0:
        pos = d2[d2 > 0]
        med = float(pos.mean()) if pos.size else 1.0
    if med < SIGMA2_MIN:
        raise ValueError(f"the node features in `{name}` are too close: their median squared "
                         f"distance {med:.3g} is below {SIGMA2_MIN:g} (a Gaussian width whose "
                         f"inverse overflows float64); rescale them")
    return med


#: squared distances at most this fraction of ``||x||^2 + ||y||^2`` are rounding noise: the
#: expanded form ``||x||^2 + ||y||^2 - 2 <x, y>`` that the kernels' Gram matrices use cannot
#: resolve them (float64 carries about 16 digits), so they count as 0 everywhere. Without it,
#: features equal up to rounding (identical graphs) gave a median width of 1e-30, a Gaussian
#: of width 1e30 on the expansion's noise and a Gram matrix that was not PSD.
D2_RESOLUTION = 1e-12


def squared_distances(X, Y, name: str) -> np.ndarray:
    """``((X - Y) ** 2).sum(-1)``, 0 below :data:`D2_RESOLUTION`; refusing features too large
    for float64 (a ``ValueError`` naming ``name``) instead of returning infinite distances and
    a zero or NaN kernel width."""
    X, Y = np.asarray(X, dtype=float), np.asarray(Y, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        d2 = ((X - Y) ** 2).sum(-1)
        noise = D2_RESOLUTION * ((X * X).sum(-1) + (Y * Y).sum(-1))
    if d2.size and not (np.isfinite(d2).all() and np.isfinite(noise).all()):
        raise ValueError(f"the node features in `{name}` are too large: their squared "
                         f"distances overflow float64; rescale them")
    d2[d2 <= noise] = 0.0
    return d2


def expanded_squared_distances(xx: np.ndarray, yy: np.ndarray, cross: np.ndarray) -> np.ndarray:
    """``xx + yy - 2 cross`` (broadcast; ``xx``, ``yy`` the squared norms, ``cross`` the inner
    products, overwritten): the squared distances of a Gram-style expansion, clipped at 0, and 0
    below :data:`D2_RESOLUTION`, as :func:`squared_distances` counts them. Center the points
    first (subtract one common vector from both sides): the expansion's rounding error grows
    with the norms, not with the distances."""
    norms = xx + yy
    d2 = np.multiply(cross, -2.0, out=cross)
    d2 += norms
    d2[d2 <= D2_RESOLUTION * norms] = 0.0
    return d2
