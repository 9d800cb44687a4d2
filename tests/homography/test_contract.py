"""Homography layer: bad input gets a clear error, the rng contract holds (same seed, same
answer; OpenCV's global random state untouched), results are frozen, never change type with a
flag, and pickle (issues 9 and 13)."""

import dataclasses
import logging
import pickle
import threading

import numpy as np
import pytest

from transync.datasets import make_planar_scene
from transync.exceptions import DegenerateInputError, UnlinkedViewsWarning
from transync.homography import (
    DenseOptions,
    PlaneSegmentation,
    chained_homographies,
    estimate_pairwise_homographies,
    estimate_plane_homographies,
    extract_planes,
    misclassification_error,
    refine_homography_ecc,
    segment_plane,
    segment_plane_evidence,
    to_reference_homographies,
)


@pytest.fixture(scope="module")
def small():
    return make_planar_scene(4, image_size=(200, 150), difficulty="easy", rng=1)


FAST = dict(n_features=500, max_iter=1)


# ------------------------------------------------------------------------------- options
@pytest.mark.parametrize("kw, exc, match", [
    ({"dense_weight": float("nan")}, ValueError, r"`dense_weight` must be finite and > 0, got nan"),
    ({"dense_weight": 1e300}, ValueError, r"`dense_weight` must lie in \(0, 1e\+06\]"),
    ({"canvas_margin": 1e6}, ValueError, r"`canvas_margin` must lie in \[0, 2\]"),
    ({"n_features": 0}, ValueError, r"`n_features` must be >= 1, got 0"),
    ({"n_features": 10**12}, ValueError, r"`n_features` must be <= 1000000"),
    ({"levels": 0}, ValueError, r"`levels` must be >= 1, got 0"),
    ({"levels": 20}, ValueError, r"`levels` must be <= 8, got 20"),
    ({"max_step": -1}, ValueError, r"`max_step` must be finite and > 0, got -1"),
    ({"dense": "yes"}, TypeError, r"`dense` must be a bool, got str 'yes'"),
    ({"segment": 1}, TypeError, r"`segment` must be a bool"),
    ({"dense_check": None}, TypeError, r"`dense_check` must be a bool"),
    ({"max_iter": -1}, ValueError, r"`max_iter` must be >= 0"),
    ({"tol": float("inf")}, ValueError, r"`tol` must be finite"),
    ({"dense_target": "median"}, ValueError, r"`dense_target` must be one of"),
    ({"method": "bogus"}, ValueError, r"`method` must be one of 'ransac'"),
    ({"threshold": 0}, ValueError, r"`threshold` must be finite and > 0"),
    ({"n_neighbors": 0}, ValueError, r"`n_neighbors` must be >= 1"),
    ({"pairs": "some"}, ValueError, r"`pairs` must be one of 'auto', 'all'"),
    ({"pairs": 3}, TypeError, r"`pairs` must be 'auto', 'all', a list"),
    ({"reference": 5}, ValueError, r"`reference` must be <= 3, got 5"),
    ({"rng": "seed"}, TypeError, r"`rng` must be None, an int"),
    ({"bogus": 1}, TypeError, r"unexpected keyword arguments \['bogus'\]; dense options"),
])
def test_pipeline_options_validated(small, kw, exc, match):
    with pytest.raises(exc, match=match):
        estimate_plane_homographies(small.images, **kw)


