"""Resumable experiment runner: sweeps x methods x trials, one SQLite row per finished trial.

An :class:`Experiment` is a list of :class:`Sweep` s (one swept variable each, a set of fixed
parameters, the methods to compare) and a ``trial(config, rng) -> dict`` function. The runner

* derives every trial's random generator from ``(experiment, sweep, value, trial, seed)`` — not
  from the method, so all methods of a trial see the same generated problem;
* skips trials already in ``DIR/results.sqlite`` (rerunning resumes) and commits each trial in its
  own transaction as soon as it finishes (a killed run loses at most the trials in flight); the
  configuration key covers everything that changes a trial's result, the ``seed`` included;
* keeps ``results.sqlite`` self-contained: a rollback journal (no ``-wal`` file), so the file
  alone holds every committed trial, after a normal exit as after ``kill -9``;
* holds an exclusive lock on ``DIR`` for the whole run (a second run on the same folder is
  refused with :class:`~transync.exceptions.ExperimentStoreError`), and reports a corrupted
  store with its path and a salvage hint instead of touching it;
* runs serially or on a process pool (``workers``) whose processes ignore Ctrl-C (the parent
  stops them) and die with their parent, with a tqdm progress bar;
* summarizes mean and standard error per (sweep, value, method, metric), writes
  ``summary.csv``/``summary.md`` and plots one panel per sweep and metric.

Examples
--------
>>> import tempfile
>>> from transync.experiments import Experiment, Sweep, run_experiment
>>> exp = Experiment(name="toy", trial=_toy_trial, trials=3, sweeps=[
...     Sweep(name="noise", variable="noise", values=[0.0, 0.5], methods=["a", "b"],
...           metrics=("error",))])
>>> with tempfile.TemporaryDirectory() as d:
...     report = run_experiment(exp, d, progress=False, plot=False)
...     again = run_experiment(exp, d, progress=False, plot=False)
>>> report.n_new, again.n_new, len(again.records)
(12, 0, 12)
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import math
import numbers
import os
import re
import signal
import sqlite3
import sys
import threading
import time
import traceback
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._progress import progress_bar
from .._validation import check_bool, check_int, check_path, short_repr
from ..exceptions import ExecutorError, ExperimentStoreError

__all__ = ["Experiment", "ExperimentReport", "ExperimentStore", "Sweep", "run_experiment",
           "summarize"]

#: an experiment's name names its figure on disk: no folder separators, not "." or ".."
_FILE_NAME = re.compile(r"(?![.]{1,2}$)[^/\\\x00]+")
#: Most trials per configuration and most worker processes a run takes (a plan of 10**12
#: trials never finished planning; 10**6 workers would fork without end).
MAX_TRIALS = 10**6
MAX_WORKERS = 256
#: longest experiment name (in UTF-8 bytes): it names ``<name>.png`` and the system's file
#: names stop at 255 bytes (a 300-character name failed with a raw OSError after every trial)
_MAX_NAME_BYTES = 200


def _check_json(value, name: str, depth: int = 0) -> None:
    """A configuration value must be plain data (None, bool, numbers, str, NumPy scalars and
    arrays, lists, tuples and dicts of them with str or number keys): its text is the trial's
    key in the store. An object whose text is its address (``<Opt object at 0x7f...>``) made a new key in
    every process, so a rerun repeated every trial."""
    if value is None or isinstance(value, (str, bool, numbers.Number, np.generic)):
        return
    if depth > 32:
        raise ValueError(f"`{name}` is nested more than 32 levels deep")
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "biufc":
            return
        raise TypeError(f"`{name}` must be plain data (a configuration is stored as JSON), got "
                        f"an array of dtype {value.dtype}")
    if isinstance(value, Mapping):
        for k, v in value.items():
            if not (k is None or isinstance(k, (str, int, float))):   # JSON's keys (as text)
                raise TypeError(f"`{name}` must have str or number keys (a configuration is "
                                f"stored as JSON), got {k!r:.40}")
            _check_json(v, f"{name}[{k!r}]", depth + 1)
        return
    if isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _check_json(v, f"{name}[{i}]", depth + 1)
        return
    raise TypeError(f"`{name}` must be plain data (None, bool, numbers, str, arrays, lists or "
                    f"dicts of them; a configuration is stored as JSON), got "
                    f"{type(value).__name__} {short_repr(value, 40)}")


def _check_name(value, name: str) -> str:
    if not isinstance(value, str) or not value:
        raise TypeError(f"`{name}` must be a non-empty string, got {value!r:.60}")
    return value


@dataclass(frozen=True)
class Sweep:
    """One swept variable: ``config = base | {variable: value, "method": method}``.

    Parameters
    ----------
    name : str
        Name of the sweep (a panel of the figure, a section of ``summary.md``).
    variable : str
        The configuration key the sweep varies.
    values : sequence
        The values of ``variable``, in plotting order (numbers or strings; JSON-serializable).
    methods : sequence of str
        The methods compared at each value (``config["method"]``).
    base : mapping, optional
        The fixed part of every configuration of the sweep.
    metrics : sequence of str, default=("accuracy",)
        The metrics of the trial's result that are summarized and plotted (``"seconds"``, the
        time per trial, is always added).
    xlabel : str, optional
        Label of the figure's x axis (default: ``variable``).

    Examples
    --------
    >>> from transync.experiments import Sweep
    >>> sweep = Sweep(name="noise", variable="noise", values=[0.0, 0.1], methods=["a"],
    ...               base={"n": 10})
    >>> [config for _, _, config in sweep.configs()]
    [{'n': 10, 'noise': 0.0, 'method': 'a'}, {'n': 10, 'noise': 0.1, 'method': 'a'}]
    """

    name: str
    variable: str
    values: Sequence
    methods: Sequence[str]
    base: Mapping = field(default_factory=dict)
    metrics: Sequence[str] = ("accuracy",)
    xlabel: str | None = None

    def __post_init__(self):
        for attr in ("name", "variable"):
            _check_name(getattr(self, attr), f"Sweep.{attr}")
        if self.variable == "method":
            raise ValueError("`Sweep.variable` must not be 'method': every configuration's "
                             "'method' is one of `Sweep.methods` (sweep methods there)")
        for attr in ("values", "methods", "metrics"):
            seq = getattr(self, attr)
            if (isinstance(seq, (str, bytes)) or not isinstance(seq, (Sequence, np.ndarray))
                    or (isinstance(seq, np.ndarray) and seq.ndim == 0)):
                raise TypeError(f"`Sweep.{attr}` must be a list, got {type(seq).__name__}")
            if attr != "metrics" and len(seq) == 0:
                raise ValueError(f"`Sweep.{attr}` must not be empty (sweep {self.name!r})")
            for k, v in enumerate(seq):
                _check_json(v, f"Sweep.{attr}[{k}]")
            keys = [json.dumps(v, default=str) for v in seq]
            if len(set(keys)) != len(keys):
                dup = next(v for v, k in zip(seq, keys) if keys.count(k) > 1)
                raise ValueError(f"`Sweep.{attr}` must not repeat an entry (it would run and "
                                 f"count twice), got {dup!r} more than once in sweep "
                                 f"{self.name!r}")
        for attr in ("methods", "metrics"):
            for item in getattr(self, attr):
                _check_name(item, f"Sweep.{attr}")
        if not isinstance(self.base, Mapping):
            raise TypeError(f"`Sweep.base` must be a mapping, got {type(self.base).__name__}")
        if not all(isinstance(k, str) for k in self.base):
            raise TypeError(f"`Sweep.base` keys must be str (configuration names), got "
                            f"{[k for k in self.base if not isinstance(k, str)][:5]!r}")
        for k, v in self.base.items():
            _check_json(v, f"Sweep.base[{k!r}]")
        if self.xlabel is not None and not isinstance(self.xlabel, str):
            raise TypeError(f"`Sweep.xlabel` must be a string or None, got {self.xlabel!r}")

    def configs(self):
        for value in self.values:
            for method in self.methods:
                yield value, method, {**dict(self.base), self.variable: value, "method": method}


@dataclass(frozen=True)
class Experiment:
    """A named set of sweeps sharing one ``trial(config, rng) -> {metric: value}`` function.

    Parameters
    ----------
    name : str
        Name of the experiment (key of the stored trials, name of the figure).
    sweeps : sequence of Sweep
        The swept variables.
    trial : callable
        ``trial(config, rng) -> {metric: value}``: one random problem solved by
        ``config["method"]``; ``rng`` is a :class:`numpy.random.Generator` derived from the
        experiment, sweep, value, trial index and seed (the same for every method). It must be
        picklable (a module-level function) to run on several workers.
    trials : int, default=20
        Trials per configuration, 1 to 10**6 (:func:`run_experiment` may override it).
    description : str, default=""
        One line shown by ``transync experiment --list``.
    finish : callable, optional
        ``finish(records, summary, out_dir) -> list of paths``: figures and tables beyond the
        standard plot (e.g. a thesis table built from the stored records); run with ``plot``.

    Examples
    --------
    >>> from transync.experiments import Experiment, Sweep
    >>> def trial(config, rng):
    ...     return {"accuracy": 1.0 - config["noise"]}
    >>> exp = Experiment(name="toy", trial=trial, trials=2, sweeps=[
    ...     Sweep(name="noise", variable="noise", values=[0.0, 0.5], methods=["a"])])
    >>> exp.name, len(exp.sweeps), exp.trials
    ('toy', 1, 2)
    """

    name: str
    sweeps: Sequence[Sweep]
    trial: Callable[[dict, np.random.Generator], Mapping[str, float]]
    trials: int = 20
    description: str = ""
    finish: Callable[[list, list, Path], Sequence[Path]] | None = None

    def __post_init__(self):
        _check_name(self.name, "Experiment.name")
        if not _FILE_NAME.fullmatch(self.name):
            raise ValueError(f"`Experiment.name` names its figure file: no '/', '\\' or NUL, "
                             f"not '.' or '..', got {self.name!r}")
        if len(self.name.encode("utf-8", "surrogatepass")) > _MAX_NAME_BYTES:
            raise ValueError(f"`Experiment.name` names its figure file: at most "
                             f"{_MAX_NAME_BYTES} bytes, got {len(self.name)} characters "
                             f"({self.name[:40]!r}...)")
        if (isinstance(self.sweeps, (str, bytes)) or not isinstance(self.sweeps, Sequence)
                or not self.sweeps or not all(isinstance(s, Sweep) for s in self.sweeps)):
            raise TypeError(f"`Experiment.sweeps` must be a non-empty list of Sweep, got "
                            f"{self.sweeps!r:.80}")
        names = [s.name for s in self.sweeps]
        if len(set(names)) != len(names):
            raise ValueError(f"`Experiment.sweeps` must have distinct names, got {names}")
        if not callable(self.trial):
            raise TypeError(f"`Experiment.trial` must be callable (config, rng) -> metrics, got "
                            f"{type(self.trial).__name__}")
        check_int(self.trials, "Experiment.trials", minimum=1, maximum=MAX_TRIALS)
        if not isinstance(self.description, str):
            raise TypeError(f"`Experiment.description` must be a string, got "
                            f"{type(self.description).__name__}")
        if self.finish is not None and not callable(self.finish):
            raise TypeError(f"`Experiment.finish` must be callable or None, got "
                            f"{type(self.finish).__name__}")


@dataclass(frozen=True)
class ExperimentReport:
    """What a run produced: all stored records (old and new), the summary and output paths.

    Attributes
    ----------
    experiment : str
        Name of the experiment.
    records : list of dict
        The stored trials of this run's configurations and seed (earlier runs' included): dicts
        with keys ``sweep``, ``config``, ``trial``, ``metrics``, ``error`` (``None`` on
        success) and ``seconds``.
    summary : list of dict
        The rows of :func:`summarize` (also written to ``summary.csv`` and ``summary.md``).
    n_new : int
        Trials run by this call (the others were already stored).
    n_failed : int
        Trials of this call that raised (their error is stored in the record).
    out_dir : pathlib.Path
        The output folder.
    figure : pathlib.Path or None
        The figure written (``None`` when run with ``plot=False``).
    seconds : float
        Wall-clock time of the run.
    extra_files : tuple of pathlib.Path
        The files written by ``Experiment.finish``.
    n_other : int
        Trials in the store that belong to other configurations or seeds (not reported).

    Examples
    --------
    >>> import tempfile
    >>> from transync.experiments import Experiment, Sweep, run_experiment
    >>> def trial(config, rng):
    ...     return {"accuracy": 1.0 - config["noise"]}
    >>> exp = Experiment(name="toy", trial=trial, trials=2, sweeps=[
    ...     Sweep(name="noise", variable="noise", values=[0.0, 0.5], methods=["a"])])
    >>> with tempfile.TemporaryDirectory() as d:
    ...     report = run_experiment(exp, d, progress=False, plot=False)
    >>> report.n_new, report.n_failed, len(report.records), report.figure is None
    (4, 0, 4, True)
    """

    experiment: str
    records: list
    summary: list
    n_new: int
    n_failed: int
    out_dir: Path
    figure: Path | None
    seconds: float
    extra_files: tuple = ()
    n_other: int = 0


def _config_key(sweep: str, config: Mapping, seed: int) -> str:
    """Hash of everything that changes a trial's result besides its index: sweep, config, seed."""
    blob = json.dumps({"sweep": sweep, "config": dict(config), "seed": int(seed)},
                      sort_keys=True, default=str)
    return hashlib.sha1(blob.encode()).hexdigest()[:16]


