"""Geometric verification of a pairwise assignment between point sets.

A quadratic-assignment matcher scores every match by how well its edges agree; with every
affinity positive it prefers matching every node, and when the two graphs share only part of
their nodes (missing landmarks, occlusion) the extra matches pull true ones away. Points that
come from one rigid or planar scene obey one plane transform between the two sets; a robust fit
of that transform to the putative matches (RANSAC, as OpenCV implements it), followed by
*guided matching* (every point mapped through the fit and matched to the nearest point of the
other set within a gate, by linear assignment) and a least-squares refit, keeps the matches the
geometry supports, recovers true matches the matcher missed, and leaves the rest unmatched.

This is the geometric verification step of feature-matching pipelines (Hartley & Zisserman,
*Multiple View Geometry*, 2nd ed., section 4.8, "guided matching"), applied to graph matching's
node correspondences.

Examples
--------
>>> import numpy as np
>>> from transync.matching import verify_assignment
>>> rng = np.random.default_rng(0)
>>> p1 = rng.random((12, 2))
>>> A = np.array([[0.9, -0.3, 2.0], [0.4, 1.1, -1.0]])
>>> p2 = p1 @ A[:, :2].T + A[:, 2]                     # node u of graph 1 is node u of graph 2
>>> putative = np.arange(12); putative[[0, 1]] = [1, 0]   # two nodes swapped by the matcher
>>> res = verify_assignment(p1, p2, putative, rng=0)
>>> res.assignment.tolist() == list(range(12)), res.verified, res.n_inliers
(True, True, 12)
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .._validation import (as_generator, check_array, check_bool, check_choices, check_int,
                           check_positive)
from ..permutations import UNMATCHED, check_assignment, solve_lap

__all__ = ["VERIFY_MODELS", "VerificationResult", "verify_assignment"]

#: plane transforms a verification can fit, and the matches a minimal sample needs
VERIFY_MODELS = {"similarity": 2, "affine": 3, "homography": 4}
#: default gate: this fraction of the median nearest-neighbour distance among ``points2``
DEFAULT_THRESHOLD = 0.5
#: RANSAC iterations and confidence of the robust fit
_RANSAC_ITERS = 2000
_RANSAC_CONFIDENCE = 0.999
#: largest coordinate accepted (the fits run in float32 after normalization)
_MAX_COORDINATE = 1e12


@dataclass(frozen=True)
class VerificationResult:
    """The outcome of :func:`verify_assignment`.

    Attributes
    ----------
    assignment : ndarray of shape (n1,), int
        The verified map (``-1``: no match the geometry supports). All ``-1`` when the
        verification failed.
    transform : ndarray of shape (3, 3)
        The plane transform fitted last (``points2 ~ transform @ [points1, 1]``; affine and
        similarity transforms have last row ``[0, 0, 1]``); all NaN when no model was found.
    n_inliers : int
        Matches in ``assignment``.
    verified : bool
        Whether at least ``min_inliers`` matches were supported by the fitted transform.
    threshold : float
        The gate used, in the units of ``points2``.
    model : str
        The transform family fitted (of several candidates: the one kept).
    n_rounds : int
        Guided-matching rounds run (each a linear assignment and a refit).
    support : dict
        Every candidate model's verified matches, ``{model: n_inliers}`` (0: that model's
        verification failed); one entry when one model was asked for.
    """

    assignment: np.ndarray
    transform: np.ndarray
    n_inliers: int
    verified: bool
    threshold: float
    model: str
    n_rounds: int
    support: dict = field(default_factory=dict)


#: smallest ratio of the two point sets' scales a verification takes (and its inverse the
#: largest): the transform between them, in the callers' units, must stay finite
_MIN_SCALE_RATIO = 1e-280


def _check_points(points, name: str) -> np.ndarray:
    P = check_array(points, name, ndim=2)
    if P.shape[1] != 2:
        raise ValueError(f"`{name}` must be 2-d points of shape (n, 2): verification fits plane "
                         f"transforms; got shape {P.shape}")
    if P.shape[0] == 0:
        raise ValueError(f"`{name}` must hold at least one point, got shape {P.shape}")
    if np.abs(P).max() > _MAX_COORDINATE:
        raise ValueError(f"`{name}` coordinates must be at most {_MAX_COORDINATE:g} in absolute "
                         f"value, got {np.abs(P).max():g}")
    return P


def _nearest_neighbour_scale(points: np.ndarray) -> float:
    """Median distance from each point to its nearest other point (0.0 for one point).

    >>> _nearest_neighbour_scale(np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]]))
    1.0
    """
    from scipy.spatial import cKDTree

    if len(points) < 2:
        return 0.0
    d, _ = cKDTree(points).query(points, k=2)
    return float(np.median(d[:, 1]))


def _normalization(points: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(T, T(points))``: a similarity taking the points' median to the origin and their median
    distance from it to 1 (robust: one far point does not squeeze the others below OpenCV's
    single precision). The points are first divided by a power of two near their largest
    magnitude (exact), so that squared distances neither overflow nor underflow."""
    top = float(np.abs(points).max())
    unit = 2.0 ** np.round(np.log2(top)) if top > 0 else 1.0
    q = points / unit
    centre = np.median(q, axis=0)
    r = np.sqrt(((q - centre) ** 2).sum(axis=1))
    spread = float(np.median(r))
    if spread <= 0:
        spread = float(r.mean()) if r.mean() > 0 else 1.0
    with np.errstate(over="ignore", divide="ignore"):    # subnormal: spread * unit is 0
        s = 1.0 / (spread * unit)
    if not np.isfinite(s):
        raise ValueError(f"`{name}` cannot be normalized in floating point: the points' "
                         f"spread (median distance {spread * unit:.3g} at magnitudes up to "
                         f"{top:.3g}) is too small; rescale the points")
    T = np.array([[s, 0.0, -s * unit * centre[0]], [0.0, s, -s * unit * centre[1]],
                  [0.0, 0.0, 1.0]])
    return T, (q - centre) / spread


