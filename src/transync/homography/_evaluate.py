"""Baselines and the evaluation used by the homography experiment and benchmark."""

from __future__ import annotations

import warnings

import numpy as np

from ..exceptions import UnlinkedViewsWarning
from ..geometry import normalize_determinant
from ._dense import mean_warped_image
from ..metrics import brenner_focus, corner_error, pairwise_corner_error, segmentation_scores
from .._validation import (check_array, check_bool, check_homographies, check_int,
                           invertible_homographies)
from ._sparse import (check_image, check_image_list, check_masks,
                      estimate_pairwise_homographies, load_images, to_gray)

__all__ = ["chained_homographies", "evaluate_alignment", "to_reference_homographies"]


def _no_pairs(kw: dict, fn: str, which: str) -> None:
    """A baseline fixes its own view graph: ``pairs`` among the options passed on to
    :func:`estimate_pairwise_homographies` is refused by name (it was a duplicate keyword)."""
    if "pairs" in kw:
        raise TypeError(f"{fn}() takes no `pairs`: the baseline matches {which}; call "
                        "estimate_pairwise_homographies(images, pairs=...) for another view "
                        "graph")


def to_reference_homographies(images, *, reference=0, n_features=2000, features=None,
                              **kw) -> np.ndarray:
    """OpenCV baseline: every view matched to the reference (SIFT + ratio + RANSAC + LM).

    Parameters
    ----------
    images : list of arrays or paths
        The views (see :func:`load_images`).
    reference : int, default=0
        The reference view.
    n_features : int, default=2000
        SIFT features per view.
    features : list of (pts, desc), optional
        Precomputed features (as returned by :func:`sift_features`).
    **kw
        Passed to :func:`estimate_pairwise_homographies` (``rng``, ``method``, ...).

    Returns
    -------
    ndarray of shape (N, 3, 3)
        Homographies of every view into the reference, determinant 1; NaN for views whose pair
        failed.

    Raises
    ------
    ValueError, TypeError
        Invalid images or options.

    Warns
    -----
    UnlinkedViewsWarning
        When some views have no estimate.

    Examples
    --------
    >>> import cv2
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> base = cv2.GaussianBlur((rng.random((180, 240)) * 255).astype(np.uint8), (0, 0), 1.5)
    >>> M = np.array([[1.0, 0.05, 8.0], [-0.03, 1.0, 5.0], [0.0, 0.0, 1.0]])
    >>> view = cv2.warpPerspective(base, M, (240, 180))      # view 1 = view 0 moved by M
    >>> H = to_reference_homographies([base, view], n_features=500, rng=0)
    >>> from transync.metrics import corner_error
    >>> bool(corner_error(H[1], np.linalg.inv(M), image_size=(240, 180)) < 0.5)
    True
    """
    _no_pairs(kw, "to_reference_homographies", "every view to the reference")
    images = load_images(images)
    n = len(images)
    reference = check_int(reference, "reference", minimum=0, maximum=max(n - 1, 0))
    pw = estimate_pairwise_homographies(images, pairs=[(reference, i) for i in range(n)
                                                       if i != reference],
                                        n_features=n_features, features=features, **kw)
    H = np.stack([np.eye(3) if i == reference else pw.H[reference, i] for i in range(n)])
    return _finish(H, "to_reference_homographies", pw)


def _finish(H, name, pw):
    """Determinant-normalized estimates; views without one are NaN, with an
    :class:`UnlinkedViewsWarning` naming them and the failed pairs."""
    H = normalize_determinant(H)
    bad = np.flatnonzero(~np.all(np.isfinite(H), axis=(1, 2)))
    if bad.size:
        why = "; ".join(f"({i}, {j}): {r}" for i, j, r in pw.failed[:5])
        warnings.warn(f"{name}: views {bad.tolist()} have no estimate (NaN homographies); "
                      f"failed pairs: {why or 'none'}", UnlinkedViewsWarning, stacklevel=3)
    return H


