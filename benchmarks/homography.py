"""Benchmark: multi-view plane homographies on generated 640x480 scenes, N = 20 (issue #4 targets).

In one run, on the same moderate (+-25 deg, ~20 % clutter) and hard (+-45 deg, ~33 % clutter)
scenes: the OpenCV baselines (every view SIFT + RANSAC to the reference; consecutive views
chained) against :func:`transync.estimate_plane_homographies` without the dense step (``sync``)
and in full (``sync_dense``), each through the trial function of ``transync experiment
homography`` (so the benchmark and the experiment measure the same thing; ``sync`` is its own
run with ``dense=False, segment=False``, timed like the others). Reports mean / max corner error of the non-reference views, the
error over all overlapping pairs, accuracy at 1 px, the Brenner ratio of the mean warped image
(estimated vs true homographies over the true masks; ``own`` = estimated homographies and masks
vs the true ones), segmentation precision / recall / F1, time, the load average, and the ratios
to the to-reference baseline. Targets: sync max <= 0.25 px (moderate), <= 0.5 px (hard);
sync_dense mean <= 0.06 px, Brenner >= 0.9995, F1 >= 0.95, whole pipeline < 60 s.

    python benchmarks/homography.py                 # seeds 0 1 2, moderate and hard
    python benchmarks/homography.py --quick         # one moderate scene
    python benchmarks/homography.py --json out.json
"""

from __future__ import annotations

import argparse
import json
import os

import numpy as np

from transync.datasets import make_planar_scene
from transync.experiments.homography import METHODS, trial

#: the scene presets of make_planar_scene, as (max_angle, clutter) of the experiment's trials
PRESETS = {"moderate": (25.0, 0.20), "hard": (45.0, 0.33)}


def run_scene(difficulty, seed, n_views=20, size=(640, 480)):
    """Every method of ``transync experiment homography`` on one scene: the experiment's own
    :func:`~transync.experiments.homography.trial` (same scene for every method: rendered from
    ``seed``), with all metrics; ``seconds`` is the estimation only, timed alike for every method.
    """
    max_angle, clutter = PRESETS[difficulty]
    config = {"n_views": n_views, "image_size": tuple(size), "max_angle": max_angle,
              "clutter": clutter, "features": 2000, "all_metrics": True}
    rows = []
    for method in METHODS:
        out = trial({**config, "method": method}, np.random.default_rng(seed))
        row = {"difficulty": difficulty, "seed": seed, "method": method,
               "load": os.getloadavg()[0], **out}
        if "n_iter" in out:
            row["rounds"] = out["n_iter"]
        rows.append(row)
    return rows


def check_scene(difficulty, seed, n_views=20, size=(640, 480)) -> bool:
    """The trials render exactly the preset scene of ``make_planar_scene(difficulty=...)``."""
    max_angle, clutter = PRESETS[difficulty]
    a = make_planar_scene(n_views, image_size=size, difficulty=difficulty, rng=seed)
    b = make_planar_scene(n_views, image_size=size, max_angle=max_angle, clutter=clutter,
                          rng=np.random.default_rng(seed))
    return all(np.array_equal(x, y) for x, y in zip(a.images, b.images))


def _fmt(v, nd=3):
    return "—" if v is None or (isinstance(v, float) and not np.isfinite(v)) else f"{v:.{nd}f}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one moderate scene")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--difficulty", nargs="+", default=["moderate", "hard"])
    ap.add_argument("--json", help="write all rows to this JSON file")
    args = ap.parse_args(argv)
    seeds = [0] if args.quick else args.seeds
    diffs = ["moderate"] if args.quick else args.difficulty
    rows = []
    if not check_scene(diffs[0], seeds[0], size=(160, 120)):
        raise SystemExit("the experiment's scenes differ from the make_planar_scene presets")
    for d in diffs:
        for s in seeds:
            rows += run_scene(d, s)
    cols = ["mean_error", "max_error", "pairwise_mean_error", "pairwise_median_error", "acc_1px", "brenner_ratio",
            "brenner_ratio_own_masks", "precision", "recall", "f1", "seconds", "load"]
    print("| scene | seed | method | " + " | ".join(cols) + " |")
    print("|---|---|---|" + "---|" * len(cols))
    for r in rows:
        print(f"| {r['difficulty']} | {r['seed']} | {r['method']} | "
              + " | ".join(_fmt(r.get(c), 5 if c.startswith("brenner") else 3) for c in cols)
              + " |")
    print()
    print("ratios to ransac_to_reference (mean error, max error), averaged over seeds:")
    for d in diffs:
        base = [r for r in rows if r["difficulty"] == d and r["method"] == "ransac_to_reference"]
        for m in ("chained", "sync", "sync_dense"):
            sub = [r for r in rows if r["difficulty"] == d and r["method"] == m]
            rm = np.mean([a["mean_error"] / b["mean_error"] for a, b in zip(sub, base)])
            rx = np.mean([a["max_error"] / b["max_error"] for a, b in zip(sub, base)])
            print(f"  {d:9s} {m:11s} mean x{rm:.3f}  max x{rx:.3f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1, default=float)


if __name__ == "__main__":
    main()
