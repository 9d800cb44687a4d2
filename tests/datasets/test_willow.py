"""Willow-ObjectClass class folders (``<name>.png`` + ``<name>.mat`` with ``pts_coord``, 2 x 10),
on fixtures written here with scipy.io.savemat (issue 10 item 4)."""

import re
import struct
import zlib

import numpy as np
import pytest
from scipy.io import savemat

from transync.datasets import LANDMARK_AFFINITY, LandmarkSequence, load_willow_class
from transync.matching import gaussian_edge_affinity, match_graphs

RNG = np.random.default_rng(4)
XY = np.vstack([RNG.uniform(0, 200, 10), RNG.uniform(0, 150, 10)])   # 2 x 10: x row, y row


def _png(path, width, height):
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    chunk = struct.pack(">I", len(ihdr)) + b"IHDR" + ihdr + struct.pack(
        ">I", zlib.crc32(b"IHDR" + ihdr))
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk)


def _class(root, n=4, images=True, jitter=0.0):
    root.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    for k in range(n):
        name = f"060_{k:04d}"
        savemat(root / f"{name}.mat", {"pts_coord": XY + k + jitter * rng.normal(size=XY.shape)})
        if images:
            _png(root / f"{name}.png", 200 + k, 150)
    return root


def test_reads_layout(tmp_path):
    root = _class(tmp_path / "Duck")
    seq = load_willow_class(root)
    assert isinstance(seq, LandmarkSequence)
    assert seq.name == "Duck" and seq.source == root
    assert seq.points.shape == (4, 10, 2) and seq.frames.tolist() == [0, 1, 2, 3]
    np.testing.assert_allclose(seq.points[2], XY.T + 2)          # column k = keypoint k
    assert [p.name for p in seq.image_paths] == [f"060_{k:04d}.png" for k in range(4)]
    assert seq.image_sizes.tolist() == [[200 + k, 150] for k in range(4)]


def test_without_images(tmp_path):
    root = _class(tmp_path / "Car", images=False)
    seq = load_willow_class(root)
    assert seq.image_paths is None and seq.image_sizes is None
    np.testing.assert_allclose(seq.normalized_points([0])[0],
                               seq.points[0] / np.hypot(*np.ptp(seq.points[0], axis=0)))


def test_planted_round_trip_and_matching(tmp_path):
    seq = load_willow_class(_class(tmp_path / "Face", n=3, jitter=0.5))
    prob = seq.graphs([0, 1, 2], rng=5)
    for i in range(3):
        for j in range(3):
            np.testing.assert_array_equal(prob.labels[j][prob.truth(i, j)], prob.labels[i])
    g1, g2 = prob.graphs[:2]
    affinity = gaussian_edge_affinity(g1, g2, **LANDMARK_AFFINITY)
    result = match_graphs(g1, g2, method="rrwm", affinity=affinity)
    np.testing.assert_array_equal(result.assignment, prob.truth(0, 1))
    part = seq.graphs([0, 1, 2], keep=(6, 8), rng=5)
    assert all(6 <= g.n_nodes <= 8 for g in part.graphs)


def _err(exc, root, message):
    with pytest.raises(exc, match="^" + re.escape(message) + "$"):
        load_willow_class(root)


def test_missing_folder(tmp_path):
    _err(FileNotFoundError, tmp_path / "Car",
         f"{tmp_path / 'Car'}: no such folder (expected a Willow-ObjectClass class folder of "
         "`<name>.png` + `<name>.mat` files)")


def test_no_annotations(tmp_path):
    _png(tmp_path / "a.png", 4, 4)
    _err(ValueError, tmp_path,
         f"{tmp_path}: no annotation files (expected `<name>.mat` files with a 'pts_coord' "
         "field beside `<name>.png` images)")


def test_unreadable_mat(tmp_path):
    _class(tmp_path, n=2)
    bad = tmp_path / "060_0001.mat"
    bad.write_bytes(b"this is not a mat file at all" * 10)
    with pytest.raises(ValueError, match="^" + re.escape(f"{bad}: cannot read as a MATLAB .mat "
                                                         "file (")):
        load_willow_class(tmp_path)


def test_missing_field(tmp_path):
    _class(tmp_path, n=2)
    bad = tmp_path / "060_0001.mat"
    savemat(bad, {"pts": XY, "img": np.zeros(2)})
    _err(ValueError, tmp_path,
         f"{bad}: no field 'pts_coord' (expected a 2 x K array of keypoints; fields present: "
         "'img', 'pts')")


@pytest.mark.parametrize("value, message", [
    (XY.T, "expected a 2 x K array (x row, y row), got shape (10, 2)"),
    (np.zeros((3, 10)), "expected a 2 x K array (x row, y row), got shape (3, 10)"),
    (np.zeros((2, 0)), "expected a 2 x K array (x row, y row), got shape (2, 0)"),
    (np.array(["ab", "cd"]), "expected a numeric 2 x K array, got dtype <U2"),
])
def test_bad_field_shape_or_type(tmp_path, value, message):
    _class(tmp_path, n=2)
    bad = tmp_path / "060_0000.mat"
    savemat(bad, {"pts_coord": value})
    _err(ValueError, tmp_path, f"{bad}, field 'pts_coord': {message}")


def test_nan_coordinate(tmp_path):
    _class(tmp_path, n=2)
    bad = tmp_path / "060_0001.mat"
    xy = XY.copy()
    xy[1, 3] = np.nan
    savemat(bad, {"pts_coord": xy})
    _err(ValueError, tmp_path,
         f"{bad}, field 'pts_coord': expected finite coordinates, got "
         f"{[float(xy[0, 3]), float('nan')]} in column 3")


def test_inconsistent_keypoint_counts(tmp_path):
    _class(tmp_path, n=3)
    bad = tmp_path / "060_0002.mat"
    savemat(bad, {"pts_coord": XY[:, :9]})
    _err(ValueError, tmp_path,
         f"{bad}, field 'pts_coord': 9 keypoints, but {tmp_path / '060_0000.mat'} has 10; every "
         "image must have the same keypoints")


def test_bad_png(tmp_path):
    _class(tmp_path, n=2)
    bad = tmp_path / "060_0001.png"
    bad.write_bytes(b"\x89PNG\r\n")
    _err(ValueError, tmp_path, f"{bad}: not a PNG image (cannot read its size from the header)")
