"""Dense photometric refinement of plane homographies: masked, coarse-to-fine ECC (OpenCV)."""

from __future__ import annotations

import numbers

import cv2
import numpy as np

from .._validation import (MAX_ITER, check_array, check_bool, check_homographies, check_int,
                           check_positive)
from ..geometry import normalize_determinant, rescale_homogeneous, translation
from ._sparse import check_image, check_image_list, check_masks

__all__ = ["mean_warped_image", "refine_homography_ecc", "warp_to_reference"]

#: OpenCV's largest warp canvas side (``SHRT_MAX``: its remap tables hold short coordinates)
MAX_CANVAS = 32767
#: largest canvas in pixels (16384 x 16384): ``mean_warped_image`` holds a float64 sum, an int32
#: count and a float32 warp of the canvas, about 24 bytes a pixel at its peak (6 GiB here)
MAX_CANVAS_PIXELS = 2**28
#: OpenCV interpolation flags ``warp_to_reference`` takes (nearest, linear, cubic, area, Lanczos)
_INTERPOLATIONS = (cv2.INTER_NEAREST, cv2.INTER_LINEAR, cv2.INTER_CUBIC, cv2.INTER_AREA,
                   cv2.INTER_LANCZOS4)


def _canvas(size, offset) -> tuple[tuple[int, int], tuple[float, float]]:
    """``size`` as (width, height) integers in ``[1, MAX_CANVAS]``, at most
    ``MAX_CANVAS_PIXELS`` in all, and ``offset`` as two finite floats."""
    if size is None or isinstance(size, (str, bytes)):
        raise TypeError(f"`size` must be (width, height), got {type(size).__name__} {size!r}")
    s = check_array(size, "size", finite=False)
    if (s.shape != (2,) or not np.all(np.isfinite(s)) or np.any(s != np.round(s))
            or np.any(s < 1) or np.any(s > MAX_CANVAS)):
        raise ValueError(f"`size` must be (width, height), integers in [1, {MAX_CANVAS}], got "
                         f"{np.asarray(size).tolist()!r}")
    if s[0] * s[1] > MAX_CANVAS_PIXELS:
        raise ValueError(f"`size` must hold at most {MAX_CANVAS_PIXELS:,} pixels (a mean image of "
                         f"that size takes about {MAX_CANVAS_PIXELS * 24 / 2**30:.0f} GiB), got "
                         f"{int(s[0])} x {int(s[1])} = {int(s[0] * s[1]):,}")
    if offset is None or isinstance(offset, (str, bytes)):
        raise TypeError(f"`offset` must be (x, y), got {type(offset).__name__} {offset!r}")
    o = check_array(offset, "offset")
    if o.shape != (2,):
        raise ValueError(f"`offset` must be (x, y), got shape {o.shape}")
    return (int(s[0]), int(s[1])), (float(o[0]), float(o[1]))


def _scale(H, s):
    S = np.diag([s, s, 1.0])
    return S @ H @ np.linalg.inv(S)


