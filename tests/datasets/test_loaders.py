"""Error paths of the real-data loaders on small malformed fixtures written by the tests.

Every error names the file, and the line or field where the format has one (issue 13 item 10).
"""

import re
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.io import savemat

from transync.datasets import (
    list_adelaidermf,
    load_adelaidermf,
    load_graf,
    load_hpatches_sequence,
    load_oxford_sequence,
)

GOOD_H = "1 0 2\n0 1 0\n0 0 1\n"


def _png(path, shape=(6, 8), value=0):
    import cv2

    assert cv2.imwrite(str(path), np.full(shape, value, np.uint8))


def _oxford(tmp_path, htext, n=2):
    for k in range(1, n + 1):
        _png(tmp_path / f"img{k}.png")
    for k in range(2, n + 1):
        (tmp_path / f"H1to{k}p").write_text(htext)
    return tmp_path


def _q(path):
    return re.escape(str(path))


# --------------------------------------------------------------------------- text homographies

@pytest.mark.parametrize("text, where, what", [
    ("1 0 2\nfoo 1.0\n0 0 1\n", "line 2", "expected 3 finite numbers, got 'foo 1.0'"),
    ("1 0 2\n0 1 nan\n0 0 1\n", "line 2", "expected 3 finite numbers"),
    ("1 0 2\n0 1 0\ninf 0 1\n", "line 3", "expected 3 finite numbers"),
    ("1 0 2\n0 1 0\n1e999 0 1\n", "line 3", "expected finite numbers"),
    ("1 0 2\n0 1_5 0\n0 0 1\n", "line 2", "expected 3 finite numbers, got '0 1_5 0'"),   # 15
    ("1 0 2\x0c0 1 0\n0 0 1\n", "line 1", "expected 3 numbers, got 6"),  # \x0c: no line end
    ("1 0 2\n0 1\n0 0 1\n", "line 2", "expected 3 numbers, got 2"),
    ("1 0 0 0 1 0\n", "line 1", "expected 3 numbers, got 6"),
])
def test_homography_text_bad_line(tmp_path, text, where, what):
    _oxford(tmp_path, text)
    pattern = _q(tmp_path / "H1to2p") + f"`, {where}: {re.escape(what)}"
    with pytest.raises(ValueError, match=pattern):
        load_oxford_sequence(tmp_path)


@pytest.mark.parametrize("text, what", [
    ("1 0 2\n0 1 0\n", "expected a 3x3 matrix (3 lines of 3 numbers), got 2 non-empty lines"),
    ("", "expected a 3x3 matrix (3 lines of 3 numbers), got 0 non-empty lines"),
    ("1 0 2\n0 1 0\n0 0 1\n1 1 1\n",
     "expected a 3x3 matrix (3 lines of 3 numbers), got 4 non-empty lines"),
    ("0 0 0\n0 0 0\n0 0 0\n", "expected an invertible 3x3 homography, got a singular matrix"),
    ("1 2 3\n2 4 6\n0 0 1\n", "expected an invertible 3x3 homography, got a singular matrix"),
])
def test_homography_text_bad_matrix(tmp_path, text, what):
    _oxford(tmp_path, text)
    with pytest.raises(ValueError, match=_q(tmp_path / "H1to2p") + "`: " + re.escape(what)):
        load_oxford_sequence(tmp_path)


def test_homography_text_tolerates_blank_lines_crlf_and_commas(tmp_path):
    _oxford(tmp_path, "\r\n1, 0, 2\r\n\r\n0 1 0 \r\n0\t0\t1\r\n\r\n")
    seq = load_oxford_sequence(tmp_path)
    np.testing.assert_allclose(seq.homographies[1], [[1, 0, -2], [0, 1, 0], [0, 0, 1]], atol=1e-12)


def test_homography_is_normalized_to_det_one(tmp_path):
    _oxford(tmp_path, "2 0 4\n0 2 0\n0 0 2\n")
    seq = load_oxford_sequence(tmp_path)
    np.testing.assert_allclose(np.linalg.det(seq.homographies), 1.0, rtol=1e-12)
    np.testing.assert_allclose(seq.homographies[1], [[1, 0, -2], [0, 1, 0], [0, 0, 1]], atol=1e-12)


def test_homography_binary_file(tmp_path):
    _oxford(tmp_path, GOOD_H)
    (tmp_path / "H1to2p").write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(ValueError, match=_q(tmp_path / "H1to2p") + "`: cannot read the homography"):
        load_oxford_sequence(tmp_path)


