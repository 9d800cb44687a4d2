"""Heat kernel signature (HKS) node features on the normalized graph Laplacian.

With the normalized Laplacian ``L = I - D^{-1/2} A D^{-1/2} = Phi diag(lambda) Phi^T`` of a graph,
the heat kernel signature of node ``v`` at time ``t`` is the diagonal of the heat kernel
``exp(-t L)`` (Sun, Ovsjanikov & Guibas, SGP 2009; methods page *Transitive assignment
kernels*):

.. math:: \\mathrm{HKS}(v, t) = \\sum_k e^{-\\lambda_k t} \\, \\phi_k(v)^2 .

It is invariant to node relabelling (a permutation of the rows), takes values in ``(0, 1]``,
equals 1 at ``t = 0`` and, on a connected graph, tends to ``phi_0(v)^2 = d_v / vol(G)`` as
``t -> inf``: small times describe a node's neighbourhood, large ones its place in the whole graph.

Isolated nodes (degree 0) follow Chung's convention ``L[v, v] = 0``: each is its own connected
component with eigenvalue 0, so its HKS is exactly 1 at every time (no ``0 / 0``).
:func:`hks_features` stacks the Laplacians of all graphs of one size and runs one batched
:func:`numpy.linalg.eigh` per size.

Examples
--------
>>> import numpy as np
>>> A = np.array([[0.0, 1.0], [1.0, 0.0]])                 # K2: eigenvalues 0 and 2
>>> h = heat_kernel_signature(A, times=[0.5, 1.0])
>>> bool(np.allclose(h, (1 + np.exp(-2 * np.array([0.5, 1.0]))) / 2))
True
"""

from __future__ import annotations

import numpy as np

from .._blas import blas_limit
from .._validation import check_array
from ._checks import check_adjacency, check_graph_list

__all__ = ["HKS_TIMES", "heat_kernel_signature", "hks_features"]

#: Default time grid: 10 times log-spaced in [0.1, 30], the same for every graph of a data set.
#: A kernel compares feature coordinates across graphs, so coordinate ``k`` must mean the same
#: time ``t_k`` everywhere (Sun et al.'s per-shape grid ``4 ln 10 / lambda_max ... 4 ln 10 /
#: lambda_2`` would not). On the normalized Laplacian every eigenvalue lies in [0, 2], so the grid
#: is data-set independent: at ``t = 0.1`` the signature is ``1 - 0.1 + O(t^2)`` (local: it sees
#: the degree and the neighbours), at ``t = 30`` every mode with ``lambda >= 0.2`` has decayed by
#: ``e^{-6}`` and only the slowest diffusion modes (global position, component size) remain --
#: e.g. for paths of 15-30 nodes (molecule backbones) ``lambda_2 ~ 0.01-0.05``.
HKS_TIMES: np.ndarray = np.logspace(-1, np.log10(30), 10)

# one stacked eigh holds at most this many bytes of Laplacians (bounds memory on large sets)
_STACK_BYTES = 64 << 20


def _check_times(times) -> np.ndarray:
    if times is None:
        return HKS_TIMES.copy()
    try:
        booleans = not isinstance(times, (str, bytes)) and np.asarray(times).dtype == bool
    except (TypeError, ValueError):         # ragged: check_array names it
        booleans = False
    if booleans:
        raise TypeError(f"`times` must hold positive numbers, got booleans {times!r:.60}")
    t = check_array(times, "times", ndim=1)
    if t.size == 0:
        raise ValueError("`times` must hold at least one time, got an empty array")
    if t.min() <= 0:
        raise ValueError(f"`times` must be positive, got minimum {t.min():.6g}")
    return t