def _trial_seed(experiment: str, sweep: str, value, trial: int, seed: int) -> int:
    blob = json.dumps([experiment, sweep, value, trial, seed], default=str).encode()
    return int.from_bytes(hashlib.sha256(blob).digest()[:8], "little")


_SALVAGE = ("it was left untouched; to salvage its rows run `sqlite3 {path} .recover > "
            "salvage.sql`, or move it away to start afresh")


class ExperimentStore:
    """SQLite store of finished trials, keyed by (experiment, configuration hash, trial index).

    The database uses a rollback journal with ``synchronous=FULL``: every committed trial is in
    ``results.sqlite`` itself (no ``-wal`` file to copy along), at the price of one ``fsync`` per
    trial. A file that is not a readable SQLite database raises
    :class:`~transync.exceptions.ExperimentStoreError` naming it; it is never overwritten.

    Parameters
    ----------
    path : str or path-like
        The database file (created with its folder when missing).

    Raises
    ------
    ExperimentStoreError
        The folder or file cannot be written, or the file is not a readable experiment store.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from transync.experiments import ExperimentStore
    >>> with tempfile.TemporaryDirectory() as d:
    ...     store = ExperimentStore(Path(d) / "results.sqlite")
    ...     store.add("toy", "key", 0, "noise", {"noise": 0.0}, {"accuracy": 1.0}, None, 0.1)
    ...     rows = store.records("toy")
    ...     store.close()
    >>> rows[0]["metrics"], rows[0]["error"]
    ({'accuracy': 1.0}, None)
    """

    def __init__(self, path) -> None:
        self.path = check_path(path, "path")
        _prepare_folder(self.path.parent)
        self._con = None
        with self._guard(opening=True):
            self._con = sqlite3.connect(str(self.path), timeout=30)
            # a store written by an older version in WAL mode is checkpointed into the main file
            self._con.execute("PRAGMA journal_mode=TRUNCATE")
            self._con.execute("PRAGMA synchronous=FULL")
            check = self._con.execute("PRAGMA quick_check").fetchone()[0]
            if check != "ok":
                raise sqlite3.DatabaseError(f"integrity check failed: {check}")
            self._con.execute("""CREATE TABLE IF NOT EXISTS trials (
                experiment TEXT NOT NULL, config_hash TEXT NOT NULL, trial INTEGER NOT NULL,
                sweep TEXT NOT NULL, config TEXT NOT NULL, metrics TEXT NOT NULL,
                error TEXT, seconds REAL NOT NULL, finished REAL NOT NULL,
                PRIMARY KEY (experiment, config_hash, trial))""")
            self._con.commit()

    @contextlib.contextmanager
    def _guard(self, *, opening: bool = False):
        """Turn SQLite errors into :class:`ExperimentStoreError` naming the file; a closed
        store (after :meth:`close` or an error) says so."""
        if self._con is None and not opening:
            raise ExperimentStoreError(f"the experiment store {self.path} is closed (after "
                                       "close() or an error); open a new ExperimentStore")
        try:
            yield
        except sqlite3.DatabaseError as exc:
            if self._con is not None:
                self._con.close()
                self._con = None
            msg = str(exc)
            if isinstance(exc, sqlite3.OperationalError) and self.path.is_dir():
                raise ExperimentStoreError(
                    f"cannot open the experiment store {self.path}: it is a folder, not a file; "
                    "move it away or choose another --out") from exc
            if isinstance(exc, sqlite3.OperationalError) and (
                    "unable to open" in msg or "readonly" in msg or "read-only" in msg):
                raise ExperimentStoreError(
                    f"cannot write the experiment store {self.path} ({msg}): the folder "
                    f"{self.path.parent} or the file is not writable") from exc
            if "full" in msg or "disk I/O" in msg:
                raise ExperimentStoreError(
                    f"cannot write the experiment store {self.path} ({msg}): is the disk full? "
                    "The stored trials are intact; free space and rerun to resume") from exc
            if isinstance(exc, sqlite3.OperationalError) and "locked" in msg:
                raise ExperimentStoreError(
                    f"the experiment store {self.path} is locked by another process ({msg})"
                ) from exc
            raise ExperimentStoreError(
                f"{self.path} is not a readable experiment store ({msg}); "
                + _SALVAGE.format(path=self.path)) from exc

    def done(self, experiment: str) -> set[tuple[str, int]]:
        """The (configuration, trial) keys stored *without* an error: a failed trial is run
        again by the next run (its row is replaced), as the CLI's "rerun to retry" says."""
        _check_name(experiment, "experiment")      # not an SQLite error blaming the file
        with self._guard():
            rows = self._con.execute(
                "SELECT config_hash, trial FROM trials WHERE experiment = ? AND error IS NULL",
                (experiment,))
            return {(h, int(t)) for h, t in rows}

    def add(self, experiment: str, key: str, trial: int, sweep: str, config: Mapping,
            metrics: Mapping, error: str | None, seconds: float) -> None:
        """Store one finished trial (replacing a stored one with the same key); the arguments
        are checked before the transaction, so a bad one leaves the store open and intact."""
        row = _check_row(experiment, key, trial, sweep, config, metrics, error, seconds)
        with self._guard(), self._con:  # one transaction per trial
            self._con.execute(
                "INSERT OR REPLACE INTO trials VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                row + (time.time(),))

    def records(self, experiment: str, keys=None) -> list[dict]:
        """Stored trials of ``experiment``; only those whose configuration hash is in ``keys``
        when given (a run reports the trials of its own configurations and seed)."""
        _check_name(experiment, "experiment")      # not an SQLite error blaming the file
        with self._guard():
            rows = self._con.execute(
                "SELECT sweep, config, trial, metrics, error, seconds, config_hash FROM trials "
                "WHERE experiment = ? ORDER BY sweep, config_hash, trial", (experiment,))
            return [dict(sweep=s, config=config, trial=t, metrics=metrics, error=e, seconds=sec)
                    for s, c, t, m, e, sec, h in rows if keys is None or h in keys
                    for config, metrics in [self._decode(experiment, s, h, t, c, m)]]

    def _decode(self, experiment, sweep, key, trial, config, metrics) -> tuple[dict, dict]:
        """A stored row's config and metrics, or an error naming the store and the row (a row
        edited or damaged outside transync: text that is not JSON, values of the wrong type)."""
        where = (f"the experiment store {self.path}, row (experiment={experiment!r}, "
                 f"sweep={sweep!r}, config hash {str(key)[:12]}, trial={trial})")
        try:
            c, m = json.loads(config), json.loads(metrics)
        except (TypeError, ValueError) as exc:
            raise ExperimentStoreError(f"{where} does not hold JSON ({exc}); delete that row or "
                                       + _SALVAGE.format(path=self.path)) from None
        if not isinstance(c, dict) or not isinstance(m, dict) or not all(
                v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))
                for v in m.values()):
            raise ExperimentStoreError(f"{where}: 'config' must be a JSON object and 'metrics' "
                                       "one of numbers; delete that row or "
                                       + _SALVAGE.format(path=self.path))
        return c, m

    def close(self):
        if self._con is not None:
            with contextlib.suppress(sqlite3.Error):
                self._con.execute("PRAGMA journal_mode=DELETE")   # remove the empty journal
            self._con.close()
            self._con = None


