"""Row-block threaded sparse products: bit for bit the single product; the block eigensolver."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from transync.synchronization import _linalg
from transync.synchronization import _spectral as spec


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("n_threads", [1, 2, 3, 7])
def test_row_blocks_give_the_single_product_exactly(monkeypatch, dtype, n_threads):
    monkeypatch.setattr(_linalg, "_THREADED_MIN_WORK", 0)       # thread even small products
    rng = np.random.default_rng(0)
    A = sp.random(57, 57, density=0.2, format="csr", dtype=dtype, random_state=1)
    A = A.tolil()
    A[10:20] = 0.0                                             # empty rows
    A = A.tocsr()
    op = _linalg.RowBlockProduct(A, n_threads=n_threads)
    assert len(op.blocks) <= n_threads
    assert [b[0] for b in op.blocks][0] == 0 and op.blocks[-1][1] == 57
    for X in (rng.random((57, 9)).astype(dtype), rng.random(57), rng.random((57, 1))):
        ref = A @ X
        out = op @ X
        assert out.dtype == ref.dtype and out.shape == ref.shape
        np.testing.assert_array_equal(out, ref)


def test_more_threads_than_rows_and_an_empty_matrix(monkeypatch):
    monkeypatch.setattr(_linalg, "_THREADED_MIN_WORK", 0)
    A = sp.csr_matrix(np.array([[0.0, 2.0], [3.0, 0.0]]))
    X = np.array([[1.0], [5.0]])
    np.testing.assert_array_equal(_linalg.RowBlockProduct(A, n_threads=8) @ X, A @ X)
    Z = sp.csr_matrix((3, 3))
    np.testing.assert_array_equal(_linalg.RowBlockProduct(Z, n_threads=4) @ np.ones((3, 2)),
                                  np.zeros((3, 2)))


def test_one_thread_in_worker_processes():
    from concurrent.futures import ProcessPoolExecutor
    assert _linalg._n_threads() >= 1
    with ProcessPoolExecutor(1) as pool:
        assert pool.submit(_linalg._n_threads).result() == 1


@pytest.mark.parametrize("n_threads", [1, 2])
def test_sliced_row_products_give_each_slice_product_exactly(monkeypatch, n_threads):
    monkeypatch.setattr(_linalg, "_SPLIT_MIN_NNZ", 0)             # split even small slices
    rng = np.random.default_rng(2)
    A = sp.random(60, 60, density=0.3, format="csr", random_state=3).tolil()
    A[20:25] = 0.0                                                 # a slice with empty rows
    A = A.tocsr()
    off = np.array([0, 1, 7, 20, 25, 44, 60])                      # a one-row slice too
    with _linalg.SlicedRowProducts(A, off, n_threads=n_threads) as rows:
        if n_threads == 2:
            assert sum(second is not None for _, second in rows.parts) >= 4
        for _ in range(2):                                         # X changes between calls
            X = rng.standard_normal((60, 5))
            for g in range(off.size - 1):
                out = rows(g, X)
                ref = A[off[g]:off[g + 1]] @ X
                assert out.shape == ref.shape
                np.testing.assert_array_equal(out, ref)
    assert rows._pool is None                                      # the thread is released


def test_block_krylov_caps_its_depth_at_the_operator_size():
    """A block too wide for depth * block <= M columns runs with fewer Krylov blocks (above
    M / 2: V and the images of its leading M - block vectors). The former fallback,
    Rayleigh-Ritz on span(V) alone, never left its start: it used all its restarts and
    reported no convergence."""
    rng = np.random.default_rng(4)
    M = 60
    Qm, _ = np.linalg.qr(rng.standard_normal((M, M)))
    vals = np.r_[np.linspace(2.0, 1.5, 20), np.linspace(0.5, 0.0, M - 20)]
    A = (Qm * vals) @ Qm.T
    for block, depth in ((35, 2), (25, 4), (20, 3)):
        w, U, _, it, ok = spec.block_krylov_eigs(A.__matmul__, M, 20, block=block, depth=depth,
                                                 tol=1e-8, rng=0)
        assert ok and it < 300
        np.testing.assert_allclose(w, vals[:20], atol=1e-8)
        P = U @ U.T                                                # the top-20 eigenspace
        np.testing.assert_allclose(P @ Qm[:, :20], Qm[:, :20], atol=1e-6)


def test_synchronization_eigs_widens_only_when_narrow_blocks_are_slow():
    rng = np.random.default_rng(5)
    M, k = 400, 20
    Qm, _ = np.linalg.qr(rng.standard_normal((M, M)))

    def run(vals):
        A = (Qm * vals) @ Qm.T
        calls = []

        def matmat(X):
            calls.append(X.shape[1])
            return A @ X
        w, U, n_prod, restarts, ok = spec.synchronization_eigs(matmat, M, k, tol=1e-4, rng=0)
        assert ok and n_prod == sum(calls)
        np.testing.assert_allclose(w, vals[:k], atol=1e-4)
        res = np.linalg.norm(A @ U - U * w, axis=0)             # the stopping rule's residuals
        assert np.all(res <= 1e-4 * w[0])
        return restarts, max(calls)

    # a clear gap after the k-th eigenvalue: the narrow blocks converge, nothing wider is used
    restarts, widest = run(np.r_[np.linspace(1.0, 0.9, k), np.linspace(0.3, 0.0, M - k)])
    assert restarts <= spec.QUICK_RESTARTS and widest <= 2 * spec.krylov_block(k, M)
    # no gap: after QUICK_RESTARTS narrow restarts the wide, deep blocks finish the job
    restarts, widest = run(np.linspace(1.0, 0.0, M))
    assert restarts > spec.QUICK_RESTARTS
    assert widest == spec.WIDE_DEPTH * spec.krylov_block(k, M, spec.WIDE_BLOCK_FACTOR)


@pytest.mark.parametrize("M, rank, k", [(12, 3, 6), (20, 4, 10)])
def test_block_krylov_wide_block_on_a_low_rank_operator(M, rank, k):
    """Blocks above M / 2 keep V in the basis: the eigenvalue-0 vectors of a low-rank operator
    lie outside span(AV), and a basis of AV alone returned non-orthonormal vectors while
    reporting convergence."""
    rng = np.random.default_rng(6)
    B = rng.standard_normal((M, rank))
    A = B @ B.T
    w, U, _, _, ok = spec.block_krylov_eigs(A.__matmul__, M, k, tol=1e-8, rng=0)
    assert ok
    np.testing.assert_allclose(U.T @ U, np.eye(k), atol=1e-8)
    np.testing.assert_allclose(w, np.linalg.eigvalsh(A)[::-1][:k], atol=1e-8)
    assert np.all(np.linalg.norm(A @ U - U * w, axis=0) <= 1e-8 * w[0])
