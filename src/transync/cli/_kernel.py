"""``transync kernel DATASET --out DIR``: transitive assignment kernel of a TU set, Gram matrix
and cross-validated accuracy.

Loads ``DATASET`` (a TU name in the data home or a TU folder), prunes it by size with the
``kernels`` experiment's rule (:func:`transync.experiments.kernels.prune`), fits
:class:`transync.kernels.TransitiveAssignmentKernel` on all kept graphs (transductive: the
synchronization sees every graph, no labels) and evaluates the Gram matrix with
:func:`transync.kernels.repeated_cv` (stratified folds, C chosen by an inner CV on the training
folds). Writes ``DIR/gram.npz`` (``K``, ``y``, ``kept``, ``params``), ``DIR/report.md`` and
``DIR/report.json``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from ._common import (CLIError, check_output_folder, cli_message, int_at_least,
                      new_output_folder, positive_int, seed_int)

__all__ = ["add_parser"]

MATCHERS = ("rrwm", "sm", "node")
SYNCS = ("orthogonal", "spectral")
KERNEL_VARIANTS = ("linear", "gaussian", "relaxed")


_at_least_2 = int_at_least(2)

#: the estimator's parameters that are options of this command, under their option names
_OPTIONS = {"n_alignments": "--alignments", "n_neighbors": "--neighbors", "matcher": "--matcher",
            "sync": "--sync", "kernel": "--kernel", "random_state": "--seed",
            "executor": "--workers"}


def _load(spec: str):
    from ..datasets import load_tu

    try:
        return load_tu(spec)
    except FileNotFoundError as exc:
        raise CLIError(f"data set {spec!r}: {' '.join(str(exc).split())}") from None
    except ValueError as exc:
        raise CLIError(f"data set {spec!r}: {' '.join(str(exc).split())}") from None


def _cmd_kernel(args) -> int:
    import numpy as np

    from ..experiments.kernels import PSD_TOL, prune
    from ..kernels import TransitiveAssignmentKernel, repeated_cv, spectrum

    args.interrupt_hint = "nothing was written"
    check_output_folder(args.out)             # before minutes of work, not after
    ds = _load(args.dataset)
    try:
        keep, rule = prune(ds.sizes, ds.y)
    except ValueError as exc:
        raise CLIError(f"data set {ds.name!r}: {exc}") from None
    sub = ds.subset(keep)
    y = np.asarray(sub.y)
    counts = np.unique(y, return_counts=True)[1]
    if counts.size < 2:
        raise CLIError(f"data set {ds.name!r}: {rule}; at least 2 classes are needed")
    if counts.min() < args.folds:
        raise CLIError(f"--folds {args.folds}: the smallest class of {ds.name!r} has "
                       f"{counts.min()} graphs after pruning; use fewer folds")
    params = dict(matcher=args.matcher, sync=args.sync, kernel=args.kernel,
                  n_neighbors=args.neighbors, n_alignments=args.alignments,
                  random_state=args.seed)
    progress = not args.no_progress
    est = TransitiveAssignmentKernel(**params, executor=args.workers, progress=progress)
    t0 = time.perf_counter()
    try:
        K = np.asarray(est.fit_transform(list(sub.graphs)), dtype=float)
    except (ValueError, TypeError) as exc:     # the library's names written as this command's
        raise CLIError(cli_message(exc, _OPTIONS)) from exc
    fit_seconds = time.perf_counter() - t0
    ev = spectrum(K)
    top = float(np.max(np.abs(ev)))
    ratio = float(ev[0] / top) if top > 0 else 0.0
    t0 = time.perf_counter()
    cv = repeated_cv(K, y, n_splits=args.folds, n_repeats=args.repeats,
                     random_state=args.seed, progress=progress)
    cv_seconds = time.perf_counter() - t0
    chosen, n_chosen = np.unique(cv.chosen_C, return_counts=True)
    report = {
        "dataset": ds.name, "folder": str(ds.path), "graphs": len(ds), "kept": len(sub),
        "classes": int(counts.size), "pruning": rule,
        "universe": int(getattr(est, "n_universe_", max(sub.sizes))),
        "params": params,
        # --neighbors K >= graphs - 1 matches every pair: the report says what was matched
        "view_graph_neighbors": getattr(est, "n_neighbors_", None),
        "accuracy": {"mean": cv.mean, "std": cv.std, "per_repeat": cv.per_repeat.tolist(),
                     "folds": args.folds, "repeats": args.repeats,
                     "std_convention": "standard deviation of the per-repetition means"},
        "C": {"grid": cv.C_grid.tolist(), "most_chosen": float(chosen[np.argmax(n_chosen)]),
              "chosen": cv.chosen_C.tolist()},
        "psd": {"min_over_max_eigenvalue": ratio, "psd": bool(ratio >= -PSD_TOL),
                "tolerance": PSD_TOL},
        "seconds": {"gram": fit_seconds, "cv": cv_seconds},
    }
    def written():
        args.interrupt_hint = f"the results were written to {args.out}"

    with new_output_folder(args.out, on_written=written) as stage:   # all three files or none
        np.savez(stage / "gram.npz", K=K, y=y, kept=np.asarray(keep),
                 params=np.str_(json.dumps(params)))
        (stage / "report.json").write_text(json.dumps(report, indent=2) + "\n")
        lines = _markdown(report)
        (stage / "report.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[2:9]))
    print(f"written to {Path(args.out)}")
    return 0


def _markdown(r: dict) -> list[str]:
    acc, psd, p = r["accuracy"], r["psd"], r["params"]
    return [
        f"# transync kernel: {r['dataset']}", "",
        f"- kernel: transitive assignment, matcher {p['matcher']}, sync {p['sync']}, "
        f"{p['kernel']} slot kernel, cosine-normalized (seed {p['random_state']}); pairs "
        f"matched: " + ("all" + ("" if p.get("n_neighbors") is None else
                                 f" (--neighbors {p['n_neighbors']} reaches every graph)")
                        if r.get("view_graph_neighbors") is None else
                        f"view graph, {r['view_graph_neighbors']} nearest graphs + spanning tree")
        + ("" if p.get("n_alignments", 1) == 1 else
           f"; Gram matrix averaged over {p['n_alignments']} alignments (the first of all "
           "pairs, the others of random 70 % subsamples)"),
        f"- graphs: {r['kept']} of {r['graphs']} kept, {r['classes']} classes, universe "
        f"n = {r['universe']}; pruning: {r['pruning']}",
        (f"- accuracy: {100 * acc['mean']:.2f} ± {100 * acc['std']:.2f} % ({acc['repeats']} x "
         f"{acc['folds']}-fold stratified CV; ± = std of the repetition means)"
         if acc["repeats"] > 1 else
         f"- accuracy: {100 * acc['mean']:.2f} % (one {acc['folds']}-fold stratified CV: no "
         f"spread between repetitions; --repeats 10 gives one)"),
        f"- C: chosen by a 3-fold inner CV on the training folds from "
        f"{', '.join(f'{c:g}' for c in r['C']['grid'])}; most chosen {r['C']['most_chosen']:g}",
        f"- PSD: λ_min / λ_max = {psd['min_over_max_eigenvalue']:.3g} -> "
        f"{'PSD' if psd['psd'] else 'NOT PSD'} (tolerance {psd['tolerance']:g})",
        f"- time: Gram matrix {r['seconds']['gram']:.1f} s, cross-validation "
        f"{r['seconds']['cv']:.1f} s",
        "- transductive: the synchronization used every kept graph (no labels)",
        "", "Files: `gram.npz` (K, y, kept = indices of the kept graphs in the file, params), "
        "`report.json`.",
    ]


def add_parser(sub) -> None:
    """Register ``kernel``."""
    p = sub.add_parser(
        "kernel", help="transitive assignment kernel of a TU data set: Gram matrix + "
                       "cross-validated SVM accuracy")
    p.add_argument("dataset", metavar="DATASET",
                   help="TU data set: a name in the data home's tu/ folder (e.g. MUTAG) or a "
                        "folder holding DS_A.txt, DS_graph_indicator.txt, DS_graph_labels.txt "
                        "(a path: with a separator or a leading . or ~, e.g. ./MYSET)")
    p.add_argument("--out", default="transync-kernel",
                   help="output folder (default: transync-kernel; created only on success)")
    p.add_argument("--matcher", choices=MATCHERS, default="rrwm",
                   help="pairwise matcher: rrwm, sm (spectral matching) or node (node-only "
                        "assignment, fast) (default: rrwm)")
    p.add_argument("--sync", choices=SYNCS, default="orthogonal",
                   help="synchronization onto the transitive space (default: orthogonal)")
    p.add_argument("--kernel", choices=KERNEL_VARIANTS, default="linear",
                   help="slot kernel on the aligned features (default: linear)")
    p.add_argument("--neighbors", type=positive_int, default=None, metavar="K",
                   help="view graph: match each graph to its K nearest graphs (mean HKS + "
                        "label histogram) plus a spanning tree instead of all pairs (default: "
                        "all pairs; use it on large sets, e.g. NCI1)")
    p.add_argument("--alignments", type=positive_int, default=1, metavar="R",
                   help="ensemble: average the kernels of R synchronizations of the same "
                        "matches, the first of all pairs, the others of random 70%% subsamples "
                        "(R times the synchronization's cost)")
    p.add_argument("--folds", type=_at_least_2, default=10,
                   help="outer stratified folds (default: 10)")
    p.add_argument("--repeats", type=positive_int, default=10,
                   help="repetitions of the cross-validation (default: 10)")
    p.add_argument("--seed", type=seed_int, default=0,
                   help="seed of the matcher and of the folds (default: 0)")
    p.add_argument("--workers", type=positive_int, default=1,
                   help="processes for the pairwise matching (default: 1)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    p.set_defaults(func=_cmd_kernel)
