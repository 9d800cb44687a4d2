"""Synchronization over the Birkhoff polytope (documentation: methods page *Birkhoff-polytope
synchronization*).

Soft pairwise matches ``X_ij`` (doubly stochastic) are projected onto the convex hull of the
*consistent configurations* ``S_k`` (block matrices ``S_k,ij = P_i^k P_j^kT`` of absolute
permutations ``P_i^k``):

.. math:: \\min_{\\alpha \\in \\Delta} \\tfrac12 \\sum_{(i,j) \\in \\Omega} w_{ij}
          \\| X_{ij} - \\textstyle\\sum_k \\alpha_k S_{k,ij} \\|_F^2 ,

by conditional gradient (Frank-Wolfe) with column generation: "solving for k-hat" is a
permutation synchronization on the residual (Gauss-Seidel Hungarian sweeps from a spectral start
and from warm starts), "solving for alpha" is the exact line search of the quadratic (pairwise
Frank-Wolfe step), or a fully corrective re-optimization of all weights on the simplex
(active-set QP on the Gram matrix of the atoms).

Vectorized throughout: the observed pairs are directed edges sorted by source object,
so one object's Gauss-Seidel update is one row gather over its incident blocks plus one
Hungarian per start configuration (all starts in lock-step); maps, blocks and Gram rows of the
atoms are batched gathers; the weight problem lives on the ``K x K`` Gram matrix, never on the
``(P, n, n)`` blocks.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.optimize import linear_sum_assignment

from .._validation import (
    MAX_ITER,
    as_generator,
    check_array,
    check_bool,
    check_choice,
    check_index_pairs,
    check_int,
    check_positive,
)
from ..exceptions import ConvergenceWarning
from ..permutations import MultiMatching
from . import _spectral as spec
from ._linalg import RowBlockProduct
from ._pairwise_input import check_universe, parse_pairwise
from ._result import CarriesMatching

__all__ = ["BirkhoffSyncResult", "UniverseEstimate", "birkhoff_von_neumann", "estimate_universe",
           "synchronize_doubly_stochastic"]


def birkhoff_von_neumann(X, *, tol: float = 1e-9,
                         max_terms: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Birkhoff-von Neumann decomposition of a doubly-stochastic matrix (greedy, §1.7).

    Repeatedly finds a permutation inside the support of the remainder (Hungarian on ``log X``,
    which favours large entries), removes it with the largest feasible weight, and stops when the
    remainder is below ``tol``. At most ``n^2 - 2n + 2`` terms for an exact DS matrix.

    Parameters
    ----------
    X : (n, n) array
        Non-negative, every row and column summing to 1 (to ``1e-6``).
    tol : float, default=1e-9
        Entries of the remainder at or below ``tol`` count as zero (round-off; at most 1e-6).
    max_terms : int, optional
        At most this many terms (>= 1). Default ``n^2 - 2n + 2`` (at least 1) plus ``n`` for
        round-off. A ``ValueError`` is raised when ``X`` needs more terms than allowed (the
        weights would not sum to 1).

    Returns
    -------
    weights : (K,) ndarray
        Positive weights, summing to 1 up to ``n * tol``.
    permutations : (K, n) int ndarray
        Assignments: ``X ~= sum_k weights[k] * assignment_to_matrix(permutations[k], n)``.

    Raises
    ------
    ValueError, TypeError
        ``X`` not square, negative, or with row or column sums off 1 by more than 1e-6; bad
        ``tol`` or ``max_terms``; more terms needed than ``max_terms`` allows.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.synchronization import birkhoff_von_neumann
    >>> X = np.array([[0.7, 0.3, 0.0], [0.3, 0.2, 0.5], [0.0, 0.5, 0.5]])
    >>> w, P = birkhoff_von_neumann(X)
    >>> np.round(w, 3), P.tolist()
    (array([0.5, 0.3, 0.2]), [[0, 2, 1], [1, 0, 2], [0, 1, 2]])
    """
    X = check_array(X, "X", ndim=2)
    n = X.shape[0]
    if X.shape != (n, n) or n == 0:
        raise ValueError(f"`X` must be a non-empty square matrix, got shape {X.shape}")
    if X.min() < -1e-12:
        raise ValueError(f"`X` must be non-negative, got minimum {X.min():.3g}")
    err = max(np.abs(X.sum(0) - 1).max(), np.abs(X.sum(1) - 1).max())
    if err > 1e-6:
        raise ValueError(f"`X` must be doubly stochastic (rows and columns summing to 1), got a "
                         f"deviation of {err:.3g}")
    tol = check_positive(tol, "tol")
    if tol > 1e-6:
        raise ValueError(f"`tol` must be <= 1e-6 (it only absorbs round-off; a larger one leaves "
                         f"part of `X` undecomposed), got {tol!r}")
    limit = (max(n * n - 2 * n + 2, 1) + n if max_terms is None
             else check_int(max_terms, "max_terms", minimum=1))
    R = np.clip(X, 0, None).copy()
    weights: list[float] = []
    perms: list[np.ndarray] = []
    rows = np.arange(n)
    while R.max() > tol and len(weights) < limit:
        support = R > tol
        score = np.where(support, np.log(np.where(support, R, 1.0)), -1e9)
        _, cols = linear_sum_assignment(score, maximize=True)
        if not support[rows, cols].all():
            break                                   # round-off left no perfect matching
        a = float(R[rows, cols].min())
        R[rows, cols] -= a
        weights.append(a)
        perms.append(cols.astype(np.int64))
    if len(weights) >= limit and R.max() > tol:
        raise ValueError(f"`max_terms`={limit} is too small for `X`: after {limit} terms a "
                         f"remainder of total weight {R.sum() / n:.3g} is left; raise "
                         "`max_terms` or leave it at None")
    return np.asarray(weights), np.asarray(perms, dtype=np.int64).reshape(-1, n)


#: Warm start: at most this many atoms of ``init`` (the heaviest) are kept.
WARM_MAX_ATOMS = 32
#: Largest total node count whose universe size is estimated (a dense eigenproblem, 3 GiB here).
MAX_DENSE_UNIVERSE_NODES = 20_000
#: Atoms whose weight falls to or below this value are dropped (weights renormalized).
_DROP = 1e-12
#: Matrix-free eigensolver: the block matrix is formed densely (one GEMM per product) when the
#: view covers at least a quarter of it and it has at most this many rows, padding included
#: (8 000: 512 MB).
DENSE_OPERATOR_MAX = 8000
#: Restarts of the matrix-free eigensolver for the spectral start of the first k-hat step (on the
#: residual). The start is only rounded and then improved by the sweeps; on a residual with a
#: flat spectrum (input that is already nearly consistent) the default 300 restarts were spent
#: for nothing (N = 128, n = 30: 208 restarts, 15 s, of a 24 s synchronization). The initial
#: vertex (the spectral rounding of the input itself) keeps the default: capped at 25 there,
#: N = 256, n = 20 on a view graph of degree 16 fell from accuracy 1.000 to 0.938.
RESIDUAL_MAX_RESTARTS = 25
#: Soft universe estimate (:func:`estimate_universe`): one slot more than the largest eigengap
#: says when the next gap is at least this fraction of it (a universe node kept by few objects
#: splits the gap). Measured with RRWM's soft solutions on collections of 8 graphs over d = 20
#: (p ~ U(p_low, 1)): right on 91.0 % -> 94.2 % of 600 collections at p_low = 0.6, deformation
#: 0.05 (20 collections right only with it, 1 only without), 57.7 % -> 59.7 % of 300 at
#: p_low = 0.3 (12 / 6), 73.7 % -> 73.0 % of 300 at deformation 0.1 (7 / 9); on 400 held-out
#: collections of the first setting 93.2 % -> 94.0 % (3 / 0). Fractions 0.4-0.6 and one or two
#: extra slots were tried on the first three sets; 0.6 and one slot lost least at deformation 0.1.
SOFT_SPLIT_GAP = 0.6