def test_missing_homography_file(tmp_path):
    _oxford(tmp_path, GOOD_H, n=3)
    (tmp_path / "H1to3p").unlink()
    with pytest.raises(FileNotFoundError, match=_q(tmp_path / "H1to3p") + "`: ground-truth"):
        load_oxford_sequence(tmp_path)


def test_hpatches_errors_name_file_and_line(tmp_path):
    for k in (1, 2):
        _png(tmp_path / f"{k}.png")
    (tmp_path / "H_1_2").write_text("1 0 0\n0 1 0\n0 0 x\n")
    (tmp_path / "notes.txt").write_text("3.txt is not an image")
    with pytest.raises(ValueError, match=_q(tmp_path / "H_1_2") + "`, line 3: expected 3 finite "
                                         "numbers"):
        load_hpatches_sequence(tmp_path)
    (tmp_path / "H_1_2").write_text(GOOD_H)
    (tmp_path / "3.txt").write_text("not an image, ignored")
    assert load_hpatches_sequence(tmp_path).n_views == 2


# --------------------------------------------------------------------------- folders and images

@pytest.mark.parametrize("loader, what", [(load_oxford_sequence, "Oxford"),
                                          (load_hpatches_sequence, "HPatches")])
def test_empty_and_missing_folders(tmp_path, loader, what):
    with pytest.raises(FileNotFoundError, match=_q(tmp_path) + f"`: no {what} sequence"):
        loader(tmp_path)
    with pytest.raises(FileNotFoundError, match="`folder` must be an existing directory, got"):
        loader(tmp_path / "absent")
    (tmp_path / "file").write_text("x")
    with pytest.raises(FileNotFoundError, match="`folder` must be an existing directory"):
        loader(tmp_path / "file")
    with pytest.raises(TypeError, match=r"`folder` must be a path \(str or os.PathLike\), got "
                                        r"int 3"):
        loader(3)
    with pytest.raises(ValueError, match=r"`folder` must be a path, got ''"):     # was the cwd
        loader("")


def test_sequence_must_start_at_image_one(tmp_path):
    _png(tmp_path / "img2.png")
    with pytest.raises(FileNotFoundError, match="no Oxford sequence"):
        load_oxford_sequence(tmp_path)


@pytest.mark.parametrize("content, why", [(b"", "empty file"),
                                          (b"P6\n8 6\n255\n\x00\x01", "unknown or corrupt format"),
                                          (b"not an image at all", "unknown or corrupt format")])
def test_unreadable_image(tmp_path, content, why):
    _oxford(tmp_path, GOOD_H)
    (tmp_path / "img2.png").unlink()
    (tmp_path / "img2.ppm").write_bytes(content)
    with pytest.raises(ValueError, match=_q(tmp_path / "img2.ppm") + "`: cannot decode the image "
                                         r"file \(.*" + why):
        load_oxford_sequence(tmp_path)


def test_duplicate_extensions_are_one_view_and_sizes_may_differ(tmp_path):
    _oxford(tmp_path, GOOD_H)
    _png(tmp_path / "img1.jpg")                    # same index, another extension
    _png(tmp_path / "img2.png", shape=(10, 12))    # sequences may mix sizes (HPatches does)
    seq = load_oxford_sequence(tmp_path)
    assert seq.n_views == 2 and seq.names == ["img1.png", "img2.png"]
    assert seq.images[1].shape == (10, 12)


def test_sequence_with_gaps_padding_and_bom(tmp_path):
    """Indices follow the file names (img01, img4: a gap) and a UTF-8 BOM is tolerated."""
    _png(tmp_path / "img01.png")
    _png(tmp_path / "img4.png")
    (tmp_path / "H1to4p").write_text("\ufeff1 0 0\n0 1 7\n0 0 1\n", encoding="utf-8")
    seq = load_oxford_sequence(tmp_path)
    assert seq.names == ["img01.png", "img4.png"]
    np.testing.assert_allclose(seq.homographies[1][1, 2], -7.0)


