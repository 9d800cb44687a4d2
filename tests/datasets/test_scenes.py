"""Rendered planar scenes and the light import of transync.datasets (issue 9)."""

import subprocess
import sys

import numpy as np
import pytest

from transync.datasets import make_planar_scene
from transync.geometry import image_corners, transfer_points


def test_import_datasets_loads_no_heavy_module():
    code = ("import sys, transync.datasets as d; d.make_permutation_collection; "
            "print(sorted(m for m in ('cv2', 'skimage', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_lazy_names_resolve_and_are_listed():
    import transync.datasets as d

    assert {"make_planar_scene", "PlanarScene", "load_graf"} <= set(d.__all__)
    assert {"make_planar_scene", "load_graf"} <= set(dir(d))
    assert d.make_planar_scene is make_planar_scene
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        d.nope


def test_scene_is_repeatable_and_homographies_normalized():
    a = make_planar_scene(3, image_size=(96, 72), difficulty="hard", rng=4)
    b = make_planar_scene(3, image_size=(96, 72), difficulty="hard",
                          rng=np.random.default_rng(4))
    assert all(np.array_equal(x, y) for x, y in zip(a.images, b.images))
    np.testing.assert_allclose(np.linalg.det(a.homographies), 1.0, rtol=1e-12)
    # the reference view's corners stay put; the others land inside a bounded region
    c = transfer_points(a.homographies, image_corners(a.image_size))
    np.testing.assert_allclose(c[a.reference], image_corners(a.image_size), atol=1e-9)
    assert np.all(np.isfinite(c)) and np.abs(c).max() < 10 * 96


@pytest.mark.parametrize("kw, match", [({"image_size": (20, 20)}, r"each in \[32, 16384\]"),
                                       ({"image_size": (np.inf, 64)}, r"each in \[32, 16384\]"),
                                       ({"image_size": (64.5, 64)}, "whole pixels"),
                                       ({"difficulty": "extreme"}, "`difficulty` must be one"),
                                       ({"clutter": 2.0}, r"`clutter` must lie in \[0, 1\]")])
def test_scene_options_checked(kw, match):
    with pytest.raises(ValueError, match=match):
        make_planar_scene(2, **kw)


@pytest.mark.parametrize("generator", ["make_noisy_linear_maps", "make_noisy_homographies"])
def test_noisy_map_generators_refuse_sizes_they_cannot_build(generator):
    """10**20 objects (or dimensions) looped for ever; now refused before any work."""
    from transync import datasets

    make = getattr(datasets, generator)
    with pytest.raises(ValueError, match=r"`n_(objects|views)`=10+.*would need about 10\^41"):
        make(10**20)
    with pytest.raises(ValueError, match=r"would need about 10\^400 observed entries"):
        make(10**200)                      # was OverflowError formatting the count
    if generator == "make_noisy_linear_maps":
        with pytest.raises(ValueError, match=r"`dim`=10+ would need"):
            make(3, dim=10**20)
    # noise=1e300 overflowed into maps of infinite condition, refused by the synchronizers
    with pytest.raises(ValueError, match=r"`noise` must be at most 1e\+100 .* got 1e\+300"):
        make(4, noise=1e300)
    prob = make(4, noise=1e100, rng=0)
    assert np.isfinite(prob.observed[prob.mask]).all()


@pytest.mark.parametrize("image_size, error, match", [
    ((1e200, 1e200), ValueError, r"\[2, 1048576\]"),       # was: NaN homographies
    ((1, 1), ValueError, r"\[2, 1048576\]"),               # was: LinAlgError (corners coincide)
    ((0, 5), ValueError, "`image_size`"),                   # was named `size`
    ((640.5, 480), ValueError, "whole pixels"),
    (640, TypeError, "`image_size` must be \\(width, height\\), got int"),
    ((np.nan, 3), ValueError, "`image_size`"),
    ((640, 480, 3), ValueError, "3 value"),
    ((True, 480), TypeError, "`image_size`"),
    ((10**5000, 3), ValueError, r"got <tuple with an integer of about 10\^5000>"),
])
def test_make_noisy_homographies_checks_image_size(image_size, error, match):
    from transync.datasets import make_noisy_homographies

    with pytest.raises(error, match=match):
        make_noisy_homographies(4, image_size=image_size, rng=0)


@pytest.mark.parametrize("max_angle", [-1.0, np.nan, None, "10"])
def test_make_noisy_homographies_checks_max_angle(max_angle):
    from transync.datasets import make_noisy_homographies

    with pytest.raises((ValueError, TypeError), match="`max_angle`"):
        make_noisy_homographies(4, max_angle=max_angle, rng=0)


def test_make_noisy_homographies_extreme_valid_sizes_stay_finite():
    from transync.datasets import make_noisy_homographies

    for size in ((2, 2), (2**20, 2**20), (640.0, 480.0)):
        p = make_noisy_homographies(4, image_size=size, rng=0)
        assert np.isfinite(p.observed[p.mask]).all() and np.isfinite(p.truth).all()
        assert p.image_size == (int(size[0]), int(size[1]))
