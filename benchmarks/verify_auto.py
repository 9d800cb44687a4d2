"""When the geometric verification pays: the data behind ``match_collection(verify="auto")``.

``verify="auto"`` (the default) verifies graphs of different sizes that carry 2-d points, every
pair keeping the better supported of an affine map and a homography, and keeps the verified maps
only when at least ``AUTO_VERIFY_MIN_SHARE`` (70 %) of the pairs verify with the affine map. This
script measures, per kind of collection, the share of pairs that verify (affine) and the F1 of
``verify=None``, of ``verify="affine"`` and of the default, on the same problems and with the
same method (``--method``, a line of ``transync experiment subgraph``, verification switched by
this script; default ``S-RRWM``, the default call):

* ``jitter``: ``--points`` random points in the unit square, ``--views`` views each keeping every
  point with its own probability ``p ~ U(0.6, 1)``, moved by a random similarity (rotation up
  to 0.3 rad, scale 0.8-1.2, translation) after an independent Gaussian jitter of ``sigma`` per
  point (non-rigid: ``sigma`` against a typical point spacing of about ``0.5 / sqrt(points)``),
  Delaunay graphs, the landmark affinity;
* ``cmu``: a sequence in the CMU layout (``--data``, default ``TRANSYNC_DATA``'s ``cmu-house``),
  ``F`` frames spread over the sequence, each keeping a random two thirds to five sixths of its
  landmarks, node orders shuffled (the ``cmu`` point of ``transync experiment subgraph``);
* ``perspective``: the same protocol on generated sequences in the CMU layout
  (:func:`perspective_sequence`): 30 points on three faces of a house-shaped solid (front wall,
  side wall, roof), 101 frames of a pinhole camera orbiting it over ``--yaws`` degrees, label
  noise of 1 pixel (``--seed`` draws the points). Yaw 20 distorts the views about as much as
  CMU House (the mean residual of the best affine map between the first and the last frame,
  4.3 % of the landmarks' extent at seed 0, against House's 3.8 %); yaw 40 twice as much
  (8.6 %).

Usage::

    python benchmarks/verify_auto.py                        # both parts, defaults below
    python benchmarks/verify_auto.py --parts jitter --sigmas 0 0.02 0.04 --collections 10
    python benchmarks/verify_auto.py --parts cmu --frames 6 20 --draws 20 --method RRWM+spectral
    python benchmarks/verify_auto.py --parts perspective --yaws 20 40 --frames 20

Prints one Markdown table: share of pairs verified by the affine map (min-max, mean), mean F1
of ``verify=None``, ``"affine"``, ``("affine", "homography")`` (A/H) and the default (A/H kept
only from 70 % of affinely verified pairs), the smallest and largest per-problem change of
``"affine"`` against ``None``, A/H against ``"affine"`` (mean, problems better / worse), and on
how many problems the default kept the verification.
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


def perspective_sequence(folder, seed: int, yaw_range: float, *, n_frames: int = 101,
                         noise: float = 1.0, name: str = "persp"):
    """Write a generated landmark sequence in the CMU layout into ``folder`` (see the module
    docstring): ``label/<name><k>`` for frame ``k - 1``, one ``x y`` row per landmark."""
    from pathlib import Path

    rng = np.random.default_rng(seed)
    u, v = rng.random((2, 30))
    face = rng.integers(0, 3, 30)
    P = np.where(face[:, None] == 0, np.c_[-1 + 2 * u, 1.2 * v, np.full(30, 0.7)],  # front
                 np.where(face[:, None] == 1, np.c_[np.ones(30), 1.2 * v, -0.7 + 1.4 * u],
                          np.c_[-1 + 2 * u, 1.2 + 0.6 * v, 0.7 * (1 - v)]))           # roof
    P = P - [0.0, 0.9, 0.0]
    pitch = np.deg2rad(15.0)
    Rx = np.array([[1, 0, 0], [0, np.cos(pitch), -np.sin(pitch)],
                   [0, np.sin(pitch), np.cos(pitch)]])
    out = Path(folder) / "label"
    out.mkdir(parents=True, exist_ok=True)
    for k, yaw in enumerate(np.deg2rad(-35 + np.linspace(-yaw_range / 2, yaw_range / 2,
                                                         n_frames))):
        Ry = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0],
                       [-np.sin(yaw), 0, np.cos(yaw)]])
        X = P @ (Rx @ Ry).T
        z = 8.0 - X[:, 2]
        x = np.c_[288 + 700 * X[:, 0] / z, 192 - 700 * X[:, 1] / z]
        np.savetxt(out / f"{name}{k + 1}", x + noise * rng.standard_normal(x.shape), fmt="%.7e")
    return Path(folder)


def _compare(method: str, graphs, truth, seed: int) -> dict:
    """F1 of four settings of ``verify`` on one problem, and the affinely verified share."""
    from transync import match_collection
    from transync.datasets import LANDMARK_AFFINITY
    from transync.experiments.subgraph import METHODS
    from transync.matching import gaussian_edge_affinity
    from transync.metrics import multimatching_precision_recall

    aff = functools.partial(gaussian_edge_affinity, **LANDMARK_AFFINITY)
    kwargs = {k: v for k, v in METHODS[method].items() if k != "verify"}
    out = {}
    for name, verify in (("none", None), ("affine", "affine"),
                         ("both", ("affine", "homography")), ("auto", "auto")):
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
    gain = np.array([r["both"] - r["affine"] for r in rows])
    f1 = {k: np.mean([r[k] for r in rows]) for k in ("none", "affine", "both", "auto")}
    return (f"| {label} | {len(rows)} | {share.min():.2f}-{share.max():.2f} ({share.mean():.2f}) "
            f"| {f1['none']:.3f} | {f1['affine']:.3f} | {f1['both']:.3f} | {f1['auto']:.3f} | "
            f"{delta.min():+.3f} .. {delta.max():+.3f} | {gain.mean():+.4f} "
            f"({np.sum(gain > 0)} / {np.sum(gain < 0)}) | {sum(r['kept'] for r in rows)} |")


def _sequence_rows(folder, args, prefix: str) -> list[str]:
    """Rows of the CMU-layout sequence in ``folder``, one per number of frames."""
    from transync.experiments.cmu import load_sequence
    from transync.experiments.subgraph import _cmu_problem, cmu_keep_range

    seq = load_sequence(folder)
    lo, hi = cmu_keep_range(seq.n_landmarks)
    lines = []
    for frames in args.frames:
        rows = []
        for d in range(args.draws):
            seed = args.seed + 1000 * frames + d
            config = dict(n_frames=frames, keep_low=lo, keep_high=hi)
            prob = _cmu_problem(config, np.random.default_rng(seed), str(folder))
            rows.append(_compare(args.method, prob.graphs, prob.ground_truth, seed))
        lines.append(_row(f"{prefix}{seq.name}, {frames} frames over the sequence, {lo}-{hi} "
                          f"of {seq.n_landmarks} landmarks", rows))
    return lines


def main(argv=None) -> None:
    from transync.experiments.subgraph import METHODS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", nargs="+", default=["jitter", "cmu"],
                    choices=["jitter", "cmu", "perspective"])
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
    ap.add_argument("--yaws", nargs="+", type=float, default=[20.0, 40.0],
                    help="perspective: degrees the camera turns over a sequence")
    ap.add_argument("--seed", type=int, default=0, help="first problem's seed (default: 0)")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    lines = ["| collection | problems | pairs verified (affine): min-max (mean) | "
             "F1 verify=None | F1 'affine' | F1 ('affine', 'homography') | F1 default ('auto') "
             "| 'affine' - None per problem | A/H - 'affine': mean (better / worse) | "
             "default kept the verification |", "|---|---|---|---|---|---|---|---|---|---|"]
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

        folder = args.data or data_home(required=False, subfolder="cmu-house")
        if folder is None:
            print("cmu: no sequence found (pass --data); part skipped")
        else:
            lines += _sequence_rows(folder, args, "")
    if "perspective" in args.parts:
        import tempfile

        for yaw in args.yaws:
            with tempfile.TemporaryDirectory() as tmp:
                folder = perspective_sequence(tmp, args.seed, yaw)
                lines += _sequence_rows(folder, args, f"generated, yaw {yaw:g} deg: ")
    print(f"method {args.method}; {time.perf_counter() - t0:.0f} s")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