def _check_row(experiment, key, trial, sweep, config, metrics, error, seconds) -> tuple:
    """The columns of one trial row, each argument checked by name."""
    for name, v in (("experiment", experiment), ("key", key), ("sweep", sweep)):
        if not isinstance(v, str) or not v:
            raise TypeError(f"`{name}` must be a non-empty str, got {type(v).__name__} {v!r:.60}")
    if isinstance(trial, bool) or not isinstance(trial, numbers.Integral):
        raise TypeError(f"`trial` must be an int, got {type(trial).__name__} {trial!r:.60}")
    if not 0 <= trial < 2**63:
        raise ValueError(f"`trial` must lie in [0, 2**63), got {trial!r:.60}")
    if not isinstance(config, Mapping) or not all(isinstance(k, str) for k in config):
        raise TypeError(f"`config` must be a dict with str keys, got {config!r:.80}")
    if not isinstance(metrics, Mapping):
        raise TypeError(f"`metrics` must be a dict of numbers, got {type(metrics).__name__}")
    values = {}
    for k, v in metrics.items():          # bools count 0/1, as in a trial's own metrics
        if not isinstance(k, str) or not isinstance(v, numbers.Real):
            raise TypeError(f"`metrics` must map str names to real numbers, got {k!r}: "
                            f"{type(v).__name__} {short_repr(v, 40)}")
        try:
            values[k] = float(v)
        except OverflowError:
            raise ValueError(f"`metrics[{k!r}]` must fit in float64, got an integer beyond "
                             "it") from None
    if error is not None and not isinstance(error, str):
        raise TypeError(f"`error` must be None or a str, got {type(error).__name__}")
    if isinstance(seconds, bool) or not isinstance(seconds, numbers.Real):
        raise TypeError(f"`seconds` must be a number, got {type(seconds).__name__}")
    try:
        sec = float(seconds)
    except OverflowError:
        sec = math.inf
    if not (math.isfinite(sec) and sec >= 0):
        raise ValueError(f"`seconds` must be a finite number >= 0, got {short_repr(seconds, 40)}")
    return (experiment, key, int(trial), sweep, json.dumps(dict(config), default=str),
            json.dumps(values), error, sec)


