"""Row-block threaded sparse products: bit for bit the single product."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from transync.synchronization import _linalg


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
