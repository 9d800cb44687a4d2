"""The BLAS thread limit is shared by nested and overlapping uses and always lifted."""

import numpy as np  # noqa: F401  (loads the BLAS library whose pool is limited)
from threadpoolctl import threadpool_info

from transync._blas import blas_limit


def _threads():
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_overlapping_limits_restore_the_callers_setting():
    before = _threads()
    a, b = blas_limit(), blas_limit()
    a.__enter__()
    b.__enter__()
    assert all(t == 1 for t in _threads())
    a.__exit__(None, None, None)             # out of order: the limit stays while b is inside
    assert all(t == 1 for t in _threads())
    b.__exit__(None, None, None)
    assert _threads() == before


def test_large_problems_keep_the_setting():
    before = _threads()
    with blas_limit(10**6):
        assert _threads() == before