def chained_homographies(images, *, reference=0, n_features=2000, features=None,
                         **kw) -> np.ndarray:
    """OpenCV baseline: consecutive views matched and chained to the reference.

    ``H_i = H_{i-1} H_{i-1,i}`` outward from the reference; a failed link breaks the chain: the
    views beyond it get NaN, with an :class:`~transync.exceptions.UnlinkedViewsWarning`.

    Parameters
    ----------
    images : list of arrays or paths
        The views, in sequence order.
    reference : int, default=0
        The reference view.
    n_features : int, default=2000
        SIFT features per view.
    features : list of (pts, desc), optional
        Precomputed features (as returned by :func:`sift_features`).
    **kw
        Passed to :func:`estimate_pairwise_homographies` (``rng``, ``method``, ...).

    Returns
    -------
    ndarray of shape (N, 3, 3)
        Homographies of every view into the reference, determinant 1 (NaN beyond a broken link).

    Raises
    ------
    ValueError, TypeError
        Invalid images or options.

    Warns
    -----
    UnlinkedViewsWarning
        When some views have no estimate.

    Examples
    --------
    >>> import cv2
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> base = cv2.GaussianBlur((rng.random((180, 240)) * 255).astype(np.uint8), (0, 0), 1.5)
    >>> M = np.array([[1.0, 0.05, 8.0], [-0.03, 1.0, 5.0], [0.0, 0.0, 1.0]])
    >>> view = cv2.warpPerspective(base, M, (240, 180))      # view 1 = view 0 moved by M
    >>> H = chained_homographies([base, view], n_features=500, rng=0)
    >>> H.shape
    (2, 3, 3)
    """
    _no_pairs(kw, "chained_homographies", "consecutive views")
    images = load_images(images)
    n = len(images)
    reference = check_int(reference, "reference", minimum=0, maximum=max(n - 1, 0))
    pairs = [(i, i + 1) for i in range(n - 1)]
    pw = estimate_pairwise_homographies(images, pairs=pairs, n_features=n_features,
                                        features=features, **kw)
    H = np.full((n, 3, 3), np.nan)
    H[reference] = np.eye(3)
    for i in range(reference + 1, n):
        H[i] = H[i - 1] @ pw.H[i - 1, i]
    for i in range(reference - 1, -1, -1):
        H[i] = H[i + 1] @ pw.H[i + 1, i]
    return _finish(H, "chained_homographies", pw)


