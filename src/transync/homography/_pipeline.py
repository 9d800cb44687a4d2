"""Front door: multi-view plane homographies with synchronization, dense refinement, segmentation.

:func:`estimate_plane_homographies` is a short driver over named stages: features
(:func:`_features`), sparse pairs (:func:`_sparse_pairs`), synchronization (:func:`_synchronize`),
the rectified second sparse pass (:func:`_rectified_pass`), then rounds of segmentation
(:func:`_segment_round`) and dense refinement (:func:`_dense_round`). The options of the dense
stage are one frozen :class:`DenseOptions`. Measurements behind the defaults:
``docs/homography.md``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import (
    MAX_ITER,
    as_generator,
    check_array,
    check_bool,
    check_choice,
    check_int,
    check_positive,
    invertible_homographies,
)
from ..exceptions import DegenerateInputError, UnlinkedViewsWarning
from ..geometry import image_corners, normalize_determinant, transfer_points, translation
from ..synchronization import synchronize_homographies
from ._dense import MAX_CANVAS, MAX_CANVAS_PIXELS, mean_warped_image, refine_homography_ecc
from ._segmentation import segment_plane
from ._sparse import (
    _METHODS,
    PairwiseHomographies,
    estimate_pairwise_homographies,
    estimate_rectified_pairwise,
    load_images,
    margin_canvas,
    sift_features,
    to_gray,
)

__all__ = ["DenseOptions", "PlaneAlignmentResult", "estimate_plane_homographies",
           "view_graph_pairs"]

logger = logging.getLogger("transync.homography")

#: Largest canvas margin (fraction of the reference frame on every side): the canvas of the
#: segmentation and of the mean image is at most 5 x 5 reference frames.
MAX_CANVAS_MARGIN = 2.0
#: Largest ``dense_weight``: beyond it the sparse pairs no longer count at all.
MAX_DENSE_WEIGHT = 1e6
#: Largest weight (inlier count) of a precomputed pair (``pairs=PairwiseHomographies``).
MAX_PAIR_WEIGHT = 1e12


@dataclass(frozen=True)
class DenseOptions:
    """Options of the dense stage of :func:`estimate_plane_homographies` (rounds of plane
    segmentation, masked ECC of every view and re-synchronization). Each field is also accepted
    as a keyword of :func:`estimate_plane_homographies`. Measurements: ``docs/homography.md``.

    Attributes
    ----------
    max_iter : int, default=3
        Rounds of segmentation + dense refinement (0: none).
    tol : float, default=0.02
        Stop when the largest mean corner change of a round is below this (pixels).
    levels : int, default=2
        ECC pyramid levels of the first round (later rounds: full resolution only), 1 to 8.
    max_step : float, default=10.0
        A dense update moving a view's corners by more than this (pixels) is a divergence and
        is discarded.
    dense_target : {"auto", "mean", "reference"}, default="auto"
        Template of the ECC: the mean warped image or the reference view; "auto" takes the
        mean image from 4 views on.
    dense_weight : float, default=1.0
        Weight of a view's dense estimate in the re-synchronization relative to the sum of the
        inlier counts of that view's sparse pairs (1: equal say; at most 1e6). Raise it for
        coarse pairwise inputs passed through ``pairs``.
    canvas_margin : float, default=0.5
        The canvas of the segmentation and of the mean warped image extends the reference
        frame by this fraction on every side (0 to :data:`MAX_CANVAS_MARGIN`).
    dense_check : bool, default=True
        Accept a view's ECC update only if the median distance between its sparse inlier
        matches and their partners stays within ``1 + sparse_tolerance`` times that of the
        synchronized sparse solution. A view without inlier matches (precomputed ``pairs``
        given without ``matches``) cannot be checked: its update is accepted, and its record in
        ``info["history"][k]["dense_views"]`` says ``"sparse_check": "no inlier matches"``.
    sparse_tolerance : float, default=0.25
        Relative slack of the ``dense_check`` (see above).

    Raises
    ------
    ValueError, TypeError
        A field out of range or of the wrong type (checked when the options are created).

    Examples
    --------
    >>> opts = DenseOptions(max_iter=1)
    >>> opts.max_iter, opts.levels
    (1, 2)
    """

    max_iter: int = 3
    tol: float = 0.02
    levels: int = 2
    max_step: float = 10.0
    dense_target: str = "auto"
    dense_weight: float = 1.0
    canvas_margin: float = 0.5
    dense_check: bool = True
    sparse_tolerance: float = 0.25

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "max_iter", check_int(self.max_iter, "max_iter", minimum=0, maximum=MAX_ITER))
        set_(self, "tol", check_positive(self.tol, "tol", allow_zero=True))
        set_(self, "levels", check_int(self.levels, "levels", minimum=1, maximum=8))
        set_(self, "max_step", check_positive(self.max_step, "max_step"))
        set_(self, "dense_target", check_choice(self.dense_target, "dense_target",
                                                ("auto", "mean", "reference")))
        set_(self, "dense_weight", check_positive(self.dense_weight, "dense_weight"))
        if self.dense_weight > MAX_DENSE_WEIGHT:
            raise ValueError(f"`dense_weight` must lie in (0, {MAX_DENSE_WEIGHT:g}] (a relative "
                             f"weight; beyond it the sparse pairs no longer count), got "
                             f"{self.dense_weight!r}")
        margin = check_positive(self.canvas_margin, "canvas_margin", allow_zero=True)
        if margin > MAX_CANVAS_MARGIN:
            raise ValueError(f"`canvas_margin` must lie in [0, {MAX_CANVAS_MARGIN:g}] "
                             f"(fraction of the reference frame), got {margin!r}")
        set_(self, "canvas_margin", margin)
        set_(self, "dense_check", check_bool(self.dense_check, "dense_check"))
        set_(self, "sparse_tolerance", check_positive(self.sparse_tolerance, "sparse_tolerance",
                                                      allow_zero=True))


_DENSE_FIELDS = tuple(f.name for f in dataclasses.fields(DenseOptions))


@dataclass(frozen=True)
class PlaneAlignmentResult:
    """Result of :func:`estimate_plane_homographies`.

    Attributes
    ----------
    homographies : ndarray (N, 3, 3)
        ``homographies[i]`` maps pixel coordinates of view ``i`` into the reference view
        (determinant 1; NaN for views that could not be registered).
    masks : list of (h_i, w_i) bool arrays
        Plane mask of every view (all True when ``segment=False``; all False for a view that
        could not be registered).
    mean_image : ndarray (h, w) float32
        Mean of the plane pixels of all views warped into the reference view; NaN where no
        view's plane pixels land (as :func:`mean_warped_image`).
    reference : int
    sparse_homographies : ndarray (N, 3, 3)
        The synchronized sparse estimate (before the dense step).
    pairwise : PairwiseHomographies
        The sparse pairwise estimates (failed pairs in ``pairwise.failed``).
    objective : float
        Final mean corner change of the last iteration (pixels).
    n_iter : int
        Dense/segmentation rounds.
    converged : bool
    info : dict
        ``history``: per-iteration diagnostics (``max_corner_change`` of the round's update in
        pixels, ``mask_change``: fraction of pixels whose plane label the round's segmentation
        flipped, against all-plane in the first round; ``plane_fraction`` of the registered
        views, per-view dense outcomes, stage times); ``seconds``: timing per stage; ``sync``:
        the sparse :class:`LinearMapSyncResult`; ``options``: the :class:`DenseOptions` used.

    Examples
    --------
    See :func:`estimate_plane_homographies`.

    >>> sorted(PlaneAlignmentResult.__dataclass_fields__)[:3]
    ['converged', 'homographies', 'info']
    """

    homographies: np.ndarray
    masks: list
    mean_image: np.ndarray
    reference: int
    sparse_homographies: np.ndarray
    pairwise: Any = field(repr=False)
    objective: float = 0.0
    n_iter: int = 0
    converged: bool = True
    info: dict[str, Any] = field(default_factory=dict, repr=False)


def _corner_change(A, B, sizes):
    return np.asarray([np.linalg.norm(transfer_points(Ha, c) - transfer_points(Hb, c),
                                      axis=1).mean()
                       for Ha, Hb, c in ((a, b, image_corners(s)) for a, b, s in
                                         zip(A, B, sizes))])


def _resynchronize(H, H_dense, pw, idx, reference, sizes, dense_target, *, robust=True,
                   dense_weight=1.0):
    """Robust SL(3) synchronization of dense view-to-template estimates and sparse pairs.

    The dense edge of view ``i`` weighs ``dense_weight`` times the sum of the sparse weights
    (inlier counts) of the view's pairs.
    """
    n = len(H)
    extra = dense_target == "mean"
    m = n + 1 if extra else n
    node = n if extra else reference
    T = np.full((m, m, 3, 3), np.nan)
    mask = np.zeros((m, m), bool)
    W = np.zeros((m, m))
    T[:n, :n] = pw.H
    mask[:n, :n] = pw.mask
    keep = np.zeros(n, bool)
    keep[idx] = True
    mask[:n, :n] &= keep[:, None] & keep[None, :]
    W[:n, :n] = np.where(mask[:n, :n], pw.weights, 0.0)
    sparse_sum = W[:n, :n].sum(axis=0)
    for i, Hi in H_dense.items():
        T[node, i] = Hi
        T[i, node] = np.linalg.inv(Hi)
        mask[node, i] = mask[i, node] = True
        W[node, i] = W[i, node] = dense_weight * max(float(sparse_sum[i]), 1.0)
    if not H_dense:
        return H.copy(), None
    size_list = list(sizes) + ([sizes[reference]] if extra else [])
    sub = np.concatenate([idx, [n]]) if extra else idx
    sub_ref = int(np.flatnonzero(sub == reference)[0])
    res = synchronize_homographies(T[np.ix_(sub, sub)], mask=mask[np.ix_(sub, sub)],
                                   weights=W[np.ix_(sub, sub)], reference=sub_ref,
                                   robust=robust, image_size=np.array(
                                       [size_list[k] for k in sub], float),
                                   disconnected="component")
    out = H.copy()
    good = np.all(np.isfinite(res.maps), axis=(1, 2))
    for k, i in enumerate(sub):
        if i < n and good[k]:
            out[i] = res.maps[k]
    return out, res


def _crop_to_footprint(Tc, H, size, tpl, tmask, pad=16):
    """Canvas transform, template and template mask cropped to the footprint of one view.

    ``Tc @ H`` maps the view into the canvas; the crop is the bounding box of the mapped view
    corners plus ``pad`` pixels, clipped to the canvas (the whole canvas when that box is
    degenerate). Returns ``(C @ Tc, tpl[crop], tmask[crop])`` with ``C`` the crop translation.
    """
    M = Tc @ H
    c = image_corners(size)
    if not np.all(c @ M[2, :2] + M[2, 2] > 0):
        return Tc, tpl, tmask
    x, y = transfer_points(M, c).T
    Hc, Wc = tpl.shape[:2]
    x0, x1 = (int(np.clip(v, 0, Wc)) for v in (np.floor(x.min()) - pad, np.ceil(x.max()) + pad))
    y0, y1 = (int(np.clip(v, 0, Hc)) for v in (np.floor(y.min()) - pad, np.ceil(y.max()) + pad))
    if x1 - x0 < 32 or y1 - y0 < 32:
        return Tc, tpl, tmask
    return translation(-x0, -y0) @ Tc, tpl[y0:y1, x0:x1], tmask[y0:y1, x0:x1]


def _sparse_correspondences(pw, H_warp=None, T=None):
    """Inlier correspondences of the sparse pairs in original view pixels:
    ``{(i, j): (x_i, x_j)}``. Matches of the rectified pass (found between views warped by
    ``T @ H_warp[i]``) are mapped back into the views."""
    out = {}
    for (i, j), (dst, src, inl) in pw.matches.items():
        if not pw.mask[i, j] or inl.sum() < 4:
            continue
        a = np.asarray(dst, float)[inl]
        b = np.asarray(src, float)[inl]
        if H_warp is not None:
            a = transfer_points(np.linalg.inv(T @ H_warp[i]), a)
            b = transfer_points(np.linalg.inv(T @ H_warp[j]), b)
        out[(i, j)] = (a, b)
    return out


def _sparse_residual(i, Hi, H, corr):
    """Median distance, in reference pixels, between the sparse inliers of view ``i`` mapped by
    ``Hi`` and their partners mapped by the current estimates ``H`` (NaN without inliers)."""
    r = []
    for (a, b), (xa, xb) in corr.items():
        if a == i and np.all(np.isfinite(H[b])):
            r.append(np.linalg.norm(transfer_points(Hi, xa) - transfer_points(H[b], xb),
                                    axis=1))
        elif b == i and np.all(np.isfinite(H[a])):
            r.append(np.linalg.norm(transfer_points(Hi, xb) - transfer_points(H[a], xa),
                                    axis=1))
    return float(np.median(np.concatenate(r))) if r else float("nan")


#: ``pairs="auto"`` matches every pair of views up to this many views, a view graph beyond.
EXHAUSTIVE_UP_TO = 40


def view_graph_pairs(H_to_ref, sizes, *, reference, k=3) -> list[tuple[int, int]]:
    """Pairs (i, j) linking every view to its ``k`` nearest views.

    Distances are between the views' footprint centres in the reference frame; views without
    an estimate are linked to every other view. The reference is not counted among the nearest
    views (link it to every view yourself when that is wanted).

    Parameters
    ----------
    H_to_ref : array_like of shape (N, 3, 3)
        Homographies of every view into the reference (NaN: no estimate).
    sizes : sequence of (width, height)
        Image sizes in pixels.
    reference : int
        The reference view.
    k : int, default=3
        Nearest views per view.

    Returns
    -------
    list of (int, int)
        Sorted pairs ``i < j``.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.geometry import translation
    >>> H = np.stack([translation(10.0 * i, 0.0) for i in range(4)])   # views in a row
    >>> view_graph_pairs(H, [(100, 100)] * 4, reference=0, k=1)
    [(1, 2), (2, 3)]
    """
    H_to_ref = check_array(H_to_ref, "H_to_ref", ndim=3, finite=False)
    n = len(H_to_ref)
    if H_to_ref.shape[1:] != (3, 3) or n < 1:
        raise ValueError(f"`H_to_ref` must have shape (N, 3, 3) with N >= 1, got shape "
                         f"{H_to_ref.shape}")
    if sizes is None or isinstance(sizes, (str, bytes)):
        raise TypeError(f"`sizes` must be a sequence of (width, height), got {sizes!r}")
    sizes = check_array(sizes, "sizes")
    if sizes.shape != (n, 2) or np.any(sizes <= 0):
        raise ValueError(f"`sizes` must hold one positive (width, height) per view, shape "
                         f"({n}, 2), got {sizes.tolist() if sizes.size < 20 else sizes.shape}")
    reference = check_int(reference, "reference", minimum=0, maximum=n - 1)
    k = check_int(k, "k", minimum=1)
    centers = np.full((n, 2), np.nan)
    for i in range(n):
        if np.all(np.isfinite(H_to_ref[i])):
            w, h = sizes[i]
            centers[i] = transfer_points(H_to_ref[i], [[(w - 1) / 2, (h - 1) / 2]])[0]
    pairs = set()
    for i in range(n):
        if i == reference:
            continue
        if not np.all(np.isfinite(centers[i])):
            pairs.update((min(i, j), max(i, j)) for j in range(n) if j != i)
            continue
        with np.errstate(over="ignore", invalid="ignore"):   # far centres: inf, not linked
            d = np.hypot(*(centers - centers[i]).T)
        d[i] = np.inf
        d[reference] = np.inf
        d[~np.isfinite(d)] = np.inf
        for j in np.argsort(d)[:k]:
            if np.isfinite(d[j]):
                pairs.add((min(i, int(j)), max(i, int(j))))
    return sorted(pairs)


# ------------------------------------------------------------------------------------ stages
def _features(gray, n_features):
    """Stage 1: SIFT features of every view."""
    return [sift_features(g, n_features=n_features) for g in gray]


def _sparse_pairs(gray, sizes, feats, pairs, *, reference, n_neighbors, rng, **kw):
    """Stage 2: sparse pairwise homographies along the view graph (``pairs``)."""
    n = len(gray)
    kw = dict(kw, features=feats, rng=rng)
    if isinstance(pairs, PairwiseHomographies):
        return pairs
    if not isinstance(pairs, str):
        return estimate_pairwise_homographies(gray, pairs=pairs, **kw)
    if pairs == "all" or n <= max(n_neighbors + 2, EXHAUSTIVE_UP_TO):
        return estimate_pairwise_homographies(gray, **kw)
    g_first, g_extra = rng.spawn(2)
    first = [(reference, i) for i in range(n) if i != reference]
    pw0 = estimate_pairwise_homographies(gray, pairs=first, **dict(kw, rng=g_first))
    approx = np.stack([np.eye(3) if i == reference else pw0.H[reference, i] for i in range(n)])
    extra = [p for p in view_graph_pairs(approx, sizes, reference=reference, k=n_neighbors)
             if reference not in p]
    pw1 = estimate_pairwise_homographies(gray, pairs=extra, **dict(kw, rng=g_extra))
    H = np.where(pw0.mask[..., None, None], pw0.H, pw1.H)
    return PairwiseHomographies(H=H, mask=pw0.mask | pw1.mask, weights=pw0.weights + pw1.weights,
                                failed=pw0.failed + pw1.failed,
                                matches={**pw0.matches, **pw1.matches},
                                info={"n_keypoints": pw0.info["n_keypoints"]})


def _synchronize(pw, sizes, reference, robust):
    """Stage 3: robust SL(3) synchronization of the pairs, weighted by their inlier counts."""
    return synchronize_homographies(pw.H, mask=pw.mask, weights=pw.weights, reference=reference,
                                    robust=robust, image_size=np.array(sizes, float),
                                    disconnected="component")


def _rectified_pass(gray, pw, sync, *, reference, robust, n_features, method, rng):
    """Stage 4: second sparse pass between the views warped into the reference frame.

    The corrections ``C_i`` are synchronized in the canvas (reference) frame, where every
    residual is measured with the same geometry (no extrapolation to the corners of strongly
    tilted views): ``H'_ij ~ inv(C_i) C_j``, ``H_i <- inv(T) C_i T H_i``. Returns
    ``(maps, pairwise, sync_rectified)``, or ``None`` when the pass links fewer views.
    """
    ok0 = np.all(np.isfinite(sync.maps), axis=(1, 2))
    edges = [(int(i), int(j)) for i, j in zip(*np.nonzero(np.triu(pw.mask, 1)))
             if ok0[i] and ok0[j]]
    pw_r = estimate_rectified_pairwise(gray, sync.maps, edges, reference=reference,
                                       n_features=n_features, method=method, rng=rng)
    if not pw_r.mask.any():
        return None
    Tc, csize = pw_r.info["canvas"]
    sync_r = synchronize_homographies(pw_r.info["H_warped"], mask=pw_r.mask,
                                      weights=pw_r.weights, reference=reference, robust=robust,
                                      image_size=csize, disconnected="component")
    ok_r = np.all(np.isfinite(sync_r.maps), axis=(1, 2))
    if ok_r.sum() < ok0.sum():
        return None
    maps = np.full_like(sync.maps, np.nan)
    for i in np.flatnonzero(ok_r):
        maps[i] = normalize_determinant(np.linalg.inv(Tc) @ sync_r.maps[i] @ Tc @ sync.maps[i])
    # the pass re-estimates only the pairs the first pass linked: the pairs that failed there
    # stay failed (they were dropped from the result and the CLI's report)
    pw_r = dataclasses.replace(pw_r, failed=list(pw.failed) + list(pw_r.failed))
    return maps, pw_r, sync_r


def _segment_round(gray, H, idx, masks, *, r_sub, margin, rng):
    """Stage 5a: plane masks of the linked views (``idx``), updated in place; returns the
    fraction of pixels whose label flipped."""
    sub = segment_plane([gray[i] for i in idx], H[idx], reference=r_sub, margin=margin, rng=rng)
    flipped = sum(int(np.count_nonzero(masks[i] != sub[k])) for k, i in enumerate(idx))
    total = sum(masks[i].size for i in idx)
    for k, i in enumerate(idx):
        masks[i] = sub[k]
    return flipped / total


def _check_canvas(size, margin: float, reference: int) -> None:
    """The canvas of the reference view widened by ``margin`` on every side must fit OpenCV's
    and the mean image's limits (checked before the sparse stage, not after it)."""
    (w, h), _ = margin_canvas(size, margin)
    if max(w, h) > MAX_CANVAS or w * h > MAX_CANVAS_PIXELS:
        raise ValueError(f"`canvas_margin`={margin:g} on the reference view {reference} "
                         f"({size[0]} x {size[1]} pixels) makes a {w} x {h} canvas, beyond "
                         f"{MAX_CANVAS} pixels a side or {MAX_CANVAS_PIXELS:,} in all: lower "
                         f"`canvas_margin` or downscale the images")


