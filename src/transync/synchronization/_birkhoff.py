"""Synchronization over the Birkhoff polytope (ALGORITHMS.md §1.7, §4.1-4.2).

Soft pairwise matches ``X_ij`` (doubly stochastic) are projected onto the convex hull of the
*consistent configurations* ``S_k`` (block matrices ``S_k,ij = P_i^k P_j^kT`` of absolute
permutations ``P_i^k``):

.. math:: \\min_{\\alpha \\in \\Delta} \\tfrac12 \\sum_{(i,j) \\in \\Omega} w_{ij}
          \\| X_{ij} - \\textstyle\\sum_k \\alpha_k S_{k,ij} \\|_F^2 ,

by conditional gradient (Frank-Wolfe) with column generation: "solving for k-hat" is a
permutation synchronization on the residual (spectral start, then Gauss-Seidel Hungarian sweeps),
"solving for alpha" is the exact line search of the quadratic, optionally followed by a fully
corrective re-optimization of all weights on the simplex (projected gradient).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg as sla
from scipy.optimize import linear_sum_assignment

from .._validation import as_generator, check_array, check_choice, check_int, check_positive
from ..exceptions import ConvergenceWarning
from ..permutations import MultiMatching
from . import _spectral as spec
from ._pairwise_input import check_universe, parse_pairwise
from ._result import CarriesMatching

__all__ = ["BirkhoffSyncResult", "birkhoff_von_neumann", "synchronize_doubly_stochastic"]


def birkhoff_von_neumann(X, *, tol: float = 1e-9, max_terms: int | None = None):
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


@dataclass(frozen=True)
class BirkhoffSyncResult(CarriesMatching):
    """Result of :func:`synchronize_doubly_stochastic`.

    Attributes
    ----------
    blocks : dict {(i, j): (n_i, n_j) ndarray}
        Consistent soft blocks ``Y_ij = sum_k weights[k] X_i^k X_j^kT`` for the observed pairs
        (``i < j``). With equal sizes and ``n_universe = n`` every block is doubly stochastic;
        in the partial (multi-simplex) model rows and columns sum to at most 1.
        ``block(i, j)`` gives any pair.
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
        Objective after the initialization and after every iteration (non-increasing).
    n_iter : int
    converged : bool
        The Frank-Wolfe gap fell below ``tol * sum w_ij ||X_ij||^2``.
    info : dict
        ``"gap_history"``, ``"n_atoms"``, ``"fully_corrective"``, ``"solver"`` (eigensolver of
        the k-hat step), ``"n_universe"``, ``"n_universe_rule"``...
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
        ni, nj = int(sizes[i]), int(sizes[j])
        K = self.atoms.shape[0]
        # one inverse table per atom (slot -> node of object j; the extra last column is slot -1)
        inv = np.full((K, self.n_universe + 1), -1, dtype=np.int64)
        lab_j = self.atoms[:, j, :nj]
        k_idx, u = np.nonzero(lab_j >= 0)
        inv[k_idx, lab_j[k_idx, u]] = u
        a = np.take_along_axis(inv, self.atoms[:, i, :ni], axis=1)   # (K, n_i) maps i -> j
        Y = np.zeros((ni, nj))
        k_idx, r = np.nonzero(a >= 0)
        np.add.at(Y, (r, a[k_idx, r]), np.asarray(self.weights, dtype=float)[k_idx])
        return Y

    def pairwise(self, i: int, j: int) -> np.ndarray:
        """The MAP consistent assignment from object ``i`` to object ``j`` (``-1`` unmatched)."""
        return self.matching.pairwise(i, j)

    def to_matrix(self) -> np.ndarray:
        """The ``(sum n_g, sum n_g)`` soft block matrix ``sum_k weights[k] X^k X^kT`` (blocks
        ``Y_ij``, identity blocks on the diagonal); meant for small problems."""
        return sum(w * self.atom(k).to_matrix() for k, w in enumerate(self.weights))


