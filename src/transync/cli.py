"""Command-line interface: ``transync demo | experiment | match | sync | homography | datasets``.

The CLI holds no logic of its own: every subcommand parses arguments, calls the library and
writes plain files (JSON, CSV, PNG) that other tools can read.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from pathlib import Path

__all__ = ["main"]


def _cmd_experiment(args) -> int:
    from .experiments import REGISTRY
    from .experiments._runner import run_experiment

    if args.list or not args.name:
        for name in sorted(REGISTRY):
            mod = importlib.import_module(REGISTRY[name])
            doc = (mod.__doc__ or "").strip().splitlines()
            print(f"{name:14s} {doc[0] if doc else ''}")
        return 0
    if args.name not in REGISTRY:
        print(f"transync: unknown experiment {args.name!r}; choose from "
              f"{', '.join(sorted(REGISTRY))}", file=sys.stderr)
        return 2
    exp = importlib.import_module(REGISTRY[args.name]).build(quick=args.quick)
    out = Path(args.out or f"results/{args.name}{'-quick' if args.quick else ''}")
    report = run_experiment(exp, out, trials=args.trials, workers=args.workers, seed=args.seed,
                            progress=not args.no_progress)
    print(f"{report.n_new} new trials ({report.n_failed} failed) in {report.seconds:.1f} s; "
          f"{len(report.records)} stored in {out / 'results.sqlite'}")
    print(f"summary: {out / 'summary.md'}  plot: {report.figure}")
    for path in report.extra_files:
        print(f"also: {path}")
    return 1 if report.n_failed else 0


def _cmd_demo(args) -> int:
    from .experiments import REGISTRY
    from .experiments._runner import run_experiment

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    lines = ["# transync demo", "",
             "Quick versions of the experiments on generated data (offline). Each folder holds "
             "`results.sqlite`, `summary.md`, `summary.csv` and a plot.", ""]
    failed = 0
    for name in args.experiments:
        if name not in REGISTRY:
            continue
        exp = importlib.import_module(REGISTRY[name]).build(quick=True)
        report = run_experiment(exp, out / name, workers=args.workers,
                                progress=not args.no_progress)
        failed += report.n_failed
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


def _emit(payload: dict, out: str | None) -> int:
    """Write ``payload`` as JSON to ``out``, or print it."""
    text = json.dumps(payload, indent=2)
    if out:
        Path(out).write_text(text + "\n")
        print(f"wrote {out}")
    else:
        print(text)
    return 0


def _load_points(path: str):
    import numpy as np

    p = Path(path)
    if not p.exists():
        raise SystemExit(f"transync: no such file: {path}")
    if p.suffix == ".npy":
        return np.load(p)
    return np.loadtxt(p, delimiter="," if p.suffix == ".csv" else None, ndmin=2)


def _cmd_match(args) -> int:
    import numpy as np

    from .graphs import Graph
    from .matching import gaussian_edge_affinity, match_graphs

    P1, P2 = _load_points(args.points1), _load_points(args.points2)
    scale = float(max(np.ptp(P1, axis=0).max(), np.ptp(P2, axis=0).max(), 1e-12))
    g1 = Graph.from_points(P1 / scale, edges=args.edges)
    g2 = Graph.from_points(P2 / scale, edges=args.edges)
    aff = gaussian_edge_affinity(g1, g2, sigma2=args.sigma2)
    res = match_graphs(g1, g2, method=args.method, affinity=aff)
    payload = {"method": args.method, "assignment": res.assignment.tolist(),
               "objective": res.objective, "n_iter": res.n_iter, "converged": res.converged,
               "edges": args.edges, "sigma2": args.sigma2, "coordinate_scale": scale}
    return _emit(payload, args.out)


def _cmd_sync(args) -> int:
    import numpy as np

    from .synchronization import synchronize_permutations

    data = json.loads(Path(args.pairwise).read_text())
    pairs = {(int(i), int(j)): np.asarray(a, dtype=np.int64) for i, j, a in data["pairs"]}
    res = synchronize_permutations(pairs, method=args.method, n_universe=args.n_universe)
    payload = {"method": args.method, "labels": [np.asarray(lab).tolist() for lab in res.labels],
               "objective": float(res.objective), "converged": bool(res.converged),
               "n_iter": int(res.n_iter)}
    info = {k: v for k, v in res.info.items() if isinstance(v, (int, float, str, bool))}
    payload["info"] = info
    return _emit(payload, args.out)


def _cmd_datasets(args) -> int:
    from .datasets._home import data_home

    home = data_home(required=False)
    if home is None:
        print("no data folder found: set TRANSYNC_DATA or place the data in ../shared/data")
        return 1
    print(f"data home: {home}")
    for sub in sorted(p for p in Path(home).iterdir() if p.is_dir()):
        n = sum(1 for _ in sub.rglob("*") if _.is_file())
        print(f"  {sub.name:14s} {n} files")
    return 0


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = argparse.ArgumentParser(prog="transync", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"transync {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("demo", help="run quick experiments on generated data (offline)")
    p.add_argument("--out", default="transync-demo", help="output folder (default: transync-demo)")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--experiments", nargs="+", default=["pairwise", "sync", "homography"],
                   help="which quick experiments to run")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("experiment", help="run (or resume) a thesis experiment")
    p.add_argument("name", nargs="?", help="experiment name (see --list)")
    p.add_argument("--list", action="store_true", help="list the experiments")
    p.add_argument("--quick", action="store_true", help="small version (about a minute)")
    p.add_argument("--out", help="output folder (default: results/NAME)")
    p.add_argument("--trials", type=int, help="trials per configuration")
    p.add_argument("--workers", type=int, default=1, help="processes")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_cmd_experiment)

    p = sub.add_parser("match", help="match two point sets (.npy, .txt or .csv, one point a row)")
    p.add_argument("points1")
    p.add_argument("points2")
    p.add_argument("--method", default="rrwm",
                   choices=["hungarian", "sinkhorn", "sm", "rrwm", "ipfp", "ga", "pf"])
    p.add_argument("--edges", default="full", choices=["full", "delaunay", "knn"])
    p.add_argument("--sigma2", type=float, default=0.05,
                   help="Gaussian edge-length kernel width after scaling points to unit size")
    p.add_argument("--out", help="JSON output file (default: print)")
    p.set_defaults(func=_cmd_match)

    p = sub.add_parser("sync", help="synchronize pairwise assignments given as JSON "
                                    "{\"pairs\": [[i, j, assignment], ...]}")
    p.add_argument("pairwise")
    p.add_argument("--method", default="spectral")
    p.add_argument("--n-universe", type=int, default=None)
    p.add_argument("--out", help="JSON output file (default: print)")
    p.set_defaults(func=_cmd_sync)

    try:
        from .homography._cli import add_homography_parser
    except ImportError:  # pragma: no cover - homography CLI not available
        add_homography_parser = None
    if add_homography_parser is not None:
        add_homography_parser(sub)

    p = sub.add_parser("datasets", help="show where the real data sets are found")
    p.set_defaults(func=_cmd_datasets)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
