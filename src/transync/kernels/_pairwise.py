"""Batched pairwise matching of many graphs padded to one size (the kernel's pairwise step).

:func:`match_pairs` matches every listed pair ``(i, j)`` of a graph collection and returns a full
permutation of the ``n`` padded nodes per pair (methods page *Transitive assignment kernels*,
step 4). Every graph
is padded to ``n`` nodes, real nodes first, then isolated dummy nodes. The affinity of a pair is
the Lawler QAP matrix

.. math:: K[(u, a), (v, b)] = [u = v, a = b]\\, N[u, a] + A_i[u, v]\\, A_j[a, b]

with ``A`` the 0/1 adjacencies (edges only, weight 1) and the node term

.. math:: N[u, a] = \\exp(-\\|h_u - h_a\\|^2 / \\sigma^2)\\; [\\ell_u = \\ell_a]

between real nodes (the label factor only when ``node_labels`` are given) and the constant
``dummy_affinity`` (default :data:`DUMMY_AFFINITY`) wherever a dummy is involved.

Matchers (:data:`PAIRWISE_MATCHERS`)
------------------------------------
``"rrwm"``  the lock-step RRWM of :func:`transync.multigraph.run_lockstep` (its default variant,
            which reproduces ``transync.matching.rrwm(K, variant="pygmtools")`` pair by pair) on
            :meth:`PairAffinities.from_factors` with the padded adjacencies as factors:
            ``O(n^3)`` per pair and step, ``O(|E| n)`` on sparse graphs (whose adjacencies
            the products take as CSR rows), the ``(n^2, n^2)`` matrix is never formed.
``"sm"``    spectral matching: power iteration on ``K`` for all pairs of a chunk in lock-step
            (each pair stops on :func:`transync.matching.sm`'s own test, same start, same
            defaults), then the Hungarian rounding of the eigenvector.
``"node"``  node-only linear assignment on ``N`` (the fast, structure-blind ablation): one batched
            cost construction, one :func:`transync.permutations.solve_lap` per pair.

Pair ``(i, j)`` is solved at size ``m = max(n_i, n_j)``, the smallest padding that admits a
full permutation; the remaining slots ``m..n-1`` are dummies in both graphs (node affinity
``dummy_affinity``, no edges) and are matched to themselves. Measured on 1000 random ENZYMES
pairs (``n = 54``, rrwm, node labels): mean QAP objective ``x^T K x`` on the ``n``-padded
problem 63.2 this way against 62.0 when solving at ``n``, at half the cost. The one thing lost:
at size ``n`` two real nodes with node affinity below ``dummy_affinity`` and no edge support
could both go to spare dummies; at size ``m`` only the ``m - n_i`` dummies of the smaller graph
can take real nodes (on those 1000 pairs the ``n``-size solve never used the spare dummies).

Every matcher ends with a maximizing linear assignment of its ``(m, m)`` scores, so each row is
a permutation of ``range(n)`` (dummies take the leftovers).

Work is split into chunks of pairs that go through :func:`transync.parallel.map_chunks` (serial,
joblib processes, any ``concurrent.futures`` executor, Dask), in waves so that only a few chunks'
inputs exist at once. The chunks are cut from the work (about 1/64 of the total ``m^3`` each)
and the memory of their own solve size ``m``, largest ``m`` first so that the costly chunks do
not finish last; pairs are visited in tiles of graph indices, so a chunk ships only the padded
graphs it uses. The cut depends on the pairs and sizes only, never on the executor: serial and
parallel runs solve the same chunks and return the same result.

Pairs solved in one batch share its floating-point rounding (batched products, by ~1e-16),
and RRWM's fifty amplifying steps can carry such differences up to the assignment where two
candidates nearly tie: on 11,175 ENZYMES pairs, two different chunk cuts gave different
assignments on 2.7 % of the pairs (848 pairs). The scores are rounded to 10 decimals
relative to their maximum before the assignment, so exact ties (automorphic nodes, dummies)
are broken by node index whatever the chunks; a given ``chunk_size`` is a different cut and
may break near-ties differently.

Examples
--------
>>> import numpy as np
>>> from transync.kernels._hks import hks_features
>>> rng = np.random.default_rng(0)
>>> A = np.triu(rng.random((6, 6)) < 0.5, 1).astype(float); A = A + A.T
>>> perm = rng.permutation(6)                      # graph 1 = graph 0 relabelled
>>> B = A[np.ix_(perm, perm)]
>>> feats = hks_features([A, B])
>>> out = match_pairs(feats, [A, B], [[0, 1]], n=8, matcher="rrwm")
>>> out.shape, out.dtype.name
((1, 8), 'int32')
>>> bool(np.all(perm[out[0, :6]] == np.arange(6)))  # node u of graph 0 is node perm^-1(u) of 1
True
"""