def _least_squares(model: str, src: np.ndarray, dst: np.ndarray) -> np.ndarray | None:
    """The least-squares transform ``src -> dst`` on every match (no outlier left to reject)."""
    k = len(src)
    if model == "affine":
        A = np.c_[src, np.ones(k)]
        M, _, rank, _ = np.linalg.lstsq(A, dst, rcond=None)
        return np.vstack([M.T, [0.0, 0.0, 1.0]]) if rank == 3 else None
    if model == "similarity":       # x' = a x - b y + tx, y' = b x + a y + ty
        A = np.zeros((2 * k, 4))
        A[0::2] = np.c_[src[:, 0], -src[:, 1], np.ones(k), np.zeros(k)]
        A[1::2] = np.c_[src[:, 1], src[:, 0], np.zeros(k), np.ones(k)]
        (p, q, tx, ty), _, rank, _ = np.linalg.lstsq(A, dst.reshape(-1), rcond=None)
        return np.array([[p, -q, tx], [q, p, ty], [0.0, 0.0, 1.0]]) if rank == 4 else None
    return None


def _fit(model: str, src: np.ndarray, dst: np.ndarray, threshold: float, robust: bool,
         gen: np.random.Generator) -> np.ndarray | None:
    """A ``(3, 3)`` transform ``src -> dst`` (normalized coordinates), or None: RANSAC
    (``robust``) or least squares on every match."""
    import cv2

    if not robust and model != "homography":
        H = _least_squares(model, src, dst)
    else:
        order = gen.permutation(len(src)) if robust else np.arange(len(src))
        s = np.ascontiguousarray(src[order], dtype=np.float64)
        d = np.ascontiguousarray(dst[order], dtype=np.float64)
        try:
            if model == "homography":
                H, _ = cv2.findHomography(s, d, cv2.RANSAC if robust else 0, threshold,
                                          maxIters=_RANSAC_ITERS, confidence=_RANSAC_CONFIDENCE)
            else:
                fn = cv2.estimateAffine2D if model == "affine" else cv2.estimateAffinePartial2D
                M, _ = fn(s, d, method=cv2.RANSAC, ransacReprojThreshold=threshold,
                          maxIters=_RANSAC_ITERS, confidence=_RANSAC_CONFIDENCE, refineIters=10)
                H = None if M is None else np.vstack([M, [0.0, 0.0, 1.0]])
        except cv2.error:          # degenerate samples (collinear points, ...): no model
            return None
    if H is None or not np.all(np.isfinite(H)):
        return None
    return np.asarray(H, dtype=float)


def _guided(H: np.ndarray, x1: np.ndarray, x2: np.ndarray, gate: float) -> np.ndarray:
    """Linear assignment of ``x1`` mapped through ``H`` to ``x2`` within ``gate``."""
    q = x1 @ H[:2, :2].T + H[:2, 2]
    w = x1 @ H[2, :2] + H[2, 2]               # 1 for affine and similarity transforms
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        q = q / w[:, None]
    q[w <= 0] = np.inf                        # mapped behind the camera: matches nothing
    with np.errstate(over="ignore", invalid="ignore"):   # a wild transform: beyond any gate
        D = np.sqrt(((q[:, None, :] - x2[None, :, :]) ** 2).sum(-1))
    D = np.where(np.isfinite(D), D, np.inf)
    a = solve_lap(np.minimum(D, gate), maximize=False)
    rows = np.flatnonzero(a >= 0)
    a[rows[D[rows, a[rows]] >= gate]] = UNMATCHED
    return a


