"""Sparse pairwise homographies with OpenCV: SIFT, Lowe's ratio test, RANSAC (+ LM polish)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from .._validation import (
    as_generator,
    check_array,
    check_bool,
    check_choice,
    check_homographies,
    check_index_pairs,
    check_int,
    check_positive,
)
from ..datasets import read_image
from ..geometry import transfer_points, translation

__all__ = [
    "PairwiseHomographies",
    "estimate_pairwise_homographies",
    "estimate_rectified_pairwise",
    "load_images",
    "sift_features",
    "to_gray",
]

_METHODS = {
    "ransac": cv2.RANSAC,
    "lmeds": cv2.LMEDS,
    "rho": cv2.RHO,
    "usac_default": cv2.USAC_DEFAULT,
    "usac_magsac": cv2.USAC_MAGSAC,
    "usac_accurate": cv2.USAC_ACCURATE,
    "usac_prosac": cv2.USAC_PROSAC,
    "usac_fast": cv2.USAC_FAST,
}


@dataclass(frozen=True)
class PairwiseHomographies:
    """Pairwise homographies of a view graph.

    Attributes
    ----------
    H : ndarray (N, N, 3, 3)
        ``H[i, j]`` maps pixels of view ``j`` into view ``i`` (NaN where not estimated); both
        directions of every successful pair are filled.
    mask : ndarray (N, N), bool
        Successful pairs (symmetric).
    weights : ndarray (N, N)
        Inlier counts (symmetric, 0 where failed).
    failed : list of (i, j, reason)
        Attempted pairs that did not give a homography.
    matches : dict
        ``(i, j) -> (pts_i, pts_j, inlier)``, the ratio-test matches of each attempted pair.
    info : dict
        ``n_keypoints`` per view, ``seconds``.

    Examples
    --------
    See :func:`estimate_pairwise_homographies`, which returns one.

    >>> import numpy as np
    >>> H = np.full((2, 2, 3, 3), np.nan)
    >>> H[0, 1] = H[1, 0] = np.eye(3)
    >>> pw = PairwiseHomographies(H=H, mask=~np.eye(2, dtype=bool), weights=np.ones((2, 2)),
    ...                           failed=[])
    >>> pw.H.shape, bool(pw.mask[0, 1])
    ((2, 2, 3, 3), True)
    """

    H: np.ndarray
    mask: np.ndarray
    weights: np.ndarray
    failed: list
    matches: dict = field(repr=False, default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)


_MIN_SIZE = 16


_FLOAT32_MAX = float(np.finfo(np.float32).max)


def check_image_list(images, what: str = "images") -> list:
    """``images`` as a list, refused (``TypeError`` naming ``images``) when it is one 2-D array,
    a path, ``None`` or not iterable; ``what`` says what its entries must be."""
    if isinstance(images, np.ndarray) and images.ndim == 2:
        raise TypeError(f"`images` must be a list of {what}, got one 2-D array")
    if images is None or isinstance(images, (str, bytes, os.PathLike)):
        raise TypeError(f"`images` must be a list of {what}, got {type(images).__name__}")
    try:
        return list(images)
    except TypeError:                    # images=3 gave "'int' object is not iterable"
        raise TypeError(f"`images` must be a list of {what}, got "
                        f"{type(images).__name__} {images!r}") from None


def check_image(image, name: str, *, min_size: int = _MIN_SIZE, grey: bool = False,
                float32: bool = False) -> np.ndarray:
    """One image array: (H, W) or (H, W, C) with C in (1, 3, 4) (``grey``: (H, W) only), real
    numeric pixels (no float16), finite and non-negative, at least ``min_size`` pixels a side;
    with ``float32`` (the caller computes on the pixels in single precision) within its range."""
    if image is None or isinstance(image, (str, bytes)) or np.iscomplexobj(image):
        raise TypeError(f"`{name}` must be an image array, got {type(image).__name__}")
    try:
        arr = np.asarray(image)
    except (TypeError, ValueError) as exc:          # ragged nesting
        raise TypeError(f"`{name}` must be an image array: {exc}") from None
    if arr.dtype.kind not in "uif" or arr.dtype == np.float16:
        raise TypeError(f"`{name}` must be an unsigned/integer or float image, "
                        f"got dtype {arr.dtype}")
    if grey and arr.ndim != 2:
        raise ValueError(f"`{name}` must be a (H, W) grey image, got shape {arr.shape}")
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (1, 3, 4)):
        raise ValueError(f"`{name}` must be a (H, W) or (H, W, C) image with C in "
                         f"(1, 3, 4), got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"`{name}` is empty (shape {arr.shape})")
    if min(arr.shape[:2]) < min_size:
        raise ValueError(f"`{name}` must be at least {min_size} x {min_size} pixels, "
                         f"got shape {arr.shape}")
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}` must be finite, got NaN or infinite pixels")
    big = float(np.abs(arr).max()) if float32 and arr.dtype.kind == "f" else 0.0
    if big > _FLOAT32_MAX:
        raise ValueError(f"`{name}` must have pixels within float32's range (+-3.4e38), got "
                         f"up to {big:.3g}")
    if arr.dtype.kind == "i" and arr.min() < 0:
        raise ValueError(f"`{name}` must be non-negative, got minimum {int(arr.min())}")
    return arr


def check_masks(masks, images, name: str) -> list:
    """One boolean mask per image of ``images``, each of its image's (h, w) shape."""
    if masks is None or isinstance(masks, (str, bytes)) or not hasattr(masks, "__len__"):
        raise TypeError(f"`{name}` must be a list of boolean masks, one per image, got "
                        f"{type(masks).__name__}")
    if len(masks) != len(images):
        raise ValueError(f"`{name}` must hold one mask per image ({len(images)}), got "
                         f"{len(masks)}")
    out = []
    for k, (m, im) in enumerate(zip(masks, images)):
        m = check_array(m, f"{name}[{k}]", dtype=bool)
        if m.shape != im.shape[:2]:
            raise ValueError(f"`{name}[{k}]` must have the shape of `images[{k}]` {im.shape[:2]}, "
                             f"got {m.shape}")
        out.append(m)
    return out