def refine_homography_ecc(template, image, H_init, *, mask=None, template_mask=None, levels=3,
                          max_iter=60, eps=1e-5, gauss_size=3) -> tuple[np.ndarray, bool]:
    """Refine ``H`` (pixels of ``image`` into ``template``) by maximizing the ECC criterion.

    Coarse-to-fine over ``levels`` pyramid levels with ``cv2.findTransformECC``
    (``MOTION_HOMOGRAPHY``). ``mask`` marks the valid (plane) pixels of ``image``;
    ``template_mask`` (optional) the valid pixels of ``template``: template pixels outside it are
    replaced by the warped image so that they carry no error.

    Parameters
    ----------
    template : array_like of shape (h_t, w_t)
        Grey template (the target frame).
    image : array_like of shape (h, w)
        Grey image to align onto the template.
    H_init : array_like of shape (3, 3)
        Initial homography from pixels of ``image`` into ``template``.
    mask : array_like of shape (h, w), bool, optional
        Valid pixels of ``image`` (e.g. its plane mask); default all.
    template_mask : array_like of shape (h_t, w_t), bool, optional
        Valid pixels of ``template``; default all.
    levels : int, default=3
        Pyramid levels, 1 to 8.
    max_iter : int, default=60
        ECC iterations per level.
    eps : float, default=1e-5
        ECC convergence threshold.
    gauss_size : int, default=3
        Gaussian filter size of ``cv2.findTransformECC``: odd, from 1 (no smoothing) to 1001.

    Returns
    -------
    H : ndarray of shape (3, 3)
        Refined homography (determinant 1), or ``H_init`` when ECC fails at the finest level.
    ok : bool
        Whether every level converged without an OpenCV error.

    Raises
    ------
    ValueError, TypeError
        Images that are not 2-d, masks of the wrong shape, ``H_init`` not (3, 3), bad options.

    Examples
    --------
    >>> import cv2
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> base = cv2.GaussianBlur(rng.random((120, 160)).astype(np.float32), (0, 0), 3.0)
    >>> M = np.array([[1.0, 0.0, 4.0], [0.0, 1.0, 2.0], [0.0, 0.0, 1.0]])  # shift by (4, 2)
    >>> view = cv2.warpPerspective(base, M, (160, 120))
    >>> valid = cv2.warpPerspective(np.ones((120, 160), np.uint8), M, (160, 120))
    >>> valid = cv2.erode(valid, np.ones((5, 5), np.uint8)) > 0   # away from the black border
    >>> H0 = np.linalg.inv(M)
    >>> H0[0, 2] += 1.5                                  # start 1.5 px off
    >>> H, ok = refine_homography_ecc(base, view, H0, mask=valid, levels=2)
    >>> ok, np.round(H[:2, 2] / H[2, 2], 1).tolist()     # back to the true shift (-4, -2)
    (True, [-4.0, -2.1])
    """
    tpl = check_image(template, "template", min_size=1, grey=True,
                      float32=True).astype(np.float32)
    img = check_image(image, "image", min_size=1, grey=True,
                      float32=True).astype(np.float32)
    H_init = check_homographies(H_init, "H_init", ndim=2)
    levels = check_int(levels, "levels", minimum=1, maximum=8)
    max_iter = check_int(max_iter, "max_iter", minimum=1, maximum=MAX_ITER)
    eps = check_positive(eps, "eps")
    gauss_size = check_int(gauss_size, "gauss_size", minimum=1, maximum=1001)
    if gauss_size % 2 == 0:
        raise ValueError(f"`gauss_size` must be odd (an OpenCV Gaussian kernel), got {gauss_size}")
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
    if not abs(W[2, 2]) > 1e-12 * np.abs(W).max():
        raise ValueError("`H_init` must map the image's origin to a finite point of the template "
                         "(ECC keeps the [2, 2] entry of the inverse warp at 1), got an inverse "
                         f"whose [2, 2] entry is {W[2, 2]:.3g}")
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


def warp_to_reference(image, H, size, *, offset=(0, 0),
                      interpolation=cv2.INTER_LINEAR) -> np.ndarray:
    """Warp ``image`` into a reference canvas of ``size`` (w, h) whose origin sits at ``offset``.

    Parameters
    ----------
    image : ndarray of shape (h_i, w_i) or (h_i, w_i, c)
        The view.
    H : array_like of shape (3, 3)
        Homography from pixels of the view into the reference frame.
    size : (width, height)
        Canvas size in pixels.
    offset : (float, float), default=(0, 0)
        Position of the reference frame's origin in the canvas.
    interpolation : int, default=cv2.INTER_LINEAR
        OpenCV interpolation flag.

    Returns
    -------
    ndarray of shape (height, width) or (height, width, c)
        The warped view; canvas pixels it does not cover are 0.

    Examples
    --------
    >>> import cv2
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> base = cv2.GaussianBlur(rng.random((120, 160)).astype(np.float32), (0, 0), 3.0)
    >>> M = np.array([[1.0, 0.0, 4.0], [0.0, 1.0, 2.0], [0.0, 0.0, 1.0]])  # shift by (4, 2)
    >>> view = cv2.warpPerspective(base, M, (160, 120))
    >>> back = warp_to_reference(view, np.linalg.inv(M), (160, 120))
    >>> bool(np.allclose(back[10:-10, 10:-10], base[10:-10, 10:-10], atol=1e-5))
    True
    """
    image = check_image(image, "image", min_size=1)
    H = check_homographies(H, "H", ndim=2)
    size, offset = _canvas(size, offset)
    if isinstance(interpolation, bool) or not isinstance(interpolation, numbers.Integral):
        raise TypeError(f"`interpolation` must be an OpenCV INTER_* flag (an int), got "
                        f"{type(interpolation).__name__} {interpolation!r}")
    if interpolation not in _INTERPOLATIONS:
        raise ValueError(f"`interpolation` must be one of OpenCV's INTER_NEAREST, INTER_LINEAR, "
                         f"INTER_CUBIC, INTER_AREA, INTER_LANCZOS4 {_INTERPOLATIONS}, got "
                         f"{interpolation!r}")
    if image.dtype not in (np.uint8, np.uint16, np.int16, np.float32, np.float64):
        image = image.astype(np.float64)           # the types OpenCV warps
    return _warp(image, translation(*offset) @ rescale_homogeneous(H), size,
                 int(interpolation))


