"""One BLAS thread for many small products (private; one home for every layer).

Threads only add start-up and synchronization cost to products of small matrices, and on a
loaded 2-core machine they multiplied some solver times by ten. Problems whose size is below
``SINGLE_THREAD_BELOW`` run on one BLAS thread; larger ones keep the library's setting.
"""

from __future__ import annotations

import contextlib

SINGLE_THREAD_BELOW = 200 * 200
_CONTROLLER = None


def blas_limit(size: int = 0):
    """Context limiting BLAS to one thread when ``size < SINGLE_THREAD_BELOW`` (no-op otherwise)."""
    global _CONTROLLER
    if size >= SINGLE_THREAD_BELOW:
        return contextlib.nullcontext()
    if _CONTROLLER is None:
        from threadpoolctl import ThreadpoolController

        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER.limit(limits=1, user_api="blas")