@dataclass(frozen=True)
class BirkhoffSyncResult(CarriesMatching):
    """Result of :func:`synchronize_doubly_stochastic`.

    Attributes
    ----------
    blocks : dict {(i, j): (n_i, n_j) ndarray}
        Consistent soft blocks ``Y_ij = sum_k weights[k] X_i^k X_j^kT`` for the observed pairs
        (``i < j``). With equal sizes and ``n_universe = n`` every block is doubly stochastic;
        in the partial (multi-simplex) model rows and columns sum to at most 1.
        ``block(i, j)`` gives any pair, ``stacked_blocks(pairs)`` many pairs at once.
    atoms : (K, N, n_max) int ndarray
        Consistent configurations as universe labels: ``atoms[k, g, u]`` is the slot of node ``u``
        of object ``g`` (``-1`` = padding beyond ``n_g``); canonical gauge: slots numbered in
        order of first appearance, so ``atoms[k, 0, :n_0] = arange(n_0)``.
    weights : (K,) ndarray
        Convex weights of the atoms (sum 1).
    matching : MultiMatching
        The MAP configuration (atom with the largest weight): a cycle-consistent multi-matching;
        ``labels``, ``n_universe`` and ``pairwise`` delegate to it.
    objective : float
        Final ``1/2 sum_{(i,j) observed} w_ij ||X_ij - Y_ij||_F^2`` (pairs counted once).
    objective_history : ndarray
        Objective after the initialization (the re-fitted ``init`` for a warm start) and after
        every iteration (non-increasing).
    n_iter : int
    converged : bool
        The Frank-Wolfe gap fell below ``tol * sum w_ij ||X_ij||^2``.
    info : dict
        ``"gap_history"``, ``"n_atoms"``, ``"fully_corrective"``, ``"solver"`` (eigensolver of
        the k-hat step), ``"n_universe"``, ``"n_universe_rule"``, ``"warm_start"`` (atoms
        taken from ``init``, or None)...

    Examples
    --------
    >>> from transync.datasets import make_permutation_collection
    >>> from transync.synchronization import synchronize_doubly_stochastic
    >>> data = make_permutation_collection(4, 5, rng=0)          # consistent input
    >>> res = synchronize_doubly_stochastic(data.pairwise)
    >>> len(res.weights), float(res.weights.sum()), data.accuracy(res.labels)
    (1, 1.0, 1.0)
    """

    blocks: Mapping[tuple[int, int], np.ndarray]
    atoms: np.ndarray
    weights: np.ndarray
    matching: MultiMatching
    objective: float
    objective_history: np.ndarray
    n_iter: int
    converged: bool
    info: Mapping[str, Any] = field(default_factory=dict)

    def atom(self, k: int) -> MultiMatching:
        """Atom ``k`` (a consistent configuration) as a :class:`MultiMatching`."""
        k = check_int(k, "k", minimum=0, maximum=self.atoms.shape[0] - 1)
        sizes = self.sizes
        return MultiMatching([self.atoms[k, g, : sizes[g]] for g in range(sizes.size)],
                             self.n_universe)

    def block(self, i: int, j: int) -> np.ndarray:
        """Soft consistent block ``Y_ij`` (``n_i x n_j``) for any pair (identity if ``i == j``)."""
        self.matching.pairwise(i, j)                      # validates i and j (cheap)
        i, j = int(i), int(j)
        sizes = self.sizes
        return self.stacked_blocks(np.array([[i, j]]))[0, : sizes[i], : sizes[j]]

    def stacked_blocks(self, pairs) -> np.ndarray:
        """Soft consistent blocks of many pairs at once, stacked in the order of ``pairs``.

        Parameters
        ----------
        pairs : (P, 2) int array_like
            Object pairs ``(i, j)`` (any order; ``i == j`` gives the identity, ``i > j`` the
            transpose of ``(j, i)``).

        Returns
        -------
        (P, n_max, n_max) ndarray
            ``out[p, :n_i, :n_j] = block(i, j)`` for ``pairs[p] = (i, j)``, zero padded beyond
            the objects' sizes (no padding when all objects have the same size). One vectorized
            gather over atoms and pairs; no Python loop over pairs.

        Examples
        --------
        >>> import numpy as np
        >>> from transync.synchronization import synchronize_doubly_stochastic
        >>> I, S = np.eye(3), np.eye(3)[[1, 0, 2]]
        >>> X = {(0, 1): 0.8 * I + 0.2 * S, (1, 2): I, (0, 2): 0.8 * I + 0.2 * S}
        >>> res = synchronize_doubly_stochastic(X, fully_corrective=True)
        >>> Y = res.stacked_blocks([[0, 1], [0, 2], [2, 1]])
        >>> Y.shape, bool(np.allclose(Y[0], X[(0, 1)])), bool(np.allclose(Y[2], I))
        ((3, 3, 3), True, True)
        """
        arr = check_index_pairs(pairs, self.n_objects)
        return _stack_atoms(self.atoms, np.asarray(self.weights, dtype=float), arr,
                            self.n_universe)

    def pairwise(self, i: int, j: int) -> np.ndarray:
        """The MAP consistent assignment from object ``i`` to object ``j`` (``-1`` unmatched)."""
        return self.matching.pairwise(i, j)

    def to_matrix(self) -> np.ndarray:
        """The ``(sum n_g, sum n_g)`` soft block matrix ``sum_k weights[k] X^k X^kT`` (blocks
        ``Y_ij``, identity blocks on the diagonal); meant for small problems."""
        return sum(w * self.atom(k).to_matrix() for k, w in enumerate(self.weights))


# ----------------------------------------------------------------------------------------------
# configurations held as padded labels (N, n_max): maps and blocks, vectorized
# ----------------------------------------------------------------------------------------------

def _inverse(labels: np.ndarray, d: int, fill: int) -> np.ndarray:
    """``inv[..., g, a]`` = node of object ``g`` in slot ``a`` (``fill`` if none); the extra
    last column (slot ``-1``, padding) is ``fill``. ``labels``: (..., N, n_max)."""
    inv = np.full(labels.shape[:-1] + (d + 1,), fill, dtype=np.int64)
    idx = np.nonzero(labels >= 0)
    inv[idx[:-1] + (labels[idx],)] = idx[-1]
    return inv