from __future__ import annotations

import functools
import inspect

import numpy as np

from .._blas import blas_limit
from .._progress import progress_bar
from .._validation import (
    as_generator,
    check_bool,
    check_choice,
    check_index_pairs,
    check_int,
    check_positive,
)
from ..matching import sm as _sm_reference
from ..multigraph import PairAffinities, run_lockstep
from ..parallel import map_chunks, split_chunks
from ..permutations import solve_lap
from ._checks import (check_adjacency, check_feature_list, check_node_labels, check_sequence,
                      check_width, expanded_squared_distances, median_width,
                      squared_distances)

__all__ = ["DUMMY_AFFINITY", "LABEL_MISMATCH", "PAIRWISE_MATCHERS",
           "default_sigma2", "match_pairs"]

PAIRWISE_MATCHERS = ("rrwm", "sm", "node")

#: Node affinity of every candidate that involves a dummy node. Real-to-real affinities lie in
#: (0, 1]; a small constant keeps them preferred while a real node whose best real partner is
#: worse than this (e.g. a different label) is left to a dummy -- dummies absorb unmatched nodes.
DUMMY_AFFINITY = 1e-3

#: Factor of the node affinity of two real nodes with different labels (0: label equality).
LABEL_MISMATCH = 0.0

# spectral matching's own defaults, read from transync.matching.sm (one home for them)
_SM_DEFAULTS = {k: inspect.signature(_sm_reference).parameters[k].default
                for k in ("max_iter", "tol")}
# the default sigma2 is the median over the node pairs of at most this many sampled nodes
_SIGMA_NODES = 1000
# decimals (relative to each pair's largest score) kept before the final assignment
_SCORE_DECIMALS = 10
# memory target of one chunk's (c, m, m) state, bytes: 8 MiB keeps a chunk's arrays near the
# caches (the 100 largest ENZYMES graphs' 4950 RRWM pairs, two worker processes: 33-38 s at
# 32 MiB, 29-34 s at 8 MiB; serial 60-62 s vs 52 s CPU, on a machine whose speed varied)
_CHUNK_BYTES = 8 << 20
# the work is cut into about this many chunks (enough for 4 per worker on 16 workers)
_CHUNK_COUNT = 64
# (c, n, n) float arrays alive at once per matcher (measured from the solvers' state)
_STATE_ARRAYS = {"rrwm": 14, "sm": 6, "node": 4}


# --------------------------------------------------------------------------- validation


def _check_inputs(features, adjacencies, node_labels):
    feats = check_feature_list(features, ndim=(1, 2))
    adjs = check_sequence(adjacencies, "adjacencies", "a list or tuple of (n_g, n_g) arrays, one "
                                                      "per graph", allow_empty=True)
    if len(adjs) != len(feats):
        raise ValueError(f"`features` and `adjacencies` must have the same length (one entry per "
                         f"graph), got {len(feats)} and {len(adjs)}")
    adjs = [check_adjacency(a, f"adjacencies[{k}]", n=len(h), edges_only=True)
            for k, (h, a) in enumerate(zip(feats, adjs))]
    labels = None if node_labels is None else check_node_labels(node_labels,
                                                                [len(h) for h in feats])
    return feats, adjs, labels


