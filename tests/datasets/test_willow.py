"""Willow-ObjectClass class folders (``<name>.png`` + ``<name>.mat`` with ``pts_coord``, 2 x 10),
on fixtures written here with scipy.io.savemat (issue 10 item 4)."""

import re
import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
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
    (np.array(["ab", "cd"]), "expected a numeric 2 x K array, got MATLAB class char"),
    (XY + 1j, "expected a numeric 2 x K array, got MATLAB class double (complex)"),
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


# --------------------------------------------------------------------------- corrupt .mat files
# scipy.io.loadmat trusts a MAT-file's tags: a corrupted data type (the first test) crashes the
# interpreter (segmentation fault, scipy 1.16) inside its compiled reader; the loader reads v5
# files with its own small reader, which refuses it with an error naming the file.

def _mat_bytes(value=XY, **kw):
    import io

    buf = io.BytesIO()
    savemat(buf, {"pts_coord": value}, **kw)
    return bytearray(buf.getvalue())


def _corrupt_class(tmp_path, data):
    _class(tmp_path, n=2)
    bad = tmp_path / "060_0001.mat"
    bad.write_bytes(bytes(data))
    return bad


def test_corrupted_data_type_is_a_named_error(tmp_path):
    data = _mat_bytes()
    tag = data.find(b"\x09\x00\x00\x00\xa0\x00\x00\x00")     # miDOUBLE, 160 bytes: the 2 x 10
    assert tag > 0
    data[tag:tag + 4] = (777).to_bytes(4, "little")
    bad = _corrupt_class(tmp_path, data)
    with pytest.raises(ValueError, match="^" + re.escape(
            f"{bad}: cannot read as a MATLAB .mat file (an unknown data type 777 at byte")):
        load_willow_class(tmp_path)


def test_complex_flag_without_imaginary_part_is_a_named_error(tmp_path):
    data = _mat_bytes()
    flags = data.find(b"\x06\x00\x00\x00\x08\x00\x00\x00") + 8   # miUINT32 array-flags tag
    data[flags + 1] |= 0x08                                      # the complex bit
    bad = _corrupt_class(tmp_path, data)
    _err(ValueError, tmp_path,
         f"{bad}, field 'pts_coord': expected a numeric 2 x K array, got MATLAB class double "
         "(complex)")


def test_compressed_v4_and_integer_annotations_load(tmp_path):
    _class(tmp_path, n=3)
    savemat(tmp_path / "060_0001.mat", {"pts_coord": XY + 1}, do_compression=True)
    savemat(tmp_path / "060_0002.mat", {"pts_coord": XY + 2}, format="4")
    seq = load_willow_class(tmp_path)
    np.testing.assert_allclose(seq.points, np.stack([XY.T, XY.T + 1, XY.T + 2]))
    savemat(tmp_path / "060_0002.mat", {"pts_coord": np.rint(XY).astype(np.int16)})
    np.testing.assert_allclose(load_willow_class(tmp_path).points[2], np.rint(XY).T)


def test_v73_file_is_a_named_error(tmp_path):
    data = _mat_bytes()
    data[124:128] = b"\x00\x02IM"                                # version 0x0200: HDF5-based
    bad = _corrupt_class(tmp_path, data)
    _err(ValueError, tmp_path,
         f"{bad}: a MATLAB v7.3 (HDF5) .mat file, which is not supported; save it with -v7 "
         "(or -v6)")


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(compress=st.booleans(), edits=st.lists(
    st.tuples(st.integers(0, 10**6), st.integers(0, 255), st.sampled_from(["set", "cut", "ins"])),
    min_size=1, max_size=4))
def test_mutated_mat_files_load_or_name_the_file(tmp_path_factory, compress, edits):
    """Byte-level corruptions of a valid annotation: the same keypoints, other numbers, or a
    ValueError that names the file -- never a crash, never another exception."""
    root = tmp_path_factory.mktemp("willow")
    data = _mat_bytes(do_compression=compress)
    for pos, byte, op in edits:
        pos %= len(data) + 1
        if op == "set" and pos < len(data):
            data[pos] = byte
        elif op == "cut":
            del data[pos:]
        else:
            data[pos:pos] = bytes([byte]) * 3
    bad = _corrupt_class(root, data)
    try:
        seq = load_willow_class(root)
    except ValueError as exc:
        assert str(bad) in str(exc)
    else:
        assert np.isfinite(seq.points).all()


def test_folder_argument_named():
    """None, 1.5 and b"/tmp" reached pathlib ("expected str, bytes or os.PathLike object")."""
    for bad in (None, 1.5, b"/tmp"):
        with pytest.raises(TypeError, match=r"`folder` must be a path"):
            load_willow_class(bad)
    with pytest.raises(ValueError, match="`folder`: cannot expand '~nosuchuser_x/Car'"):
        load_willow_class("~nosuchuser_x/Car")
