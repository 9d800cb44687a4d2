"""Refusals and documented values from the homography review of 2026-11-30."""

import numpy as np
import pytest

from transync.datasets import make_planar_scene
from transync.homography import (
    estimate_rectified_pairwise,
    evaluate_alignment,
    load_images,
    sift_features,
)


@pytest.fixture(scope="module")
def scene():
    return make_planar_scene(3, image_size=(160, 120), difficulty="easy", noise=0.0, rng=1)


@pytest.mark.parametrize("ratio, exc, match", [
    ("x", TypeError, r"`ratio`"), (None, TypeError, r"`ratio`"),
    (0.0, ValueError, r"`ratio`"), (5.0, ValueError, r"`ratio` must lie in \(0, 1\], got 5.0"),
])
def test_rectified_pass_checks_ratio_on_its_guided_path(scene, ratio, exc, match):
    # the guided (default) path used ratio unchecked: numpy's UFuncTypeError for "x", every
    # pair "failed" with a RuntimeWarning for 0, 5.0 accepted
    with pytest.raises(exc, match=match):
        estimate_rectified_pairwise(list(scene.images), scene.homographies, [(0, 1)],
                                    ratio=ratio)


def test_a_single_grey_image_is_not_a_list_of_rows():
    # split into rows, it was refused as "`images[0]` ... got shape (160,)"
    grey = np.full((120, 160), 7, np.uint8)
    with pytest.raises(TypeError, match=r"got a single \(120, 160\) grey image; pass"):
        load_images(grey)
    assert [im.shape for im in load_images([grey, grey])] == [(120, 160)] * 2


def test_sift_features_wants_at_least_one_keypoint():
    # 0 reached OpenCV, whose 0 means "every keypoint"
    img = (np.random.default_rng(0).random((64, 64)) * 255).astype(np.uint8)
    with pytest.raises(ValueError, match=r"`n_features` must be >= 1, got 0"):
        sift_features(img, n_features=0)
    pts, desc = sift_features(img, n_features=5)
    assert 0 < len(pts) <= 5 + 2 and desc.shape == (len(pts), 128)   # OpenCV keeps ties


def test_brenner_ratio_without_texture_is_nan_not_zero(scene):
    # a perfect alignment of texture-less views read 0.0, as a complete failure
    flat = [np.full_like(np.asarray(im), 9) for im in scene.images]
    r = evaluate_alignment(flat, scene.homographies, scene.homographies,
                           masks_true=list(scene.masks))
    assert np.isnan(r["brenner_ratio"]) and r["mean_error"] < 1e-6
    ok = evaluate_alignment(list(scene.images), scene.homographies, scene.homographies,
                            masks_true=list(scene.masks))
    assert ok["brenner_ratio"] == pytest.approx(1.0)
