"""Helpers shared by the subcommands: the CLI's error type, argument types, JSON output."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path

__all__ = ["CLIError", "emit", "int_at_least", "new_output_folder", "positive_int"]


class CLIError(Exception):
    """A user error the command line reports as one line (exit status 2).

    Examples
    --------
    >>> from transync.cli._common import CLIError
    >>> str(CLIError("no such file: points.txt"))
    'no such file: points.txt'
    """


def int_at_least(minimum: int, maximum: int | None = None):
    """``argparse`` type factory: an integer >= ``minimum`` (and <= ``maximum`` if given).

    Parameters
    ----------
    minimum : int
        The smallest accepted value.
    maximum : int, optional
        The largest accepted value.

    Returns
    -------
    callable
        ``parse(text) -> int``, raising ``argparse.ArgumentTypeError`` otherwise.

    Examples
    --------
    >>> int_at_least(2)("3")
    3
    """
    what = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"
    if maximum is not None:
        what += f" and <= {maximum}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if value < minimum or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
        return value

    parse.__name__ = f"integer >= {minimum}"
    return parse


#: ``argparse`` type: an integer >= 1.
positive_int = int_at_least(1)


def cli_message(exc: BaseException, options=()) -> str:
    """The first line of a library error, with the library's argument names that are this
    command's options written as options (a quoted ``n_universe`` becomes ``--n-universe``,
    ``verify='affine'`` becomes ``--verify affine``; ``options`` as a dict maps a name to an
    option of another name).

    >>> cli_message(ValueError("`n_universe` must be >= 5"), ["n_universe"])
    '`--n-universe` must be >= 5'
    >>> cli_message(ValueError("pass verify='affine' (or 'similarity')"), ["verify"])
    "pass --verify affine (or 'similarity')"
    >>> cli_message(ValueError("verify=None runs no check, got verify_threshold=0.3"),
    ...             ["verify_threshold", "verify"])
    '--verify none runs no check, got --verify-threshold 0.3'
    >>> cli_message(ValueError("`n_alignments` must be <= 1000"), {"n_alignments": "--alignments"})
    '`--alignments` must be <= 1000'
    """
    import re

    msg = (str(exc).splitlines() or [""])[0] or type(exc).__name__
    for name in options:
        flag = options[name] if isinstance(options, dict) else "--" + name.replace("_", "-")
        msg = msg.replace(f"`{name}`", f"`{flag}`")
        msg = re.sub(rf"\b{name}=(?:'([^']*)'|([^\s,;)']+))",
                     lambda m, f=flag: f"{f} {m.group(1) or m.group(2).replace('None', 'none')}",
                     msg)
    return msg


#: ``argparse`` type of every ``--seed``: an integer >= 0 (refused at parse time, naming the
#: option, instead of by the library naming its ``rng`` argument)
seed_int = int_at_least(0)


def positive_float(text: str) -> float:
    """``argparse`` type: a finite float > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive finite number, got {text}")
    return value


def input_file(path, expected: str) -> Path:
    """``path`` as a Path when it is a regular file; else a :class:`CLIError` that says what it
    is instead: missing, a folder, or another kind of file (a pipe, socket or device, which
    the readers cannot seek in). ``expected`` completes "expected ...".

    Examples
    --------
    >>> from transync.cli._common import input_file
    >>> input_file("/nonexistent/p.csv", "a text/CSV or .npy file of points")
    Traceback (most recent call last):
    ...
    transync.cli._common.CLIError: no such file: /nonexistent/p.csv
    """
    p = Path(path)
    if p.is_dir():
        raise CLIError(f"{path} is a folder; expected {expected}")
    if not p.exists():
        raise CLIError(f"no such file: {path}")
    if not p.is_file():
        raise CLIError(f"{path} is not a regular file (a pipe, socket or device); expected "
                       f"{expected}")
    return p