# --------------------------------------------------------------------------- sigma2


def default_sigma2(features, *, rng=None) -> float:
    """The default node-affinity width: the median squared distance between node features.

    Computed once over the pooled real nodes of all graphs, so that every pair uses the same
    width (the kernel compares all pairs on one scale): all pairs of distinct nodes when there
    are at most 1000 nodes, else all pairs among 1000 sampled nodes -- evenly spaced through the
    pooled nodes when ``rng`` is None (deterministic), drawn with ``rng`` otherwise. Falls back
    to the mean of the positive squared distances when the median is 0, and to 1.0 when all
    features are equal.

    Parameters
    ----------
    features : sequence of array_like of shape (n_g, f)
        Node features per graph.
    rng : None, int or numpy.random.Generator, optional
        Sampling of the nodes (only with more than 1000 nodes).

    Returns
    -------
    float
        The width ``sigma2`` > 0 of the Gaussian node affinity.

    Examples
    --------
    >>> default_sigma2([np.array([[0.0], [1.0]]), np.array([[3.0]])])
    4.0
    """
    gen = None if rng is None else as_generator(rng)    # checked whatever the size
    H = np.concatenate(check_feature_list(features, ndim=(1, 2)))
    if len(H) > _SIGMA_NODES:
        if gen is None:
            sel = np.linspace(0, len(H) - 1, _SIGMA_NODES).round().astype(np.int64)
        else:
            sel = np.sort(gen.choice(len(H), _SIGMA_NODES, replace=False))
        H = H[sel]
    if len(H) < 2:
        return 1.0
    u, v = np.triu_indices(len(H), 1)
    return median_width(squared_distances(H[u], H[v], "features"), "features")


# --------------------------------------------------------------------------- chunk work


def _node_affinity(feat, sizes, labels, pl, sigma2, dummy):
    """Node term (c, n, n) of the chunk's pairs ``pl`` (local graph indices)."""
    Hi, Hj = feat[pl[:, 0]], feat[pl[:, 1]]
    n = feat.shape[1]
    sq_i, sq_j = (Hi * Hi).sum(2), (Hj * Hj).sum(2)
    D = expanded_squared_distances(sq_i[:, :, None], sq_j[:, None, :],
                                   np.matmul(Hi, np.swapaxes(Hj, 1, 2)))
    with np.errstate(over="ignore", under="ignore"):            # far nodes: exactly 0
        N = np.exp(D * (-1.0 / sigma2), out=D)
    if labels is not None:
        same = labels[pl[:, 0]][:, :, None] == labels[pl[:, 1]][:, None, :]
        N *= np.where(same, 1.0, LABEL_MISMATCH)
    slot = np.arange(n)
    real = slot[None, :] < sizes[:, None]                 # (m, n)
    both = real[pl[:, 0]][:, :, None] & real[pl[:, 1]][:, None, :]
    return np.where(both, N, dummy)


def _power_iteration(aff, max_iter, tol):
    """Lock-step :class:`transync.matching.SMStepper` on every pair of ``aff``."""
    c, n1, n2 = len(aff), aff.n1, aff.n2
    X = np.full((c, n1, n2), 1.0 / (n1 * n2))
    active = np.arange(c)
    sub = aff
    for _ in range(max_iter):
        if not len(active):
            break
        W = sub.matvec(X[active])
        with np.errstate(over="ignore"):
            nrm = np.sqrt((W * W).sum((1, 2)))
        big = ~np.isfinite(nrm)                   # |W|^2 overflows (a huge dummy_affinity):
        if big.any():                             # the norm of W / max|W| instead
            W[big] /= np.abs(W[big]).max((1, 2))[:, None, None]
            nrm[big] = np.sqrt((W[big] * W[big]).sum((1, 2)))
        moving = nrm > 0
        W /= np.where(moving, nrm, 1.0)[:, None, None]
        settled = np.sqrt(((W - X[active]) ** 2).sum((1, 2))) < tol
        X[active[moving]] = W[moving]
        keep = moving & ~settled
        if not keep.all():
            active = active[keep]
            sub = aff.subset(active) if len(active) else sub
    return X


