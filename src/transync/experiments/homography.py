"""Multi-view plane homographies on generated scenes (thesis Fig. 5.1, 5.3-5.5, Tables 5.1-5.5).

Methods on the same rendered scene (:func:`transync.datasets.make_planar_scene`):

* ``ransac_to_reference`` - every view matched to the reference (SIFT + ratio + RANSAC + LM);
* ``chained`` - consecutive views matched and chained to the reference (the incremental,
  structure-from-motion-like baseline in place of the thesis's VisualSFM);
* ``sync`` - :func:`transync.estimate_plane_homographies` without the dense step and
  segmentation (sparse estimates of all pairs, or of a view graph beyond 40 views, and robust
  SL(3) synchronization);
* ``sync_dense`` - the whole pipeline (segmentation + dense ECC + re-synchronization). Its trials
  also record the synchronized sparse estimate of the same run (``sparse_*``: the state before
  the dense optimization) and the precision/recall of the plane masks after every round
  (``precision_r1``...: round 1 is the segmentation obtained from the sparse estimate).

Sweeps:

* ``datasets`` - five named scene settings, data sets 1-4 of growing difficulty and "no clutter"
  (:data:`DATASETS`): homography accuracy of every method per data set (Fig. 5.3a), the Brenner
  focus ratio before and after the optimization (Tables 5.1-5.5), plane precision/recall per
  iteration (Fig. 5.5);
* ``init_error`` - error of the initial pairwise homographies (Fig. 5.3b: ground-truth pairs of a
  view graph perturbed by random corner displacements of the given size, no SIFT;
  ``ransac_to_reference`` then means the perturbed to-reference pairs without synchronization);
* ``angle``, ``clutter``, ``views`` - maximum view angle, clutter fraction and number of views.

Besides the standard plot, a run writes ``fig_5_3a_datasets.png``, ``fig_5_5_precision_recall.png``,
``tables_5_1-5_5.md`` (from the stored trials) and ``fig_5_1_5_4_segmentation.png`` (one scene of
data set 2 with ``rng=0``: a view, its warp into the reference, the initial and final plane
segmentation against the truth; the pipeline is run once more for it).
Metrics: mean and max corner error of the non-reference views, Brenner ratio of the mean warped
image (estimated vs true homographies, over the true plane masks), segmentation F1
(``sync_dense``) and seconds (the estimation only, not the evaluation).
"""

from __future__ import annotations

import functools
import time
from pathlib import Path

import numpy as np

from ..datasets import make_planar_scene
from ..geometry import image_corners
from ..homography import (
    PairwiseHomographies,
    chained_homographies,
    estimate_plane_homographies,
    evaluate_alignment,
    to_reference_homographies,
)
from ..metrics import segmentation_scores
from ..synchronization import synchronize_homographies
from ._plot import pyplot
from ._runner import Experiment, Sweep, mean_se

METHODS = ("ransac_to_reference", "chained", "sync", "sync_dense")

#: The named scene settings of the ``datasets`` sweep (maximum view angle in degrees, target
#: fraction of the reference view covered by clutter).
DATASETS = {
    "1": {"max_angle": 15.0, "clutter": 0.1},
    "2": {"max_angle": 25.0, "clutter": 0.2},
    "3": {"max_angle": 35.0, "clutter": 0.25},
    "4": {"max_angle": 45.0, "clutter": 0.33},
    "no clutter": {"max_angle": 25.0, "clutter": 0.0},
}
#: rounds of segmentation + dense refinement (the pipeline's default ``max_iter``)
ROUNDS = 3


def _perturb(H, sigma, size, rng):
    """``H`` followed by the homography moving the 4 image corners by N(0, sigma^2) pixels."""
    import cv2

    c = image_corners(size).astype(np.float32)
    d = (c + rng.normal(0, sigma, c.shape)).astype(np.float32)
    return cv2.getPerspectiveTransform(c, d) @ H