def _maps_of(labels: np.ndarray, pairs: np.ndarray, d: int) -> np.ndarray:
    """Maps ``i -> j`` of configurations ``labels`` (..., N, n_max) on ``pairs``:
    (..., P, n_max), ``-1`` unmatched / padding."""
    inv = _inverse(labels, d, -1)                         # (..., N, d + 1)
    src = labels[..., pairs[:, 0], :]                     # (..., P, n_max), -1 -> column d
    return np.take_along_axis(inv[..., pairs[:, 1], :], np.where(src >= 0, src, d), axis=-1)


def _stack_atoms(atoms, weights, pairs, d) -> np.ndarray:
    """``sum_k weights[k] * P_ij^k`` for every pair, (P, n_max, n_max)."""
    n_max = atoms.shape[2]
    maps = _maps_of(atoms, pairs, d) if atoms.shape[0] else np.zeros((0, len(pairs), n_max),
                                                                     dtype=np.int64)
    return _blocks_of_maps(maps, weights, len(pairs), n_max)


def _blocks_of_maps(maps, weights, P, n_max) -> np.ndarray:
    """Dense ``(P, n_max, n_max)`` blocks ``sum_k weights[k] * onehot(maps[k])``."""
    k, q, u = np.nonzero(maps >= 0)
    flat = (q * n_max + u) * n_max + maps[k, q, u]
    return np.bincount(flat, weights=np.asarray(weights, dtype=float)[k],
                       minlength=P * n_max * n_max).reshape(P, n_max, n_max)


def _matching(labels: np.ndarray, sizes: np.ndarray, d: int) -> MultiMatching:
    """The configuration held as padded ``labels`` (N, n_max) as a :class:`MultiMatching`."""
    return MultiMatching([labels[g, : sizes[g]] for g in range(sizes.size)], d)


def _canonical(labels: np.ndarray, d: int) -> np.ndarray:
    """Relabel slots in order of first appearance (object 0's nodes first)."""
    flat = labels.ravel()
    seen = flat[flat >= 0]
    _, first = np.unique(seen, return_index=True)
    used = seen[np.sort(first)]
    new = np.full(d + 1, -1, dtype=np.int64)
    new[used] = np.arange(used.size)
    rest = np.setdiff1d(np.arange(d), used)
    new[rest] = np.arange(used.size, d)
    return new[labels]


def _masked_take(B: np.ndarray, maps: np.ndarray) -> np.ndarray:
    """``B[q, u, maps[q, u]]`` where ``maps >= 0``, else 0."""
    vals = np.take_along_axis(B, np.maximum(maps, 0)[:, :, None], axis=2)[:, :, 0]
    return np.where(maps >= 0, vals, 0.0)


def _project_simplex(v: np.ndarray) -> np.ndarray:
    u = np.sort(v)[::-1]
    css = np.cumsum(u) - 1
    k = np.arange(1, v.size + 1)
    rho = np.nonzero(u - css / k > 0)[0][-1]
    return np.maximum(v - css[rho] / (rho + 1), 0)


# ----------------------------------------------------------------------------------------------
# solving for k-hat: the linear minimization oracle
# ----------------------------------------------------------------------------------------------