def _round(scores):
    """Maximizing assignment (:func:`transync.permutations.solve_lap`) of every (n, n) block
    after rounding to ``_SCORE_DECIMALS`` (ties then broken by node index)."""
    top = np.abs(scores).max((1, 2))
    q = np.round(scores / np.where(top > 0, top, 1.0)[:, None, None], _SCORE_DECIMALS)
    out = np.empty(scores.shape[:2], np.int32)
    for p, s in enumerate(q):                     # one LAP per pair (square: all matched)
        out[p] = solve_lap(s)
    return out


def _solve_block(adj, feat, sizes, labels, pl, *, matcher, sigma2, dummy):
    """Scores' assignments (c, m) of pairs ``pl`` whose graphs all fit in ``m`` slots."""
    node = _node_affinity(feat, sizes, labels, pl, sigma2, dummy)
    if matcher == "node":
        return _round(node)
    A = adj.astype(float)[:, None]
    aff = PairAffinities.from_factors(A, A, pl, node=node)
    if matcher == "rrwm":
        scores = run_lockstep(aff, solver="rrwm").scores
    else:
        scores = _power_iteration(aff, _SM_DEFAULTS["max_iter"], _SM_DEFAULTS["tol"])
    return _round(scores)


def _solve_chunk(payload, *, matcher, sigma2, dummy):
    """Assignments (c, n) of one chunk: ``payload = (pairs, adjacency, features, sizes, labels)``
    with the pairs' graphs only (local indices), adjacency as uint8 (None for "node").

    Pair ``(i, j)`` is solved at size ``m = max(n_i, n_j)``, the smallest padding that admits a
    full permutation; padded slots ``m..n-1`` (dummy to dummy, node affinity ``dummy`` and no
    edges in both graphs) are matched to themselves.
    """
    pl, adj, feat, sizes, labels = payload
    n = feat.shape[1]
    m_pair = np.maximum(sizes[pl[:, 0]], sizes[pl[:, 1]])
    out = np.empty((len(pl), n), np.int32)
    out[:] = np.arange(n, dtype=np.int32)
    for m in np.unique(m_pair):
        sel = np.flatnonzero(m_pair == m)
        with blas_limit(int(m) * int(m)):
            out[sel, :m] = _solve_block(
                None if adj is None else adj[:, :m, :m], feat[:, :m], sizes,
                None if labels is None else labels[:, :m], pl[sel], matcher=matcher,
                sigma2=sigma2, dummy=dummy)
    return out


# --------------------------------------------------------------------------- front