def load_images(images) -> list:
    """Read file paths (:func:`transync.datasets.read_image`) and pass arrays through.

    Every image is checked: (H, W) or (H, W, C) with C in (1, 3, 4), integer or float pixels,
    finite, at least 16 x 16 pixels.

    Parameters
    ----------
    images : sequence of arrays or paths
        The views (a stacked ``(N, H, W)`` or ``(N, H, W, C)`` array is split).

    Returns
    -------
    list of ndarray
        The images (read from disk where a path was given).

    Raises
    ------
    TypeError
        A single path or image instead of a sequence, or non-numeric pixels.
    ValueError
        Fewer than one image, images smaller than 16 x 16 pixels or not finite, bad shapes, a
        path that cannot be read or decoded (missing, empty, damaged: the message names
        ``images[k]`` and the file).

    Examples
    --------
    >>> import numpy as np
    >>> [im.shape for im in load_images([np.zeros((20, 30)), np.zeros((16, 16, 3))])]
    [(20, 30), (16, 16, 3)]
    """
    if isinstance(images, np.ndarray) and images.ndim in (3, 4) and images.dtype != object:
        if images.ndim == 3 and images.shape[-1] in (3, 4) and images.shape[0] > 4:
            raise ValueError("`images` must be a list of images; got a single (H, W, C) array")
        images = list(images)
    if isinstance(images, (str, os.PathLike)):
        raise TypeError("`images` must be a list of images or paths, got a single path")
    if isinstance(images, np.ndarray) and images.ndim == 2 and images.dtype != object:
        # split into rows, it was refused as images[0] "of shape (W,)"
        raise TypeError(f"`images` must be a list of images or paths, got a single "
                        f"{images.shape} grey image; pass [image, ...]")
    try:
        images = list(images)
    except TypeError:
        raise TypeError(f"`images` must be a list of images or paths, "
                        f"got {type(images).__name__}") from None
    if not images:
        raise ValueError("`images` must hold at least one image or path, got none")
    out = []
    for k, im in enumerate(images):
        if isinstance(im, (str, os.PathLike)):
            try:
                arr = read_image(im)            # refuses a damaged file (imread half-decoded)
            except ValueError as exc:
                raise ValueError(f"`images[{k}]`: {exc}") from None
        else:
            if (np.iscomplexobj(im) or isinstance(im, (str, bytes)) or im is None
                    or np.ndim(im) == 0):               # a number: neither image nor path
                raise TypeError(f"`images[{k}]` must be an image array or a path, "
                                f"got {type(im).__name__}")
            arr = np.asarray(im)
        out.append(check_image(arr, f"images[{k}]"))
    return out