def _template(gray, H, idx, masks, sizes, *, reference, r_sub, target, margin):
    """The dense step's template: the mean warped image on the canvas, or the reference view.
    Returns ``(Tc, template, template_mask)`` with ``Tc`` the reference-to-canvas offset."""
    if target == "reference":
        return np.eye(3), gray[reference].astype(np.float32), masks[reference]
    wr, hr = sizes[reference]
    canvas, (ox, oy) = margin_canvas((wr, hr), margin)
    tpl, cnt = mean_warped_image([gray[i] for i in idx], H[idx], size=canvas, offset=(ox, oy),
                                 masks=[masks[i] for i in idx], reference=r_sub)
    return translation(ox, oy), np.nan_to_num(tpl), cnt > 0


def _dense_view(i, gray, H, H_sparse, masks, sizes, tpl_data, corr, *, first, target,
                opts: DenseOptions):
    """Masked coarse-to-fine ECC of view ``i`` against the template, with the safeguards:
    returns ``(H_i, record)``; ``record["status"]``: accepted / rejected_sparse / diverged."""
    Tc, tpl, tmask = tpl_data
    Ti, tpl_i, tmask_i = Tc, tpl, tmask
    if target == "mean":
        # ECC costs per template pixel: crop the canvas to the view's footprint (pixels outside
        # it are invalid for this view anyway)
        Ti, tpl_i, tmask_i = _crop_to_footprint(Tc, H[i], sizes[i], tpl, tmask)
    # the first round starts from the sparse estimate (pyramid); later rounds start within a
    # fraction of a pixel and run at full resolution only
    Hi, ok_i = refine_homography_ecc(tpl_i, gray[i], Ti @ H[i], mask=masks[i],
                                     template_mask=tmask_i, levels=opts.levels if first else 1,
                                     max_iter=40 if first else 15, eps=1e-4)
    Hi = np.linalg.inv(Ti) @ Hi
    rec = {"step": float(_corner_change(Hi[None], H[i][None], [sizes[i]])[0])}
    if not (ok_i and np.all(np.isfinite(Hi)) and rec["step"] <= opts.max_step):
        rec["status"] = "diverged"
    elif opts.dense_check:
        # safeguard: the update must stay consistent with the sparse inliers
        rec["sparse_before"] = _sparse_residual(i, H_sparse[i], H_sparse, corr)
        rec["sparse_after"] = _sparse_residual(i, Hi, H, corr)
        if np.isnan(rec["sparse_before"]) or np.isnan(rec["sparse_after"]):
            # no inlier matches to check against (precomputed pairs without `matches`): NaN
            # compared False and every update of such a view was silently rejected
            rec["sparse_check"] = "no inlier matches"
            rec["status"] = "accepted"
        else:
            ok = rec["sparse_after"] <= (1.0 + opts.sparse_tolerance) * rec["sparse_before"]
            rec["status"] = "accepted" if ok else "rejected_sparse"
    else:
        rec["status"] = "accepted"
    return Hi, rec