class _Oracle:
    """argmax over consistent (partial) configurations of ``<G, X X^T>`` (solving for k-hat).

    The observed pairs as directed edges sorted by source object, so that every object's
    incident blocks are one contiguous slice: the Gauss-Seidel update of object ``g`` is one
    batched gather over its edges plus one Hungarian; the block operator of the matrix-free
    eigensolver is one GEMM (dense views) or one sparse product.
    """

    def __init__(self, pairs, sizes, d, *, sweeps, rng, solver):
        self.pairs, self.sizes, self.d = pairs, sizes, d
        self.sweeps, self.rng = sweeps, rng
        N, P = sizes.size, pairs.shape[0]
        self.N, self.n_max = N, int(sizes.max())
        src = np.concatenate([pairs[:, 0], pairs[:, 1]])
        order = np.argsort(src, kind="stable")
        self.dst = np.concatenate([pairs[:, 1], pairs[:, 0]])[order]
        self.q = np.concatenate([np.arange(P), np.arange(P)])[order]
        self.transposed = order >= P
        self.ptr = np.searchsorted(src[order], np.arange(N + 1))
        off = np.concatenate([[0], np.cumsum(sizes)])
        self.M = int(off[-1])
        self.valid = np.arange(self.n_max)[None, :] < sizes[:, None]          # (N, n_max)
        self.use = solver if solver != "auto" else (
            "dense" if self.M <= spec.DENSE_MAX else "matrix_free")
        # matrix-free on a dense view (e.g. all pairs): the block matrix as one dense array costs
        # no more memory than the stacked blocks, and one GEMM per product instead of a batched
        # matmul + reduceat is ~5x faster (N = 128, n = 30, 72 columns: 0.08 s vs 0.37 s)
        self.dense_operator = (self.use == "matrix_free" and N * self.n_max <= DENSE_OPERATOR_MAX
                               and 2 * P * self.n_max ** 2 >= 0.25 * self.M ** 2)
        self._V = None                                    # warm eigenvectors (matrix-free)
        self.col_base = np.arange(int(np.diff(self.ptr).max(initial=0))) * (self.n_max + 1)
        self.nodes = [np.arange(n_g) for n_g in sizes.tolist()]

    def directed(self, wG: np.ndarray) -> np.ndarray:
        """(2P, n_max, n_max + 1): edge ``e`` = block from ``src`` to ``dst`` (zero last column)."""
        D = np.zeros((self.q.size, self.n_max, self.n_max + 1))
        t = self.transposed
        D[~t, :, : self.n_max] = wG[self.q[~t]]
        D[t, :, : self.n_max] = wG[self.q[t]].transpose(0, 2, 1)
        return D

    def block_matrix(self, wG) -> np.ndarray:
        """The symmetric (M, M) block matrix of ``wG``, real nodes only."""
        N, n = self.N, self.n_max
        pi, pj = self.pairs[:, 0], self.pairs[:, 1]
        B4 = np.zeros((N, n, N, n))
        B4[pi, :, pj, :] = wG
        B4[pj, :, pi, :] = wG.transpose(0, 2, 1)
        flat = self.valid.ravel()
        B = B4.reshape(N * n, N * n)
        return B if flat.all() else B[np.ix_(flat, flat)]

    def sparse_block_matrix(self, D):
        """The block matrix of the directed blocks ``D`` as float32 CSR, real nodes only
        (sparse views: N = 256, n = 20, degree 16, 52 columns: 16 ms a product in float64
        against 61 ms for a batched matmul of the blocks plus a ``reduceat``)."""
        n = self.n_max
        src = np.repeat(np.arange(self.N), np.diff(self.ptr))          # (2P,) edge sources
        u = np.arange(n)
        rows = np.broadcast_to((src[:, None] * n + u)[:, :, None], (src.size, n, n))
        cols = np.broadcast_to((self.dst[:, None] * n + u)[:, None, :], (src.size, n, n))
        pos = np.cumsum(self.valid.ravel()) - 1                         # padded -> real index
        ok = self.valid.ravel()[rows] & self.valid.ravel()[cols]
        return sp.csr_matrix((D[:, :, :n][ok].astype(np.float32),
                              (pos[rows[ok]], pos[cols[ok]])), shape=(self.M, self.M))

    def spectral(self, wG, D, max_restarts: int | None = None) -> np.ndarray:
        """Top-``d`` eigenvectors of the block matrix of ``wG`` rounded into ``d`` slots
        (``max_restarts``: of the matrix-free eigensolver, default its own)."""
        N, n = self.N, self.n_max
        k = min(self.d, self.M)
        kw = {} if max_restarts is None else {"max_restarts": max_restarts}
        if self.use == "dense":
            _, U = sla.eigh(self.block_matrix(wG), subset_by_index=[self.M - k, self.M - 1])
            U = U[:, ::-1]
        else:
            if self.dense_operator:
                matmat = self.block_matrix(wG).__matmul__
            else:
                A = RowBlockProduct(self.sparse_block_matrix(D))

                def matmat(X):      # float32 products (as the permutation synchronization's)
                    return (A @ X.astype(np.float32)).astype(np.float64)

            _, U, _, _, _ = spec.block_krylov_eigs(matmat, self.M, k, V0=self._V,
                                                   rng=self.rng, **kw)
            self._V = U
        lab_list = spec.round_to_universe(U, self.sizes, self.d, refine=1)
        labels = np.full((N, n), -1, dtype=np.int64)
        for g, lab in enumerate(lab_list):
            labels[g, : self.sizes[g]] = lab
        return labels

    def sweep(self, F, wG, labels):
        """At most ``sweeps`` Gauss-Seidel sweeps ``X_g <- Hungarian(sum_j w_gj G_gj X_j)``
        (rectangular ``n_g x d``: the exact block maximizer, so the score never decreases), run
        in lock-step for a stack of start configurations ``labels`` (C, N, n_max).

        ``F[g]`` holds object ``g``'s incident blocks transposed and stacked,
        ``(deg_g * (n + 1), n_g)``, so ``sum_j G_gj X_j`` of every start is one row gather and
        one sum; only the Hungarian runs per start. An object is revisited only when one of its
        neighbours changed (in that start)."""
        d, n = self.d, self.n_max
        labels = labels.copy()
        C = labels.shape[0]
        inv = _inverse(labels, d, n)[:, :, :d]            # node in slot, n (zero row) if none
        # relative to the scores' scale: an absolute floor outweighed the scores of small
        # weights (uniform weights of 1e-12 froze the sweeps), and only ratios of weights count
        scale = np.abs(wG).max(initial=0.0) * self.col_base.size
        eps = 1e-12 * scale if scale > 0 else np.finfo(float).tiny
        dirty = np.broadcast_to(np.diff(self.ptr) > 0, (C, self.N)).copy()
        for _ in range(self.sweeps):
            if not dirty.any():
                break
            for g in np.flatnonzero(dirty.any(0)).tolist():
                cs = np.flatnonzero(dirty[:, g])
                dirty[cs, g] = False
                lo, hi = self.ptr[g], self.ptr[g + 1]
                deg, n_g = hi - lo, int(self.sizes[g])
                rows = (inv[cs[:, None], self.dst[lo:hi]] + self.col_base[:deg, None]).ravel()
                S = F[g][rows].reshape(cs.size, deg, d, n_g).sum(1)          # (c, d, n_g)
                cur = labels[cs, g, :n_g]
                nodes = self.nodes[g]
                S[np.arange(cs.size)[:, None], cur, nodes] += eps   # keep current slots on ties
                for k, c in enumerate(cs.tolist()):
                    _, col = linear_sum_assignment(S[k].T, maximize=True)  # all rows assigned
                    if not np.array_equal(col, cur[k]):   # strictly better (ties keep cur)
                        inv[c, g, cur[k]] = n
                        inv[c, g, col] = nodes
                        labels[c, g, :n_g] = col
                        dirty[c, self.dst[lo:hi]] = True
        maps = _maps_of(labels, self.pairs, d)                            # (C, P, n_max)
        vals = np.take_along_axis(wG[None], np.maximum(maps, 0)[..., None], axis=3)[..., 0]
        return labels, np.where(maps >= 0, vals, 0.0).sum((1, 2))

    def __call__(self, G, w, starts=(), spectral=True, max_restarts: int | None = None):
        """Configurations (canonical labels) and their scores ``<G, X X^T>_w``, best first:
        the spectral start (``spectral``, its eigensolver capped at ``max_restarts``) and the
        given ``starts``, each improved by the sweeps; duplicates removed."""
        wG = G * w[:, None, None]
        D = self.directed(wG)
        cands = ([self.spectral(wG, D, max_restarts)] if spectral else []) + list(starts)
        F = [D[lo:hi, : self.sizes[g]].transpose(0, 2, 1).reshape(-1, self.sizes[g])
             for g, (lo, hi) in enumerate(zip(self.ptr[:-1], self.ptr[1:]))]
        labels, scores = self.sweep(F, wG, np.stack(cands))
        out, seen = [], set()
        for c in np.argsort(-scores, kind="stable").tolist():
            lab = _canonical(labels[c], self.d)
            key = lab.tobytes()
            if key not in seen:
                seen.add(key)
                out.append((lab, float(scores[c])))
        return out


# ----------------------------------------------------------------------------------------------
# the front door
# ----------------------------------------------------------------------------------------------