def test_colour_and_alpha_images_become_rgb(tmp_path):
    import cv2

    bgra = np.zeros((4, 5, 4), np.uint8)
    bgra[..., 0] = 255                            # blue in OpenCV's BGR order
    cv2.imwrite(str(tmp_path / "img1.png"), bgra)
    _png(tmp_path / "img2.png")
    (tmp_path / "H1to2p").write_text(GOOD_H)
    seq = load_oxford_sequence(tmp_path)
    assert seq.images[0].shape == (4, 5, 3) and seq.images[0].flags.c_contiguous
    assert np.all(seq.images[0][..., 2] == 255) and np.all(seq.images[0][..., 0] == 0)


# --------------------------------------------------------------------------- graf (XML)

_XML = """<?xml version="1.0"?>
<opencv_storage>
<H13 type_id="opencv-matrix">
  <rows>{rows}</rows>
  <cols>3</cols>
  <dt>d</dt>
  <data>
    {data}</data></H13>
</opencv_storage>
"""


def _graf(tmp_path, xml=None):
    _png(tmp_path / "graf1.png")
    _png(tmp_path / "graf3.png")
    if xml is not None:
        (tmp_path / "H1to3p.xml").write_text(xml)
    return tmp_path


def test_graf_fixture_xml_and_text(tmp_path):
    _graf(tmp_path, _XML.format(rows=3, data="1 0 2 0 1 0 0 0 1"))
    g = load_graf(tmp_path)
    np.testing.assert_allclose(g.homographies[1], [[1, 0, -2], [0, 1, 0], [0, 0, 1]], atol=1e-12)
    (tmp_path / "H1to3p.xml").unlink()
    (tmp_path / "H1to3p").write_text("1 0 0\n0 1 5\n0 0 1\n")
    np.testing.assert_allclose(load_graf(tmp_path).homographies[1][1, 2], -5.0)


@pytest.mark.parametrize("xml, what", [
    (_XML.format(rows=3, data="1 0 2 0 1 0 0 0 1")[:120],
     r"`, line \d+, column \d+: malformed XML"),
    (_XML.format(rows=2, data="1 0 2 0 1 0"),
     "`, fields <rows>/<cols>: expected a 3x3 matrix, got 2x3"),
    (_XML.format(rows="x", data="1 0 2 0 1 0"), "`, fields <rows>/<cols>: expected integers"),
    (_XML.format(rows=3, data="1 0 2 0 1 0 0 0"), "`, field <data>: expected 9 numbers, got 8"),
    (_XML.format(rows=3, data="1 0 2 0 1 0 0 0 word"), "`, field <data>: expected 9 numbers, got"),
    (_XML.format(rows=3, data="1 0 2 0 nan 0 0 0 1"),
     "`, field <data>: expected 9 numbers, got 'nan'"),
    # float() read these as 10 and 1: the XML reader now takes the text reader's numbers only
    (_XML.format(rows=3, data="1 0 1_0 0 1 0 0 0 1"),
     "`, field <data>: expected 9 numbers, got '1_0'"),
    (_XML.format(rows=3, data="1 0 1 0 1 0 0 0 \uff11"),
     "`, field <data>: expected 9 numbers, got '\uff11'"),
    (_XML.format(rows="\uff13", data="1 0 1 0 1 0 0 0 1"),
     "`, fields <rows>/<cols>: expected integers"),
    (_XML.format(rows=3, data="0 0 0 0 0 0 0 0 0"), "`, field <data>: expected an invertible"),
    (_XML.format(rows=3, data=""), "`, field <H13><data>: missing or empty"),
    ("<?xml version=\"1.0\"?>\n<opencv_storage><a>1</a></opencv_storage>\n",
     "`: expected an element with type_id=\"opencv-matrix\""),
])
def test_graf_bad_xml(tmp_path, xml, what):
    _graf(tmp_path, xml)
    with pytest.raises(ValueError, match=_q(tmp_path / "H1to3p.xml") + what):
        load_graf(tmp_path)


def test_graf_missing_files(tmp_path):
    _graf(tmp_path)
    with pytest.raises(FileNotFoundError, match=_q(tmp_path) + "`: no ground truth H1to3p.xml"):
        load_graf(tmp_path)
    (tmp_path / "H1to3p").write_text(GOOD_H)
    (tmp_path / "graf3.png").unlink()
    with pytest.raises(FileNotFoundError, match=_q(tmp_path) + "`: no image graf3"):
        load_graf(tmp_path)


# --------------------------------------------------------------------------- AdelaideRMF (.mat)