def _noisy_pairs(scene, sigma, rng, k=3):
    """Perturbed ground-truth pairs: each view to the reference and to ``k`` random others."""
    n = scene.n_views
    Ht = scene.homographies
    pairs = {(0, i) for i in range(1, n)}
    for i in range(1, n):
        for j in rng.choice([v for v in range(1, n) if v != i], size=min(k, n - 2),
                            replace=False):
            pairs.add((min(i, int(j)), max(i, int(j))))
    T = np.full((n, n, 3, 3), np.nan)
    mask = np.zeros((n, n), bool)
    for i, j in sorted(pairs):
        Hij = _perturb(np.linalg.inv(Ht[i]) @ Ht[j], sigma, scene.image_size, rng)
        T[i, j], T[j, i] = Hij, np.linalg.inv(Hij)
        mask[i, j] = mask[j, i] = True
    return PairwiseHomographies(H=T, mask=mask, weights=mask.astype(float), failed=[])


def _make_scene(config, rng):
    params = {"max_angle": config["max_angle"], "clutter": config["clutter"]}
    if config.get("dataset") is not None:
        params.update(DATASETS[config["dataset"]])
    return make_planar_scene(config["n_views"], image_size=tuple(config["image_size"]), rng=rng,
                             **params)


def _round_scores(rounds, masks_true, n_rounds=ROUNDS) -> dict:
    """Precision/recall of the masks of every round; rounds the pipeline skipped after
    converging keep the last masks it computed."""
    truth = np.concatenate([np.ravel(m) for m in masks_true])
    out = {}
    last = None
    for k in range(1, n_rounds + 1):
        if k <= len(rounds):
            last = segmentation_scores(np.concatenate([np.ravel(m) for m in rounds[k - 1]]),
                                       truth)
        if last is not None:
            out[f"precision_r{k}"], out[f"recall_r{k}"] = last["precision"], last["recall"]
    return out


def _estimate(method, scene, config, rng, record):
    """The estimate of one method on one scene: ``(H, masks, result)`` (``masks`` and the
    pipeline's ``result`` only for ``sync_dense``)."""
    imgs, features = scene.images, config["features"]
    sigma = config.get("init_error")
    if sigma is not None:
        pw = _noisy_pairs(scene, float(sigma), np.random.default_rng(rng.integers(2**31)))
        if method == "ransac_to_reference":
            return np.stack([np.eye(3)] + [pw.H[0, i] for i in range(1, scene.n_views)]), None, None
        if method == "sync":
            return synchronize_homographies(pw.H, mask=pw.mask, reference=0, robust=True,
                                            image_size=scene.image_size).maps, None, None
        res = estimate_plane_homographies(imgs, pairs=pw, n_features=features, max_iter=ROUNDS,
                                          callback=record, rng=rng)
        return res.homographies, res.masks, res
    if method == "ransac_to_reference":
        return to_reference_homographies(imgs, n_features=features, rng=rng), None, None
    if method == "chained":
        return chained_homographies(imgs, n_features=features, rng=rng), None, None
    if method == "sync":
        return estimate_plane_homographies(imgs, dense=False, segment=False, n_features=features,
                                           rng=rng).homographies, None, None
    res = estimate_plane_homographies(imgs, n_features=features, max_iter=ROUNDS, callback=record,
                                      rng=rng)
    return res.homographies, res.masks, res


_KEEP = ("mean_error", "max_error", "acc_1px", "brenner_ratio", "precision", "recall", "f1")


