"""Command-line interface: ``transync demo | experiment | match | collection | sync |
homography | kernel | datasets``.

The CLI holds no logic of its own: every subcommand parses arguments, calls the library through
its public names and writes plain files (JSON, CSV, PNG) that other tools can read. Heavy
libraries (OpenCV, matplotlib) are imported only inside the commands that need them.

Every error prints one line, ``transync: error: ...``, on stderr and exits with status 2
(``--debug`` prints the traceback before it); Ctrl-C, SIGTERM and SIGHUP exit with status 130.

>>> build_parser().parse_args(["sync", "pairs.json", "--method", "spectral"]).command
'sync'
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import traceback
import warnings

from ._common import CLIError, signal_handlers

__all__ = ["CLIError", "build_parser", "main"]


_DESCRIPTION = """\
transync: consistent correspondences and transformations from many noisy pairwise ones.

Run `transync COMMAND --help` for a command's options (each shows its default)."""

_EPILOG = """\
exit status: 0 success; 1 finished, but some trials failed (experiment, demo: rerun to retry)
or no data folder was found (datasets); 2 an error (one line on stderr: `transync: error: ...`;
--debug also prints the traceback); 130 interrupted (Ctrl-C, SIGTERM or SIGHUP; stored experiment
trials are kept, rerun to resume).
Warnings (e.g. a solver stopped at its iteration budget) print one line each on stderr:
`transync: warning: ...`."""


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the description's line breaks; appends ``(default: X)`` to every option that has
    a default worth saying (not None/False, not already in its help)."""

    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        if (default is not None and default is not False and default is not argparse.SUPPRESS
                and "(default" not in text
                and action.option_strings):
            shown = " ".join(map(str, default)) if isinstance(default, (list, tuple)) else default
            text = f"{text} (default: {shown})" if text else f"default: {shown}"
        return text


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line too: ``transync: error: ... (see `transync CMD --help`)``;
    every subcommand's help shows its defaults."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", _HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message):
        self.exit(2, f"transync: error: {message} (see `{self.prog} --help`)\n")

    def parse_args(self, args=None, namespace=None):
        # argparse reports a subcommand's unknown options from the top-level parser, whose
        # message then pointed at `transync --help`; the subcommand's own help is the one to read
        argv = list(sys.argv[1:] if args is None else args)
        ns, extras = self.parse_known_args(argv, namespace)
        if extras:
            command = getattr(ns, "command", None)
            sub = getattr(self, "subcommands", {}).get(command, self)
            # an unknown option before the subcommand's name is the top-level parser's
            if command in argv and any(x in argv[:argv.index(command)] for x in extras):
                sub = self
            sub.error(f"unrecognized arguments: {' '.join(extras)}")
        return ns


def build_parser() -> argparse.ArgumentParser:
    """The ``argparse`` parser of every subcommand (each sets ``func``).

    Returns
    -------
    argparse.ArgumentParser
        The ``transync`` parser; parsing a command line gives a namespace whose ``func``
        attribute runs the chosen subcommand.

    Examples
    --------
    >>> from transync.cli import build_parser
    >>> args = build_parser().parse_args(["experiment", "--list"])
    >>> args.command, callable(args.func)
    ('experiment', True)
    """
    from .. import __version__
    from . import _datasets, _experiment, _homography, _kernel, _match

    parser = _Parser(prog="transync", description=_DESCRIPTION, epilog=_EPILOG)
    parser.add_argument("--version", action="version", version=f"transync {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback of an error (any position)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _experiment.add_parsers(sub)
    _match.add_parsers(sub)
    _homography.add_parser(sub)
    _kernel.add_parser(sub)
    _datasets.add_parser(sub)
    parser.subcommands = dict(sub.choices)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (default: ``sys.argv[1:]``); returns the exit status.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after the program name; ``None`` reads ``sys.argv[1:]``. A ``--debug``
        anywhere in it shows the full traceback of an error (and warnings in Python's own
        format; without it a warning prints as one line, ``transync: warning: ...``).

    Returns
    -------
    int
        The exit status: 0 on success, 1 when the output pipe was closed, 2 for an error
        (reported as one line on standard error), 130 when interrupted (Ctrl-C, SIGTERM,
        SIGHUP). Usage errors exit with status 2 through ``argparse`` (``SystemExit``).

    Examples
    --------
    >>> from transync.cli import main
    >>> main(["experiment", "--list"])
    cmu ...
    0
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    argv = [a for a in argv if a != "--debug"]
    args = None
    for stream in (sys.stdout, sys.stderr):   # a cp1252 console cannot print the reports' λ:
        with contextlib.suppress(AttributeError, ValueError):   # escaped, not an error after
            stream.reconfigure(errors="backslashreplace")       # every file was written
    try:
        with _terminate_as_interrupt(), warnings.catch_warnings():
            # building the parser imports the subcommands: a Ctrl-C there is an interrupt too
            args = build_parser().parse_args(argv)   # usage errors: argparse prints, exits 2
            args.debug = debug
            if not debug:                   # one line each, as the errors
                warnings.showwarning = _show_warning
            return int(args.func(args) or 0)
    except BrokenPipeError:        # output piped into e.g. `head`, which stopped reading
        import os

        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except KeyboardInterrupt as exc:
        if debug:
            traceback.print_exc()
        hint = getattr(args, "interrupt_hint", None)
        hint = hint() if callable(hint) else hint      # what is on disk now
        by = f" by {exc.args[0]}" if exc.args and isinstance(exc.args[0], str) else ""
        print(f"transync: interrupted{by}" + (f"; {hint}" if hint else ""), file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the one place that turns errors into one line
        if debug:
            traceback.print_exc()
        print(f"transync: error: {_one_line(exc)}", file=sys.stderr)
        return 2


@contextlib.contextmanager
def _terminate_as_interrupt():
    """SIGTERM (and SIGHUP) handled as Ctrl-C while a command runs: the experiment runner
    stops its workers, closes its store and the interrupt is reported with its resume hint
    (a plain SIGTERM left the store's journal and lock file behind and said nothing)."""
    import signal

    def interrupt(signum, frame):
        raise KeyboardInterrupt(signal.Signals(signum).name)

    with signal_handlers(("SIGTERM", "SIGHUP"), interrupt):
        yield


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Print a warning as ``transync: warning: ...`` on one line of standard error."""
    print(f"transync: warning: {' '.join(str(message).split())}", file=sys.stderr)


def _one_line(exc: BaseException) -> str:
    from ..exceptions import TransyncError

    msg = " ".join(str(exc).split()) or type(exc).__name__
    notes = [" ".join(str(n).split()) for n in getattr(exc, "__notes__", None) or []]
    if notes:       # where it happened (a pair, a chunk): Python shows notes, str(exc) does not
        msg = f"{msg} ({'; '.join(notes)})"
    if isinstance(exc, (CLIError, TransyncError, ValueError, TypeError)):
        return msg
    if isinstance(exc, MemoryError):    # an input too large for this machine, not a bug
        return ("out of memory: the input is too large for this machine's memory (a dense "
                f"array could not be allocated{': ' + msg if msg != 'MemoryError' else ''}); "
                "use fewer or smaller inputs")
    if isinstance(exc, OSError):
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        return f"{where}{exc.strerror or msg}"
    return (f"unexpected {type(exc).__name__}: {msg} (please report it; rerun with --debug "
            "for the traceback)")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