def _matching(labels: np.ndarray, sizes: np.ndarray, d: int) -> MultiMatching:
    """The configuration held as padded ``labels`` (N, n_max) as a :class:`MultiMatching`."""
    return MultiMatching([labels[g, : sizes[g]] for g in range(sizes.size)], d)


def _pair_maps(labels: np.ndarray, pairs: np.ndarray, d: int) -> np.ndarray:
    """(Q, n_max) maps i -> j (``-1`` unmatched / padding) of padded ``labels`` (N, n_max).

    Padding entries are unplaced nodes of the :class:`MultiMatching`, so they map to -1."""
    return MultiMatching(list(labels), d).pairwise_array(pairs)


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


def _vertex_score(G, w, pairs, labels, d) -> float:
    return float((_masked_take(G, _pair_maps(labels, pairs, d)).sum(1) * w).sum())


def _lmo(G, w, pairs, sizes, d, sweeps, rng, solver):
    """argmax over consistent (partial) configurations of <G, X X^T> (solving for k-hat).

    Spectral start (top-``d`` eigenvectors of the weighted block matrix of ``G``; dense ``eigh``
    or matrix-free block Krylov), rounding into ``d`` slots, then at most ``sweeps``
    Gauss-Seidel sweeps ``X_g <- Hungarian(sum_j w_gj G_gj X_j)`` (rectangular ``n_g x d``: the
    exact block maximizer, so the score never decreases).
    """
    N = sizes.size
    n_max = int(sizes.max())
    off = np.concatenate([[0], np.cumsum(sizes)])
    M = int(off[-1])
    wG = G * w[:, None, None]
    # row index of (g, u) in the stacked order, M (a zero row) for padding
    pad_index = np.full((N, n_max), M, dtype=np.int64)
    for g in range(N):
        pad_index[g, : sizes[g]] = off[g] + np.arange(sizes[g])
    valid = pad_index < M

    def matmat(V):
        Vp = np.vstack([V, np.zeros((1, V.shape[1]))])[pad_index]       # (N, n_max, k)
        out = np.zeros_like(Vp)
        np.add.at(out, pairs[:, 0], np.einsum("quv,qvk->quk", wG, Vp[pairs[:, 1]]))
        np.add.at(out, pairs[:, 1], np.einsum("quv,quk->qvk", wG, Vp[pairs[:, 0]]))
        return out[valid]

    k = min(d, M)
    use = solver if solver != "auto" else ("dense" if M <= spec.DENSE_MAX else "matrix_free")
    if use == "dense":
        B = np.zeros((M, M))
        for q, (i, j) in enumerate(pairs):
            B[off[i]:off[i + 1], off[j]:off[j + 1]] += wG[q][: sizes[i], : sizes[j]]
            B[off[j]:off[j + 1], off[i]:off[i + 1]] += wG[q][: sizes[i], : sizes[j]].T
        _, U = sla.eigh(B, subset_by_index=[M - k, M - 1])
        U = U[:, ::-1]
    else:
        _, U, _, _, _ = spec.block_krylov_eigs(matmat, M, k, rng=rng)
    lab_list = spec.round_to_universe(U, sizes, d, refine=1)
    labels = np.full((N, n_max), -1, dtype=np.int64)
    for g, lab in enumerate(lab_list):
        labels[g, : sizes[g]] = lab
    best = _vertex_score(G, w, pairs, labels, d)
    for _ in range(sweeps):
        changed = False
        for g in range(N):
            n_g = int(sizes[g])
            S = np.zeros((n_g, d + 1))                    # column d collects padding (-1)
            for q in np.flatnonzero(pairs[:, 0] == g):
                j = pairs[q, 1]
                # (G_gj X_j)[u, a] = G_gj[u, v] for the node v of j in slot a
                np.add.at(S.T, labels[j], wG[q][:n_g].T)
            for q in np.flatnonzero(pairs[:, 1] == g):
                i = pairs[q, 0]
                np.add.at(S.T, labels[i], wG[q][:, :n_g])
            S = S[:, :d]
            cur = labels[g, :n_g]
            S[np.arange(n_g), cur] += 1e-12 * (np.abs(S).max() + 1.0)   # keep current on ties
            r, c = linear_sum_assignment(S, maximize=True)
            new = np.full(n_g, -1, dtype=np.int64)
            new[r] = c
            if not np.array_equal(new, cur):
                old = cur.copy()
                labels[g, :n_g] = new
                score = _vertex_score(G, w, pairs, labels, d)
                if score > best + 1e-12 * max(abs(best), 1.0):
                    best = score
                    changed = True
                else:
                    labels[g, :n_g] = old
        if not changed:
            break
    return _canonical(labels, d), best


