"""Noisy collections of pairwise transformations with outlier pairs, and their ground truth.

Convention: ``truth[i]`` maps coordinates of object ``i`` into the reference object 0, and the
observation ``observed[i, j]`` is a noisy ``inv(truth[i]) @ truth[j]`` (object ``j`` into ``i``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import (as_generator, check_choice, check_image_size, check_int,
                           check_positive, check_probability, int_magnitude, short_repr)
from ..geometry import image_corners, normalize_determinant, transfer_points
from ._graphs import _MAX_ENTRIES, check_deformation

__all__ = ["TransformProblem", "make_noisy_homographies", "make_noisy_linear_maps"]


@dataclass(frozen=True)
class TransformProblem:
    """Observed pairwise maps with ground truth.

    Attributes
    ----------
    observed : ndarray (N, N, d, d)
        ``observed[i, j]`` maps object ``j`` into object ``i`` (NaN where not observed).
    mask : ndarray (N, N), bool
        Observed pairs (symmetric, False on the diagonal).
    truth : ndarray (N, d, d)
        ``truth[i]`` maps object ``i`` into the reference (``truth[0] = I``).
    outliers : ndarray (N, N), bool
        Pairs replaced by a gross outlier.
    image_size : tuple or None
        ``(width, height)`` for homography problems.
    info : dict

    Examples
    --------
    >>> from transync.datasets import make_noisy_linear_maps
    >>> prob = make_noisy_linear_maps(n_objects=4, noise=0.0, rng=0)
    >>> prob.observed.shape, bool(prob.mask[0, 1])
    ((4, 4, 3, 3), True)
    """

    observed: np.ndarray
    mask: np.ndarray
    truth: np.ndarray
    outliers: np.ndarray
    image_size: tuple | None = None
    info: dict[str, Any] = field(default_factory=dict)

    def true_pairwise(self) -> np.ndarray:
        """Ground-truth pairwise maps ``inv(truth[i]) @ truth[j]`` as (N, N, d, d)."""
        return np.einsum("iab,jbc->ijac", np.linalg.inv(self.truth), self.truth)


def _check_size(n: int, d: int, given: str) -> None:
    """Refuse problems whose (N, N, d, d) observations would not fit (``given``: the arguments
    as the user gave them, for the message)."""
    if n * n * d * d > _MAX_ENTRIES:
        raise ValueError(f"{given} would need about 10^{int_magnitude(n * n * d * d)} observed "
                         f"entries (N * N * d * d, more than {_MAX_ENTRIES:.0e}); use a smaller "
                         "problem")


def _observation_graph(n, density, rng):
    """Symmetric boolean mask with the given edge density, always connected (random path added)."""
    upper = np.triu(rng.random((n, n)) < density, 1)
    order = rng.permutation(n)
    upper[np.minimum(order[:-1], order[1:]), np.maximum(order[:-1], order[1:])] = True
    return upper | upper.T


def _random_group_element(d, group, rng, spread=1.0):
    if group == "SO":
        q, r = np.linalg.qr(rng.normal(size=(d, d)))
        q = q * np.sign(np.diag(r))
        if np.linalg.det(q) < 0:
            q[:, 0] *= -1
        return q
    A = np.eye(d) + spread * rng.normal(size=(d, d)) / np.sqrt(d)
    while abs(np.linalg.det(A)) < 0.1:
        A = np.eye(d) + spread * rng.normal(size=(d, d)) / np.sqrt(d)
    if group == "SL":
        if np.linalg.det(A) < 0:
            A[:, 0] *= -1
        A = normalize_determinant(A)
    return A


def make_noisy_linear_maps(n_objects=10, dim=3, *, group="GL", noise=0.05, outlier_fraction=0.0,
                           density=1.0, rng=None) -> TransformProblem:
    """Random invertible maps with noisy, partly missing and partly corrupted pairwise observations.

    ``observed[i, j] = inv(M_i) @ M_j @ (I + noise * G)`` (projected back to the group), with
    ``G`` standard normal; a fraction ``outlier_fraction`` of the observed pairs is replaced by a
    random group element.

    Parameters
    ----------
    n_objects : int, default=10
        Number of objects ``N``.
    dim : int, default=3
        Dimension ``d`` of the maps.
    group : {"GL", "SL", "SO"}, default="GL"
        Group the true maps are drawn from.
    noise : float, default=0.05
        Standard deviation of the Gaussian noise added to every observed map.
    outlier_fraction : float, default=0.0
        Fraction of observed pairs replaced by random maps.
    density : float, default=1.0
        Probability that a pair is observed (a random spanning path is always observed).
    rng : None, int or Generator
        Source of randomness.

    Returns
    -------
    TransformProblem
        The noisy pairwise maps, the observation mask and the true absolute maps.

    Examples
    --------
    >>> prob = make_noisy_linear_maps(5, 3, group="SO", noise=0.0, rng=0)
    >>> import numpy as np
    >>> bool(np.allclose(prob.observed[1, 2], prob.true_pairwise()[1, 2]))
    True
    """
    n = check_int(n_objects, "n_objects", minimum=2)
    d = check_int(dim, "dim", minimum=1)
    _check_size(n, d, f"`n_objects`={short_repr(n, 30)} and `dim`={short_repr(d, 30)}")
    group = check_choice(group, "group", ("GL", "SL", "SO"))
    noise = check_deformation(noise, "noise")
    outlier_fraction = check_probability(outlier_fraction, "outlier_fraction")
    density = check_probability(density, "density")
    rng = as_generator(rng)
    truth = np.stack([np.eye(d)] + [_random_group_element(d, group, rng, spread=0.5)
                                    for _ in range(n - 1)])
    mask = _observation_graph(n, density, rng)
    outliers = _pick_outlier_pairs(mask, outlier_fraction, rng)
    pairs = np.argwhere(np.triu(mask, 1))
    observed = np.full((n, n, d, d), np.nan)
    inv = np.linalg.inv(truth)
    for i, j in pairs:
        if outliers[i, j]:
            Tij = _random_group_element(d, group, rng, spread=1.5)
        else:
            Tij = inv[i] @ truth[j] @ (np.eye(d) + noise * rng.normal(size=(d, d)))
            if group == "SO":
                u, _, vt = np.linalg.svd(Tij)
                Tij = u @ np.diag([1.0] * (d - 1) + [np.linalg.det(u @ vt)]) @ vt
            elif group == "SL":
                Tij = normalize_determinant(Tij)
        observed[i, j] = Tij
        observed[j, i] = np.linalg.inv(Tij)
    return TransformProblem(observed=observed, mask=mask, truth=truth, outliers=outliers,
                            info={"group": group, "noise": noise})


def _homography_from_points(src, dst):
    """Exact 4-point homography (DLT via a linear solve), src/dst (4, 2)."""
    A = []
    b = []
    for (x, y), (u, v) in zip(src, dst):
        A.append([x, y, 1, 0, 0, 0, -u * x, -u * y])
        A.append([0, 0, 0, x, y, 1, -v * x, -v * y])
        b.extend([u, v])
    h = np.linalg.solve(np.array(A), np.array(b))
    return np.append(h, 1.0).reshape(3, 3)


def random_view_homography(image_size, rng, *, max_angle=25.0, scale_range=(0.85, 1.15),
                           shift=0.08, perspective=0.08):
    """A homography taking pixels of a random view into the reference view (``image_size``).

    The reference corners are rotated by up to ``max_angle`` degrees, scaled, shifted, and each
    corner is moved by up to ``perspective`` times the image size; the homography maps the view's
    corners to these points.
    """
    w, h = image_size
    c = image_corners((w, h))
    center = np.array([(w - 1) / 2, (h - 1) / 2])
    ang = np.deg2rad(rng.uniform(-max_angle, max_angle))
    s = rng.uniform(*scale_range)
    R = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    dst = (c - center) @ R.T * s + center
    dst = dst + rng.uniform(-shift, shift, size=2) * [w, h]
    dst = dst + rng.uniform(-perspective, perspective, size=(4, 2)) * [w, h]
    return _homography_from_points(c, dst)


def make_noisy_homographies(n_views=10, *, image_size=(640, 480), noise=0.5, outlier_fraction=0.0,
                            density=1.0, max_angle=25.0, rng=None) -> TransformProblem:
    """Pairwise plane homographies between ``n_views`` views, with corner noise and outlier pairs.

    ``truth[i]`` maps pixels of view ``i`` into view 0. For every observed pair the corners of
    view ``j`` are mapped into view ``i`` by the true homography, perturbed by Gaussian noise
    of ``noise`` pixels per coordinate, and the homography is refitted (4-point DLT); outlier
    pairs get corners displaced by 40–150 px instead.

    Parameters
    ----------
    n_views : int, default=10
        Number of views ``N``.
    image_size : (width, height), default=(640, 480)
        Image size in whole pixels, each from 2 to 2**20 (the corners define the noise and the
        errors).
    noise : float, default=0.5
        Pixel noise on the transferred corners.
    outlier_fraction : float, default=0.0
        Fraction of observed pairs replaced by gross outliers.
    density : float, default=1.0
        Probability that a pair is observed (the graph is always connected).
    max_angle : float, default=25.0
        In-plane rotation range of the views, degrees.
    rng : None, int or Generator
        Source of randomness.

    Returns
    -------
    TransformProblem
        ``observed[i, j]`` maps pixels of view ``j`` into view ``i``, normalized to H[2, 2] = 1.

    Examples
    --------
    >>> prob = make_noisy_homographies(4, noise=0.0, rng=0)
    >>> import numpy as np
    >>> Hp = prob.true_pairwise()[2, 3]
    >>> bool(np.allclose(prob.observed[2, 3] / prob.observed[2, 3][2, 2], Hp / Hp[2, 2]))
    True
    """
    n = check_int(n_views, "n_views", minimum=2)
    _check_size(n, 3, f"`n_views`={short_repr(n, 30)} (3 x 3 homographies)")
    w, h = check_image_size(image_size, "image_size", minimum=2, maximum=2**20)
    max_angle = check_positive(max_angle, "max_angle", allow_zero=True)
    noise = check_deformation(noise, "noise")
    outlier_fraction = check_probability(outlier_fraction, "outlier_fraction")
    density = check_probability(density, "density")
    rng = as_generator(rng)
    truth = np.stack([np.eye(3)] + [random_view_homography((w, h), rng, max_angle=max_angle)
                                    for _ in range(n - 1)])
    mask = _observation_graph(n, density, rng)
    outliers = _pick_outlier_pairs(mask, outlier_fraction, rng)
    pairs = np.argwhere(np.triu(mask, 1))
    inv = np.linalg.inv(truth)
    c = image_corners((w, h))
    observed = np.full((n, n, 3, 3), np.nan)
    for i, j in pairs:
        Tij = inv[i] @ truth[j]
        dst = transfer_points(Tij, c)
        if outliers[i, j]:
            mag = rng.uniform(40, 150, size=(4, 1))
            ang = rng.uniform(0, 2 * np.pi, size=(4, 1))
            dst = dst + mag * np.hstack([np.cos(ang), np.sin(ang)])
        else:
            dst = dst + noise * rng.normal(size=dst.shape)
        Hij = _homography_from_points(c, dst)
        observed[i, j] = Hij
        Hji = np.linalg.inv(Hij)
        observed[j, i] = Hji / Hji[2, 2]
    return TransformProblem(observed=observed, mask=mask, truth=truth, outliers=outliers,
                            image_size=(w, h), info={"noise": noise, "max_angle": max_angle})


def _pick_outlier_pairs(mask: np.ndarray, fraction: float, rng) -> np.ndarray:
    """Symmetric mask of ``round(fraction * #observed pairs)`` observed pairs drawn at random."""
    n = mask.shape[0]
    pairs = np.argwhere(np.triu(mask, 1))
    n_out = int(round(fraction * len(pairs)))
    out_idx = rng.choice(len(pairs), size=n_out, replace=False)
    outliers = np.zeros((n, n), dtype=bool)
    outliers[pairs[out_idx, 0], pairs[out_idx, 1]] = True
    return outliers | outliers.T