def synchronize_doubly_stochastic(pairwise, *, mask=None, weights=None, max_iter: int = 20,
                                  n_universe: int | None = None, inner_sweeps: int = 10,
                                  tol: float = 1e-6, fully_corrective: bool = False,
                                  solver: str = "auto", init=None,
                                  rng=None) -> BirkhoffSyncResult:
    """Project soft pairwise matches onto the hull of consistent permutation configurations.

    Conditional gradient (methods page *Birkhoff-polytope synchronization*): start from the
    permutation synchronization of the input (one atom of weight 1); at every iteration the
    residual ``G = X - Y`` on the observed pairs defines a new vertex ``U`` maximizing ``<G, U
    U^T>`` ("solving for k-hat": at most ``inner_sweeps`` Gauss-Seidel sweeps ``P_i <-
    Hungarian(sum_j w_ij G_ij P_j)``, run from the heaviest atom, and on the first iteration of a
    cold start also from the spectral rounding of ``G``; the best result is the vertex). "Solving
    for alpha": the exact minimizer of the quadratic along the better of the Frank-Wolfe direction
    ``U U^T - Y`` and the pairwise direction that moves weight from the active atom least aligned
    with the residual to ``U``; with ``fully_corrective`` every improving start's vertex joins the
    active set (eight heaviest atoms as starts) and all atom weights are re-optimized exactly on
    the simplex. Atoms whose weight vanishes are dropped. Stops when the Frank-Wolfe gap ``<G, U
    U^T - Y>`` is below ``tol * sum w_ij ||X_ij||^2``, or after ``max_iter`` iterations
    (``ConvergenceWarning``). The k-hat step is a heuristic, so "converged" means that it found no
    improving vertex; noisy input usually needs hundreds of atoms to close the gap, and a few
    iterations (warm-started across calls) are the intended use.

    **Warm start** (``init``, for repeated calls on slowly changing input, e.g. the
    synchronization points of an online solver): the atoms of a previous result on the same
    objects and universe replace the spectral initialization. At most ``WARM_MAX_ATOMS`` (32)
    of them, the heaviest, are kept; their weights are first re-fitted to the new input (the
    fully corrective re-optimization on the simplex, started from the old weights), atoms whose
    weight vanishes are dropped. The k-hat steps then start from those atoms only (no spectral
    rounding), which keeps a warm call cheap at large ``N``.

    Objects of different sizes (or ``n_universe`` larger than the objects) use the multi-simplex
    model (methods page *Permutation synchronization*, partial matchings): every node goes to
    exactly one of ``d`` universe slots, every slot takes at most one node per object; the vertices
    are partial permutations ``X_ij = X_i X_j^T`` and the input blocks must be
    sub-doubly-stochastic (non-negative, rows and columns summing to at most 1). With equal sizes
    ``n`` and ``d = n`` the blocks must be doubly stochastic and so is every output block.

    The observation graph is not split into components: when it is disconnected, the output
    still places every object in the one universe, and maps between objects of different
    components (``pairwise(i, j)``, ``block(i, j)``) rest on no observation. Check connectivity
    first (e.g. ``synchronize_permutations(..., disconnected="raise")``) when that matters.

    Parameters
    ----------
    pairwise : dict {(i, j): (n_i, n_j) soft matrix or assignment}
        Soft matches ``X_ij`` of node ``u`` of ``i`` with node ``v`` of ``j``; ``(j, i)`` is the
        transpose. Both given: their weighted average is used. Also an iterable of
        ``(i, j, X_ij)`` triples or a dense ``(N, N, n, n)`` array (see
        :func:`synchronize_permutations`); stacked blocks ``X`` (P, n, n) of ``pairs`` (P, 2)
        pass cheaply as ``dict(zip(map(tuple, pairs.tolist()), X))``.
    mask, weights : array_like or dict, optional
        Pairs to use and their non-negative weights, as in :func:`synchronize_permutations`.
    max_iter : int, default=20
        Frank-Wolfe iterations. ``0`` returns the initialization: the consistent configuration
        closest to the input (one atom of weight 1, ``n_iter=0``), not a projection; with
        ``init``, the re-fitted atoms of ``init``.
    n_universe : int, optional
        Universe size ``d >= max n_i``. Default: ``n`` for equal sizes, otherwise
        :func:`estimate_universe`'s rule (the eigengap of the degree-normalized soft block
        matrix; ``info["n_universe_rule"]``); with ``init``, the universe of ``init``.
    inner_sweeps : int, default=10
        Largest number of Gauss-Seidel Hungarian sweeps of one k-hat step.
    tol : float, default=1e-6
        Stop when the Frank-Wolfe gap is below ``tol * sum w_ij ||X_ij||^2``.
    fully_corrective : bool, default=False
        Re-optimize all atom weights on the simplex at every iteration (slower, fewer atoms).
    solver : {"auto", "dense", "matrix_free"}, default="auto"
        Eigensolver of the k-hat step: dense ``eigh`` when ``sum n_i <= 2000`` under ``"auto"``,
        else matrix-free block Krylov on the residual block operator (warm-started from the
        previous iteration's eigenvectors; the operator is one dense array when the observed
        pairs cover at least a quarter of the block matrix and ``N max n_i <= 8000``, a sparse
        matrix otherwise; on the residual at most 25 restarts, as the result is only a start
        for the sweeps).
    init : BirkhoffSyncResult, optional
        A previous result on the same number of objects, the same object sizes and the same
        universe size (any observed pairs): warm start, see above.
    rng : None, int or numpy.random.Generator
        Seeds the matrix-free eigensolver.

    Returns
    -------
    BirkhoffSyncResult
        The doubly-stochastic absolute maps (atoms and weights), the synchronized pairwise
        blocks and the objective history.

    Raises
    ------
    TypeError
        ``init`` is not a :class:`BirkhoffSyncResult`.
    ValueError
        Blocks that are not (sub-)doubly stochastic, a bad ``n_universe``, or an ``init`` with
        another number of objects, other sizes or another universe.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.synchronization import synchronize_doubly_stochastic
    >>> I, S = np.eye(3), np.eye(3)[[1, 0, 2]]
    >>> X = {(0, 1): 0.8 * I + 0.2 * S, (1, 2): I, (0, 2): 0.8 * I + 0.2 * S}
    >>> res = synchronize_doubly_stochastic(X, fully_corrective=True)
    >>> len(res.weights), np.round(res.weights, 3).tolist()
    (2, [0.8, 0.2])
    >>> bool(np.allclose(res.blocks[(0, 1)], X[(0, 1)]))
    True

    A warm start from that result converges at once:

    >>> X2 = {(0, 1): 0.7 * I + 0.3 * S, (1, 2): I, (0, 2): 0.7 * I + 0.3 * S}
    >>> res2 = synchronize_doubly_stochastic(X2, init=res)
    >>> res2.n_iter, np.round(res2.weights, 3).tolist()
    (0, [0.7, 0.3])
    """
    max_iter = check_int(max_iter, "max_iter", minimum=0, maximum=MAX_ITER)
    inner_sweeps = check_int(inner_sweeps, "inner_sweeps", minimum=0, maximum=MAX_ITER)
    tol = check_positive(tol, "tol")
    fully_corrective = check_bool(fully_corrective, "fully_corrective")
    check_choice(solver, "solver", ("auto", "dense", "matrix_free"))
    if init is not None and not isinstance(init, BirkhoffSyncResult):
        raise TypeError("`init` must be a BirkhoffSyncResult (a previous result of "
                        f"synchronize_doubly_stochastic) or None, got {type(init).__name__}")
    gen = as_generator(rng)
    stk = parse_pairwise(pairwise, mask=mask, weights=weights, soft=True)
    sizes = stk.sizes
    n_max = int(sizes.max())
    n_universe = check_universe(n_universe, sizes)
    if init is not None:
        _check_init(init, sizes, n_universe)
        if n_universe is None:
            n_universe = int(init.n_universe)
    full = bool(np.all(sizes == sizes[0])) and n_universe in (None, n_max)
    _check_soft_blocks(stk.soft, full)
    pairs, w, X = _merge_observations(stk)
    info: dict = {"fully_corrective": fully_corrective, "pairs": pairs}
    d = _choose_universe(n_universe, full, X, w, pairs, sizes, info)
    fw = _FrankWolfe(X, w, pairs, sizes, d, inner_sweeps=inner_sweeps, rng=gen, solver=solver)
    info["solver"] = fw.oracle.use
    start = start_w = None
    if init is not None:
        order = np.argsort(-np.asarray(init.weights), kind="stable")[:WARM_MAX_ATOMS]
        start, start_w = np.asarray(init.atoms)[order], np.asarray(init.weights)[order]
    info["warm_start"] = None if init is None else int(start.shape[0])
    atoms, alpha, Y, history, gaps, it, converged = fw.run(max_iter, tol, fully_corrective,
                                                           start, start_w)
    if not converged and max_iter > 0:
        warnings.warn(f"synchronize_doubly_stochastic stopped after max_iter={max_iter} "
                      f"iterations with Frank-Wolfe gap {gaps[-1]:.3g} > tol * ||X||^2",
                      ConvergenceWarning, stacklevel=2)
    best = int(np.argmax(alpha))
    blocks = {(int(i), int(j)): Y[q][: sizes[i], : sizes[j]]
              for q, (i, j) in enumerate(pairs.tolist())}
    info.update({"gap_history": np.asarray(gaps), "n_atoms": int(atoms.shape[0])})
    matching = _matching(atoms[best], sizes, d)
    return BirkhoffSyncResult(blocks=blocks, atoms=atoms, weights=alpha, matching=matching,
                              objective=history[-1], objective_history=np.asarray(history),
                              n_iter=it, converged=converged, info=info)


