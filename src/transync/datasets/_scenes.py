"""Rendered multi-view scenes of a textured plane with parallax clutter, with ground truth.

World frame: the dominant plane is ``z = 0``; cameras sit above it (``z > 0``) and look at it. The
plane texture is a mosaic of distinct, never repeated crops of images shipped with scikit-image (no
downloads), blended with smooth windows, plus fine unique noise. Clutter objects are textured
rectangles floating parallel to the plane at heights ``h > 0``; each is rendered through its own
induced homography, so it moves with parallax relative to the plane and breaks the plane homography
where it occludes the plane.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import (as_generator, check_choice, check_image_size, check_int,
                           check_positive, check_probability)
from ..geometry import image_corners, normalize_determinant

__all__ = ["PlanarScene", "make_planar_scene"]

# grey-level images shipped inside scikit-image (no downloads); regular or repeated content
# (brick, text, page, checkerboard) is left out on purpose
_SOURCES = ("astronaut", "camera", "chelsea", "coffee", "coins", "grass", "gravel",
            "hubble_deep_field", "immunohistochemistry", "moon", "rocket", "retina", "cell",
            "clock")
_PRESETS = {
    "easy": {"max_angle": 15.0, "clutter": 0.0},
    "moderate": {"max_angle": 25.0, "clutter": 0.20},
    "hard": {"max_angle": 45.0, "clutter": 0.33},
}


@dataclass(frozen=True)
class PlanarScene:
    """N views of a textured plane with clutter.

    Attributes
    ----------
    images : list of ndarray (height, width), uint8
        The rendered grey-level views.
    homographies : ndarray (N, 3, 3)
        ``homographies[i]`` maps pixel coordinates of view ``i`` into the reference view
        (ground truth, determinant 1).
    masks : ndarray (N, height, width), bool
        True where view ``i`` sees the plane (not occluded by clutter).
    reference : int
    image_size : (width, height)
    clean_images : list of ndarray
        The views without photometric noise.
    info : dict
        Cameras ``K``, ``R``, ``C``, clutter list, ``clutter_fraction`` per view, preset values.

    Examples
    --------
    >>> from transync.datasets import make_planar_scene
    >>> scene = make_planar_scene(3, image_size=(160, 120), difficulty="easy", rng=0)
    >>> len(scene.images), scene.homographies.shape, scene.masks[0].shape
    (3, (3, 3, 3), (120, 160))
    """

    images: list
    homographies: np.ndarray
    masks: np.ndarray
    reference: int
    image_size: tuple
    clean_images: list = field(repr=False, default_factory=list)
    info: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def n_views(self) -> int:
        return len(self.images)


@functools.lru_cache(maxsize=None)
def _source(name: str) -> np.ndarray:
    import cv2

    import skimage.data

    img = getattr(skimage.data, name)()
    if img.ndim == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img[..., :3]), cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(img, dtype=np.float32)


@functools.lru_cache(maxsize=16)
def _patch_pool(size: int) -> tuple:
    """Disjoint ``size`` x ``size`` crops of the scikit-image sources that carry texture.

    Every crop is normalized to mean 128 and standard deviation 45. Crops never overlap, so a
    texture built from distinct crops never shows the same content twice (no false matches).
    """
    import cv2

    out = []
    for name in _SOURCES:
        src = _source(name)
        h, w = src.shape
        for a in range(h // size):
            for b in range(w // size):
                p = src[a * size:(a + 1) * size, b * size:(b + 1) * size]
                sd = float(p.std())
                if sd < 8.0:
                    continue
                p = (p - p.mean()) / sd
                gx = cv2.Sobel(p, cv2.CV_32F, 1, 0)
                gy = cv2.Sobel(p, cv2.CV_32F, 0, 1)
                if float(np.sqrt(gx * gx + gy * gy).mean()) < 0.35:   # smooth: little texture
                    continue
                out.append(np.ascontiguousarray(np.clip(p * 45.0 + 128.0, 0, 255), np.float32))
    return tuple(out)


def _source_patch_size(n_needed: int) -> int:
    """Largest crop size whose pool still holds ``n_needed`` distinct crops (48 at least)."""
    for size in (160, 144, 128, 112, 96, 80, 64, 56, 48):
        if len(_patch_pool(size)) >= n_needed:
            return size
    return 48


class _PatchDealer:
    """Deals distinct source crops in a random order, each with a random rotation by a multiple
    of 90 degrees, mirror and gain; it only cycles (with a new orientation) when the pool runs
    out."""

    def __init__(self, size, rng):
        self.pool = _patch_pool(size)
        self.size = size
        self.order = rng.permutation(len(self.pool))
        self.k = 0
        self.rng = rng

    def next(self, out_size, scale=None):
        """A crop resized to ``out_size``; with ``scale`` (output px per source px), only the
        central part of the crop that gives that magnification is used."""
        import cv2

        p = self.pool[self.order[self.k % len(self.order)]]
        if scale is not None:
            ow, oh = (out_size, out_size) if np.isscalar(out_size) else out_size
            cw = int(np.clip(round(ow / scale), 8, p.shape[1]))
            ch = int(np.clip(round(oh / scale), 8, p.shape[0]))
            y0, x0 = (p.shape[0] - ch) // 2, (p.shape[1] - cw) // 2
            p = p[y0:y0 + ch, x0:x0 + cw]
        cycle = self.k // len(self.order)
        self.k += 1
        p = np.rot90(p, int(self.rng.integers(4)) + cycle)
        if self.rng.random() < 0.5:
            p = p[:, ::-1]
        ow, oh = (out_size, out_size) if np.isscalar(out_size) else out_size
        p = cv2.resize(np.ascontiguousarray(p), (int(ow), int(oh)), interpolation=cv2.INTER_CUBIC)
        gain = self.rng.uniform(0.7, 1.1)
        return (p - 128.0) * gain + 128.0 + self.rng.uniform(-20, 20)


def _noise_patch(size, rng):
    """Multi-scale random texture (unique by construction), mean 128 and deviation 45."""
    import cv2

    p = np.zeros((size, size), np.float32)
    for sigma in (1.0, 2.0, 4.0, 8.0):
        noise = rng.normal(0, 1, (size, size)).astype(np.float32)
        p += cv2.GaussianBlur(noise, (0, 0), sigma) * sigma
    return (p - p.mean()) / (p.std() + 1e-6) * 45.0 + 128.0


def _texture(size_px, cell, visible, near, dealer, rng):
    """Plane texture: one distinct crop per visible cell, blended with overlapping smooth windows
    (no seams, no periodic tiling), plus fine unique noise. ``visible`` and ``near`` are boolean
    cell grids; cells seen only from far (``visible & ~near``) get the crops left over, then
    multi-scale noise once the pool of distinct crops is used up."""
    import cv2

    n = visible.shape[0]
    m = int(round(1.5 * cell))                       # window (patch) size
    pad = m
    acc = np.zeros((n * cell + 2 * pad, n * cell + 2 * pad), np.float32)
    wsum = np.zeros_like(acc)
    x = (np.arange(m) + 0.5) / m
    win = np.sin(np.pi * x) ** 2
    win2 = np.outer(win, win).astype(np.float32) + 1e-4
    cells = list(zip(*np.nonzero(near))) + list(zip(*np.nonzero(visible & ~near)))
    for a, b in cells:
        p = dealer.next(m) if dealer.k < len(dealer.order) - 60 else _noise_patch(m, rng)
        jy, jx = rng.integers(-cell // 6, cell // 6 + 1, size=2)
        y0 = pad + a * cell + cell // 2 - m // 2 + int(jy)
        x0 = pad + b * cell + cell // 2 - m // 2 + int(jx)
        acc[y0:y0 + m, x0:x0 + m] += win2 * p
        wsum[y0:y0 + m, x0:x0 + m] += win2
    out = np.where(wsum > 1e-3, acc / np.maximum(wsum, 1e-6), 128.0)[pad:pad + n * cell,
                                                                       pad:pad + n * cell]
    # unique fine-scale structure: no two places of the plane look alike even at small scales
    noise = cv2.GaussianBlur(rng.normal(0, 14, size=out.shape).astype(np.float32), (0, 0), 1.2)
    out = out[:size_px, :size_px] + noise[:size_px, :size_px]
    return np.clip(out, 0, 255).astype(np.uint8)


def _look_at(C, target, roll):
    f = target - C
    f = f / np.linalg.norm(f)
    up = np.array([0.0, 1.0, 0.0])
    x = np.cross(up, f)
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0])
    x = x / np.linalg.norm(x)
    y = np.cross(f, x)
    R = np.stack([x, y, f])
    c, s = np.cos(roll), np.sin(roll)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return Rz @ R


def _plane_homography(K, R, C, height, S):
    """Homography from plane-texture pixels (via S: texture px -> plane (X, Y, 1)) to image px."""
    t = -R @ C
    M = np.column_stack([R[:, 0], R[:, 1], height * R[:, 2] + t])
    return K @ M @ S


def make_planar_scene(n_views=20, *, image_size=(640, 480), difficulty="moderate", max_angle=None,
                      clutter=None, noise=2.0, reference=0, rng=None) -> PlanarScene:
    """Render ``n_views`` views of a textured plane with parallax clutter and known homographies.

    Parameters
    ----------
    n_views : int, default=20
        Number of views (images).
    image_size : (width, height), default=(640, 480)
        Size of every image in whole pixels, each from 32 to 2**14.
    difficulty : {"easy", "moderate", "hard"}, default="moderate"
        Presets: moderate = views within +-25 degrees of the plane normal and about 20 % of
        the reference view covered by clutter; hard = +-45 degrees and about 33 %; easy =
        +-15 degrees and no clutter.
    max_angle : float, default=None
        Overrides the preset: maximum tilt of the viewing direction from the plane normal, degrees.
    clutter : float, default=None
        Overrides the preset: target fraction of the reference view covered by clutter.
    noise : float, default=2.0
        Standard deviation of the additive Gaussian noise in grey levels (per-view gain/bias
        changes are always applied).
    reference : int, default=0
        The reference view (fronto-parallel camera).
    rng : None, int or Generator
        Source of randomness.

    Returns
    -------
    PlanarScene
        The rendered views, their true homographies into the reference and the true plane
        masks.

    Raises
    ------
    ValueError, TypeError
        No view, a ``reference`` out of range, an image smaller than 32 x 32 pixels, an
        unknown ``difficulty``, angles, clutter or noise out of range.

    Examples
    --------
    >>> scene = make_planar_scene(3, image_size=(160, 120), rng=0)
    >>> scene.images[0].shape, scene.homographies.shape, scene.masks.shape
    ((120, 160), (3, 3, 3), (3, 120, 160))
    >>> bool(np.allclose(scene.homographies[scene.reference], np.eye(3)))
    True
    """
    n = check_int(n_views, "n_views", minimum=1)
    difficulty = check_choice(difficulty, "difficulty", tuple(_PRESETS))
    preset = dict(_PRESETS[difficulty])
    if max_angle is not None:
        preset["max_angle"] = check_positive(max_angle, "max_angle", allow_zero=True)
    if clutter is not None:
        preset["clutter"] = check_probability(clutter, "clutter")
    noise = check_positive(noise, "noise", allow_zero=True)
    reference = check_int(reference, "reference", minimum=0, maximum=n - 1)
    w, h = check_image_size(image_size, "image_size", minimum=32, maximum=2**14)
    rng = as_generator(rng)
    f = 1.1 * w
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
    px_per_unit = f * 0.9          # texture resolution close to the image's at distance 1
    corners = np.column_stack([image_corners((w, h)), np.ones(4)]).T   # homogeneous, (3, 4)
    Rs, Cs, reach = _cameras(n, K, corners, reference, np.deg2rad(preset["max_angle"]), rng)
    extent = 2.0 * reach + 0.2     # the plane texture covers every view
    tex_px = int(extent * px_per_unit)
    s = extent / tex_px
    S = np.array([[s, 0, -extent / 2], [0, s, -extent / 2], [0, 0, 1.0]])
    texture, dealer, cell = _plane_texture(K, Rs, Cs, S, corners, tex_px, px_per_unit, rng)
    Gr = _plane_homography(K, Rs[reference], Cs[reference], 0.0, S)
    patches = _clutter(K, Rs[reference], Cs[reference], Gr, S, (w, h), preset["clutter"],
                       px_per_unit, dealer, cell, rng)
    images, clean, masks, Hs, fractions = _render(texture, patches, K, Rs, Cs, S, Gr, (w, h),
                                                  noise, rng)
    return PlanarScene(images=images, homographies=np.stack(Hs), masks=np.stack(masks),
                       reference=reference, image_size=(w, h), clean_images=clean,
                       info={"K": K, "R": np.stack(Rs), "C": np.stack(Cs),
                             "n_clutter": len(patches), "clutter_fraction": np.array(fractions),
                             "difficulty": difficulty, **preset})


def _cameras(n, K, corners, reference, max_ang, rng):
    """Cameras looking at the plane: the reference fronto-parallel at distance 1, the others
    tilted by up to ``max_ang``; returns ``(Rs, Cs, reach)`` with ``reach`` the largest plane
    coordinate any view sees."""
    Rs, Cs = [], []
    reach = 0.0
    for i in range(n):
        for _attempt in range(200):
            if i == reference:
                theta, phi, roll, dist = 0.0, 0.0, 0.0, 1.0
                target = np.zeros(3)
            else:
                theta = max_ang * np.sqrt(rng.uniform(0.1, 1.0))
                phi = rng.uniform(0, 2 * np.pi)
                roll = np.deg2rad(rng.uniform(-15, 15))
                target = np.array([*rng.uniform(-0.08, 0.08, size=2), 0.0])
                dist = rng.uniform(0.9, 1.1)
            C = target + dist * np.array([np.sin(theta) * np.cos(phi),
                                          np.sin(theta) * np.sin(phi), np.cos(theta)])
            R = _look_at(C, target, roll)
            G = _plane_homography(K, R, C, 0.0, np.eye(3))   # plane (X, Y, 1) -> pixels
            foot = np.linalg.solve(G, corners)
            if np.all(foot[2] * np.sign(foot[2, 0]) > 0):
                r_i = float(np.abs(foot[:2] / foot[2]).max())
                # keep the texture below OpenCV's remap limit (32767 px)
                if r_i < 3.0:
                    break
        else:
            raise ValueError("`max_angle` too large: no camera sees a bounded part of the plane")
        reach = max(reach, r_i)
        Rs.append(R)
        Cs.append(C)
    return Rs, Cs, reach


def _plane_texture(K, Rs, Cs, S, corners, tex_px, px_per_unit, rng):
    """The plane texture: only the cells that some view sees get content (fewer cells, so the
    pool of distinct source crops stays large enough for crops never to repeat). Returns
    ``(texture, dealer, cell)``; the dealer goes on dealing crops to the clutter."""
    import cv2

    cell = max(48, int(0.16 * px_per_unit))
    n_cells = int(np.ceil(tex_px / cell))
    visible = np.zeros((n_cells, n_cells), np.uint8)
    mag = np.zeros((n_cells, n_cells))        # largest image px per texture px over the views
    cc = (np.stack(np.meshgrid(np.arange(n_cells), np.arange(n_cells)), -1).reshape(-1, 2) + 0.5)
    cc = np.column_stack([cc * cell, np.ones(len(cc))]).T
    for R, C in zip(Rs, Cs):
        G = _plane_homography(K, R, C, 0.0, S)
        foot = np.linalg.solve(G, corners)
        foot = (foot[:2] / foot[2]).T / cell
        cv2.fillConvexPoly(visible, np.round(foot * 16).astype(np.int32), 1, cv2.LINE_8, 4)
        z = G[2] @ cc                             # |det J| of the plane-to-image map = det G / z^3
        with np.errstate(divide="ignore"):
            m_i = np.sqrt(np.abs(np.linalg.det(G)) / np.abs(z) ** 3)
        mag = np.maximum(mag, np.where(z > 0, m_i, 0.0).reshape(n_cells, n_cells))
    visible = cv2.dilate(visible, np.ones((3, 3), np.uint8)) > 0
    near = visible & (mag >= 0.55)
    dealer = _PatchDealer(_source_patch_size(int(near.sum()) + 60), rng)
    return _texture(tex_px, cell, visible, near, dealer, rng), dealer, cell


def _clutter(K, R, C, Gr, S, size, target, px_per_unit, dealer, cell, rng):
    """Many small floating textured rectangles in front of the plane, placed over the reference
    view until they cover about ``target`` of it (small, so that no single object rivals the
    plane in the number of matches); sorted by height."""
    import cv2

    w, h = size
    patches = []
    covered = np.zeros((h, w), dtype=bool)
    attempts = 0
    while covered.mean() < target and attempts < 400:
        attempts += 1
        ph = rng.uniform(0.06, 0.2)
        size = rng.uniform(0.07, 0.16) * np.array([1.0, rng.uniform(0.6, 1.6)])
        # centre: a random reference pixel back-projected onto the plane
        u = np.array([rng.uniform(0.05, 0.95) * w, rng.uniform(0.05, 0.95) * h, 1.0])
        X = np.linalg.solve(Gr, u)
        X = S @ (X / X[2])
        ptex_px = max(16, int(size.max() * px_per_unit))
        pw, phh = (int(round(ptex_px * size[0] / size.max())),
                   int(round(ptex_px * size[1] / size.max())))
        sp = size.max() / ptex_px
        Sp = np.array([[sp, 0, X[0] - size[0] / 2], [0, sp, X[1] - size[1] / 2], [0, 0, 1.0]])
        Gp = _plane_homography(K, R, C, ph, Sp)
        cov = cv2.warpPerspective(np.ones((phh, pw), np.uint8), Gp, (w, h),
                                  flags=cv2.INTER_NEAREST) > 0
        gain = (cov & ~covered).mean()
        if gain < 0.002 or covered.mean() + gain > target + 0.02:
            continue
        covered |= cov
        # same magnification of the source as the plane texture: clutter is not sharper
        ptex = np.clip(dealer.next((pw, phh), scale=1.5 * cell / dealer.size), 0, 255)
        ptex = ptex.astype(np.float32)
        patches.append({"height": ph, "S": Sp, "texture": ptex})
    patches.sort(key=lambda p: p["height"])
    return patches


def _render(texture, patches, K, Rs, Cs, S, Gr, size, noise, rng):
    """Every view: the plane, then the clutter over it (far to near), gain, bias and noise.
    Returns ``(images, clean, masks, homographies, clutter_fractions)``."""
    import cv2

    w, h = size
    images, clean, masks, Hs, fractions = [], [], [], [], []
    for R, C in zip(Rs, Cs):
        G = _plane_homography(K, R, C, 0.0, S)
        img = cv2.warpPerspective(texture, G, (w, h), flags=cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_REFLECT).astype(np.float32)
        plane = np.ones((h, w), dtype=bool)
        for p in patches:
            Gp = _plane_homography(K, R, C, p["height"], p["S"])
            pt = p["texture"]
            warped = cv2.warpPerspective(pt, Gp, (w, h), flags=cv2.INTER_LINEAR)
            alpha = cv2.warpPerspective(np.ones(pt.shape, np.float32), Gp, (w, h),
                                        flags=cv2.INTER_LINEAR)
            img = img * (1 - alpha) + warped * alpha
            plane &= alpha < 0.5
        clean.append(np.clip(img, 0, 255).astype(np.uint8))
        gain = rng.uniform(0.85, 1.15)
        bias = rng.uniform(-12, 12)
        noisy = (img * gain + bias + rng.normal(0, noise, size=img.shape) if noise
                 else img * gain + bias)
        images.append(np.clip(np.round(noisy), 0, 255).astype(np.uint8))
        masks.append(plane)
        Hs.append(normalize_determinant(Gr @ np.linalg.inv(G)))
        fractions.append(1.0 - plane.mean())
    return images, clean, masks, Hs, fractions
