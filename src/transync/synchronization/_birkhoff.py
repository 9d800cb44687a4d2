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

from .._validation import as_generator, check_array, check_int, check_positive
from ..exceptions import ConvergenceWarning
from . import _spectral as spec
from ._pairwise_input import parse_pairwise

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
        Entries of the remainder at or below ``tol`` count as zero.
    max_terms : int, optional
        Default ``n^2 - 2n + 2`` (at least 1) plus ``n`` for round-off.

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
    limit = max_terms if max_terms is not None else max(n * n - 2 * n + 2, 1) + n
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
    return np.asarray(weights), np.asarray(perms, dtype=np.int64).reshape(-1, n)


@dataclass(frozen=True)
class BirkhoffSyncResult:
    """Result of :func:`synchronize_doubly_stochastic`.

    Attributes
    ----------
    blocks : dict {(i, j): (n, n) ndarray}
        Consistent soft blocks ``Y_ij = sum_k weights[k] P_i^k P_j^kT`` for the observed pairs
        (``i < j``); every block is doubly stochastic. ``block(i, j)`` gives any pair.
    atoms : (K, N, n) int ndarray
        Consistent configurations as universe labels: ``atoms[k, g, u]`` is the slot of node ``u``
        of object ``g`` (canonical gauge: ``atoms[k, 0] = arange(n)``).
    weights : (K,) ndarray
        Convex weights of the atoms (sum 1).
    labels : tuple of ndarray
        The MAP configuration (atom with the largest weight): a cycle-consistent multi-matching.
    objective : float
        Final ``1/2 sum_{(i,j) observed} w_ij ||X_ij - Y_ij||_F^2`` (pairs counted once).
    objective_history : ndarray
        Objective after the initialization and after every iteration (non-increasing).
    n_iter : int
    converged : bool
        The Frank-Wolfe gap fell below ``tol * sum w_ij ||X_ij||^2``.
    info : dict
        ``"gap_history"``, ``"n_atoms"``, ``"fully_corrective"``...
    """

    blocks: Mapping[tuple[int, int], np.ndarray]
    atoms: np.ndarray
    weights: np.ndarray
    labels: tuple[np.ndarray, ...]
    objective: float
    objective_history: np.ndarray
    n_iter: int
    converged: bool
    info: Mapping[str, Any] = field(default_factory=dict)

    @property
    def n_universe(self) -> int:
        return int(self.atoms.shape[2])

    def block(self, i: int, j: int) -> np.ndarray:
        """Soft consistent block ``Y_ij`` for any pair of objects (identity when ``i == j``)."""
        N, n = self.atoms.shape[1], self.atoms.shape[2]
        for name, g in (("i", i), ("j", j)):
            if not 0 <= int(g) < N:
                raise ValueError(f"`{name}` must be an object index in [0, {N}), got {g}")
        Y = np.zeros((n, n))
        u = np.arange(n)
        for w, lab in zip(self.weights, self.atoms):
            Y[u, np.argsort(lab[j])[lab[i]]] += w
        return Y

    def pairwise(self, i: int, j: int) -> np.ndarray:
        """The MAP consistent assignment from object ``i`` to object ``j``."""
        return np.argsort(self.labels[j])[self.labels[i]]


