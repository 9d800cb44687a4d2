"""Several planes between two views: sequential robust homography extraction (AdelaideRMF).

The same machinery as the multi-view pipeline's sparse step: ``cv2.findHomography`` (RANSAC with
its Levenberg-Marquardt polish) followed by the inlier tightening of
:func:`transync.homography._sparse._refine_inliers`; the inliers of each plane are removed and the
next plane is extracted from what is left, until a plane gathers fewer than ``min_inliers``
points.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from .._validation import check_int, check_positive
from ._sparse import _METHODS, _refine_inliers

__all__ = ["MultiPlaneResult", "extract_planes", "misclassification_error"]


@dataclass(frozen=True)
class MultiPlaneResult:
    """Planes found between two views.

    Attributes
    ----------
    labels : ndarray (n,) int
        0 = outlier, k = plane k (in extraction order, the largest first).
    homographies : list of ndarray (3, 3)
        ``homographies[k - 1]`` maps points of view 1 into view 2 for plane ``k``.
    info : dict
    """

    labels: np.ndarray
    homographies: list
    info: dict[str, Any] = field(default_factory=dict, repr=False)


def _transfer_error(H, x1, x2):
    p = np.column_stack([x1, np.ones(len(x1))]) @ H.T
    q = np.column_stack([x2, np.ones(len(x2))]) @ np.linalg.inv(H).T
    with np.errstate(divide="ignore", invalid="ignore"):
        e1 = np.linalg.norm(p[:, :2] / p[:, 2:3] - x2, axis=1)
        e2 = np.linalg.norm(q[:, :2] / q[:, 2:3] - x1, axis=1)
    return np.nan_to_num(0.5 * (e1 + e2), nan=np.inf)


def extract_planes(x1, x2, *, threshold=5.0, min_inliers=10, max_planes=None, method="ransac",
                   max_iter=5000, rng=0) -> MultiPlaneResult:
    """Sequential extraction of plane homographies from point correspondences.

    Parameters
    ----------
    x1, x2 : ndarray (n, 2)
        Corresponding points (pixels) in view 1 and view 2.
    threshold : float or None, default=5.0
        Inlier threshold in pixels (5 px: mean misclassification error 11.3 % over the 12
        AdelaideRMF pairs); ``None``: 1 % of the larger extent spanned by the points, at least
        3 px (13.1 %).
    min_inliers : int, default=10
        Stop when the next plane has fewer inliers.
    max_planes : int, default=None
        Stop after this many planes.
    method : str, default="ransac"
        Robust estimator (as in :func:`estimate_pairwise_homographies`).
    max_iter : int, default=5000
    rng : int, default=0
        Seed of OpenCV's random generator (RANSAC sampling).

    Returns
    -------
    MultiPlaneResult

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> a = rng.uniform(0, 100, (60, 2)); b = rng.uniform(0, 100, (40, 2))
    >>> x1 = np.vstack([a, b]); x2 = np.vstack([a + 5.0, b @ np.diag([1.2, 0.9])])
    >>> res = extract_planes(x1, x2, threshold=1.0)
    >>> len(res.homographies), int((res.labels == 1).sum()), int((res.labels == 2).sum())
    (2, 60, 40)
    """
    x1 = np.asarray(x1, dtype=np.float64)
    x2 = np.asarray(x2, dtype=np.float64)
    if x1.ndim != 2 or x1.shape[1] != 2 or x1.shape != x2.shape:
        raise ValueError(f"`x1` and `x2` must both have shape (n, 2), got {x1.shape} and "
                         f"{x2.shape}")
    min_inliers = check_int(min_inliers, "min_inliers", minimum=4)
    if threshold is None:
        span = float(np.ptp(np.vstack([x1, x2]), axis=0).max()) if len(x1) else 0.0
        threshold = max(3.0, 0.01 * span)
    threshold = check_positive(threshold, "threshold")
    cv2.setRNGSeed(int(rng))
    labels = np.zeros(len(x1), dtype=int)
    Hs = []
    left = np.ones(len(x1), bool)
    while left.sum() >= max(min_inliers, 4) and (max_planes is None or len(Hs) < max_planes):
        idx = np.flatnonzero(left)
        src = x1[idx].astype(np.float32)
        dst = x2[idx].astype(np.float32)
        try:
            H, inl = cv2.findHomography(src, dst, _METHODS[method], threshold,
                                        maxIters=max_iter, confidence=0.999)
        except cv2.error:
            break
        if H is None or inl is None:
            break
        inl = inl.ravel().astype(bool)
        if inl.sum() >= 8:
            H, _ = _refine_inliers(src, dst, H, inl, threshold)
        err = _transfer_error(H, x1[idx], x2[idx])
        inl = err <= threshold
        if inl.sum() < min_inliers:
            break
        Hs.append(H / H[2, 2])
        labels[idx[inl]] = len(Hs)
        left[idx[inl]] = False
    return MultiPlaneResult(labels=labels, homographies=Hs,
                            info={"threshold": threshold, "n_outliers": int((labels == 0).sum())})


def misclassification_error(pred, truth) -> float:
    """Fraction of points whose label differs from the ground truth under the best one-to-one
    relabelling of the planes (label 0, outliers, maps to 0).

    Examples
    --------
    >>> misclassification_error([0, 1, 1, 2, 2], [0, 2, 2, 1, 1])
    0.0
    >>> misclassification_error([1, 1, 1, 1], [1, 1, 2, 2])
    0.5
    """
    from scipy.optimize import linear_sum_assignment

    p = np.asarray(pred, dtype=int).ravel()
    t = np.asarray(truth, dtype=int).ravel()
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