def _warp(image, H, size, interpolation=cv2.INTER_LINEAR) -> np.ndarray:
    """``cv2.warpPerspective`` of checked arguments (a canvas of ``size`` = (w, h)), ``H``
    scaled by a power of two (exact) to a largest entry in [0.5, 1): a homography is defined up
    to scale, and OpenCV's own inversion took ``1e-40 * I`` (or ``1e300 * I``) for singular,
    an all-black canvas."""
    H = np.ldexp(H, -np.frexp(np.abs(H).max())[1])
    return cv2.warpPerspective(image, H, size, flags=interpolation,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def mean_warped_image(images, homographies, *, size, masks=None, offset=(0, 0),
                      normalize=True, reference=0) -> tuple[np.ndarray, np.ndarray]:
    """Average of the views warped into the reference frame (over their masks).

    Parameters
    ----------
    images : sequence of ndarray of shape (h_i, w_i)
        Grey views.
    homographies : array_like of shape (N, 3, 3)
        ``homographies[i]`` maps pixels of view ``i`` into the reference frame.
    size : (width, height)
        Canvas size in pixels.
    masks : sequence of bool arrays of shape (h_i, w_i), optional
        Pixels of each view to use (e.g. plane masks); default all.
    offset : (float, float), default=(0, 0)
        Position of the reference frame's origin in the canvas.
    normalize : bool, default=True
        Fit each view's photometric gain and bias to the running mean (least squares on the
        overlap) before adding it.
    reference : int, default=0
        The view added first (the photometric reference).

    Returns
    -------
    mean : ndarray of shape (height, width), float32
        The mean warped image, NaN where no view contributes.
    count : ndarray of shape (height, width), int32
        Number of views contributing to each pixel.

    Examples
    --------
    >>> import cv2
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> base = cv2.GaussianBlur(rng.random((120, 160)).astype(np.float32), (0, 0), 3.0)
    >>> M = np.array([[1.0, 0.0, 4.0], [0.0, 1.0, 2.0], [0.0, 0.0, 1.0]])  # shift by (4, 2)
    >>> view = cv2.warpPerspective(base, M, (160, 120))
    >>> H = np.stack([np.eye(3), np.linalg.inv(M)])
    >>> mean, count = mean_warped_image([base, view], H, size=(160, 120))
    >>> int(count.max()), bool(np.allclose(mean[10:-10, 10:-10], base[10:-10, 10:-10], atol=1e-4))
    (2, True)
    """
    imgs = [check_image(im, f"images[{k}]", min_size=1, grey=True,
                        float32=True).astype(np.float32)
            for k, im in enumerate(check_image_list(images, "(h, w) grey images"))]
    N = len(imgs)
    if N < 1:
        raise ValueError("`images` must hold at least one image, got 0")
    Hs = rescale_homogeneous(check_homographies(homographies, "homographies", ndim=3))
    if len(Hs) != N:
        raise ValueError(f"`homographies` must hold one homography per image ({N}), got "
                         f"{len(Hs)}")
    if masks is not None:
        masks = check_masks(masks, imgs, "masks")
    (w, h), offset = _canvas(size, offset)
    normalize = check_bool(normalize, "normalize")
    reference = check_int(reference, "reference", minimum=0, maximum=N - 1)
    T = translation(*offset)
    acc = np.zeros((h, w), np.float64)
    cnt = np.zeros((h, w), np.int32)
    order = [reference] + [k for k in range(N) if k != reference]
    for k in order:
        im, H = imgs[k], T @ Hs[k]
        src_mask = np.ones(im.shape, np.uint8) if masks is None else masks[k].astype(np.uint8)
        wi = _warp(im, H, (w, h))
        vi = _warp(src_mask, H, (w, h), cv2.INTER_NEAREST) > 0
        vi &= _warp(np.ones(im.shape, np.uint8), H, (w, h), cv2.INTER_NEAREST) > 0
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
    acc /= np.maximum(cnt, 1)                 # in place: the canvas may be large
    acc[cnt == 0] = np.nan
    return acc.astype(np.float32), cnt