def _prepare_folder(folder: Path) -> None:
    """Create ``folder`` if needed and check that it can be written, naming it otherwise."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError as exc:
        raise ExperimentStoreError(f"the output folder {folder} exists and is not a folder") \
            from exc
    except OSError as exc:
        raise ExperimentStoreError(f"cannot create the output folder {folder}: "
                                   f"{exc.strerror or exc}") from exc
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ExperimentStoreError(f"the output folder {folder} is not writable; choose another "
                                   "output folder")


_HELD_LOCKS: set[str] = set()      # folders locked by this process (POSIX locks do not conflict
                                   # within one process)


class _FolderLock:
    """Exclusive lock on an output folder for the length of a run (``lockf``; ``msvcrt``).

    A second run on the same folder, from another process or this one, fails at once with
    :class:`ExperimentStoreError` instead of computing the same trials twice. The lock belongs
    to the process (worker processes forked later do not hold it), so it is released the moment
    the run ends or is killed. The lock file is removed when the run ends.
    """

    def __init__(self, folder: Path):
        self.path = folder / "results.sqlite.lock"
        self._fh = None

    def _busy(self, holder) -> ExperimentStoreError:
        return ExperimentStoreError(
            f"another run (pid {holder}) is using the output folder {self.path.parent}; wait "
            "for it to finish, or choose another output folder")

    def __enter__(self):
        key = os.path.realpath(self.path)
        if key in _HELD_LOCKS:
            raise self._busy(os.getpid())
        for _attempt in range(5):
            try:
                fh = open(self.path, "a+")
            except OSError as exc:
                raise ExperimentStoreError(f"cannot create the lock file {self.path}: "
                                           f"{exc.strerror or exc}; is the output folder "
                                           "writable?") from exc
            if not _try_lock(fh):
                fh.seek(0)
                holder = fh.read().strip() or "unknown"
                fh.close()
                raise self._busy(holder)
            try:  # the file we locked must still be the one at self.path (see __exit__)
                same = os.path.samestat(os.fstat(fh.fileno()), os.stat(self.path))
            except OSError:
                same = False
            if same:
                fh.seek(0)
                fh.truncate()
                fh.write(str(os.getpid()))
                fh.flush()
                self._fh = fh
                self._key = key
                _HELD_LOCKS.add(key)
                return self
            fh.close()
        raise ExperimentStoreError(f"cannot lock the output folder {self.path.parent}")

    def __exit__(self, *exc):
        if self._fh is not None:
            with contextlib.suppress(OSError):
                os.unlink(self.path)       # while still held: no one can lock a stale file
            self._fh.close()               # closing releases the lock
            self._fh = None
            _HELD_LOCKS.discard(self._key)
        return False


def _try_lock(fh) -> bool:
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        import msvcrt

        try:
            fh.seek(0)
            msvcrt.locking(fh.fileno(), msvcrt.LK_NBLCK, 1)
            return True
        except OSError:
            return False
    try:  # a POSIX record lock: owned by this process, not inherited by forked workers
        fcntl.lockf(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except OSError as exc:
        if exc.errno in (errno.EAGAIN, errno.EACCES):
            return False                  # held by another run
        raise ExperimentStoreError(
            f"cannot lock the output folder {Path(fh.name).parent}: the file system does not "
            f"support locks ({exc.strerror or exc}); choose an output folder on a local disk"
        ) from exc


def _worker_init(parent_pid: int) -> None:
    """Pool initializer: ignore Ctrl-C (the parent stops the pool) and die with the parent.

    On Linux ``prctl(PR_SET_PDEATHSIG, SIGKILL)``; everywhere a daemon thread that exits the
    worker once the parent is gone (its parent process id changes).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL, 0, 0, 0)       # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):  # pragma: no cover - no libc
            pass
    def parent_gone() -> bool:
        # re-parented (to init or a subreaper), or the parent process no longer exists
        if os.getppid() == parent_pid:
            return False
        try:
            os.kill(parent_pid, 0)
        except ProcessLookupError:
            return True
        except OSError:
            return False
        return False

    if parent_gone():  # parent died before this worker started
        os._exit(1)

    def watch():
        while True:
            time.sleep(0.5)
            if parent_gone():
                os._exit(1)

    threading.Thread(target=watch, name="transync-parent-watch", daemon=True).start()