def _mat(tmp_path, name="pair", n=5, **override):
    rng = np.random.default_rng(0)
    x1 = rng.uniform(0, 50, (2, n))
    data = np.vstack([x1, np.ones(n), x1 + 3, np.ones(n)])
    fields = {"data": data, "label": np.arange(n, dtype=np.uint8).reshape(1, n) % 3,
              "img1": np.zeros((60, 70, 3), np.uint8), "img2": np.zeros((60, 70, 3), np.uint8)}
    fields.update(override)
    savemat(str(tmp_path / f"{name}.mat"), {k: v for k, v in fields.items() if v is not None})
    return tmp_path / f"{name}.mat"


def test_adelaidermf_fixture_loads(tmp_path):
    _mat(tmp_path)
    assert list_adelaidermf(tmp_path) == ["pair"]
    d = load_adelaidermf("pair", tmp_path)
    assert d.x1.shape == d.x2.shape == (5, 2) and d.n_planes == 2
    np.testing.assert_allclose(d.x2 - d.x1, 3.0)
    np.testing.assert_array_equal(d.labels, [0, 1, 2, 0, 1])


@pytest.mark.parametrize("override, what", [
    ({"data": None}, "`: field 'data' missing (expected data, label, img1, img2; found img1, img2, "
                     "label)"),
    ({"label": None}, "`: field 'label' missing"),
    ({"img2": None}, "`: field 'img2' missing"),
    ({"label": np.zeros((1, 2), np.uint8)}, "`, field 'label': expected 5 labels (one per column "
                                            "of 'data'), got shape (1, 2)"),
    ({"label": -np.ones((1, 5))}, "`, field 'label': expected labels from 0 (outlier) to "
                                  "4611686018427387903, got -1"),
    ({"label": np.full((1, 5), 1e19)}, "`, field 'label': expected labels from 0 (outlier) to "
                                       "4611686018427387903, got 1e+19"),
    ({"label": np.full((1, 5), 0.5)}, "`, field 'label': expected integer labels"),
    ({"data": np.ones((3, 5))}, "`, field 'data': expected a 6xN array (x1, y1, 1, x2, y2, 1), "
                                "got shape (3, 5)"),
    ({"data": np.full((6, 5), np.nan)}, "`, field 'data': expected finite values"),
    ({"data": np.zeros((6, 5))}, "`, field 'data': homogeneous rows 3 and 6 must be non-zero"),
    ({"data": "text"}, "`, field 'data': expected a 6xN array"),
    ({"img1": np.zeros((0, 4))}, "`, field 'img1': expected an image (H, W) or (H, W, 3)"),
    ({"img1": np.zeros((4, 4, 7))}, "`, field 'img1': expected an image (H, W) or (H, W, 3)"),
])
def test_adelaidermf_bad_fields(tmp_path, override, what):
    path = _mat(tmp_path, **override)
    with pytest.raises(ValueError, match=_q(path) + re.escape(what)):
        load_adelaidermf("pair", tmp_path)


def test_adelaidermf_silent_misreads_refused(tmp_path):
    """A 2x3 label for 6 points was flattened; a homogeneous entry of 1e-320 gave inf points
    (with an overflow warning); an all-NaN or negative float image was an image."""
    path = _mat(tmp_path, n=6, label=np.ones((2, 3), np.uint8))
    with pytest.raises(ValueError, match=_q(path) + re.escape("`, field 'label': expected 6 "
                                                              "labels (one per column of 'data'), "
                                                              "got shape (2, 3)")):
        load_adelaidermf("pair", tmp_path)
    data = np.vstack([np.ones((2, 5)), np.full(5, 1e-320), np.ones((3, 5))])
    path = _mat(tmp_path, data=data)
    with pytest.raises(ValueError, match=_q(path) + re.escape("`, field 'data': the points "
                                                              "(x / w, y / w) overflow float64")):
        load_adelaidermf("pair", tmp_path)
    for img, got in ((np.full((4, 4), np.nan), "NaN or infinite"), (-np.ones((4, 4)), "negative")):
        path = _mat(tmp_path, img2=img)
        with pytest.raises(ValueError, match=_q(path) + re.escape(
                f"`, field 'img2': expected an image of finite non-negative intensities, got "
                f"{got} values")):
            load_adelaidermf("pair", tmp_path)


def test_two_spellings_of_one_image_number_refused(tmp_path):
    """img01.png beside img1.png: the loader silently took img01.png as view 1."""
    _oxford(tmp_path, GOOD_H)
    _png(tmp_path / "img01.png", value=9)
    with pytest.raises(ValueError, match=_q(tmp_path) + re.escape("`: image 1 is given twice "
                                                                  "(img01, img1)")):
        load_oxford_sequence(tmp_path)


