"""``transync experiment`` and ``transync demo``: thesis experiments on the resumable runner."""

from __future__ import annotations

import contextlib
import functools
import importlib
import inspect
import sys
import time
from pathlib import Path

from ._common import CLIError, check_output_folder, positive_int, seed_int

__all__ = ["add_parsers"]


def _registry() -> dict:
    from ..experiments import REGISTRY

    return REGISTRY


def _build(name: str, *, quick: bool, data=None, sets=None, out=None):
    """The experiment ``name``; ``data``/``sets`` only for builds that take them (an error
    otherwise), ``out`` (the output folder, for on-disk caches) whenever the build takes it."""
    build = importlib.import_module(_registry()[name]).build
    params = inspect.signature(build).parameters
    kwargs = {"quick": quick}
    for option, value, flag in (("data", data, "--data"), ("sets", sets, "--sets")):
        if value is None:
            continue
        if option not in params:
            raise CLIError(f"experiment {name!r} takes no {flag}; {flag} is for the experiments "
                           "on real data sets (cmu, subgraph: --data; kernels: --data, --sets)")
        kwargs[option] = value
    if out is not None and "out" in params:
        kwargs["out"] = out
    return build(**kwargs)


def _check_names(names, what: str) -> None:
    known = sorted(_registry())
    unknown = [n for n in names if n not in known]
    if unknown:
        raise CLIError(f"unknown {what} {', '.join(map(repr, unknown))}; choose from "
                       f"{', '.join(known)}")


def _cmd_experiment(args) -> int:
    from ..experiments import run_experiment

    registry = _registry()
    if args.list or args.name is None:
        for name in sorted(registry):
            mod = importlib.import_module(registry[name])
            doc = (mod.__doc__ or "").strip().splitlines()
            print(f"{name:14s} {doc[0] if doc else ''}")
        return 0
    _check_names([args.name], "experiment")
    if args.data is not None and not str(args.data).strip():
        raise CLIError("--data: got an empty path (it would read the current folder)")
    out = check_output_folder(args.out if args.out is not None
                              else f"results/{args.name}{'-quick' if args.quick else ''}")
    sets = [s for s in args.sets.split(",") if s.strip()] if args.sets else None
    exp = _build(args.name, quick=args.quick, data=args.data, sets=sets, out=out)
    args.interrupt_hint = functools.partial(_resume_hint, out)
    report = run_experiment(exp, out, trials=args.trials, workers=args.workers, seed=args.seed,
                            progress=not args.no_progress)
    print(f"{report.n_new} new trials ({report.n_failed} failed) in {report.seconds:.1f} s; "
          f"{len(report.records)} stored in {out / 'results.sqlite'}")
    if report.n_other:
        print(f"({report.n_other} other stored trials of this experiment, from other "
              "configurations, seeds or an older transync, are kept but not reported)")
    print(f"summary: {out / 'summary.md'}  plot: {report.figure}")
    for path in report.extra_files:
        print(f"also: {path}")
    _warn_failures(report, out)
    return 1 if report.n_failed else 0


def _warn_failures(report, out: Path) -> None:
    """One warning line saying why the first failed trial failed (its error, stored with the
    trial, was said nowhere else: 14 of 14 failed trials on a bad --data folder printed only
    "(14 failed)")."""
    if not report.n_failed:
        return
    bad = [r for r in report.records if r.get("error")]
    if not bad:
        return
    lines = [ln for ln in bad[0]["error"].strip().splitlines() if ln.strip()]
    where = f"sweep {bad[0]['sweep']!r}, trial {bad[0]['trial']}"
    print(f"transync: warning: {report.n_failed} trial(s) failed; the first ({where}): "
          f"{lines[-1] if lines else 'no message'} (tracebacks stored in "
          f"{out / 'results.sqlite'}; rerun to retry them)", file=sys.stderr)


def _stored_trials(store: Path) -> int:
    """Rows in the experiment store ``store`` (0 when absent or unreadable)."""
    import sqlite3

    if not store.is_file():
        return 0
    try:
        # as a URI ('?', '#' and '%' in folder names escaped), read-only: never creates a file
        con = sqlite3.connect(f"{store.resolve().as_uri()}?mode=ro", uri=True, timeout=1)
        try:
            return int(con.execute("SELECT COUNT(*) FROM trials").fetchone()[0])
        finally:
            con.close()
    except sqlite3.Error:
        return 0


def _resume_hint(out: Path) -> str:
    """What an interrupted experiment left in ``out`` (said after Ctrl-C)."""
    store = out / "results.sqlite"
    cache = out / "cache"
    if _stored_trials(store):
        return f"finished trials are saved in {store}; run the same command again to resume"
    said = "no trial had finished, so none is stored; "
    if cache.is_dir() and any(cache.iterdir()):
        return said + (f"the computations cached in {cache} are reused when you run the same "
                       "command again")
    return said + "run the same command again to start over"


