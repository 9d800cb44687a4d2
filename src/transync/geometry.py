"""Plane geometry shared by every layer: determinant normalization, image corners, point
transfer and Hartley normalization.

Homographies are ``(3, 3)`` float arrays (stacks ``(..., 3, 3)``) acting on column vectors of
homogeneous pixel coordinates ``(x, y, 1)``, with ``x`` the column and ``y`` the row.

Examples
--------
>>> import numpy as np
>>> from transync.geometry import image_corners, normalize_determinant, transfer_points
>>> H = normalize_determinant(2.0 * np.eye(3))
>>> bool(np.allclose(H, np.eye(3)))
True
>>> image_corners((640, 480))
array([[  0.,   0.],
       [639.,   0.],
       [639., 479.],
       [  0., 479.]])
>>> T = np.array([[1.0, 0, 5], [0, 1, -2], [0, 0, 1]])
>>> transfer_points(T, [[0.0, 0.0], [1.0, 1.0]])
array([[ 5., -2.],
       [ 6., -1.]])
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "image_corners",
    "normalization_matrix",
    "normalize_determinant",
    "transfer_points",
]


def normalize_determinant(A) -> np.ndarray:
    """Scale square matrices to determinant +1 (real d-th root); works on stacks ``(..., d, d)``.

    For odd ``d`` a negative determinant is fixed by a negative scale (the projective class is
    unchanged). Singular matrices give NaN, so that a missing map stays visibly missing.

    Parameters
    ----------
    A : array_like of shape (..., d, d)

    Returns
    -------
    ndarray of shape (..., d, d)

    Examples
    --------
    >>> import numpy as np
    >>> H = normalize_determinant(-8.0 * np.eye(3))
    >>> bool(np.allclose(H, np.eye(3)))
    True
    """
    A = np.asarray(A, dtype=float)
    d = A.shape[-1]
    with np.errstate(divide="ignore", invalid="ignore"):   # NaN maps (disconnected) stay NaN
        det = np.linalg.det(A)
        if d % 2:
            scale = np.sign(det) * np.abs(det) ** (1.0 / d)
        else:
            scale = np.abs(det) ** (1.0 / d)
        scale = np.where(det == 0, np.nan, scale)
        return A / scale[..., None, None]


def image_corners(size) -> np.ndarray:
    """The four pixel corners of a ``(width, height)`` image, clockwise from the origin.

    Parameters
    ----------
    size : (width, height)

    Returns
    -------
    ndarray of shape (4, 2)
        ``(0, 0), (w-1, 0), (w-1, h-1), (0, h-1)`` as ``(x, y)`` rows.

    Examples
    --------
    >>> image_corners((3, 2)).tolist()
    [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]
    """
    w, h = float(size[0]), float(size[1])
    return np.array([[0.0, 0.0], [w - 1, 0.0], [w - 1, h - 1], [0.0, h - 1]])


def transfer_points(H, points) -> np.ndarray:
    """Map 2-D points through homographies: ``x' ~ H [x, 1]``, then dehomogenize.

    Parameters
    ----------
    H : array_like of shape (..., 3, 3)
    points : array_like of shape (k, 2) or (..., k, 2)
        Broadcast against the leading dimensions of ``H``.

    Returns
    -------
    ndarray of shape (..., k, 2)
        Points at infinity come back as ``inf``/``nan``; callers decide what that means.

    Examples
    --------
    >>> import numpy as np
    >>> H = np.stack([np.eye(3), np.diag([2.0, 2.0, 1.0])])
    >>> transfer_points(H, [[1.0, 1.0]]).tolist()
    [[[1.0, 1.0]], [[2.0, 2.0]]]
    """
    H = np.asarray(H, dtype=float)
    pts = np.asarray(points, dtype=float)
    p = pts @ H[..., :2, :2].swapaxes(-1, -2) + H[..., None, :2, 2]
    z = pts @ H[..., 2, :2][..., :, None] + H[..., 2, 2][..., None, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        return p / z


def normalization_matrix(image_size) -> np.ndarray:
    """Hartley-style similarity taking pixel coordinates of a ``(width, height)`` image to ~[-1, 1].

    Parameters
    ----------
    image_size : (width, height)

    Returns
    -------
    ndarray of shape (3, 3)

    Examples
    --------
    >>> normalization_matrix((640, 480)) @ [320, 240, 1]
    array([0., 0., 1.])
    """
    w, h = (float(v) for v in image_size)
    s = 2.0 / max(w, h)
    return np.array([[s, 0.0, -s * w / 2], [0.0, s, -s * h / 2], [0.0, 0.0, 1.0]])