def _stop_pool(pool) -> None:
    """Cancel queued trials and terminate the workers (they would finish their trial first)."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        with contextlib.suppress(Exception):
            p.terminate()
    for p in procs:
        with contextlib.suppress(Exception):
            p.join(timeout=5)


def _checked_metrics(out) -> dict:
    """A trial's result as ``{name: float}``; anything else fails the trial, naming what."""
    if not isinstance(out, Mapping):
        raise TypeError(f"the trial must return a mapping {{metric: number}}, got "
                        f"{type(out).__name__}")
    metrics = {}
    for k, v in out.items():
        if not isinstance(k, str) or not isinstance(v, (numbers.Real, np.number, np.bool_)) \
                or isinstance(v, np.complexfloating):          # a bool counts as 0 / 1
            raise TypeError(f"the trial must return real numbers by metric name, got "
                            f"{k!r}: {v!r:.60}")
        metrics[k] = float(v)
    return metrics


def _run_one(trial_fn, config, seed):
    """Run one trial; never raises (errors are returned and stored)."""
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    n_warn = 0
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            metrics = _checked_metrics(trial_fn(dict(config), rng))
        n_warn = len(caught)
        error = None
    except Exception:  # noqa: BLE001 - a failed trial is recorded, the run goes on
        metrics, error = {}, traceback.format_exc(limit=5)
    seconds = time.perf_counter() - t0
    metrics.setdefault("seconds", seconds)
    metrics.setdefault("warnings", n_warn)
    return metrics, error, seconds


def run_experiment(experiment: Experiment, out_dir, *, trials: int | None = None,
                   workers: int = 1, seed: int = 0, progress: bool = True,
                   plot: bool = True) -> ExperimentReport:
    """Run (or resume) ``experiment``, storing trials in ``out_dir/results.sqlite``.

    Parameters
    ----------
    experiment : Experiment
        The sweeps and trial function to run.
    out_dir : str or path-like
        Folder for ``results.sqlite``, ``summary.csv``, ``summary.md`` and ``<name>.png``.
    trials : int, optional
        Trials per configuration, 1 to 10**6 (default: ``experiment.trials``), and at most
        10**6 over all configurations of the run.
    workers : int, default=1
        Processes, 1 to 256 (never more than the trials to run); 1 runs in this process.
    seed : int, default=0
        Changes every trial's random problem; part of the configuration key, so trials stored
        under another seed are neither skipped nor reported.
    progress : bool, default=True
        Show a tqdm progress bar.
    plot : bool, default=True
        Write the figure (and run ``experiment.finish``, whose files are listed in
        ``extra_files``).

    Returns
    -------
    ExperimentReport
        The records of this run's configurations (stored earlier or now), their summary, the
        number of new and failed trials and the files written.

    Raises
    ------
    ValueError, TypeError
        ``trials``, ``workers`` or ``seed`` not an integer in range; with ``workers > 1`` a
        trial function that cannot be pickled to the worker processes (checked before any
        work).
    ExecutorError
        A worker process died (a signal, ``os._exit``, the out-of-memory killer); the message
        names the trials it took with it. Every finished trial is stored.
    ExperimentStoreError
        ``out_dir`` cannot be created or written, another run holds it, it holds a FIFO, socket
        or device, or its ``results.sqlite`` is corrupted (reported with a salvage hint, never
        overwritten).
    KeyboardInterrupt
        Re-raised after the pool is stopped and the store closed; every finished trial is
        stored and rerunning resumes.

    Examples
    --------
    >>> import tempfile
    >>> from transync.experiments import Experiment, Sweep, run_experiment
    >>> def trial(config, rng):
    ...     return {"accuracy": 1.0 - config["noise"]}
    >>> exp = Experiment(name="toy", trial=trial, trials=2, sweeps=[
    ...     Sweep(name="noise", variable="noise", values=[0.0, 0.5], methods=["a", "b"])])
    >>> with tempfile.TemporaryDirectory() as d:
    ...     first = run_experiment(exp, d, progress=False, plot=False)
    ...     again = run_experiment(exp, d, progress=False, plot=False)  # resumes: nothing to do
    >>> first.n_new, again.n_new, len(again.records)
    (8, 0, 8)
    """
    if not isinstance(experiment, Experiment):
        raise TypeError(f"`experiment` must be an Experiment, got {type(experiment).__name__}")
    out = check_path(out_dir, "out_dir")
    n_trials = check_int(trials if trials is not None else experiment.trials, "trials", minimum=1,
                         maximum=MAX_TRIALS)
    configs = sum(len(sw.values) * len(sw.methods) for sw in experiment.sweeps)
    if configs * n_trials > MAX_TRIALS:
        # planning alone took minutes and tens of GB at 10**6 trials of 176 configurations
        raise ValueError(f"`trials`={n_trials} for the {configs} configurations of experiment "
                         f"{experiment.name!r} is {configs * n_trials} trials, more than "
                         f"{MAX_TRIALS} in one run: ask for at most "
                         f"{max(MAX_TRIALS // configs, 1)} trials")
    workers = check_int(workers, "workers", minimum=1, maximum=MAX_WORKERS)
    seed = check_int(seed, "seed")
    progress = check_bool(progress, "progress")
    plot = check_bool(plot, "plot")
    created = not out.exists()
    t_start = time.perf_counter()
    try:
        _prepare_folder(out)
    except ExperimentStoreError:
        if created:  # made by this call but unusable: leave nothing behind
            with contextlib.suppress(OSError):
                out.rmdir()
        raise
    remove_folder = False
    try:
        # Clean-up happens only while this run holds the lock: a run refused because another
        # holds the folder never touches that run's files. The lock covers the summary, plot
        # and `finish` files too: a second run waits for none of them half-written.
        with _FolderLock(out):
            try:
                _refuse_special_files(out)
                store = ExperimentStore(out / "results.sqlite")
                try:
                    todo, keys, n_other = _plan(experiment, store, n_trials, seed)
                    n_failed = _execute(experiment, store, todo, workers, progress)
                    records = store.records(experiment.name, keys)
                finally:
                    store.close()
            except BaseException:
                # a run that created the folder and stored nothing leaves no folder behind
                remove_folder = created and _remove_store_if_empty(out)
                raise
            summary, figure, extra = _write_outputs(experiment, records, out, plot)
    finally:
        if remove_folder:  # after the lock file is gone; fails harmlessly if a newcomer is in
            with contextlib.suppress(OSError):
                out.rmdir()
    return ExperimentReport(experiment.name, records, summary, len(todo), n_failed, out, figure,
                            time.perf_counter() - t_start, extra, n_other)


