"""Allocator settings for worker processes (private; one home, used by :mod:`transync.parallel`).

The solvers allocate and free arrays of a few megabytes at every step. In a fresh worker
process (joblib's loky, ``concurrent.futures.ProcessPoolExecutor``, Dask), glibc's malloc
keeps returning the top of its heap to the system after each free (``brk`` down, then up again
at the next allocation, every page faulted in and zeroed anew): measured on ENZYMES pairs with
two loky workers, 28 s of system time beside 34 s of computation, and two workers slower than
one process. Fixing the thresholds keeps freed memory in the process: at most
``TRIM_BYTES`` of it beyond what the process uses, and arrays above ``MMAP_BYTES`` still get
their own mapping (returned at once when freed).

Only worker processes are tuned (a caller's own process is left as it is); on systems without
glibc this is a no-op.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import multiprocessing
import sys

MMAP_BYTES = 32 << 20
TRIM_BYTES = 256 << 20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_DONE = {"tuned": False}


def tune_worker_allocator() -> bool:
    """Set glibc's trim and mmap thresholds once, in a worker process only.

    Returns True when the thresholds are set (now or by an earlier call), False in the main
    process or without glibc.
    """
    if _DONE["tuned"]:
        return True
    if multiprocessing.parent_process() is None or not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):     # musl and others: no mallopt
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    ok = mallopt(_M_MMAP_THRESHOLD, MMAP_BYTES) == 1 and mallopt(_M_TRIM_THRESHOLD,
                                                                   TRIM_BYTES) == 1
    _DONE["tuned"] = bool(ok)
    return _DONE["tuned"]