@dataclass(frozen=True)
class UniverseEstimate:
    """Universe size estimated from soft pairwise matches (:func:`estimate_universe`).

    Attributes
    ----------
    n_universe : int
        The estimate ``d`` (at least the largest object's size).
    rule : str
        How ``d`` was chosen, in words.
    eigenvalues : ndarray
        The leading eigenvalues of the degree-normalized soft block matrix, largest first.
    sizes : ndarray of int
        Object sizes read from the input.
    """

    n_universe: int
    rule: str
    eigenvalues: np.ndarray = field(repr=False)
    sizes: np.ndarray = field(repr=False)


def estimate_universe(pairwise, *, mask=None, weights=None, sizes=None) -> UniverseEstimate:
    """Universe size of objects of different sizes from their soft pairwise matches.

    The soft blocks (identity on the diagonal) form a block matrix whose degree-normalized
    version has, for consistent input, one eigenvalue 1 per universe node and 0 elsewhere; the
    estimate is the largest eigengap ``l_d - l_{d+1}`` with ``d`` at least the largest object
    (the leading ``2 n_max + 10`` eigenvalues first, more while the gap may lie further down),
    plus one when the next gap is at least ``SOFT_SPLIT_GAP`` (0.6) times it: a universe
    node kept by few objects has a lower eigenvalue than the others, between them and the
    noise, and splits one gap into two comparable ones. This is the rule
    :func:`synchronize_doubly_stochastic` uses when ``n_universe`` is not given; alone it costs
    one dense symmetric eigenproblem of size ``sum n_i``.

    Soft matches keep the pairwise solver's uncertainty, which rounded maps lose: fed the soft
    solutions of RRWM on 400 collections of 8 graphs drawn from a universe of 20 nodes (each
    node kept with probability ``U(0.6, 1)``, deformation 0.05;
    ``benchmarks/universe_estimate.py``), the largest eigengap alone was right on 93.2 %
    against 92.0 % for the same rule on the rounded maps (:func:`synchronize_permutations`),
    and with the split-gap step on 94.0 % (on 600 other collections: 91.0 % -> 94.2 %).

    On an incomplete view graph (some pair of objects unobserved; three objects or more) a
    universe node's eigenvalues are those of the normalized adjacency of the objects holding
    it, spread below 1, and the eigengap overestimates (eight 6-node objects matched exactly in
    a chain gave 24). There the blocks are rounded (an entry above 1/2 is a match) and the
    universe is the one :func:`synchronize_permutations` finds for those maps, with its rule
    for incomplete view graphs; ``rule`` says which rule was used.

    Parameters
    ----------
    pairwise : dict {(i, j): (n_i, n_j) array}
        Non-negative soft matches, rows and columns summing to at most 1 (e.g. Sinkhorn
        output restricted to real nodes, or 0/1 partial permutations); any input
        :func:`synchronize_doubly_stochastic` takes.
    mask, weights : optional
        Pairs to use and their weights, as in :func:`synchronize_permutations`.
    sizes : array_like of int, optional
        Object sizes, for objects that appear in no pair.

    Returns
    -------
    UniverseEstimate

    Raises
    ------
    ValueError
        Negative blocks, rows or columns summing to more than 1, no observed pair, bad sizes.

    Examples
    --------
    >>> import numpy as np
    >>> # three objects of 2, 2 and 3 nodes drawn from a universe of 3 nodes {a, b, c}:
    >>> # object 0 = (a, b), object 1 = (b, c), object 2 = (a, b, c)
    >>> X01 = np.array([[0.0, 0.0], [1.0, 0.0]])                     # b -> b
    >>> X02 = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])           # a -> a, b -> b
    >>> X12 = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])           # b -> b, c -> c
    >>> est = estimate_universe({(0, 1): X01, (0, 2): X02, (1, 2): X12})
    >>> est.n_universe, est.sizes.tolist()
    (3, [2, 2, 3])
    """
    stk = parse_pairwise(pairwise, mask=mask, weights=weights, sizes=sizes, soft=True)
    _check_soft_blocks(stk.soft, False)
    pairs, w, X = _merge_observations(stk)
    d, rule, vals = _estimate_universe_soft(X, w, pairs, stk.sizes)
    return UniverseEstimate(n_universe=int(d), rule=rule, eigenvalues=np.asarray(vals),
                            sizes=np.asarray(stk.sizes).copy())


def _check_init(init: BirkhoffSyncResult, sizes: np.ndarray, n_universe) -> None:
    """``init`` must describe the same objects (count, sizes) in the same universe."""
    N = sizes.size
    if init.n_objects != N:
        raise ValueError(f"`init` must be a result on the same objects: it has {init.n_objects} "
                         f"objects, `pairwise` has {N}")
    if not np.array_equal(init.sizes, sizes):
        g = int(np.flatnonzero(init.sizes != sizes)[0])
        raise ValueError(f"`init` must be a result on objects of the same sizes: object {g} has "
                         f"{int(init.sizes[g])} nodes in `init`, {int(sizes[g])} in `pairwise`")
    if n_universe is not None and n_universe != init.n_universe:
        raise ValueError(f"`init` must be a result in the same universe: its n_universe is "
                         f"{init.n_universe}, got n_universe={n_universe}")
    atoms, wts = np.asarray(init.atoms), np.asarray(init.weights)
    if (atoms.ndim != 3 or atoms.shape[:2] != (wts.size, N) or atoms.shape[2] != sizes.max()
            or wts.size == 0):
        raise ValueError(f"`init` has inconsistent atoms {atoms.shape} and weights {wts.shape} "
                         f"for {N} objects of at most {int(sizes.max())} nodes")


