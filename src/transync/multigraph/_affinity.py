"""Affinities of many graph pairs, multiplied in one batched call.

:class:`PairAffinities` holds the Lawler QAP affinities ``K_p`` of ``P`` graph pairs
``pairs[p] = (i, j)`` (all of sizes ``n1 x n2``) and computes ``reshape(K_p vec(X_p))`` for all
``p`` at once from a stacked ``(P, n1, n2)`` array -- the product the lock-step solvers
(:mod:`transync.multigraph._lockstep`) need at every step. The layout is pygmtools' (as in
:func:`transync.matching.as_affinity`): candidate ``(u, a)`` (node ``u`` of graph ``i``, node ``a``
of graph ``j``) has index ``a * n1 + u`` in ``vec``.

Backends (chosen by the constructors, reported by :attr:`PairAffinities.backend`)
-----------------------------------------------------------------------------
``"separable"``  ``K_p = diag(node_p) + sum_r F[gi_p, r] (x) G[gj_p, r]`` with factors stored
                 per *graph* (the default Gaussian edge affinity: one Chebyshev expansion of the
                 kernel over the union of all graphs' edge attributes, factors built once per
                 graph, see :func:`gaussian_edge_factors`) or per pair (user affinities that are
                 all :class:`~transync.matching.SeparableAffinity`). A product is two rounds of
                 large GEMMs, grouped by graph: ``O(P R (n1^2 n2 + n1 n2^2))`` flops, memory
                 ``O(N R n^2)``. With one factor per graph (``R = 1``) at most a quarter
                 nonzero, e.g. the graph kernels' 0/1 adjacencies, a product is two
                 block-diagonal CSR products instead: ``O(P (nnz(F) n2 + nnz(G) n1))``.
``"dense"``      stacked ``(P, n1 n2, n1 n2)`` matrices (pygmtools K blocks handed in dense);
                 one batched ``matmul``.
``"sparse"``     one block-diagonal CSR matrix of all pairs (sparse K blocks, or per-pair
                 :class:`~transync.matching.FactorizedAffinity` objects, e.g. length + angle
                 affinities on Delaunay graphs); one sparse product for all pairs.
``"loop"``       per-pair fallback, a Python loop over the pairs' own ``matvec``: ONLY for
                 user callables returning other :class:`~transync.matching.Affinity` types (or a
                 mix of types). Correct, not fast.

Examples
--------
>>> import numpy as np
>>> from transync.datasets import make_graph_collection
>>> from transync.multigraph import PairAffinities
>>> graphs = make_graph_collection(n_graphs=4, n_inliers=6, rng=0).graphs
>>> aff = PairAffinities.from_graphs(graphs)
>>> len(aff), aff.backend
(6, 'separable')
>>> X = np.random.default_rng(0).random((6, 6, 6))
>>> dense = aff.pair(1).to_dense()                  # pair (0, 2)
>>> y = dense @ X[1].ravel(order="F")
>>> bool(np.allclose(aff.matvec(X)[1], y.reshape(6, 6, order="F"), atol=1e-8))
True
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from .._validation import (
    check_affinity_magnitude,
    check_array,
    check_index_pairs,
    check_int,
    check_int_array,
    check_nonnegative,
    check_positive,
)
from ..graphs import Graph
from ..matching import (
    DEFAULT_SIGMA2,
    MAX_SEPARABLE_ERROR,
    Affinity,
    DenseAffinity,
    FactorizedAffinity,
    SeparableAffinity,
    SparseAffinity,
    as_affinity,
    gaussian_edge_affinity,
    gaussian_edge_factors,
    prefers_separable,
)

__all__ = ["PairAffinities", "all_pairs", "check_graphs", "check_pairs"]

# stacked dense K blocks up to this many bytes; beyond, sparse blocks go to the CSR backend
DENSE_BYTES = 1 << 30
# candidates scored per chunk in score_assignments (bounds the gathered (chunk, R, n, n) arrays)
_SCORE_CHUNK_BYTES = 64 << 20
# per-chunk intermediate of the separable product (fits L2)
_CHUNK_BYTES = 256 << 10
# below this many pairs the separable product chunks the pairs in order (no grouping by graph)
_FEW_PAIRS = 64
# graphs of at most this many nodes do not decide whether a collection's Gaussian edge
# affinity takes the per-graph separable expansion (see _all_separable)
_TINY_GRAPH = 2
# A separable product with one factor per graph (e.g. 0/1 adjacencies, the graph kernels'
# RRWM) runs as two block-diagonal CSR products when the factors hold at most this share of
# nonzeros, graphs have at least _CSR_MIN_SIZE nodes and the product at least _CSR_MIN_PAIRS
# pairs (with fewer, building the block matrices costs more than it saves). Measured on 2
# cores (random graphs, mean degree 3 / 6 / 10, n = 12-96, chunks of 8-276 pairs): 1.1-4x
# faster than the dense GEMMs, the gain growing with n and sparsity.
_CSR_DENSITY = 0.25
_CSR_MIN_SIZE = 8
_CSR_MIN_PAIRS = 4


def all_pairs(n_graphs: int) -> np.ndarray:
    """All pairs ``(i, j)``, ``i < j``, in ``np.triu_indices(n_graphs, 1)`` order; shape (P, 2)."""
    n_graphs = check_int(n_graphs, "n_graphs", minimum=2)
    return np.stack(np.triu_indices(n_graphs, 1), axis=1).astype(np.int64)


def check_pairs(pairs, n_graphs: int, name: str = "pairs", *,
                complete: str | None = None) -> np.ndarray:
    """``pairs`` as an int array of shape (P, 2) with ``0 <= i < j < n_graphs``, no duplicates
    (and every pair when ``complete`` says why, as in ``check_index_pairs``).

    ``None`` gives :func:`all_pairs`.
    """
    if pairs is None:
        return all_pairs(n_graphs)
    return check_index_pairs(pairs, n_graphs, name, what="graph indices", ordered=True,
                             unique=True, nonempty=True, complete=complete)


def _vec_batch(X: np.ndarray) -> np.ndarray:
    """(P, n1, n2) -> (P, n1 n2), column-major per pair (pygmtools' vec)."""
    return np.ascontiguousarray(np.swapaxes(X, 1, 2)).reshape(len(X), -1)


def _unvec_batch(x: np.ndarray, n1: int, n2: int) -> np.ndarray:
    return np.swapaxes(x.reshape(len(x), n2, n1), 1, 2)


# --------------------------------------------------------------------------- per-graph factors


_FAST_KEYWORDS = {"sigma2", "attribute", "tol", "backend", "angle_weight"}


def _fast_gaussian_options(affinity):
    """Keyword options when ``affinity`` is the default Gaussian edge affinity, else ``None``.

    ``None`` (the default, ``sigma2=DEFAULT_SIGMA2`` = 0.15) or
    ``functools.partial(gaussian_edge_affinity,
    **kw)`` with only ``sigma2``, ``attribute`` (scalar), ``tol``, ``backend`` in {"auto",
    "separable"} and ``angle_weight``.
    """
    if affinity is None:
        return {"sigma2": DEFAULT_SIGMA2}
    if not (isinstance(affinity, functools.partial) and affinity.func is gaussian_edge_affinity
            and not affinity.args and set(affinity.keywords) <= _FAST_KEYWORDS):
        return None
    kw = dict(affinity.keywords)
    if kw.get("backend", "auto") not in ("auto", "separable"):
        return None
    if kw.get("attribute") == "length+angle":
        return None
    return kw


# --------------------------------------------------------------------------- backends


class _Separable:
    """``K_p = diag(node_p) + sum_r F[gi_p, r] (x) G[gj_p, r]``; factors per graph (or pair)."""

    kind = "separable"

    def __init__(self, F, G, gi, gj, node=None, *, exact=None, csr=None):
        self.F, self.G = F, G             # (Ng, R, n1, n1), (Ng, R, n2, n2)
        # one-factor stacks sparse enough for CSR products: {transposed: (F rows, G rows)} of
        # _CsrRows, shared with the subsets made after the first product; None until the first
        # product decides, False: dense GEMMs
        self._csr = csr
        self._csr_last = None             # (rows, gi, gj, Bi, Bj) of the last CSR product
        # (E as first graph, E as second graph, sigma2, symmetric): per-graph edge attributes of
        # a Gaussian edge affinity (non-edges: sentinels), for exact O(n^2) candidate scores
        self.exact = exact
        self.gi, self.gj = np.asarray(gi, np.int64), np.asarray(gj, np.int64)
        self.node = node                  # (P, n1, n2) or None
        R, n1, n2 = F.shape[1], F.shape[2], G.shape[2]
        self.R, self.n1, self.n2 = R, n1, n2
        # concatenated factors (as SeparableAffinity): Gcat[b, r n2 + a] = G[r, a, b],
        # Fcat[i, r n1 + j] = F[r, i, j]
        self._cats = None
        self._tcats = None

    def _cat(self, transposed: bool):
        F, G = self.F, self.G
        if transposed:
            F, G = np.swapaxes(F, 2, 3), np.swapaxes(G, 2, 3)
        Ng, R, n1, n2 = F.shape[0], self.R, self.n1, self.n2
        Fcat = np.ascontiguousarray(F.transpose(0, 2, 1, 3).reshape(Ng, n1, R * n1))
        Gcat = np.ascontiguousarray(np.swapaxes(G, 2, 3).transpose(0, 2, 1, 3)
                                    .reshape(G.shape[0], n2, R * n2))
        return Fcat, Gcat

    def cats(self, transposed=False):
        if not transposed:
            if self._cats is None:
                self._cats = self._cat(False)
            return self._cats
        if self._tcats is None:
            sym = (np.array_equal(self.F, np.swapaxes(self.F, 2, 3))
                   and np.array_equal(self.G, np.swapaxes(self.G, 2, 3)))
            self._tcats = self.cats(False) if sym else self._cat(True)
        return self._tcats

    def subset(self, idx):
        node = None if self.node is None else self.node[idx]
        return _Separable(self.F, self.G, self.gi[idx], self.gj[idx], node, exact=self.exact,
                          csr=self._csr)

    def _csr_rows(self, transposed):
        """Per-graph CSR rows of the factors (transposed ones if asked) when the product should
        run on them (one factor per graph, at most :data:`_CSR_DENSITY` dense), else None."""
        same = self.G is self.F                       # e.g. from_factors(A, A)
        if self._csr is None:
            csr = False
            if self.R == 1 and min(self.n1, self.n2) >= _CSR_MIN_SIZE:
                dense_f = np.count_nonzero(self.F) / self.F.size
                dense_g = dense_f if same else np.count_nonzero(self.G) / self.G.size
                if max(dense_f, dense_g) <= _CSR_DENSITY:
                    csr = {}
            self._csr = csr
        if self._csr is False:
            return None
        if transposed not in self._csr:
            F, G = self.F[:, 0], self.G[:, 0]
            if transposed:
                sym_f = np.array_equal(F, np.swapaxes(F, 1, 2))
                sym_g = sym_f if same else np.array_equal(G, np.swapaxes(G, 1, 2))
                if sym_f and sym_g:
                    self._csr[True] = self._csr_rows(False)
                    return self._csr[True]
                F, G = np.swapaxes(F, 1, 2), np.swapaxes(G, 1, 2)
            rows_f = _CsrRows(F)
            self._csr[transposed] = (rows_f, rows_f if same else _CsrRows(G))
        return self._csr[transposed]

    def _csr_product(self, X, gi, gj, transposed, rows):
        """``F X G^T`` per pair as two block-diagonal CSR products (``O(nnz n)`` per pair)."""
        last = self._csr_last
        if (last is not None and last[0] is rows and np.array_equal(last[1], gi)
                and np.array_equal(last[2], gj)):
            Bi, Bj = last[3], last[4]
        else:
            Bi, Bj = rows[0].block(gi), rows[1].block(gj)
            self._csr_last = (rows, gi.copy(), gj.copy(), Bi, Bj)
        k, n1, n2 = len(X), self.n1, self.n2
        Z = Bi @ np.ascontiguousarray(X).reshape(k * n1, n2)             # F_p X_p, stacked
        Zt = np.ascontiguousarray(Z.reshape(k, n1, n2).transpose(0, 2, 1)).reshape(k * n2, n1)
        W = Bj @ Zt                                                      # G_p (F_p X_p)^T
        return np.ascontiguousarray(W.reshape(k, n2, n1).transpose(0, 2, 1))

    def product(self, X, idx, transposed=False):
        gi = self.gi if idx is None else self.gi[idx]
        gj = self.gj if idx is None else self.gj[idx]
        k, n1, n2, R = len(X), self.n1, self.n2, self.R
        rows = self._csr_rows(transposed) if k >= _CSR_MIN_PAIRS else None
        if rows is not None:
            Y = self._csr_product(X, gi, gj, transposed, rows)
            if self.node is not None:
                Y += (self.node if idx is None else self.node[idx]) * X
            return Y
        Fcat, Gcat = self.cats(transposed)
        Y = np.empty((k, n1, n2))
        # Pairs sharing their first graph i share Fcat[i]: for a chunk of them, stage 1 is a
        # stacked matmul Z_p = X_p @ Gcat[j_p] (Gcat, N R n^2 floats, stays in cache), stage 2
        # one GEMM Fcat[i] @ [Z_p ...]. Chunks keep Z (c n1 R n2 floats) in L2: measured at
        # N = 32, n = 20, R = 25 on 2 cores, this is 1.5x faster than two rounds of whole-batch
        # GEMMs (whose (P, n1, R n2) intermediate makes them memory-bound).
        c = max(1, _CHUNK_BYTES // (8 * n1 * n2 * R))
        if k <= _FEW_PAIRS:     # few pairs (solvers' shrinking active sets): no grouping
            for s in range(0, k, c):
                part = slice(s, min(k, s + c))
                m = part.stop - part.start
                Z = np.matmul(X[part], Gcat[gj[part]])
                Zt = Z.reshape(m, n1, R, n2).transpose(0, 2, 1, 3).reshape(m, R * n1, n2)
                Y[part] = np.matmul(Fcat[gi[part]], Zt)
            groups = ()
        else:
            groups = _groups(gi)
        for g, sel in groups:
            sel = np.arange(sel.start, sel.stop) if isinstance(sel, slice) else sel
            for s in range(0, len(sel), c):
                part = sel[s:s + c]
                if len(part) and part[-1] - part[0] == len(part) - 1:
                    part = slice(int(part[0]), int(part[-1]) + 1)     # contiguous: views
                Z = np.matmul(X[part], Gcat[gj[part]])                 # (m, n1, R n2)
                m = len(Z)
                Zs = np.ascontiguousarray(Z.reshape(m, n1, R, n2).transpose(2, 1, 0, 3))
                Y[part] = (Fcat[g] @ Zs.reshape(R * n1, m * n2)).reshape(n1, m, n2) \
                    .transpose(1, 0, 2)
        if self.node is not None:
            node = self.node if idx is None else self.node[idx]
            Y += node * X
        return Y

    def diag(self, idx=None):
        gi = self.gi if idx is None else self.gi[idx]
        gj = self.gj if idx is None else self.gj[idx]
        dF = np.diagonal(self.F, axis1=2, axis2=3)      # (Ng, R, n1)
        dG = np.diagonal(self.G, axis1=2, axis2=3)
        d = np.einsum("pri,pra->pia", dF[gi], dG[gj])
        if self.node is not None:
            d = d + (self.node if idx is None else self.node[idx])
        return d

    def pair(self, p):
        node = None if self.node is None else self.node[p]
        return SeparableAffinity(node, self.F[self.gi[p]], self.G[self.gj[p]])

    def score_assignments(self, p_idx, A, valid):
        c, n1 = A.shape
        n2 = self.n2
        out = np.empty(c)
        Ac = np.where(valid, A, 0)
        gi, gj = self.gi[p_idx], self.gj[p_idx]
        if self.exact is not None:
            # the Gaussian kernel on the edge attributes themselves (non-edges carry sentinels
            # +-1e100 whose kernel value is exactly 0): n^2 exps per candidate, n(n-1)/2 for
            # undirected graphs (each edge pair counted once, doubled)
            Efirst, Esecond, sigma2, sym = self.exact
            if sym:
                u, v = np.triu_indices(n1, 1)
                factor = 2.0
            else:
                u, v = np.nonzero(~np.eye(n1, dtype=bool))
                factor = 1.0
            Ei_all = Efirst[:, u, v]                                   # (Ng, m)
            Ef = Esecond.reshape(-1)
            all_valid = bool(valid.all())
            chunk = max(1, _SCORE_CHUNK_BYTES // (8 * 4 * len(u)))
            for s in range(0, c, chunk):
                a = Ac[s:s + chunk]
                lin = gj[s:s + chunk, None] * (n2 * n2) + a[:, u] * n2 + a[:, v]
                k = np.exp(-(Ei_all[gi[s:s + chunk]] - Ef[lin]) ** 2 / sigma2)
                if not all_valid:
                    vv = valid[s:s + chunk]
                    k *= vv[:, u] & vv[:, v]
                out[s:s + chunk] = factor * k.sum(1)
        else:
            # x^T K x = sum_{r, u, v} F_i[r, u, v] G_j[r, a_u, a_v] over matched u, v
            R = self.R
            Ff = self.F.reshape(-1, R, n1 * n1)
            Gf = self.G.reshape(-1, n2 * n2)
            chunk = max(1, _SCORE_CHUNK_BYTES // (8 * 3 * R * n1 * n1))
            for s in range(0, c, chunk):
                a, v = Ac[s:s + chunk], valid[s:s + chunk]
                m = len(a)
                lin = (a[:, :, None] * n2 + a[:, None, :]).reshape(m, 1, n1 * n1)
                rows = (gj[s:s + chunk, None] * R + np.arange(R)[None, :])[:, :, None]
                w = (v[:, :, None] & v[:, None, :]).reshape(m, n1 * n1).astype(float)
                out[s:s + chunk] = np.einsum("crk,crk,ck->c", Ff[gi[s:s + chunk]], Gf[rows, lin], w)
        if self.node is not None:
            u = np.arange(n1)[None, :]
            out += (self.node[p_idx[:, None], u, Ac] * valid).sum(1)
        return out


class _CsrRows:
    """Rows of a stack of ``(Ng, n, n)`` matrices in CSR form, for block-diagonal products."""

    def __init__(self, M):
        Ng, n, _ = M.shape
        g, r, c = np.nonzero(M)
        self.n = n
        self.counts = np.bincount(g * n + r, minlength=Ng * n).reshape(Ng, n).astype(np.int32)
        self.cols = c.astype(np.int32)
        self.data = M[g, r, c]
        self.start = np.zeros(Ng + 1, np.int64)
        np.cumsum(self.counts.sum(1), out=self.start[1:])

    def block(self, g):
        """CSR matrix ``blockdiag(M[g[0]], M[g[1]], ...)`` of shape (k n, k n)."""
        n, k = self.n, len(g)
        nnz = self.start[g + 1] - self.start[g]
        total = int(nnz.sum())
        index = np.int32 if max(total, k * n) < 2**31 else np.int64     # as scipy would pick
        indptr = np.zeros(k * n + 1, index)
        np.cumsum(self.counts[g].ravel(), out=indptr[1:])
        pos = np.arange(total, dtype=np.int64)
        pos += np.repeat(self.start[g] - indptr[:-1:n], nnz)
        cols = self.cols[pos].astype(index, copy=False)
        cols += np.repeat(np.arange(0, k * n, n, dtype=index), nnz)
        return sp.csr_matrix((self.data[pos], cols, indptr), shape=(k * n, k * n))


def _groups(g):
    """(graph, selection) groups of equal values of ``g``: slices where runs are contiguous."""
    g = np.asarray(g)
    if len(g) == 0:
        return []
    if np.all(g[1:] >= g[:-1]):
        starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
        ends = np.r_[starts[1:], len(g)]
        return [(int(g[s]), slice(int(s), int(e))) for s, e in zip(starts, ends)]
    order = np.argsort(g, kind="stable")
    gs = g[order]
    starts = np.flatnonzero(np.r_[True, gs[1:] != gs[:-1]])
    ends = np.r_[starts[1:], len(g)]
    return [(int(gs[s]), order[s:e]) for s, e in zip(starts, ends)]


class _Dense:
    """Stacked dense blocks ``K`` of shape (P, n1 n2, n1 n2)."""

    kind = "dense"

    def __init__(self, K, n1, n2):
        self.K, self.n1, self.n2 = K, n1, n2

    def subset(self, idx):
        return _Dense(self.K[idx], self.n1, self.n2)

    def product(self, X, idx, transposed=False):
        K = self.K if idx is None else self.K[idx]
        if transposed:
            K = np.swapaxes(K, 1, 2)
        y = np.matmul(K, _vec_batch(X)[:, :, None])[:, :, 0]
        return _unvec_batch(y, self.n1, self.n2)

    def diag(self, idx=None):
        K = self.K if idx is None else self.K[idx]
        return _unvec_batch(np.diagonal(K, axis1=1, axis2=2), self.n1, self.n2)

    def pair(self, p):
        return DenseAffinity(self.K[p], self.n1, self.n2)

    def score_assignments(self, p_idx, A, valid):
        n1 = self.n1
        cand = np.where(valid, np.where(valid, A, 0) * n1 + np.arange(n1)[None, :], 0)
        sub = self.K[p_idx[:, None, None], cand[:, :, None], cand[:, None, :]]
        w = valid[:, :, None] & valid[:, None, :]
        return (sub * w).sum((1, 2))

    def drop_conflicts(self):
        n1, n2 = self.n1, self.n2
        idx = np.arange(n1 * n2)
        i, a = idx % n1, idx // n1
        conflict = (i[:, None] == i[None, :]) ^ (a[:, None] == a[None, :])
        return _Dense(np.where(conflict[None], 0.0, self.K), n1, n2)


class _Sparse:
    """All blocks on the diagonal of one CSR matrix ``B`` of shape (P n1 n2, P n1 n2)."""

    kind = "sparse"

    def __init__(self, B, P, n1, n2):
        self.B, self.P, self.n1, self.n2 = B.tocsr(), P, n1, n2
        self._BT = None

    @classmethod
    def from_triplets(cls, triplets, n1, n2):
        """Per-pair ``(rows, cols, vals)`` in local indices; duplicates summed."""
        nn = n1 * n2
        P = len(triplets)
        off = np.repeat(np.arange(P) * nn, [len(t[0]) for t in triplets])
        rows = np.concatenate([t[0] for t in triplets]) + off
        cols = np.concatenate([t[1] for t in triplets]) + off
        vals = np.concatenate([t[2] for t in triplets]).astype(float)
        return cls(sp.csr_matrix((vals, (rows, cols)), shape=(P * nn, P * nn)), P, n1, n2)

    def _ix(self, idx):
        nn = self.n1 * self.n2
        return (np.asarray(idx).reshape(-1, 1) * nn + np.arange(nn)).ravel()

    def subset(self, idx):
        ix = self._ix(idx)
        return _Sparse(self.B[ix][:, ix], len(np.asarray(idx).ravel()), self.n1, self.n2)

    def product(self, X, idx, transposed=False):
        B = self.B
        if transposed:
            if self._BT is None:
                self._BT = self.B.T.tocsr()
            B = self._BT
        if idx is None:
            y = B @ _vec_batch(X).ravel()
            return _unvec_batch(y.reshape(self.P, -1), self.n1, self.n2)
        full = np.zeros((self.P, self.n1, self.n2))
        full[idx] = X
        y = (B @ _vec_batch(full).ravel()).reshape(self.P, -1)[idx]
        return _unvec_batch(y, self.n1, self.n2)

    def diag(self, idx=None):
        d = _unvec_batch(self.B.diagonal().reshape(self.P, -1), self.n1, self.n2)
        return d if idx is None else d[idx]

    def pair(self, p):
        nn = self.n1 * self.n2
        return SparseAffinity(self.B[p * nn:(p + 1) * nn, p * nn:(p + 1) * nn], self.n1, self.n2)

    def score_assignments(self, p_idx, A, valid):
        nn = self.n1 * self.n2
        c, n1 = A.shape
        cols = np.repeat(np.arange(c), n1)
        rows = (p_idx[:, None] * nn + np.where(valid, A, 0) * n1 + np.arange(n1)[None, :])
        Xs = sp.csc_matrix((valid.ravel().astype(float), (rows.ravel(), cols)),
                           shape=(self.B.shape[0], c))
        return np.asarray(Xs.multiply(self.B @ Xs).sum(0)).ravel()

    def drop_conflicts(self):
        nn, n1 = self.n1 * self.n2, self.n1
        K = self.B.tocoo()
        r, c = K.row % nn, K.col % nn
        conflict = ((r % n1) == (c % n1)) ^ ((r // n1) == (c // n1))
        keep = ~conflict
        B = sp.csr_matrix((K.data[keep], (K.row[keep], K.col[keep])), shape=K.shape)
        return _Sparse(B, self.P, self.n1, self.n2)


class _Loop:
    """Per-pair fallback: a Python loop over the pairs' own ``matvec`` (exotic affinities only)."""

    kind = "loop"

    def __init__(self, affs, n1, n2):
        self.affs, self.n1, self.n2 = list(affs), n1, n2
        self._scorers = {}                # pair -> its one-pair backend (_pair_scorer) or None

    def subset(self, idx):
        return _Loop([self.affs[k] for k in np.asarray(idx).ravel()], self.n1, self.n2)

    def product(self, X, idx, transposed=False):
        ids = range(len(self.affs)) if idx is None else np.asarray(idx).ravel()
        f = (lambda a, x: a.rmatvec(x)) if transposed else (lambda a, x: a.matvec(x))
        return np.stack([f(self.affs[k], x) for k, x in zip(ids, X)])

    def diag(self, idx=None):
        ids = range(len(self.affs)) if idx is None else np.asarray(idx).ravel()
        return np.stack([self.affs[k].diag() for k in ids])

    def pair(self, p):
        return self.affs[p]

    def score_assignments(self, p_idx, A, valid):
        out = np.empty(len(A))
        for p in np.unique(p_idx):
            rows = np.flatnonzero(p_idx == p)
            if p not in self._scorers:
                self._scorers[p] = _pair_scorer(self.affs[p])
            if self._scorers[p] is not None:
                out[rows] = self._scorers[p].score_assignments(
                    np.zeros(len(rows), dtype=np.int64), A[rows], valid[rows])
                continue
            for k in rows:
                X = np.zeros((self.n1, self.n2))
                X[np.flatnonzero(valid[k]), A[k][valid[k]]] = 1.0
                out[k] = self.affs[p].score(X)
        return out

    def drop_conflicts(self):
        return _Loop([a.drop_conflicts() for a in self.affs], self.n1, self.n2)


def _pair_scorer(aff):
    """One pair's affinity as a batched backend, for candidate scores without a product per
    candidate: a :class:`SeparableAffinity` as :class:`_Separable`, an explicit or factorized
    one as :class:`_Sparse` (its K entries; repeated edges summed); ``None`` for others."""
    if isinstance(aff, SeparableAffinity):
        node = None if aff.node is None else aff.node[None]
        return _Separable(aff.F[None], aff.G[None], [0], [0], node)
    if isinstance(aff, (DenseAffinity, SparseAffinity, FactorizedAffinity)):
        return _Sparse.from_triplets([_triplets(aff)], aff.n1, aff.n2)
    return None


# --------------------------------------------------------------------------- the public class


class PairAffinities:
    """Affinities ``K_p`` of ``P`` graph pairs behind batched products.

    Build with :meth:`from_graphs`, :meth:`from_blocks`, :meth:`from_factors` or
    :meth:`from_affinities`; the constructor itself takes an internal backend object.

    Parameters
    ----------
    impl : object
        The internal backend computing the products (built by the ``from_*`` constructors,
        which check their inputs and raise ``ValueError`` or ``TypeError`` on bad ones).
    pairs : int ndarray of shape (P, 2)
        ``pairs[p] = (i, j)``; rows of ``X[p]`` are nodes of graph ``i``.
    max_error : float, default=0.0
        Entrywise bound on the error of the separable expansion (0 for the others).

    Attributes
    ----------
    pairs : int ndarray of shape (P, 2)
        As given.
    n1, n2 : int
        Sizes of the graphs of every pair.
    backend : {"separable", "dense", "sparse", "loop"}
        How products are computed (module docstring).
    max_error : float
        As given.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.graphs import Graph
    >>> from transync.multigraph import PairAffinities
    >>> rng = np.random.default_rng(0)
    >>> graphs = [Graph.from_points(rng.random((4, 2)), edges="full") for _ in range(3)]
    >>> aff = PairAffinities.from_graphs(graphs)                # all 3 pairs
    >>> aff.pairs.tolist(), aff.backend, (aff.n1, aff.n2)
    ([[0, 1], [0, 2], [1, 2]], 'separable', (4, 4))
    >>> aff.score(np.broadcast_to(np.eye(4), (3, 4, 4))).shape  # one score per pair
    (3,)
    """

    def __init__(self, impl, pairs: np.ndarray, *, max_error: float = 0.0) -> None:
        self._impl = impl
        self.pairs = pairs
        self.n1, self.n2 = impl.n1, impl.n2
        self.max_error = float(max_error)

    # ---------------------------------------------------------------- constructors
    @classmethod
    def from_graphs(cls, graphs, pairs=None, affinity=None, *,
                    n_pad: int | None = None) -> PairAffinities:
        """Affinities of ``pairs`` of ``graphs`` (default all pairs).

        ``affinity``: callable ``(g_i, g_j) -> Affinity``; ``None`` is
        ``gaussian_edge_affinity(g_i, g_j, sigma2=0.15)``. ``None`` and
        ``functools.partial(gaussian_edge_affinity, sigma2=..., attribute=..., tol=...)`` take the
        per-graph separable path when the pairwise function would pick its separable backend
        (scalar edge attributes on dense graphs): no per-pair object is ever built. Otherwise the
        callable runs once per pair and its results are stacked (see the module docstring).

        Graphs of different sizes need ``n_pad >= max n_i``: every pair's affinity (computed on
        the real graphs) is embedded in an ``n_pad x n_pad`` problem whose extra *dummy* nodes
        have zero affinity to everything (isolated nodes without attributes), so that the
        lock-step solvers run on one shape; the real block of every ``K_p`` is the pair's own
        affinity, exactly.

        Examples
        --------
        >>> import numpy as np
        >>> from transync.graphs import Graph
        >>> rng = np.random.default_rng(0)
        >>> g = [Graph.from_points(rng.random((k, 2)), edges="full") for k in (3, 4)]
        >>> aff = PairAffinities.from_graphs(g, n_pad=4)
        >>> (aff.n1, aff.n2), bool(np.all(aff.diag()[0, 3] == 0))      # node 3 of g[0]: dummy
        ((4, 4), True)
        """
        graphs = check_graphs(graphs, equal_sizes=n_pad is None)
        pairs = check_pairs(pairs, len(graphs))
        sizes = np.array([g.n_nodes for g in graphs])
        if n_pad is not None:
            n_pad = check_int(n_pad, "n_pad", minimum=int(sizes.max()), maximum=10**5)
        n = int(sizes.max()) if n_pad is None else n_pad
        padded = bool(np.any(sizes != n))
        opts = _fast_gaussian_options(affinity)
        if opts is not None:
            used = sorted({int(k) for k in pairs.ravel()})
            sub = [_pad_isolated(graphs[k], n) for k in used]
            attribute = opts.get("attribute")
            kinds = {(g.edge_features is not None, g.points is not None) for g in sub}
            mixed = attribute is None and len(kinds) > 1   # the per-pair default would differ
            backend = opts.get("backend", "auto")
            remap = np.full(len(graphs), -1, np.int64)
            remap[used] = np.arange(len(used))
            local = remap[pairs]
            if not mixed and (backend == "separable" or _all_separable(sub, local, sizes[used])):
                sigma2 = opts.get("sigma2", DEFAULT_SIGMA2)
                check_positive(opts.get("angle_weight", 0.1), "angle_weight", allow_zero=True)
                fac = gaussian_edge_factors(sub, sigma2=sigma2, attribute=attribute,
                                            tol=opts.get("tol", 1e-10), pairs=local)
                F, G, err, M, E = fac.F, fac.G, fac.max_error, fac.masks, fac.attributes
                sym = bool(np.array_equal(M, np.swapaxes(M, 1, 2))
                           and np.array_equal(np.where(M, E, 0), np.where(M, E, 0).swapaxes(1, 2)))
                exact = (np.where(M, E, 1e100), np.where(M, E, -1e100), sigma2, sym)
                if err <= MAX_SEPARABLE_ERROR or backend == "separable":
                    impl = _Separable(F, G, local[:, 0], local[:, 1], exact=exact)
                    return cls(impl, pairs, max_error=err)
                # the expansion over all graphs' attributes is too coarse (attributes spread
                # over many kernel widths): the exact factorized form, pair by pair
                kw = {k: v for k, v in opts.items() if k != "backend"}
                affinity = functools.partial(gaussian_edge_affinity, backend="factorized", **kw)
        if affinity is None:          # the default, where the per-graph expansion does not apply
            affinity = functools.partial(gaussian_edge_affinity, sigma2=DEFAULT_SIGMA2)
        if not callable(affinity):
            raise TypeError(f"`affinity` must be None or a callable (g_i, g_j) -> Affinity, got "
                            f"{type(affinity).__name__}")
        affs = []
        for i, j in pairs:
            n_i, n_j = graphs[i].n_nodes, graphs[j].n_nodes
            try:
                a = affinity(graphs[i], graphs[j])
            except (ValueError, TypeError) as exc:      # say which pair ("g1" = graphs[i])
                if hasattr(exc, "add_note"):
                    exc.add_note(f"while building the affinity of graphs[{i}] (g1) and "
                                 f"graphs[{j}] (g2)")
                raise
            if not isinstance(a, Affinity):
                raise TypeError(f"`affinity` must return a transync.matching.Affinity, got "
                                f"{type(a).__name__} for pair ({i}, {j})")
            if a.shape != (n_i, n_j):
                raise ValueError(f"`affinity` returned shape {a.shape} for pair ({i}, {j}), "
                                 f"expected ({n_i}, {n_j})")
            a = as_affinity(a, name=f"affinity(graphs[{i}], graphs[{j}])")  # a user's: checked
            affs.append(_pad_affinity(a, n) if padded else a)
        return cls.from_affinities(affs, pairs)

    @classmethod
    def from_factors(cls, F, G, pairs, *, node=None) -> PairAffinities:
        """Separable affinities from per-graph factors (the ``"separable"`` backend).

        ``K_p = diag(vec(node[p])) + sum_r F[i_p, r] (x) G[j_p, r]`` for ``pairs[p] = (i_p,
        j_p)``, i.e. ``K_p[(u, a), (v, b)] = node[p, u, a] [u == v, a == b] + sum_r F[i_p, r, u,
        v] G[j_p, r, a, b]``; a product is ``Y_p = node_p * X_p + sum_r F_r X_p G_r^T``. With
        ``F = G = A[:, None]`` (adjacencies) the edge term is ``A_i[u, v] A_j[a, b]``; such
        one-factor stacks, when at most a quarter of their entries are nonzero, are multiplied
        as block-diagonal CSR matrices (``O(nnz n)`` per pair instead of ``O(n^3)``; the same
        products up to rounding).

        Parameters
        ----------
        F : array_like of shape (Ng1, R, n1, n1)
            Factors of the first graph of each pair, indexed by ``pairs[:, 0]``.
        G : array_like of shape (Ng2, R, n2, n2)
            Factors of the second graph, indexed by ``pairs[:, 1]`` (``G`` may be ``F``).
        pairs : array_like of shape (P, 2), int
            Indices into ``F`` and ``G`` (any order, repeats allowed); kept as :attr:`pairs`.
        node : array_like of shape (P, n1, n2), optional
            Node (unary) term of every pair.

        Raises
        ------
        ValueError, TypeError
            Wrong shapes or dimensions, non-finite values, indices out of range, factors so
            large that the products could overflow.

        Examples
        --------
        >>> import numpy as np
        >>> A = np.zeros((2, 1, 3, 3)); A[:, 0, 0, 1] = A[:, 0, 1, 0] = 1.0
        >>> aff = PairAffinities.from_factors(A, A, [[0, 1]], node=np.ones((1, 3, 3)))
        >>> aff.backend, aff.pair(0).to_dense().shape
        ('separable', (9, 9))
        """
        F = check_array(F, "F", ndim=4)
        G = check_array(G, "G", ndim=4)
        if F.shape[0] == 0 or F.shape[1] == 0 or F.shape[2] == 0 or F.shape[2] != F.shape[3]:
            raise ValueError(f"`F` must have shape (Ng, R, n1, n1) with Ng, R, n1 >= 1, got "
                             f"{F.shape}")
        if (G.shape[0] == 0 or G.shape[1] != F.shape[1] or G.shape[2] == 0
                or G.shape[2] != G.shape[3]):
            raise ValueError(f"`G` must have shape (Ng, R, n2, n2) with R={F.shape[1]} (as `F`) "
                             f"and Ng, n2 >= 1, got {G.shape}")
        pairs = check_array(pairs, "pairs", dtype=None)
        if pairs.ndim != 2 or pairs.shape[1] != 2 or pairs.shape[0] == 0:
            raise ValueError(f"`pairs` must have shape (P, 2) with P >= 1, got shape "
                             f"{pairs.shape}")
        pairs = check_int_array(pairs, "pairs", what="integer indices", copy=True)
        for col, name, size in ((0, "F", F.shape[0]), (1, "G", G.shape[0])):
            lo, hi = int(pairs[:, col].min()), int(pairs[:, col].max())
            if lo < 0 or hi >= size:
                raise ValueError(f"`pairs[:, {col}]` must index `{name}` in [0, {size}), got "
                                 f"range [{lo}, {hi}]")
        n1, n2 = F.shape[2], G.shape[2]
        if node is not None:
            node = check_array(node, "node", ndim=3)
            if node.shape != (len(pairs), n1, n2):
                raise ValueError(f"`node` must have shape (P, n1, n2) = ({len(pairs)}, {n1}, "
                                 f"{n2}), got {node.shape}")
        def top(a):                             # max |a| without an |a| copy of the stack
            return max(float(a.max(initial=0.0)), -float(a.min(initial=0.0)))

        with np.errstate(over="ignore"):        # inf here is refused below
            # |K_p| <= R max|F| max|G| + max|node| entrywise (as SeparableAffinity checks it):
            # factors of 1e154 passed, and every score and product came back inf or NaN
            top_f = top(F)
            bound = F.shape[1] * top_f * (top_f if G is F else top(G))
            if node is not None:
                bound += top(node)
        check_affinity_magnitude(bound, n1 * n2, "F, G, node" if node is not None else "F, G")
        impl = _Separable(F, G, pairs[:, 0], pairs[:, 1], node)
        return cls(impl, pairs)

    @classmethod
    def from_affinities(cls, affinities, pairs) -> PairAffinities:
        """Stack per-pair :class:`~transync.matching.Affinity` objects (all of one shape)."""
        affs = list(affinities)
        if not affs:
            raise ValueError("`affinities` must not be empty")
        pairs = check_array(pairs, "pairs", dtype=None, finite=False)
        if pairs.shape != (len(affs), 2):
            raise ValueError(f"`pairs` must have shape ({len(affs)}, 2), got {pairs.shape}")
        pairs = check_int_array(pairs, "pairs", integral_floats=True, allow_bool=True,
                                what="integer graph indices")
        n1, n2 = affs[0].n1, affs[0].n2
        for k, a in enumerate(affs):
            if not isinstance(a, Affinity):
                raise TypeError(f"`affinities[{k}]` must be an Affinity, got {type(a).__name__}")
            if (a.n1, a.n2) != (n1, n2):
                raise ValueError(f"`affinities[{k}]` has shape {(a.n1, a.n2)}, expected "
                                 f"{(n1, n2)} as the first")
            affs[k] = as_affinity(a, name=f"affinities[{k}]")        # a user's: checked
        types = {type(a) for a in affs}
        if types == {SeparableAffinity}:
            R = max(a.rank for a in affs)
            P = len(affs)
            F = np.zeros((P, R, n1, n1))
            G = np.zeros((P, R, n2, n2))
            for k, a in enumerate(affs):
                F[k, :a.rank], G[k, :a.rank] = a.F, a.G
            node = None
            if any(a.node is not None for a in affs):
                node = np.stack([np.zeros((n1, n2)) if a.node is None else a.node for a in affs])
            err = max(a.max_error for a in affs)
            return cls(_Separable(F, G, np.arange(P), np.arange(P), node), pairs, max_error=err)
        if types == {DenseAffinity} and len(affs) * (n1 * n2) ** 2 * 8 <= DENSE_BYTES:
            return cls(_Dense(np.stack([a.K for a in affs]), n1, n2), pairs)
        if types <= {DenseAffinity, SparseAffinity, FactorizedAffinity}:
            return cls(_Sparse.from_triplets([_triplets(a) for a in affs], n1, n2), pairs)
        return cls(_Loop(affs, n1, n2), pairs)

    @classmethod
    def from_blocks(cls, K, pairs=None, n: int | None = None, *, n_graphs: int | None = None,
                    sizes=None, name: str = "K") -> PairAffinities:
        """Precomputed pygmtools-layout blocks ``K_ij`` of shape ``(n*n, n*n)``.

        ``K``: an ndarray of shape ``(N, N, n*n, n*n)``, a dict ``{(i, j): K_ij}`` or an ``(N, N)``
        nested list (entries dense or ``scipy.sparse``). A pair ``(i, j)`` missing from a dict or
        list whose ``(j, i)`` block is present uses that block, re-indexed. ``pairs`` default:
        all pairs of the ``N`` graphs (``N`` from the array or list; required for a dict).
        ``n_graphs``: the number of graphs the blocks must describe (checked when given).

        Graphs of different sizes: ``sizes`` (the ``N`` graphs' node counts; dict or nested list
        only), block ``K_ij`` of shape ``(n_i n_j, n_i n_j)``, every pair embedded in an
        ``n x n`` problem (``n >= max sizes``, default the largest) with zero-affinity dummies
        (as :meth:`from_graphs` with ``n_pad``).
        """
        if sizes is not None:
            sizes = check_array(sizes, "sizes", dtype=None, ndim=1)
            if sizes.dtype.kind not in "iu" or sizes.size == 0 or sizes.min() < 1:
                raise ValueError(f"`sizes` must be positive integer node counts, got "
                                 f"{sizes.tolist()[:10]}")
            n = int(sizes.max()) if n is None else n
            n = check_int(n, "n", minimum=int(sizes.max()))
            if isinstance(K, np.ndarray) and K.dtype != object and np.any(sizes != n):
                raise ValueError(f"`{name}` as one (N, N, n*n, n*n) array holds graphs of one "
                                 "size; graphs of different sizes need a dict or nested list")
        if n is None:
            raise TypeError("`n` (the number of nodes per graph) is required")
        n = check_int(n, "n", minimum=1)
        nn = n * n
        if isinstance(K, dict):
            if pairs is None:
                raise TypeError("`pairs` is required when `K` is a dict")
            keys = _dict_keys(K, name)
            given = check_int_array(pairs, "pairs", integral_floats=True,
                                    what="integer graph indices")
            top = given.max(initial=0) if given.size else 0
            N = 1 + max([int(top)] + [max(i, j) for i, j in keys])
            if n_graphs is not None and N > n_graphs:
                raise ValueError(f"`{name}` has a block for graph {N - 1}, but there are only "
                                 f"{n_graphs} graphs")
            pairs = check_pairs(pairs, max(N, 2) if n_graphs is None else n_graphs)
            get = lambda i, j: K.get((i, j))  # noqa: E731
        elif isinstance(K, np.ndarray) and K.dtype != object:
            K = check_array(K, name, ndim=4)
            if K.shape[0] != K.shape[1] or K.shape[2:] != (nn, nn):
                raise ValueError(f"`{name}` must have shape (N, N, n*n, n*n) = "
                                 f"(N, N, {nn}, {nn}), got "
                                 f"{K.shape}")
            _check_count(K.shape[0], n_graphs, name)
            pairs = check_pairs(pairs, K.shape[0])
            sel = K[pairs[:, 0], pairs[:, 1]]
            check_nonnegative(sel, name)
            if sel.size:
                check_affinity_magnitude(sel.max(), nn, name)
            if len(pairs) * nn * nn * 8 <= DENSE_BYTES:
                return cls(_Dense(np.ascontiguousarray(sel), n, n), pairs)
            return cls(_Sparse.from_triplets([_triplets(b) for b in sel], n, n), pairs)
        elif isinstance(K, (list, tuple, np.ndarray)):
            N = len(K)
            if any(not isinstance(row, (list, tuple, np.ndarray)) or len(row) != N for row in K):
                raise ValueError(f"`{name}` as a nested list must be (N, N) = ({N}, {N}) blocks")
            _check_count(N, n_graphs, name)
            pairs = check_pairs(pairs, N)
            get = lambda i, j: K[i][j]  # noqa: E731
        else:
            raise TypeError(f"`{name}` must be an ndarray (N, N, n*n, n*n), a dict "
                            "{(i, j): K_ij} or "
                            f"an (N, N) nested list, got {type(K).__name__}")
        if sizes is not None and sizes.size < int(pairs.max()) + 1:
            raise ValueError(f"`sizes` must give the size of every graph, got {sizes.size} for "
                             f"graph indices up to {int(pairs.max())}")
        affs = []
        for i, j in pairs:
            i, j = int(i), int(j)
            ni, nj = (n, n) if sizes is None else (int(sizes[i]), int(sizes[j]))
            b, where = get(i, j), f"{name}[{i}][{j}]"
            if b is None:
                b, where = get(j, i), f"{name}[{j}][{i}]"
                if b is None:
                    raise ValueError(f"`{name}` has no block for pair ({i}, {j}) (nor ({j}, {i}))")
                # re-indexing of a (j, i) block: candidate (a, u) of K_ji -> (u, a) of K_ij
                t = np.arange(ni * nj).reshape(ni, nj).T.ravel()
                b = b.tocsr()[t][:, t] if sp.issparse(b) else np.asarray(b)[np.ix_(t, t)]
            a = as_affinity(b, n1=ni, n2=nj, name=where)
            affs.append(_pad_affinity(a, n) if (ni, nj) != (n, n) else a)
        return cls.from_affinities(affs, pairs)

    # ---------------------------------------------------------------- container
    def __len__(self) -> int:
        return len(self.pairs)

    @property
    def backend(self) -> str:
        return self._impl.kind

    def __repr__(self) -> str:
        return (f"PairAffinities(pairs={len(self)}, n1={self.n1}, n2={self.n2}, "
                f"backend={self.backend!r})")

    def _index(self, idx, name="idx") -> np.ndarray:
        idx = check_array(idx, name, dtype=None)
        if idx.dtype == bool:
            if idx.shape != (len(self),):
                raise ValueError(f"`{name}` as a mask must have shape ({len(self)},), got "
                                 f"{idx.shape}")
            return np.flatnonzero(idx)
        if idx.dtype.kind not in "iu" or idx.ndim != 1:
            raise TypeError(f"`{name}` must be a 1-D int array of pair indices, got "
                            f"{idx.dtype} of shape {idx.shape}")
        if idx.size and (idx.min() < -len(self) or idx.max() >= len(self)):
            raise ValueError(f"`{name}` must hold pair indices in [0, {len(self)}), got range "
                             f"[{idx.min()}, {idx.max()}]")
        return idx.astype(np.int64) % len(self)

    def subset(self, idx) -> PairAffinities:
        """The affinities of pairs ``idx`` (int indices or a boolean mask), in that order."""
        idx = self._index(idx)
        return PairAffinities(self._impl.subset(idx), self.pairs[idx], max_error=self.max_error)

    def pair(self, p) -> Affinity:
        """Pair ``p``'s affinity as a :class:`~transync.matching.Affinity`."""
        p = check_int(p, "p", minimum=-len(self), maximum=len(self) - 1) % len(self)
        return self._impl.pair(p)

    # ---------------------------------------------------------------- products
    def _check_X(self, X, k=None):
        X = check_array(X, "X", ndim=3)
        k = len(self) if k is None else k
        if X.shape != (k, self.n1, self.n2):
            raise ValueError(f"`X` must have shape (P, n1, n2) = ({k}, {self.n1}, {self.n2}), "
                             f"got {X.shape}")
        return X

    def matvec(self, X) -> np.ndarray:
        """``reshape(K_p vec(X_p))`` for every pair: (P, n1, n2) -> (P, n1, n2)."""
        return self._impl.product(self._check_X(X), None)

    def rmatvec(self, X) -> np.ndarray:
        """``reshape(K_p^T vec(X_p))`` for every pair."""
        return self._impl.product(self._check_X(X), None, True)

    def _product(self, X, idx=None, transposed=False):
        """Trusted internal product on pairs ``idx`` (None: all); ``X``: (len(idx), n1, n2)."""
        return self._impl.product(X, idx, transposed)

    def diag(self) -> np.ndarray:
        """Diagonals of the ``K_p`` (unary terms), shape (P, n1, n2)."""
        return self._impl.diag()

    def score(self, X) -> np.ndarray:
        """``vec(X_p)^T K_p vec(X_p)`` for every pair, shape (P,)."""
        X = self._check_X(X)
        return np.einsum("pij,pij->p", X, self._impl.product(X, None))

    def score_assignments(self, p_idx, assignments) -> np.ndarray:
        """``x^T K_p x`` of assignments (node ``u`` -> ``assignments[c, u]``, -1 unmatched).

        ``p_idx`` (c,) pair indices (repeats allowed), ``assignments`` (c, n1). Costs
        ``O(R n^2)`` (separable) or ``O(n^2)`` (dense) gathers per candidate; no product.
        """
        p_idx = self._index(np.atleast_1d(np.asarray(p_idx)), "p_idx")
        A = check_array(assignments, "assignments", dtype=None)
        if A.ndim == 1 and len(p_idx) == 1:
            A = A[None]
        if A.ndim != 2 or A.shape != (len(p_idx), self.n1):
            raise ValueError(f"`assignments` must have shape (c, n1) = ({len(p_idx)}, {self.n1}),"
                             f" got {A.shape}")
        A = check_int_array(A, "assignments", integral_floats=True, copy=True)
        if A.size and (A.min() < -1 or A.max() >= self.n2):
            raise ValueError(f"`assignments` entries must lie in [-1, {self.n2}), got range "
                             f"[{A.min()}, {A.max()}]")
        return self._impl.score_assignments(p_idx, A, A >= 0)

    # ---------------------------------------------------------------- solver support
    def drop_conflicts(self) -> PairAffinities:
        """Affinities with conflicting entries zeroed (edge-based backends have none)."""
        if self.backend == "separable":
            return self
        return PairAffinities(self._impl.drop_conflicts(), self.pairs, max_error=self.max_error)

    def column_sums(self) -> np.ndarray:
        """Column sums of every ``K_p``, shape (P, n1, n2)."""
        return self._impl.product(np.ones((len(self), self.n1, self.n2)), None, True)

    def asymmetric(self, *, rtol: float = 1e-10) -> np.ndarray:
        """(P,) bool: pairs whose ``K_p`` is not symmetric, tested as the pairwise solvers do
        (one fixed random probe, relative tolerance ``rtol``)."""
        rtol = check_positive(rtol, "rtol", allow_zero=True)     # NaN made every pair symmetric
        probe = np.random.default_rng(12345).random((self.n1, self.n2))
        Xp = np.broadcast_to(probe, (len(self), self.n1, self.n2)).copy()
        a = self._impl.product(Xp, None)
        b = self._impl.product(Xp, None, True)
        scale = np.maximum(np.abs(a).max((1, 2), initial=0.0), 1e-300)
        return np.abs(a - b).max((1, 2), initial=0.0) > rtol * scale


def _triplets(a):
    """Entries ``(rows, cols, vals)`` of one pair's ``K`` (pygmtools layout), never densified
    for factorized affinities (duplicates are summed by the CSR constructor)."""
    if isinstance(a, np.ndarray):
        r, c = np.nonzero(a)
        return r, c, a[r, c]
    if isinstance(a, (SparseAffinity, DenseAffinity)):
        K = a.K.tocoo() if sp.issparse(a.K) else sp.coo_matrix(a.K)
        return K.row, K.col, K.data
    n1 = a.n1                                   # FactorizedAffinity
    rows = (a.edges2[:, 0][None, :] * n1 + a.edges1[:, 0][:, None]).ravel()
    cols = (a.edges2[:, 1][None, :] * n1 + a.edges1[:, 1][:, None]).ravel()
    d = a.diag().ravel(order="F")
    nz = np.flatnonzero(d)
    return np.r_[rows, nz], np.r_[cols, nz], np.r_[a.edge.ravel(), d[nz]]


def _pad_isolated(g: Graph, n: int) -> Graph:
    """``g`` with ``n - n_g`` isolated dummy nodes appended (no edges; zero points and edge
    attributes; node features and labels dropped): for the edge-only Gaussian affinity only,
    where a dummy's affinity to anything is exactly zero."""
    k = n - g.n_nodes
    if k == 0:
        return g
    A = np.zeros((n, n))
    A[:g.n_nodes, :g.n_nodes] = g.adjacency
    pts = None if g.points is None else np.vstack([g.points, np.zeros((k, g.points.shape[1]))])
    E = None
    if g.edge_features is not None:
        E = np.zeros((n, n))
        E[:g.n_nodes, :g.n_nodes] = g.edge_features
    return Graph(adjacency=A, points=pts, edge_features=E, directed=g.directed)


class _PaddedAffinity(Affinity):
    """An ``(n1, n2)`` affinity embedded in ``(n, n)``; rows / columns beyond are dummies."""

    def __init__(self, a: Affinity, n: int):
        self.a, self.n1, self.n2 = a, n, n

    def _apply(self, f, X):
        Y = np.zeros((self.n1, self.n2))
        Y[:self.a.n1, :self.a.n2] = f(np.asarray(X, dtype=float)[:self.a.n1, :self.a.n2])
        return Y

    def matvec(self, X):
        return self._apply(self.a.matvec, X)

    def rmatvec(self, X):
        return self._apply(self.a.rmatvec, X)

    def diag(self):
        D = np.zeros((self.n1, self.n2))
        D[:self.a.n1, :self.a.n2] = self.a.diag()
        return D

    def to_dense(self):
        idx = _padded_index(self.a.n1, self.a.n2, self.n1)
        K = np.zeros((self.n1 * self.n2,) * 2)
        K[np.ix_(idx, idx)] = self.a.to_dense()
        return K

    def drop_conflicts(self):
        return _PaddedAffinity(self.a.drop_conflicts(), self.n1)


def _padded_index(n1: int, n2: int, n: int) -> np.ndarray:
    """Index in the ``n x n`` pygmtools layout of candidate ``a * n1 + u`` of ``n1 x n2``."""
    u, a = np.meshgrid(np.arange(n1), np.arange(n2), indexing="xy")
    return (a * n + u).ravel()


def _pad_affinity(a: Affinity, n: int) -> Affinity:
    """``a`` embedded in an ``n x n`` problem with zero-affinity dummies, in the cheapest form
    the stacking backends take: padded factors, re-indexed sparse entries, or a wrapper."""
    if a.shape == (n, n):
        return a
    n1, n2 = a.shape
    if isinstance(a, SeparableAffinity):
        F = np.zeros((a.rank, n, n))
        G = np.zeros((a.rank, n, n))
        F[:, :n1, :n1], G[:, :n2, :n2] = a.F, a.G
        node = None
        if a.node is not None:
            node = np.zeros((n, n))
            node[:n1, :n2] = a.node
        return SeparableAffinity(node, F, G, max_error=a.max_error)
    if isinstance(a, (DenseAffinity, SparseAffinity, FactorizedAffinity)):
        r, c, v = _triplets(a)
        idx = _padded_index(n1, n2, n)
        K = sp.csr_matrix((v, (idx[r], idx[c])), shape=(n * n, n * n))
        return SparseAffinity(K, n, n)
    return _PaddedAffinity(a, n)


def _all_separable(graphs, pairs, sizes) -> bool:
    """Whether ``gaussian_edge_affinity(backend="auto")`` picks the separable form for every pair
    (:func:`~transync.matching.prefers_separable`), on the graphs' real sizes ``sizes``
    (``graphs`` may be padded with isolated dummies: the per-pair function sees the real graphs,
    and the rule on the padded size refused every pair of a collection holding one small graph,
    whose per-pair fallback then paid for an expansion per pair and a product without shared
    factors). Pairs with a graph of at most :data:`_TINY_GRAPH` nodes do not count, as long as
    one pair does: the rule prefers their factorized form, but either form costs them
    ``O(n)`` per expansion term, while per-pair affinities for the whole collection cost an
    expansion per pair and the per-pair loop."""
    m = np.array([int(g.mask.sum()) for g in graphs], dtype=np.int64)
    n = np.asarray(sizes, dtype=np.int64)
    i, j = pairs[:, 0], pairs[:, 1]
    prefer = prefers_separable(n[i], n[j], m[i], m[j])
    tiny = np.minimum(n[i], n[j]) <= _TINY_GRAPH
    return bool(np.all(prefer | tiny) and np.any(prefer))


def _check_count(N: int, n_graphs, name: str) -> None:
    if N < 2:
        raise ValueError(f"`{name}` must hold blocks for at least 2 graphs, got {N}")
    if n_graphs is not None and N != n_graphs:
        raise ValueError(f"`{name}` holds blocks for {N} graphs, but {n_graphs} graphs were given")


def _dict_keys(K: dict, name: str) -> list[tuple[int, int]]:
    keys = []
    for key in K:
        ok = (isinstance(key, tuple) and len(key) == 2
              and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 0
                      for v in key))
        if not ok:
            raise TypeError(f"`{name}` as a dict must have keys (i, j) of graph indices, got "
                            f"{key!r}")
        if key[0] == key[1]:
            raise ValueError(f"`{name}` as a dict holds blocks between two graphs; key {key!r} "
                             f"pairs graph {int(key[0])} with itself")
        keys.append((int(key[0]), int(key[1])))
    return keys


def check_graphs(graphs, *, equal_sizes: bool = True) -> list:
    """``graphs`` as a list of at least two Graphs of ``n >= 1`` nodes, of one size when
    ``equal_sizes`` (full permutations)."""
    if isinstance(graphs, (str, bytes, Graph)) or not isinstance(graphs, Sequence):
        raise TypeError("`graphs` must be a sequence (list or tuple) of transync.graphs.Graph, "
                        f"got {type(graphs).__name__}")
    graphs = list(graphs)
    if len(graphs) < 2:
        raise ValueError(f"`graphs` must hold at least 2 graphs to match, got {len(graphs)}")
    for k, g in enumerate(graphs):
        if not isinstance(g, Graph):
            raise TypeError(f"`graphs[{k}]` must be a transync.graphs.Graph, got "
                            f"{type(g).__name__}")
    sizes = np.array([g.n_nodes for g in graphs])
    if sizes.min() < 1:
        raise ValueError(f"`graphs[{int(np.argmin(sizes))}]` has no nodes; every graph needs at "
                         "least one")
    if equal_sizes and np.any(sizes != sizes[0]):
        shown = sizes.tolist()[:12]
        raise ValueError(
            "`graphs` must all have the same number of nodes here (full permutations); got "
            f"sizes {shown}{' ...' if len(sizes) > 12 else ''}. Pass `n_pad` to embed them in "
            "one padded size")
    return graphs
