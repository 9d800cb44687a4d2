"""Executors for independent pairwise work: serial, joblib processes, concurrent.futures, Dask.

One home for every layer that spreads independent work (multi-graph matching, assignment
kernels).

The multi-graph solvers and the kernels split the pairs of a collection into chunks
(:func:`split_chunks`) and run one function per chunk (:func:`map_chunks`). The chunks are
independent, so they can run in this process, on local processes, or on any
``concurrent.futures``-like executor, a ``dask.distributed.Client`` included; the results are the same whichever runs them.

``executor`` accepts

* ``None`` or ``"serial"``: a plain loop in this process;
* ``"processes"``: joblib's loky process pool on all cores (joblib is an optional dependency:
  ``pip install transync[distributed]``); an int ``n_jobs``: that many processes (joblib's
  convention: ``-1`` = all cores, ``-2`` = all but one; ``1`` = serial, without joblib), at
  most one per CPU and per chunk of work (more only compete for the same cores: 1000 asked
  for on 2 cores started hundreds of processes and never finished);
* any object with ``submit(fn, *args)`` returning futures with ``result(timeout)``: a
  ``concurrent.futures.ThreadPoolExecutor`` or ``ProcessPoolExecutor`` (the caller keeps
  ownership and shuts it down), a loky executor, or a ``dask.distributed.Client``.

Guarantees

* Results come back in the order of the chunks.
* No hang: a dead or unreachable Dask scheduler, a lost worker, or a chunk that never finishes
  raises :class:`~transync.exceptions.ExecutorError` within ``timeout`` seconds (default
  :data:`DEFAULT_TIMEOUT`, 600 s, measured as the longest wait for the next chunk to finish; a
  Dask client's scheduler is also checked for liveness first, within
  ``min(timeout, 10 s)``). The outstanding chunks are cancelled. A chunk already running on a
  caller-owned executor cannot be killed: it keeps its worker busy until it ends (joblib's
  pool, owned here, is terminated).
* An exception raised by ``fn`` keeps its type, gains a note naming the chunk (and, from a
  worker, the worker's traceback as its ``__cause__``) and cancels the outstanding chunks.
* ``fn`` and the chunks must be picklable for process-based executors: they are test-pickled
  once (``fn`` and the first chunk), before anything is submitted, with the pickler the executor
  uses (the standard library's for ``ProcessPoolExecutor``, cloudpickle for joblib and Dask,
  which also take lambdas and local functions); a failure is a ``TypeError`` naming ``fn`` or
  ``chunks``.

Worker processes (joblib's, a ``ProcessPoolExecutor``'s, Dask's) fix glibc's malloc trim and
mmap thresholds before their first chunk (``transync._malloc``): left at their defaults, a fresh
worker gave freed heap back to the system after every solver step and faulted it in again
(two loky workers on ENZYMES pairs spent 28 s in the kernel beside 34 s of computation and
were slower than one process; with the thresholds fixed, 1.7x faster than one process). A
worker then keeps up to 256 MB of freed memory for reuse. The calling process is never changed.

Examples
--------
>>> from concurrent.futures import ThreadPoolExecutor
>>> chunks = split_chunks(10, None, min_chunk=3)
>>> [c.tolist() for c in chunks]
[[0, 1, 2, 3], [4, 5, 6], [7, 8, 9]]
>>> serial = map_chunks(_demo_chunk, chunks)
>>> with ThreadPoolExecutor(2) as pool:
...     threaded = map_chunks(_demo_chunk, chunks, executor=pool)
>>> all(np.array_equal(a, b) for a, b in zip(serial, threaded))
True
"""

from __future__ import annotations

import math
import numbers
import os
import pickle
import reprlib
import time
import traceback
import warnings
from collections.abc import Callable, Iterable, Sequence
from concurrent import futures as cf
from typing import Any, NamedTuple

import numpy as np

from ._malloc import tune_worker_allocator
from ._progress import progress_bar
from ._validation import check_bool, check_int, check_positive, short_repr
from .exceptions import ExecutorError

__all__ = ["DEFAULT_TIMEOUT", "MAX_TIMEOUT", "is_serial", "map_chunks", "split_chunks"]