def _write_outputs(experiment: Experiment, records: list[dict], out: Path, plot: bool):
    """The summary files, the figure and ``experiment.finish``'s files: ``(summary, figure,
    extra files)``."""
    summary = summarize(experiment, records)
    _write_summary(summary, out)
    figure = None
    extra: tuple = ()
    if plot:
        from ._plot import plot_experiment

        figure = plot_experiment(experiment, summary, out / f"{experiment.name}.png")
        if experiment.finish is not None:
            written = experiment.finish(records, summary, out)
            paths = (list(written) if isinstance(written, Iterable)
                     and not isinstance(written, (str, bytes, os.PathLike)) else [None])
            if not all(isinstance(p, (str, os.PathLike)) for p in paths):
                raise TypeError(f"`Experiment.finish` must return the paths of the files it "
                                f"wrote (a list, possibly empty), got {short_repr(written, 60)}"
                                " (the trials are stored)")
            extra = tuple(Path(p) for p in paths)
    return summary, figure, extra


def _refuse_special_files(out: Path) -> None:
    """Refuse an output folder holding a FIFO, socket or device where a run writes its files
    (writing a summary into a FIFO blocked for ever, after every trial was computed)."""
    import stat

    for entry in out.iterdir():
        try:
            mode = entry.stat().st_mode            # follows links: what a write would open
        except OSError:
            continue                               # broken link: a write replaces it
        if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
            raise ExperimentStoreError(
                f"the output folder {out} holds {entry.name}, which is neither a file nor a "
                "folder (a FIFO, socket or device): a run could block writing into it; remove "
                "it or choose another output folder")


def _remove_store_if_empty(out: Path) -> bool:
    """Remove the store in ``out`` (a folder this run created and still locks) when it holds no
    trial; True when the folder may then be removed."""
    db = out / "results.sqlite"
    if db.exists():
        try:
            con = sqlite3.connect(str(db))
            try:
                n = con.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
            finally:
                con.close()
        except sqlite3.Error:
            return False
        if n:
            return False
        for name in ("results.sqlite", "results.sqlite-journal"):
            with contextlib.suppress(OSError):
                (out / name).unlink()
    return True


def _plan(experiment: Experiment, store: ExperimentStore, n_trials: int, seed: int):
    """The trials still to run, the configuration keys of this run, and how many stored trials
    of this experiment belong to other configurations or seeds (or to a store written before the
    seed entered the key): they are kept, not reported."""
    finished = store.done(experiment.name)
    todo, keys = [], set()
    for sw in experiment.sweeps:
        for value, _method, config in sw.configs():
            key = _config_key(sw.name, config, seed)
            keys.add(key)
            for t in range(n_trials):
                if (key, t) not in finished:
                    todo.append((sw.name, key, t, config,
                                 _trial_seed(experiment.name, sw.name, value, t, seed)))
    n_other = sum(1 for key, _t in finished if key not in keys)
    return todo, keys, n_other