def trial(config: dict, rng: np.random.Generator) -> dict:
    """One rendered scene, one method (``config["method"]``, one of :data:`METHODS`).

    ``seconds`` times the estimation only (not the rendering or the evaluation), the same way
    for every method. With ``config["all_metrics"]`` (used by ``benchmarks/homography.py``)
    every measure of :func:`~transync.homography.evaluate_alignment` is returned, pairwise
    errors included.
    """
    scene = _make_scene(config, rng)
    method = config["method"]
    if method == "chained" and config.get("init_error") is not None:
        return {}
    full = bool(config.get("all_metrics", False))
    rounds = []
    t0 = time.perf_counter()
    H, masks, res = _estimate(method, scene, config, rng, lambda it, H, m: rounds.append(m))
    seconds = time.perf_counter() - t0
    out = evaluate_alignment(scene.images, H, scene.homographies, masks_true=scene.masks,
                             masks_est=masks, pairwise=full)
    metrics = {**(out if full else {k: out[k] for k in _KEEP if k in out}), "seconds": seconds}
    if res is not None:
        sparse = evaluate_alignment(scene.images, res.sparse_homographies, scene.homographies,
                                    masks_true=scene.masks)
        metrics.update({f"sparse_{k}": sparse[k]
                        for k in ("mean_error", "max_error", "brenner_ratio")})
        metrics.update(_round_scores(rounds, scene.masks))
        metrics["n_iter"] = res.n_iter
    return metrics


def build(*, quick: bool = False) -> Experiment:
    if quick:
        # small images and few views: the dense step needs enough views for the consensus, so
        # the quick numbers favour it less than the full 640x480, N = 20 runs
        base = dict(n_views=6, image_size=(240, 180), max_angle=25.0, clutter=0.2, features=800)
        angles, clutters, errors, views = [15.0, 35.0], [0.3], [2.0], [4, 8]
        datasets = ["2", "no clutter"]
        trials = 1
    else:
        base = dict(n_views=20, image_size=(640, 480), max_angle=25.0, clutter=0.2,
                    features=2000)
        angles = [10.0, 20.0, 30.0, 40.0, 50.0]
        clutters = [0.0, 0.1, 0.2, 0.3, 0.4]
        errors = [0.5, 1.0, 2.0, 4.0, 8.0]
        views = [5, 10, 20, 30]
        datasets = list(DATASETS)
        trials = 5
    metrics = ("mean_error", "max_error", "brenner_ratio", "f1", "seconds")
    sweeps = [
        Sweep(name="datasets", variable="dataset", values=datasets,
              methods=("ransac_to_reference", "chained", "sync_dense"), base=base,
              metrics=metrics, xlabel="data set (Fig. 5.3a, Tables 5.1-5.5, Fig. 5.5)"),
        Sweep(name="init_error", variable="init_error", values=errors,
              methods=("ransac_to_reference", "sync", "sync_dense"), base=base,
              metrics=metrics,
              xlabel="corner noise of the initial pairwise homographies (std, px)"),
        Sweep(name="angle", variable="max_angle", values=angles, methods=METHODS, base=base,
              metrics=metrics, xlabel="maximum view angle (degrees)"),
        Sweep(name="clutter", variable="clutter", values=clutters, methods=METHODS, base=base,
              metrics=metrics, xlabel="clutter fraction of the reference view"),
        Sweep(name="views", variable="n_views", values=views, methods=METHODS, base=base,
              metrics=metrics, xlabel="number of views N"),
    ]
    if quick:
        sweeps = sweeps[:3]
    return Experiment(name="homography", sweeps=sweeps, trial=trial, trials=trials,
                      description="RANSAC vs synchronized vs synchronized + dense on rendered "
                                  "planar scenes",
                      finish=functools.partial(finish, base=base))


# --------------------------------------------------------------------------- thesis outputs
def _cell(values, fmt="{:.4f}"):
    m, se, n = mean_se(values)
    if n == 0:
        return "—"
    return fmt.format(m) if n == 1 else (fmt + " ± " + fmt).format(m, se)


def _dataset_records(records):
    """{dataset: {method: [metrics, ...]}} of the successful ``datasets`` trials."""
    out = {}
    for r in records:
        if r["sweep"] != "datasets" or r["error"]:
            continue
        out.setdefault(r["config"]["dataset"], {}).setdefault(r["config"]["method"], []).append(
            r["metrics"])
    return {d: out[d] for d in DATASETS if d in out}


