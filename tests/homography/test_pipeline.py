"""Tests for the multi-view plane homography pipeline (small images, fast)."""

import numpy as np
import pytest

from transync.datasets import make_planar_scene
from transync.exceptions import UnlinkedViewsWarning
from transync.homography import (
    brenner_focus,
    chained_homographies,
    corner_error,
    estimate_pairwise_homographies,
    estimate_plane_homographies,
    estimate_rectified_pairwise,
    evaluate_alignment,
    extract_planes,
    misclassification_error,
    refine_homography_ecc,
    segment_plane,
    segmentation_scores,
    to_reference_homographies,
)


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
    res = estimate_plane_homographies(scene.images, n_features=1000, max_iter=2, rng=0)
    e = corner_error(res.homographies, scene.homographies, image_size=(320, 240))
    es = corner_error(res.sparse_homographies, scene.homographies, image_size=(320, 240))
    assert es.max() < 1.0
    assert e.mean() < 0.3
    assert len(res.masks) == 5 and res.masks[0].shape == (240, 320)
    assert res.mean_image.shape == (240, 320)
    assert res.info["history"]


def test_pipeline_callback_every_round(scene):
    calls = []

    def cb(it, H, masks):
        calls.append((it, H, masks))
        H[:] = np.nan          # copies: the pipeline must not see these edits
        masks[0][:] = False

    res = estimate_plane_homographies(scene.images, n_features=1000, max_iter=2, tol=0.0,
                                      callback=cb, rng=0)
    assert [c[0] for c in calls] == [1, 2] == [h["iteration"] for h in res.info["history"]]
    assert all(c[1].shape == (5, 3, 3) and len(c[2]) == 5 for c in calls)
    assert np.all(np.isfinite(res.homographies)) and res.masks[0].any()
    # round 1 flips the clutter pixels of the all-plane start; round 2 changes far fewer
    ch = [h["mask_change"] for h in res.info["history"]]
    assert 0.05 < ch[0] < 0.5 and ch[1] < ch[0] / 5
    # the first call carries the segmentation computed from the sparse estimate
    assert 0.5 < segmentation_scores(np.stack(calls[1][2]), scene.masks)["f1"] <= 1.0
    with pytest.raises(TypeError, match="callback"):
        estimate_plane_homographies(scene.images[:2], callback=3)


def test_brenner_prefers_sharp():
    rng = np.random.default_rng(0)
    img = rng.random((64, 64))
    import cv2
    blurred = cv2.GaussianBlur(img, (0, 0), 1.5)
    assert brenner_focus(img) > brenner_focus(blurred)


def test_bad_images():
    with pytest.raises(ValueError, match="at least 2"):
        estimate_plane_homographies([np.zeros((40, 40), np.uint8)])
    with pytest.raises(ValueError, match="cannot read"):
        estimate_plane_homographies(["/nonexistent/a.png", "/nonexistent/b.png"])


def test_canvas_too_large_is_refused_before_the_sparse_stage():
    """A 4000 x 2700 reference with canvas_margin=2 needs a 20000 x 13500 canvas (270 M
    pixels): refused at once, naming canvas_margin (not the internal `size` of
    mean_warped_image, after the sparse stage); the segmentation alone needs the canvas too."""
    big = np.zeros((2700, 4000), np.uint8)
    with pytest.raises(ValueError, match=r"`canvas_margin`=2 on the reference view 0 "
                                         r"\(4000 x 2700 pixels\) makes a 20000 x 13500"):
        estimate_plane_homographies([big, big], canvas_margin=2.0)
    wide = np.zeros((16, 7000), np.uint8)                 # 35000 pixels a side
    with pytest.raises(ValueError, match="beyond 32767 pixels a side"):
        estimate_plane_homographies([wide, wide], canvas_margin=2.0, dense=False)