def test_truncated_png_prints_nothing(tmp_path, capfd):
    """OpenCV logged "[ WARN:0@...] ... PNG input buffer is incomplete" to stderr."""
    import cv2

    _oxford(tmp_path, GOOD_H)
    ok, buf = cv2.imencode(".png", np.random.default_rng(0).integers(0, 255, (40, 40), np.uint8))
    (tmp_path / "img2.png").write_bytes(buf.tobytes()[:-30])
    with pytest.raises(ValueError, match="cannot decode the image file"):
        load_oxford_sequence(tmp_path)
    assert capfd.readouterr().err == ""


def test_adelaidermf_ten_labels_for_many_points(tmp_path):
    """Issue 13 item 10: 10 labels for 241 points were accepted."""
    path = _mat(tmp_path, n=241, label=np.zeros((1, 10), np.uint8))
    with pytest.raises(ValueError, match=_q(path) + re.escape("`, field 'label': expected 241")):
        load_adelaidermf("pair", tmp_path)


@pytest.mark.parametrize("cut", [0, 10, 200])
def test_adelaidermf_truncated_or_garbage_file(tmp_path, cut):
    path = _mat(tmp_path, n=241)
    raw = path.read_bytes()
    path.write_bytes(raw[:cut] if cut else b"garbage, not MATLAB")
    with pytest.raises(ValueError, match=_q(path) + "`: cannot read as a MATLAB .mat file"):
        load_adelaidermf("pair", tmp_path)


def test_adelaidermf_names_and_folders(tmp_path):
    with pytest.raises(FileNotFoundError, match="`name`: no AdelaideRMF file"):
        load_adelaidermf("absent", tmp_path)
    for bad in ("../pair", "", 3, None):
        with pytest.raises(ValueError, match="`name` must be a sequence name"):
            load_adelaidermf(bad, tmp_path)
    with pytest.raises(FileNotFoundError, match="`folder` must be an existing directory"):
        list_adelaidermf(tmp_path / "absent")
    assert list_adelaidermf(tmp_path) == []


# --------------------------------------------------------------------------- imports

