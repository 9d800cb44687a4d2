"""One BLAS thread for many small products (private; one home for every layer).

Threads only add start-up and synchronization cost to products of small matrices, and on a
loaded 2-core machine they multiplied some solver times by ten. Problems whose size is below
``SINGLE_THREAD_BELOW`` run on one BLAS thread; larger ones keep the library's setting.

The limit is process-wide (BLAS has one thread pool per process). Nested and concurrent uses
(several threads of the caller inside transync at once) share one limit: it is set by the first
entry and lifted by the last exit, so the caller's setting always comes back.
"""

from __future__ import annotations

import contextlib
import threading

SINGLE_THREAD_BELOW = 200 * 200
_LOCK = threading.Lock()
_STATE = {"depth": 0, "limiter": None, "controller": None}


@contextlib.contextmanager
def _single_thread():
    with _LOCK:
        if _STATE["depth"] == 0:
            if _STATE["controller"] is None:
                from threadpoolctl import ThreadpoolController

                _STATE["controller"] = ThreadpoolController()
            _STATE["limiter"] = _STATE["controller"].limit(limits=1, user_api="blas")
        _STATE["depth"] += 1
    try:
        yield
    finally:
        with _LOCK:
            _STATE["depth"] -= 1
            if _STATE["depth"] == 0:
                _STATE["limiter"].restore_original_limits()
                _STATE["limiter"] = None


def blas_limit(size: int = 0):
    """Context limiting BLAS to one thread when ``size < SINGLE_THREAD_BELOW`` (no-op otherwise)."""
    if size >= SINGLE_THREAD_BELOW:
        return contextlib.nullcontext()
    return _single_thread()
