"""Plane geometry (transync.geometry): round trips and invariances."""

import numpy as np
import pytest

from transync.geometry import (
    hartley_normalization,
    image_corners,
    normalization_matrix,
    normalize_determinant,
    transfer_points,
    translation,
)


def _random_homographies(rng, k):
    H = np.eye(3) + 0.1 * rng.normal(size=(k, 3, 3))
    H[:, 2, :2] *= 1e-3
    return H


def test_normalize_determinant_projective_class_and_unit_det():
    rng = np.random.default_rng(0)
    H = _random_homographies(rng, 5)
    scales = rng.uniform(-5, 5, 5)
    N = normalize_determinant(H * scales[:, None, None])
    np.testing.assert_allclose(np.linalg.det(N), 1.0, rtol=1e-12)
    # same projective class: identical point transfer
    pts = rng.uniform(0, 100, (7, 2))
    np.testing.assert_allclose(transfer_points(N, pts), transfer_points(H, pts), rtol=1e-9)
    # idempotent; singular maps stay visibly missing
    np.testing.assert_allclose(normalize_determinant(N), N, rtol=1e-12)
    assert np.isnan(normalize_determinant(np.zeros((3, 3)))).all()


def test_transfer_points_round_trip_and_composition():
    rng = np.random.default_rng(1)
    A, B = _random_homographies(rng, 2)
    pts = rng.uniform(0, 300, (20, 2))
    np.testing.assert_allclose(transfer_points(np.linalg.inv(A), transfer_points(A, pts)), pts,
                               atol=1e-9)
    np.testing.assert_allclose(transfer_points(A @ B, pts),
                               transfer_points(A, transfer_points(B, pts)), atol=1e-9)
    # stacks broadcast against the points
    both = transfer_points(np.stack([A, B]), pts)
    assert both.shape == (2, 20, 2)
    np.testing.assert_allclose(both[1], transfer_points(B, pts))
    with pytest.raises(ValueError, match="`points`.*`H`.*do not broadcast"):
        transfer_points(np.stack([A, B, A]), np.zeros((2, 5, 2)))


def test_transfer_points_ignores_the_scale_of_the_homography():
    """A homography of huge entries (1e308 I) overflowed its products: every point came back
    inf or NaN, and corner_error called it infinitely wrong."""
    rng = np.random.default_rng(3)
    H = np.stack(_random_homographies(rng, 3))
    pts = rng.uniform(0, 500, (6, 2))
    ref = transfer_points(H, pts)
    for power in (-1000, -200, 200, 1000):      # exact powers of two: the same bits
        np.testing.assert_array_equal(transfer_points(np.ldexp(H, power), pts), ref)
    for scale in (1e308, 1e-308):
        np.testing.assert_allclose(transfer_points(H * scale, pts), ref, rtol=1e-12)
    big = transfer_points(np.eye(3) * 1e297, [[1e12, 1e12]])
    np.testing.assert_allclose(big, [[1e12, 1e12]], rtol=1e-12)
    # a homography that is not finite, or all zero, stays visibly missing
    assert not np.isfinite(transfer_points(np.full((3, 3), np.nan), pts)).any()
    assert not np.isfinite(transfer_points(np.zeros((3, 3)), pts)).any()


def test_normalize_determinant_of_huge_entries():
    """A well-conditioned matrix of 1e308 entries overflowed the LU of its determinant: NaN."""
    A = np.array([[1.0, 1, 0], [-1, 1, 0], [0, 0, 1]])
    np.testing.assert_allclose(normalize_determinant(A * 1e308), normalize_determinant(A),
                               rtol=1e-12)
    np.testing.assert_allclose(normalize_determinant(A * 1e-320), normalize_determinant(A),
                               rtol=1e-12)


def test_translation_and_corners():
    T = translation(3, -2)
    np.testing.assert_array_equal(transfer_points(T, image_corners((4, 3))),
                                  [[3, -2], [6, -2], [6, 0], [3, 0]])
    np.testing.assert_array_equal(translation(3, -2) @ translation(-3, 2), np.eye(3))


