"""Spectral machinery for permutation synchronization (private).

* ``block_matrix``: the sparse ``(M, M)`` block matrix ``T`` (``M = sum n_i``) with blocks
  ``w_ij P_ij`` and ``w_ij P_ij^T`` for observed pairs and identity blocks on the diagonal, built
  once from the stacked assignments (every block is a gather: ``(P_ij V)[u] = V_j[a_ij[u]]``).
* ``top_eigenpairs``: leading eigenpairs of the degree-normalized ``D^-1/2 T D^-1/2``, by dense
  ``eigh`` for small ``M`` or matrix-free (restarted block Krylov with Rayleigh-Ritz; repeated
  eigenvalues, which consistent input always has, need a block method).
* ``round_to_universe``: rows -> universe slots (pivoted QR picks one row per slot, a Procrustes
  rotation aligns the slots with the axes, then rectangular Hungarian per object, then a few
  Procrustes/Hungarian refinements).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.optimize import linear_sum_assignment

from ._pairwise_input import StackedPairs

__all__: list[str] = []

DENSE_MAX = 2000          # "auto" uses dense eigh up to this total number of nodes


def block_matrix(stk: StackedPairs, *, identity: bool = True) -> sp.csr_matrix:
    """Symmetric sparse block matrix of the observations (see module docstring)."""
    off = stk.offsets
    M = int(off[-1])
    idx_dtype = np.int32 if M < 2**31 - 1 else np.int64
    n_max = stk.maps.shape[1]
    valid = stk.maps >= 0
    q, u = np.nonzero(valid)
    rows = (off[stk.pairs[q, 0]] + u).astype(idx_dtype)
    cols = (off[stk.pairs[q, 1]] + stk.maps[q, u]).astype(idx_dtype)
    data = stk.weights[q]
    del q, u, valid
    parts_r = [rows, cols]
    parts_c = [cols, rows]
    parts_d = [data, data]
    if identity:
        diag = np.arange(M, dtype=idx_dtype)
        parts_r.append(diag); parts_c.append(diag); parts_d.append(np.ones(M))  # noqa: E702
    r = np.concatenate(parts_r); del parts_r, rows  # noqa: E702
    c = np.concatenate(parts_c); del parts_c, cols  # noqa: E702
    d = np.concatenate(parts_d); del parts_d, data  # noqa: E702
    T = sp.coo_matrix((d, (r, c)), shape=(M, M)).tocsr()
    del r, c, d
    _ = n_max
    return T


def normalized(T: sp.csr_matrix) -> tuple[sp.csr_matrix, np.ndarray]:
    """``D^-1/2 T D^-1/2`` with ``D`` the absolute row sums; returns it and ``D^-1/2``."""
    deg = np.asarray(abs(T).sum(axis=1)).ravel()
    dinv = 1.0 / np.sqrt(np.maximum(deg, 1e-300))
    A = sp.diags(dinv) @ T @ sp.diags(dinv)
    return A.tocsr(), dinv


def _orth(X: np.ndarray) -> np.ndarray:
    Q, _ = np.linalg.qr(X)
    return Q


def block_krylov_eigs(matmat, M: int, k: int, *, block: int | None = None, depth: int = 3,
                      tol: float = 1e-6, max_restarts: int = 200, rng=None):
    """Top-``k`` eigenpairs of a symmetric operator by restarted block Krylov + Rayleigh-Ritz.

    The basis ``[V, AV, ..., A^depth V]`` is orthonormalized, the Ritz pairs of ``A`` on it are
    computed, and the best ``block`` Ritz vectors restart the next round. Stops when the residual
    of each of the top ``k`` Ritz pairs is below ``tol * |lambda_max|``. Returns
    ``(values descending, vectors, n_products, converged)``.
    """
    gen = np.random.default_rng(rng)
    b = block or min(M, max(k + 8, int(1.25 * k)))
    b = min(b, M)
    V = _orth(gen.standard_normal((M, b)))
    AV = matmat(V)
    n_prod = b
    converged = False
    vals = vecs = None
    for _ in range(max_restarts):
        basis = [V, AV]
        cur = AV
        for _d in range(depth - 1):
            cur = matmat(_orth(cur))
            n_prod += b
            basis.append(cur)
        Q = _orth(np.hstack(basis))
        if Q.shape[1] > M:
            Q = Q[:, :M]
        AQ = matmat(Q)
        n_prod += Q.shape[1]
        H = Q.T @ AQ
        H = 0.5 * (H + H.T)
        w, S = np.linalg.eigh(H)
        order = np.argsort(w)[::-1][:b]
        w, S = w[order], S[:, order]
        V = Q @ S
        AV = AQ @ S
        R = AV[:, :k] - V[:, :k] * w[:k]
        res = np.linalg.norm(R, axis=0)
        vals, vecs = w[:k], V[:, :k]
        if np.all(res <= tol * max(abs(w[0]), 1e-12)):
            converged = True
            break
    return vals, vecs, n_prod, converged


def top_eigenpairs(A, k: int, *, solver: str, tol: float = 1e-6, rng=None):
    """Top-``k`` eigenpairs (descending) of the symmetric ``A``; returns ``vals, vecs, n, ok``."""
    M = A.shape[0]
    k = min(k, M)
    if solver == "dense":
        Ad = A.toarray() if sp.issparse(A) else np.asarray(A)
        w, U = sla.eigh(Ad, subset_by_index=[M - k, M - 1])
        return w[::-1], U[:, ::-1], 1, True
    return block_krylov_eigs(lambda X: A @ X, M, k, tol=tol, rng=rng)


def estimate_universe(vals: np.ndarray, n_max: int) -> tuple[int, str]:
    """Eigengap rule on the normalized spectrum: ``d = argmax_{k >= n_max} (l_k - l_{k+1})``."""
    vals = np.asarray(vals)
    if vals.size <= n_max:
        return int(max(n_max, vals.size)), "fewer eigenvalues than nodes: d = n_max"
    gaps = vals[:-1] - vals[1:]           # gaps[k-1] = l_k - l_{k+1}
    cand = gaps[n_max - 1:]
    d = int(n_max + np.argmax(cand))
    return d, ("largest gap l_d - l_{d+1} of the degree-normalized block matrix among "
               "d >= max object size")


def _polar(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M, full_matrices=False)
    return U @ Vt


def _hungarian_rows(S_blocks, sizes, off, d):
    labels = []
    for g in range(len(sizes)):
        S = S_blocks[off[g]:off[g + 1]]
        r, c = linear_sum_assignment(S, maximize=True)
        lab = np.full(sizes[g], -1, dtype=np.int64)
        lab[r] = c
        labels.append(lab)
    return labels


def round_to_universe(V: np.ndarray, sizes: np.ndarray, d: int, *, refine: int = 3):
    """Round stacked embeddings ``V`` ((M, k), rows = nodes) to labels into ``d`` slots.

    Rows are normalized; a column-pivoted QR of ``V^T`` picks ``k`` well separated rows as slot
    prototypes, the Procrustes rotation of those prototypes onto the axes is applied, and every
    object is assigned by rectangular Hungarian (each node to a distinct slot). Then ``refine``
    rounds of: rotation = polar(V^T X) (best rotation onto the current labels), re-assign.
    Slots ``k .. d-1`` (when ``k < d``) are never used.
    """
    sizes = np.asarray(sizes)
    off = np.concatenate([[0], np.cumsum(sizes)])
    M, k = V.shape
    norms = np.linalg.norm(V, axis=1, keepdims=True)
    Vn = V / np.maximum(norms, 1e-300)
    _, _, piv = sla.qr(Vn.T, mode="economic", pivoting=True)
    C = Vn[piv[:k]]                         # (k, k): one prototype row per slot
    R = _polar(C.T)                        # Vn @ R puts prototype a on axis a
    S = Vn @ R
    if k < d:
        S = np.hstack([S, np.full((M, d - k), -1.0)])
    labels = _hungarian_rows(S, sizes, off, d)
    for _ in range(refine):
        X = np.zeros((M, k))
        lab_all = np.concatenate(labels)
        ok = (lab_all >= 0) & (lab_all < k)
        X[np.flatnonzero(ok), lab_all[ok]] = 1.0
        R = _polar(Vn.T @ X)
        S = Vn @ R
        if k < d:
            S = np.hstack([S, np.full((M, d - k), -1.0)])
        new = _hungarian_rows(S, sizes, off, d)
        if all(np.array_equal(a, b) for a, b in zip(new, labels)):
            break
        labels = new
    return labels