def _dense_round(gray, H, H_sparse, idx, masks, sizes, pw, corr, *, reference, first, target,
                 robust, opts: DenseOptions):
    """Stage 5b: ECC of every linked view, then re-synchronization of the accepted dense
    estimates together with the sparse pairs. Returns ``(H_new, resync, views, rejected)``."""
    r_sub = int(np.flatnonzero(idx == reference)[0])
    tpl_data = _template(gray, H, idx, masks, sizes, reference=reference, r_sub=r_sub,
                         target=target, margin=opts.canvas_margin)
    H_dense, views, rejected = {}, {}, []
    for i in idx:
        if target == "reference" and i == reference:
            continue
        Hi, rec = _dense_view(i, gray, H, H_sparse, masks, sizes, tpl_data, corr, first=first,
                              target=target, opts=opts)
        views[int(i)] = rec
        if rec["status"] == "accepted":
            H_dense[i] = Hi
        else:
            rejected.append(int(i))
    H_new, rs = _resynchronize(H, H_dense, pw, idx, reference, sizes, target, robust=robust,
                               dense_weight=opts.dense_weight)
    return H_new, rs, views, rejected


# ------------------------------------------------------------------------------------ driver
def _dense_options(dense, options) -> tuple[bool, DenseOptions]:
    unknown = sorted(set(options) - set(_DENSE_FIELDS))
    if unknown:
        raise TypeError(f"estimate_plane_homographies() got unexpected keyword arguments "
                        f"{unknown}; dense options accepted as keywords: {list(_DENSE_FIELDS)}")
    if isinstance(dense, DenseOptions):
        return True, dataclasses.replace(dense, **options)
    return check_bool(dense, "dense"), DenseOptions(**options)