def verify_assignment(points1, points2, assignment, *, model="affine",
                      threshold: float = DEFAULT_THRESHOLD, min_inliers: int | None = None,
                      max_rounds: int = 5, reflections: bool = False,
                      rng=None) -> VerificationResult:
    """Keep the matches one plane transform supports; recover the ones it predicts.

    Stages: a RANSAC fit of ``model`` to the putative matches ``u -> assignment[u]``
    (OpenCV's ``estimateAffine2D`` / ``estimateAffinePartial2D`` / ``findHomography``, on
    normalized coordinates); guided matching: every point of ``points1`` mapped through the fit
    and matched by linear assignment to a point of ``points2`` closer than the gate; a
    least-squares refit on those matches; repeated until the matches stop changing or
    ``max_rounds``. Fewer than ``min_inliers`` supported matches: the verification fails and
    the returned map is empty (all ``-1``), since no transform explains the putative matches.

    Parameters
    ----------
    points1 : array_like of shape (n1, 2)
        Points of the first graph.
    points2 : array_like of shape (n2, 2)
        Points of the second graph.
    assignment : array_like of shape (n1,), int
        Putative map ``u -> assignment[u]`` (``-1`` unmatched), e.g. a matcher's output.
    model : {"affine", "similarity", "homography"} or sequence of them, default="affine"
        Transform family: ``"similarity"`` (rotation, uniform scale, translation; 2 matches per
        sample), ``"affine"`` (3) or ``"homography"`` (4; points on one plane seen by a pinhole
        camera). A sequence, e.g. ``("affine", "homography")``, verifies with each and keeps
        the verified result with the most matches (ties: the earlier model; none verified:
        the first model's failed result); ``.model`` names the one kept. Each candidate is
        exactly ``verify_assignment(..., model=m, rng=rng)`` from the same state of ``rng``
        (a Generator is left where the first model's call leaves it), so the first model's
        verdict is the one it gives alone. Views of a scene that is not one plane, or seen in
        perspective, are often explained better by one model in some pairs and by the other
        in others.
    threshold : float, default=0.5
        The gate, as a fraction of the median nearest-neighbour distance among ``points2``: a
        point mapped closer than that to a point of ``points2`` may match it. Half the typical
        spacing keeps a mapped point from reaching its neighbour's match.
    min_inliers : int, optional
        Matches needed for a verified map. Default: half the smaller point set (rounded up),
        and at least twice the minimal sample (similarity 4, affine 6, homography 8; per
        candidate model). Given, it must be at least every model's minimal sample. A wrong
        transform still lands points within the gate of others by chance (about one point in
        six at the default gate, for evenly spread points), and the best of RANSAC's samples
        collects several such chance matches; a transform that explains half the nodes is
        rarely wrong. Pairs that share fewer nodes need a lower value.
    max_rounds : int, default=5
        Guided-matching rounds after the robust fit.
    reflections : bool, default=False
        Accept a transform that mirrors the plane (``det < 0``: an affine map or homography
        with a reflection; a similarity never has one). Two views of a scene are not mirror
        images of each other, and a length-based matcher's mirrored answer can be fitted by a
        mirroring affine map: on ten to thirteen random points, 7 supported matches, none of
        them right. Such a fit fails the verification unless this is True.
    rng : None, int or numpy.random.Generator
        Orders the putative matches before the robust fit, and with them OpenCV's RANSAC
        samples: the same ``rng``, the same result.

    Returns
    -------
    VerificationResult
        The verified map, the transform, the number of matches, whether it verified.

    Raises
    ------
    ValueError, TypeError
        Points not of shape ``(n, 2)``, empty or non-finite, an assignment of the wrong length,
        out of range or not injective, an unknown ``model``, a non-positive ``threshold``,
        ``min_inliers`` below the minimal sample, ``max_rounds`` below 1.

    Examples
    --------
    A similarity between two views, two of twelve nodes unseen in the second, and a matcher
    that matched them anyway (to other nodes' points):

    >>> import numpy as np
    >>> rng = np.random.default_rng(1)
    >>> p1 = rng.random((12, 2))
    >>> c, s = np.cos(0.4), np.sin(0.4)
    >>> p2 = 2.0 * p1[:10] @ np.array([[c, -s], [s, c]]).T + 5.0   # nodes 10, 11 unseen
    >>> putative = np.array([0, 1, 2, 3, 4, 5, 6, 7, 9, 8, -1, -1])
    >>> putative[[8, 9]] = -1; putative[[10, 11]] = [8, 9]         # two spurious matches
    >>> res = verify_assignment(p1, p2, putative, model="similarity", rng=0)
    >>> res.assignment.tolist()
    [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, -1, -1]
    """
    p1 = _check_points(points1, "points1")
    p2 = _check_points(points2, "points2")
    a = check_assignment(assignment, "assignment", n1=len(p1), n2=len(p2))
    models = check_choices(model, "model", tuple(VERIFY_MODELS))
    threshold = check_positive(threshold, "threshold")
    if min_inliers is not None:
        min_inliers = check_int(min_inliers, "min_inliers",
                                minimum=max(VERIFY_MODELS[m] for m in models))
    max_rounds = check_int(max_rounds, "max_rounds", minimum=1)
    reflections = check_bool(reflections, "reflections")
    gen = as_generator(rng)

    # Normalized coordinates: the fits and the gate do not depend on the units
    T1, x1 = _normalization(p1, "points1")
    T2, x2 = _normalization(p2, "points2")
    with np.errstate(over="ignore", under="ignore"):
        ratio = T1[0, 0] / T2[0, 0]           # spread of points2 / spread of points1
    if not _MIN_SCALE_RATIO < ratio < 1.0 / _MIN_SCALE_RATIO:
        raise ValueError(f"`points1` and `points2` differ too much in scale (the spread of "
                         f"`points2` is {ratio:.3g} times that of `points1`): a transform "
                         f"between them overflows float64; rescale one of them")
    g = threshold * _nearest_neighbour_scale(x2)
    with np.errstate(over="ignore"):
        gate = g / T2[0, 0]                   # the gate in the units of points2
    if not np.isfinite(gate):
        raise ValueError(f"`threshold` times the spacing of `points2` must be a finite "
                         f"distance, got {threshold:g} x {1 / T2[0, 0]:g}")
    if len(models) == 1:
        res = _verify(models[0], a, x1, x2, T1, T2, g, gate, min_inliers, max_rounds, gen,
                      reflections)
        return replace(res, support={res.model: res.n_inliers})
    # every candidate from the same generator state, which is left where the first model's
    # verification leaves it: the first candidate is exactly the first model's own call
    start, after_first = gen.bit_generator.state, None
    best, support = None, {}
    for m in models:
        gen.bit_generator.state = start
        res = _verify(m, a, x1, x2, T1, T2, g, gate, min_inliers, max_rounds, gen,
                      reflections)
        after_first = after_first or gen.bit_generator.state
        support[m] = res.n_inliers
        if best is None or (res.verified and (not best.verified
                                              or res.n_inliers > best.n_inliers)):
            best = res
    gen.bit_generator.state = after_first
    return replace(best, support=support)