def to_gray(image) -> np.ndarray:
    """Grey-level uint8 version of an image (RGB assumed for 3 or 4 channels).

    Intensity scale by dtype: uint8 as is; uint16 divided by 257; floats with maximum <= 2 are
    taken as [0, 1] (overshoot from interpolation is clipped), other floats as [0, 255]; other
    integer types as 8-bit when their maximum is <= 255, else rescaled to their maximum.

    Parameters
    ----------
    image : array_like of shape (h, w) or (h, w, c)
        Grey or color image (c in 1, 3, 4).

    Returns
    -------
    ndarray of shape (h, w), uint8
        Grey levels.

    Examples
    --------
    >>> import numpy as np
    >>> to_gray(np.full((2, 2, 3), 0.5)).tolist()
    [[128, 128], [128, 128]]
    """
    image = arr = check_image(image, "image", min_size=1)
    if arr.dtype == np.uint8:
        if arr.ndim == 3:
            arr = arr[..., 0] if arr.shape[2] == 1 else cv2.cvtColor(
                np.ascontiguousarray(arr[..., :3]), cv2.COLOR_RGB2GRAY)
        return np.ascontiguousarray(arr)
    arr = arr.astype(np.float64)             # float32 only once scaled to [0, 255]
    top = float(arr.max()) if arr.size else 0.0
    if image.dtype == np.uint16:
        arr /= 257.0
    elif image.dtype.kind == "f" and top <= 2.0:
        arr *= 255.0
    elif top > 255.0:
        arr *= 255.0 / top
    arr = np.clip(arr, 0.0, 255.0).astype(np.float32)
    if arr.ndim == 3:
        arr = arr[..., 0] if arr.shape[2] == 1 else cv2.cvtColor(
            np.ascontiguousarray(arr[..., :3]), cv2.COLOR_RGB2GRAY)
    return np.clip(np.round(arr), 0, 255).astype(np.uint8)


def sift_features(gray, *, n_features=4000) -> tuple[np.ndarray, np.ndarray]:
    """SIFT keypoint coordinates and descriptors of a grey image (OpenCV).

    Parameters
    ----------
    gray : ndarray of shape (h, w), uint8
        Grey image (see :func:`to_gray`).
    n_features : int, default=4000
        Largest number of keypoints kept (the strongest).

    Returns
    -------
    points : ndarray of shape (k, 2), float32
        Keypoint coordinates ``(x, y)`` in pixels.
    descriptors : ndarray of shape (k, 128), float32
        SIFT descriptors; both arrays are empty when no keypoint is found.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> pts, desc = sift_features((rng.random((64, 64)) * 255).astype(np.uint8), n_features=50)
    >>> pts.shape[1], desc.shape[1], len(pts) <= 51
    (2, 128, True)
    """
    gray = check_image(gray, "gray", min_size=1, grey=True)
    if gray.dtype != np.uint8:
        raise TypeError(f"`gray` must be a uint8 image (see to_gray), got dtype {gray.dtype}")
    n_features = check_int(n_features, "n_features", minimum=1, maximum=10**6)
    sift = cv2.SIFT_create(nfeatures=n_features)
    kp, desc = sift.detectAndCompute(gray, None)
    if desc is None or not kp:
        return np.zeros((0, 2), np.float32), np.zeros((0, 128), np.float32)
    pts = np.array([k.pt for k in kp], dtype=np.float32)
    return pts, desc


def margin_canvas(size, margin: float) -> tuple[tuple[int, int], tuple[int, int]]:
    """``((width, height), (mx, my))``: the canvas of a ``size = (w, h)`` reference view widened
    by ``margin`` times its width / height on every side, and the view's offset in it."""
    w, h = size
    mx, my = int(round(margin * w)), int(round(margin * h))
    return (w + 2 * mx, h + 2 * my), (mx, my)


def _check_ratio(ratio) -> float:
    """Lowe's ratio, in (0, 1] (one check for both sparse passes)."""
    ratio = check_positive(ratio, "ratio")
    if ratio > 1:
        raise ValueError(f"`ratio` must lie in (0, 1], got {ratio!r}")
    return ratio