def _check_soft_blocks(Xq: np.ndarray, full: bool) -> None:
    """Doubly stochastic blocks (``full``) or sub-doubly stochastic ones (partial model)."""
    if Xq.min() < -1e-12:
        raise ValueError("`pairwise` blocks must be non-negative (doubly stochastic), got a "
                         f"minimum of {Xq.min():.3g}")
    if full:
        dev = max(np.abs(Xq.sum(1) - 1).max(), np.abs(Xq.sum(2) - 1).max())
        if dev > 1e-6:
            raise ValueError("`pairwise` blocks must be doubly stochastic (rows and columns "
                             f"summing to 1; use Sinkhorn first), got a deviation of {dev:.3g}")
    else:
        over = max(Xq.sum(1).max() - 1, Xq.sum(2).max() - 1)
        if over > 1e-6:
            raise ValueError("`pairwise` blocks must be sub-doubly stochastic for objects of "
                             "different sizes (rows and columns summing to at most 1), got a "
                             f"sum of {1 + over:.6g}")


def _merge_observations(stk):
    """One block per observed pair: duplicates averaged (weights were split by the parser)."""
    N = stk.n_objects
    n_max = int(stk.sizes.max())
    key = stk.pairs[:, 0] * N + stk.pairs[:, 1]
    uniq, inverse = np.unique(key, return_inverse=True)
    pairs = np.column_stack([uniq // N, uniq % N])
    w = np.bincount(inverse, weights=stk.weights, minlength=uniq.size)
    if uniq.size == key.size:                             # no duplicates: a permutation
        X = np.empty((uniq.size, n_max, n_max))
        X[inverse] = stk.soft
        return pairs, w, X
    X = np.zeros((uniq.size, n_max, n_max))
    np.add.at(X, inverse, stk.soft * stk.weights[:, None, None])
    X /= np.maximum(w, 1e-300)[:, None, None]
    return pairs, w, X


def _choose_universe(n_universe, full, X, w, pairs, sizes, info) -> int:
    if n_universe is not None:
        d = n_universe
        info["n_universe_rule"] = "given"
    elif full:
        d = int(sizes.max())
        info["n_universe_rule"] = "equal sizes: d = number of nodes"
    else:
        d, rule, vals = _estimate_universe_soft(X, w, pairs, sizes)
        info["n_universe_rule"] = rule
        info["eigenvalues"] = vals
    info["n_universe"] = d
    return d


def _estimate_universe_soft(X, w, pairs, sizes):
    """Eigengap of the degree-normalized soft block matrix (identity diagonal blocks of the
    smallest positive pair weight, as in the permutation synchronization's block matrix, so
    that scaling every weight changes nothing); on an incomplete view graph, the universe of
    the rounded maps (:func:`_view_graph_universe_soft`)."""
    n_max = int(sizes.max())
    off = np.concatenate([[0], np.cumsum(sizes)])
    M = int(off[-1])
    if M > MAX_DENSE_UNIVERSE_NODES:        # a dense M x M eigenproblem (2 * 10**5: 298 GiB)
        raise ValueError(f"estimating the universe of {M} nodes in all needs a dense {M} x {M} "
                         f"eigenproblem (at most {MAX_DENSE_UNIVERSE_NODES} nodes); pass "
                         "`n_universe`")
    from ._permutations import _complete_view

    if not _complete_view(pairs, w, sizes.size):
        return _view_graph_universe_soft(X, w, pairs, sizes)
    w = spec.relative_weights(np.asarray(w, dtype=float))
    B = spec.identity_weight(w) * np.eye(M)
    for q, (i, j) in enumerate(pairs):
        blk = w[q] * X[q][: sizes[i], : sizes[j]]
        B[off[i]:off[i + 1], off[j]:off[j + 1]] += blk
        B[off[j]:off[j + 1], off[i]:off[i + 1]] += blk.T
    deg = B.sum(1)
    dinv = 1.0 / np.sqrt(np.maximum(deg, 1e-300))
    B = dinv[:, None] * B * dinv[None, :]
    k = min(M, 2 * n_max + 10)
    while True:
        vals = sla.eigh(B, eigvals_only=True, subset_by_index=[M - k, M - 1])[::-1]
        d, rule = spec.estimate_universe(vals, n_max, split=SOFT_SPLIT_GAP)
        if not (d >= vals.size - 1 or vals[-1] > 0.5 * vals[0]) or k >= M:
            return d, rule, vals
        k = min(M, 2 * k)


def _view_graph_universe_soft(X, w, pairs, sizes):
    """Universe size of soft matches observed on an incomplete view graph.

    There a universe node's eigenvalues are those of the normalized adjacency of the objects
    holding it, spread below 1, and the eigengap lies far too low: eight 6-node objects matched
    in a chain, exactly, gave 24. The soft blocks are rounded (an entry above 1/2 is the row's
    only one above 1/2 in its column too, so the maps are injective) and
    :func:`~transync.synchronization.synchronize_permutations` estimates their universe with
    its rule for incomplete view graphs."""
    from ._permutations import synchronize_permutations

    maps = {}
    for q, (i, j) in enumerate(pairs.tolist()):
        blk = X[q][: sizes[i], : sizes[j]]
        maps[(i, j)] = (np.where(blk.max(1) > 0.5, blk.argmax(1), -1) if blk.size
                        else np.full(int(sizes[i]), -1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        res = synchronize_permutations(
            maps, weights={key: float(wq) for key, wq in zip(maps, w)}, sizes=sizes,
            disconnected="separate")
    rule = ("incomplete view graph: universe of the maps rounded at 1/2, by "
            f"synchronize_permutations ({res.info.get('n_universe_rule', 'equal sizes')})")
    return int(res.n_universe), rule, np.asarray(res.info.get("eigenvalues", np.empty(0)))


class _FrankWolfe:
    """Conditional gradient with column generation on the consistent configurations (§4.2).

    The active atoms are held as stacked maps ``(K, P, n_max)``; the Gram matrix
    ``A_kl = <S_k, S_l>_w`` and ``b_k = <X, S_k>_w`` of the weight problem are updated one row
    per new atom, so a weight step costs ``O(K^2)`` (pairwise) or ``O(K^3)`` (fully
    corrective), independent of the number of pairs.
    """

    def __init__(self, X, w, pairs, sizes, d, *, inner_sweeps, rng, solver):
        self.X, self.w, self.pairs, self.sizes, self.d = X, w, pairs, sizes, d
        self.P, self.n = X.shape[0], X.shape[1]
        self.oracle = _Oracle(pairs, sizes, d, sweeps=inner_sweeps, rng=rng, solver=solver)

    def objective(self, Y) -> float:
        return 0.5 * float((self.w * ((self.X - Y) ** 2).sum((1, 2))).sum())

    def blocks(self, maps, alpha) -> np.ndarray:
        return _blocks_of_maps(maps, alpha, self.P, self.n)

    def gram(self, maps_new, maps_all):
        """``(<S_new, S_k>_w for k, <X, S_new>_w)`` for ``maps_new`` (m, P, n) against
        ``maps_all`` (K, P, n)."""
        same = (maps_new[:, None] == maps_all[None]) & (maps_new[:, None] >= 0)
        A = same.sum(3) @ self.w                                          # (m, K)
        b = np.array([(_masked_take(self.X, m).sum(1) * self.w).sum() for m in maps_new])
        return A, b

    def run(self, max_iter, tol, fully_corrective, start=None, start_weights=None):
        X, w = self.X, self.w
        norm_x = float((w * (X ** 2).sum((1, 2))).sum())
        if start is None:
            lab0 = self.oracle(X, w)[0][0]
            labs = lab0[None]
            alpha = np.array([1.0])
        else:
            labs = np.stack([_canonical(a, self.d) for a in start])
            _, keep = np.unique(labs.reshape(labs.shape[0], -1), axis=0, return_index=True)
            keep = np.sort(keep)                          # duplicates merged (heaviest first)
            labs = labs[keep]
            alpha = np.full(keep.size, 1.0 / keep.size)
            if start_weights is not None:
                a0 = np.asarray(start_weights, dtype=float)[keep]
                if a0.sum() > 0:
                    alpha = a0 / a0.sum()
        maps = _maps_of(labs, self.pairs, self.d)                         # (K, P, n)
        A, b = self.gram(maps, maps)
        if start is not None and labs.shape[0] > 1:
            alpha = _reoptimize(alpha, A, b)
        labs, maps, alpha, A, b = _drop(labs, maps, alpha, A, b)
        Y = self.blocks(maps, alpha)
        history, gaps = [self.objective(Y)], []
        converged = False
        it = 0
        for it in range(1, max_iter + 1):
            G = X - Y
            heavy = np.argsort(-alpha, kind="stable")[: 8 if fully_corrective else 1]
            starts = list(labs[heavy])
            found = self.oracle(G, w, starts, spectral=it == 1 and start is None,
                                max_restarts=RESIDUAL_MAX_RESTARTS)
            lab = found[0][0]
            maps_hat = _maps_of(lab, self.pairs, self.d)
            S_hat = self.blocks(maps_hat[None], [1.0])
            D = S_hat - Y
            gap = float((w * (G * D).sum((1, 2))).sum())
            gaps.append(gap)
            if gap <= tol * max(norm_x, 1e-300):
                converged = True
                it -= 1
                break
            # fully corrective: every improving candidate vertex joins the active set
            extra = [c for c, _ in found[1:]] if fully_corrective else []
            h = None
            for c_lab in [lab] + extra:
                k = np.flatnonzero((labs == c_lab).all((1, 2)))
                if k.size:
                    h = int(k[0]) if h is None else h
                    continue
                c_maps = maps_hat if c_lab is lab else _maps_of(c_lab, self.pairs, self.d)
                a_new, b_new = self.gram(c_maps[None], maps)
                if c_lab is not lab and b_new[0] - a_new[0] @ alpha <= alpha @ (b - A @ alpha):
                    continue                              # not an improving direction
                aa = float((c_maps >= 0).sum(1) @ w)
                A = np.block([[A, a_new.T], [a_new, np.array([[aa]])]])
                b = np.append(b, b_new)
                labs = np.concatenate([labs, c_lab[None]])
                maps = np.concatenate([maps, c_maps[None]])
                alpha = np.append(alpha, 0.0)
                h = alpha.size - 1 if h is None else h
            if fully_corrective:
                alpha = _reoptimize(_fw_step(alpha, h, A, b), A, b)
            else:
                alpha = _pairwise_step(alpha, h, A, b)
            labs, maps, alpha, A, b = _drop(labs, maps, alpha, A, b)
            Y = self.blocks(maps, alpha)
            history.append(self.objective(Y))
        return labs, alpha, Y, history, gaps, it, converged


def _fw_step(alpha, h, A, b):
    """Frank-Wolfe step toward atom ``h`` with exact line search on ``1/2 a^T A a - b^T a``."""
    g = b - A @ alpha                                     # <G, S_k>: residual . atom k
    gap = g[h] - g @ alpha
    dd = A[h, h] - 2 * (A[h] @ alpha) + alpha @ A @ alpha
    gamma = float(np.clip(gap / dd, 0.0, 1.0)) if dd > 0 else 0.0
    out = alpha * (1 - gamma)
    out[h] += gamma
    return out


def _pairwise_step(alpha, h, A, b):
    """Pairwise Frank-Wolfe step: weight moves from the active atom least aligned with the
    residual (the away atom) to atom ``h``, exact line search capped by the away weight; a plain
    Frank-Wolfe step when that one decreases the objective more."""
    g = b - A @ alpha
    active = np.flatnonzero(alpha > 0)
    a = int(active[np.argmin(g[active])])
    dd = A[h, h] + A[a, a] - 2 * A[h, a]
    cand = [_fw_step(alpha, h, A, b)]
    if a != h and dd > 0:
        gamma = float(np.clip((g[h] - g[a]) / dd, 0.0, alpha[a]))
        out = alpha.copy()
        out[h] += gamma
        out[a] -= gamma
        cand.append(out)

    def f(x):
        return 0.5 * x @ A @ x - b @ x

    return min(cand, key=f)


def _drop(labs, maps, alpha, A, b):
    """Atoms of vanishing weight removed, weights renormalized."""
    keep = alpha > _DROP
    if keep.all():
        return labs, maps, alpha / alpha.sum(), A, b
    return labs[keep], maps[keep], alpha[keep] / alpha[keep].sum(), A[np.ix_(keep, keep)], b[keep]


def _reoptimize(alpha, A, b):
    """Fully corrective step: all atom weights re-optimized on the simplex for
    ``1/2 a^T A a - b^T a`` (``A`` PSD, small), by a primal active-set method started from
    ``alpha`` (finite; equality-constrained KKT solves on the support, least squares when ``A``
    is singular); kept only when the objective does not increase."""
    K = alpha.size

    def f(a):
        return 0.5 * a @ A @ a - b @ a

    f_old = f(alpha)
    x = alpha.copy()
    scale = max(float(np.abs(A).max()), float(np.abs(b).max()), 1e-300)
    support = x > 0
    for _ in range(4 * K + 10):
        S = np.flatnonzero(support)
        m = S.size
        kkt = np.zeros((m + 1, m + 1))
        kkt[:m, :m] = A[np.ix_(S, S)]
        kkt[:m, m] = kkt[m, :m] = 1.0
        rhs = np.append(b[S], 1.0)
        try:
            sol = np.linalg.solve(kkt, rhs)
            if not np.allclose(kkt @ sol, rhs, rtol=1e-9, atol=1e-9 * scale):
                raise np.linalg.LinAlgError
        except np.linalg.LinAlgError:                     # singular: least squares
            sol = np.linalg.lstsq(kkt, rhs, rcond=None)[0]
        z = sol[:m]
        if z.min() < -1e-15:                              # blocked: walk to the boundary
            d = z - x[S]
            neg = d < 0
            t = np.min(-x[S][neg] / d[neg]) if neg.any() else 1.0
            t = min(max(t, 0.0), 1.0)
            x[S] = np.maximum(x[S] + t * d, 0.0)
            x /= x.sum()
            support = x > 1e-15
            continue
        x = np.zeros(K)
        x[S] = z
        x /= x.sum()
        g = A @ x - b
        mu = g[S].mean()
        out = np.flatnonzero(~support)
        if not out.size:
            break
        k = out[np.argmin(g[out])]
        if g[k] >= mu - 1e-12 * scale:                   # KKT: no atom outside improves
            break
        support[k] = True
    return x if f(x) <= f_old else alpha