def _execute(experiment: Experiment, store: ExperimentStore, todo: list, workers: int,
             progress: bool) -> int:
    """Run ``todo`` serially or on a process pool, storing each trial as it finishes."""
    n_failed = 0
    bar = progress_bar(len(todo), f"experiment {experiment.name}", enabled=progress,
                       unit="trial")
    try:
        if workers == 1 or len(todo) <= 1:
            for sw_name, key, t, config, s in todo:
                metrics, error, sec = _run_one(experiment.trial, config, s)
                store.add(experiment.name, key, t, sw_name, config, metrics, error, sec)
                n_failed += error is not None
                bar.update(1)
            return n_failed
        _check_picklable(experiment.trial)
        pool = ProcessPoolExecutor(max_workers=min(workers, len(todo)),   # no idle processes
                                   initializer=_worker_init, initargs=(os.getpid(),))
        pending = {}

        def store_done(futures) -> BaseException | None:
            """Store every finished trial of ``futures``; the first exception a future holds
            (a worker that died, an interrupt) is returned, after the others are stored."""
            nonlocal n_failed
            raised, lost = None, []
            for fut in futures:
                if not fut.done() or fut.cancelled():
                    continue
                sw_name, key, t, config, _s = pending.pop(fut)
                exc = fut.exception()
                if exc is not None:
                    raised = raised or exc
                    lost.append((sw_name, t, config))
                    continue
                metrics, error, sec = fut.result()
                store.add(experiment.name, key, t, sw_name, config, metrics, error, sec)
                n_failed += error is not None
                bar.update(1)
            return None if raised is None else _pool_error(raised, lost)

        it = iter(todo)

        def fill() -> None:
            """Keep two trials a worker submitted (no more: an interrupt cancels the rest)."""
            for item in it:
                pending[pool.submit(_run_one, experiment.trial, item[3], item[4])] = item
                if len(pending) >= 2 * workers:
                    break

        try:
            fill()
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                raised = store_done(done)
                if raised is not None:
                    raise raised
                fill()
        except BaseException:
            with contextlib.suppress(Exception):
                store_done(list(pending))         # what finished meanwhile is kept too
            _stop_pool(pool)
            raise
        pool.shutdown(wait=True)
        return n_failed
    finally:
        bar.close()


def _check_picklable(trial) -> None:
    """A trial that cannot reach the worker processes is refused before any work (a closure
    or a lambda raised pickling errors from the pool's feeder thread, with tracebacks)."""
    import pickle

    try:
        pickle.dumps(trial)
    except Exception as exc:  # noqa: BLE001 - any pickling failure means the same here
        raise TypeError(f"`Experiment.trial` must be picklable to run on worker processes "
                        f"(a module-level function, not a lambda or a closure), got "
                        f"{getattr(trial, '__qualname__', type(trial).__name__)!r}: {exc}; "
                        "or run it with workers=1") from None


def _pool_error(exc: BaseException, lost: list) -> BaseException:
    """The exception of the trials' futures as the run reports it: an interrupt as it is; a
    worker that died (``os._exit``, a signal, the out-of-memory killer) as an
    :class:`~transync.exceptions.ExecutorError` naming the trials it took with it (was a raw
    ``BrokenProcessPool``; the pool cannot tell which of them killed the worker)."""
    from concurrent.futures.process import BrokenProcessPool

    if isinstance(exc, BrokenProcessPool):
        sweep, trial, config = lost[0]
        err = ExecutorError(f"a worker process died (a signal, os._exit, the out-of-memory "
                            f"killer) with {len(lost)} trial(s) running or queued, the first "
                            f"sweep {sweep!r}, trial {trial}, config "
                            f"{short_repr(dict(config), 120)}; the finished trials are "
                            "stored, rerun to resume (with workers=1 a failing trial is "
                            "recorded with its error)")
        err.__cause__ = exc
        return err
    return exc


def mean_se(values) -> tuple[float, float, int]:
    """Mean, standard error and count of the finite values (None skipped); (nan, 0, 0) if none.

    Parameters
    ----------
    values : iterable of float or None
        The values; ``None``, NaN and infinite values are skipped.

    Returns
    -------
    mean : float
        Mean of the finite values (NaN if there are none).
    se : float
        Standard error of the mean, ``std(ddof=1) / sqrt(n)`` (0 for fewer than two values).
    n : int
        Number of finite values.

    Examples
    --------
    >>> from transync.experiments import mean_se
    >>> mean_se([1.0, 3.0, None, float("nan")])
    (2.0, 1.0, 2)
    >>> mean_se([])
    (nan, 0.0, 0)
    """
    if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
        raise TypeError(f"`values` must be an iterable of numbers, got {type(values).__name__}")
    vals = []
    for v in values:
        if v is None:
            continue
        if isinstance(v, (str, bytes)) or not isinstance(v, numbers.Real):
            raise TypeError(f"`values` must hold numbers (or None), got {type(v).__name__} "
                            f"{v!r:.40}")
        try:
            vals.append(float(v))
        except OverflowError:           # an int beyond float64: infinite, skipped as such
            vals.append(math.inf)
    vals = np.array(vals, dtype=float)
    vals = vals[np.isfinite(vals)]
    n = vals.size
    # values beyond 1e150 would overflow the squares: their statistics are taken scaled
    scale = float(np.abs(vals).max()) if n else 0.0
    scale = scale if scale > 1e150 else 1.0
    vals = vals / scale if scale != 1.0 else vals
    return (float(vals.mean()) * scale if n else math.nan,
            float(vals.std(ddof=1) / math.sqrt(n)) * scale if n > 1 else 0.0, int(n))


#: axis labels (with units) of the metrics the experiments report
METRIC_LABELS = {
    "accuracy": "accuracy (fraction of true matches)",
    "objective": "affinity score / ground truth's\n(> 1: the solver beats the truth)",
    "consistency": "output cycle consistency\n(1 - fraction of nodes disagreeing on triangles)",
    "input_consistency": "input cycle consistency\n(1 - fraction of nodes disagreeing on "
                         "triangles)",
    "cycle_error": "cycle error\n(fraction of inconsistent triangles)",
    "seconds": "time per trial (s)",
    "time": "time (s)",
    "mean_error": "mean corner error (px)",
    "max_error": "max corner error (px)",
    "acc_1px": "views with corner error < 1 px (fraction)",
    "brenner_ratio": "Brenner focus of the mean warp\n(estimated / true homographies)",
    "precision": "precision",
    "recall": "recall",
    "f1": "F1 score",
    "error": "error",
    "universe_ok": "universe size = truth\n(fraction of trials)",
    "universe_error": "estimated - true universe size",
    "capacity_cvr": "capacity CVR\n(violated / constraints)",
    "transitivity_cvr": "transitivity CVR\n(violated / constraints)",
    "soft_capacity_cvr": "soft capacity CVR\n(violated / constraints)",
    "soft_transitivity_cvr": "soft transitivity CVR\n(violated / constraints)",
    "capacity_cvvr": "capacity CVVR\n(violation / mass)",
    "transitivity_cvvr": "transitivity CVVR\n(violation / mass)",
    "soft_capacity_cvvr": "soft capacity CVVR\n(violation / mass)",
    "soft_transitivity_cvvr": "soft transitivity CVVR\n(violation / mass)",
    "capacity_acvv": "capacity ACVV\n(mean violation)",
    "transitivity_acvv": "transitivity ACVV\n(mean violation)",
    "soft_capacity_acvv": "soft capacity ACVV\n(mean violation)",
    "soft_transitivity_acvv": "soft transitivity ACVV\n(mean violation)",
}

