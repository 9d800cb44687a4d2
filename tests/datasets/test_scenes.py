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


@pytest.mark.parametrize("kw, match", [({"image_size": (20, 20)}, r"at least \(32, 32\)"),
                                       ({"difficulty": "extreme"}, "`difficulty` must be one"),
                                       ({"clutter": 2.0}, r"`clutter` must lie in \[0, 1\]")])
def test_scene_options_checked(kw, match):
    with pytest.raises(ValueError, match=match):
        make_planar_scene(2, **kw)
