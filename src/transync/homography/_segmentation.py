"""Plane segmentation from per-pixel evidence across views warped into the reference frame.

Evidence per view and canvas pixel: the photometric residual against the robust consensus
(median of the photometrically normalized warped views), the local ZNCC against that consensus
over a small window, the local texture of the consensus and the number of views that see the
pixel. A logistic-regression classifier is self-trained on confident pixels (high ZNCC and low
residual as plane, low ZNCC or a large residual as non-plane); its probabilities are smoothed
spatially, thresholded, cleaned morphologically and warped back into every view.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import cv2
import numpy as np

from .._validation import (as_generator, check_array, check_homographies, check_int,
                           check_positive, check_probability)
from ..geometry import translation
from ._sparse import check_image, check_image_list, margin_canvas, to_gray

__all__ = ["PlaneSegmentation", "segment_plane", "segment_plane_evidence"]


@dataclass(frozen=True)
class PlaneSegmentation:
    """Result of :func:`segment_plane_evidence`.

    Attributes
    ----------
    masks : list of (h_i, w_i) bool arrays
        Plane mask of every view (what :func:`segment_plane` returns).
    canvas_masks : list of bool arrays
        The masks in the canvas (reference frame plus margin).
    median : ndarray
        Consensus image of the photometrically normalized warped views, in the canvas.
    count : ndarray of int
        Number of views seeing each canvas pixel.
    offset : (int, int)
        Canvas position of the reference view's origin.
    probability : ndarray (N, H, W)
        Plane probability of every view and canvas pixel (before smoothing).

    Examples
    --------
    See :func:`segment_plane_evidence`, which returns one.

    >>> sorted(PlaneSegmentation.__dataclass_fields__)
    ['canvas_masks', 'count', 'masks', 'median', 'offset', 'probability']
    """

    masks: list
    canvas_masks: list
    median: np.ndarray
    count: np.ndarray
    offset: tuple
    probability: np.ndarray


def _box(x, k):
    return cv2.boxFilter(x, cv2.CV_32F, (k, k), borderType=cv2.BORDER_REFLECT)


def segment_plane(images, homographies, *, reference=0, window=7, margin=0.2, smooth=4.0,
                  min_views=3, threshold=0.35, rng=None) -> list:
    """Per-view plane masks from the consensus of the views warped into the reference frame.

    Parameters and method as in :func:`segment_plane_evidence`, which also returns the
    evidence behind the masks.

    Parameters
    ----------
    images : list of (h_i, w_i) or (h_i, w_i, c) images
        The views, at least 8 x 8 pixels, brought to grey levels by :func:`to_gray` (uint8 as
        is; floats with maximum <= 2 read as [0, 1], floats and ints with maximum > 255
        rescaled to [0, 255]; the result is rounded to uint8, negatives clipped to 0).
    homographies : ndarray of shape (N, 3, 3)
        ``homographies[i]`` maps pixels of view ``i`` into the reference view.
    reference, window, margin, smooth, min_views, threshold, rng
        As in :func:`segment_plane_evidence`.

    Returns
    -------
    masks : list of (h_i, w_i) bool arrays
        The plane mask of every view.

    Raises
    ------
    ValueError, TypeError
        As :func:`segment_plane_evidence`.

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
    >>> masks = segment_plane(views, H, rng=0)          # every pixel lies on the one plane
    >>> [m.shape for m in masks], round(float(np.mean(masks[1])), 2)
    ([(120, 160), (120, 160), (120, 160)], 1.0)
    """
    return segment_plane_evidence(images, homographies, reference=reference, window=window,
                                  margin=margin, smooth=smooth, min_views=min_views,
                                  threshold=threshold, rng=rng).masks


MAX_SMOOTH = 100.0
"""Largest ``smooth`` (Gaussian sigma, pixels) the segmentation takes."""


def _check_inputs(images, homographies, reference, window, margin, smooth, min_views,
                  threshold):
    images = check_image_list(images)
    # the intensity rule of the whole pipeline: grey levels 0..255 as to_gray makes them (the
    # ZNCC regularizer and the texture feature assume that scale; floats x 1e30 overflowed)
    imgs = [to_gray(check_image(im, f"images[{k}]", min_size=8)).astype(np.float32)
            for k, im in enumerate(images)]
    n = len(imgs)
    if n < 1:
        raise ValueError("`images` must hold at least one image, got 0")
    H = check_array(homographies, "homographies", ndim=3)
    if H.shape != (n, 3, 3):
        raise ValueError(f"`homographies` must have shape ({n}, 3, 3) (one per image), "
                         f"got {H.shape}")
    H = check_homographies(H, "homographies", ndim=3)
    opts = {"reference": check_int(reference, "reference", minimum=0, maximum=n - 1),
            "window": check_int(window, "window", minimum=1, maximum=101),
            "margin": check_positive(margin, "margin", allow_zero=True),
            "smooth": check_positive(smooth, "smooth", allow_zero=True),
            "min_views": check_int(min_views, "min_views", minimum=1),
            "threshold": check_probability(threshold, "threshold")}
    if opts["margin"] > 2:
        raise ValueError(f"`margin` must lie in [0, 2], got {opts['margin']!r}")
    if opts["smooth"] > MAX_SMOOTH:
        raise ValueError(f"`smooth` must lie in [0, {MAX_SMOOTH:g}] pixels, got "
                         f"{opts['smooth']!r}")
    return imgs, H, opts


def segment_plane_evidence(images, homographies, *, reference=0, window=7, margin=0.2,
                           smooth=4.0, min_views=3, threshold=0.35,
                           rng=None) -> PlaneSegmentation:
    """Per-view plane masks and their evidence, from the consensus of the views warped into
    the reference frame.

    Parameters
    ----------
    images : list of (h_i, w_i) or (h_i, w_i, c) images
        The views, at least 8 x 8 pixels, brought to grey levels by :func:`to_gray` (uint8 as
        is; floats with maximum <= 2 read as [0, 1], floats and ints with maximum > 255
        rescaled to [0, 255]; the result is rounded to uint8, negatives clipped to 0).
    homographies : ndarray (N, 3, 3)
        ``homographies[i]`` maps pixels of view ``i`` into the reference view.
    reference : int, default=0
        The reference view.
    window : int, default=7
        Window of the local ZNCC (1 to 101 pixels).
    margin : float, default=0.2
        The canvas extends the reference frame by this fraction on every side (at most 2).
    smooth : float, default=4.0
        Gaussian sigma (pixels, at most 100) applied to the plane probabilities before
        thresholding.
    min_views : int, default=3
        Canvas pixels seen by fewer views are labelled plane only if they look like the
        consensus (no evidence against it).
    threshold : float, default=0.35
        Smoothed plane probability above which a pixel is labelled plane (below 0.5: the
        self-trained classifier is conservative on weakly textured plane pixels).
    rng : None, int or Generator, default=None
        Draws the training pixels of the classifier.

    Returns
    -------
    PlaneSegmentation
        The masks, the canvas masks, the median image, the per-pixel view counts, the canvas
        offset and every view's plane probability.

    Raises
    ------
    ValueError, TypeError
        No views, bad images, homographies of the wrong shape, not finite or singular,
        bad options.

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
    >>> seg = segment_plane_evidence(views, H, rng=0)
    >>> seg.probability.shape[0], seg.probability.shape[1:] == seg.count.shape
    (3, True)
    """
    imgs, homographies, o = _check_inputs(images, homographies, reference, window, margin,
                                          smooth, min_views, threshold)
    h0, w0 = imgs[o["reference"]].shape[:2]
    (W, Hc), (ox, oy) = margin_canvas((w0, h0), o["margin"])
    T = translation(ox, oy)
    warped, valid = _warp_views(imgs, homographies, T, (W, Hc))
    count = valid.sum(axis=0)
    _match_photometry(warped, valid, count)
    med = _consensus(warped, valid, count)
    zs, rs, tex = _local_evidence(warped, valid, med, o["window"])
    prob = _plane_probability(zs, rs, tex, valid, count, o["min_views"], as_generator(rng))
    masks, canvas_masks = _view_masks(prob, valid, imgs, homographies, T, o["smooth"],
                                      o["threshold"])
    return PlaneSegmentation(masks=masks, canvas_masks=canvas_masks, median=med, count=count,
                             offset=(ox, oy), probability=prob)


_ERODE = np.ones((5, 5), np.uint8)      # valid regions lose a 2-pixel rim (interpolated border)


def _warp_views(imgs, homographies, T, canvas):
    """Every view warped onto the canvas (float32), with its eroded valid region."""
    W, Hc = canvas
    n = len(imgs)
    warped = np.empty((n, Hc, W), np.float32)
    valid = np.empty((n, Hc, W), bool)
    for i, (im, H) in enumerate(zip(imgs, homographies)):
        M = T @ H
        warped[i] = cv2.warpPerspective(im, M, (W, Hc), flags=cv2.INTER_LINEAR)
        ones = np.ones(im.shape[:2], np.uint8)
        valid[i] = cv2.erode(cv2.warpPerspective(ones, M, (W, Hc), flags=cv2.INTER_NEAREST),
                             _ERODE) > 0
    return warped, valid


def _consensus(warped, valid, count):
    """Per-pixel median of the views that see the pixel (0 where none does)."""
    n = len(warped)
    s = np.where(valid, warped, np.inf)
    s.sort(axis=0)
    idx = np.clip((count - 1) // 2, 0, n - 1)
    idx2 = np.clip(count // 2, 0, n - 1)
    med = 0.5 * (np.take_along_axis(s, idx[None], 0)[0]
                 + np.take_along_axis(s, idx2[None], 0)[0])
    return np.where(count > 0, med, 0.0).astype(np.float32)


def _match_photometry(warped, valid, count):
    """In place: every view's grey levels mapped to the consensus by a robust gain and offset
    (a flat view: offset only)."""
    med = _consensus(warped, valid, count)
    for i in range(len(warped)):
        v = valid[i] & (count >= 2)
        if v.sum() > 100:
            x = warped[i][v][::7].astype(np.float64)     # a subsample is plenty for 2 numbers
            y = med[v][::7].astype(np.float64)
            r = np.abs(y - x - np.median(y - x))
            keep = r <= np.percentile(r, 70)
            if np.ptp(x[keep]) > 0:
                a, b = np.polyfit(x[keep], y[keep], 1)
                warped[i] = a * warped[i] + b
            else:                       # a flat view: no gain to estimate, only the offset
                warped[i] = warped[i] + np.median(y - x)


def _local_evidence(warped, valid, med, window):
    """Per view and pixel: local ZNCC against the consensus ``zs``, mean absolute residual
    ``rs`` (both float32, (n, H, W)), and the consensus' log texture ``tex`` (H, W)."""
    mu_m = _box(med, window)
    var_m = np.maximum(_box(med * med, window) - mu_m ** 2, 0)
    tex = np.log1p(np.sqrt(var_m))
    zs, rs = [], []
    for i in range(len(warped)):
        wi = np.where(valid[i], warped[i], med)   # windows at the view border see the consensus
        mu_i = _box(wi, window)
        var_i = np.maximum(_box(wi * wi, window) - mu_i ** 2, 0)
        cov = _box(wi * med, window) - mu_i * mu_m
        z = cov / np.sqrt(var_i * var_m + 25.0)
        r = _box(np.abs(wi - med), 5)
        zs.append(z.astype(np.float32))
        rs.append(r.astype(np.float32))
    return np.stack(zs), np.stack(rs), tex


