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

import numbers

import numpy as np

from ._validation import check_array, check_real

__all__ = [
    "hartley_normalization",
    "image_corners",
    "normalization_matrix",
    "normalize_determinant",
    "rescale_homogeneous",
    "transfer_points",
    "translation",
]


def normalize_determinant(A, *, singular_tol: float = 1e-14) -> np.ndarray:
    """Scale square matrices to determinant +1 (real d-th root); works on stacks ``(..., d, d)``.

    For odd ``d`` a negative determinant is fixed by a negative scale (the projective class is
    unchanged); for even ``d`` no real scale can change its sign, and it becomes -1. Singular
    matrices (condition number above 1e14) and matrices with NaN or infinite entries give NaN,
    so that a missing map stays visibly missing.

    Parameters
    ----------
    A : array_like of shape (..., d, d)
        Square matrices (a stack).
    singular_tol : float, default=1e-14
        Matrices whose smallest singular value is at most ``singular_tol`` times their largest
        give NaN. ``0`` skips that test (one SVD per matrix) and leaves only exactly singular
        matrices NaN: for hot loops over matrices known to be well conditioned.

    Returns
    -------
    ndarray of shape (..., d, d)
        The scaled matrices (NaN for singular or non-finite ones).

    Raises
    ------
    ValueError, TypeError
        ``A`` not a stack of square real matrices; ``singular_tol`` outside [0, 1).

    Examples
    --------
    >>> import numpy as np
    >>> H = normalize_determinant(-8.0 * np.eye(3))
    >>> bool(np.allclose(H, np.eye(3)))
    True
    """
    A = _square_stack(A, "A")
    if isinstance(singular_tol, bool) or not isinstance(singular_tol, numbers.Real) or not (
            0 <= singular_tol < 1):
        raise ValueError(f"`singular_tol` must be a real number in [0, 1), got {singular_tol!r}")
    d = A.shape[-1]
    A = rescale_homogeneous(A)        # 1e308 entries overflowed the LU of the determinant
    bad = ~np.isfinite(A).all(axis=(-2, -1))
    with np.errstate(all="ignore"):   # NaN maps (disconnected) stay NaN
        # log-determinant: no overflow for large entries
        sign, logdet = np.linalg.slogdet(np.where(bad[..., None, None], 0.0, A))
        # numerically singular: condition number above 1e14 (an exact zero determinant can
        # come out of floating point as a tiny nonzero one)
        bad = bad | (sign == 0) | ~np.isfinite(logdet)
        if singular_tol > 0:
            A0 = np.where(bad[..., None, None], 0.0, A)
            big = np.abs(A0).max(axis=(-2, -1), keepdims=True)
            sv = np.linalg.svd(A0 / np.where(big > 0, big, 1.0), compute_uv=False)
            bad = bad | (sv[..., -1] <= singular_tol * sv[..., 0])
        scale = np.exp(logdet / d)
        if d % 2:
            scale = sign * scale
        out = A / np.where(bad, 1.0, scale)[..., None, None]
    out[bad] = np.nan
    return out


def image_corners(size) -> np.ndarray:
    """The four pixel corners of a ``(width, height)`` image, clockwise from the origin.

    Parameters
    ----------
    size : (width, height)
        Image size in pixels, each at least 1 (one pixel).

    Returns
    -------
    ndarray of shape (4, 2)
        ``(0, 0), (w-1, 0), (w-1, h-1), (0, h-1)`` as ``(x, y)`` rows.

    Raises
    ------
    ValueError, TypeError
        ``size`` not two finite numbers of at least 1.

    Examples
    --------
    >>> image_corners((3, 2)).tolist()
    [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]
    """
    w, h = _image_size(size, "size")
    if min(w, h) < 1:           # the corners (w - 1, h - 1) would lie left of / above the origin
        raise ValueError(f"`size` must be (width, height) of at least one pixel each, got "
                         f"({w:g}, {h:g})")
    return np.array([[0.0, 0.0], [w - 1, 0.0], [w - 1, h - 1], [0.0, h - 1]])


#: matrices with an entry of magnitude above this (or all entries below its inverse) are
#: rescaled by :func:`rescale_homogeneous`
_SCALE_LIMIT = 2.0 ** 100


