"""Accuracy measures for multi-view plane homographies: corner errors, Brenner focus,
segmentation."""

from __future__ import annotations

import contextlib

import numpy as np

from .._validation import check_array, check_homographies, check_int_array, check_probability
from ..geometry import image_corners as _corners
from ..geometry import transfer_points as _transfer

__all__ = [
    "brenner_focus",
    "corner_error",
    "corner_accuracy",
    "pairwise_corner_error",
    "segmentation_scores",
]


def _sizes(image_size, n):
    if isinstance(image_size, (str, bytes)) or image_size is None:
        raise TypeError(f"`image_size` must be (width, height) or an array of shape ({n}, 2), "
                        f"got {type(image_size).__name__} {image_size!r}")
    arr = check_array(image_size, "image_size", finite=False)
    if arr.shape == (2,):
        arr = np.broadcast_to(arr, (n, 2))
    if (arr.shape != (n, 2) or not np.all(np.isfinite(arr)) or not np.all(arr >= 1)
            or not np.all(arr <= MAX_IMAGE_SIDE)):
        raise ValueError(f"`image_size` must be (width, height) or of shape ({n}, 2), with "
                         f"entries in [1, {MAX_IMAGE_SIDE:.0e}] pixels, got "
                         f"{np.asarray(image_size).tolist()!r:.80}")
    return arr


#: largest image side the homography metrics take: corners beyond it made the transfer error
#: of two identical homographies inf (1e308 * 2 overflows)
MAX_IMAGE_SIDE = 1e12


def corner_error(H_est, H_true, *, image_size) -> np.ndarray:
    """Mean distance, in reference pixels, between the view corners mapped by two homographies.

    Parameters
    ----------
    H_est, H_true : ndarray (3, 3) or (N, 3, 3)
        Homographies taking pixels of each view into the reference view.
    image_size : (width, height) or ndarray (N, 2)
        Size of the views whose corners are transferred.

    Returns
    -------
    ndarray of shape (N,) (or a float for single homographies)
        ``inf`` where an estimate is not finite or singular, or a corner is sent to infinity
        (by either homography, even by both: the distance is undefined there): a failed
        estimate counts as infinitely wrong.

    Raises
    ------
    ValueError
        A non-finite or singular ``H_true``, shapes that disagree, a bad ``image_size``.

    Examples
    --------
    >>> import numpy as np
    >>> H = np.eye(3); H2 = np.eye(3); H2[0, 2] = 0.5
    >>> float(corner_error(H, H2, image_size=(640, 480)))
    0.5
    """
    He = check_array(H_est, "H_est", ndim=(2, 3), finite=False)  # a failed estimate: inf error
    Ht = check_homographies(H_true, "H_true", (2, 3))
    single = He.ndim == 2
    if single:
        He = He[None]
    if Ht.ndim == 2:
        Ht = Ht[None]
    if He.shape != Ht.shape or He.shape[1:] != (3, 3):
        raise ValueError(f"`H_est` and `H_true` must both have shape (N, 3, 3), got "
                         f"{He.shape} and {Ht.shape}")
    sizes = _sizes(image_size, len(He))
    err = np.empty(len(He))
    for i in range(len(He)):
        c = _corners(sizes[i])
        with np.errstate(all="ignore"):
            err[i] = np.linalg.norm(_transfer(He[i], c) - _transfer(Ht[i], c), axis=1).mean()
    err[~np.isfinite(err)] = np.inf         # a corner sent to infinity: infinitely wrong
    return float(err[0]) if single else err


