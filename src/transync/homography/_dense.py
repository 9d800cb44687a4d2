"""Dense photometric refinement of plane homographies: masked, coarse-to-fine ECC (OpenCV)."""

from __future__ import annotations

import cv2
import numpy as np

from .._validation import check_array, check_int, check_positive
from ..geometry import normalize_determinant, translation

__all__ = ["mean_warped_image", "refine_homography_ecc", "warp_to_reference"]


def _scale(H, s):
    S = np.diag([s, s, 1.0])
    return S @ H @ np.linalg.inv(S)


def refine_homography_ecc(template, image, H_init, *, mask=None, template_mask=None, levels=3,
                          max_iter=60, eps=1e-5, gauss_size=3):
    """Refine ``H`` (pixels of ``image`` into ``template``) by maximizing the ECC criterion.

    Coarse-to-fine over ``levels`` pyramid levels with ``cv2.findTransformECC``
    (``MOTION_HOMOGRAPHY``). ``mask`` marks the valid (plane) pixels of ``image``;
    ``template_mask`` (optional) the valid pixels of ``template``: template pixels outside it are
    replaced by the warped image so that they carry no error.

    Returns
    -------
    H : ndarray (3, 3)
        Refined homography, or ``H_init`` when ECC fails at the finest level.
    ok : bool
        Whether every level converged without an OpenCV error.
    """
    tpl = check_array(template, "template", ndim=2, dtype=np.float32)
    img = check_array(image, "image", ndim=2, dtype=np.float32)
    H_init = check_array(H_init, "H_init", ndim=2)
    if H_init.shape != (3, 3):
        raise ValueError(f"`H_init` must have shape (3, 3), got {H_init.shape}")
    levels = check_int(levels, "levels", minimum=1, maximum=8)
    max_iter = check_int(max_iter, "max_iter", minimum=1)
    eps = check_positive(eps, "eps")
    m = tm = None
    if mask is not None:
        m = check_array(mask, "mask", ndim=2, dtype=bool)
        if m.shape != img.shape:
            raise ValueError(f"`mask` must have the shape of `image` {img.shape}, got {m.shape}")
        m = m.astype(np.uint8) * 255
    if template_mask is not None:
        tm = check_array(template_mask, "template_mask", ndim=2, dtype=bool)
        if tm.shape != tpl.shape:
            raise ValueError(f"`template_mask` must have the shape of `template` {tpl.shape}, "
                             f"got {tm.shape}")
    # ECC warp: template coordinates -> image coordinates = inv(H)
    W = np.linalg.inv(H_init)
    W = W / W[2, 2]
    pyr_t, pyr_i, pyr_m, pyr_tm = [tpl], [img], [m], [tm]
    for _ in range(levels - 1):
        pyr_t.append(cv2.pyrDown(pyr_t[-1]))
        pyr_i.append(cv2.pyrDown(pyr_i[-1]))
        pyr_m.append(None if m is None else cv2.resize(pyr_m[-1], pyr_i[-1].shape[::-1],
                                                       interpolation=cv2.INTER_NEAREST))
        pyr_tm.append(None if tm is None else cv2.resize(pyr_tm[-1].astype(np.uint8),
                                                         pyr_t[-1].shape[::-1],
                                                         interpolation=cv2.INTER_NEAREST) > 0)
    ok = True
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, max_iter, eps)
    for lvl in range(levels - 1, -1, -1):
        s = 0.5 ** lvl
        Wl = _scale(W, s).astype(np.float32)
        t_l = pyr_t[lvl]
        if pyr_tm[lvl] is not None:
            warped = cv2.warpPerspective(pyr_i[lvl], Wl, t_l.shape[::-1],
                                         flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
            t_l = np.where(pyr_tm[lvl], t_l, warped).astype(np.float32)
        try:
            _, Wl = cv2.findTransformECC(t_l, pyr_i[lvl], Wl, cv2.MOTION_HOMOGRAPHY, criteria,
                                         pyr_m[lvl], gauss_size)
        except cv2.error:
            ok = False
            continue
        W = _scale(Wl.astype(np.float64), 1.0 / s)
    return normalize_determinant(np.linalg.inv(W)), ok


def warp_to_reference(image, H, size, *, offset=(0, 0), interpolation=cv2.INTER_LINEAR):
    """Warp ``image`` into a reference canvas of ``size`` (w, h) whose origin sits at ``offset``."""
    T = translation(*offset)
    return cv2.warpPerspective(image, T @ H, tuple(int(v) for v in size), flags=interpolation,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def mean_warped_image(images, homographies, *, size, masks=None, offset=(0, 0),
                      normalize=True, reference=0):
    """Average of the views warped into the reference frame (over their masks).

    Returns
    -------
    mean : ndarray (h, w) float32 (NaN where no view contributes)
    count : ndarray (h, w) int
    """
    w, h = (int(v) for v in size)
    acc = np.zeros((h, w), np.float64)
    cnt = np.zeros((h, w), np.float64)
    order = [reference] + [k for k in range(len(images)) if k != reference]
    for k in order:
        im = np.asarray(images[k], dtype=np.float32)
        H = homographies[k]
        src_mask = np.ones(im.shape[:2], np.uint8) if masks is None else \
            np.asarray(masks[k], dtype=np.uint8)
        wi = warp_to_reference(im, H, (w, h), offset=offset)
        vi = warp_to_reference(src_mask, H, (w, h), offset=offset,
                               interpolation=cv2.INTER_NEAREST) > 0
        vi &= warp_to_reference(np.ones(im.shape[:2], np.uint8), H, (w, h), offset=offset,
                                interpolation=cv2.INTER_NEAREST) > 0
        both = vi & (cnt > 0)
        if normalize and both.sum() > 100:
            # photometric gain/bias of this view against the running mean: least squares on
            # every overlapping pixel, in closed form (a subsample made the fit, and with it
            # the Brenner ratio of estimated vs true alignments, noisy at the 1e-3 level)
            x = wi[both].astype(np.float64)
            y = acc[both] / cnt[both]
            xm, ym = x.mean(), y.mean()
            x -= xm
            vx = float(x @ x)
            a = float(x @ (y - ym)) / vx if vx > 0 else 1.0
            wi = a * wi + (ym - a * xm)
        acc[vi] += wi[vi]
        cnt[vi] += 1
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(cnt > 0, acc / np.maximum(cnt, 1), np.nan)
    return mean.astype(np.float32), cnt.astype(int)