def _ratio_matches(desc_i, desc_j, ratio, seed):
    """Lowe's ratio-test matches ``(index in i, index in j)`` of the descriptors of view j.

    Nearest neighbours come from FLANN's randomized kd-trees (4 trees, 64 checks), whose random
    choices draw from OpenCV's random generator. That generator is thread-local: this function
    runs only in pool threads owned by :func:`estimate_pairwise_homographies` (never in the
    caller's thread) and seeds it with the pair's own ``seed`` before every match, so the result
    depends on the pair's seed alone and the caller's OpenCV random state is never touched.
    """
    if len(desc_i) < 2 or len(desc_j) < 2:
        return np.zeros((0, 2), int)
    cv2.setRNGSeed(int(seed))
    matcher = cv2.FlannBasedMatcher({"algorithm": 1, "trees": 4}, {"checks": 64})
    knn = matcher.knnMatch(desc_j, desc_i, k=2)
    good = [(m[0].trainIdx, m[0].queryIdx) for m in knn
            if len(m) == 2 and m[0].distance < ratio * m[1].distance]
    if not good:
        return np.zeros((0, 2), int)
    good = np.array(good, dtype=int)
    # one-to-one: keep the first match of every keypoint of view i
    _, first = np.unique(good[:, 0], return_index=True)
    return good[np.sort(first)]


def _refine_inliers(src, dst, H, inl, threshold, n_rounds=3):
    """Tighten the inlier set to the residual scale and refit by least squares + LM.

    RANSAC's fixed threshold lets in points of nearby surfaces (small parallax) that bias the
    fit; the scale of the true inliers' residuals (1.4826 MAD) is much smaller than the threshold.
    """
    src64 = src.astype(np.float64)
    dst64 = dst.astype(np.float64)
    for _ in range(n_rounds):
        r = np.linalg.norm(transfer_points(H, src64) - dst64, axis=1)
        sigma = 1.4826 * np.median(r[inl])
        new = r <= min(threshold, max(2.5 * sigma, 0.5))
        if new.sum() < 8:
            break
        Hn, _ = cv2.findHomography(src[new], dst[new], 0)
        if Hn is None or not np.all(np.isfinite(Hn)):
            break
        H = Hn
        if np.array_equal(new, inl):
            inl = new
            break
        inl = new
    return H, inl


def _all_pairs(n):
    return [(i, j) for i in range(n) for j in range(i + 1, n)]


def _check_pairs(pairs, n) -> list:
    if pairs is None:
        return _all_pairs(n)
    return [tuple(p) for p in check_index_pairs(pairs, n, what="view indices",
                                                 distinct=True).tolist()]


def _pair_seeds(rng, n_pairs) -> list:
    """One independent generator per pair, drawn from ``rng`` (SPEC 7): the result of a pair
    does not depend on which thread fits it or in which order."""
    ss = np.random.SeedSequence(as_generator(rng).integers(2**63, size=4).tolist())
    return [np.random.default_rng(c) for c in ss.spawn(n_pairs)]


MAX_RANSAC_ITER = 2**31 - 1
"""Most robust-fit iterations OpenCV's ``findHomography`` takes (its ``maxIters`` is an int)."""


def _robust_fit(src, dst, method, threshold, max_iter, confidence, refine, gen):
    """``cv2.findHomography`` on the correspondences in an order drawn from ``gen``.

    OpenCV's robust estimators draw their samples from an internal generator with a fixed seed,
    so the order of the points decides the samples: shuffling it with ``gen`` seeds RANSAC per
    call, without touching OpenCV's global random state. Returns ``(H, inlier, why)``.
    """
    order = gen.permutation(len(src))
    inv = np.empty_like(order)
    inv[order] = np.arange(len(order))
    try:
        H, inl = cv2.findHomography(src[order], dst[order], _METHODS[method], threshold,
                                    maxIters=max_iter, confidence=confidence)
    except cv2.error as exc:  # degenerate configurations
        return None, None, f"OpenCV error: {str(exc).strip()[:80]}"
    if H is None or inl is None:
        return None, None, "no homography found"
    inl = inl.ravel().astype(bool)[inv]
    if refine and inl.sum() >= 8:
        H, inl = _refine_inliers(src, dst, H, inl, threshold)
    return H, inl, None