def finish(records, summary, out_dir, *, base) -> list[Path]:
    """Thesis-style outputs from the stored trials (and one extra pipeline run for Fig. 5.1/5.4)."""
    out = Path(out_dir)
    data = _dataset_records(records)
    paths = []
    if data:
        paths.append(_write_tables(data, out / "tables_5_1-5_5.md"))
        paths.append(_plot_datasets(data, out / "fig_5_3a_datasets.png"))
        paths.append(_plot_precision_recall(data, out / "fig_5_5_precision_recall.png"))
    paths.append(_plot_segmentation_example(base, out / "fig_5_1_5_4_segmentation.png"))
    return paths


_COLUMNS = (("RANSAC to reference", "ransac_to_reference", ""),
            ("chained", "chained", ""),
            ("sync (before dense)", "sync_dense", "sparse_"),
            ("sync + dense (after)", "sync_dense", ""))


def _write_tables(data, path) -> Path:
    intro = ("Brenner focus measure of the mean of all views warped into the reference view "
             "(each view's gain and bias fitted to the running mean first, "
             "`mean_warped_image(normalize=True)`) with the estimated homographies, divided by "
             "the same measure with the true "
             "homographies (over the true plane pixels; 1 = as sharp as the truth). \"before\" "
             "is the synchronized sparse estimate, \"after\" the same run after segmentation + "
             "dense refinement. Mean ± standard error over trials.")
    lines = ["# Tables 5.1-5.5: focus of the mean warped image before and after optimization", "",
             intro, ""]
    for title, key, fmt in (("Brenner ratio", "brenner_ratio", "{:.5f}"),
                            ("mean corner error (px)", "mean_error", "{:.3f}"),
                            ("worst-view corner error (px)", "max_error", "{:.3f}")):
        lines += [f"## {title}", "",
                  "| data set | trials | " + " | ".join(c[0] for c in _COLUMNS) + " |",
                  "|---" * (len(_COLUMNS) + 2) + "|"]
        for d, by_method in data.items():
            cells = [_cell([m.get(prefix + key) for m in by_method.get(method, [])], fmt)
                     for _, method, prefix in _COLUMNS]
            n = len(by_method.get("sync_dense", []))
            lines.append(f"| {d} | {n} | " + " | ".join(cells) + " |")
        lines.append("")
    header = ("| data set | precision, round 1 | recall, round 1 | precision, final | "
              "recall, final | F1, final |")
    lines += ["## Plane segmentation (sync + dense)", "", header, "|---|---|---|---|---|---|"]
    for d, by_method in data.items():
        ms = by_method.get("sync_dense", [])
        lines.append(f"| {d} | " + " | ".join(_cell([m.get(k) for m in ms], "{:.3f}") for k in (
            "precision_r1", "recall_r1", "precision", "recall", "f1")) + " |")
    lines += ["", "Data sets: " + "; ".join(
        f"{d}: views within ±{p['max_angle']:g}°, clutter {p['clutter']:g}"
        for d, p in DATASETS.items()) + "."]
    path.write_text("\n".join(lines) + "\n")
    return path


def _plot_datasets(data, path) -> Path:
    plt = pyplot()
    names = list(data)
    x = np.arange(len(names))
    width = 0.8 / len(_COLUMNS)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax, key, label in ((axes[0], "mean_error", "mean corner error (px)"),
                           (axes[1], "max_error", "worst-view corner error (px)")):
        for k, (title, method, prefix) in enumerate(_COLUMNS):
            stats = [mean_se([m.get(prefix + key) for m in data[d].get(method, [])])
                     for d in names]
            ax.bar(x + (k - (len(_COLUMNS) - 1) / 2) * width, [s[0] for s in stats], width,
                   yerr=[s[1] for s in stats], label=title, capsize=2)
        ax.set_xticks(x, names)
        ax.set_xlabel("data set")
        ax.set_ylabel(label)
        ax.set_yscale("log")
        ax.grid(alpha=0.3, axis="y")
    axes[1].legend(fontsize=7, frameon=False, loc="center left", bbox_to_anchor=(1.0, 0.5))
    fig.suptitle("Fig. 5.3a: homography accuracy per generated data set", fontsize=10)
    fig.text(0.01, 0.005, "Bars: mean over trials; error bars: ± 1 standard error of the mean.",
             fontsize=7.5, color="0.3")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path