def _chunk_plan(pairs, sizes, matcher, chunk_size):
    """Order of the pairs and chunk boundaries into it; they depend on the pairs, the graph
    sizes, ``matcher`` and ``chunk_size`` only -- never on the executor, so that every executor
    sees the same chunks and returns the same result.

    Pairs are ordered by solve size ``m = max(n_i, n_j)``, largest first (the costliest chunks
    start first, so workers finish together), then tile by tile of graph indices (a chunk
    ships few graphs), then by ``(i, j)``. A chunk holds ``chunk_size`` pairs when it is given;
    else about ``1 / _CHUNK_COUNT`` of the total work (``m^3`` per pair) within the memory
    target at its own solve size, and at least 8 pairs.
    """
    m = np.maximum(sizes[pairs[:, 0]], sizes[pairs[:, 1]])
    if chunk_size is not None:
        cap = np.full(len(pairs), chunk_size, np.int64)
    else:
        cost = m.astype(float) ** 3
        share = max(1.0, float(cost.sum()) / _CHUNK_COUNT)
        memory = _CHUNK_BYTES // (8 * _STATE_ARRAYS[matcher] * m * m)
        cap = np.maximum(8, np.minimum(memory, (share / cost).astype(np.int64)))
    tile = np.maximum(1, np.sqrt(cap).astype(np.int64))
    order = np.lexsort((pairs[:, 1], pairs[:, 0], pairs[:, 1] // tile, pairs[:, 0] // tile, -m))
    cap = cap[order]
    bounds, P = [0], len(pairs)
    while bounds[-1] < P:       # caps are equal within one m and grow as m falls: greedy fill
        bounds.append(min(P, bounds[-1] + int(cap[bounds[-1]])))
    return order, bounds


def match_pairs(features, adjacencies, pairs, *, n, matcher="rrwm", sigma2=None, node_labels=None,
                dummy_affinity=None, executor=None, chunk_size=None, progress=False,
                rng=None) -> np.ndarray:
    """Match graph pairs padded to ``n`` nodes; one full permutation of ``range(n)`` per pair.

    .. math:: \\max_{X \\in \\Pi_n} \\mathrm{vec}(X)^\\top K_{ij}\\, \\mathrm{vec}(X), \\quad
              K_{ij}[(u,a),(v,b)] = [u{=}v, a{=}b]\\, N_{ij}[u,a] + A_i[u,v] A_j[a,b]

    (``"node"``: :math:`\\max_X \\langle N_{ij}, X \\rangle`). See the module documentation for the
    affinity and the matchers. Each pair is solved at size ``max(n_i, n_j)`` (the remaining
    dummy slots map to themselves); for a given ``sigma2`` its result depends on its two
    graphs and the options, not on ``executor``; exact ties are broken by node index, while a
    near-tie may fall differently when another cut of the pairs into chunks (other pairs,
    another ``chunk_size``) changes the batch rounding (see the module documentation).

    Parameters
    ----------
    features : sequence of array_like of shape (n_g, f)
        Node features of the real nodes of each graph (e.g. :func:`hks_features`).
    adjacencies : sequence of array_like of shape (n_g, n_g)
        Symmetric adjacencies; only the edge pattern (``!= 0``) is used.
    pairs : array_like of shape (P, 2), int
        Graph index pairs ``(i, j)``; row ``p`` of the result maps graph ``i`` into graph ``j``.
    n : int
        Padded size, at least the largest graph of the collection.
    matcher : {"rrwm", "sm", "node"}, default="rrwm"
        Pairwise solver (:data:`PAIRWISE_MATCHERS`).
    sigma2 : float, optional
        Width of the Gaussian node affinity; default :func:`default_sigma2` of ``features``
        (computed once, the same for every pair).
    node_labels : sequence of int array_like of shape (n_g,), optional
        Categorical node labels: the node affinity of two real nodes is multiplied by
        ``[label_u == label_a]`` (:data:`LABEL_MISMATCH` = 0 for different labels).
    dummy_affinity : float, optional
        Node affinity of candidates involving a dummy node, >= 0; default
        :data:`DUMMY_AFFINITY` (1e-3).
    executor : None, str, int or executor, optional
        Where the chunks run (:func:`transync.parallel.map_chunks`): serial (default),
        ``"processes"``, an int ``n_jobs``, a ``concurrent.futures`` executor or a
        ``dask.distributed.Client``. The result does not depend on it.
    chunk_size : int, optional
        Pairs per chunk; default: about 1/64 of the work each, within a memory target at the
        chunk's own solve size (the ``(c, m, m)`` state about 8 MiB: at most 83 pairs at
        ``m = 30`` for RRWM), at least 8 pairs. Exact ties are broken the same way whatever it
        is; near-ties may not (see the module documentation).
    progress : bool, default=False
        Show a progress bar over the pairs.
    rng : None, int or numpy.random.Generator, optional
        Only for :func:`default_sigma2`'s node sample (collections of more than 1000 nodes);
        None keeps that deterministic. The matchers themselves are deterministic.

    Returns
    -------
    ndarray of shape (P, n), int32
        ``out[p, u] = a``: padded node ``u`` of graph ``pairs[p, 0]`` goes to padded node ``a``
        of graph ``pairs[p, 1]`` (real nodes first, dummies after); each row a permutation.

    Raises
    ------
    TypeError
        Inputs that are not sequences/arrays, non-integer pairs, labels or ``n``.
    ValueError
        ``features`` and ``adjacencies`` of different lengths or shapes, asymmetric or negative
        adjacencies, a graph larger than ``n``, pair indices out of range, unknown ``matcher``,
        ``sigma2`` not positive, ``dummy_affinity`` negative, ``chunk_size`` < 1.

    Examples
    --------
    >>> import numpy as np
    >>> tri = np.ones((3, 3)) - np.eye(3)
    >>> edge = np.array([[0.0, 1.0], [1.0, 0.0]])
    >>> feats = [np.ones((3, 1)), np.ones((2, 1))]
    >>> match_pairs(feats, [tri, edge], [[0, 1]], n=3, matcher="node", sigma2=1.0)
    array([[0, 1, 2]], dtype=int32)
    """
    feats, adjs, labels = _check_inputs(features, adjacencies, node_labels)
    N = len(feats)
    pairs = check_index_pairs(pairs, N, what="graph indices")
    sizes = np.array([len(h) for h in feats], dtype=np.int64)
    n = check_int(n, "n", minimum=1)
    if sizes.max() > n:
        k = int(np.argmax(sizes))
        raise ValueError(f"`n` must be at least the largest graph: graph {k} has {sizes[k]} "
                         f"nodes, n={n}")
    matcher = check_choice(matcher, "matcher", PAIRWISE_MATCHERS)
    if rng is not None:
        rng = as_generator(rng)                 # checked even where the sample needs none
    sigma2 = default_sigma2(feats, rng=rng) if sigma2 is None else check_width(sigma2, "sigma2")
    dummy = DUMMY_AFFINITY if dummy_affinity is None else check_positive(
        dummy_affinity, "dummy_affinity", allow_zero=True)
    if chunk_size is not None:
        chunk_size = check_int(chunk_size, "chunk_size", minimum=1)
    check_bool(progress, "progress")
    P = len(pairs)
    out = np.empty((P, n), np.int32)
    if P == 0:
        return out

    # padded collection at the largest graph's size (every pair is solved within it; the
    # slots beyond map to themselves): features (N, m, f), adjacency (N, m, m) uint8, labels
    m_max = int(sizes.max())
    out[:, m_max:] = np.arange(m_max, n, dtype=np.int32)
    f = feats[0].shape[1]
    H = np.zeros((N, m_max, f))
    A = None if matcher == "node" else np.zeros((N, m_max, m_max), np.uint8)
    L = None if labels is None else np.full((N, m_max), -1, np.int64)
    for g in range(N):
        k = sizes[g]
        H[g, :k] = feats[g]
        if A is not None:
            A[g, :k, :k] = adjs[g] != 0
        if L is not None:
            L[g, :k] = labels[g]

    # chunks from work and memory (not from the executor); waves of a few chunks per worker
    order, bounds = _chunk_plan(pairs, sizes, matcher, chunk_size)
    n_slots = len(split_chunks(1 << 20, executor, min_chunk=1))      # ~4 per worker
    wave = max(8, 2 * n_slots)
    fn = functools.partial(_solve_chunk, matcher=matcher, sigma2=sigma2, dummy=dummy)
    bar = progress_bar(P, f"match_pairs ({matcher})", enabled=bool(progress), unit="pair")
    try:
        for w in range(0, len(bounds) - 1, wave):
            sel, payloads = [], []
            for s, e in zip(bounds[w:w + wave], bounds[w + 1:w + 1 + wave]):
                idx = order[s:e]
                used, inv = np.unique(pairs[idx], return_inverse=True)
                pl = inv.reshape(-1, 2).astype(np.int64)
                payloads.append((pl, None if A is None else A[used], H[used], sizes[used],
                                 None if L is None else L[used]))
                sel.append(idx)
            results = map_chunks(fn, payloads, executor=executor)
            for idx, res in zip(sel, results):
                out[idx, :m_max] = res
                bar.update(len(idx))
    finally:
        bar.close()
    return out