def _check_features(features, n):
    """One ``(points (m, 2), descriptors (m, k))`` pair per image, descriptors as float32 (what
    FLANN takes) with one width ``k`` for all images; names the image and what is wrong."""
    if isinstance(features, (str, bytes)) or not isinstance(features, (Sequence, np.ndarray)):
        raise TypeError(f"`features` must be a list of (points, descriptors) pairs, got "
                        f"{type(features).__name__}")
    if len(features) != n:
        raise ValueError(f"`features` must hold one (pts, desc) pair per image ({n}), "
                         f"got {len(features)}")
    out = []
    width = None
    for i, f in enumerate(features):
        if isinstance(f, (str, bytes)) or not isinstance(f, (Sequence, np.ndarray)) or len(f) != 2:
            raise TypeError(f"`features[{i}]` must be a (points, descriptors) pair, got "
                            f"{type(f).__name__}")
        pts = check_array(f[0], f"features[{i}][0] (points)", ndim=2)
        desc = check_array(f[1], f"features[{i}][1] (descriptors)", ndim=2)
        if pts.shape[1] != 2:
            raise ValueError(f"`features[{i}][0]` (points) must have shape (m, 2), got "
                             f"{pts.shape}")
        if desc.shape[0] != pts.shape[0] or desc.shape[1] == 0:
            raise ValueError(f"`features[{i}][1]` (descriptors) must have shape ({pts.shape[0]}, "
                             f"k), k >= 1, one row per point, got {desc.shape}")
        if np.abs(desc).max(initial=0.0) > np.finfo(np.float32).max:
            raise ValueError(f"`features[{i}][1]` (descriptors) must fit float32, got a "
                             f"largest magnitude of {np.abs(desc).max():.3g}")
        if width is not None and desc.shape[1] != width:
            raise ValueError(f"`features[{i}][1]` (descriptors) has width {desc.shape[1]}, "
                             f"the images before it {width}: all must match")
        width = desc.shape[1]
        out.append((pts, np.ascontiguousarray(desc, dtype=np.float32)))
    return out