def corner_accuracy(errors, thresholds=(1.0, 3.0, 5.0)) -> dict:
    """Fraction of views whose corner error is at most each threshold (pixels).

    Parameters
    ----------
    errors : array_like of shape (N,)
        Corner errors in pixels (``inf`` for a failed view), e.g. from :func:`corner_error`.
    thresholds : sequence of float, default=(1.0, 3.0, 5.0)
        Thresholds in pixels.

    Returns
    -------
    dict
        ``{"acc@<t>px": fraction}`` for every threshold ``t``.

    Raises
    ------
    ValueError, TypeError
        Empty, NaN or negative errors; thresholds that are not a sequence of non-negative
        numbers.

    Examples
    --------
    >>> corner_accuracy([0.5, 2.0, float("inf")], thresholds=(1, 3))
    {'acc@1px': 0.333..., 'acc@3px': 0.666...}
    """
    errors = check_array(errors, "errors", ndim=1, finite=False)
    if errors.size == 0:
        raise ValueError("`errors` must hold at least one corner error, got an empty array")
    if np.isnan(errors).any() or (errors < 0).any():
        raise ValueError("`errors` must be non-negative numbers (inf allowed), got NaN or "
                         "negative entries")
    if isinstance(thresholds, (str, bytes)):
        raise TypeError(f"`thresholds` must be a sequence of pixel thresholds, got {thresholds!r}")
    ts = check_array(thresholds, "thresholds", ndim=1)
    if (ts < 0).any():
        raise ValueError(f"`thresholds` must be non-negative, got {ts.tolist()!r}")
    out, given = {}, {}
    for t in ts.tolist():
        key = f"acc@{t:g}px"
        if given.setdefault(key, t) != t:       # close thresholds print alike: one was lost
            raise ValueError(f"`thresholds` must give distinct keys: {given[key]!r} and {t!r} "
                             f"both print as {key!r}")
        out[key] = float(np.mean(errors <= t))
    return out


def pairwise_corner_error(H_est, H_true, *, image_size, min_overlap=0.05) -> np.ndarray:
    """Corner errors of every ordered pair of overlapping views (``inv(H_i) @ H_j``), in pixels.

    Two views overlap when the ground-truth footprint of view ``j`` covers at least
    ``min_overlap`` of view ``i``.

    Parameters
    ----------
    H_est : array_like of shape (N, 3, 3)
        Estimated homographies of every view into the reference (NaN for a failed view: an
        infinite error).
    H_true : array_like of shape (N, 3, 3)
        Ground-truth homographies, finite and invertible.
    image_size : (width, height) or array_like of shape (N, 2)
        Image sizes in pixels.
    min_overlap : float, default=0.05
        Fraction of view ``i`` that view ``j``'s footprint must cover for the pair to count.

    Returns
    -------
    ndarray of shape (n_pairs,)
        Mean corner transfer error of every overlapping ordered pair, in pixels of view ``i``.

    Raises
    ------
    ValueError
        Mis-shaped stacks, or non-finite or singular ground truth.

    Examples
    --------
    >>> import numpy as np
    >>> H = np.stack([np.eye(3), np.eye(3)])
    >>> pairwise_corner_error(H, H, image_size=(64, 48)).tolist()
    [0.0, 0.0]
    """
    import cv2

    He = check_array(H_est, "H_est", ndim=3, finite=False)      # a failed estimate: inf error
    Ht = check_homographies(H_true, "H_true", 3)
    if He.shape != Ht.shape:
        raise ValueError(f"`H_est` and `H_true` must both have shape (N, 3, 3), got "
                         f"{He.shape} and {Ht.shape}")
    n = len(He)
    sizes = _sizes(image_size, n)
    min_overlap = check_probability(min_overlap, "min_overlap")
    inv_t = np.linalg.inv(Ht)
    inv_e = np.full_like(He, np.nan)
    for k, Hk in enumerate(He):            # singular or non-finite estimates stay NaN
        if np.all(np.isfinite(Hk)):
            with contextlib.suppress(np.linalg.LinAlgError):
                inv_e[k] = np.linalg.inv(Hk)
    out = []
    for i in range(n):
        # the overlap in units of view i's corner-to-corner extent (w - 1, h - 1), so that its
        # own polygon has area 1 exactly (the size (w, h) gave (w - 1)(h - 1) / (w h) < 1: a
        # view identical to i failed min_overlap=1); OpenCV's float32 never overflows on the
        # corners, whatever the pixel scale
        unit = np.maximum(np.asarray(sizes[i], dtype=float) - 1.0, 1.0)
        ci = (_corners(sizes[i]) / unit).astype(np.float32)
        for j in range(n):
            if i == j:
                continue
            cj = _corners(sizes[j])
            with np.errstate(over="ignore", invalid="ignore"):    # far footprints: inf
                Pt = inv_t[i] @ Ht[j]
                foot = (_transfer(Pt, cj) / unit).astype(np.float32)
            try:
                inter, _ = cv2.intersectConvexConvex(ci, foot)
            except cv2.error:
                inter = 0.0
            if not inter >= min_overlap:
                continue
            with np.errstate(all="ignore"):
                Pe = inv_e[i] @ He[j]
                e = np.linalg.norm(_transfer(Pe, cj) - _transfer(Pt, cj), axis=1).mean()
            out.append(e if np.isfinite(e) else np.inf)
    return np.asarray(out, dtype=float)


