"""Multi-view plane homographies on generated scenes (thesis Fig. 5.3-5.5, Tables 5.1-5.5).

Methods on the same rendered scene (:func:`transync.datasets.make_planar_scene`):

* ``ransac_to_reference`` - every view matched to the reference (SIFT + ratio + RANSAC + LM);
* ``chained`` - consecutive views matched and chained to the reference;
* ``sync`` - :func:`transync.estimate_plane_homographies` without the dense step and
  segmentation (view graph + robust SL(3) synchronization);
* ``sync_dense`` - the whole pipeline (segmentation + dense ECC + re-synchronization).

Sweeps: maximum view angle (Fig. 5.3a), clutter fraction (Fig. 5.4), error of the initial
pairwise homographies (Fig. 5.3b: ground-truth pairs of the view graph perturbed by random
corner displacements of the given size, no SIFT; ``ransac_to_reference`` then means the perturbed
to-reference pairs without synchronization) and the number of views (Fig. 5.5).
Metrics: mean and max corner error of the non-reference views, Brenner ratio of the mean warped
image (estimated vs true homographies), segmentation F1 (``sync_dense``) and seconds.
"""

from __future__ import annotations

import time

import numpy as np

from ..datasets._scenes import make_planar_scene
from ..homography._evaluate import (
    chained_homographies,
    evaluate_alignment,
    to_reference_homographies,
)
from ..homography._pipeline import estimate_plane_homographies
from ..homography._sparse import PairwiseHomographies
from ..synchronization import synchronize_homographies
from ._runner import Experiment, Sweep

METHODS = ("ransac_to_reference", "chained", "sync", "sync_dense")


def _perturb(H, sigma, size, rng):
    """``H`` followed by the homography moving the 4 image corners by N(0, sigma^2) pixels."""
    import cv2

    w, h = size
    c = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float32)
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


def trial(config: dict, rng: np.random.Generator) -> dict:
    """One rendered scene, one method."""
    scene = make_planar_scene(config["n_views"], image_size=tuple(config["image_size"]),
                              max_angle=config["max_angle"], clutter=config["clutter"],
                              rng=rng)
    method = config["method"]
    sigma = config.get("init_error")
    imgs = scene.images
    t0 = time.perf_counter()
    masks = None
    if sigma is not None:
        pw = _noisy_pairs(scene, float(sigma), np.random.default_rng(rng.integers(2**31)))
        if method == "ransac_to_reference":
            H = np.stack([np.eye(3)] + [pw.H[0, i] for i in range(1, scene.n_views)])
        elif method == "chained":
            return {}
        elif method == "sync":
            H = synchronize_homographies(pw.H, mask=pw.mask, reference=0, robust=True,
                                         image_size=scene.image_size).maps
        else:
            res = estimate_plane_homographies(imgs, pairs=pw, n_features=config["features"])
            H, masks = res.homographies, res.masks
    elif method == "ransac_to_reference":
        H = to_reference_homographies(imgs, n_features=config["features"])
    elif method == "chained":
        H = chained_homographies(imgs, n_features=config["features"])
    elif method == "sync":
        H = estimate_plane_homographies(imgs, dense=False, segment=False,
                                        n_features=config["features"]).homographies
    else:
        res = estimate_plane_homographies(imgs, n_features=config["features"])
        H, masks = res.homographies, res.masks
    seconds = time.perf_counter() - t0
    out = evaluate_alignment(imgs, H, scene.homographies, masks_true=scene.masks,
                             masks_est=masks)
    keep = ("mean_error", "max_error", "acc_1px", "brenner_ratio", "f1")
    return {**{k: out[k] for k in keep if k in out}, "seconds": seconds}


def build(*, quick: bool = False) -> Experiment:
    if quick:
        # small images and few views: the dense step needs enough views for the consensus, so
        # the quick numbers favour it less than the full 640x480, N = 20 runs
        base = dict(n_views=6, image_size=(240, 180), max_angle=25.0, clutter=0.2, features=800)
        angles, clutters, errors, views = [15.0, 35.0], [0.3], [2.0], [4, 8]
        trials = 1
    else:
        base = dict(n_views=20, image_size=(640, 480), max_angle=25.0, clutter=0.2,
                    features=2000)
        angles = [10.0, 20.0, 30.0, 40.0, 50.0]
        clutters = [0.0, 0.1, 0.2, 0.3, 0.4]
        errors = [0.5, 1.0, 2.0, 4.0, 8.0]
        views = [5, 10, 20, 30]
        trials = 5
    metrics = ("mean_error", "max_error", "brenner_ratio", "f1", "seconds")
    sweeps = [
        Sweep(name="angle", variable="max_angle", values=angles, methods=METHODS, base=base,
              metrics=metrics, xlabel="maximum view angle (degrees)"),
        Sweep(name="clutter", variable="clutter", values=clutters, methods=METHODS, base=base,
              metrics=metrics, xlabel="clutter fraction of the reference view"),
        Sweep(name="init_error", variable="init_error", values=errors,
              methods=("ransac_to_reference", "sync", "sync_dense"), base=base,
              metrics=metrics, xlabel="corner error of the initial pairwise homographies (px)"),
    ]
    if quick:
        sweeps = [sweeps[0], sweeps[2]]
    else:
        sweeps.append(Sweep(name="views", variable="n_views", values=views, methods=METHODS,
                            base=base, metrics=metrics, xlabel="number of views N"))
    return Experiment(name="homography", sweeps=sweeps, trial=trial, trials=trials,
                      description="RANSAC vs synchronized vs synchronized + dense on rendered "
                                  "planar scenes")
