"""When the geometric verification pays: the data behind ``match_collection(verify="auto")``.

``verify="auto"`` (the default) verifies graphs of different sizes that carry 2-d points with an
affine model and keeps the verified maps only when at least ``AUTO_VERIFY_MIN_SHARE`` (70 %) of
the pairs verify. This script measures, per kind of collection, the share of pairs that verify
and the F1 of ``verify=None``, of ``verify="affine"`` and of the default, on the same problems
and with the same method (``--method``, a line of ``transync experiment subgraph``, verification
switched by this script; default ``S-RRWM``, the default call):

* ``jitter``: ``--points`` random points in the unit square, ``--views`` views each keeping every
  point with its own probability ``p ~ U(0.6, 1)``, moved by a random similarity (rotation up
  to 0.3 rad, scale 0.8-1.2, translation) after an independent Gaussian jitter of ``sigma`` per
  point (non-rigid: ``sigma`` against a typical point spacing of about ``0.5 / sqrt(points)``),
  Delaunay graphs, the landmark affinity;
* ``cmu``: a sequence in the CMU layout (``--data``, default ``TRANSYNC_DATA``'s ``cmu-house``),
  ``F`` frames spread over the sequence, each keeping a random two thirds to five sixths of its
  landmarks, node orders shuffled (the ``cmu`` point of ``transync experiment subgraph``).

Usage::

    python benchmarks/verify_auto.py                        # both parts, defaults below
    python benchmarks/verify_auto.py --parts jitter --sigmas 0 0.02 0.04 --collections 10
    python benchmarks/verify_auto.py --parts cmu --frames 6 20 --draws 20 --method RRWM+spectral

Prints one Markdown table: share of pairs verified (min-max, mean), mean F1 of ``verify=None``,
``"affine"`` and the default, the smallest and largest per-problem change of ``"affine"``
against ``None``, and on how many problems the default kept the verification.
"""

from __future__ import annotations

import argparse
import functools
import time
import warnings

import numpy as np


def jitter_collection(seed: int, sigma: float, *, n_points: int = 20, n_views: int = 10):
    """Views of one random point set (see the module docstring); ``(graphs, truth)``."""
    from transync.graphs import Graph
    from transync.permutations import MultiMatching

    rng = np.random.default_rng(seed)
    base = rng.random((n_points, 2))
    graphs, labels = [], []
    for _ in range(n_views):
        a, s = rng.uniform(-0.3, 0.3), rng.uniform(0.8, 1.2)
        R = s * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        kept = np.flatnonzero(rng.random(n_points) < rng.uniform(0.6, 1.0))
        kept = rng.permutation(kept if kept.size >= 3 else np.arange(3))
        pts = (base[kept] + sigma * rng.standard_normal((kept.size, 2))) @ R.T
        graphs.append(Graph.from_points(pts + rng.uniform(-1, 1, 2), edges="delaunay"))
        labels.append(kept)
    return graphs, MultiMatching(labels, n_points)


def _compare(method: str, graphs, truth, seed: int) -> dict:
    """F1 of the three settings of ``verify`` on one problem, and the verified share."""
    from transync import match_collection
    from transync.datasets import LANDMARK_AFFINITY
    from transync.experiments.subgraph import METHODS
    from transync.matching import gaussian_edge_affinity
    from transync.metrics import multimatching_precision_recall

    aff = functools.partial(gaussian_edge_affinity, **LANDMARK_AFFINITY)
    kwargs = {k: v for k, v in METHODS[method].items() if k != "verify"}
    out = {}
    for name, verify in (("none", None), ("affine", "affine"), ("auto", "auto")):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = match_collection(graphs, affinity=aff, rng=seed, progress=False,
                                   verify=verify, **kwargs)
        out[name] = multimatching_precision_recall(res, truth)["f1"]
        if name == "affine":
            out["share"] = float(np.mean(res.info["verify"]["verified"]))
        if name == "auto":
            out["kept"] = bool(res.info.get("verify", {}).get("used", False))
    return out


def _row(label: str, rows: list[dict]) -> str:
    share = np.array([r["share"] for r in rows])
    delta = np.array([r["affine"] - r["none"] for r in rows])
    f1 = {k: np.mean([r[k] for r in rows]) for k in ("none", "affine", "auto")}
    return (f"| {label} | {len(rows)} | {share.min():.2f}-{share.max():.2f} ({share.mean():.2f}) "
            f"| {f1['none']:.3f} | {f1['affine']:.3f} | {f1['auto']:.3f} | "
            f"{delta.min():+.3f} .. {delta.max():+.3f} | {sum(r['kept'] for r in rows)} |")


def main(argv=None) -> None:
    from transync.experiments.subgraph import METHODS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", nargs="+", default=["jitter", "cmu"], choices=["jitter", "cmu"])
    ap.add_argument("--method", default="S-RRWM",
                    choices=[m for m, kw in METHODS.items() if kw.get("verify", 0) is None
                             and kw.get("partial") != "dummies"],
                    help="line of the subgraph experiment (default: S-RRWM, the default call)")
    ap.add_argument("--sigmas", nargs="+", type=float, default=[0.0, 0.02, 0.04, 0.06, 0.08])
    ap.add_argument("--collections", type=int, default=6, help="per sigma (default: 6)")
    ap.add_argument("--points", type=int, default=20)
    ap.add_argument("--views", type=int, default=10)
    ap.add_argument("--data", default=None, help="a folder in the CMU layout")
    ap.add_argument("--frames", nargs="+", type=int, default=[6, 10, 20])
    ap.add_argument("--draws", type=int, default=10, help="per number of frames (default: 10)")
    ap.add_argument("--seed", type=int, default=0, help="first problem's seed (default: 0)")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    lines = ["| collection | problems | pairs verified: min-max (mean) | F1 verify=None | "
             "F1 'affine' | F1 default ('auto') | 'affine' - None per problem | "
             "default kept the verification |", "|---|---|---|---|---|---|---|---|"]
    if "jitter" in args.parts:
        for sigma in args.sigmas:
            rows = []
            for c in range(args.collections):
                seed = args.seed + c
                graphs, truth = jitter_collection(seed, sigma, n_points=args.points,
                                                  n_views=args.views)
                rows.append(_compare(args.method, graphs, truth, seed))
            lines.append(_row(f"{args.points} points, {args.views} views, jitter sigma "
                              f"{sigma:g}", rows))
    if "cmu" in args.parts:
        from transync.datasets import data_home
        from transync.experiments.subgraph import _cmu_problem, cmu_keep_range
        from transync.experiments.cmu import load_sequence

        folder = args.data or data_home(required=False, subfolder="cmu-house")
        if folder is None:
            print("cmu: no sequence found (pass --data); part skipped")
        else:
            seq = load_sequence(folder)
            lo, hi = cmu_keep_range(seq.n_landmarks)
            for frames in args.frames:
                rows = []
                for d in range(args.draws):
                    seed = args.seed + 1000 * frames + d
                    config = dict(n_frames=frames, keep_low=lo, keep_high=hi)
                    prob = _cmu_problem(config, np.random.default_rng(seed), str(folder))
                    rows.append(_compare(args.method, prob.graphs, prob.ground_truth, seed))
                lines.append(_row(f"{seq.name}, {frames} frames over the sequence, {lo}-{hi} "
                                  f"of {seq.n_landmarks} landmarks", rows))
    print(f"method {args.method}; {time.perf_counter() - t0:.0f} s")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