def _plane_probability(zs, rs, tex, valid, count, min_views, gen):
    """Plane probability per view and pixel: a logistic regression self-trained on confident
    pixels (high ZNCC and low residual vs low ZNCC on texture or a large residual), or a ZNCC
    threshold when too few are confident; pixels seen by few views lean to the plane."""
    from sklearn.linear_model import LogisticRegression

    sel = valid & (count >= min_views)[None]
    r_scale = float(np.median(rs[sel])) + 1e-3 if sel.any() else 1.0
    lr = np.log1p(rs / np.float32(r_scale))
    textured = (tex > np.median(tex[count >= min_views]))[None] if (count >= min_views).any() \
        else np.ones_like(sel)
    pos = sel & (((zs > 0.85) & (rs < 1.5 * r_scale)) | (~textured & (rs < 0.7 * r_scale)))
    neg = sel & (((zs < 0.3) & textured) | (rs > 5 * r_scale))
    if pos.sum() > 50 and neg.sum() > 50:
        ip = np.flatnonzero(pos.ravel())
        ineg = np.flatnonzero(neg.ravel())
        ip = gen.choice(ip, size=min(20000, ip.size), replace=False)
        ineg = gen.choice(ineg, size=min(20000, ineg.size), replace=False)
        ii = np.concatenate([ip, ineg])
        X = np.column_stack([zs.ravel()[ii], lr.ravel()[ii],
                             np.broadcast_to(tex, zs.shape).ravel()[ii]])
        y = np.concatenate([np.ones(ip.size), np.zeros(ineg.size)])
        clf = LogisticRegression(C=1.0, max_iter=200)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            clf.fit(X, y)
        coef, icpt = clf.coef_[0].astype(np.float32), np.float32(clf.intercept_[0])
        logit = coef[0] * zs + coef[1] * lr + (coef[2] * tex + icpt)[None]
        prob = (1.0 / (1.0 + np.exp(-logit))).astype(np.float32)
    else:
        prob = (zs > 0.6).astype(np.float32)
    # few views: no evidence against the plane unless the residual says so
    few = valid & ~(count >= min_views)[None]
    return np.where(few, np.maximum(prob, 0.6 * (zs > 0.5)), prob)


def _view_masks(prob, valid, imgs, homographies, T, smooth, threshold):
    """Smoothed, thresholded and cleaned canvas masks, and the view masks warped back."""
    masks, canvas_masks = [], []
    k3 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    for i in range(len(imgs)):
        p = cv2.GaussianBlur(prob[i], (0, 0), smooth) if smooth > 0 else prob[i]
        cm = ((p > threshold) & valid[i]).astype(np.uint8)
        cm = cv2.morphologyEx(cm, cv2.MORPH_OPEN, k3)
        cm = cv2.morphologyEx(cm, cv2.MORPH_CLOSE, k3)
        # pixels outside the eroded valid region keep the label of their neighbourhood
        cm_full = cv2.dilate(cm, _ERODE)
        cm = np.where(valid[i], cm, cm_full)
        canvas_masks.append(cm > 0)
        hi, wi_ = imgs[i].shape[:2]
        back = cv2.warpPerspective(cm, T @ homographies[i], (wi_, hi),
                                   flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=1)
        masks.append(back > 0)
    return masks, canvas_masks