def estimate_pairwise_homographies(images, *, pairs=None, method="ransac", ratio=0.8,
                                   threshold=3.0, max_iter=2000, confidence=0.995,
                                   min_inliers=20, n_features=4000,
                                   features=None, refine=True, rng=None) -> PairwiseHomographies:
    """Pairwise homographies between views: SIFT, ratio test, robust fit (``cv2.findHomography``).

    Parameters
    ----------
    images : list of arrays or paths
        The views (see :func:`load_images`).
    pairs : list of (i, j), default=None
        View graph; default all pairs.
    method : str, default="ransac"
        ``"ransac"`` (OpenCV RANSAC followed by its Levenberg-Marquardt polish on the inliers),
        ``"lmeds"``, ``"rho"`` or a USAC variant: ``"usac_default"``, ``"usac_magsac"``,
        ``"usac_accurate"``, ``"usac_prosac"``, ``"usac_fast"``.
    ratio : float, default=0.8
        Lowe's ratio test, in (0, 1]. Nearest neighbours from FLANN, seeded per pair.
    threshold : float, default=3.0
        Reprojection threshold in pixels.
    max_iter : int, default=2000
        Iterations of the robust estimator, at most ``2**31 - 1`` (OpenCV's limit).
    confidence : float, default=0.995
        Confidence of the robust estimator.
    min_inliers : int, default=20
        Pairs with fewer inliers are recorded as failed.
    n_features : int, default=4000
        SIFT features per view.
    features : list of (pts, desc), default=None
        Precomputed features (as returned by :func:`sift_features`), one pair per image:
        points ``(m, 2)`` and descriptors ``(m, k)`` (any real dtype, matched as float32; one
        ``k`` for all images).
    refine : bool, default=True
        After the robust fit, shrink the inlier set to 2.5 robust standard deviations of the
        inlier residuals (at most ``threshold``, at least 0.5 px) and refit by least squares
        with Levenberg-Marquardt polish (a few rounds): points of nearby surfaces that RANSAC's
        fixed threshold admits no longer bias the homography.
    rng : None, int or Generator, default=None
        Draws one generator per pair, which orders the pair's correspondences and with them
        RANSAC's samples (OpenCV's global random state is never used). Pairs are fitted on up
        to 4 threads; the same ``rng`` gives the same result whatever the number of threads.

    Returns
    -------
    PairwiseHomographies
        ``H[i, j]`` maps pixels of view ``j`` into view ``i`` (both directions filled), with the
        mask of estimated pairs, inlier counts as weights and the failed pairs with a reason.

    Raises
    ------
    ValueError, TypeError
        Invalid images, pairs or options (an unknown ``method``, a ``ratio`` outside (0, 1]).

    Examples
    --------
    >>> import cv2
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> base = cv2.GaussianBlur((rng.random((180, 240)) * 255).astype(np.uint8), (0, 0), 1.5)
    >>> M = np.array([[1.0, 0.05, 8.0], [-0.03, 1.0, 5.0], [0.0, 0.0, 1.0]])
    >>> view = cv2.warpPerspective(base, M, (240, 180))      # view 1 = view 0 moved by M
    >>> pw = estimate_pairwise_homographies([base, view], n_features=500, rng=0)
    >>> bool(pw.mask[0, 1]), pw.failed
    (True, [])
    >>> bool(np.allclose(pw.H[1, 0] / pw.H[1, 0][2, 2], M, atol=0.05))
    True
    """
    import time

    t0 = time.perf_counter()
    method = check_choice(method, "method", tuple(_METHODS))
    ratio = _check_ratio(ratio)
    threshold = check_positive(threshold, "threshold")
    max_iter = check_int(max_iter, "max_iter", minimum=1, maximum=MAX_RANSAC_ITER)
    confidence = check_positive(confidence, "confidence")
    if confidence >= 1:
        raise ValueError(f"`confidence` must lie in (0, 1), got {confidence!r}")
    min_inliers = check_int(min_inliers, "min_inliers", minimum=4)
    n_features = check_int(n_features, "n_features", minimum=1, maximum=10**6)
    refine = check_bool(refine, "refine")
    imgs = load_images(images)
    n = len(imgs)
    if n < 2:
        raise ValueError(f"`images` must hold at least 2 images, got {n}")
    pairs = _check_pairs(pairs, n)
    if features is None:
        features = [sift_features(to_gray(im), n_features=n_features) for im in imgs]
    features = _check_features(features, n)
    gens = _pair_seeds(rng, len(pairs))

    def fit(k, i, j):
        pi, di = features[i]
        pj, dj = features[j]
        m = _ratio_matches(di, dj, ratio, gens[k].integers(2**31 - 1))
        if len(m) < max(min_inliers, 4):
            return None, f"{len(m)} ratio-test matches"
        src = pj[m[:, 1]]
        dst = pi[m[:, 0]]
        Hij, inl, why = _robust_fit(src, dst, method, threshold, max_iter, confidence, refine,
                                    gens[k])
        if Hij is None:
            return None, why
        return (Hij, dst, src, inl), None

    jobs = [(k, int(i), int(j)) for k, (i, j) in enumerate(pairs)]
    # OpenCV's matching and RANSAC release the GIL: threads use every core. Always pool threads,
    # even for one job: the per-pair seeding of OpenCV's (thread-local) generator stays in them.
    workers = max(1, min(len(jobs), os.cpu_count() or 1, 4))
    with ThreadPoolExecutor(max_workers=workers) as pool:
        outcomes = list(pool.map(lambda job: fit(*job), jobs))
    H = np.full((n, n, 3, 3), np.nan)
    mask = np.zeros((n, n), dtype=bool)
    weights = np.zeros((n, n))
    failed, matches = [], {}
    for (_, i, j), (fit_ij, why) in zip(jobs, outcomes):
        if fit_ij is None:
            failed.append((i, j, why))
            continue
        Hij, dst, src, inl = fit_ij
        matches[(i, j)] = (dst, src, inl)
        k = int(inl.sum())
        if k < min_inliers or not np.all(np.isfinite(Hij)) or abs(np.linalg.det(Hij)) < 1e-12:
            failed.append((i, j, f"{k} inliers"))
            continue
        H[i, j] = Hij / Hij[2, 2]
        Hji = np.linalg.inv(Hij)
        H[j, i] = Hji / Hji[2, 2]
        mask[i, j] = mask[j, i] = True
        weights[i, j] = weights[j, i] = k
    return PairwiseHomographies(H=H, mask=mask, weights=weights, failed=failed, matches=matches,
                                info={"n_keypoints": [len(f[0]) for f in features],
                                      "seconds": time.perf_counter() - t0})


_EMPTY = (np.zeros((0, 2), np.float32), np.zeros((0, 128), np.float32))


def _warped_features(gray, H_to_ref, T, size, n_features):
    """SIFT features of every view warped into the canvas ``T`` (NaN estimate: no features)."""
    kern = np.ones((7, 7), np.uint8)
    feats = []
    for g, Hi in zip(gray, H_to_ref):
        if not np.all(np.isfinite(Hi)):
            feats.append(_EMPTY)
            continue
        M = T @ Hi
        wi = cv2.warpPerspective(g, M, size, flags=cv2.INTER_LINEAR)
        valid = cv2.warpPerspective(np.full(g.shape, 255, np.uint8), M, size,
                                    flags=cv2.INTER_NEAREST)
        sift = cv2.SIFT_create(nfeatures=int(n_features))
        kp, desc = sift.detectAndCompute(wi, cv2.erode(valid, kern))
        if desc is None or not kp:
            feats.append(_EMPTY)
        else:
            feats.append((np.array([k.pt for k in kp], dtype=np.float32), desc))
    return feats


