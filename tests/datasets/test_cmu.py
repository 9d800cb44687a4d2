"""CMU House / Hotel landmark sequences: format errors, planted round trips, the partial protocol,
and the real House sequence (issue 10 item 4)."""

import re
import struct
import zlib

import numpy as np
import pytest

from transync.datasets import (
    LANDMARK_AFFINITY,
    LandmarkSequence,
    load_cmu_sequence,
)
from transync.permutations import MultiMatching

RNG = np.random.default_rng(12345)
BASE = RNG.uniform(0, 300, size=(12, 2))


def _rows(P):
    return "".join(f"  {x:.7e}  {y:.7e}\n" for x, y in P)


def _png(path, width, height):
    """A minimal valid PNG header (IHDR) -- the loader reads only the size."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    chunk = struct.pack(">I", len(ihdr)) + b"IHDR" + ihdr + struct.pack(
        ">I", zlib.crc32(b"IHDR" + ihdr))
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk)


def _sequence(root, name="hotel", n_frames=4, numbers=None, images=False, size=(40, 30)):
    label = root / "label"
    label.mkdir(parents=True, exist_ok=True)
    numbers = list(range(1, n_frames + 1)) if numbers is None else numbers
    for k, n in enumerate(numbers):
        (label / f"{name}{n}").write_text(_rows(BASE + k))
    if images:
        (root / "images").mkdir(exist_ok=True)
        for n in numbers:
            _png(root / "images" / f"{name}.seq{n - 1}.png", *size)
    return root


# --------------------------------------------------------------------------- reading


def test_reads_layout_and_finds_prefix(tmp_path):
    root = _sequence(tmp_path, name="hotel", numbers=[3, 1, 10, 2], images=True, size=(40, 30))
    (root / "label" / "README.txt").write_text("not a label file")
    seq = load_cmu_sequence(root)
    assert isinstance(seq, LandmarkSequence)
    assert seq.name == "hotel" and seq.source == root
    assert seq.frames.tolist() == [0, 1, 2, 9]
    assert seq.points.shape == (4, 12, 2) and seq.points.dtype == float
    np.testing.assert_allclose(seq.points[1], BASE + 3, rtol=1e-7)    # hotel2 was written 4th
    assert [p.name for p in seq.image_paths] == ["hotel.seq0.png", "hotel.seq1.png",
                                                 "hotel.seq2.png", "hotel.seq9.png"]
    assert seq.image_sizes.tolist() == [[40, 30]] * 4
    assert not seq.points.flags.writeable
    with pytest.raises(AttributeError):
        seq.name = "house"


def test_images_missing_for_a_frame_gives_none(tmp_path):
    root = _sequence(tmp_path, images=True)
    (root / "images" / "hotel.seq2.png").unlink()
    seq = load_cmu_sequence(root)
    assert seq.image_paths is None and seq.image_sizes is None


def test_default_path_is_data_home(tmp_path, monkeypatch):
    _sequence(tmp_path / "cmu-house", name="house")
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path))
    assert load_cmu_sequence().name == "house"


# --------------------------------------------------------------------------- errors


def _err(exc, root, message):
    with pytest.raises(exc, match="^" + re.escape(message) + "$"):
        load_cmu_sequence(root)


def test_missing_folder(tmp_path):
    _err(FileNotFoundError, tmp_path / "nope",
         f"{tmp_path / 'nope'}: no such folder (expected a folder in the CMU layout, holding "
         "`label/`)")


def test_missing_label_folder(tmp_path):
    _err(FileNotFoundError, tmp_path,
         f"{tmp_path}: no `label` folder (expected `label/<name><N>` text files, one `x y` row "
         "per landmark)")


def test_default_path_missing(tmp_path, monkeypatch):
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path))
    with pytest.raises(FileNotFoundError, match="cmu-house"):
        load_cmu_sequence()


def test_no_label_files(tmp_path):
    (tmp_path / "label").mkdir()
    (tmp_path / "label" / "notes.txt").write_text("1 2\n")
    _err(ValueError, tmp_path,
         f"{tmp_path / 'label'}: no label files (expected text files `<name><N>`, e.g. `house1`, "
         "one `x y` row per landmark)")


def test_several_prefixes(tmp_path):
    _sequence(tmp_path, name="house", n_frames=2)
    _sequence(tmp_path, name="hotel", n_frames=2)
    _err(ValueError, tmp_path,
         f"{tmp_path / 'label'}: label files of several sequences ('hotel', 'house'); expected "
         "one name prefix")


def test_duplicate_frame_number(tmp_path):
    _sequence(tmp_path, n_frames=2)
    (tmp_path / "label" / "hotel01").write_text(_rows(BASE))
    label = tmp_path / "label"
    _err(ValueError, tmp_path,
         f"{label / 'hotel1'}: duplicate frame number 1 (also {label / 'hotel01'})")


def test_frame_number_zero(tmp_path):
    _sequence(tmp_path, numbers=[0, 1])
    _err(ValueError, tmp_path,
         f"{tmp_path / 'label' / 'hotel0'}: frame numbers in the CMU layout start at 1 (file "
         "`<name><N>` is frame N-1), got 0")


@pytest.mark.parametrize("line, message", [
    ("1.0 2.0 3.0", "expected 2 columns `x y`, got 3: '1.0 2.0 3.0'"),
    ("7.5", "expected 2 columns `x y`, got 1: '7.5'"),
    ("1.0 abc", "expected two numbers `x y`, got '1.0 abc'"),
    ("nan 2.0", "expected finite coordinates, got 'nan 2.0'"),
    ("1.0 -inf", "expected finite coordinates, got '1.0 -inf'"),
    # finite, but the bounding box is not: the frame was normalized to all zeros
    ("-1e308 3", "expected coordinates of magnitude <= 1e+300 (their distances must be "
                 "finite), got '-1e308 3'"),
])
def test_bad_row_names_file_and_line(tmp_path, line, message):
    _sequence(tmp_path, n_frames=3)
    bad = tmp_path / "label" / "hotel2"
    (bad).write_text(_rows(BASE[:4]) + line + "\n" + _rows(BASE[4:]))
    _err(ValueError, tmp_path, f"{bad}, line 5: {message}")


def test_a_blank_line_among_the_rows_is_named(tmp_path):
    # it was skipped: every later landmark moved up one, and the error (if any) said only that
    # the frame had 29 landmarks, without a line
    _sequence(tmp_path, n_frames=3)
    bad = tmp_path / "label" / "hotel2"
    bad.write_text(_rows(BASE[:4]) + "  \n" + _rows(BASE[5:]))
    _err(ValueError, tmp_path, f"{bad}, line 5: a blank line among the landmark rows (blank "
                               "lines may only follow the last row)")
    bad.write_text(_rows(BASE) + "\n  \n\n")           # after the last row: ignored
    assert load_cmu_sequence(tmp_path).points.shape[0] == 3


def test_empty_file(tmp_path):
    _sequence(tmp_path, n_frames=2)
    (tmp_path / "label" / "hotel2").write_text("\n  \n")
    _err(ValueError, tmp_path,
         f"{tmp_path / 'label' / 'hotel2'}: no landmark rows (expected rows `x y`)")


def test_binary_file(tmp_path):
    _sequence(tmp_path, n_frames=2)
    (tmp_path / "label" / "hotel2").write_bytes(b"\xff\xfe\x00\x81")
    _err(ValueError, tmp_path,
         f"{tmp_path / 'label' / 'hotel2'}: not a text file (expected rows `x y`)")


def test_inconsistent_landmark_counts(tmp_path):
    _sequence(tmp_path, n_frames=3)
    (tmp_path / "label" / "hotel3").write_text(_rows(BASE[:11]))
    label = tmp_path / "label"
    _err(ValueError, tmp_path,
         f"{label / 'hotel3'}: 11 landmarks, but {label / 'hotel1'} has 12; every frame must "
         "have the same landmarks")


def test_bad_png(tmp_path):
    _sequence(tmp_path, n_frames=2, images=True)
    bad = tmp_path / "images" / "hotel.seq1.png"
    bad.write_bytes(b"GIF89a" + bytes(30))
    _err(ValueError, tmp_path,
         f"{bad}: not a PNG image (cannot read its size from the header)")


# --------------------------------------------------------------------------- graphs


@pytest.fixture
def seq(tmp_path):
    return load_cmu_sequence(_sequence(tmp_path, n_frames=5, images=True, size=(400, 300)))


def test_planted_round_trip(seq):
    prob = seq.graphs([0, 2, 4, 1], rng=7)
    assert isinstance(prob.ground_truth, MultiMatching)
    assert prob.n_universe == 12 and len(prob.graphs) == 4
    P = seq.normalized_points([0, 2, 4, 1])
    for g, (graph, lab) in enumerate(zip(prob.graphs, prob.labels)):
        assert sorted(lab.tolist()) == list(range(12))
        assert not np.array_equal(lab, np.arange(12))           # shuffled
        np.testing.assert_array_equal(graph.points, P[g][lab])  # node u is landmark lab[u]
    for i in range(4):
        for j in range(4):
            t = prob.truth(i, j)
            # the true map sends each node to the node holding the same landmark
            np.testing.assert_array_equal(prob.labels[j][t], prob.labels[i])
    # the image diagonal normalizes (sizes known)
    np.testing.assert_allclose(P[0], seq.points[0] / 500.0)
    assert prob.params["frames"] == [0, 2, 4, 1]


def test_same_seed_same_problem_and_no_shuffle(seq):
    a, b = seq.graphs([0, 1], rng=3), seq.graphs([0, 1], rng=np.random.default_rng(3))
    assert all(np.array_equal(x, y) for x, y in zip(a.labels, b.labels))
    plain = seq.graphs([0, 1], shuffle=False)
    assert all(np.array_equal(lab, np.arange(12)) for lab in plain.labels)
    assert np.array_equal(plain.graphs[0].adjacency, plain.graphs[0].adjacency.T)


def test_bbox_normalization_without_images(tmp_path):
    seq = load_cmu_sequence(_sequence(tmp_path, n_frames=2))
    assert seq.image_sizes is None
    P = seq.normalized_points([1])
    ext = seq.points[1].max(0) - seq.points[1].min(0)
    np.testing.assert_allclose(P[0], seq.points[1] / np.hypot(*ext))
    np.testing.assert_allclose(seq.normalized_points([1], normalize="none")[0], seq.points[1])
    with pytest.raises(ValueError, match=r"^`normalize='image'` needs the image sizes"):
        seq.normalized_points(normalize="image")


@pytest.mark.parametrize("keep, lo, hi", [(8, 8, 8), ((5, 9), 5, 9), ([12, 12], 12, 12)])
def test_partial_keep_protocol(seq, keep, lo, hi):
    prob = seq.graphs([0, 1, 2, 3, 4, 0, 1, 2], keep=keep, rng=11)
    sizes = [g.n_nodes for g in prob.graphs]
    assert all(lo <= s <= hi for s in sizes)
    if lo < hi:
        assert len(set(sizes)) > 1                       # sizes drawn, not fixed
    P = seq.normalized_points([0, 1, 2, 3, 4, 0, 1, 2])
    for g, lab in enumerate(prob.labels):
        assert len(set(lab.tolist())) == len(lab) and lab.min() >= 0 and lab.max() < 12
        np.testing.assert_array_equal(prob.graphs[g].points, P[g][lab])
    for i in range(len(sizes)):
        for j in range(len(sizes)):
            t = prob.truth(i, j)
            shared = np.isin(prob.labels[i], prob.labels[j])
            np.testing.assert_array_equal(t >= 0, shared)
            np.testing.assert_array_equal(prob.labels[j][t[shared]], prob.labels[i][shared])


@pytest.mark.parametrize("kwargs, exc, message", [
    (dict(frames=[0, 7]), ValueError,
     "`frames[1]` must be a frame of 'hotel' (frame numbers 0..4), got 7"),
    (dict(frames=[0, 1.0]), TypeError, "`frames[1]` must be an int frame number, got float 1.0"),
    (dict(frames=[]), ValueError, "`frames` must name at least one frame, got none"),
    (dict(frames=3), TypeError, "`frames` must be a sequence of frame numbers, got int"),
    (dict(frames=[0], keep=13), ValueError, "`keep` must be <= 12, got 13"),
    (dict(frames=[0], keep=0), ValueError, "`keep` must be >= 1, got 0"),
    (dict(frames=[0], keep=(6, 5)), ValueError,
     "`keep` must be a range (min, max) with 1 <= min <= max <= 12, got (6, 5)"),
    (dict(frames=[0], keep=0.5), TypeError,
     "`keep` must be None, an int or a (min, max) pair of ints, got float 0.5"),
    (dict(frames=[0], shuffle=1), TypeError, "`shuffle` must be a bool, got int 1"),
    (dict(frames=[0], normalize="pixels"), ValueError,
     "`normalize` must be one of 'auto', 'image', 'bbox', 'none', got 'pixels'"),
    (dict(frames=[0], rng="seed"), TypeError,
     "`rng` must be None, an int or a numpy.random.Generator, got str"),
])
def test_graphs_bad_arguments(seq, kwargs, exc, message):
    frames = kwargs.pop("frames")
    with pytest.raises(exc, match="^" + re.escape(message) + "$"):
        seq.graphs(frames, **kwargs)


# --------------------------------------------------------------------------- real data


@pytest.mark.dataset("cmu-house")
def test_real_house_sequence():
    from transync.matching import gaussian_edge_affinity, match_graphs

    seq = load_cmu_sequence()
    assert seq.name == "house"
    assert seq.points.shape == (111, 30, 2)
    assert seq.frames.tolist() == list(range(111))
    assert seq.image_sizes is not None and seq.image_sizes.tolist()[0] == [576, 384]
    accuracies = []
    for start in (0, 50, 100):
        prob = seq.graphs([start, start + 10], rng=start)
        g1, g2 = prob.graphs
        affinity = gaussian_edge_affinity(g1, g2, **LANDMARK_AFFINITY)
        result = match_graphs(g1, g2, method="rrwm", affinity=affinity)
        accuracies.append(np.mean(result.assignment == prob.truth(0, 1)))
    # measured: 1.0 on 20 random starts with a gap of 10 (frames shuffled)
    assert min(accuracies) >= 0.95, accuracies


def test_frame_number_beyond_int64_and_a_byte_order_mark(tmp_path):
    """A 20-digit frame number is refused with the file named (before: a raw OverflowError);
    a label file with a UTF-8 byte-order mark reads as without."""
    _sequence(tmp_path, numbers=[1, 99999999999999999999])
    _err(ValueError, tmp_path,
         f"{tmp_path / 'label' / 'hotel99999999999999999999'}: frame number "
         "99999999999999999999 out of range (at most 4611686018427387903)")
    other = _sequence(tmp_path / "bom", n_frames=3)
    plain = load_cmu_sequence(other)
    f = other / "label" / "hotel2"
    f.write_bytes(b"\xef\xbb\xbf" + f.read_bytes())
    np.testing.assert_array_equal(load_cmu_sequence(other).points, plain.points)


def test_numbers_and_lines_are_read_strictly(tmp_path):
    """`1_5` read as 15 and full-width digits as numbers; a form feed split a row of four
    numbers into two rows (30 landmarks from 15 lines) and shifted the line numbers."""
    _sequence(tmp_path, n_frames=3)
    bad = tmp_path / "label" / "hotel2"
    for token in ("1_5", "\uff11", "2\x00"):
        bad.write_text(_rows(BASE[:4]) + f"1.0 {token}\n" + _rows(BASE[5:]))
        _err(ValueError, tmp_path, f"{bad}, line 5: expected two numbers `x y`, got "
                                   f"{('1.0 ' + token).strip()!r}")
    bad.write_text(_rows(BASE[:2]).replace("\n", "\x0c", 1) + _rows(BASE[2:]))
    with pytest.raises(ValueError, match=re.escape(f"{bad}, line 1: expected 2 columns `x y`, "
                                                   "got 4")):
        load_cmu_sequence(tmp_path)
    bad.write_text(_rows(BASE).replace("\n", "\r"))              # old Mac line ends: still rows
    assert load_cmu_sequence(tmp_path).n_landmarks == 12


def test_label_files_not_silently_skipped(tmp_path):
    """`hotel6.txt` beside hotel1..5 was skipped without a word; a prefix with a digit
    (`cam2_1`) was not recognized at all."""
    _sequence(tmp_path, n_frames=5)
    (tmp_path / "label" / "hotel6.txt").write_text(_rows(BASE))
    _err(ValueError, tmp_path,
         f"{tmp_path / 'label' / 'hotel6.txt'}: looks like frame 6 of 'hotel' but label files are "
         "named `hotel<N>` without an extension; rename or remove it")
    seq = load_cmu_sequence(_sequence(tmp_path / "cam", name="cam2_", n_frames=3))
    assert seq.name == "cam2_" and seq.frames.tolist() == [0, 1, 2]
    (tmp_path / "label" / "hotel6.txt").unlink()
    (tmp_path / "label" / "hotel3").unlink()                 # frame 2 a folder, or a dead link
    (tmp_path / "label" / "hotel3").mkdir()
    _err(ValueError, tmp_path, f"{tmp_path / 'label' / 'hotel3'}: label file of frame 2 of "
                               "'hotel' is a folder; expected a text file of `x y` rows")
    (tmp_path / "label" / "hotel3").rmdir()
    (tmp_path / "label" / "hotel3").symlink_to(tmp_path / "nowhere")
    _err(ValueError, tmp_path, f"{tmp_path / 'label' / 'hotel3'}: label file of frame 2 of "
                               "'hotel' is a broken link; expected a text file of `x y` rows")


def test_png_size_beyond_the_format_and_bad_paths(tmp_path):
    _sequence(tmp_path, n_frames=2, images=True)
    _png(tmp_path / "images" / "hotel.seq1.png", 2**32 - 1, 30)
    _err(ValueError, tmp_path, f"{tmp_path / 'images' / 'hotel.seq1.png'}: PNG header gives "
                               "4294967295 x 30 pixels, beyond the format's limit of 2147483647 "
                               "(a damaged header)")
    _err(TypeError, 5, "`path` must be a path (str or os.PathLike), got int 5")
    _err(ValueError, "", "`path` must be a path, got '' (write '.' for the working folder)")
    with pytest.raises(ValueError, match="`path`: cannot expand '~nosuchuser_x/house'"):
        load_cmu_sequence("~nosuchuser_x/house")


def test_landmark_sequence_checks_its_fields():
    """The constructor checked nothing: 3 frames of points with 2 frame numbers, repeated
    frames (silently the last row), fractional frames (truncated) and NaN points passed."""
    P = np.zeros((3, 4, 2))
    ok = LandmarkSequence("toy", P, [0, 1, 2], None, None, ".")
    assert ok.n_frames == 3 and ok.frames.dtype == np.int64
    for kwargs, exc, msg in [
        (dict(frames=[0, 1]), ValueError, "`frames` must hold one frame number per row"),
        (dict(frames=[0, 1, 1]), ValueError, "`frames` must not repeat a frame number"),
        (dict(frames=[0.5, 1, 2]), TypeError, "`frames`"),
        (dict(points=np.full((3, 4, 2), np.nan)), ValueError, "`points` must be finite"),
        (dict(points=np.zeros((3, 4, 3))), ValueError, r"`points` must have shape \(n_frames"),
        (dict(image_sizes=[[4, 3]] * 3), ValueError, "must be given together"),
        (dict(image_paths=("a",) * 3, image_sizes=[[4, 0]] * 3), ValueError,
         "`image_sizes` must hold a positive"),
    ]:
        args = dict(name="toy", points=P, frames=[0, 1, 2], image_paths=None,
                    image_sizes=None, source=".") | kwargs
        with pytest.raises(exc, match=msg):
            LandmarkSequence(**args)