def _as_array(x, name: str) -> np.ndarray:
    """``np.asarray`` whose ragged-nesting error names the argument."""
    try:
        return np.asarray(x)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"`{name}` must be an array, got a ragged or odd sequence: "
                        f"{str(exc).splitlines()[0]}") from None


def _as_mask(x, name: str) -> np.ndarray:
    """A boolean mask from bools or finite numbers (non-zero: True); text is refused (numpy
    reads "False" as True), NaN too."""
    arr = _as_array(x, name)
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"`{name}` must be a boolean (or numeric) mask, got dtype {arr.dtype}")
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}` must be finite, got NaN or infinite entries")
    return arr.astype(bool)


def brenner_focus(image, mask=None) -> float:
    """Brenner focus measure: mean of ``max(|I(x+2,y) - I(x,y)|, |I(x,y+2) - I(x,y)|)^2``.

    Color images are averaged over their channels. Unsigned integer images are brought to grey
    levels in [0, 1] by their type's maximum (uint8 by 255, the 16-bit files
    :func:`~transync.datasets.read_image` returns by 65535), so that one picture scores the
    same at any bit depth; float, signed and boolean images are taken as they are. Sharp (well
    aligned) mean warped images score higher than blurred ones.

    Parameters
    ----------
    image : array_like of shape (h, w) or (h, w, c)
        Grey or color image (1, 3 or 4 channels), finite.
    mask : array_like of shape (h, w), bool, optional
        Pixels to average over; a difference counts when both of its pixels are inside.

    Returns
    -------
    float
        The measure (0.0 when no difference is inside the mask).

    Raises
    ------
    TypeError
        A non-numeric image.
    ValueError
        Empty, non-finite or mis-shaped image or mask; values so large that the squares
        overflow.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.zeros((8, 8)); img[:, 4:] = 1.0
    >>> round(brenner_focus(img), 4)
    0.3333
    """
    img = _as_array(image, "image")
    if img.dtype.kind not in "biuf":
        raise TypeError(f"`image` must be a real-valued image, got dtype {img.dtype}")
    if img.dtype.kind == "f" and not np.all(np.isfinite(img)):
        raise ValueError("`image` must be finite, got NaN or infinite pixels")
    if img.ndim not in (2, 3) or img.size == 0 or (img.ndim == 3 and img.shape[2] not in (1, 3, 4)):
        raise ValueError("`image` must be a non-empty 2-D grey or 3-D color image (1, 3 or 4 "
                         f"channels), got shape {img.shape}")
    top = float(np.iinfo(img.dtype).max) if img.dtype.kind == "u" else 1.0
    img = img.astype(float)
    if img.ndim == 3:
        img = img.mean(axis=2)
    if top != 1.0:
        img = img / top
    if img.ndim != 2:
        raise ValueError(f"`image` must be a 2-D grey or 3-D color image, got shape {img.shape}")
    dh = np.zeros_like(img)
    dv = np.zeros_like(img)
    dh[:, :-2] = img[:, 2:] - img[:, :-2]
    dv[:-2, :] = img[2:, :] - img[:-2, :]
    with np.errstate(over="ignore"):
        fm = np.maximum(np.abs(dh), np.abs(dv)) ** 2
    if not np.all(np.isfinite(fm)):
        raise ValueError("`image` values are too large for the focus measure (squared "
                         "differences overflow); scale the image to [0, 1] or [0, 255]")
    valid = np.zeros(img.shape, dtype=bool)
    valid[:-2, :-2] = True
    if mask is not None:
        m = _as_mask(mask, "mask")
        if m.shape != img.shape:
            raise ValueError(f"`mask` must have the image's shape {img.shape}, got {m.shape}")
        # both samples of each difference must be inside the mask
        m2 = m.copy()
        m2[:, :-2] &= m[:, 2:]
        m2[:-2, :] &= m[2:, :]
        valid &= m2
    if not valid.any():
        return 0.0
    with np.errstate(over="ignore"):
        focus = float(fm[valid].mean())
    if not np.isfinite(focus):                  # each square finite, their sum not
        raise ValueError("`image` values are too large for the focus measure (the mean of the "
                         "squared differences overflows); scale the image to [0, 1] or "
                         "[0, 255]")
    return focus


def segmentation_scores(pred, truth, *, valid=None) -> dict:
    """Pixel-wise precision, recall, F1 and IoU of binary masks (stacks allowed).

    Parameters
    ----------
    pred : array_like of bool
        Predicted mask (or stack of masks).
    truth : array_like of bool
        Ground-truth mask, the same shape as ``pred``.
    valid : array_like of bool, optional
        Pixels to count (default: all).

    Returns
    -------
    dict
        ``{"precision", "recall", "f1", "iou"}``, floats; precision, recall and IoU are 1.0 when
        their denominator is empty.

    Raises
    ------
    ValueError
        ``pred`` and ``truth`` of different shapes.

    Examples
    --------
    >>> segmentation_scores([[True, True, False]], [[True, False, False]])
    {'precision': 0.5, 'recall': 1.0, 'f1': 0.666..., 'iou': 0.5}
    """
    p = _as_mask(pred, "pred")
    t = _as_mask(truth, "truth")
    if p.shape != t.shape:
        raise ValueError(f"`pred` and `truth` must have the same shape, got {p.shape} and "
                         f"{t.shape}")
    if valid is not None:
        v = _as_mask(valid, "valid")
        if v.shape != p.shape:
            raise ValueError(f"`valid` must have the shape of `pred` {p.shape}, got {v.shape}")
        p, t = p[v], t[v]
    tp = float(np.sum(p & t))
    fp = float(np.sum(p & ~t))
    fn = float(np.sum(~p & t))
    prec = tp / (tp + fp) if tp + fp else 1.0
    rec = tp / (tp + fn) if tp + fn else 1.0
    f1 = 2 * prec * rec / (prec + rec) if prec + rec else 0.0
    iou = tp / (tp + fp + fn) if tp + fp + fn else 1.0
    return {"precision": prec, "recall": rec, "f1": f1, "iou": iou}


def misclassification_error(pred, truth) -> float:
    """Fraction of points whose label differs from the ground truth under the best one-to-one
    relabelling of the planes (label 0, outliers, maps to 0).

    Parameters
    ----------
    pred : array_like of int
        Predicted plane label of every point (0: outlier).
    truth : array_like of int
        True plane label of every point (0: outlier), the same size.

    Returns
    -------
    float
        Misclassified fraction in [0, 1].

    Raises
    ------
    ValueError, TypeError
        Labels that are not integer arrays of the same size.

    Examples
    --------
    >>> misclassification_error([0, 1, 1, 2, 2], [0, 2, 2, 1, 1])
    0.0
    >>> misclassification_error([1, 1, 1, 1], [1, 1, 2, 2])
    0.5
    """
    from scipy.optimize import linear_sum_assignment

    p = check_array(pred, "pred", dtype=None).ravel()
    t = check_array(truth, "truth", dtype=None).ravel()
    checked = []
    for name, a in (("pred", p), ("truth", t)):
        try:
            a = check_int_array(a, name, integral_floats=True, allow_bool=True,
                                what="integer labels")
        except TypeError as exc:
            if a.dtype.kind != "f":
                raise
            raise ValueError(str(exc)) from None     # here a fractional label is a wrong value
        if a.size and a.min() < 0:
            raise ValueError(f"`{name}` must hold labels >= 0 (0 = outlier), got {a.min()}")
        checked.append(a)
    p, t = checked
    # compact labels (0 stays 0): the contingency table is as small as the labels used
    p = np.unique(np.concatenate([[0], p]), return_inverse=True)[1][1:]
    t = np.unique(np.concatenate([[0], t]), return_inverse=True)[1][1:]
    if p.shape != t.shape:
        raise ValueError(f"`pred` and `truth` must have the same length, got {p.size} and {t.size}")
    if p.size == 0:
        return 0.0
    kp, kt = p.max() + 1, t.max() + 1
    C = np.zeros((kp, kt))
    np.add.at(C, (p, t), 1)
    correct = C[0, 0]
    if kp > 1 and kt > 1:
        r, c = linear_sum_assignment(-C[1:, 1:])
        correct += C[1:, 1:][r, c].sum()
    return float(1.0 - correct / p.size)