def _pair_maps(labels: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """(Q, n) assignments i -> j of the configuration ``labels`` (N, n)."""
    inv = np.argsort(labels, axis=1)
    return np.take_along_axis(inv[pairs[:, 1]], labels[pairs[:, 0]], axis=1)


def _canonical(labels: np.ndarray) -> np.ndarray:
    return np.argsort(labels[0])[labels]


def _vertex_score(G: np.ndarray, w: np.ndarray, pairs: np.ndarray, labels: np.ndarray) -> float:
    maps = _pair_maps(labels, pairs)
    vals = np.take_along_axis(G, maps[:, :, None], axis=2)[:, :, 0]
    return float((vals.sum(1) * w).sum())


def _lmo(G, w, pairs, N, n, sweeps, rng):
    """argmax_U <G, U U^T>: spectral start + Gauss-Seidel Hungarian sweeps (solving for k-hat)."""
    M = N * n
    wG = G * w[:, None, None]

    def matmat(V):
        Vb = V.reshape(N, n, -1)
        out = np.zeros_like(Vb)
        np.add.at(out, pairs[:, 0], np.einsum("quv,qvk->quk", wG, Vb[pairs[:, 1]]))
        np.add.at(out, pairs[:, 1], np.einsum("quv,quk->qvk", wG, Vb[pairs[:, 0]]))
        return out.reshape(M, -1)

    if M <= spec.DENSE_MAX:
        B = np.zeros((M, M))
        for q, (i, j) in enumerate(pairs):
            B[i * n:(i + 1) * n, j * n:(j + 1) * n] += wG[q]
            B[j * n:(j + 1) * n, i * n:(i + 1) * n] += wG[q].T
        _, U = sla.eigh(B, subset_by_index=[M - n, M - 1])
        U = U[:, ::-1]
    else:
        _, U, _, _, _ = spec.block_krylov_eigs(matmat, M, n, rng=rng)
    labels = np.asarray(spec.round_to_universe(U, np.full(N, n), n, refine=1))
    best = _vertex_score(G, w, pairs, labels)
    # neighbour lists for sweeps
    for _ in range(sweeps):
        changed = False
        for g in range(N):
            S = np.zeros((n, n))
            inv = np.argsort(labels, axis=1)
            for q in np.flatnonzero(pairs[:, 0] == g):
                j = pairs[q, 1]
                S += wG[q][:, inv[j]]              # (G_gj P_j)[u, a] = G_gj[u, inv_j[a]]
            for q in np.flatnonzero(pairs[:, 1] == g):
                i = pairs[q, 0]
                S += wG[q].T[:, inv[i]]
            _, c = linear_sum_assignment(S, maximize=True)
            if not np.array_equal(c, labels[g]):
                old = labels[g].copy()
                labels[g] = c
                new = _vertex_score(G, w, pairs, labels)
                if new > best + 1e-12:
                    best = new
                    changed = True
                else:
                    labels[g] = old
        if not changed:
            break
    return _canonical(labels), best


def _project_simplex(v: np.ndarray) -> np.ndarray:
    u = np.sort(v)[::-1]
    css = np.cumsum(u) - 1
    k = np.arange(1, v.size + 1)
    rho = np.nonzero(u - css / k > 0)[0][-1]
    return np.maximum(v - css[rho] / (rho + 1), 0)


def synchronize_doubly_stochastic(pairwise, *, mask=None, weights=None, max_iter: int = 20,
                                  inner_sweeps: int = 10, tol: float = 1e-6,
                                  fully_corrective: bool = False, rng=None) -> BirkhoffSyncResult:
    """Project soft pairwise matches onto the hull of consistent permutation configurations.

    Conditional gradient of ALGORITHMS.md §4.2: start from the permutation synchronization of
    the input (one atom of weight 1); at every iteration the residual ``G = X - Y`` on the
    observed pairs defines a new vertex ``U`` maximizing ``<G, U U^T>`` ("solving for k-hat":
    spectral start, then at most ``inner_sweeps`` Gauss-Seidel sweeps
    ``P_i <- Hungarian(sum_j w_ij G_ij P_j)``); the step toward it is the exact minimizer of the
    quadratic on the segment ("solving for alpha"); with ``fully_corrective`` all atom weights are
    then re-optimized on the simplex by projected gradient. Stops when the Frank-Wolfe gap
    ``<G, U U^T - Y>`` is below ``tol * sum w_ij ||X_ij||^2``, or after ``max_iter`` iterations
    (``ConvergenceWarning``). Objects must all have ``n`` nodes (pad with dummy nodes otherwise).

    Parameters
    ----------
    pairwise : dict {(i, j): (n, n) doubly-stochastic matrix or assignment}
        Soft matches ``X_ij`` of node ``u`` of ``i`` with node ``v`` of ``j``; ``(j, i)`` is the
        transpose. Both given: their weighted average is used.
    mask, weights : see :func:`synchronize_permutations`.
    max_iter : int, default=20
    inner_sweeps : int, default=10
    tol : float, default=1e-6
    fully_corrective : bool, default=False
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
    gen = as_generator(rng)
    stk = parse_pairwise(pairwise, mask=mask, weights=weights, soft=True)
    sizes = stk.sizes
    if not np.all(sizes == sizes[0]):
        raise ValueError("`pairwise`: synchronize_doubly_stochastic needs objects of equal size "
                         f"(pad with dummy nodes), got sizes {sorted(set(sizes.tolist()))}")
    N, n = stk.n_objects, int(sizes[0])
    Xq = stk.soft
    if Xq.min() < -1e-12:
        raise ValueError("`pairwise` blocks must be non-negative (doubly stochastic)")
    dev = max(np.abs(Xq.sum(1) - 1).max(), np.abs(Xq.sum(2) - 1).max())
    if dev > 1e-6:
        raise ValueError("`pairwise` blocks must be doubly stochastic (rows and columns summing "
                         f"to 1; use Sinkhorn first), got a deviation of {dev:.3g}")
    # merge duplicate observations of a pair (weights were split by parse_pairwise)
    key = stk.pairs[:, 0] * N + stk.pairs[:, 1]
    uniq, inverse = np.unique(key, return_inverse=True)
    pairs = np.column_stack([uniq // N, uniq % N])
    w = np.bincount(inverse, weights=stk.weights, minlength=uniq.size)
    X = np.zeros((uniq.size, n, n))
    np.add.at(X, inverse, Xq * stk.weights[:, None, None])
    X /= np.maximum(w, 1e-300)[:, None, None]
    norm_x = float((w * (X ** 2).sum((1, 2))).sum())

    def objective(Y):
        return 0.5 * float((w * ((X - Y) ** 2).sum((1, 2))).sum())

    def S_of(labels):
        maps = _pair_maps(labels, pairs)
        S = np.zeros_like(X)
        q, u = np.indices(maps.shape)
        S[q, u, maps] = 1.0
        return S, maps

    lab0, _ = _lmo(X, w, pairs, N, n, inner_sweeps, gen)
    atoms = [lab0]
    maps_list = [S_of(lab0)[1]]
    alpha = np.array([1.0])
    Y = S_of(lab0)[0]
    history = [objective(Y)]
    gaps: list[float] = []
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        G = X - Y
        lab, _ = _lmo(G, w, pairs, N, n, inner_sweeps, gen)
        S_hat, maps_hat = S_of(lab)
        D = S_hat - Y
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
            K = len(atoms)
            A = np.empty((K, K))
            b = np.empty(K)
            qi = np.arange(pairs.shape[0])[:, None]
            ui = np.arange(n)[None, :]
            for k in range(K):
                b[k] = float((w * X[qi, ui, maps_list[k]].sum(1)).sum())
                for m in range(k, K):
                    A[k, m] = A[m, k] = float((w * (maps_list[k] == maps_list[m]).sum(1)).sum())
            L = max(np.linalg.eigvalsh(A)[-1], 1e-12)
            f_old = 0.5 * alpha @ A @ alpha - b @ alpha
            a_new = alpha.copy()
            for _ in range(500):
                a_next = _project_simplex(a_new - (A @ a_new - b) / L)
                if np.abs(a_next - a_new).max() < 1e-12:
                    a_new = a_next
                    break
                a_new = a_next
            if 0.5 * a_new @ A @ a_new - b @ a_new <= f_old:
                alpha = a_new
        keep = alpha > 1e-14
        atoms = [a for a, k in zip(atoms, keep) if k]
        maps_list = [m for m, k in zip(maps_list, keep) if k]
        alpha = alpha[keep] / alpha[keep].sum()
        Y = np.zeros_like(X)
        for a, m in zip(alpha, maps_list):
            q, u = np.indices(m.shape)
            Y[q, u, m] += a
        history.append(objective(Y))
    if not converged and max_iter > 0:
        warnings.warn(f"synchronize_doubly_stochastic stopped after max_iter={max_iter} "
                      f"iterations with Frank-Wolfe gap {gaps[-1]:.3g} > tol * ||X||^2",
                      ConvergenceWarning, stacklevel=2)
    atoms_arr = np.asarray(atoms, dtype=np.int64)
    best = int(np.argmax(alpha))
    blocks = {(int(i), int(j)): Y[q] for q, (i, j) in enumerate(pairs.tolist())}
    info = {"gap_history": np.asarray(gaps), "n_atoms": len(atoms),
            "fully_corrective": fully_corrective, "pairs": pairs}
    return BirkhoffSyncResult(blocks=blocks, atoms=atoms_arr, weights=alpha,
                              labels=tuple(atoms_arr[best]), objective=history[-1],
                              objective_history=np.asarray(history), n_iter=it,
                              converged=converged, info=info)