def _demo_hint(out: Path, names) -> str:
    """What an interrupted demo left in ``out`` (one store per experiment)."""
    if any(_stored_trials(out / name / "results.sqlite") for name in names):
        return f"finished trials are saved under {out}; run the same command again to resume"
    return "no trial had finished, so none is stored; run the same command again to start over"


def _cmd_demo(args) -> int:
    from ..experiments import run_experiment

    _check_names(args.experiments, "experiment")
    out = check_output_folder(args.out)
    args.interrupt_hint = functools.partial(_demo_hint, out, args.experiments)
    t0 = time.perf_counter()
    lines = ["# transync demo", "",
             "Quick versions of the experiments on generated data (offline). Each folder holds "
             "`results.sqlite`, `summary.md`, `summary.csv` and a plot.", "",
             "They show that every stage runs and what its outputs look like, on one or two "
             "trials of small problems: too few to rank the methods (a difference between two "
             "methods here can go either way). The full runs are `transync experiment NAME` "
             "(many trials per point); their stored results are in the documentation "
             "(docs/experiments).", ""]
    failed = 0
    created = not out.exists()
    for name in dict.fromkeys(args.experiments):
        exp = _build(name, quick=True, out=out / name)
        try:
            report = run_experiment(exp, out / name, workers=args.workers,
                                    progress=not args.no_progress)
        except BaseException:
            if created:  # leave no empty folder behind (stored trials stay)
                with contextlib.suppress(OSError):
                    out.rmdir()
            raise
        failed += report.n_failed
        _warn_failures(report, out / name)
        lines += [f"## {name}: {exp.description}", "",
                  f"{len(report.records)} trials, {report.n_failed} failed, "
                  f"{report.seconds:.1f} s. Plot: `{name}/{report.figure.name}`"
                  + "".join(f", `{name}/{p.name}`" for p in report.extra_files), "",
                  _headline(report.summary), ""]
    lines.append(f"Total time: {time.perf_counter() - t0:.1f} s")
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"\nwritten to {out.resolve()}")
    return 1 if failed else 0


def _headline(summary: list[dict]) -> str:
    """Mean of each method's first metric over the first sweep, as a small Markdown table."""
    if not summary:
        return ""
    sweep = summary[0]["sweep"]
    metric = summary[0]["metric"]
    rows = [r for r in summary if r["sweep"] == sweep and r["metric"] == metric and r["n"]]
    methods = list(dict.fromkeys(r["method"] for r in rows))
    out = [f"{metric} averaged over the `{sweep}` sweep:", "", "| method | " + metric + " |",
           "|---|---|"]
    for m in methods:
        vals = [r["mean"] for r in rows if r["method"] == m]
        out.append(f"| {m} | {sum(vals) / len(vals):.3f} |")
    return "\n".join(out)


def add_parsers(sub) -> None:
    """Register ``demo`` and ``experiment``."""
    p = sub.add_parser("demo", help="run quick experiments on generated data (offline)")
    p.add_argument("--out", default="transync-demo", help="output folder")
    p.add_argument("--workers", type=positive_int, default=1,
                   help="worker processes for the trials (1 = in this process)")
    p.add_argument("--experiments", nargs="+",
                   default=["pairwise", "sync", "multigraph", "homography"],
                   help="which quick experiments to run (see `transync experiment --list`)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("experiment", help="run (or resume) a thesis experiment")
    p.add_argument("name", nargs="?", help="experiment name (see --list)")
    p.add_argument("--list", action="store_true", help="list the experiments")
    p.add_argument("--quick", action="store_true",
                   help="small version (seconds to a minute; what `transync demo` runs)")
    p.add_argument("--out", help="output folder (default: results/NAME, or results/NAME-quick "
                                 "with --quick)")
    p.add_argument("--data", metavar="PATH",
                   help="data of the experiments on real data (cmu: a folder in the CMU layout, "
                        "default TRANSYNC_DATA's cmu-house; subgraph: the same, for its CMU "
                        "partial point; kernels: a TU folder or a folder of TU folders, default "
                        "TRANSYNC_DATA's tu)")
    p.add_argument("--sets", metavar="NAME,NAME",
                   help="comma-separated data sets to run (kernels: TU names, e.g. MUTAG,PTC_MR; "
                        "default: all five of the thesis)")
    p.add_argument("--trials", type=positive_int,
                   help="trials per configuration (default: the experiment's own: 20 for "
                        "multigraph, subgraph, cmu and sync, 30 for pairwise, 5 for homography, "
                        "10 repetitions for kernels; fewer than stored: nothing new runs and "
                        "every stored trial is reported)")
    p.add_argument("--workers", type=positive_int, default=1,
                   help="worker processes for the trials (1 = in this process)")
    p.add_argument("--seed", type=seed_int, default=0,
                   help="base seed of every trial's random problem (stored apart from other "
                        "seeds: a new seed adds trials, it never overwrites)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    p.set_defaults(func=_cmd_experiment)