def _project_simplex(v: np.ndarray) -> np.ndarray:
    u = np.sort(v)[::-1]
    css = np.cumsum(u) - 1
    k = np.arange(1, v.size + 1)
    rho = np.nonzero(u - css / k > 0)[0][-1]
    return np.maximum(v - css[rho] / (rho + 1), 0)


def _estimate_universe_soft(X, w, pairs, sizes, solver, rng):
    """Eigengap of the degree-normalized soft block matrix (identity diagonal blocks)."""
    n_max = int(sizes.max())
    off = np.concatenate([[0], np.cumsum(sizes)])
    M = int(off[-1])
    B = np.eye(M)
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
        d, rule = spec.estimate_universe(vals, n_max)
        if not (d >= vals.size - 1 or vals[-1] > 0.5 * vals[0]) or k >= M:
            return d, rule, vals
        k = min(M, 2 * k)


def synchronize_doubly_stochastic(pairwise, *, mask=None, weights=None, max_iter: int = 20,
                                  n_universe: int | None = None, inner_sweeps: int = 10,
                                  tol: float = 1e-6, fully_corrective: bool = False,
                                  solver: str = "auto", rng=None) -> BirkhoffSyncResult:
    """Project soft pairwise matches onto the hull of consistent permutation configurations.

    Conditional gradient of ALGORITHMS.md §4.2: start from the permutation synchronization of
    the input (one atom of weight 1); at every iteration the residual ``G = X - Y`` on the
    observed pairs defines a new vertex ``U`` maximizing ``<G, U U^T>`` ("solving for k-hat":
    spectral start, then at most ``inner_sweeps`` Gauss-Seidel sweeps
    ``P_i <- Hungarian(sum_j w_ij G_ij P_j)``); the step toward it is the exact minimizer of the
    quadratic on the segment ("solving for alpha"); with ``fully_corrective`` all atom weights are
    then re-optimized on the simplex by projected gradient. Stops when the Frank-Wolfe gap
    ``<G, U U^T - Y>`` is below ``tol * sum w_ij ||X_ij||^2``, or after ``max_iter`` iterations
    (``ConvergenceWarning``).

    Objects of different sizes (or ``n_universe`` larger than the objects) use the multi-simplex
    model of ALGORITHMS.md §5: every node goes to exactly one of ``d`` universe slots, every slot
    takes at most one node per object; the vertices are partial permutations
    ``X_ij = X_i X_j^T`` and the input blocks must be sub-doubly-stochastic (non-negative, rows
    and columns summing to at most 1). With equal sizes ``n`` and ``d = n`` the blocks must be
    doubly stochastic and so is every output block.

    The observation graph is not split into components: when it is disconnected, the output
    still places every object in the one universe, and maps between objects of different
    components (``pairwise(i, j)``, ``block(i, j)``) rest on no observation. Check connectivity
    first (e.g. ``synchronize_permutations(..., disconnected="raise")``) when that matters.

    Parameters
    ----------
    pairwise : dict {(i, j): (n_i, n_j) soft matrix or assignment}
        Soft matches ``X_ij`` of node ``u`` of ``i`` with node ``v`` of ``j``; ``(j, i)`` is the
        transpose. Both given: their weighted average is used.
    mask, weights : see :func:`synchronize_permutations`.
    max_iter : int, default=20
        Frank-Wolfe iterations. ``0`` returns the initialization: the consistent configuration
        closest to the input (one atom of weight 1, ``n_iter=0``), not a projection.
    n_universe : int, optional
        Universe size ``d >= max n_i``. Default: ``n`` for equal sizes, otherwise the eigengap of
        the degree-normalized soft block matrix (``info["n_universe_rule"]``).
    inner_sweeps : int, default=10
    tol : float, default=1e-6
    fully_corrective : bool, default=False
    solver : {"auto", "dense", "matrix_free"}, default="auto"
        Eigensolver of the k-hat step: dense ``eigh`` when ``sum n_i <= 2000`` under ``"auto"``,
        else matrix-free block Krylov on the residual block operator.
    rng : None, int or numpy.random.Generator

    Returns
    -------
    BirkhoffSyncResult

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
    """
    max_iter = check_int(max_iter, "max_iter", minimum=0)
    inner_sweeps = check_int(inner_sweeps, "inner_sweeps", minimum=0)
    tol = check_positive(tol, "tol")
    check_choice(solver, "solver", ("auto", "dense", "matrix_free"))
    gen = as_generator(rng)
    stk = parse_pairwise(pairwise, mask=mask, weights=weights, soft=True)
    sizes = stk.sizes
    n_max = int(sizes.max())
    n_universe = check_universe(n_universe, sizes)
    full = bool(np.all(sizes == sizes[0])) and n_universe in (None, n_max)
    _check_soft_blocks(stk.soft, full)
    pairs, w, X = _merge_observations(stk)
    info: dict = {"fully_corrective": fully_corrective, "pairs": pairs}
    d = _choose_universe(n_universe, full, X, w, pairs, sizes, solver, gen, info)
    M = int(sizes.sum())
    info["solver"] = solver if solver != "auto" else (
        "dense" if M <= spec.DENSE_MAX else "matrix_free")
    fw = _FrankWolfe(X, w, pairs, sizes, d, inner_sweeps=inner_sweeps, rng=gen, solver=solver)
    atoms, alpha, Y, history, gaps, it, converged = fw.run(max_iter, tol, fully_corrective)
    if not converged and max_iter > 0:
        warnings.warn(f"synchronize_doubly_stochastic stopped after max_iter={max_iter} "
                      f"iterations with Frank-Wolfe gap {gaps[-1]:.3g} > tol * ||X||^2",
                      ConvergenceWarning, stacklevel=2)
    atoms_arr = np.asarray(atoms, dtype=np.int64)
    best = int(np.argmax(alpha))
    blocks = {(int(i), int(j)): Y[q][: sizes[i], : sizes[j]].copy()
              for q, (i, j) in enumerate(pairs.tolist())}
    info.update({"gap_history": np.asarray(gaps), "n_atoms": len(atoms)})
    matching = _matching(atoms_arr[best], sizes, d)
    return BirkhoffSyncResult(blocks=blocks, atoms=atoms_arr, weights=alpha, matching=matching,
                              objective=history[-1], objective_history=np.asarray(history),
                              n_iter=it, converged=converged, info=info)


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
    X = np.zeros((uniq.size, n_max, n_max))
    np.add.at(X, inverse, stk.soft * stk.weights[:, None, None])
    X /= np.maximum(w, 1e-300)[:, None, None]
    return pairs, w, X


