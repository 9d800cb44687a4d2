"""Tests for the multi-view plane homography pipeline (small images, fast)."""

import numpy as np
import pytest

from transync.datasets._scenes import make_planar_scene
from transync.homography import brenner_focus, corner_error, segmentation_scores
from transync.homography._dense import refine_homography_ecc
from transync.homography._pipeline import estimate_plane_homographies
from transync.homography._segmentation import segment_plane
from transync.homography._sparse import estimate_pairwise_homographies


@pytest.fixture(scope="module")
def scene():
    return make_planar_scene(5, image_size=(320, 240), difficulty="moderate", rng=0)


def test_scene_ground_truth_consistent(scene):
    assert np.allclose(scene.homographies[0], np.eye(3))
    np.testing.assert_allclose(np.linalg.det(scene.homographies), 1.0, atol=1e-9)
    assert 0.05 < 1 - scene.masks[0].mean() < 0.4


def test_sparse_pairs_and_failed_pairs_recorded(scene):
    imgs = list(scene.images) + [np.zeros((240, 320), np.uint8)]
    pw = estimate_pairwise_homographies(imgs, n_features=1000)
    assert pw.mask[0, 1] and pw.mask[1, 0]
    assert not pw.mask[5].any()
    assert any(5 in (i, j) for i, j, _ in pw.failed)
    T = np.einsum("iab,jbc->ijac", np.linalg.inv(scene.homographies), scene.homographies)
    assert corner_error(pw.H[0, 2], T[0, 2], image_size=(320, 240)) < 1.0


def test_ecc_refines_with_mask(scene):
    H0 = scene.homographies[1].copy()
    P = np.eye(3)
    P[:2, 2] = [1.0, -0.7]
    H, ok = refine_homography_ecc(scene.images[0], scene.images[1], P @ H0,
                                  mask=scene.masks[1], template_mask=scene.masks[0])
    assert ok
    assert corner_error(H, H0, image_size=(320, 240)) < 0.2


def test_segmentation_with_true_homographies(scene):
    masks = segment_plane(scene.images, scene.homographies)
    s = segmentation_scores(np.stack(masks), scene.masks)
    assert s["precision"] > 0.9 and s["recall"] > 0.8


def test_pipeline_small(scene):
    res = estimate_plane_homographies(scene.images, n_features=1000, max_iter=2)
    e = corner_error(res.homographies, scene.homographies, image_size=(320, 240))
    es = corner_error(res.sparse_homographies, scene.homographies, image_size=(320, 240))
    assert es.max() < 1.0
    assert e.mean() < 0.3
    assert len(res.masks) == 5 and res.masks[0].shape == (240, 320)
    assert res.mean_image.shape == (240, 320)
    assert res.info["history"]


def test_brenner_prefers_sharp():
    rng = np.random.default_rng(0)
    img = rng.random((64, 64))
    import cv2
    blurred = cv2.GaussianBlur(img, (0, 0), 1.5)
    assert brenner_focus(img) > brenner_focus(blurred)


def test_bad_images():
    with pytest.raises(ValueError, match="at least 2"):
        estimate_plane_homographies([np.zeros((10, 10), np.uint8)])
    with pytest.raises(ValueError, match="cannot read"):
        estimate_plane_homographies(["/nonexistent/a.png", "/nonexistent/b.png"])