def _check_pairwise_homographies(pw: PairwiseHomographies, n: int) -> PairwiseHomographies:
    """A hand-made (or loaded) ``PairwiseHomographies`` checked field by field, as ``pairs.*``:
    the arrays of the shapes the pipeline reads, a symmetric mask with an empty diagonal,
    finite invertible homographies and finite non-negative weights where the mask is set,
    matches as a dict. Returns a copy with the arrays in their dtypes."""
    H = check_array(pw.H, "pairs.H", ndim=4, finite=False)
    if H.shape != (n, n, 3, 3):
        raise ValueError(f"`pairs.H` must have shape ({n}, {n}, 3, 3) for the {n} images, got "
                         f"{H.shape}")
    mask = check_array(pw.mask, "pairs.mask", ndim=2, dtype=bool)
    if mask.shape != (n, n) or (mask != mask.T).any() or mask.diagonal().any():
        raise ValueError(f"`pairs.mask` must be a symmetric ({n}, {n}) boolean array with a "
                         f"False diagonal, got shape {mask.shape}")
    weights = check_array(pw.weights, "pairs.weights", ndim=2, finite=False)
    if weights.shape != (n, n):
        raise ValueError(f"`pairs.weights` must have shape ({n}, {n}), got {weights.shape}")
    w = weights[mask]
    if not (np.isfinite(w).all() and (w >= 0).all() and w.max(initial=0.0) <= MAX_PAIR_WEIGHT):
        raise ValueError(f"`pairs.weights` must be finite, in [0, {MAX_PAIR_WEIGHT:g}] "
                         f"(inlier counts) where `pairs.mask` is set, got {w.min():.3g} .. "
                         f"{w.max():.3g}")
    idx = np.argwhere(mask)
    finite = np.isfinite(H[mask]).all(axis=(1, 2))
    ok = finite.copy()
    ok[finite] = invertible_homographies(H[mask][finite])
    if not ok.all():
        i, j = idx[np.flatnonzero(~ok)[0]]
        what = "a singular matrix" if finite[np.flatnonzero(~ok)[0]] else "NaN or inf entries"
        raise ValueError(f"`pairs.H[{i}, {j}]` must be a finite invertible homography where "
                         f"`pairs.mask` is set, got {what}")
    if not isinstance(pw.matches, dict):
        raise TypeError(f"`pairs.matches` must be a dict {{(i, j): (pts_i, pts_j, inliers)}}, "
                        f"got {type(pw.matches).__name__}")
    matches = {}
    for key, value in pw.matches.items():
        where = f"pairs.matches[{key!r}]"
        if (not isinstance(key, tuple) or len(key) != 2
                or not all(isinstance(k, (int, np.integer)) and 0 <= k < n for k in key)):
            raise ValueError(f"`pairs.matches` keys must be pairs (i, j) of view indices in "
                             f"[0, {n}), got {key!r}")
        if not isinstance(value, (tuple, list)) or len(value) != 3:
            raise TypeError(f"`{where}` must be (pts_i, pts_j, inliers), got "
                            f"{type(value).__name__}")
        a = check_array(value[0], f"{where}[0]", ndim=2)
        b = check_array(value[1], f"{where}[1]", ndim=2)
        inl = check_array(value[2], f"{where}[2]", ndim=1, dtype=bool)
        if a.shape[1:] != (2,) or b.shape != a.shape or inl.shape != a.shape[:1]:
            raise ValueError(f"`{where}` must hold two (m, 2) point arrays and m inlier flags, "
                             f"got shapes {a.shape}, {b.shape}, {inl.shape}")
        matches[(int(key[0]), int(key[1]))] = (a, b, inl)
    failed = [] if pw.failed is None else list(pw.failed)
    info = {} if pw.info is None else dict(pw.info)
    return dataclasses.replace(pw, H=H, mask=mask, weights=weights, failed=failed,
                               matches=matches, info=info)