def _hks_stack(A: np.ndarray, times: np.ndarray) -> np.ndarray:
    """HKS of a stack of adjacencies ``(G, n, n)`` -> ``(G, n, T)`` (one batched ``eigh``)."""
    A = np.array(A, dtype=float)
    n = A.shape[1]
    idx = np.arange(n)
    A[:, idx, idx] = 0.0                        # self-loops do not enter the Laplacian
    # L does not change when a graph's weights are scaled: a power of 4 (exact, with an exact
    # square root) brings the largest weight to [1/4, 1], so the degrees neither overflow
    # (weights near 1e308) nor lose digits as subnormals
    top = A.max((1, 2))
    exp4 = np.where(top > 0, np.frexp(np.where(top > 0, top, 1.0))[1] // 2, 0)
    if exp4.any():
        A = np.ldexp(A, -2 * exp4[:, None, None])
    deg = A.sum(2)                              # (G, n)
    inv = np.zeros_like(deg)
    np.divide(1.0, np.sqrt(deg), out=inv, where=deg > 0)
    L = -(inv[:, :, None] * A * inv[:, None, :])
    L[:, idx, idx] = (deg > 0).astype(float)    # Chung: L[v, v] = 0 for an isolated node
    with blas_limit(n * n):         # many small eigh: threads only add contention
        lam, phi = np.linalg.eigh(L)
    lam = np.clip(lam, 0.0, 2.0)                # rounding: the spectrum lies in [0, 2]
    heat = np.exp(-lam[:, :, None] * times[None, None, :])      # (G, n, T)
    return np.matmul(phi * phi, heat)


def heat_kernel_signature(graph_or_adjacency, times=None) -> np.ndarray:
    """Heat kernel signature of every node of one graph.

    .. math:: \\mathrm{HKS}(v, t) = \\sum_k e^{-\\lambda_k t} \\phi_k(v)^2, \\qquad
              L = I - D^{-1/2} A D^{-1/2} = \\Phi \\,\\mathrm{diag}(\\lambda)\\, \\Phi^\\top

    Parameters
    ----------
    graph_or_adjacency : Graph or array_like of shape (n, n)
        An undirected graph, or its adjacency (symmetric, non-negative, finite; weights are
        used as edge weights, the diagonal is ignored).
    times : array_like of shape (T,), optional
        Positive diffusion times; default :data:`HKS_TIMES` (10 times log-spaced in [0.1, 30]).

    Returns
    -------
    ndarray of shape (n, T)
        ``HKS(v, t)`` in ``(0, 1]``; exactly 1 for isolated nodes.

    Raises
    ------
    ValueError
        Non-square, asymmetric, negative, empty or non-finite adjacency, a directed Graph,
        non-positive or empty ``times``.
    TypeError
        Input that is not an array or a Graph.

    Examples
    --------
    >>> import numpy as np
    >>> A = np.zeros((3, 3)); A[0, 1] = A[1, 0] = 1.0       # an edge and an isolated node
    >>> h = heat_kernel_signature(A, times=[1.0, 10.0])
    >>> h.shape, h[2].tolist()
    ((3, 2), [1.0, 1.0])
    >>> bool(np.allclose(h[0], (1 + np.exp(-2 * np.array([1.0, 10.0]))) / 2))
    True
    """
    A = check_adjacency(graph_or_adjacency, "graph_or_adjacency")
    return _hks_stack(A[None], _check_times(times))[0]


def hks_features(graphs, times=None) -> list[np.ndarray]:
    """Heat kernel signatures of many graphs, batched by size.

    Graphs of equal size share one stacked :func:`numpy.linalg.eigh`, so a data set of thousands
    of small graphs costs a few batched calls (one per distinct size); the result equals
    :func:`heat_kernel_signature` graph by graph.

    Parameters
    ----------
    graphs : sequence of Graph or (n_g, n_g) arrays
        Undirected graphs (or adjacencies, as :func:`heat_kernel_signature` accepts).
    times : array_like of shape (T,), optional
        Positive diffusion times, the same for every graph; default :data:`HKS_TIMES`.

    Returns
    -------
    list of ndarray
        ``features[g]`` of shape ``(n_g, T)``, in the order of ``graphs``.

    Raises
    ------
    TypeError
        ``graphs`` not a sequence.
    ValueError
        An invalid graph (the message names ``graphs[k]``) or invalid ``times``.

    Examples
    --------
    >>> import numpy as np
    >>> path = np.diag(np.ones(3), 1); path = path + path.T               # P4
    >>> feats = hks_features([path, np.zeros((1, 1)), path], times=[0.5, 2.0])
    >>> [f.shape for f in feats]
    [(4, 2), (1, 2), (4, 2)]
    >>> bool(np.allclose(feats[0], heat_kernel_signature(path, times=[0.5, 2.0])))
    True
    """
    adj = check_graph_list(graphs, allow_empty=True)
    t = _check_times(times)
    out: list = [None] * len(adj)
    sizes = np.array([a.shape[0] for a in adj], dtype=np.int64)
    for n in np.unique(sizes):
        members = np.flatnonzero(sizes == n)
        step = max(1, _STACK_BYTES // (8 * int(n) * int(n)))
        for s in range(0, len(members), step):
            part = members[s:s + step]
            H = _hks_stack(np.stack([adj[k] for k in part]), t)
            for k, h in zip(part, H):
                out[k] = h
    return out