def test_import_datasets_loaders_without_opencv():
    """The loaders import OpenCV only when an image is decoded (issue 9 item 9)."""
    code = ("import sys, transync.datasets as d; d.load_oxford_sequence, d.load_adelaidermf; "
            "print('cv2' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# --------------------------------------------------------------------------- fuzzed file contents

_FUZZ = dict(max_examples=40, deadline=None, derandomize=True, database=None,
             suppress_health_check=list(HealthCheck))
_TEXT = st.one_of(
    st.text(alphabet="0123456789 .-e+\nnaif,;x\t", max_size=60),
    st.lists(st.lists(st.sampled_from(["1", "0", "-2.5e3", "nan", "inf", "1e-300", "1e300",
                                       "x", ""]), max_size=4), max_size=5).map(
        lambda rows: "\n".join(" ".join(r) for r in rows)),
)


def _assert_names_file(exc, path):
    assert isinstance(exc, (ValueError, FileNotFoundError)), repr(exc)
    assert str(path) in str(exc), f"error does not name {path}: {exc}"


@settings(**_FUZZ)
@given(text=_TEXT)
def test_fuzzed_homography_text(text):
    """Any text either loads as a finite det-1 homography or is refused naming the file."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        folder = _oxford(Path(d), GOOD_H)
        (folder / "H1to2p").write_text(text)
        try:
            seq = load_oxford_sequence(folder)
        except Exception as exc:  # noqa: BLE001 - which exception is what is tested
            _assert_names_file(exc, folder / "H1to2p")
            return
        assert np.all(np.isfinite(seq.homographies))
        np.testing.assert_allclose(np.linalg.det(seq.homographies), 1.0, rtol=1e-6)


@settings(**_FUZZ)
@given(cut=st.integers(0, 400), junk=st.binary(max_size=20))
def test_fuzzed_graf_xml(cut, junk):
    """Truncated or corrupted FileStorage XML is refused naming the file (never SystemError)."""
    import tempfile
    from pathlib import Path

    xml = _XML.format(rows=3, data="1 0 2 0 1 0 0 0 1").encode()
    with tempfile.TemporaryDirectory() as d:
        folder = _graf(Path(d))
        (folder / "H1to3p.xml").write_bytes(xml[:cut] + junk)
        try:
            g = load_graf(folder)
        except Exception as exc:  # noqa: BLE001
            _assert_names_file(exc, folder / "H1to3p.xml")
            return
        assert np.all(np.isfinite(g.homographies))


@settings(**dict(_FUZZ, max_examples=25))
@given(cut=st.integers(0, 2000), flip=st.integers(0, 2000), byte=st.integers(0, 255))
def test_fuzzed_adelaidermf_file(cut, flip, byte):
    """Truncated or corrupted .mat files are refused naming the file, or load consistently."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        path = _mat(Path(d), n=20)
        raw = bytearray(path.read_bytes())
        if flip < len(raw):
            raw[flip] = byte
        path.write_bytes(bytes(raw[:cut]) if cut < len(raw) else bytes(raw))
        try:
            pair = load_adelaidermf("pair", Path(d))
        except Exception as exc:  # noqa: BLE001
            _assert_names_file(exc, path)
            return
        n = pair.labels.size
        assert pair.x1.shape == pair.x2.shape == (n, 2)
        assert np.all(np.isfinite(pair.x1)) and np.all(pair.labels >= 0)


def test_one_image_reader_refuses_a_truncated_jpeg(tmp_path):
    """The homography pipeline read files with cv2.imread, which returned a truncated JPEG half
    decoded (grey lower half; "Premature end of JPEG file" on stderr only) where the loaders'
    reader refused it. Both now read through `read_image`."""
    import cv2

    from transync.datasets import read_image
    from transync.homography import load_images

    rng = np.random.default_rng(0)
    img = rng.integers(0, 255, (64, 80, 3), np.uint8)
    ok, buf = cv2.imencode(".jpg", img)
    full, half = tmp_path / "full.jpg", tmp_path / "half.jpg"
    full.write_bytes(buf.tobytes())
    half.write_bytes(buf.tobytes()[: len(buf) * 6 // 10])
    assert read_image(full).shape == (64, 80, 3)
    with pytest.raises(ValueError, match=_q(half) + "`: cannot decode the image file"):
        read_image(half)
    with pytest.raises(ValueError, match=r"`images\[1\]`: `" + _q(half) + "`: cannot decode"):
        load_images([full, half])
    # grey stays grey, RGBA comes back as RGB (OpenCV writes BGR)
    grey, rgba = tmp_path / "grey.png", tmp_path / "rgba.png"
    cv2.imwrite(str(grey), img[..., 0])
    cv2.imwrite(str(rgba), np.dstack([img, np.full((64, 80), 255, np.uint8)]))
    out = load_images([grey, rgba])
    np.testing.assert_array_equal(out[0], img[..., 0])
    np.testing.assert_array_equal(out[1], cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
    with pytest.raises(TypeError, match="`path` must be a path"):
        read_image(3)
    # a number is neither an image nor a path (was "must be a (H, W)... got shape ()")
    with pytest.raises(TypeError, match=r"`images\[0\]` must be an image array or a path, got int"):
        load_images([5, full])


@pytest.mark.parametrize("scale", ["1e-320", "1e-200", "1e300"])
def test_a_homography_of_tiny_or_huge_entries_is_read_at_a_safe_scale(tmp_path, scale):
    """Subnormal entries (1e-320 I) passed the checks, then the inverse overflowed and the
    loader returned an all-NaN homography without a word."""
    text = "\n".join(" ".join(scale if i == j else "0" for j in range(3)) for i in range(3))
    seq = load_oxford_sequence(_oxford(tmp_path, text + "\n"))
    np.testing.assert_allclose(seq.homographies[1], np.eye(3), atol=1e-12)


@pytest.mark.parametrize("loader", ["load_cmu_sequence", "load_oxford_sequence", "load_tu",
                                    "load_willow_class", "load_adelaidermf", "load_graf",
                                    "load_hpatches_sequence", "read_image"])
@pytest.mark.parametrize("arg", ["a" * 300, "./" + "a" * 300, "a\x00b"])
def test_a_path_too_long_or_with_a_nul_byte_is_a_named_error(loader, arg):
    """A name of 300 characters made Path.is_dir() raise a raw OSError (File name too long)."""
    import transync.datasets as ds

    with pytest.raises((ValueError, FileNotFoundError)) as info:
        getattr(ds, loader)(arg)
    assert "Errno" not in str(info.value)