def _check_pairs_input(pairs, n):
    if isinstance(pairs, PairwiseHomographies):
        pairs = _check_pairwise_homographies(pairs, n)
    elif isinstance(pairs, str):
        check_choice(pairs, "pairs", ("auto", "all"))
    elif pairs is None or not hasattr(pairs, "__iter__"):
        raise TypeError(f"`pairs` must be 'auto', 'all', a list of (i, j) or a "
                        f"PairwiseHomographies, got {type(pairs).__name__}")
    return pairs


def _require_pairs(pw, n):
    if not np.any(pw.mask):
        kp = pw.info.get("n_keypoints")
        why = "; ".join(f"({i}, {j}): {r}" for i, j, r in pw.failed[:6])
        raise DegenerateInputError(
            f"`images`: no pair of the {n} views could be matched (no homography between any "
            f"two views; keypoints per view: {kp}; failed pairs: {why or 'none'}). The images "
            "must show a common textured plane.")


def _log_round(it, change, seconds):
    logger.info("round %d: max corner change %.4f px (%.1f s)", it, change, seconds)


def estimate_plane_homographies(images, *, reference=0, dense=True, segment=True,
                                pairs="auto", n_neighbors=3, method="ransac", threshold=3.0,
                                n_features=2000, robust=True, rectify=True, rng=None,
                                callback=None, verbose=False,
                                **dense_options) -> PlaneAlignmentResult:
    """Homographies of the dominant plane across views, with plane masks.

    Stages: SIFT features; sparse pairwise homographies (ratio test + RANSAC) along the view
    graph; robust SL(3) synchronization weighted by inlier counts; a second sparse pass between
    the views warped into the reference frame (``rectify``); then rounds of (a) plane
    segmentation from the views warped into the reference and (b) masked coarse-to-fine ECC of
    every view against the mean warped image (or the reference), each update checked against
    the sparse inliers, followed by re-synchronization of the dense and sparse edges; until
    the homographies move less than ``tol`` pixels. Measurements behind the defaults:
    ``docs/homography.md``. Progress is logged to the ``transync.homography`` logger.

    Parameters
    ----------
    images : list of arrays (grey or RGB) or file paths
        At least 2 images, each at least 16 x 16 pixels, finite.
    reference : int, default=0
        The reference view: its homography is the identity.
    dense : bool or DenseOptions, default=True
        Run the dense refinement (with these options).
    segment : bool, default=True
        Segment the plane in every round; with False the masks are all True and the dense
        refinement uses every pixel.
    pairs : "auto", "all", list of (i, j) or PairwiseHomographies, default="auto"
        The view graph, or precomputed pairwise estimates (then no matching is done; their
        fields are checked: shapes, a symmetric mask, finite invertible ``H`` and finite
        weights in [0, 1e12] where the mask is set, ``matches`` a dict). "auto"
        matches all pairs up to ``EXHAUSTIVE_UP_TO = 40`` views and, beyond, every view to the
        reference and to its ``n_neighbors`` nearest views.
    n_neighbors : int, default=3
        Beyond ``EXHAUSTIVE_UP_TO`` views: nearest views each view is matched to.
    method : str, default="ransac"
        Robust estimator of :func:`estimate_pairwise_homographies` (USAC variants allowed).
    threshold : float, default=3.0
        RANSAC reprojection threshold in pixels.
    n_features : int, default=2000
        SIFT features per view.
    robust : bool, default=True
        Robust synchronization (IRLS + rejection).
    rectify : bool, default=True
        Second sparse pass (:func:`estimate_rectified_pairwise`) on the views warped into the
        reference frame with the first synchronized estimate.
    rng : None, int or Generator, default=None
        Every stochastic stage (pairwise RANSAC, rectified RANSAC, segmentation) draws from its
        own child generator; the same seed gives the same result. OpenCV's global random
        state is never used.
    callback : callable, optional
        Called after every round as ``callback(iteration, homographies, masks)``:
        ``homographies`` (N, 3, 3) after the round's update, ``masks`` the plane masks computed
        at the start of the round (copies).
    verbose : bool, default=False
        Show a progress bar (tqdm) over the rounds.
    **dense_options
        Fields of :class:`DenseOptions` (``max_iter``, ``tol``, ``levels``, ``max_step``,
        ``dense_target``, ``dense_weight``, ``canvas_margin``, ``dense_check``,
        ``sparse_tolerance``) override those of ``dense``.

    Returns
    -------
    PlaneAlignmentResult
        Homographies of every view into the reference, plane masks, mean warped image, the
        sparse estimate and per-round diagnostics.

    Raises
    ------
    DegenerateInputError
        When no pair of views can be matched.

    Warns
    -----
    UnlinkedViewsWarning
        When some views cannot be linked to the reference (their homographies are NaN).

    Examples
    --------
    >>> from transync.datasets import make_planar_scene
    >>> from transync.homography import corner_error
    >>> scene = make_planar_scene(4, image_size=(240, 180), difficulty="easy", rng=0)
    >>> res = estimate_plane_homographies(scene.images, n_features=800, max_iter=1, rng=0)
    >>> err = corner_error(res.homographies, scene.homographies, image_size=(240, 180))
    >>> bool(err.max() < 0.5), res.masks[1].shape
    (True, (180, 240))
    """
    t_start = time.perf_counter()
    use_dense, opts = _dense_options(dense, dense_options)
    segment, rectify, robust = (check_bool(v, k) for k, v in
                                (("segment", segment), ("rectify", rectify), ("robust", robust)))
    sparse_kw = {"method": check_choice(method, "method", tuple(_METHODS)),
                 "threshold": check_positive(threshold, "threshold"),
                 "n_features": check_int(n_features, "n_features", minimum=1, maximum=10**6),
                 "n_neighbors": check_int(n_neighbors, "n_neighbors", minimum=1)}
    if callback is not None and not callable(callback):
        raise TypeError(f"`callback` must be callable or None, got {type(callback).__name__}")
    g_pairs, g_rect, g_seg = as_generator(rng).spawn(3)
    imgs = load_images(images)
    n = len(imgs)
    if n < 2:
        raise ValueError(f"`images` must hold at least 2 images, got {n}")
    reference = check_int(reference, "reference", minimum=0, maximum=n - 1)
    pairs = _check_pairs_input(pairs, n)
    gray = [to_gray(im) for im in imgs]
    sizes = [(g.shape[1], g.shape[0]) for g in gray]
    if use_dense or segment:
        _check_canvas(sizes[reference], opts.canvas_margin, reference)
    timing = {}
    pw, sync, maps, corr, sync_rect = _sparse_stage(gray, sizes, pairs, reference=reference,
                                                    robust=robust, rectify=rectify,
                                                    rngs=(g_pairs, g_rect), timing=timing,
                                                    **sparse_kw)
    ok = np.all(np.isfinite(maps), axis=(1, 2))
    if not ok.all():
        warnings.warn(f"views {np.flatnonzero(~ok).tolist()} could not be linked to the "
                      "reference (no chain of matched pairs) and are left out: their "
                      "homographies are NaN", UnlinkedViewsWarning, stacklevel=2)
    target = opts.dense_target
    if target == "auto":
        target = "mean" if n >= 4 else "reference"
    H, masks, state = _refine_rounds(gray, sizes, maps, pw, corr, np.flatnonzero(ok),
                                     reference=reference, dense=use_dense, segment=segment,
                                     target=target, robust=robust, opts=opts, rng=g_seg,
                                     callback=callback, verbose=verbose)
    idx = np.flatnonzero(ok)
    mean, _ = mean_warped_image([gray[i] for i in idx], H[idx], size=sizes[reference],
                                masks=[masks[i] for i in idx],
                                reference=int(np.flatnonzero(idx == reference)[0]))
    timing["total"] = time.perf_counter() - t_start
    return PlaneAlignmentResult(homographies=H, masks=masks, mean_image=mean, reference=reference,
                                sparse_homographies=maps, pairwise=pw, objective=state["change"],
                                n_iter=state["n_iter"], converged=state["converged"],
                                info={"history": state["history"], "seconds": timing,
                                      "sync": sync, "sync_rectified": sync_rect, "options": opts,
                                      "excluded": np.flatnonzero(~ok)})