#: Default ``timeout`` of :func:`map_chunks`: the longest wait, in seconds, for the next chunk to
#: finish before :class:`~transync.exceptions.ExecutorError` is raised.
DEFAULT_TIMEOUT = 600.0
#: Largest ``timeout`` of :func:`map_chunks` (a year): 1e10 s raised a raw ``OverflowError``
#: from the futures' wait (``timestamp out of range for platform time_t``).
MAX_TIMEOUT = 3.2e7

_DASK_LIVENESS_TIMEOUT = 10.0   # at most this long for the Dask scheduler's first answer
_DASK_RECONNECT_GRACE = 1.0     # a client that lost its scheduler gets this long to reconnect
_ACCEPTED = ("None or 'serial' (this process), 'processes' (joblib, all cores), an int n_jobs "
             "(joblib processes; 1 = serial), or an executor object with a submit(fn, *args) "
             "method returning futures (concurrent.futures.Executor, dask.distributed.Client)")


# --------------------------------------------------------------------------- public API

def map_chunks(fn: Callable[[Any], Any], chunks: Iterable, *, executor=None,
               timeout: float | None = None, progress: bool = False,
               desc: str = "pair chunks") -> list:
    """Apply ``fn`` to every chunk on ``executor``; results in the order of ``chunks``.

    Parameters
    ----------
    fn : callable
        ``fn(chunk) -> result``. With a process-based executor it must be picklable (a
        module-level function or a ``functools.partial`` of one; joblib and Dask also take
        lambdas and local functions) and must not modify its arguments in place (joblib passes
        large arrays as read-only memory maps).
    chunks : iterable
        The chunks, e.g. the index arrays of :func:`split_chunks`.
    executor : None, str, int or executor object, optional
        Where the chunks run: ``None``/``"serial"`` (default), ``"processes"``, an int
        ``n_jobs``, or an object with ``submit(fn, *args)`` (``concurrent.futures`` executor,
        ``dask.distributed.Client``). See the module documentation.
    timeout : float, optional
        Seconds to wait for the next chunk to finish (for joblib: for each chunk to finish)
        before giving up with :class:`~transync.exceptions.ExecutorError`. Default
        :data:`DEFAULT_TIMEOUT` (600 s), at most :data:`MAX_TIMEOUT` (a year). Not applied to
        the serial loop, which runs here.
    progress : bool, default False
        Show a tqdm progress bar over the finished chunks.
    desc : str, default "pair chunks"
        Label of the progress bar.

    Returns
    -------
    list
        ``[fn(c) for c in chunks]``.

    Raises
    ------
    TypeError
        ``fn`` not callable, ``chunks`` not iterable, ``executor`` of an unknown form, or ``fn``
        / the chunks not picklable for a process-based executor.
    ExecutorError
        The executor could not run the chunks: dead or unreachable scheduler, lost or killed
        worker, no chunk finished within ``timeout`` seconds.
    Exception
        Whatever ``fn`` raised, with its type, and a note naming the chunk.

    Examples
    --------
    >>> results = map_chunks(_demo_chunk, [np.arange(3), np.arange(3, 5)])
    >>> [r.shape for r in results]
    [(3,), (2,)]
    >>> try:
    ...     map_chunks(_demo_chunk, [np.arange(2), np.array([1, -1])])
    ... except ValueError as exc:
    ...     print(exc)
    ...     print(exc.__notes__[-1])
    `chunk` must hold non-negative indices, got -1
    in map_chunks: raised by fn on chunk 1 of 2 (array of shape (2,) ..., items [1, -1])
    """
    if not callable(fn):
        raise TypeError(f"`fn` must be callable, got {type(fn).__name__} {fn!r:.60}")
    if isinstance(chunks, (str, bytes)) or not isinstance(chunks, Iterable):
        raise TypeError(f"`chunks` must be an iterable of chunks, got {type(chunks).__name__}")
    chunks = list(chunks)
    timeout = DEFAULT_TIMEOUT if timeout is None else check_positive(timeout, "timeout")
    if timeout > MAX_TIMEOUT:          # the waits' clocks overflow (time_t) beyond a point
        raise ValueError(f"`timeout` must be at most {MAX_TIMEOUT:g} s (about a year), got "
                         f"{timeout:g}")
    check_bool(progress, "progress")
    kind, handle = _resolve(executor)
    if kind == "dask":
        _check_dask_client(handle, min(timeout, _DASK_LIVENESS_TIMEOUT))
    if kind == "joblib" and _n_workers(kind, handle) == 1:
        kind, handle = "serial", None       # e.g. "processes" on one core: no pool to start
    if not chunks:
        return []
    pickler = _pickler_for(kind, handle)
    if pickler is not None:
        _check_picklable(fn, "fn", pickler, _label(kind, handle))
        _check_picklable(chunks[0], "chunks", pickler, _label(kind, handle))
    bar = progress_bar(len(chunks), desc, enabled=bool(progress), unit="chunk", leave=False)
    try:
        if kind == "serial":
            return _run_serial(fn, chunks, bar)
        if kind == "joblib":
            return _run_joblib(fn, chunks, handle, timeout, bar)
        if kind == "dask":
            return _run_dask(fn, chunks, handle, timeout, bar)
        return _run_futures(fn, chunks, handle, timeout, bar, pickler)
    finally:
        bar.close()