def _plot_precision_recall(data, path) -> Path:
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
    rounds = list(range(1, ROUNDS + 1))
    for ax, key in ((axes[0], "precision"), (axes[1], "recall")):
        for d, by_method in data.items():
            ms = by_method.get("sync_dense", [])
            stats = [mean_se([m.get(f"{key}_r{k}") for m in ms]) for k in rounds]
            stats.append(mean_se([m.get(key) for m in ms]))
            mean = np.array([s[0] for s in stats])
            se = np.array([s[1] for s in stats])
            xs = np.arange(len(stats))
            label = f"data set {d}" if d[0].isdigit() else d
            line, = ax.plot(xs, mean, marker="o", ms=3.5, label=label)
            ax.fill_between(xs, mean - se, mean + se, color=line.get_color(), alpha=0.2, lw=0)
        ax.set_xticks(np.arange(ROUNDS + 1), [str(k) for k in rounds] + ["final"])
        ax.set_xlabel("iteration (segmentation round)")
        ax.set_ylabel(f"plane pixel {key}")
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7, frameon=False, loc="center left", bbox_to_anchor=(1.0, 0.5))
    fig.suptitle("Fig. 5.5: plane segmentation per iteration", fontsize=10)
    fig.text(0.01, 0.005, "Lines: mean over trials; band: ± 1 standard error of the mean.",
             fontsize=7.5, color="0.3")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path


def _plot_segmentation_example(base, path) -> Path:
    """Fig. 5.1 / 5.4: one scene of data set 2, a view warped into the reference, the initial
    (round 1) and final plane masks against the true one."""
    import cv2

    config = {**dict(base), "dataset": "2"}
    scene = _make_scene(config, np.random.default_rng(0))
    rounds = []
    res = estimate_plane_homographies(scene.images, n_features=config["features"],
                                      max_iter=ROUNDS, rng=0,
                                      callback=lambda it, H, m: rounds.append(m))
    # the view most covered by clutter among the last half (tilted views)
    n = scene.n_views
    view = max(range(n // 2, n), key=lambda i: float((~scene.masks[i]).mean()))
    w, h = scene.image_size
    Hv = res.homographies[view]
    warped = (cv2.warpPerspective(scene.images[view], Hv, (w, h), flags=cv2.INTER_LINEAR,
                                  borderValue=0)
              if np.all(np.isfinite(Hv)) else np.zeros((h, w), np.uint8))   # view not registered
    first = rounds[0][view] if rounds else res.masks[view]
    final = res.masks[view]
    truth = scene.masks[view]

    def score(m):
        s = segmentation_scores(m, truth)
        return f"P {s['precision']:.3f}  R {s['recall']:.3f}"

    plt = pyplot()
    fig, axes = plt.subplots(2, 3, figsize=(11, 6.6))
    panels = [(scene.images[scene.reference], "reference view", "gray"),
              (scene.images[view], f"view {view}", "gray"),
              (warped, f"view {view} warped into the reference", "gray"),
              (truth, "true plane mask", "gray"),
              (first, "initial segmentation (round 1)\n" + score(first), "gray"),
              (final, "final segmentation\n" + score(final), "gray")]
    for ax, (img, title, cmap) in zip(axes.ravel(), panels):
        ax.imshow(img, cmap=cmap, vmin=0, vmax=255 if img.dtype != bool else 1)
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    fig.suptitle("Fig. 5.1 / 5.4: generated scene (data set 2, rng 0), recovered homography and "
                 "plane segmentation", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