def rescale_homogeneous(A) -> np.ndarray:
    """Bring matrices defined up to scale (homographies) of huge or tiny entries to a safe
    scale: largest entry in ``[0.5, 1)``, by a power of two (exact for every entry that stays a
    normal number; an entry more than about 2**1022 times smaller than the largest becomes
    subnormal and keeps fewer digits, or 0).

    Products and inverses of a homography like ``1e308 I`` overflow, and those of ``1e-320 I``
    (subnormal entries) overflow once inverted, though both are the identity map. Matrices whose
    largest entry lies in ``[2**-100, 2**100]`` come back unchanged, bit for bit; so do
    non-finite and all-zero ones.

    Parameters
    ----------
    A : array_like of shape (..., m, n)
        Matrices (a stack).

    Returns
    -------
    ndarray of shape (..., m, n)
        The rescaled matrices (a new array).

    Raises
    ------
    ValueError, TypeError
        ``A`` not an array of real matrices (at least 2 dimensions).

    Examples
    --------
    >>> import numpy as np
    >>> rescale_homogeneous(1e308 * np.eye(2)).max() < 1
    np.True_
    >>> rescale_homogeneous(3.0 * np.eye(2)).tolist()
    [[3.0, 0.0], [0.0, 3.0]]
    """
    A = check_array(A, "A", finite=False)
    if A.ndim < 2:
        raise ValueError(f"`A` must be matrices of shape (..., m, n), got shape {A.shape}")
    with np.errstate(invalid="ignore"):
        top = np.abs(A).max(axis=(-2, -1), initial=0.0)
        far = np.isfinite(top) & (top > 0) & ((top > _SCALE_LIMIT) | (top < 1 / _SCALE_LIMIT))
    if not far.any():
        return A.copy()
    exponent = np.frexp(np.where(far, top, 1.0))[1]
    return np.where(far[..., None, None], np.ldexp(A, -exponent[..., None, None]), A)


def transfer_points(H, points) -> np.ndarray:
    """Map 2-D points through homographies: ``x' ~ H [x, 1]``, then dehomogenize.

    Parameters
    ----------
    H : array_like of shape (..., 3, 3)
        Homographies (a stack).
    points : array_like of shape (k, 2) or (..., k, 2)
        Points ``(x, y)``, broadcast against the leading dimensions of ``H``.

    Returns
    -------
    ndarray of shape (..., k, 2)
        Points at infinity come back as ``inf``/``nan``; callers decide what that means. A
        homography's scale does not matter: one with entries as large as ``1e308`` is brought to
        a safe scale (by a power of two, exactly) before it is applied.

    Raises
    ------
    ValueError, TypeError
        Mis-shaped or non-numeric ``H`` or ``points``.

    Examples
    --------
    >>> import numpy as np
    >>> H = np.stack([np.eye(3), np.diag([2.0, 2.0, 1.0])])
    >>> transfer_points(H, [[1.0, 1.0]]).tolist()
    [[[1.0, 1.0]], [[2.0, 2.0]]]
    """
    H = check_array(H, "H", finite=False)
    if H.ndim < 2 or H.shape[-2:] != (3, 3):
        raise ValueError(f"`H` must have shape (..., 3, 3), got shape {H.shape}")
    pts = check_array(points, "points", finite=False)
    if pts.ndim < 2 or pts.shape[-1] != 2:
        raise ValueError(f"`points` must have shape (k, 2) or (..., k, 2), got shape {pts.shape}")
    try:
        np.broadcast_shapes(pts.shape[:-2], H.shape[:-2])
    except ValueError:
        raise ValueError(f"the leading dimensions of `points` {pts.shape[:-2]} and `H` "
                         f"{H.shape[:-2]} do not broadcast") from None
    H = rescale_homogeneous(H)      # up to scale: 1e308 I would overflow every product
    with np.errstate(all="ignore"):
        p = pts @ H[..., :2, :2].swapaxes(-1, -2) + H[..., None, :2, 2]
        z = pts @ H[..., 2, :2][..., :, None] + H[..., 2, 2][..., None, None]
        return p / z


def normalization_matrix(image_size) -> np.ndarray:
    """Similarity taking pixel coordinates of a ``(width, height)`` image to about [-1, 1].

    Hartley-style: the image centre goes to the origin and the longer side to length 2.

    Parameters
    ----------
    image_size : (width, height)
        Image size in pixels (positive).

    Returns
    -------
    ndarray of shape (3, 3)
        The normalizing similarity.

    Raises
    ------
    ValueError, TypeError
        ``image_size`` not two positive finite numbers.

    Examples
    --------
    >>> normalization_matrix((640, 480)) @ [320, 240, 1]
    array([0., 0., 1.])
    """
    w, h = _image_size(image_size, "image_size")
    with np.errstate(over="ignore"):
        s = 2.0 / max(w, h)
    if not np.isfinite(s):          # (1e-310, 1e-310) gave inf entries
        raise ValueError(f"`image_size` is too small to normalize: 2 / {max(w, h):.3g} "
                         "overflows; give the size in pixels")
    return np.array([[s, 0.0, -s * w / 2], [0.0, s, -s * h / 2], [0.0, 0.0, 1.0]])


