"""Executors for independent pairwise work (issue 10 item 3).

Every executor gives exactly the serial result; a dead Dask scheduler or a stuck worker gives
``ExecutorError`` within the timeout, never a hang; task exceptions keep their type.
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np
import pytest

from transync.exceptions import ExecutorError, TransyncError
from transync.parallel import (
    DEFAULT_TIMEOUT,
    _demo_chunk,
    map_chunks,
    split_chunks,
)

# the worker function must be importable in worker processes: _demo_chunk lives in the library
# (a function of this module is not importable there under --import-mode=importlib)
N_ITEMS = 40
# no dashboard; the scheduler's HTTP endpoints (always served) on a free port, not on 8787
NO_DASHBOARD = dict(dashboard_address=None, scheduler_kwargs={"dashboard_address": ":0"})


def _reference(n_items=N_ITEMS):
    return np.concatenate([_demo_chunk([i]) for i in range(n_items)])


def _assert_same(results, chunks):
    assert len(results) == len(chunks)
    for res, chunk in zip(results, chunks):
        np.testing.assert_array_equal(res, _demo_chunk(chunk))       # bit-identical
    np.testing.assert_array_equal(np.concatenate(results), _reference(sum(map(len, chunks))))


# --------------------------------------------------------------------------- split_chunks

@pytest.mark.parametrize("n_items", [0, 1, 7, 8, 40, 1001])
@pytest.mark.parametrize("executor, n_workers", [(None, 1), ("serial", 1), (3, 3)])
def test_split_chunks_partitions_the_range(n_items, executor, n_workers):
    chunks = split_chunks(n_items, executor, min_chunk=8, chunks_per_worker=4)
    if n_items == 0:
        assert chunks == []
        return
    np.testing.assert_array_equal(np.concatenate(chunks), np.arange(n_items))
    sizes = [len(c) for c in chunks]
    assert max(sizes) - min(sizes) <= 1
    assert len(chunks) <= 4 * n_workers
    assert min(sizes) >= min(8, n_items)
    assert all(c.dtype == np.intp for c in chunks)


def test_split_chunks_uses_the_pool_size():
    with ThreadPoolExecutor(max_workers=5) as pool:
        chunks = split_chunks(1000, pool, min_chunk=1, chunks_per_worker=2)
    assert len(chunks) == 10


@pytest.mark.parametrize("kwargs, err, match", [
    (dict(n_items=-1), ValueError, "`n_items` must be >= 0, got -1"),
    (dict(n_items=2.5), TypeError, "`n_items` must be an int"),
    (dict(n_items=4, min_chunk=0), ValueError, "`min_chunk` must be >= 1"),
    (dict(n_items=4, chunks_per_worker=0), ValueError, "`chunks_per_worker` must be >= 1"),
    (dict(n_items=4, executor="threads"), ValueError, "`executor` must be"),
])
def test_split_chunks_validation(kwargs, err, match):
    with pytest.raises(err, match=match):
        split_chunks(**kwargs)


# --------------------------------------------------------------------------- same result everywhere

def test_serial_is_the_plain_loop():
    chunks = split_chunks(N_ITEMS, None, min_chunk=4)
    assert len(chunks) > 1
    _assert_same(map_chunks(_demo_chunk, chunks), chunks)
    _assert_same(map_chunks(_demo_chunk, chunks, executor="serial"), chunks)
    _assert_same(map_chunks(_demo_chunk, chunks, executor=1), chunks)
    assert map_chunks(_demo_chunk, []) == []


@pytest.mark.parametrize("executor", ["processes", 2])
def test_joblib_matches_serial(executor):
    pytest.importorskip("joblib")
    chunks = split_chunks(N_ITEMS, executor, min_chunk=3)
    _assert_same(map_chunks(_demo_chunk, chunks, executor=executor), chunks)


def test_an_int_executor_starts_at_most_one_process_per_cpu_and_chunk(monkeypatch):
    """`executor=1000` on 2 cores started hundreds of loky processes and never finished (found
    by a review through `transync kernel --workers 1000`): the count is capped at the CPUs."""
    pytest.importorskip("joblib")
    import transync.parallel as par

    monkeypatch.setattr(par, "_cpu_count", lambda: 2)
    assert par._n_workers("joblib", 1000) == 2
    assert len(split_chunks(1000, 1000, min_chunk=1, chunks_per_worker=1)) == 2
    chunks = split_chunks(N_ITEMS, 1000, min_chunk=3)
    _assert_same(map_chunks(_demo_chunk, chunks, executor=1000), chunks)


def test_concurrent_futures_match_serial():
    chunks = split_chunks(N_ITEMS, 2, min_chunk=3)
    with ThreadPoolExecutor(max_workers=3) as pool:
        _assert_same(map_chunks(_demo_chunk, chunks, executor=pool), chunks)
    with ProcessPoolExecutor(max_workers=2) as pool:
        _assert_same(map_chunks(_demo_chunk, chunks, executor=pool), chunks)


def test_results_in_chunk_order_when_they_finish_out_of_order():
    def slow_first(chunk):
        time.sleep(0.05 * (3 - chunk))
        return chunk

    with ThreadPoolExecutor(max_workers=4) as pool:
        assert map_chunks(slow_first, [0, 1, 2, 3], executor=pool) == [0, 1, 2, 3]


def test_progress_bar_counts_chunks(capsys):
    chunks = split_chunks(20, None, min_chunk=5)
    map_chunks(_demo_chunk, chunks, progress=True, desc="my pairs")
    err = capsys.readouterr().err
    assert "my pairs" in err and "/4 " in err
    map_chunks(_demo_chunk, chunks)
    assert capsys.readouterr().err == ""


# --------------------------------------------------------------------------- Dask

@pytest.fixture(scope="module")
def dask_client():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(processes=True, n_workers=2, threads_per_worker=1,
                                       host="127.0.0.1", **NO_DASHBOARD)
    try:
        client = distributed.Client(cluster)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


def test_dask_matches_serial(dask_client):
    chunks = split_chunks(N_ITEMS, dask_client, min_chunk=3)
    assert len(chunks) == 8                     # 2 workers x 1 thread x 4 chunks per worker
    _assert_same(map_chunks(_demo_chunk, chunks, executor=dask_client), chunks)
    tuples = [tuple(c.tolist()) for c in chunks]       # containers are scattered whole
    _assert_same(map_chunks(_demo_chunk, tuples, executor=dask_client), chunks)


def test_dask_task_error_keeps_type_and_names_chunk(dask_client):
    with pytest.raises(ValueError, match="non-negative indices, got -3") as info:
        map_chunks(_demo_chunk, [np.arange(3), np.array([4, -3])], executor=dask_client)
    assert "chunk 1 of 2" in info.value.__notes__[-1]
    assert "_demo_chunk" in str(info.value.__cause__)       # the worker's traceback


def test_dask_stuck_worker_times_out(dask_client):
    start = time.monotonic()
    with pytest.raises(ExecutorError, match="no chunk finished within timeout=0.3 s"):
        map_chunks(time.sleep, [0.8, 0.8, 0.8], executor=dask_client, timeout=0.3)
    assert time.monotonic() - start < 0.3 + 20
    # the client stays usable once the sleeping tasks end
    chunks = split_chunks(10, None, min_chunk=5)
    _assert_same(map_chunks(_demo_chunk, chunks, executor=dask_client), chunks)


@pytest.mark.parametrize("by_address", [False, True])
def test_dead_dask_scheduler_raises_within_timeout(by_address):
    """A closed cluster: its own client is closed, a client by address keeps reconnecting."""
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(processes=False, n_workers=1, threads_per_worker=1,
                                       protocol="tcp", host="127.0.0.1", **NO_DASHBOARD)
    client = distributed.Client(cluster.scheduler_address if by_address else cluster)
    try:
        assert map_chunks(_demo_chunk, [[0, 1]], executor=client)[0].shape == (2,)
        cluster.close()
        timeout = 3.0
        start = time.monotonic()
        with pytest.raises(ExecutorError, match="not connected to a scheduler") as info:
            map_chunks(_demo_chunk, [[0, 1]], executor=client, timeout=timeout)
        assert time.monotonic() - start < timeout + 20      # no hang (not a speed assertion)
        assert isinstance(info.value, TransyncError) and isinstance(info.value, RuntimeError)
        if not by_address:      # (by address: the same check, one more reconnection grace)
            with pytest.raises(ExecutorError, match="client.status='closed'"):
                split_chunks(10, client)
    finally:
        client.close()
        cluster.close()


class _FakeClient:
    """Duck-typed like a dask.distributed.Client (module name 'distributed...')."""

    asynchronous = False
    status = "running"

    class scheduler:
        address = "tcp://192.0.2.1:8786"

        @staticmethod
        def identity():
            return {}

    def sync(self, fn, *args, callback_timeout=None, **kwargs):
        time.sleep(min(callback_timeout, 0.2))
        raise TimeoutError(f"timed out after {callback_timeout} s.")

    def submit(self, *args, **kwargs):
        raise AssertionError("nothing may be submitted to an unresponsive scheduler")

    scatter = submit


_FakeClient.__module__ = "distributed.client"


def test_unresponsive_dask_scheduler_is_an_executor_error():
    with pytest.raises(ExecutorError, match="tcp://192.0.2.1:8786 did not answer within 0.5 s"):
        map_chunks(_demo_chunk, [[0]], executor=_FakeClient(), timeout=0.5)


def test_asynchronous_dask_client_is_refused():
    client = _FakeClient()
    client.asynchronous = True
    with pytest.raises(TypeError, match="synchronous dask.distributed.Client"):
        map_chunks(_demo_chunk, [[0]], executor=client)


# --------------------------------------------------------------------------- failures

@pytest.mark.parametrize("executor", [object(), 2.5, True, b"x", ["serial"]])
def test_bad_executor_is_a_type_error(executor):
    with pytest.raises(TypeError, match=r"`executor` must be None or 'serial'.*submit.*got"):
        map_chunks(_demo_chunk, [[0]], executor=executor)


@pytest.mark.parametrize("executor, match", [
    ("threads", "got unknown name 'threads'"),
    (0, "number of processes.*got 0"),
])
def test_bad_executor_value_is_a_value_error(executor, match):
    with pytest.raises(ValueError, match=match):
        map_chunks(_demo_chunk, [[0]], executor=executor)


@pytest.mark.parametrize("kwargs, err, match", [
    (dict(fn=3), TypeError, "`fn` must be callable"),
    (dict(chunks=5), TypeError, "`chunks` must be an iterable"),
    (dict(chunks="ab"), TypeError, "`chunks` must be an iterable"),
    (dict(timeout=0), ValueError, "`timeout` must be finite and > 0"),
    (dict(timeout="1"), TypeError, "`timeout` must be a real number"),
    (dict(progress="yes"), TypeError, "`progress` must be a bool"),
])
def test_argument_validation(kwargs, err, match):
    args = dict(fn=_demo_chunk, chunks=[[0]]) | kwargs
    with pytest.raises(err, match=match):
        map_chunks(args.pop("fn"), args.pop("chunks"), **args)


class _SpyProcessPool(ProcessPoolExecutor):
    submitted = 0

    def submit(self, *args, **kwargs):
        type(self).submitted += 1
        return super().submit(*args, **kwargs)


def test_unpicklable_function_refused_before_submitting():
    with _SpyProcessPool(max_workers=1) as pool:
        with pytest.raises(TypeError, match="`fn` must be picklable.*module-level function"):
            map_chunks(lambda c: c, [[0], [1]], executor=pool)
        with pytest.raises(TypeError, match=r"`chunks` \(its first chunk\) must be picklable"):
            map_chunks(_demo_chunk, [threading.Lock()], executor=pool)
    assert _SpyProcessPool.submitted == 0


def test_unpicklable_for_cloudpickle_refused():
    pytest.importorskip("joblib")
    lock = threading.Lock()
    with pytest.raises(TypeError, match="`fn` must be picklable to run on joblib.*_thread.lock"):
        map_chunks(lambda c: (lock, c), [[0]], executor=2)


def test_lambda_runs_on_joblib():
    pytest.importorskip("joblib")
    assert map_chunks(lambda c: 2 * c, [1, 2, 3], executor=2) == [2, 4, 6]


@pytest.mark.parametrize("make", ["serial", "threads", "joblib", "process-pool"])
def test_task_error_keeps_its_type_and_names_the_chunk(make):
    if make == "joblib":
        pytest.importorskip("joblib")
    pool = {"threads": lambda: ThreadPoolExecutor(2),
            "process-pool": lambda: ProcessPoolExecutor(2)}.get(make, lambda: None)()
    executor = {"serial": None, "joblib": 2}.get(make, pool)
    chunks = [np.arange(3), np.array([5, -2, 7]), np.arange(3, 6)]
    try:
        with pytest.raises(ValueError, match="non-negative indices, got -2") as info:
            map_chunks(_demo_chunk, chunks, executor=executor)
    finally:
        if pool is not None:
            pool.shutdown(wait=True)
    note = info.value.__notes__[-1]
    assert "chunk 1 of 3" in note and "[5, -2, 7]" in note
    assert len(info.value.__notes__) == 1
    if make != "serial":
        assert "_demo_chunk" in str(info.value.__cause__)   # the worker's traceback


def test_stuck_thread_times_out_and_cancels_the_rest():
    ran = []

    def work(seconds):
        ran.append(seconds)
        time.sleep(seconds)
        return seconds

    pool = ThreadPoolExecutor(max_workers=1)
    start = time.monotonic()
    try:
        with pytest.raises(ExecutorError, match="timeout=0.2 s.*3 of 3 chunks outstanding"):
            map_chunks(work, [0.6, 0.01, 0.01], executor=pool, timeout=0.2)
        assert time.monotonic() - start < 0.2 + 20
    finally:
        pool.shutdown(wait=True)
    assert ran == [0.6]         # the queued chunks were cancelled


def test_stuck_joblib_worker_times_out():
    pytest.importorskip("joblib")
    start = time.monotonic()
    with pytest.raises(ExecutorError, match="did not finish within timeout=0.3 s"):
        map_chunks(time.sleep, [5.0, 0.01], executor=2, timeout=0.3)
    assert time.monotonic() - start < 0.3 + 20
    chunks = split_chunks(12, None, min_chunk=4)            # the pool comes back
    _assert_same(map_chunks(_demo_chunk, chunks, executor=2), chunks)


def test_keyboard_interrupt_cancels_outstanding_chunks():
    ran = []

    def work(chunk):
        ran.append(chunk)
        if chunk == 0:
            raise KeyboardInterrupt
        return chunk

    pool = ThreadPoolExecutor(max_workers=1)
    try:
        with pytest.raises(KeyboardInterrupt):
            map_chunks(work, range(6), executor=pool)
    finally:
        pool.shutdown(wait=True)
    assert ran == [0]


def test_broken_process_pool_is_an_executor_error():
    pool = ProcessPoolExecutor(max_workers=1)
    pool.shutdown()
    with pytest.raises(ExecutorError, match="refused chunk 0 of 1.*shutdown"):
        map_chunks(_demo_chunk, [[0]], executor=pool)


def test_default_timeout_is_documented():
    assert DEFAULT_TIMEOUT == 600.0
    assert "600 s" in map_chunks.__doc__


def test_a_timeout_beyond_the_clocks_is_refused():
    """timeout=1e10 leaked OverflowError ("timestamp out of range for platform time_t") from
    the futures' wait whenever a chunk was still running."""
    with ThreadPoolExecutor(2) as pool:
        for t in (1e10, 1e300):
            with pytest.raises(ValueError, match="`timeout` must be at most 3.2e\\+07 s"):
                map_chunks(_demo_chunk, [[0], [1]], executor=pool, timeout=t)
        assert len(map_chunks(_demo_chunk, [[0], [1]], executor=pool, timeout=3e7)) == 2