def _guided_matches(tree, pi, di, pj, dj, radius, ratio):
    """Guided matching: the warped views are already aligned to about a pixel, so the
    candidates of a keypoint of view j are the keypoints of view i within ``radius`` px;
    Lowe's ratio test among them, one-to-one. Returns index arrays ``(mi, mj)``."""
    k = min(6, len(pi))
    dist, cand = tree.query(pj, k=k, distance_upper_bound=radius)
    dist = dist.reshape(len(pj), k)
    cand = cand.reshape(len(pj), k)
    valid = np.isfinite(dist)
    cand_c = np.where(valid, cand, 0)
    dd = np.linalg.norm(di[cand_c] - dj[:, None, :], axis=2)
    dd[~valid] = np.inf
    order = np.argsort(dd, axis=1)
    best = np.take_along_axis(dd, order[:, :1], 1)[:, 0]
    second = (np.take_along_axis(dd, order[:, 1:2], 1)[:, 0] if k > 1
              else np.full(len(pj), np.inf))
    ok = np.isfinite(best) & ((best < ratio * second) | (~np.isfinite(second) & (best < 250.0)))
    mi = cand_c[np.arange(len(pj)), order[:, 0]][ok]
    mj = np.flatnonzero(ok)
    _, first = np.unique(mi, return_index=True)
    return mi[first], mj[first]