def check_output_file(out: str | None, inputs=()) -> None:
    """Refuse, before any computation, an ``--out`` file that cannot be written: an existing
    folder or non-file, a missing or non-writable parent folder, or one of the command's
    ``inputs`` (it would be overwritten: a rerun then failed). ``None``: printed instead."""
    if out is None:
        return
    path = Path(out)
    if str(out) == "":
        raise CLIError("--out: got an empty path (omit --out to print the result)")
    if path.exists() and not path.is_file():
        raise CLIError(f"--out {out} exists and is not a file")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise CLIError(f"cannot write {out}: the folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise CLIError(f"cannot write {out}: the folder {parent} is not writable")
    for name in inputs:
        if path.exists() and Path(name).exists() and path.samefile(name):
            raise CLIError(f"--out {out} is also an input of the command; choose another file")


def emit(payload: dict, out: str | None) -> int:
    """Write ``payload`` as JSON to ``out`` (complete or not at all: a temporary file in the
    same folder, renamed into place), or print it."""
    text = json.dumps(payload, indent=2)
    if out:
        path = Path(out)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        try:
            try:
                tmp.write_text(text + "\n")
                os.replace(tmp, path)
            finally:
                with contextlib.suppress(OSError):
                    tmp.unlink()
        except OSError as exc:
            raise CLIError(f"cannot write {out}: {exc.strerror or exc}") from exc
        print(f"wrote {out}")
    else:
        print(text)
    return 0


def check_output_folder(path) -> Path:
    """``path`` as a Path, refused when it is empty, exists and is not a folder, or cannot be
    created (its nearest existing ancestor not a writable folder): call it before a long
    computation, so that its result is not lost to an output path that cannot take it."""
    out = Path(path)
    if str(path) == "":
        raise CLIError("output folder: got an empty path")
    if out.exists() and not out.is_dir():
        raise CLIError(f"output folder {out} exists and is not a folder")
    # the nearest existing ancestor must be a folder this process may create entries in
    parent = out
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise CLIError(f"cannot create the output folder {out}: {parent} is not a folder")
    if parent.exists() and parent != out and not os.access(parent, os.W_OK | os.X_OK):
        raise CLIError(f"cannot create the output folder {out}: {parent} is not writable")
    return out


@contextlib.contextmanager
def signal_handlers(names, handler):
    """``handler`` for the signals ``names`` (those the platform has) while the block runs,
    the earlier handlers restored after it; outside the main thread nothing changes."""
    import signal

    previous = {}
    for name in names:
        sig = getattr(signal, name, None)
        if sig is None:                                 # pragma: no cover - Windows: SIGHUP
            continue
        try:
            previous[sig] = signal.signal(sig, handler)
        except (ValueError, OSError):      # not the main thread: leave the signals alone
            pass
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


@contextlib.contextmanager
def _signals_deferred():
    """Ctrl-C, SIGTERM and SIGHUP held back while the block runs and delivered after it, to
    the handlers that were in place: a few renames are not cut in half. (Python runs signal
    handlers in the main thread whichever thread the signal reached, so recording them there
    works where blocking the main thread's signal mask would not: the BLAS and worker threads
    would take the signal.)"""
    import signal

    pending: list = []
    with signal_handlers(("SIGINT", "SIGTERM", "SIGHUP"),
                         lambda signum, frame: pending.append(signum)):
        yield
    if pending:
        signal.raise_signal(pending[0])


@contextlib.contextmanager
def new_output_folder(path, on_written=None):
    """Create ``path`` and write a command's files into it, all of them or none.

    Yields a hidden staging folder inside ``path`` to write into. When the block finishes,
    every file in it is moved to the same name under ``path`` (replacing an earlier run's
    file), with interrupts held back until the last move (``on_written()``, if given, runs
    then, before an interrupt held back is delivered); when the block fails, the staging
    folder is removed, so a folder that already existed keeps an earlier run's files unmixed
    with this run's, and a folder this call created is removed again.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from transync.cli._common import new_output_folder
    >>> out = Path(tempfile.mkdtemp()) / "run"
    >>> with new_output_folder(out) as stage:
    ...     _ = (stage / "a.txt").write_text("new")
    >>> sorted(p.name for p in out.iterdir()), (out / "a.txt").read_text()
    (['a.txt'], 'new')
    >>> try:
    ...     with new_output_folder(out) as stage:
    ...         _ = (stage / "a.txt").write_text("half")
    ...         raise OSError("disk full")
    ... except OSError:
    ...     pass
    >>> sorted(p.name for p in out.iterdir()), (out / "a.txt").read_text()
    (['a.txt'], 'new')
    """
    out = check_output_folder(path)
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=".transync-staging-", dir=out))
    except OSError as exc:
        raise CLIError(f"cannot create the output folder {out}: {exc.strerror or exc}") from exc
    moved = False
    try:
        yield stage
        files = [src for src in sorted(stage.rglob("*")) if src.is_file()]
        for src in files:               # refused before any file moves: nothing mixed
            dst = out / src.relative_to(stage)
            if dst.exists() and not dst.is_file():
                raise CLIError(f"cannot write {dst}: it exists and is not a file")
            for parent in dst.relative_to(out).parents[:-1]:        # the folders on the way
                if (out / parent).exists() and not (out / parent).is_dir():
                    raise CLIError(f"cannot write {dst}: {out / parent} exists and is not a "
                                   "folder")
        with _signals_deferred():
            try:
                for src in files:
                    dst = out / src.relative_to(stage)
                    dst.parent.mkdir(parents=True, exist_ok=True)
                    os.replace(src, dst)
            except OSError as exc:
                raise CLIError(f"cannot write into {out}: {exc.strerror or exc}") from exc
            moved = True
            if on_written is not None:
                on_written()
    except BaseException:
        if created and not moved:       # an interrupt held back to the end: the files stay
            shutil.rmtree(out, ignore_errors=True)
        raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)