def test_scene_rendering_matches_ground_truth(scene):
    """Warping a view with its true homography reproduces the reference on the plane."""
    import cv2

    ref = scene.clean_images[0].astype(np.float32)
    w, h = scene.image_size
    for i in range(1, scene.n_views):
        wi = cv2.warpPerspective(scene.clean_images[i].astype(np.float32), scene.homographies[i],
                                 (w, h))
        vi = cv2.warpPerspective(scene.masks[i].astype(np.uint8), scene.homographies[i], (w, h),
                                 flags=cv2.INTER_NEAREST) > 0
        v = cv2.erode((vi & scene.masks[0]).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        assert v.sum() > 1000
        assert np.median(np.abs(wi[v] - ref[v])) < 3.0
        # a one-pixel shift of the true homography is clearly visible
        S = np.array([[1.0, 0, 1.0], [0, 1, 0], [0, 0, 1]])
        ws = cv2.warpPerspective(scene.clean_images[i].astype(np.float32),
                                 S @ scene.homographies[i], (w, h))
        assert np.median(np.abs(ws[v] - ref[v])) > 2 * np.median(np.abs(wi[v] - ref[v]))


def test_texture_crops_never_repeat():
    # white-box: the texture dealer of the scene generator
    from transync.datasets._scenes import _PatchDealer, _patch_pool

    pool = _patch_pool(96)
    assert len(pool) > 200
    flat = np.stack([p.ravel() for p in pool[:80]])
    # distinct crops: no two crops (of the first 80) are near-identical
    d = np.corrcoef(flat)
    np.fill_diagonal(d, 0)
    assert d.max() < 0.95
    dealer = _PatchDealer(96, np.random.default_rng(0))
    order = [dealer.order[k] for k in range(len(pool))]
    assert len(set(order)) == len(pool)


def test_rectified_pairs_and_precomputed_pairs(scene):
    T = np.einsum("iab,jbc->ijac", np.linalg.inv(scene.homographies), scene.homographies)
    rng = np.random.default_rng(1)
    H0 = scene.homographies.copy()
    H0[1:, :2, 2] += rng.normal(0, 1.0, (4, 2))       # a rough current estimate
    pw = estimate_rectified_pairwise(scene.images, H0, [(0, 1), (1, 2), (0, 3)],
                                     n_features=1000, rng=0)
    assert pw.mask[0, 1] and pw.mask[2, 1] and not pw.mask[0, 2]
    assert corner_error(pw.H[0, 1], T[0, 1], image_size=(320, 240)) < 0.5
    # precomputed pairwise estimates go straight to synchronization
    with pytest.warns(UnlinkedViewsWarning, match=r"views \[4\]"):
        res = estimate_plane_homographies(scene.images, pairs=pw, dense=False, segment=False)
    e = corner_error(res.homographies[[1, 2, 3]], scene.homographies[[1, 2, 3]],
                     image_size=(320, 240))
    assert e.max() < 0.5
    assert np.isnan(res.homographies[4]).all()


def test_multiplane_extraction_planted():
    rng = np.random.default_rng(0)
    x1 = rng.uniform(0, 200, (300, 2))
    H1 = np.array([[1.0, 0.05, 10], [0.02, 1.0, -5], [1e-4, 0, 1]])
    H2 = np.array([[0.9, -0.1, 30], [0.1, 0.95, 20], [0, 2e-4, 1]])
    truth = np.r_[np.ones(150, int), np.full(100, 2), np.zeros(50, int)]

    def tr(H, x):
        p = np.c_[x, np.ones(len(x))] @ H.T
        return p[:, :2] / p[:, 2:]

    x2 = np.r_[tr(H1, x1[:150]), tr(H2, x1[150:250]), rng.uniform(0, 200, (50, 2))]
    x2[:250] += rng.normal(0, 0.3, (250, 2))
    res = extract_planes(x1, x2, threshold=2.0, rng=0)
    assert len(res.homographies) == 2
    assert misclassification_error(res.labels, truth) < 0.05
    assert misclassification_error(truth, truth) == 0.0
    with pytest.raises(ValueError, match="same length"):
        misclassification_error([0, 1], [0])


def test_baselines_and_evaluation(scene):
    H = to_reference_homographies(scene.images, n_features=1000)
    ev = evaluate_alignment(scene.images, H, scene.homographies, masks_true=scene.masks,
                            masks_est=list(scene.masks), pairwise=True)
    assert ev["max_error"] < 1.0 and ev["acc_1px"] == 1.0
    assert ev["f1"] == 1.0 and 0.98 < ev["brenner_ratio"] <= 1.01
    Hc = chained_homographies(scene.images, n_features=1000)
    assert np.isfinite(Hc).all()
    ev_true = evaluate_alignment(scene.images, scene.homographies, scene.homographies,
                                 masks_true=scene.masks)
    assert ev_true["mean_error"] == 0.0 and ev_true["brenner_ratio"] == pytest.approx(1.0)


def test_experiment_trial_and_build():
    from transync.experiments import REGISTRY
    from transync.experiments.homography import build, trial

    assert REGISTRY["homography"] == "transync.experiments.homography"
    exp = build(quick=True)
    assert exp.name == "homography" and exp.trials == 1
    cfg = dict(n_views=4, image_size=(240, 180), max_angle=20.0, clutter=0.1, features=800,
               method="sync")
    out = trial(cfg, np.random.default_rng(0))
    assert out["max_error"] < 1.0 and out["brenner_ratio"] > 0.98
    out = trial({**cfg, "init_error": 2.0}, np.random.default_rng(0))
    assert np.isfinite(out["mean_error"])
    # data sets override the scene parameters; sync_dense records the state before the dense
    # step and the segmentation of every round (filled forward after convergence)
    assert exp.sweeps[0].name == "datasets"
    out = trial({**cfg, "dataset": "no clutter", "method": "sync_dense"},
                np.random.default_rng(0))
    for k in ("sparse_mean_error", "sparse_brenner_ratio", "precision", "recall", "f1"):
        assert np.isfinite(out[k]), k
    assert 1 <= out["n_iter"] <= 3
    assert out["precision_r3"] == out["precision_r" + str(out["n_iter"])]
    assert out["recall_r1"] > 0.95          # no clutter: (nearly) every pixel is plane


def test_round_scores_fill_forward():
    from transync.experiments.homography import _round_scores

    truth = [np.array([[True, True], [False, False]])]
    r1 = [np.array([[True, False], [True, False]])]      # P 1/2, R 1/2
    r2 = [np.array([[True, True], [False, False]])]      # exact
    out = _round_scores([r1, r2], truth, n_rounds=3)
    assert (out["precision_r1"], out["recall_r1"]) == (0.5, 0.5)
    assert out["precision_r2"] == out["precision_r3"] == 1.0 == out["recall_r3"]


def test_experiment_thesis_outputs(tmp_path):
    """Tables 5.1-5.5 and the figures from stored records (planted values), Fig. 5.1/5.4 from one
    small scene."""
    from transync.experiments.homography import finish

    records = []
    for d, err in (("1", 0.1), ("no clutter", 0.05)):
        for t in range(2):
            for method, m in (("ransac_to_reference", {"mean_error": 4 * err}),
                              ("chained", {"mean_error": 8 * err}),
                              ("sync_dense", {"mean_error": err, "sparse_mean_error": 2 * err,
                                              "precision_r1": 0.9, "recall_r1": 0.8,
                                              "precision": 0.95, "recall": 0.9, "f1": 0.92})):
                m = {"max_error": 2 * m["mean_error"], "brenner_ratio": 1 - m["mean_error"] / 10,
                     "sparse_brenner_ratio": 0.999, **m}
                records.append({"sweep": "datasets", "error": None, "trial": t,
                                "config": {"dataset": d, "method": method}, "metrics": m})
    records.append({"sweep": "datasets", "error": "boom", "trial": 0,
                    "config": {"dataset": "1", "method": "chained"}, "metrics": {}})
    base = {"n_views": 4, "image_size": (200, 150), "max_angle": 20.0, "clutter": 0.2,
            "features": 600}
    paths = finish(records, [], tmp_path, base=base)
    assert {p.name for p in paths} == {"tables_5_1-5_5.md", "fig_5_3a_datasets.png",
                                       "fig_5_5_precision_recall.png",
                                       "fig_5_1_5_4_segmentation.png"}
    assert all(p.stat().st_size > 0 for p in paths)
    md = (tmp_path / "tables_5_1-5_5.md").read_text()
    # data set 1, mean corner error: RANSAC 0.4, chained 0.8, before dense 0.2, after 0.1
    assert "| 1 | 2 | 0.400 ± 0.000 | 0.800 ± 0.000 | 0.200 ± 0.000 | 0.100 ± 0.000 |" in md
    assert ("| no clutter | 0.900 ± 0.000 | 0.800 ± 0.000 | 0.950 ± 0.000 | 0.900 ± 0.000 | "
            "0.920 ± 0.000 |") in md

@pytest.mark.slow
@pytest.mark.parametrize("difficulty", ["moderate", "hard"])
def test_full_pipeline_targets(difficulty):
    """Issue #4 targets on one generated 640x480 scene with N = 20 (minutes: slow)."""
    sc = make_planar_scene(20, difficulty=difficulty, rng=0)
    res = estimate_plane_homographies(sc.images, rng=0)
    sparse = corner_error(res.sparse_homographies, sc.homographies, image_size=sc.image_size)
    assert sparse.max() <= (0.25 if difficulty == "moderate" else 0.5)
    ev = evaluate_alignment(sc.images, res.homographies, sc.homographies, masks_true=sc.masks,
                            masks_est=res.masks)
    assert ev["mean_error"] <= (0.06 if difficulty == "moderate" else 0.1)
    assert ev["brenner_ratio"] >= 0.9995
    assert ev["f1"] >= 0.95


def test_sparse_residual_planted():
    # white-box: the dense safeguard's residual (private stage helper)
    from transync.geometry import transfer_points as _apply
    from transync.homography._pipeline import _sparse_residual

    rng = np.random.default_rng(0)
    H = np.stack([np.eye(3), np.array([[1.0, 0.02, 5], [0.01, 0.98, -3], [1e-4, 0, 1]])])
    x1 = rng.uniform(0, 300, (50, 2))
    x0 = _apply(H[1], x1)                       # view 1 -> reference (view 0)
    corr = {(0, 1): (x0, x1)}
    assert _sparse_residual(1, H[1], H, corr) < 1e-9
    S = np.array([[1.0, 0, 0.7], [0, 1, 0], [0, 0, 1]])
    assert _sparse_residual(1, S @ H[1], H, corr) == pytest.approx(0.7)
    assert _sparse_residual(0, S, H, corr) == pytest.approx(0.7)
    assert np.isnan(_sparse_residual(1, H[1], H, {}))


def test_dense_safeguard_falls_back_on_wrong_mask(scene, monkeypatch):
    """ECC fed with the clutter instead of the plane must not degrade the sparse solution."""
    import transync.homography._pipeline as pipe

    def wrong_masks(images, homographies, *, reference=0, **kw):
        # planted failure of the segmentation: the complement of the true plane masks
        return [~np.asarray(m) for m in scene.masks[:len(images)]]

    monkeypatch.setattr(pipe, "segment_plane", wrong_masks)
    kw = dict(n_features=1000, max_iter=1, pairs="all", rng=0)
    res = estimate_plane_homographies(scene.images, **kw)
    es = corner_error(res.sparse_homographies, scene.homographies, image_size=(320, 240))
    e = corner_error(res.homographies, scene.homographies, image_size=(320, 240))
    views = res.info["history"][0]["dense_views"]
    status = {k: v["status"] for k, v in views.items()}
    assert sum(s != "accepted" for s in status.values()) >= 3
    assert set(res.info["history"][0]["rejected_dense"]) == {k for k, s in status.items()
                                                             if s != "accepted"}
    assert all("sparse_after" in v for v in views.values() if v["status"] != "diverged")
    assert e.mean() <= es.mean() + 0.02


def test_dense_safeguard_rejects_planted_bad_updates(scene, monkeypatch):
    """Dense updates planted 1.5 px off are rejected (sparse check), the others accepted."""
    import transync.homography._pipeline as pipe

    real = pipe.refine_homography_ecc
    calls = []

    def bad_ecc(template, image, H_init, **kw):
        H, ok = real(template, image, H_init, **kw)
        calls.append(len(calls))
        if len(calls) in (3, 4):                 # the 3rd and 4th views of the round
            S = np.array([[1.0, 0, 1.5], [0, 1, -1.0], [0, 0, 1]])
            H = S @ H
        return H, ok

    monkeypatch.setattr(pipe, "refine_homography_ecc", bad_ecc)
    kw = dict(n_features=1000, max_iter=1, pairs="all", rng=0)
    res = estimate_plane_homographies(scene.images, **kw)
    status = {k: v["status"] for k, v in res.info["history"][0]["dense_views"].items()}
    assert [k for k, s in status.items() if s == "rejected_sparse"] == [2, 3]
    assert res.info["history"][0]["rejected_dense"] == [2, 3]
    e = corner_error(res.homographies, scene.homographies, image_size=(320, 240))
    es = corner_error(res.sparse_homographies, scene.homographies, image_size=(320, 240))
    assert e.max() < es.max() + 0.05
    calls.clear()
    raw = estimate_plane_homographies(scene.images, dense_check=False, **kw)
    er = corner_error(raw.homographies, scene.homographies, image_size=(320, 240))
    assert er.max() > 0.5                        # without the safeguard the bad update stays


def test_auto_pairs_exhaustive_then_view_graph(scene, monkeypatch):
    """``pairs="auto"``: every pair up to EXHAUSTIVE_UP_TO views, the k-nearest view graph beyond."""
    kw = dict(n_features=800, dense=False, segment=False, rectify=False, rng=0)
    full = estimate_plane_homographies(scene.images, **kw)
    assert full.pairwise.mask.sum() == 5 * 4               # all 10 pairs, both directions
    monkeypatch.setattr("transync.homography._pipeline.EXHAUSTIVE_UP_TO", 3)
    graph = estimate_plane_homographies(scene.images, n_neighbors=1, **kw)
    m = graph.pairwise.mask
    assert m[0, 1:].all()                                  # every view linked to the reference
    assert m.sum() < full.pairwise.mask.sum()
    for res in (full, graph):
        err = corner_error(res.homographies, scene.homographies, image_size=(320, 240))
        assert err.max() < 0.5


def test_pairwise_fits_repeatable_and_thread_independent(scene, monkeypatch):
    """Pairs are fitted on threads; per-pair seeding makes the result independent of them."""
    import os

    kw = dict(n_features=600, rng=3)
    a = estimate_pairwise_homographies(scene.images, **kw)       # 10 pairs: threaded
    b = estimate_pairwise_homographies(scene.images, **kw)
    monkeypatch.setattr(os, "cpu_count", lambda: 1)
    c = estimate_pairwise_homographies(scene.images, **kw)       # sequential
    for other in (b, c):
        np.testing.assert_array_equal(a.mask, other.mask)
        np.testing.assert_array_equal(a.H[a.mask], other.H[other.mask])
        np.testing.assert_array_equal(a.weights, other.weights)


def test_dense_edge_weight_relative_to_the_views_sparse_pairs():
    """Re-synchronization: a view's dense edge weighs ``dense_weight`` x the sum of its sparse
    weights, so scaling all inlier counts changes nothing, and the weight moves the result from
    the sparse towards the dense estimate."""
    # white-box: the re-synchronization stage of the pipeline
    from transync.homography import PairwiseHomographies
    from transync.homography._pipeline import _resynchronize

    n, size = 4, (320, 240)
    rng = np.random.default_rng(0)
    H = np.stack([np.eye(3)] + [np.eye(3) + np.diag([1, 1, 0]) @ rng.normal(0, 0.01, (3, 3))
                                for _ in range(n - 1)])
    H[1:, :2, 2] += rng.normal(0, 5, (n - 1, 2))
    T = np.einsum("iab,jbc->ijac", np.linalg.inv(H), H)      # exact sparse pairs
    mask = ~np.eye(n, dtype=bool)
    shift = np.eye(3)
    shift[0, 2] = 1.0                                         # dense estimate of view 2: 1 px off
    H_dense = {i: (shift @ H[i] if i == 2 else H[i]) for i in range(n)}

    def run(scale, dense_weight):
        pw = PairwiseHomographies(H=T, mask=mask, weights=scale * mask.astype(float), failed=[])
        out, _ = _resynchronize(H, H_dense, pw, np.arange(n), 0, [size] * n, "mean",
                                robust=False, dense_weight=dense_weight)
        return corner_error(out[2], H[2], image_size=size)

    e = {w: run(50.0, w) for w in (0.01, 1.0, 100.0)}
    assert e[0.01] < 0.05 < e[1.0] < e[100.0] < 1.0 and e[100.0] > 0.9
    # equal say: the weighted least-squares compromise of this graph (1 px dense offset of view
    # 2 against exact sparse pairs, all views with 3 pairs) puts view 2 at 3/7 px
    assert e[1.0] == pytest.approx(3 / 7, rel=1e-6)
    assert run(7 * 50.0, 1.0) == pytest.approx(e[1.0], rel=1e-6)


def test_dense_stage_refines_precomputed_pairs_without_matches():
    # pairs given without inlier matches (PairwiseHomographies' default): the dense check had
    # nothing to compare with, NaN <= x was False, and every update was silently rejected
    from transync.geometry import translation
    from transync.homography import PairwiseHomographies

    scene = make_planar_scene(5, image_size=(240, 180), difficulty="easy", noise=0.0, rng=0)
    rng = np.random.default_rng(0)
    T = np.einsum("iab,jbc->ijac", np.linalg.inv(scene.homographies), scene.homographies)
    H = np.full_like(T, np.nan)
    for i in range(5):
        for j in range(i + 1, 5):                         # coarse pairs: ~2 px off
            H[i, j] = T[i, j] @ translation(*rng.normal(0, 2, 2))
            H[j, i] = np.linalg.inv(H[i, j])
    mask = ~np.eye(5, dtype=bool)
    pw = PairwiseHomographies(H=H, mask=mask, weights=mask * 100.0, failed=[])
    res = estimate_plane_homographies(scene.images, pairs=pw, max_iter=3, rng=0)
    views = res.info["history"][0]["dense_views"]
    assert all(v["status"] == "accepted" and v["sparse_check"] == "no inlier matches"
               for v in views.values())
    sparse = corner_error(res.sparse_homographies, scene.homographies, image_size=(240, 180))
    final = corner_error(res.homographies, scene.homographies, image_size=(240, 180))
    assert final[1:].mean() < 0.75 * sparse[1:].mean()


def test_unlinked_view_has_an_empty_mask_and_its_failed_pairs_are_kept():
    # a view no pair links kept an all-plane mask (the CLI report said "empty mask"), and the
    # rectified second pass replaced the pairwise result, dropping the first pass's failures
    scene = make_planar_scene(n_views=2, image_size=(320, 240), rng=0)
    images = list(scene.images) + [np.full((240, 320), 128, np.uint8)]
    with pytest.warns(UnlinkedViewsWarning):
        res = estimate_plane_homographies(images, dense=False, rng=0)
    assert not res.masks[2].any() and res.masks[0].any()
    assert {(i, j) for i, j, _ in res.pairwise.failed} == {(0, 2), (1, 2)}