def estimate_rectified_pairwise(images, H_to_ref, pairs, *, reference=0, margin=0.15,
                                n_features=2000, threshold=1.5, radius=6.0, guided=True,
                                method="ransac", ratio=0.8, min_inliers=20,
                                rng=None) -> PairwiseHomographies:
    """Second sparse pass in the reference frame: pairwise homographies between the views
    warped into the reference frame with a current estimate ``H_to_ref``.

    Warping removes most of the perspective distortion between views, so SIFT keypoints are
    detected under nearly the same geometry in both views and localized far more consistently
    than between strongly tilted views. The homographies between warped views (close to the
    identity) are mapped back: ``H_ij = inv(T H_i) H'_ij (T H_j)``, with ``T`` the canvas
    offset; ``info["H_warped"]`` keeps the ``H'_ij`` and ``info["canvas"]`` ``(T, size)``.
    Pairs whose estimate is missing fall back to nothing (they are recorded as failed).

    Parameters
    ----------
    images : list of grey images
        The views.
    H_to_ref : ndarray (N, 3, 3)
        Current homographies of every view into the reference (NaN: view skipped).
    pairs : list of (i, j)
        The view pairs to estimate.
    reference : int, default=0
        The reference view.
    margin : float, default=0.15
        The canvas extends the reference frame by this fraction of its size on every side
        (at most 2).
    guided : bool, default=True
        Guided matching (fast) instead of a search over all keypoints.
    radius : float, default=6.0
        Guided matching: candidates of a keypoint are the keypoints of the other warped view
        within this distance (pixels); Lowe's ratio test among them.
    n_features, threshold, method, ratio, min_inliers, rng
        As in :func:`estimate_pairwise_homographies`.

    Returns
    -------
    PairwiseHomographies
        The pairwise homographies between the original views (pixels of ``j`` into ``i``).

    Raises
    ------
    ValueError, TypeError
        Invalid images, ``H_to_ref`` of the wrong shape, pairs out of range, bad options.

    Examples
    --------
    >>> import cv2
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> base = cv2.GaussianBlur((rng.random((120, 160)) * 255).astype(np.uint8), (0, 0), 1.5)
    >>> shifts = [(0.0, 0.0), (4.0, 2.0), (-3.0, 5.0)]
    >>> Ms = [np.array([[1.0, 0.0, x], [0.0, 1.0, y], [0.0, 0.0, 1.0]]) for x, y in shifts]
    >>> views = [cv2.warpPerspective(base, M, (160, 120)) for M in Ms]
    >>> H = np.stack([np.linalg.inv(M) for M in Ms])        # view i -> view 0
    >>> pw = estimate_rectified_pairwise(views, H, [(0, 1), (1, 2)], n_features=500, rng=0)
    >>> pw.failed, np.round(pw.H[0, 1] / pw.H[0, 1][2, 2], 1)[:2].tolist()
    ([], [[1.0, 0.0, -4.0], [0.0, 1.0, -2.0]])
    """
    from scipy.spatial import cKDTree

    gray = [to_gray(im) for im in load_images(images)]
    n = len(gray)
    reference = check_int(reference, "reference", minimum=0, maximum=n - 1)
    H_to_ref = check_array(H_to_ref, "H_to_ref", finite=False)      # NaN: no estimate
    if H_to_ref.shape != (n, 3, 3):
        raise ValueError(f"`H_to_ref` must have shape ({n}, 3, 3), got {H_to_ref.shape}")
    known = np.isfinite(H_to_ref).all(axis=(1, 2))
    check_homographies(H_to_ref[known], "H_to_ref", ndim=3)       # the estimates: invertible
    guided = check_bool(guided, "guided")
    margin = check_positive(margin, "margin", allow_zero=True)
    if margin > 2:
        raise ValueError(f"`margin` must lie in [0, 2], got {margin!r}")
    method = check_choice(method, "method", tuple(_METHODS))
    radius = check_positive(radius, "radius")
    threshold = check_positive(threshold, "threshold")
    min_inliers = check_int(min_inliers, "min_inliers", minimum=4)
    n_features = check_int(n_features, "n_features", minimum=1, maximum=10**6)
    ratio = _check_ratio(ratio)          # the guided path used it unchecked (ratio="x", 5.0)
    pairs = _check_pairs(pairs, n)
    h0, w0 = gray[reference].shape
    size, (mx, my) = margin_canvas((w0, h0), margin)
    T = translation(mx, my)
    feats = _warped_features(gray, H_to_ref, T, size, n_features)
    if not guided:
        pw = estimate_pairwise_homographies(gray, pairs=pairs, features=feats, method=method,
                                            ratio=ratio, min_inliers=min_inliers,
                                            threshold=threshold, rng=rng)
        H = np.full_like(pw.H, np.nan)
        for i, j in zip(*np.nonzero(pw.mask)):
            Hij = np.linalg.inv(T @ H_to_ref[i]) @ pw.H[i, j] @ (T @ H_to_ref[j])
            H[i, j] = Hij / Hij[2, 2]
        return PairwiseHomographies(H=H, mask=pw.mask, weights=pw.weights, failed=pw.failed,
                                    matches=pw.matches,
                                    info={**pw.info, "canvas_offset": (mx, my),
                                          "canvas": (T, size), "H_warped": pw.H})
    trees = [cKDTree(f[0]) if len(f[0]) else None for f in feats]
    gens = _pair_seeds(rng, len(pairs))
    H = np.full((n, n, 3, 3), np.nan)
    H_w = np.full((n, n, 3, 3), np.nan)
    mask = np.zeros((n, n), dtype=bool)
    weights = np.zeros((n, n))
    failed, matches = [], {}
    for k, (i, j) in enumerate(pairs):
        (pi, di), (pj, dj) = feats[i], feats[j]
        if trees[i] is None or len(pj) < 4:
            failed.append((i, j, "no keypoints in the reference frame"))
            continue
        mi, mj = _guided_matches(trees[i], pi, di, pj, dj, radius, ratio)
        if len(mi) < max(min_inliers, 4):
            failed.append((i, j, f"{len(mi)} guided matches"))
            continue
        src, dst = pj[mj], pi[mi]
        Hw, inl, why = _robust_fit(src, dst, method, threshold, 2000, 0.995, True, gens[k])
        if Hw is None:
            failed.append((i, j, why))
            continue
        if inl.sum() < min_inliers or abs(np.linalg.det(Hw)) < 1e-12:
            failed.append((i, j, f"{int(inl.sum())} inliers"))
            continue
        matches[(i, j)] = (dst, src, inl)
        Hw = Hw / Hw[2, 2]
        H_w[i, j] = Hw
        H_w[j, i] = np.linalg.inv(Hw)
        Hij = np.linalg.inv(T @ H_to_ref[i]) @ Hw @ (T @ H_to_ref[j])
        H[i, j] = Hij / Hij[2, 2]
        Hji = np.linalg.inv(Hij)
        H[j, i] = Hji / Hji[2, 2]
        mask[i, j] = mask[j, i] = True
        weights[i, j] = weights[j, i] = int(inl.sum())
    return PairwiseHomographies(H=H, mask=mask, weights=weights, failed=failed, matches=matches,
                                info={"canvas_offset": (mx, my), "canvas": (T, size),
                                      "H_warped": H_w,
                                      "n_keypoints": [len(f[0]) for f in feats]})