def is_serial(executor) -> bool:
    """Whether ``executor`` runs the work in this process: ``None``, ``"serial"`` or ``1``.

    Raises
    ------
    ValueError, TypeError
        ``executor`` is none of the accepted forms (the messages of :func:`map_chunks`).

    Examples
    --------
    >>> is_serial(None), is_serial("serial"), is_serial(1), is_serial(2)
    (True, True, True, False)
    """
    return _resolve(executor)[0] == "serial"


def split_chunks(n_items: int, executor=None, *, min_chunk: int = 8,
                 chunks_per_worker: int = 4) -> list[np.ndarray]:
    """Split ``range(n_items)`` into contiguous index chunks sized for ``executor``.

    About ``chunks_per_worker`` chunks per worker (for load balancing and a live progress bar)
    but none smaller than ``min_chunk`` items (for vectorized work per chunk); sizes differ by
    at most one. Concatenating the chunks gives ``np.arange(n_items)``.

    Parameters
    ----------
    n_items : int
        Number of items (pairs), >= 0.
    executor : optional
        As in :func:`map_chunks`. Its worker count: 1 when serial, joblib's effective
        ``n_jobs``, ``max_workers`` of a ``concurrent.futures`` executor, the total threads of
        a Dask cluster (one quick scheduler query; a dead scheduler raises
        :class:`~transync.exceptions.ExecutorError`), else the number of CPUs.
    min_chunk : int, default 8
        Smallest chunk (unless ``n_items`` itself is smaller), >= 1.
    chunks_per_worker : int, default 4
        Target number of chunks per worker, >= 1.

    Returns
    -------
    list of ndarray
        Int (``np.intp``) index arrays; empty list when ``n_items == 0``.

    Examples
    --------
    >>> [len(c) for c in split_chunks(100, 2, min_chunk=10)]
    [13, 13, 13, 13, 12, 12, 12, 12]
    >>> [len(c) for c in split_chunks(5, "serial")]
    [5]
    """
    n_items = check_int(n_items, "n_items", minimum=0, maximum=10**9)   # an index array
    min_chunk = check_int(min_chunk, "min_chunk", minimum=1)
    chunks_per_worker = check_int(chunks_per_worker, "chunks_per_worker", minimum=1)
    kind, handle = _resolve(executor)
    if n_items == 0:
        return []
    n_workers = _n_workers(kind, handle)
    n_chunks = max(1, min(n_workers * chunks_per_worker, n_items // min_chunk))
    return np.array_split(np.arange(n_items, dtype=np.intp), n_chunks)


# --------------------------------------------------------------------------- executor forms

def _resolve(executor) -> tuple[str, Any]:
    """Return ``(kind, handle)``: serial/None, joblib/n_jobs, dask/client, futures/executor."""
    if executor is None:
        return "serial", None
    if isinstance(executor, str):
        if executor == "serial":
            return "serial", None
        if executor == "processes":
            return "joblib", -1
        raise ValueError(f"`executor` must be {_ACCEPTED}; got unknown name {executor!r}")
    if isinstance(executor, (bool, np.bool_)):
        raise TypeError(f"`executor` must be {_ACCEPTED}; got bool {executor!r}")
    if isinstance(executor, numbers.Integral):
        n_jobs = int(executor)
        if n_jobs == 0:
            raise ValueError("`executor` as an int is a number of processes (joblib n_jobs: "
                             ">= 1, or -1 for all cores, -2 for all but one), got 0")
        return ("serial", None) if n_jobs == 1 else ("joblib", n_jobs)
    if _is_dask_client(executor):
        if getattr(executor, "asynchronous", False):
            raise TypeError("`executor` must be a synchronous dask.distributed.Client, got an "
                            "asynchronous one (Client(..., asynchronous=True))")
        return "dask", executor
    if isinstance(executor, type):          # ThreadPoolExecutor, not ThreadPoolExecutor(2)
        raise TypeError(f"`executor` must be an executor object, got the class "
                        f"{executor.__qualname__}: create one, e.g. {executor.__qualname__}(2)")
    if callable(getattr(executor, "submit", None)):
        return "futures", executor
    hint = ""
    if type(executor).__module__.split(".")[0] in ("distributed", "dask"):
        hint = " (for a Dask cluster pass a dask.distributed.Client(cluster))"
    raise TypeError(f"`executor` must be {_ACCEPTED}; got {type(executor).__module__}."
                    f"{type(executor).__qualname__} {executor!r:.80}{hint}")


def _is_dask_client(obj) -> bool:
    """Duck-typed Dask client check that never imports dask."""
    module = type(obj).__module__ or ""
    return (module.split(".")[0] == "distributed" and callable(getattr(obj, "submit", None))
            and callable(getattr(obj, "scatter", None)) and hasattr(obj, "status"))


def _n_workers(kind: str, handle) -> int:
    if kind == "serial":
        return 1
    if kind == "joblib":
        try:
            from joblib import effective_n_jobs
        except ImportError:
            cpus = _cpu_count()
            return min(cpus, max(1, handle if handle > 0 else cpus + 1 + handle))
        return min(_cpu_count(), max(1, int(effective_n_jobs(handle))))
    if kind == "dask":
        info = _check_dask_client(handle, _DASK_LIVENESS_TIMEOUT)
        workers = info.get("workers") or {}
        threads = sum(int(w.get("nthreads", 1)) for w in workers.values())
        return max(1, threads)
    n = getattr(handle, "_max_workers", None)    # concurrent.futures and loky executors
    return n if isinstance(n, int) and n > 0 else _cpu_count()


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


# --------------------------------------------------------------------------- pickling

def _pickler_for(kind: str, handle) -> str | None:
    """Which pickler carries the work to the workers, or None when nothing is pickled."""
    if kind in ("joblib", "dask"):
        return "cloudpickle"
    if kind == "futures":
        if isinstance(handle, cf.ProcessPoolExecutor):
            return "pickle"
        if type(handle).__module__.startswith(("loky", "joblib.externals.loky")):
            return "cloudpickle"
    return None         # serial, threads, unknown executors: not checked


def _dumps(obj, pickler: str) -> bytes:
    if pickler == "pickle":
        return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    try:
        import cloudpickle
    except ImportError:     # pragma: no cover - joblib vendors it
        from joblib.externals import cloudpickle
    return cloudpickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)


def _check_picklable(obj, name: str, pickler: str, where: str) -> None:
    try:
        _dumps(obj, pickler)
    except Exception as exc:    # PicklingError, TypeError, AttributeError, ...
        what = "`fn`" if name == "fn" else "`chunks` (its first chunk)"
        hint = ("; use a module-level function, or a functools.partial of one"
                if name == "fn" else "")
        raise TypeError(f"{what} must be picklable to run on {where} (process-based), got "
                        f"{_short(obj)} which {pickler} cannot pickle ({type(exc).__name__}: "
                        f"{exc}){hint}") from exc


# --------------------------------------------------------------------------- running

class _TaskFailure(NamedTuple):
    """What a worker sends back when ``fn`` raised: the exception and its formatted traceback."""

    exc: BaseException
    traceback: str


class _RemoteTraceback(Exception):
    """Carries a worker's traceback text as the ``__cause__`` of a re-raised exception."""

    def __str__(self) -> str:
        return self.args[0]


def _run_chunk(fn, index: int, chunk, pickler: str | None):
    """Worker side: ``(index, fn(chunk))``, or ``(index, _TaskFailure)`` if ``fn`` raised.

    Returning the failure (rather than raising it) keeps the task's own exceptions apart from
    the executor's (lost worker, timeout...), which become ``ExecutorError``. In a worker
    process, the allocator is tuned first (:mod:`transync._malloc`).
    """
    tune_worker_allocator()
    try:
        return index, fn(chunk)
    except Exception as exc:
        tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
        if pickler is not None:
            try:
                pickle.loads(_dumps(exc, pickler))
            except Exception:
                exc = RuntimeError(f"{type(exc).__module__}.{type(exc).__qualname__}: {exc} "
                                   "(the original exception cannot be pickled back)")
        return index, _TaskFailure(exc, tb)


def _raise_task_error(failure: _TaskFailure, index: int, n: int, chunk) -> None:
    exc = failure.exc
    _add_note(exc, _chunk_note(index, n, chunk))
    if exc.__cause__ is None and failure.traceback:
        exc.__cause__ = _RemoteTraceback(f"\n\"\"\"\n{failure.traceback}\"\"\"")
    raise exc


def _run_serial(fn, chunks: list, bar) -> list:
    results = []
    n = len(chunks)
    for i, chunk in enumerate(chunks):
        try:
            results.append(fn(chunk))
        except Exception as exc:
            _add_note(exc, _chunk_note(i, n, chunk))
            raise
        bar.update(1)
    return results


def _run_joblib(fn, chunks: list, n_jobs: int, timeout: float, bar) -> list:
    try:
        from joblib import Parallel, delayed
    except ImportError as exc:
        raise ImportError("`executor='processes'` or an int n_jobs needs joblib: "
                          "pip install 'transync[distributed]' (or joblib)") from exc
    n = len(chunks)
    n_jobs = min(_n_workers("joblib", n_jobs), n)      # one per CPU and per chunk at most
    if n_jobs == 1:     # joblib would run it here anyway (sequential backend), warning that
        return _run_serial(fn, chunks, bar)            # it ignores `timeout`
    kwargs = dict(n_jobs=n_jobs, backend="loky", timeout=timeout, batch_size=1)
    try:
        parallel = Parallel(return_as="generator_unordered", **kwargs)
    except (TypeError, ValueError):     # joblib < 1.4: results all at once
        parallel = Parallel(**kwargs)
    results: list = [None] * n
    tasks = (delayed(_run_chunk)(fn, i, c, "cloudpickle") for i, c in enumerate(chunks))
    gen = None
    try:
        try:
            gen = parallel(tasks)       # a generator; a list (all done) with joblib < 1.4
            items = iter(gen)
        except Exception as exc:
            raise _joblib_error(exc, n_jobs, n, timeout) from exc
        while True:
            try:
                i, value = next(items)
            except StopIteration:
                break
            except Exception as exc:
                raise _joblib_error(exc, n_jobs, n, timeout) from exc
            _store(results, i, value, n, chunks, bar)
    finally:
        close = getattr(gen, "close", None)
        if close is not None:
            with warnings.catch_warnings():     # joblib says it cancelled the tasks: we asked
                warnings.filterwarnings("ignore", message=".*still being processed",
                                        category=UserWarning)
                close()     # stopped early: joblib aborts and stops its workers
    return results


def _joblib_error(exc: BaseException, n_jobs: int, n: int, timeout: float) -> ExecutorError:
    return ExecutorError(f"{_label('joblib', n_jobs)} failed while running {n} "
                         f"chunks: {_describe_exc(exc, timeout)}")


def _store(results: list, i: int, value, n: int, chunks: list, bar) -> None:
    if isinstance(value, _TaskFailure):
        _raise_task_error(value, i, n, chunks[i])
    results[i] = value
    bar.update(1)


def _run_futures(fn, chunks: list, executor, timeout: float, bar, pickler) -> list:
    n = len(chunks)
    futs: list = []
    try:
        try:
            for i, chunk in enumerate(chunks):
                futs.append(executor.submit(_run_chunk, fn, i, chunk, pickler))
        except Exception as exc:
            raise ExecutorError(f"{_label('futures', executor)} refused chunk {len(futs)} of "
                                f"{n}: {type(exc).__name__}: {exc}") from exc
        if all(isinstance(f, cf.Future) for f in futs):
            return _collect_cf(futs, chunks, executor, timeout, bar)
        return _collect_in_order(futs, chunks, executor, timeout, bar)
    except BaseException:
        for f in futs:
            _cancel(f)
        raise


def _collect_cf(futs: list, chunks: list, executor, timeout: float, bar) -> list:
    n = len(chunks)
    results: list = [None] * n
    pending = set(futs)
    while pending:
        done, pending = cf.wait(pending, timeout=timeout, return_when=cf.FIRST_COMPLETED)
        if not done:
            raise _stalled(executor, len(pending), n, timeout)
        for f in done:
            i, value = _unwrap(f, executor, n, timeout)
            _store(results, i, value, n, chunks, bar)
    return results


def _collect_in_order(futs: list, chunks: list, executor, timeout: float, bar) -> list:
    """Futures of unknown type: ``result(timeout)`` one after the other."""
    n = len(chunks)
    results: list = [None] * n
    for f in futs:
        i, value = _unwrap(f, executor, n, timeout)
        _store(results, i, value, n, chunks, bar)
    return results


def _unwrap(f, executor, n: int, timeout: float):
    try:
        out = f.result(timeout=timeout)
    except (TimeoutError, cf.TimeoutError):
        raise _stalled(executor, None, n, timeout) from None
    except BaseException as exc:
        if isinstance(exc, (KeyboardInterrupt, SystemExit)):
            raise
        raise ExecutorError(f"{_label('futures', executor)} failed to run a chunk: "
                            f"{type(exc).__name__}: {exc}") from exc
    if (not isinstance(out, tuple) or len(out) != 2 or not isinstance(out[0], int)
            or not 0 <= out[0] < n):
        # not what _run_chunk returns: the executor ran something else, or altered the result
        raise ExecutorError(f"{_label('futures', executor)} returned {short_repr(out, 60)} for "
                            f"a chunk, not the (index, result) pair of the submitted function; "
                            f"does its submit(fn, *args) run fn(*args)?")
    return out


def _cancel(f) -> None:
    try:
        f.cancel()
    except Exception:   # a dead client or pool: nothing left to cancel
        pass


def _stalled(executor, n_pending, n: int, timeout: float) -> ExecutorError:
    left = f"{n_pending} of {n}" if n_pending is not None else f"some of {n}"
    return ExecutorError(
        f"no chunk finished within timeout={timeout:g} s on {_label('futures', executor)} "
        f"({left} chunks outstanding, now cancelled): its workers are dead, stuck or "
        f"overloaded; pass a larger `timeout` if chunks legitimately take longer")


# --------------------------------------------------------------------------- Dask

def _check_dask_client(client, timeout: float) -> dict:
    """Check that a Dask client is connected and its scheduler answers; return its identity."""
    deadline = time.monotonic() + timeout
    grace = time.monotonic() + min(timeout, _DASK_RECONNECT_GRACE)
    status = getattr(client, "status", None)
    while status in ("connecting", "newly-created") and time.monotonic() < grace:
        time.sleep(0.05)
        status = getattr(client, "status", None)
    if status != "running":
        raise ExecutorError(f"the Dask client is not connected to a scheduler (client.status="
                            f"{status!r}): its cluster is closed or unreachable; start a new "
                            f"cluster and client")
    remaining = max(deadline - time.monotonic(), 0.1)
    try:
        info = client.sync(client.scheduler.identity, callback_timeout=remaining)
    except Exception as exc:
        raise ExecutorError(f"the Dask scheduler at {_dask_address(client)} did not answer "
                            f"within {timeout:g} s ({type(exc).__name__}: {exc}); it is dead, "
                            f"unreachable or overloaded") from exc
    return info if isinstance(info, dict) else {}


def _dask_address(client) -> str:
    try:
        return str(client.scheduler.address)
    except Exception:
        return "(unknown address)"


def _run_dask(fn, chunks: list, client, timeout: float, bar) -> list:
    from distributed import wait

    n = len(chunks)
    futs: list = []
    try:
        try:
            # scatter once: fn (possibly a partial holding large arrays) and the chunks travel
            # to the workers once each, not inside every task (and no "large graph" warning)
            fn_future = client.scatter(fn, hash=False, timeout=timeout)
            chunk_futures = client.scatter(chunks, hash=False, timeout=timeout)
            futs = [client.submit(_run_chunk, fn_future, i, c, "cloudpickle", pure=False)
                    for i, c in enumerate(chunk_futures)]
        except Exception as exc:
            raise ExecutorError(f"the Dask client could not submit the {n} chunks: "
                                f"{type(exc).__name__}: {exc}") from exc
        index = {f.key: i for i, f in enumerate(futs)}
        results: list = [None] * n
        pending = list(futs)
        while pending:
            try:
                done, not_done = wait(pending, timeout=timeout, return_when="FIRST_COMPLETED")
            except (TimeoutError, cf.TimeoutError):
                raise _stalled(client, len(pending), n, timeout) from None
            except Exception as exc:
                raise ExecutorError(f"waiting on the Dask scheduler at {_dask_address(client)}"
                                    f" failed: {type(exc).__name__}: {exc}") from exc
            pending = list(not_done)
            for f in done:
                if f.status != "finished":
                    try:
                        f.result(timeout=timeout)
                        detail = f"status {f.status!r}"
                    except Exception as exc:
                        detail = f"{type(exc).__name__}: {exc}"
                    raise ExecutorError(f"Dask could not run chunk {index[f.key]} of {n} "
                                        f"(lost or killed worker, or a result that does not "
                                        f"deserialize): {detail}")
                i, value = _unwrap(f, client, n, timeout)
                _store(results, i, value, n, chunks, bar)
        return results
    except BaseException:
        for f in futs:
            _cancel(f)
        raise


# --------------------------------------------------------------------------- small helpers

def _label(kind: str, handle=None) -> str:
    if kind == "joblib":
        return "joblib (loky)" if handle is None else f"joblib (loky, n_jobs={handle})"
    if kind == "dask":
        return "Dask"
    if kind == "futures" and handle is not None:
        if _is_dask_client(handle):
            return f"the Dask cluster at {_dask_address(handle)}"
        return type(handle).__name__
    return kind


def _short(obj) -> str:
    r = reprlib.Repr()
    r.maxother = r.maxstring = 60
    if isinstance(obj, np.ndarray):
        return f"array of shape {obj.shape} and dtype {obj.dtype}"
    return f"{type(obj).__name__} {r.repr(obj)}"


def _chunk_note(index: int, n: int, chunk) -> str:
    detail = _short(chunk)
    if isinstance(chunk, np.ndarray) and chunk.ndim == 1 and chunk.dtype.kind in "iu" \
            and chunk.size:
        items = chunk.tolist()
        shown = str(items) if len(items) <= 6 else f"[{items[0]}, {items[1]}, ..., {items[-1]}]"
        detail += f", items {shown}"
    return f"in map_chunks: raised by fn on chunk {index} of {n} ({detail})"


def _add_note(exc: BaseException, note: str) -> None:
    if hasattr(exc, "add_note"):
        exc.add_note(note)
    else:   # Python 3.10: keep the note where 3.11 would put it
        notes = getattr(exc, "__notes__", None)
        try:
            exc.__notes__ = [*(notes or []), note]
        except (AttributeError, TypeError):
            pass


def _describe_exc(exc: BaseException, timeout: float) -> str:
    import multiprocessing

    if isinstance(exc, (TimeoutError, multiprocessing.TimeoutError)):
        return (f"a chunk did not finish within timeout={timeout:g} s (its worker was stopped);"
                f" pass a larger `timeout` if chunks legitimately take longer")
    return f"{type(exc).__name__}: {exc}"


def _demo_chunk(chunk: Sequence[int]) -> np.ndarray:
    """Deterministic per-item work used by the examples and tests: one seeded draw per index.

    Picklable (module level, importable in worker processes); the result of an item depends on
    the item only, so any chunking gives the same concatenated result.
    """
    idx = np.asarray(chunk, dtype=np.int64).ravel()
    if idx.size and idx.min() < 0:
        raise ValueError(f"`chunk` must hold non-negative indices, got {int(idx.min())}")
    out = np.empty(idx.size)
    for k, i in enumerate(idx):
        out[k] = np.random.default_rng(int(i)).standard_normal() + math.sqrt(i)
    return out