def _sparse_stage(gray, sizes, pairs, *, reference, robust, rectify, rngs, timing, method,
                  threshold, n_features, n_neighbors):
    """Stages 1-4: features, sparse pairs, synchronization, rectified pass. Returns
    ``(pairwise, sync, maps, correspondences, sync_rectified)``; fills ``timing``."""
    n = len(gray)
    t0 = time.perf_counter()
    precomputed = isinstance(pairs, PairwiseHomographies)
    feats = None if precomputed else _features(gray, n_features)
    timing["features"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    pw = _sparse_pairs(gray, sizes, feats, pairs, reference=reference, n_neighbors=n_neighbors,
                       rng=rngs[0], method=method, threshold=threshold)
    _require_pairs(pw, n)
    timing["matching"] = time.perf_counter() - t0
    logger.info("sparse pairs: %d of %d linked (%.1f s)", int(np.triu(pw.mask, 1).sum()),
                n * (n - 1) // 2, timing["features"] + timing["matching"])
    t0 = time.perf_counter()
    sync = _synchronize(pw, sizes, reference, robust)
    maps, sync_rect = sync.maps.copy(), None
    corr = _sparse_correspondences(pw)
    if rectify and not precomputed:
        rect = _rectified_pass(gray, pw, sync, reference=reference, robust=robust,
                               n_features=n_features, method=method, rng=rngs[1])
        if rect is not None:
            corr = _sparse_correspondences(rect[1], sync.maps, rect[1].info["canvas"][0])
            maps, pw, sync_rect = rect
    timing["sync"] = time.perf_counter() - t0
    return pw, sync, maps, corr, sync_rect


def _refine_rounds(gray, sizes, H_sparse, pw, corr, idx, *, reference, dense, segment, target,
                   robust, opts, rng, callback, verbose):
    """Stage 5: rounds of segmentation and dense refinement of the linked views ``idx``.
    Returns ``(H, masks, state)`` with ``state``: ``history``, ``change``, ``n_iter``,
    ``converged``."""
    r_sub = int(np.flatnonzero(idx == reference)[0])
    H = H_sparse.copy()
    linked = np.zeros(len(gray), bool)
    linked[idx] = True
    # a view that could not be registered has no plane region (its homography is NaN)
    masks = [np.full(g.shape, bool(linked[i])) for i, g in enumerate(gray)]
    history = []
    converged, change, it = True, 0.0, 0
    rounds = range(1, (opts.max_iter if (dense or segment) else 0) + 1)
    if verbose:
        from tqdm.auto import tqdm

        rounds = tqdm(rounds, desc="dense rounds", leave=False)
    for it in rounds:
        t0 = time.perf_counter()
        mask_change = 0.0
        if segment:
            mask_change = _segment_round(gray, H, idx, masks, r_sub=r_sub,
                                         margin=opts.canvas_margin, rng=rng)
        t_seg = time.perf_counter() - t0
        t0 = time.perf_counter()
        H_new, rejected, views = H.copy(), [], {}
        if dense:
            H_new, _, views, rejected = _dense_round(
                gray, H, H_sparse, idx, masks, sizes, pw, corr, reference=reference,
                first=it == 1, target=target, robust=robust, opts=opts)
        t_dense = time.perf_counter() - t0
        change = float(_corner_change(H_new[idx], H[idx], [sizes[i] for i in idx]).max())
        history.append({"iteration": it, "max_corner_change": change, "seconds_segment": t_seg,
                        "seconds_dense": t_dense, "rejected_dense": rejected, "dense_views": views,
                        "plane_fraction": float(np.mean([masks[i].mean() for i in idx])),
                        "mask_change": mask_change})
        _log_round(it, change, t_seg + t_dense)
        H = H_new
        if callback is not None:
            callback(it, H.copy(), [m.copy() for m in masks])
        if not dense or change < opts.tol:
            break
    else:
        converged = not dense or change < opts.tol
    if dense and segment and change > 0.1:
        # masks of the last round were computed before its (sub-pixel) update; redo them only
        # when the homographies still moved noticeably
        _segment_round(gray, H, idx, masks, r_sub=r_sub, margin=opts.canvas_margin, rng=rng)
    return H, masks, {"history": history, "change": change, "n_iter": it,
                      "converged": converged}
