"""Several planes between two views: sequential robust homography extraction (AdelaideRMF).

The same machinery as the multi-view pipeline's sparse step: ``cv2.findHomography`` (RANSAC with
its Levenberg-Marquardt polish) followed by the inlier tightening of
:func:`estimate_pairwise_homographies` (``refine=True``); the inliers of each plane are
removed and the next plane is extracted from what is left, until a plane gathers fewer than
``min_inliers`` points.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import as_generator, check_array, check_choice, check_int, check_positive
from ..geometry import transfer_points
from ._sparse import _METHODS, MAX_RANSAC_ITER, _robust_fit

__all__ = ["MultiPlaneResult", "extract_planes"]

#: largest point coordinate (pixels) a plane fit takes: OpenCV's float32 arithmetic squares it
MAX_COORDINATE = 1e12


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

    Examples
    --------
    See :func:`extract_planes`, which returns one.

    >>> import numpy as np
    >>> r = MultiPlaneResult(labels=np.array([1, 1, 0]), homographies=[np.eye(3)])
    >>> len(r.homographies), r.labels.tolist()
    (1, [1, 1, 0])
    """

    labels: np.ndarray
    homographies: list
    info: dict[str, Any] = field(default_factory=dict, repr=False)


def _transfer_error(H, x1, x2):
    with np.errstate(invalid="ignore"):
        e1 = np.linalg.norm(transfer_points(H, x1) - x2, axis=1)
        e2 = np.linalg.norm(transfer_points(np.linalg.inv(H), x2) - x1, axis=1)
    return np.nan_to_num(0.5 * (e1 + e2), nan=np.inf)


def extract_planes(x1, x2, *, threshold=5.0, min_inliers=10, max_planes=None, method="ransac",
                   max_iter=5000, rng=None) -> MultiPlaneResult:
    """Sequential extraction of plane homographies from point correspondences.

    Parameters
    ----------
    x1, x2 : ndarray (n, 2)
        Corresponding points (pixels) in view 1 and view 2.
    threshold : float or None, default=5.0
        Inlier threshold in pixels; ``None``: 1 % of the larger extent spanned by the points, at
        least 3 px (measurements on AdelaideRMF: ``docs/homography.md``).
    min_inliers : int, default=10
        Stop when the next plane has fewer inliers.
    max_planes : int, default=None
        Stop after this many planes.
    method : str, default="ransac"
        Robust estimator (as in :func:`estimate_pairwise_homographies`).
    max_iter : int, default=5000
        Iterations of each robust fit, at most ``2**31 - 1`` (OpenCV's limit).
    rng : None, int or Generator, default=None
        Orders the remaining correspondences before every robust fit, and with them RANSAC's
        samples (OpenCV's global random state is never used).

    Returns
    -------
    MultiPlaneResult
        One homography and one inlier set per extracted plane, and each point's plane label.

    Raises
    ------
    ValueError, TypeError
        ``x1`` and ``x2`` not matching ``(n, 2)`` finite arrays, bad options.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> a = rng.uniform(0, 100, (60, 2)); b = rng.uniform(0, 100, (40, 2))
    >>> x1 = np.vstack([a, b]); x2 = np.vstack([a + 5.0, b @ np.diag([1.2, 0.9])])
    >>> res = extract_planes(x1, x2, threshold=1.0, rng=0)
    >>> len(res.homographies), int((res.labels == 1).sum()), int((res.labels == 2).sum())
    (2, 60, 40)
    """
    x1 = check_array(x1, "x1", ndim=2)
    x2 = check_array(x2, "x2", ndim=2)
    if x1.ndim != 2 or x1.shape[1] != 2 or x1.shape != x2.shape:
        raise ValueError(f"`x1` and `x2` must both have shape (n, 2), got {x1.shape} and "
                         f"{x2.shape}")
    for name, x in (("x1", x1), ("x2", x2)):
        if x.size and np.abs(x).max() > MAX_COORDINATE:
            raise ValueError(f"`{name}` must hold pixel coordinates within +-{MAX_COORDINATE:g} "
                             f"(OpenCV fits homographies in float32), got {np.abs(x).max():.3g}")
    min_inliers = check_int(min_inliers, "min_inliers", minimum=4)
    if threshold is None:
        span = float(np.ptp(np.vstack([x1, x2]), axis=0).max()) if len(x1) else 0.0
        threshold = max(3.0, 0.01 * span)
    threshold = check_positive(threshold, "threshold")
    method = check_choice(method, "method", tuple(_METHODS))
    max_iter = check_int(max_iter, "max_iter", minimum=1, maximum=MAX_RANSAC_ITER)
    if max_planes is not None:
        max_planes = check_int(max_planes, "max_planes", minimum=1)
    gen = as_generator(rng)
    labels = np.zeros(len(x1), dtype=int)
    Hs = []
    left = np.ones(len(x1), bool)
    while left.sum() >= max(min_inliers, 4) and (max_planes is None or len(Hs) < max_planes):
        idx = np.flatnonzero(left)
        src = x1[idx].astype(np.float32)
        dst = x2[idx].astype(np.float32)
        H, _, _ = _robust_fit(src, dst, method, threshold, max_iter, 0.999, True, gen)
        if H is None:
            break
        err = _transfer_error(H, x1[idx], x2[idx])
        inl = err <= threshold
        if inl.sum() < min_inliers:
            break
        Hs.append(H / H[2, 2])
        labels[idx[inl]] = len(Hs)
        left[idx[inl]] = False
    return MultiPlaneResult(labels=labels, homographies=Hs,
                            info={"threshold": threshold, "n_outliers": int((labels == 0).sum())})