def _choose_universe(n_universe, full, X, w, pairs, sizes, solver, gen, info) -> int:
    if n_universe is not None:
        d = n_universe
        info["n_universe_rule"] = "given"
    elif full:
        d = int(sizes.max())
        info["n_universe_rule"] = "equal sizes: d = number of nodes"
    else:
        d, rule, vals = _estimate_universe_soft(X, w, pairs, sizes, solver, gen)
        info["n_universe_rule"] = rule
        info["eigenvalues"] = vals
    info["n_universe"] = d
    return d


class _FrankWolfe:
    """Conditional gradient with column generation on the consistent configurations (§4.2)."""

    def __init__(self, X, w, pairs, sizes, d, *, inner_sweeps, rng, solver):
        self.X, self.w, self.pairs, self.sizes, self.d = X, w, pairs, sizes, d
        self.inner_sweeps, self.rng, self.solver = inner_sweeps, rng, solver
        self.qi = np.arange(pairs.shape[0])[:, None]
        self.ui = np.arange(X.shape[1])[None, :]

    def objective(self, Y) -> float:
        return 0.5 * float((self.w * ((self.X - Y) ** 2).sum((1, 2))).sum())

    def lmo(self, G):
        lab, _ = _lmo(G, self.w, self.pairs, self.sizes, self.d, self.inner_sweeps, self.rng,
                      self.solver)
        return lab

    def add_maps(self, Y, maps, weight=1.0):
        ok = maps >= 0
        Y[np.broadcast_to(self.qi, maps.shape)[ok], np.broadcast_to(self.ui, maps.shape)[ok],
          maps[ok]] += weight
        return Y

    def run(self, max_iter, tol, fully_corrective):
        X, w = self.X, self.w
        norm_x = float((w * (X ** 2).sum((1, 2))).sum())
        lab0 = self.lmo(X)
        atoms, maps_list = [lab0], [_pair_maps(lab0, self.pairs, self.d)]
        alpha = np.array([1.0])
        Y = self.add_maps(np.zeros_like(X), maps_list[0])
        history, gaps = [self.objective(Y)], []
        converged = False
        it = 0
        for it in range(1, max_iter + 1):
            G = X - Y
            lab = self.lmo(G)
            maps_hat = _pair_maps(lab, self.pairs, self.d)
            D = self.add_maps(np.zeros_like(X), maps_hat) - Y
            gap = float((w * (G * D).sum((1, 2))).sum())
            gaps.append(gap)
            if gap <= tol * max(norm_x, 1e-300):
                converged = True
                it -= 1
                break
            dd = float((w * (D ** 2).sum((1, 2))).sum())
            gamma = float(np.clip(gap / dd, 0.0, 1.0)) if dd > 0 else 0.0
            alpha = alpha * (1 - gamma)
            found = next((k for k, a in enumerate(atoms) if np.array_equal(a, lab)), None)
            if found is None:
                atoms.append(lab)
                maps_list.append(maps_hat)
                alpha = np.append(alpha, gamma)
            else:
                alpha[found] += gamma
            if fully_corrective and len(atoms) > 1:
                alpha = self.reoptimize(alpha, maps_list)
            keep = alpha > 1e-14
            atoms = [a for a, k in zip(atoms, keep) if k]
            maps_list = [m for m, k in zip(maps_list, keep) if k]
            alpha = alpha[keep] / alpha[keep].sum()
            Y = np.zeros_like(X)
            for a, m in zip(alpha, maps_list):
                self.add_maps(Y, m, a)
            history.append(self.objective(Y))
        return atoms, alpha, Y, history, gaps, it, converged

    def reoptimize(self, alpha, maps_list):
        """Fully corrective step: all atom weights re-optimized on the simplex (projected
        gradient); kept only when the objective does not increase."""
        X, w = self.X, self.w
        K = len(maps_list)
        A = np.empty((K, K))
        b = np.empty(K)
        for k in range(K):
            b[k] = float((w * _masked_take(X, maps_list[k]).sum(1)).sum())
            for m in range(k, K):
                same = (maps_list[k] == maps_list[m]) & (maps_list[k] >= 0)
                A[k, m] = A[m, k] = float((w * same.sum(1)).sum())
        L = max(np.linalg.eigvalsh(A)[-1], 1e-12)
        f_old = 0.5 * alpha @ A @ alpha - b @ alpha
        a_new = alpha.copy()
        for _ in range(500):
            a_next = _project_simplex(a_new - (A @ a_new - b) / L)
            if np.abs(a_next - a_new).max() < 1e-12:
                a_new = a_next
                break
            a_new = a_next
        return a_new if 0.5 * a_new @ A @ a_new - b @ a_new <= f_old else alpha