def _keeps_orientation(H: np.ndarray) -> bool:
    """Whether ``H`` maps the plane without mirroring it: ``det H > 0`` (for a homography the
    sign of its Jacobian ``det H / w^3`` wherever points land in front, ``w > 0``)."""
    return bool(np.linalg.det(H) > 0)


def _verify(model: str, a, x1, x2, T1, T2, g: float, gate: float, min_inliers: int | None,
            max_rounds: int, gen: np.random.Generator,
            reflections: bool = False) -> VerificationResult:
    """One model's verification of the putative map ``a`` (normalized points ``x1``, ``x2``,
    their normalizations ``T1``, ``T2``, the gate ``g`` normalized and ``gate`` in units)."""
    if min_inliers is None:
        min_inliers = max(2 * VERIFY_MODELS[model], -(-min(len(x1), len(x2)) // 2))
    empty = np.full(len(x1), UNMATCHED, dtype=np.int64)
    failed = VerificationResult(empty, np.full((3, 3), np.nan), 0, False, gate, model, 0)
    src = np.flatnonzero(a >= 0)
    if len(src) < min_inliers or g <= 0:          # min_inliers >= k, the minimal sample
        return failed
    H = _fit(model, x1[src], x2[a[src]], g, True, gen)
    if H is None:
        return failed
    current, rounds = None, 0
    while rounds < max_rounds:
        rounds += 1
        new = _guided(H, x1, x2, g)
        if current is not None and np.array_equal(new, current):
            break
        current = new
        rows = np.flatnonzero(current >= 0)
        if len(rows) < min_inliers:
            break
        refit = _fit(model, x1[rows], x2[current[rows]], g, False, gen)
        if refit is None:
            break
        H = refit
    rows = np.flatnonzero(current >= 0)
    H = _denormalize(H, T1, T2)
    if len(rows) < min_inliers or (not reflections and not _keeps_orientation(H)):
        return VerificationResult(empty, H, 0, False, gate, model, rounds)
    return VerificationResult(current, H, int(len(rows)), True, gate, model, rounds)


def _denormalize(H, T1, T2) -> np.ndarray:
    """The transform in the callers' coordinates: ``T2^-1 H T1``, scaled to ``[2, 2] = 1``."""
    out = np.linalg.solve(T2, H @ T1)
    return out / out[2, 2] if abs(out[2, 2]) > 1e-300 else out