def metric_label(metric: str, *, inline: bool = False) -> str:
    """The axis label of ``metric`` (:data:`METRIC_LABELS`, else the name with spaces);
    ``inline``: on one line (tables, headings).

    >>> metric_label("seconds"), metric_label("n_iter")
    ('time per trial (s)', 'n iter')
    """
    label = METRIC_LABELS.get(metric, metric.replace("_", " "))
    return label.replace("\n", " ") if inline else label


def value_label(value) -> str:
    """How a swept value is written in tables and tick labels (strings without JSON quotes)."""
    return value if isinstance(value, str) else json.dumps(value, default=str)


def summarize(experiment: Experiment, records: list[dict]) -> list[dict]:
    """Mean and standard error per (sweep, value, method, metric) over successful trials.

    Parameters
    ----------
    experiment : Experiment
        The experiment whose sweeps define the rows (records of other sweeps are ignored).
    records : list of dict
        Stored trials, as in :attr:`ExperimentReport.records`.

    Returns
    -------
    list of dict
        One row per sweep, value, method and metric (the sweep's metrics and ``"seconds"``), with
        keys ``sweep``, ``variable``, ``value``, ``method``, ``metric``, ``mean``, ``se``, ``n``
        (successful trials) and ``failed`` (trials that raised).

    Examples
    --------
    >>> from transync.experiments import Experiment, Sweep, summarize
    >>> exp = Experiment(name="toy", trial=print, sweeps=[
    ...     Sweep(name="noise", variable="noise", values=[0.0], methods=["a"])])
    >>> records = [dict(sweep="noise", config={"noise": 0.0, "method": "a"}, trial=t,
    ...                 metrics={"accuracy": acc, "seconds": 0.1}, error=None, seconds=0.1)
    ...            for t, acc in enumerate([0.5, 1.0])]
    >>> row = summarize(exp, records)[0]
    >>> row["metric"], row["mean"], row["se"], row["n"], row["failed"]
    ('accuracy', 0.75, 0.25, 2, 0)
    """
    if not isinstance(experiment, Experiment):
        raise TypeError(f"`experiment` must be an Experiment, got {type(experiment).__name__}")
    if isinstance(records, (str, bytes, Mapping)) or not isinstance(records, Iterable):
        raise TypeError(f"`records` must be a list of trial records, got "
                        f"{type(records).__name__}")
    records = list(records)
    for k, r in enumerate(records):
        missing = ([f for f in ("sweep", "config", "metrics", "error") if f not in r]
                   if isinstance(r, Mapping) else None)
        if missing is None or missing:
            raise TypeError(f"`records[{k}]` must be a dict with keys 'sweep', 'config', "
                            f"'metrics' and 'error' (as ExperimentReport.records), got "
                            + (type(r).__name__ if missing is None else f"no {missing}"))
        if not isinstance(r["config"], Mapping) or not isinstance(r["metrics"], Mapping):
            raise TypeError(f"`records[{k}]`: 'config' and 'metrics' must be dicts")
    by_sweep = {sw.name: sw for sw in experiment.sweeps}
    groups: dict[tuple, list[dict]] = {}
    failures: dict[tuple, int] = {}
    for r in records:
        sw = by_sweep.get(r["sweep"])
        if sw is None:
            continue
        value = r["config"].get(sw.variable)
        gkey = (sw.name, json.dumps(value, default=str), r["config"].get("method"))
        if r["error"]:
            failures[gkey] = failures.get(gkey, 0) + 1
            continue
        groups.setdefault(gkey, []).append(r["metrics"])
    rows = []
    for sw in experiment.sweeps:
        metrics = list(dict.fromkeys([*sw.metrics, "seconds"]))
        for value, method, _cfg in sw.configs():
            gkey = (sw.name, json.dumps(value, default=str), method)
            ms = groups.get(gkey, [])
            for metric in metrics:
                mean, se, n = mean_se(m.get(metric) for m in ms)
                rows.append(dict(sweep=sw.name, variable=sw.variable, value=value, method=method,
                                 metric=metric, mean=mean, se=se, n=n,
                                 failed=failures.get(gkey, 0)))
    return rows


def _write_summary(rows: list[dict], out: Path) -> None:
    import csv

    cols = ["sweep", "variable", "value", "method", "metric", "mean", "se", "n", "failed"]
    with open(out / "summary.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        w.writerows(rows)
    lines = []
    for sweep in dict.fromkeys(r["sweep"] for r in rows):
        sub = [r for r in rows if r["sweep"] == sweep]
        metrics = list(dict.fromkeys(r["metric"] for r in sub))
        methods = list(dict.fromkeys(r["method"] for r in sub))
        values = list(dict.fromkeys(json.dumps(r["value"], default=str) for r in sub))
        for metric in metrics:
            label = metric_label(metric, inline=True)
            lines.append(f"\n### {sweep}: {label} — mean ± standard error over trials\n")
            lines.append("| " + sub[0]["variable"] + " | " + " | ".join(methods) + " |")
            lines.append("|" + "---|" * (len(methods) + 1))
            for v in values:
                cells = []
                for m in methods:
                    hit = [r for r in sub if r["metric"] == metric and r["method"] == m
                           and json.dumps(r["value"], default=str) == v]
                    r = hit[0] if hit else None
                    cells.append("—" if r is None or not r["n"]
                                 else f"{r['mean']:.4g} (1 trial)" if r["n"] == 1
                                 else f"{r['mean']:.4g} ± {r['se']:.2g}")
                lines.append(f"| {value_label(json.loads(v))} | " + " | ".join(cells) + " |")
    (out / "summary.md").write_text("\n".join(lines).lstrip() + "\n")


def _toy_trial(config, rng):
    """Toy trial used by the doctest: error grows with noise, method 'b' is better."""
    scale = 1.0 if config["method"] == "a" else 0.5
    return {"error": float(abs(rng.normal(0, config["noise"] + 0.01)) * scale)}