def translation(tx, ty) -> np.ndarray:
    """The homography ``[x, y] -> [x + tx, y + ty]`` (e.g. the offset of a canvas origin).

    Parameters
    ----------
    tx, ty : float
        Translation in pixels.

    Returns
    -------
    ndarray of shape (3, 3)
        The translation as a homography.

    Raises
    ------
    TypeError
        ``tx`` or ``ty`` not a finite real number.

    Examples
    --------
    >>> translation(2, -1) @ [1.0, 1.0, 1.0]
    array([3., 0., 1.])
    """
    out = [check_real(tx, "tx"), check_real(ty, "ty")]
    return np.array([[1.0, 0.0, out[0]], [0.0, 1.0, out[1]], [0.0, 0.0, 1.0]])


def hartley_normalization(points) -> tuple[np.ndarray, np.ndarray]:
    """Hartley's isotropic normalization of a 2-D point set.

    The similarity ``T`` moves the centroid to the origin and scales the points to a mean
    distance of ``sqrt(2)`` from it (Hartley, "In defense of the eight-point algorithm", 1997).

    Parameters
    ----------
    points : array_like of shape (k, 2)
        At least one finite point.

    Returns
    -------
    T : ndarray of shape (3, 3)
        The normalizing similarity.
    normalized : ndarray of shape (k, 2)
        ``transfer_points(T, points)``. Coincident points (no spread) get ``T`` a pure translation.

    Raises
    ------
    ValueError
        Mis-shaped, empty or non-finite points, or points whose spread overflows.

    Examples
    --------
    >>> import numpy as np
    >>> T, x = hartley_normalization([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    >>> x.round(6).tolist()
    [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]
    >>> bool(np.allclose(transfer_points(np.linalg.inv(T), x), [[0, 0], [2, 0], [2, 2], [0, 2]]))
    True
    """
    pts = check_array(points, "points", finite=False)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) == 0:
        raise ValueError(f"`points` must have shape (k, 2) with k >= 1, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("`points` must be finite, got NaN or infinite entries")
    with np.errstate(all="ignore"):
        # coincident points: their own position (the mean of three 0.1s is not 0.1, and the
        # residue of 1e-17 read as a spread scaled by 1e17)
        c = pts[0] if np.all(pts == pts[0]) else pts.mean(axis=0)
        dev = pts - c
        d = float(np.hypot(dev[:, 0], dev[:, 1]).mean())   # no underflow of squares at 1e-165
        s = np.sqrt(2.0) / d if d > 0 else 1.0
        T = np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])
        normalized = (pts - c) * s
        spread_ok = s * s > 0
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(normalized)) and spread_ok):
        raise ValueError("`points` cannot be normalized in floating point: their centroid or "
                         "spread is beyond the range a normalization can scale (largest "
                         f"magnitude {np.abs(pts).max():.3g}, mean distance to the centroid "
                         f"{d:.3g})")
    return T, normalized


def _square_stack(A, name: str) -> np.ndarray:
    """A float stack of square matrices ``(..., d, d)`` with ``d >= 1`` (entries may be NaN)."""
    A = check_array(A, name, finite=False)
    if A.ndim < 2 or A.shape[-1] != A.shape[-2] or A.shape[-1] == 0:
        raise ValueError(f"`{name}` must be a square matrix or a stack of them, shape (..., d, d) "
                         f"with d >= 1, got shape {A.shape}")
    return A


def _image_size(size, name: str) -> tuple[float, float]:
    """``(width, height)`` as two finite positive floats."""
    if isinstance(size, (str, bytes)) or size is None:
        raise TypeError(f"`{name}` must be (width, height), got {type(size).__name__} {size!r}")
    if (isinstance(size, (list, tuple)) and any(isinstance(v, (bool, np.bool_)) for v in size)
            or getattr(size, "dtype", None) == bool):
        raise TypeError(f"`{name}` must be (width, height) in pixels, got booleans {size!r}")
    arr = check_array(size, name, finite=False)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)) or not np.all(arr > 0):
        raise ValueError(f"`{name}` must be (width, height) with finite positive entries, "
                         f"got {arr.tolist()!r}")
    return float(arr[0]), float(arr[1])