def test_dense_options_object_and_keywords():
    opts = DenseOptions(max_iter=1, dense_weight=2.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.max_iter = 3
    assert pickle.loads(pickle.dumps(opts)) == opts
    assert DenseOptions(levels=np.int64(3)).levels == 3
    with pytest.raises(ValueError, match=r"`sparse_tolerance` must be finite and >= 0"):
        DenseOptions(sparse_tolerance=-0.1)


def test_dense_options_equal_to_keywords(small):
    """``dense=DenseOptions(...)`` and the same fields as keywords are the same call."""
    kw = dict(n_features=500, rng=0, segment=False, rectify=False)
    a = estimate_plane_homographies(small.images, dense=DenseOptions(max_iter=1, levels=1), **kw)
    b = estimate_plane_homographies(small.images, max_iter=1, levels=1, **kw)
    np.testing.assert_array_equal(a.homographies, b.homographies)
    assert a.info["options"] == b.info["options"] == DenseOptions(max_iter=1, levels=1)


# -------------------------------------------------------------------------------- images
def test_blank_images_say_no_pair_could_be_matched():
    with pytest.raises(DegenerateInputError, match=r"no pair of the 3 views could be matched"):
        estimate_plane_homographies([np.zeros((150, 200), np.uint8)] * 3)


@pytest.mark.parametrize("images, exc, match", [
    ([np.zeros((40, 40), complex)] * 2, TypeError, r"`images\[0\]` must be an image array"),
    ([np.zeros((40, 40), bool)] * 2, TypeError, r"`images\[0\]` must be an unsigned/integer "
                                                r"or float image, got dtype bool"),
    ([np.zeros(40, np.uint8)] * 2, ValueError, r"`images\[0\]` must be a \(H, W\) or \(H, W, C\)"),
    ([np.zeros((40, 40, 2), np.uint8)] * 2, ValueError, r"with C in \(1, 3, 4\)"),
    ([np.zeros((40, 40)), np.full((40, 40), np.nan)], ValueError,
     r"`images\[1\]` must be finite, got NaN"),
    ([np.zeros((10, 10), np.uint8)] * 2, ValueError,
     r"`images\[0\]` must be at least 16 x 16 pixels, got shape \(10, 10\)"),
    ([np.full((40, 40), -3, np.int32)] * 2, ValueError, r"`images\[0\]` must be non-negative"),
    ([np.zeros((0, 40), np.uint8)] * 2, ValueError, r"`images\[0\]` is empty"),
    ("a.png", TypeError, r"got a single path"),
    (5, TypeError, r"`images` must be a list of images or paths, got int"),
])
def test_bad_images_refused(images, exc, match):
    with pytest.raises(exc, match=match):
        estimate_plane_homographies(images)
    with pytest.raises(exc, match=match):
        estimate_pairwise_homographies(images)


def test_images_of_different_sizes_are_accepted(small):
    """Views need not share a size (HPatches): the sizes go with each view."""
    imgs = [small.images[0], small.images[1][5:, 10:]]
    pw = estimate_pairwise_homographies(imgs, n_features=500, rng=0)
    assert pw.mask[0, 1]


def test_segment_plane_inputs_checked(small):
    H = small.homographies
    with pytest.raises(ValueError, match=r"`window` must be >= 1, got 0"):
        segment_plane(small.images, H, window=0)
    with pytest.raises(ValueError, match=r"`homographies` must have shape \(4, 3, 3\) "
                                         r"\(one per image\), got \(3, 3, 3\)"):
        segment_plane(small.images, H[:3])
    Hn = H.copy()
    Hn[2, 0, 0] = np.nan
    with pytest.raises(ValueError, match=r"`homographies` must be finite"):
        segment_plane(small.images, Hn)
    with pytest.raises(ValueError, match=r"`margin` must lie in \[0, 2\]"):
        segment_plane(small.images, H, margin=1e6)
    with pytest.raises(ValueError, match=r"`threshold` must lie in \[0, 1\]"):
        segment_plane(small.images, H, threshold=2.0)
    with pytest.raises(TypeError, match="return_evidence"):
        segment_plane(small.images, H, return_evidence=True)


def test_segment_plane_intensity_scale_is_to_grays(small):
    """Float images x 1e30 overflowed float32 in the local variances (all-False masks, or NaN
    into the classifier); [0, 1] floats met a regularizer made for 0..255. The rule is
    to_gray's, so every scale gives the uint8 answer."""
    ref = segment_plane(small.images, small.homographies, rng=0)
    assert np.mean([m.mean() for m in ref]) > 0.9
    for scale in (1e30, 1 / 255):
        got = segment_plane([im.astype(np.float32) * np.float32(scale) for im in small.images],
                            small.homographies, rng=0)
        assert all(np.array_equal(a, b) for a, b in zip(ref, got))
    ev = segment_plane_evidence([im.astype(np.float32) * 1e36 for im in small.images],
                                small.homographies, rng=0)
    assert np.isfinite(ev.median).all() and np.isfinite(ev.probability).all()


def test_segment_plane_degenerate_inputs():
    blank = [np.zeros((64, 64), np.uint8)] * 3                       # was LinAlgError
    masks = segment_plane(blank, np.stack([np.eye(3)] * 3), rng=0)
    assert [m.shape for m in masks] == [(64, 64)] * 3 and all(m.dtype == bool for m in masks)
    tex = (np.random.default_rng(0).random((64, 64)) * 255).astype(np.uint8)
    with pytest.raises(ValueError, match="`homographies` must hold invertible"):
        segment_plane([tex] * 3, np.zeros((3, 3, 3)), rng=0)          # was accepted
    with pytest.raises(ValueError, match=r"`smooth` must lie in \[0, 100\]"):
        segment_plane([tex] * 3, np.stack([np.eye(3)] * 3), smooth=1e10)   # was cv2.error
    with pytest.raises(TypeError, match="`images` must be a list of images, got NoneType"):
        segment_plane(None, np.stack([np.eye(3)] * 3))
    with pytest.raises(TypeError, match=r"`images\[1\]` must be an image array"):
        segment_plane([tex, None, tex], np.stack([np.eye(3)] * 3))


def test_segment_plane_evidence_is_a_result_not_a_flag(small):
    ev = segment_plane_evidence(small.images, small.homographies, rng=0)
    assert isinstance(ev, PlaneSegmentation)
    masks = segment_plane(small.images, small.homographies, rng=0)
    assert isinstance(masks, list)
    assert all(np.array_equal(a, b) for a, b in zip(masks, ev.masks))
    assert ev.probability.shape[0] == 4 and ev.count.max() == 4
    pickle.loads(pickle.dumps(ev))


def test_refine_ecc_inputs_checked(small):
    im = small.images[0]
    with pytest.raises(ValueError, match=r"`mask` must have the shape of `image` \(150, 200\)"):
        refine_homography_ecc(im, im, np.eye(3), mask=np.ones((10, 10), bool))
    with pytest.raises(ValueError, match=r"`H_init` must have shape \(3, 3\)"):
        refine_homography_ecc(im, im, np.eye(2))
    with pytest.raises(ValueError, match=r"`H_init` must be finite"):
        refine_homography_ecc(im, im, np.full((3, 3), np.nan))
    # gauss_size went to OpenCV unchecked: junk and even sizes came back as ok=False
    for g, exc, match in ((2, ValueError, "must be odd"), (-1, ValueError, "must be >= 1"),
                          (None, TypeError, "`gauss_size` must be an int"),
                          ("a", TypeError, "`gauss_size` must be an int")):
        with pytest.raises(exc, match=match):
            refine_homography_ecc(im, im, np.eye(3), gauss_size=g)
    assert refine_homography_ecc(im, im, np.eye(3), gauss_size=1, levels=1)[1]


def test_warp_interpolation_must_be_an_opencv_flag():
    from transync.homography import warp_to_reference

    im = np.zeros((32, 32), np.uint8)
    with pytest.raises(TypeError, match="`interpolation` must be an OpenCV INTER_"):
        warp_to_reference(im, np.eye(3), (32, 32), interpolation=1.0)     # was a cv2.error
    with pytest.raises(ValueError, match="`interpolation` must be one of"):
        warp_to_reference(im, np.eye(3), (32, 32), interpolation=7)
    assert warp_to_reference(im, np.eye(3), (32, 32), interpolation=np.int64(0)).shape == (32, 32)


def test_warps_do_not_depend_on_the_scale_of_the_homography():
    """A homography is defined up to scale; OpenCV's inversion took 1e-40 * I or 1e300 * I for
    singular and returned an all-black canvas (and mean_warped_image counted no view there).
    At ordinary scales the power-of-two rescaling leaves the warp bit for bit as it was."""
    import cv2

    from transync.homography import mean_warped_image, warp_to_reference

    rng = np.random.default_rng(0)
    im = (rng.random((40, 50)) * 200 + 1).astype(np.float32)
    H = np.array([[1.0, 0.02, 1.5], [-0.01, 0.98, -2.0], [1e-4, 0.0, 1.0]])
    plain = warp_to_reference(im, H, (50, 40))
    assert np.array_equal(plain, cv2.warpPerspective(im, H, (50, 40)))
    for s in (1e-300, 1e-40, 1e40, 1e300):
        np.testing.assert_allclose(warp_to_reference(im, H * s, (50, 40)), plain, atol=0.05)
    _, count = mean_warped_image([im, im], np.stack([H, H * 1e300]), size=(50, 40))
    assert count.max() == 2


def test_masks_with_nan_are_refused():
    """NaN cast to bool is True: float masks with NaN were read as valid pixels (every mask the
    library reads goes through one conversion, check_array)."""
    from transync.homography import mean_warped_image

    rng = np.random.default_rng(0)
    im = (rng.random((40, 50)) * 200 + 1).astype(np.float32)
    bad = np.ones(im.shape)
    bad[3, 4] = np.nan
    with pytest.raises(ValueError, match=r"`masks\[1\]` must be finite, got 1 NaN or infinite"):
        mean_warped_image([im, im], np.stack([np.eye(3)] * 2), size=(50, 40),
                          masks=[np.ones(im.shape), bad])
    with pytest.raises(ValueError, match=r"`mask` must be finite, got 1 NaN or infinite"):
        refine_homography_ecc(im, im, np.eye(3), mask=bad)
    _, count = mean_warped_image([im, im], np.stack([np.eye(3)] * 2), size=(50, 40),
                                 masks=[np.ones(im.shape), np.where(np.isnan(bad), 0.0, 1.0)])
    assert count.max() == 2 and count.min() == 1          # a 0.0 entry is a masked-out pixel


def test_pairwise_features_are_checked(small):
    """Hand-made features were only length-checked: float64 descriptors hit FLANN's cv2.error,
    fewer points than descriptors an IndexError."""
    from transync.homography import sift_features

    ims = small.images[:2]
    feats = [sift_features(im, n_features=300) for im in ims]
    as64 = [(p, d.astype(np.float64)) for p, d in feats]
    a = estimate_pairwise_homographies(ims, features=as64, rng=0)
    b = estimate_pairwise_homographies(ims, features=feats, rng=0)
    np.testing.assert_array_equal(a.H, b.H)                  # matched as float32, the same
    (p0, d0), f1 = feats
    big = d0.astype(np.float64) * 1e300
    bad = [
        ([(p0[:5], d0), f1], ValueError,
         r"`features\[0\]\[1\]` \(descriptors\) must have shape \(5, k\)"),
        ([(p0[:, :1], d0), f1], ValueError,
         r"`features\[0\]\[0\]` \(points\) must have shape \(m, 2\)"),
        ([(p0, d0[:, :64]), f1], ValueError, "has width 128, the images before it 64"),
        ([(p0, big), f1], ValueError, "must fit float32"),
        ([(p0 * np.nan, d0), f1], ValueError, r"features\[0\]\[0\] \(points\)` must be finite"),
        ([p0, f1], TypeError, r"`features\[0\]` must be a \(points, descriptors\) pair"),
        ("feats", TypeError, "`features` must be a list"),
        ([f1], ValueError, "one \\(pts, desc\\) pair per image"),
    ]
    for features, exc, match in bad:
        with pytest.raises(exc, match=match):
            estimate_pairwise_homographies(ims, features=features, rng=0)
    with pytest.raises(TypeError, match="`refine` must be a bool"):
        estimate_pairwise_homographies(ims, features=feats, refine="no", rng=0)


def test_iteration_counts_beyond_opencv_are_refused(small):
    """max_iter = 2**31 overflowed OpenCV's int and came back as "degenerate" / a failed pair."""
    from transync.homography import sift_features

    x = np.random.default_rng(0).random((60, 2)) * 100
    with pytest.raises(ValueError, match=r"`max_iter` must be <= 2147483647"):
        extract_planes(x, x + 1, max_iter=2**31, rng=0)
    with pytest.raises(ValueError, match=r"`max_iter` must be <= 2147483647"):
        estimate_pairwise_homographies(small.images[:2], n_features=300, max_iter=2**31, rng=0)
    with pytest.raises(ValueError, match=r"`n_features` must be <= 1000000"):
        sift_features(small.images[0], n_features=2**31)


# ----------------------------------------------------------------------------- multiplane
def test_misclassification_error_labels_checked():
    with pytest.raises(ValueError, match=r"`pred` must hold labels >= 0 \(0 = outlier\), got -5"):
        misclassification_error([-5, 0], [0, 1])
    with pytest.raises(ValueError, match=r"`truth` must hold integer labels"):
        misclassification_error([0, 1], [0, 0.5])
    with pytest.raises(TypeError, match=r"`pred` must hold integer labels, got dtype <U1"):
        misclassification_error(np.array(["a", "b"]), [0, 1])
    # large label values cost nothing: labels are compacted
    assert misclassification_error([0, 10**12, 10**12], [0, 3, 3]) == 0.0


def test_extract_planes_options_checked():
    x = np.random.default_rng(0).uniform(0, 100, (30, 2))
    with pytest.raises(ValueError, match=r"`method` must be one of 'ransac'.*got 'bogus'"):
        extract_planes(x, x, method="bogus")
    with pytest.raises(ValueError, match=r"`x1` must be finite"):
        extract_planes(np.full((30, 2), np.nan), x)
    res = extract_planes(x, x + 1.0, rng=np.random.default_rng(0))   # a Generator works
    assert len(res.homographies) == 1
    a = extract_planes(x, x + 1.0, rng=3)
    b = extract_planes(x, x + 1.0, rng=np.random.default_rng(3))
    np.testing.assert_array_equal(a.labels, b.labels)


# ------------------------------------------------------------------------- baselines, NaN
def test_baselines_warn_about_views_without_estimate(small):
    imgs = list(small.images[:3]) + [np.zeros((150, 200), np.uint8)]
    with pytest.warns(UnlinkedViewsWarning, match=r"to_reference_homographies: views \[3\]"):
        H = to_reference_homographies(imgs, n_features=500, rng=0)
    assert np.isnan(H[3]).all() and np.isfinite(H[:3]).all()
    imgs = [small.images[0], np.zeros((150, 200), np.uint8), small.images[2]]
    with pytest.warns(UnlinkedViewsWarning, match=r"chained_homographies: views \[1, 2\]"):
        H = chained_homographies(imgs, n_features=500, rng=0)
    assert np.isnan(H[1:]).all()


def test_pipeline_warns_unlinked_views(small):
    imgs = list(small.images) + [np.zeros((150, 200), np.uint8)]
    with pytest.warns(UnlinkedViewsWarning, match=r"views \[4\] could not be linked"):
        res = estimate_plane_homographies(imgs, rng=0, **FAST)
    assert np.isnan(res.homographies[4]).all()
    assert np.isfinite(res.homographies[:4]).all()


# ------------------------------------------------------------------------------ rng contract
def _same(a, b):
    np.testing.assert_array_equal(a.homographies, b.homographies)
    np.testing.assert_array_equal(a.sparse_homographies, b.sparse_homographies)
    assert all(np.array_equal(x, y) for x, y in zip(a.masks, b.masks))


def _opencv_noise():
    import cv2

    cv2.setRNGSeed(12345)
    out = np.zeros((50, 50), np.float32)
    cv2.randu(out, 0, 1)
    m = cv2.FlannBasedMatcher({"algorithm": 1, "trees": 4}, {"checks": 32})
    d = np.random.default_rng(0).random((200, 128), dtype=np.float32)
    m.knnMatch(d, d, k=2)


def test_same_seed_same_answer_whatever_opencv_does_in_between(small):
    a = estimate_plane_homographies(small.images, rng=5, **FAST)
    _opencv_noise()
    b = estimate_plane_homographies(small.images, rng=5, **FAST)
    _same(a, b)
    # an equal Generator, while another thread uses OpenCV's random state
    t = threading.Thread(target=lambda: [_opencv_noise() for _ in range(20)])
    t.start()
    c = estimate_plane_homographies(small.images, rng=np.random.default_rng(5), **FAST)
    t.join()
    _same(a, c)


def test_pipeline_leaves_opencv_random_state_alone(small):
    import cv2

    def draw():
        out = np.zeros(8, np.float32)
        cv2.randu(out, 0, 1)
        return out

    cv2.setRNGSeed(7)
    expected = draw()
    cv2.setRNGSeed(7)
    estimate_plane_homographies(small.images, rng=0, **FAST)
    np.testing.assert_array_equal(draw(), expected)


def test_seed_reaches_every_stochastic_stage(small, monkeypatch):
    """The pairwise, rectified and segmentation stages each get a generator (not None)."""
    import transync.homography._pipeline as pipe   # white-box: the stage functions

    seen = {}
    real_pw, real_rect, real_seg = (pipe.estimate_pairwise_homographies,
                                    pipe.estimate_rectified_pairwise, pipe.segment_plane)

    def spy(name, real):
        def f(*args, **kw):
            seen.setdefault(name, []).append(kw.get("rng"))
            return real(*args, **kw)
        return f

    monkeypatch.setattr(pipe, "estimate_pairwise_homographies", spy("pairs", real_pw))
    monkeypatch.setattr(pipe, "estimate_rectified_pairwise", spy("rect", real_rect))
    monkeypatch.setattr(pipe, "segment_plane", spy("seg", real_seg))
    estimate_plane_homographies(small.images, rng=0, **FAST)
    gens = [g for name in ("pairs", "rect", "seg") for g in seen[name]]
    assert all(isinstance(g, np.random.Generator) for g in gens)
    assert len({id(g) for g in gens}) == 3      # one child generator per stage


# --------------------------------------------------------------------- logging and results
def test_progress_is_logged_not_printed(small, caplog, capsys):
    with caplog.at_level(logging.INFO, logger="transync.homography"):
        res = estimate_plane_homographies(small.images, rng=0, verbose=True, **FAST)
    assert "round 1: max corner change" in caplog.text
    assert "sparse pairs: 6 of 6 linked" in caplog.text
    assert capsys.readouterr().out == ""
    back = pickle.loads(pickle.dumps(res))
    np.testing.assert_array_equal(back.homographies, res.homographies)
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.n_iter = 5


def test_evaluate_alignment_pairwise_keys_whatever_the_estimates():
    """pairwise=True dropped its keys when one view had no estimate (the result's keys
    depended on the data); a failed view now counts 1000 px, as in the per-view errors, and
    views that do not overlap give the documented NaN."""
    from transync.geometry import translation
    from transync.homography import evaluate_alignment

    rng = np.random.default_rng(0)
    ims = [(rng.random((40, 50)) * 255).astype(np.uint8) for _ in range(3)]
    masks = [np.ones((40, 50), bool)] * 3
    H = np.stack([translation(0, 0), translation(2, 1), translation(-1, 3)])
    H_est = H.copy()
    H_est[2] = np.nan
    r = evaluate_alignment(ims, H_est, H, masks_true=masks, pairwise=True)
    assert r["pairwise_max_error"] == 1000.0 and 0 < r["pairwise_mean_error"] < 1000.0
    assert r["pairwise_median_error"] >= 0
    apart = np.stack([translation(0, 0), translation(1000, 0)])
    r = evaluate_alignment(ims[:2], apart, apart, masks_true=masks[:2], pairwise=True)
    assert r["mean_error"] == 0.0
    assert np.isnan([r["pairwise_mean_error"], r["pairwise_max_error"],
                     r["pairwise_median_error"]]).all()


def test_precomputed_pairs_are_checked_field_by_field(small):
    """A hand-made PairwiseHomographies was only shape-checked: matches=None gave an
    AttributeError, NaN or singular H and absurd weights surfaced as the synchronization's
    `T` / `weights`."""
    pw = estimate_pairwise_homographies(small.images, n_features=400, rng=0)
    H_nan, H_sing, W, M = pw.H.copy(), pw.H.copy(), pw.weights.copy(), pw.mask.copy()
    H_nan[0, 1] = np.nan
    H_sing[1, 2] = 0.0
    W[0, 1] = W[1, 0] = 1e300
    M[0, 1] = False                                      # no longer symmetric
    bad = [({"matches": None}, TypeError, r"`pairs.matches` must be a dict"),
           ({"H": H_nan}, ValueError, r"`pairs.H\[0, 1\]` must be a finite invertible.*NaN"),
           ({"H": H_sing}, ValueError, r"`pairs.H\[1, 2\]` must be a finite invertible.*"
                                       r"singular"),
           ({"H": pw.H[:3, :3]}, ValueError, r"`pairs.H` must have shape \(4, 4, 3, 3\)"),
           ({"weights": W}, ValueError, r"`pairs.weights` must be finite, in \[0, 1e\+12\]"),
           ({"mask": M}, ValueError, r"`pairs.mask` must be a symmetric"),
           ({"matches": {(0, 9): next(iter(pw.matches.values()))}}, ValueError,
            r"`pairs.matches` keys must be pairs \(i, j\) of view indices in \[0, 4\)"),
           ({"matches": {(0, 1): (np.zeros((3, 2)), np.zeros((3, 2)))}}, TypeError,
            r"`pairs.matches\[\(0, 1\)\]` must be \(pts_i, pts_j, inliers\)"),
           ({"matches": {(0, 1): (np.zeros((3, 2)), np.zeros((4, 2)), np.ones(3, bool))}},
            ValueError, r"two \(m, 2\) point arrays and m inlier flags")]
    for change, exc, match in bad:
        with pytest.raises(exc, match=match):
            estimate_plane_homographies(small.images, pairs=dataclasses.replace(pw, **change),
                                        **FAST, rng=0)
    # the valid object is used as given, lists for arrays included
    as_lists = dataclasses.replace(pw, H=pw.H.tolist(), weights=pw.weights.tolist())
    a = estimate_plane_homographies(small.images, pairs=as_lists, dense=False, segment=False,
                                    rng=0)
    b = estimate_plane_homographies(small.images, pairs=pw, dense=False, segment=False, rng=0)
    np.testing.assert_array_equal(a.homographies, b.homographies)


@pytest.mark.parametrize("fn", [to_reference_homographies, chained_homographies])
def test_baselines_refuse_pairs_by_name(fn):
    """`pairs=` in the options passed on was a duplicate keyword (a raw TypeError)."""
    with pytest.raises(TypeError, match=r"takes no `pairs`: the baseline matches"):
        fn([np.zeros((32, 32), np.uint8)] * 2, pairs=[(0, 1)])


@pytest.mark.parametrize("images, got", [(3, "int 3"), (None, "NoneType"), ("a.png", "str")])
def test_every_image_list_taker_names_images(images, got):
    """images=3 raised a bare "'int' object is not iterable" from evaluate_alignment and
    mean_warped_image; the three image-list takers now share one check."""
    from transync.homography import evaluate_alignment, mean_warped_image, segment_plane

    H = np.tile(np.eye(3), (2, 1, 1))
    calls = [lambda: evaluate_alignment(images, H, H, masks_true=None),
             lambda: mean_warped_image(images, H, size=(8, 8)),
             lambda: segment_plane(images, H)]
    for call in calls:
        with pytest.raises(TypeError, match=rf"`images` must be a list of .*got {got}"):
            call()
    with pytest.raises(TypeError, match="got one 2-D array"):
        mean_warped_image(np.zeros((8, 8)), H, size=(8, 8))