def evaluate_alignment(images, H_est, H_true, *, masks_true, reference=0, masks_est=None,
                       pairwise=False) -> dict:
    """Corner errors (views other than the reference), accuracy at 1/3/5 px, Brenner ratio and,
    with ``masks_est``, segmentation scores.

    ``brenner_ratio``: Brenner focus of the mean warped image with the estimated homographies
    over that with the true ones, both over the true plane masks and the pixels both cover
    (isolates the alignment). ``brenner_ratio_own_masks`` (with ``masks_est``): the estimated
    homographies and masks against the true homographies and masks (the full output). A ratio
    is NaN when the true mean image has no texture over its region (focus 0: undefined; it
    read 0.0, as a complete failure, for a perfect alignment).
    Views without an estimate count as 1000 px errors.

    Parameters
    ----------
    images : sequence of images
        The views.
    H_est : array_like of shape (N, 3, 3)
        Estimated homographies of every view into the reference (NaN: no estimate).
    H_true : array_like of shape (N, 3, 3)
        Ground-truth homographies.
    masks_true : sequence of bool arrays
        Ground-truth plane mask of every view.
    reference : int, default=0
        The reference view (left out of the corner errors).
    masks_est : sequence of bool arrays, optional
        Estimated plane masks: adds segmentation scores and ``brenner_ratio_own_masks``.
    pairwise : bool, default=False
        Also report ``pairwise_mean_error``, ``pairwise_max_error`` and
        ``pairwise_median_error`` over every overlapping pair (:func:`pairwise_corner_error`;
        a pair with a failed view counts 1000 px). They are NaN when no two views overlap
        (nothing to measure).

    Returns
    -------
    dict
        ``mean_error``, ``max_error``, ``median_error`` (pixels), ``acc_1px``, ``acc_3px``,
        ``acc_5px``, ``brenner_ratio`` and, as asked, the pairwise and segmentation entries.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> images = [rng.random((60, 80)), rng.random((60, 80))]
    >>> H = np.stack([np.eye(3), np.eye(3)])
    >>> masks = [np.ones((60, 80), bool)] * 2
    >>> r = evaluate_alignment(images, H, H, masks_true=masks)
    >>> r["mean_error"], r["acc_1px"], round(r["brenner_ratio"], 3)
    (0.0, 1.0, 1.0)
    """
    gray = [to_gray(check_image(im, f"images[{k}]", min_size=1))
            for k, im in enumerate(check_image_list(images))]
    n = len(gray)
    if n < 2:
        raise ValueError(f"`images` must hold at least 2 images (the reference and a view), "
                         f"got {n}")
    H_est = check_array(H_est, "H_est", ndim=3, finite=False)     # NaN: a failed view
    H_true = check_homographies(H_true, "H_true", ndim=3)
    for name, H in (("H_est", H_est), ("H_true", H_true)):
        if H.shape != (n, 3, 3):
            raise ValueError(f"`{name}` must have shape ({n}, 3, 3) (one per image), got "
                             f"{H.shape}")
    masks_true = check_masks(masks_true, gray, "masks_true")
    masks_est = None if masks_est is None else check_masks(masks_est, gray, "masks_est")
    reference = check_int(reference, "reference", minimum=0, maximum=n - 1)
    pairwise = check_bool(pairwise, "pairwise")
    sizes = np.array([(g.shape[1], g.shape[0]) for g in gray], float)
    ok = np.all(np.isfinite(H_est), axis=(1, 2))
    ok &= invertible_homographies(np.where(ok[:, None, None], H_est, np.eye(3)))  # singular: failed
    err = np.full(n, 1000.0)
    if ok.any():
        err[ok] = corner_error(H_est[ok], H_true[ok], image_size=sizes[ok])
    others = np.arange(n) != reference
    e = err[others]
    out = {"mean_error": float(e.mean()), "max_error": float(e.max()),
           "median_error": float(np.median(e))}
    for t in (1, 3, 5):
        out[f"acc_{t}px"] = float(np.mean(e <= t))
    if pairwise:
        # a pair with a failed view counts 1000 px, as a failed view does above
        pe = pairwise_corner_error(np.where(ok[:, None, None], H_est, np.nan), H_true,
                                   image_size=sizes)
        pe = np.where(np.isfinite(pe), pe, 1000.0)
        none = float("nan")         # no two views overlap: no pair to measure
        out["pairwise_mean_error"] = float(pe.mean()) if pe.size else none
        out["pairwise_max_error"] = float(pe.max()) if pe.size else none
        out["pairwise_median_error"] = float(np.median(pe)) if pe.size else none
    size = tuple(int(v) for v in sizes[reference])
    H_safe = np.where(ok[:, None, None], H_est, H_true)
    m_est, c_est = mean_warped_image(gray, H_safe, size=size, masks=masks_true,
                                     reference=reference)
    m_true, c_true = mean_warped_image(gray, H_true, size=size, masks=masks_true,
                                       reference=reference)
    region = (c_est > 0) & (c_true > 0)
    b_true = brenner_focus(np.nan_to_num(m_true) / 255.0, region)
    out["brenner_ratio"] = _ratio(brenner_focus(np.nan_to_num(m_est) / 255.0, region), b_true)
    if masks_est is not None:
        s = segmentation_scores(np.concatenate([np.ravel(m) for m in masks_est]),
                                np.concatenate([np.ravel(m) for m in masks_true]))
        out.update({"precision": s["precision"], "recall": s["recall"], "f1": s["f1"]})
        m_own, c_own = mean_warped_image(gray, H_safe, size=size, masks=masks_est,
                                         reference=reference)
        reg = (c_own > 0) & (c_true > 0)
        out["brenner_ratio_own_masks"] = _ratio(
            brenner_focus(np.nan_to_num(m_own) / 255.0, reg),
            brenner_focus(np.nan_to_num(m_true) / 255.0, reg))
    return out


def _ratio(focus_est: float, focus_true: float) -> float:
    """Focus of the estimate over the truth's; NaN when the truth has none (no texture)."""
    return focus_est / focus_true if focus_true > 0 else float("nan")