def _allocator_tuned(_chunk):
    from transync import _malloc
    return _malloc.tune_worker_allocator(), _malloc._DONE["tuned"]


def test_worker_processes_tune_the_allocator_and_the_caller_does_not():
    import sys

    from transync import _malloc
    assert _malloc.tune_worker_allocator() is False      # the caller's process is left alone
    assert map_chunks(_allocator_tuned, [0]) == [(False, False)]
    with ThreadPoolExecutor(2) as pool:                   # threads: still the caller's process
        assert map_chunks(_allocator_tuned, [0, 1], executor=pool) == [(False, False)] * 2
    with ProcessPoolExecutor(1) as pool:
        done = map_chunks(_allocator_tuned, [0, 1], executor=pool)
    if sys.platform.startswith("linux"):
        import ctypes
        import ctypes.util
        expected = hasattr(ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6"), "mallopt")
        assert done == [(expected, expected)] * 2        # set once before the first chunk


def test_split_chunks_refuses_index_arrays_beyond_memory():
    """split_chunks(2**40) tried to allocate an 8 TiB index array (MemoryError)."""
    from transync.parallel import split_chunks

    with pytest.raises(ValueError, match=r"`n_items` must be <= 1000000000"):
        split_chunks(2**40)


def test_an_executor_class_instead_of_an_instance_is_named():
    """ThreadPoolExecutor (the class) failed as "type refused chunk 0 of 2: AttributeError:
    'function' object has no attribute '_shutdown_lock'"; split_chunks accepted it."""
    for fn in (lambda: map_chunks(_demo_chunk, [[0], [1]], executor=ThreadPoolExecutor),
               lambda: split_chunks(10, ThreadPoolExecutor)):
        with pytest.raises(TypeError, match=r"`executor` must be an executor object, got the "
                                            r"class ThreadPoolExecutor: create one"):
            fn()


class _WrongValueExecutor:
    """A broken executor: ``submit`` returns a future of ``value``, whatever it was given."""

    def __init__(self, value, concurrent=True):
        self.value, self.concurrent = value, concurrent

    def submit(self, fn, *args):
        from concurrent.futures import Future

        f = Future()
        f.set_result(self.value)
        return f if self.concurrent else _PlainFuture(f)


class _PlainFuture:
    def __init__(self, f):
        self.f = f

    def result(self, timeout=None):
        return self.f.result(timeout)


@pytest.mark.parametrize("value", ["garbage", (0,), ("0", [1]), (7, [1]), (-1, [1]), None])
@pytest.mark.parametrize("concurrent", [True, False])
def test_an_executor_that_returns_something_else_is_an_executor_error(value, concurrent):
    """Futures completing with another value than the submitted function's raised "too many
    values to unpack (expected 2)" (a ValueError that named nothing)."""
    with pytest.raises(ExecutorError, match=r"_WrongValueExecutor returned .* for a chunk, not "
                                            r"the \(index, result\) pair"):
        map_chunks(_demo_chunk, [[0], [1]], executor=_WrongValueExecutor(value, concurrent))