def test_hartley_normalization_centred_unit_spread_and_invertible():
    rng = np.random.default_rng(2)
    pts = rng.uniform(100, 900, (50, 2)) * [1.0, 0.3]
    T, x = hartley_normalization(pts)
    np.testing.assert_allclose(x.mean(axis=0), 0.0, atol=1e-12)
    assert np.linalg.norm(x, axis=1).mean() == pytest.approx(np.sqrt(2))
    np.testing.assert_allclose(transfer_points(T, pts), x, atol=1e-12)
    np.testing.assert_allclose(transfer_points(np.linalg.inv(T), x), pts, atol=1e-9)
    # invariant to a similarity of the input (translation and scale of the point set)
    _, y = hartley_normalization(3.0 * pts + [5.0, -7.0])
    np.testing.assert_allclose(y, x, atol=1e-9)
    # coincident points: a pure translation
    T1, x1 = hartley_normalization([[2.0, 3.0], [2.0, 3.0]])
    np.testing.assert_array_equal(x1, 0.0)
    np.testing.assert_array_equal(T1[:2, :2], np.eye(2))


@pytest.mark.parametrize("bad, match", [(np.zeros((0, 2)), r"shape \(k, 2\) with k >= 1"),
                                        (np.zeros((3, 3)), r"shape \(k, 2\)"),
                                        ([[np.nan, 0.0]], "finite")])
def test_hartley_normalization_refuses_bad_points(bad, match):
    with pytest.raises(ValueError, match=match):
        hartley_normalization(bad)


def test_normalization_matrix_maps_image_to_unit_box():
    N = normalization_matrix((640, 480))
    c = transfer_points(N, image_corners((640, 480)))
    assert np.abs(c).max() <= 1.0 + 1e-12


def test_hartley_normalization_of_tiny_point_sets():
    # the squared distances of a 1e-165 square underflowed: d = 0, T = identity, unnormalized
    from transync.geometry import hartley_normalization

    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    for scale in (1e-165, 1e-200, 1.0, 1e100):
        _, x = hartley_normalization(square * scale)
        np.testing.assert_allclose(np.hypot(x[:, 0], x[:, 1]).mean(), np.sqrt(2.0), rtol=1e-12)


def test_integers_beyond_float64_are_named():
    """translation(10**400, 0) hit numpy's "ufunc 'isfinite' not supported"; sizes of 2**1100
    a raw OverflowError."""
    from transync.geometry import image_corners, translation

    with pytest.raises(ValueError, match=r"`tx` must be a finite real number"):
        translation(10**400, 0)
    with pytest.raises(ValueError, match=r"`ty` must be a finite real number"):
        translation(0, float("nan"))
    with pytest.raises(ValueError, match=r"`size` must fit in float64"):
        image_corners((2**1100, 3))
    with pytest.raises(TypeError, match=r"`size` must be \(width, height\) in pixels, got "
                                        r"booleans"):
        image_corners((True, True))
    with pytest.raises(ValueError, match=r"`size` must be \(width, height\) of at least one "
                                         r"pixel each, got \(0.5, 3\)"):
        image_corners((0.5, 3))             # gave a corner at x = -0.5
    np.testing.assert_array_equal(translation(2, -1)[:2, 2], [2.0, -1.0])


@pytest.mark.parametrize("n", [2, 3, 7])
def test_hartley_normalization_of_coincident_points_is_a_translation(n):
    # three copies of (0, 0.1): the mean's rounding residue (1e-17) was read as a spread and
    # scaled by 1e17, the points sent to (0, -1.41)
    from transync.geometry import hartley_normalization

    T, x = hartley_normalization([[0.0, 0.1]] * n)
    np.testing.assert_array_equal(T, [[1.0, 0.0, 0.0], [0.0, 1.0, -0.1], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(x, np.zeros((n, 2)))


def test_normalization_matrix_of_a_vanishing_size_is_refused():
    # (1e-310, 1e-310): 2 / 1e-310 overflowed to inf entries, returned silently
    from transync.geometry import normalization_matrix

    with pytest.raises(ValueError, match=r"`image_size` is too small to normalize"):
        normalization_matrix((1e-310, 1e-310))
    assert np.all(np.isfinite(normalization_matrix((1e-300, 1e-300))))
