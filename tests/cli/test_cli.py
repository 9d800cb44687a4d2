import argparse
import json
import re
import os
import subprocess
import sys
import types

import numpy as np
import pytest

from transync.cli import build_parser, main
from transync.datasets import make_permutation_collection, make_point_matching_problem
from transync.metrics import matching_accuracy


def test_match_command_recovers_a_planted_matching(tmp_path):
    p = make_point_matching_problem(n_inliers=15, deformation=0.0, rng=0)
    a, b = tmp_path / "a.txt", tmp_path / "b.npy"
    np.savetxt(a, p.g1.points * 640)           # pixel-like scale: the CLI rescales
    np.save(b, p.g2.points * 640)
    out = tmp_path / "m.json"
    assert main(["match", str(a), str(b), "--method", "rrwm", "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    assert matching_accuracy(np.array(res["assignment"]), p.truth) == 1.0


def test_sync_command_makes_pairs_consistent(tmp_path):
    c = make_permutation_collection(6, 8, corruption=0.2, rng=1)
    pairs = [[int(i), int(j), np.asarray(a).tolist()] for (i, j), a in c.pairwise.items()]
    src, out = tmp_path / "pairs.json", tmp_path / "labels.json"
    src.write_text(json.dumps({"pairs": pairs}))
    assert main(["sync", str(src), "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    labels = [np.array(lab) for lab in res["labels"]]
    assert len(labels) == 6 and all(lab.shape == (8,) for lab in labels)
    assert all(sorted(lab.tolist()) == list(range(8)) for lab in labels)


def _toy_trial(config, rng):
    if config["method"] == "spectral":
        return {"accuracy": 1.0}
    return {"accuracy": 1.0 - config["noise"] * rng.random()}


@pytest.fixture
def toy_registry(monkeypatch):
    """A tiny experiment registered under the name 'toy' (the real ones take ~10 s quick)."""
    from transync.experiments import REGISTRY
    from transync.experiments import Experiment, Sweep

    mod = types.ModuleType("transync_toy_experiment")
    mod.__doc__ = "Toy experiment for CLI tests."

    def build(*, quick=False):
        return Experiment(name="toy", trial=_toy_trial, trials=2 if quick else 5,
                          description="toy", sweeps=[
                              Sweep(name="noise", variable="noise", values=[0.0, 0.5],
                                    methods=["spectral", "other"])])

    mod.build = build
    monkeypatch.setitem(sys.modules, mod.__name__, mod)
    monkeypatch.setitem(REGISTRY, "toy", mod.__name__)


def test_experiment_list_and_unknown(capsys):
    assert main(["experiment", "--list"]) == 0
    listed = capsys.readouterr().out
    assert "pairwise" in listed and "sync" in listed
    assert main(["experiment", "no-such-thing"]) == 2


def test_experiment_quick_run_and_resume(tmp_path, capsys, toy_registry):
    out = tmp_path / "exp"
    args = ["experiment", "toy", "--quick", "--out", str(out), "--no-progress"]
    assert main(args) == 0
    first = capsys.readouterr().out
    assert (out / "results.sqlite").exists() and (out / "toy.png").exists()
    assert main(args) == 0
    assert capsys.readouterr().out.startswith("0 new trials")
    assert "new trials (0 failed)" in first


def _failing_trial(config, rng):
    if config["method"] == "other":
        raise ValueError("frame 0: all landmarks coincide")
    return {"accuracy": 1.0}


def test_failed_trials_say_why_in_one_warning(tmp_path, capsys, toy_registry, monkeypatch):
    """Every trial failing on a bad data folder printed only "(14 failed)" and exit 1; the
    reason was in a traceback stored in results.sqlite."""
    import transync_toy_experiment as mod

    build = mod.build
    monkeypatch.setattr(mod, "build", lambda **kw: build(**kw).__class__(
        **{**build(**kw).__dict__, "trial": _failing_trial}))
    out = tmp_path / "exp"
    assert main(["experiment", "toy", "--quick", "--out", str(out), "--no-progress"]) == 1
    cap = capsys.readouterr()
    assert "8 new trials (4 failed)" in cap.out
    lines = cap.err.splitlines()
    assert len(lines) == 1, cap.err
    assert re.fullmatch(r"transync: warning: 4 trial\(s\) failed; the first \(sweep 'noise', "
                        r"trial 0\): ValueError: frame 0: all landmarks coincide \(tracebacks "
                        r"stored in .*results\.sqlite; rerun to retry them\)", lines[0]), lines[0]


def test_demo_writes_summary(tmp_path, toy_registry):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--experiments", "toy", "--no-progress"]) == 0
    text = (out / "summary.md").read_text()
    assert "# transync demo" in text and "| spectral | 1.000 |" in text
    assert "too few to rank the methods" in text      # a one-trial table is no ranking
    assert (out / "toy" / "toy.png").exists()


def test_python_dash_m_entry_point():
    r = subprocess.run([sys.executable, "-m", "transync", "--version"], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.startswith("transync ")


def test_missing_input_file_is_a_clear_error(tmp_path, capsys):
    assert main(["match", str(tmp_path / "nope.txt"), str(tmp_path / "nope2.txt")]) == 2
    err = capsys.readouterr().err
    assert err == f"transync: error: no such file: {tmp_path / 'nope.txt'}\n"


def test_help_does_not_import_heavy_modules():
    code = ("import sys\nfrom transync.cli import main\ntry:\n    main(['--help'])\n"
            "except SystemExit:\n    pass\n"
            "print(sorted(m for m in ('cv2', 'matplotlib', 'skimage') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.strip().endswith("[]"), r.stdout + r.stderr


@pytest.fixture
def bad_inputs(tmp_path):
    import cv2

    (tmp_path / "empty.txt").write_text("")
    (tmp_path / "header.csv").write_text("x,y\n1,2\n3,4\n")
    (tmp_path / "ragged.txt").write_text("1 2\n3 4\n\n5 6 7\n")
    (tmp_path / "nan.txt").write_text("1 2\nnan 4\n")
    cv2.imwrite(str(tmp_path / "img.png"), np.full((8, 8), 128, np.uint8))
    np.savetxt(tmp_path / "p2.txt", np.arange(10.0).reshape(5, 2))
    np.savetxt(tmp_path / "p3.txt", np.arange(15.0).reshape(5, 3))
    np.save(tmp_path / "vec.npy", np.arange(4.0))
    (tmp_path / "empty.json").write_text("{}")
    (tmp_path / "broken.json").write_text('{"pairs": [\n[0, 1, [0, 1]],\n')
    (tmp_path / "badpair.json").write_text('{"pairs": [[0, 1, "abc"]]}')
    (tmp_path / "one.txt").write_text("1 1\n")
    (tmp_path / "near.txt").write_text("0 0\n1 0\n")
    (tmp_path / "far.txt").write_text("0 0\n1000 0\n")
    (tmp_path / "deep.json").write_text('{"pairs": ' + "[" * 5000 + "]" * 5000 + "}")
    (tmp_path / "afile").write_text("")
    (tmp_path / "huge.txt").write_text("1e308 1e308\n-1e308 -1e308\n0 0\n")
    (tmp_path / "gap.csv").write_text("0, 0\n1,,0\n")
    (tmp_path / "tail.csv").write_text("0;0\n1;0;\n")
    if hasattr(os, "mkfifo"):
        os.mkfifo(tmp_path / "fifo")
    return tmp_path


_needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")


@pytest.mark.parametrize("argv, expected", [
    (["sync", "{d}/empty.json"], r"empty\.json: expected a JSON object \{\"pairs\""),
    (["sync", "{d}/broken.json"], r"broken\.json, line 3: not valid JSON"),
    (["sync", "{d}/badpair.json"], r"badpair\.json: pairs\[0\] must be \[i, j, map\]"),
    (["sync", "{d}/deep.json"], r"deep\.json: JSON nested too deeply to read"),
    (["sync", "{d}"], r"is a folder; expected a JSON file"),
    # an output folder that cannot be made is refused before the work, not after
    (["kernel", "MUTAG", "--out", "{d}/afile/sub"],
     r"cannot create the output folder .*afile/sub: .*afile is not a folder"),
    (["experiment", "pairwise", "--quick", "--out", "{d}/afile/sub"],
     r"cannot create the output folder .*afile/sub: .*afile is not a folder"),
    (["experiment", "pairwise", "--quick", "--out", ""], r"output folder: got an empty path"),
    (["demo", "--experiments", "foo", "--out", "{d}/demo"],
     r"unknown experiment 'foo'; choose from cmu, homography, kernels, multigraph, pairwise, subgraph, sync"),
    (["experiment", "nope"], r"unknown experiment 'nope'; choose from"),
    (["match", "{d}/empty.txt", "{d}/p2.txt"], r"empty\.txt: no points found"),
    (["match", "{d}/header.csv", "{d}/p2.txt"],
     r"header\.csv, line 1: expected numbers, got 'x,y'"),
    (["match", "{d}/ragged.txt", "{d}/p2.txt"],
     r"ragged\.txt, line 4: expected 2 coordinates \(as on line 1\), got 3"),
    (["match", "{d}/nan.txt", "{d}/p2.txt"], r"nan\.txt, line 2: coordinates must be finite"),
    # an empty field was skipped: "1,,0" read as the point (1, 0)
    (["match", "{d}/gap.csv", "{d}/p2.txt"], r"gap\.csv, line 2: empty field in '1,,0'"),
    (["match", "{d}/tail.csv", "{d}/p2.txt"], r"tail\.csv, line 2: empty field in '1;0;'"),
    # a named pipe was reported as a missing file (sync, homography)
    pytest.param(["match", "{d}/fifo", "{d}/p2.txt"], r"fifo is not a regular file",
                 marks=_needs_fifo),
    pytest.param(["sync", "{d}/fifo"], r"fifo is not a regular file \(a pipe, socket or "
                 r"device\); expected a JSON file", marks=_needs_fifo),
    pytest.param(["homography", "{d}/fifo", "{d}/img.png", "--out", "{d}/h"],
                 r"fifo is not a regular file .*; expected an image file", marks=_needs_fifo),
    (["match", "{d}/img.png", "{d}/p2.txt"], r"img\.png: not a text file of points"),
    (["match", "{d}/vec.npy", "{d}/p2.txt"], r"vec\.npy: expected an array of shape"),
    (["match", "{d}/one.txt", "{d}/p2.txt"], r"need at least 2 points in each set"),
    (["match", "{d}/near.txt", "{d}/far.txt", "--sigma2", "1e-6"],
     r"(edge affinity is zero for every candidate pair|`sigma2`=1e-06 is too small)"),
    (["match", "{d}/p2.txt", "{d}/p3.txt"],
     r"different dimensions: .*p2\.txt has 2 coordinates a point, .*p3\.txt has 3"),
    # a coordinate range beyond float64: the scale was inf, every point 0, JSON "Infinity"
    (["match", "{d}/huge.txt", "{d}/p2.txt"],
     r"huge\.txt: the coordinates span more than the largest float \(from -1e\+308 to "
     r"1e\+308\); rescale them"),
    (["collection", "{d}/p2.txt", "{d}/huge.txt"], r"huge\.txt: the coordinates span more"),
    (["collection", "{d}/p2.txt"], r"need at least 2 point sets to match, got 1"),
    (["collection", "{d}/p2.txt", "{d}/p3.txt"], r"different dimensions: .*p3\.txt has 3"),
    (["collection", "{d}/p2.txt", "{d}/header.csv"], r"header\.csv, line 1"),
    (["collection", "{d}/p2.txt", "{d}/near.txt", "--n-universe", "3"],
     r"`--n-universe` must be >= the largest graph's size 5"),
    (["collection", "{d}/p2.txt", "{d}/near.txt", "--solver", "cao", "--sync", "none"],
     r"`--partial` must be 'dummies' .* CAO composes full permutations"),
    (["collection", "{d}/p3.txt", "{d}/p3.txt", "--affinity", "length+angle", "--edges",
      "full"],
     r"length\+angle needs 2-d points"),
    (["collection", "{d}/p3.txt", "{d}/p3.txt", "--edges", "full", "--verify", "affine"],
     r"`--verify affine` fits plane transforms .* graph 0 has 3-d points"),
    (["collection", "{d}/p2.txt", "{d}/near.txt", "--verify", "affine", "--partial",
      "dummies"], r"`--verify` checks matches between the graphs' points"),
])
def test_errors_are_one_line_and_exit_2(bad_inputs, capsys, argv, expected):
    argv = [a.format(d=bad_inputs) for a in argv]
    assert main(argv) == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    lines = cap.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("transync: error: "), cap.err
    assert re.search(expected, lines[0]), lines[0]
    assert not (bad_inputs / "demo").exists()


@pytest.mark.parametrize("argv", [["experiment", "pairwise", "--trials", "0"],
                                  ["experiment", "pairwise", "--workers", "-1"],
                                  ["match", "a", "b", "--sigma2", "nan"],
                                  ["match", "a", "b", "--method", "bogus"]])
def test_bad_options_are_usage_errors(capsys, argv):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("transync: error: argument --"), err
    assert "(see `transync " in err


@pytest.mark.parametrize("argv", [["collection", "x", "y"], ["kernel", "MUTAG"],
                                  ["experiment", "pairwise"], ["match", "x", "y"]])
def test_unknown_options_point_to_the_subcommand_help(capsys, argv):
    """argparse reports a subcommand's unknown option from the top-level parser: the message
    said "see `transync --help`", which does not list the subcommand's options."""
    with pytest.raises(SystemExit) as exc:
        main(argv + ["--bogus"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err == (f"transync: error: unrecognized arguments: --bogus "
                   f"(see `transync {argv[0]} --help`)\n")


def test_unknown_top_level_option_points_to_the_top_level_help(capsys):
    with pytest.raises(SystemExit):
        main(["--bogus", "sync", "x.json"])
    assert capsys.readouterr().err == ("transync: error: unrecognized arguments: --bogus "
                                       "(see `transync --help`)\n")


def test_every_subcommand_hides_progress_with_no_progress():
    """`collection` took only --quiet; every other subcommand with bars takes --no-progress."""
    parser = build_parser()
    for argv in (["collection", "a.txt", "b.txt"], ["kernel", "MUTAG"],
                 ["experiment", "pairwise"], ["homography", "a.png", "b.png"]):
        args = parser.parse_args(argv + ["--no-progress"])
        assert getattr(args, "quiet", None) or getattr(args, "no_progress", None), argv
    assert parser.parse_args(["collection", "a.txt", "b.txt", "--quiet"]).quiet


def test_help_says_each_default_once(capsys):
    for command in ("kernel", "collection", "experiment", "homography", "match", "sync"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        out = " ".join(capsys.readouterr().out.split())
        assert not re.search(r"default: [^()]*\) \(default", out), (command, out)


def test_debug_shows_the_traceback_and_unexpected_errors_stay_one_line(bad_inputs, capsys,
                                                                       monkeypatch):
    assert main(["--debug", "sync", str(bad_inputs / "empty.json")]) == 2
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err
    assert err.splitlines()[-1].startswith("transync: error: ")
    import transync.matching

    def boom(*args, **kwargs):
        raise RuntimeError("planted")

    monkeypatch.setattr(transync.matching, "match_graphs", boom)
    p = str(bad_inputs / "p2.txt")
    assert main(["match", p, p]) == 2
    err = capsys.readouterr().err
    assert err == ("transync: error: unexpected RuntimeError: planted (please report it; rerun "
                   "with --debug for the traceback)\n")


def test_error_notes_reach_the_one_line_message(bad_inputs, capsys, monkeypatch):
    """Where an error happened (the pair of an affinity, the chunk of an executor) travels as an
    exception note, which Python's traceback shows and str(exc) does not: the CLI printed the
    message without it."""
    import transync.matching

    def boom(*args, **kwargs):
        exc = ValueError("`g2` has none")
        exc.add_note("while building the affinity of graphs[0] (g1) and\ngraphs[1] (g2)")
        raise exc

    monkeypatch.setattr(transync.matching, "match_graphs", boom)
    p = str(bad_inputs / "p2.txt")
    assert main(["match", p, p]) == 2
    assert capsys.readouterr().err == (
        "transync: error: `g2` has none (while building the affinity of graphs[0] (g1) and "
        "graphs[1] (g2))\n")


@pytest.mark.filterwarnings("default")
def test_warnings_print_one_line_each(bad_inputs, capsys, monkeypatch):
    """A library warning during a command (a solver at its iteration budget) is one line on
    stderr, not Python's file:line format with the source line."""
    import warnings

    import transync.matching
    from transync.exceptions import ConvergenceWarning

    real = transync.matching.match_graphs

    def warns(*args, **kwargs):
        warnings.warn("match_graphs: stopped at\n its budget", ConvergenceWarning, stacklevel=2)
        return real(*args, **kwargs)

    monkeypatch.setattr(transync.matching, "match_graphs", warns)
    p = str(bad_inputs / "p2.txt")
    assert main(["match", p, p]) == 0
    err = capsys.readouterr().err
    assert err == "transync: warning: match_graphs: stopped at its budget\n"


def test_text_inputs_may_start_with_a_byte_order_mark(tmp_path, capsys):
    """Point files and sync JSON saved by editors that write a UTF-8 BOM read as without."""
    bom = b"\xef\xbb\xbf"
    pts = np.random.default_rng(0).random((6, 2))
    for name in ("a.txt", "b.txt"):
        (tmp_path / name).write_bytes(bom + "".join(f"{x} {y}\n" for x, y in pts).encode())
    (tmp_path / "p.json").write_bytes(bom + b'{"pairs": [[0, 1, [1, 0]], [1, 2, [0, 1]]]}')
    assert main(["match", str(tmp_path / "a.txt"), str(tmp_path / "b.txt")]) == 0
    assert json.loads(capsys.readouterr().out)["assignment"] == list(range(6))
    assert main(["sync", str(tmp_path / "p.json")]) == 0
    assert json.loads(capsys.readouterr().out)["labels"]


def test_sync_json_with_integers_beyond_int64_is_a_named_error(tmp_path, capsys):
    """A huge integer in an assignment was an 'unexpected OverflowError' (a fuzz found it)."""
    f = tmp_path / "big.json"
    f.write_text('{"pairs": [[1, 0, [100000000000000000000, 0]], [2, 0, [1, 0]]]}')
    assert main(["sync", str(f)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("transync: error: ") and "within int64" in err
    assert "unexpected" not in err


@pytest.mark.parametrize("method", ["hungarian", "sinkhorn"])
def test_linear_methods_use_a_unary_term_and_recover_shuffled_points(tmp_path, method):
    rng = np.random.default_rng(3)
    P = rng.random((12, 2)) * 500
    perm = rng.permutation(12)
    np.savetxt(tmp_path / "a.txt", P)
    np.savetxt(tmp_path / "b.txt", P[perm])
    out = tmp_path / "m.json"
    assert main(["match", str(tmp_path / "a.txt"), str(tmp_path / "b.txt"), "--method", method,
                 "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    truth = np.argsort(perm)                      # b[truth[i]] == a[i]
    assert res["assignment"] == truth.tolist()
    assert res["unary"].startswith("first-order linearization")


def test_experiment_seed_is_not_mistaken_for_stored_work(tmp_path, capsys, toy_registry):
    out = tmp_path / "exp"
    args = ["experiment", "toy", "--quick", "--out", str(out), "--no-progress", "--no-progress"]
    assert main(args) == 0
    assert capsys.readouterr().out.startswith("8 new trials")
    assert main([*args, "--seed", "1"]) == 0
    assert capsys.readouterr().out.startswith("8 new trials (0 failed)")
    assert main([*args, "--seed", "1"]) == 0
    assert "0 new trials (0 failed)" in capsys.readouterr().out


def test_corrupted_store_is_one_line(tmp_path, capsys, toy_registry):
    out = tmp_path / "exp"
    out.mkdir()
    (out / "results.sqlite").write_text("garbage" * 50)
    assert main(["experiment", "toy", "--quick", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"transync: error: {out / 'results.sqlite'} is not a readable")
    assert len(err.splitlines()) == 1 and "salvage" in err


@pytest.fixture(scope="module")
def scene():
    from transync.datasets import make_planar_scene

    return make_planar_scene(5, image_size=(320, 240), difficulty="moderate", rng=0)


def test_cli_homography(tmp_path, scene, capsys):
    import cv2

    from transync.metrics import corner_error

    paths = []
    for k, im in enumerate(scene.images[:4]):
        p = tmp_path / f"v{k}.png"
        cv2.imwrite(str(p), im)
        paths.append(str(p))
    out = tmp_path / "out"
    assert main(["homography", *paths, "--reference", "0", "--out", str(out),
                 "--features", "800", "--max-iter", "1"]) == 0
    data = json.loads((out / "homographies.json").read_text())
    H = np.array(data["homographies"])
    assert H.shape == (4, 3, 3)
    assert corner_error(H, scene.homographies[:4], image_size=(320, 240)).max() < 0.5
    assert len(list((out / "masks").glob("*.png"))) == 4
    assert (out / "mean_warped.png").exists() and (out / "report.md").exists()
    report = (out / "report.md").read_text()
    assert "dense refinement: on; view updates over 1 round(s): accepted" in report
    if "converged: False" in report:      # says why and what to change
        assert re.search(r"converged: False \(the corners still moved [\d.e+-]+ px in round 1, "
                         r"above the tolerance of 0.02 px; --max-iter allows more rounds\)",
                         report), report
    assert "views linked to the reference: all" in report and "black where no" in report
    assert "transync homography: sparse pairs" in capsys.readouterr().err    # progress shown
    assert main(["homography", *paths[:2], "--out", str(tmp_path / "quiet"), "--features", "800",
                 "--max-iter", "1", "--no-progress"]) == 0
    assert capsys.readouterr().err == ""
    # a second run on fewer images into the same folder left the first run's masks 2 and 3
    (out / "masks" / "notes.txt").write_text("mine")
    assert main(["homography", *paths[:2], "--out", str(out), "--features", "800",
                 "--max-iter", "1", "--no-progress"]) == 0
    assert sorted(p.name for p in (out / "masks").iterdir()) == [
        "mask_000.png", "mask_001.png", "notes.txt"]
    assert "- removed 2 mask file(s) of an earlier run" in capsys.readouterr().out
    assert "mask_002.png, mask_003.png" in (out / "report.md").read_text()
    # a file where the masks folder goes: refused before anything moves (the new
    # homographies.json had replaced the earlier one, then the masks failed)
    blocked = tmp_path / "blocked"
    blocked.mkdir()
    (blocked / "homographies.json").write_text("earlier")
    (blocked / "masks").write_text("a file")
    assert main(["homography", *paths[:2], "--out", str(blocked), "--features", "800",
                 "--max-iter", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert re.search(r"cannot write .*mask_000\.png: .*blocked/masks exists and is not a "
                     r"folder", err), err
    assert (blocked / "homographies.json").read_text() == "earlier"
    assert sorted(p.name for p in blocked.iterdir()) == ["homographies.json", "masks"]


def test_stale_masks_are_only_names_the_command_writes(tmp_path):
    from transync.cli._homography import _stale_masks

    for name in ("mask_000.png", "mask_001.png", "mask_002.png", "mask_1000.png",
                 "mask_0042.png", "mask_\u0660\u0660\u0667.png", "mask_003.PNG", "mine.png"):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "mask_005.png").mkdir()
    assert [p.name for p in _stale_masks(tmp_path, 2)] == ["mask_002.png", "mask_1000.png"]


def test_cli_homography_failures_leave_no_output_folder(tmp_path, capsys):
    import cv2

    paths = []
    for k in range(2):                      # blank images: nothing to relate
        p = tmp_path / f"blank{k}.png"
        cv2.imwrite(str(p), np.full((120, 160), 90, np.uint8))
        paths.append(str(p))
    out = tmp_path / "out"
    assert main(["homography", *paths, "--out", str(out), "--no-dense"]) == 2
    err = capsys.readouterr().err
    assert re.match(r"transync: error: .*(no two of the 2 images could be related|no pair of "
                    r"the 2 views could be matched)", err), err
    assert len(err.splitlines()) == 1 and not out.exists()
    (tmp_path / "notes.txt").write_text("hello")
    assert main(["homography", paths[0], str(tmp_path / "notes.txt"), "--out", str(out)]) == 2
    assert "notes.txt: not an image format OpenCV can read" in capsys.readouterr().err
    assert main(["homography", paths[0], str(tmp_path / "gone.png"), "--out", str(out)]) == 2
    assert "no such file: " in capsys.readouterr().err
    assert main(["homography", str(tmp_path), paths[0], "--out", str(out)]) == 2
    assert "a folder, not an image file" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:                  # argparse's own exit
        main(["homography", *paths, "--features", str(10**11), "--out", str(out)])
    assert exc.value.code == 2
    assert "argument --features: expected a positive integer and <= 1000000" in \
        capsys.readouterr().err
    assert main(["homography", *paths, "--reference", "2", "--out", str(out)]) == 2
    assert "--reference must be an image index in [0, 1], got 2" in capsys.readouterr().err
    assert not out.exists()


def test_datasets_command(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path / "nowhere"))
    assert main(["datasets"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("transync: error: TRANSYNC_DATA=") and "does not exist" in err
    (tmp_path / "oxford-graf").mkdir()
    (tmp_path / "oxford-graf" / "img1.ppm").write_bytes(b"P6")
    (tmp_path / "tu" / "MUTAG").mkdir(parents=True)
    (tmp_path / "results").mkdir()
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path))
    assert main(["datasets"]) == 0
    out = capsys.readouterr().out.splitlines()
    # the folders transync reads by name, present or not, and the others apart
    assert out[0] == f"data home: {tmp_path}"
    assert out[1].split()[:2] == ["cmu-house", "missing"] and "give load_cmu_sequence" in out[1]
    assert out[2].split()[:3] == ["tu", "0", "files"] and out[2].endswith("sets: MUTAG)")
    assert out[3].split()[:3] == ["oxford-graf", "1", "files"] and "load_graf" in out[3]
    assert out[4].split()[:2] == ["adelaidermf", "missing"]
    assert out[5] == "  other folders, not read by name: results"


def test_sync_command_takes_matrices_like_the_library(tmp_path):
    """A pair may be given as an assignment or as a 0/1 matrix, as synchronize_permutations
    accepts; both forms give the same labels."""
    from transync.permutations import assignment_to_matrix

    c = make_permutation_collection(5, 6, corruption=0.2, rng=2)
    as_lists = [[int(i), int(j), np.asarray(a).tolist()] for (i, j), a in c.pairwise.items()]
    as_mats = [[i, j, assignment_to_matrix(a, 6, dtype=int).tolist()] for i, j, a in as_lists]
    outs = []
    for name, pairs in (("lists", as_lists), ("mats", as_mats)):
        src, out = tmp_path / f"{name}.json", tmp_path / f"{name}-labels.json"
        src.write_text(json.dumps({"pairs": pairs}))
        assert main(["sync", str(src), "--out", str(out)]) == 0
        outs.append(json.loads(out.read_text())["labels"])
    assert outs[0] == outs[1]


def test_cli_defaults_and_choices_are_the_librarys():
    """One default per concept: the parser (built without importing the library) agrees with
    the library's own defaults and choices."""
    import inspect

    from transync.cli import _match
    from transync.matching import DEFAULT_SIGMA2, match_graphs
    from transync.synchronization import _permutations

    assert _match.DEFAULT_SIGMA2 == DEFAULT_SIGMA2
    assert inspect.signature(match_graphs).parameters["sigma2"].default == DEFAULT_SIGMA2
    assert _match.SYNC_METHODS == _permutations._METHODS
    from transync import multigraph

    assert _match.COLLECTION_SOLVERS == multigraph.SOLVERS
    assert _match.COLLECTION_SYNCS == (*multigraph.SYNCS, "none")
    assert _match.PARTIAL == multigraph.PARTIAL
    parser = build_parser()
    args = parser.parse_args(["match", "a.txt", "b.txt"])
    assert args.sigma2 == DEFAULT_SIGMA2


@pytest.mark.parametrize("command", ["demo", "experiment", "match", "collection", "sync",
                                     "homography", "kernel", "datasets"])
def test_every_option_has_help_and_shows_its_default(command):
    sub = next(a for a in build_parser()._actions
               if isinstance(a, argparse._SubParsersAction)).choices[command]
    text = sub.format_help()
    for action in sub._actions:
        if action.help == argparse.SUPPRESS or not action.option_strings or action.dest == "help":
            continue
        assert action.help, f"{command} {action.option_strings[0]} has no help"
        if action.default is not None and action.default is not False:     # 0 too (== False)
            assert "(default" in sub._get_formatter()._get_help_string(action), \
                f"{command} {action.option_strings[0]} does not show its default"
        if action.choices:
            assert "{" + ",".join(map(str, action.choices)) + "}" in text


def test_homography_report_says_when_every_dense_update_was_rejected():
    from transync.cli._homography import _dense_line, _views_line

    hist = [{"dense_views": {1: {"status": "rejected_sparse"}, 2: {"status": "diverged"}}}]
    res = types.SimpleNamespace(info={"history": hist}, n_iter=1,
                                homographies=np.stack([np.eye(3), np.full((3, 3), np.nan)]))
    on = types.SimpleNamespace(no_dense=False)
    line = _dense_line(res, on)
    assert "every dense update was rejected" in line and "sparse estimate" in line
    assert "diverged 1" in line and "rejected sparse 1" in line
    assert "off" in _dense_line(res, types.SimpleNamespace(no_dense=True))
    assert "b.png" in _views_line(res, ["a.png", "b.png"])


def _planted_point_sets(tmp_path, rng, d=15, n_sets=6):
    """Point sets that each keep part of ``d`` universe points, shuffled; their universe ids."""
    U = rng.random((d, 2))
    files, ids = [], []
    for g in range(n_sets):
        keep = np.sort(rng.choice(d, rng.integers(d - 4, d + 1), replace=False))
        perm = rng.permutation(len(keep))
        path = tmp_path / f"view{g}.txt"
        np.savetxt(path, U[keep][perm])
        files.append(str(path))
        ids.append(keep[perm])
    return files, ids


@pytest.mark.parametrize("extra", [[], ["--partial", "dummies"], ["--mode", "offline"],
                                   ["--verify", "affine"],
                                   ["--verify", "similarity", "--verify-threshold", "0.3"]])
def test_collection_command_matches_point_sets_of_different_sizes(tmp_path, extra):
    files, ids = _planted_point_sets(tmp_path, np.random.default_rng(1))
    out = tmp_path / "res.json"
    assert main(["collection", *files, "--edges", "full", "--sigma2", "0.005", "--quiet",
                 "--out", str(out), *extra]) == 0
    res = json.loads(out.read_text())
    assert res["sizes"] == [len(i) for i in ids]
    assert len(res["labels"]) == len(files) and res["consistency"] == 1.0
    for i, j, m in res["pairs"]:                 # every map is the planted one, -1 included
        expect = [int(np.flatnonzero(ids[j] == u)[0]) if u in ids[j] else -1 for u in ids[i]]
        assert m == expect
    if not extra:
        assert res["n_universe"] == 15 and "estimated" in res["n_universe_rule"]
    if "--verify" in extra:
        assert res["verify"] == extra[1] and res["verified_pairs"] == len(res["pairs"])
    elif "dummies" in extra:            # auto: the dummy-node baseline verifies nothing
        assert res["verify"] == "auto" and res["verified_pairs"] is None
        assert not res["verification_used"]
    else:                               # auto: sets of different sizes are verified
        assert res["verify"] == "auto" and res["verified_pairs"] == len(res["pairs"])
    assert res["verification_used"] == (res["verified_pairs"] is not None)


@pytest.mark.parametrize("argv", [["kernel", "NO_SUCH_SET"], ["homography", "a.png", "b.png"]])
def test_an_output_path_that_is_a_file_is_refused_before_the_work(tmp_path, capsys, argv):
    """`kernel` computed its Gram matrix and cross-validation (minutes) before saying that
    --out was a file; both long commands now check it first (before even reading the input:
    the error is the output's, not the missing data set's or images')."""
    out = tmp_path / "taken"
    out.write_text("x")
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "exists and is not a folder" in err and err.count("\n") == 1


def test_sync_is_deterministic_above_the_dense_limit(tmp_path):
    # above 2000 nodes the eigensolver starts from a random block; the command passed no seed
    # and two runs of one file gave objectives 6108 .. 6616 (70 % of the maps different)
    c = make_permutation_collection(n_objects=75, n_nodes=30, corruption=0.85, rng=1)
    rng = np.random.default_rng(0)
    pairs = []
    for (i, j), a in c.pairwise.items():
        a = np.asarray(a).copy()
        a[rng.random(a.size) < 0.3] = -1
        pairs.append([int(i), int(j), a.tolist()])
    src = tmp_path / "pairs.json"
    src.write_text(json.dumps({"pairs": pairs}))
    outs = []
    for k in range(2):
        out = tmp_path / f"out{k}.json"
        assert main(["sync", str(src), "--out", str(out)]) == 0
        outs.append(json.loads(out.read_text()))
    assert outs[0]["info"]["solver"] == "matrix_free"
    assert outs[0]["labels"] == outs[1]["labels"] and outs[0]["objective"] == outs[1]["objective"]


@pytest.mark.parametrize("cmd", [["sync", "x.json"], ["collection", "x"], ["homography", "a", "b"],
                                 ["kernel", "MUTAG"], ["experiment", "sync"]])
def test_a_negative_seed_is_a_usage_error_naming_the_option(cmd, capsys):
    # collection and homography passed it on, and the library refused its `rng` argument
    with pytest.raises(SystemExit) as exc:
        main(cmd + ["--seed", "-1"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "argument --seed: expected an integer >= 0, got -1" in err


def test_library_errors_name_the_commands_options(tmp_path, capsys):
    # the messages named match_collection's arguments (`n_universe`, verify='affine') and
    # suggested library calls (gaussian_edge_affinity) instead of the options
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    c, d = tmp_path / "c.txt", tmp_path / "d.txt"
    a.write_text("0 0\n1 0\n0 1\n1 1\n2 3\n")
    b.write_text("0 0\n1 0\n0 1\n1 1\n2 2\n")
    c.write_text("0.13 0.71\n0.92 0.05\n0.44 0.38\n0.67 0.99\n")   # no two equal lengths
    d.write_text("0.21 0.64\n0.83 0.17\n0.49 0.31\n0.58 0.93\n")
    cases = [(["collection", str(a), str(b), "--n-universe", "3", "--quiet"],
              "`--n-universe` must be >="),
             (["collection", str(a), str(b), "--verify-threshold", "0.3", "--quiet"],
              "pass --verify affine"),
             (["match", str(c), str(d), "--sigma2", "1e-300"], "increase --sigma2")]
    for argv, want in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and want in err, err
        assert "gaussian_edge_affinity" not in err and "n_universe" not in err


def test_sync_json_takes_the_sizes_the_library_asks_for(tmp_path, capsys):
    """An object in no pair: the error points to the JSON's "sizes" (not to a library
    argument the command does not have), and with "sizes" given it gets its own slots."""
    f = tmp_path / "p.json"
    f.write_text('{"pairs": [[0, 2, [1, 0]]]}')
    assert main(["sync", str(f)]) == 2
    err = capsys.readouterr().err
    assert 'give "sizes": [n_0, n_1, ...] in the JSON' in err and "sizes=" not in err
    f.write_text('{"pairs": [[0, 2, [1, 0]]], "sizes": [2, 3, 2]}')
    assert main(["sync", str(f)]) == 0
    labels = json.loads(capsys.readouterr().out)["labels"]
    assert [len(lab) for lab in labels] == [2, 3, 2]
    assert labels[0][0] == labels[2][1] and labels[0][1] == labels[2][0]
    assert not set(labels[1]) & (set(labels[0]) | set(labels[2]))
    f.write_text('{"pairs": [[0, 2, [1, 0]]], "sizes": [2, "x"]}')
    assert main(["sync", str(f)]) == 2
    assert '"sizes" must be a list of node counts' in capsys.readouterr().err


@pytest.mark.parametrize("finish_first", [False, True])
def test_interrupted_experiment_says_what_is_on_disk(tmp_path, capsys, monkeypatch,
                                                     finish_first):
    """Ctrl-C before any trial finished said "finished trials are saved in .../results.sqlite",
    a file that did not exist (the kernels experiment's Gram cache was there, not the store)."""
    import transync.cli._experiment as cli_exp
    from transync.experiments import Experiment, Sweep

    calls = []

    def trial(config, rng):
        calls.append(1)
        if len(calls) > int(finish_first):
            raise KeyboardInterrupt
        return {"v": 1.0}

    exp = Experiment(name="toy", trial=trial, trials=3, sweeps=[
        Sweep(name="s", variable="x", values=[0], methods=["m"], metrics=("v",))])
    monkeypatch.setattr(cli_exp, "_build", lambda *a, **k: exp)
    out = tmp_path / "run"
    if not finish_first:                      # a cache from an earlier stage of the run
        (out / "cache").mkdir(parents=True)
        (out / "cache" / "gram.npz").write_bytes(b"x")
    assert main(["experiment", "pairwise", "--out", str(out), "--no-progress"]) == 130
    err = capsys.readouterr().err
    if finish_first:
        assert err == (f"transync: interrupted; finished trials are saved in "
                       f"{out / 'results.sqlite'}; run the same command again to resume\n")
        assert (out / "results.sqlite").is_file()
    else:
        assert err == (f"transync: interrupted; no trial had finished, so none is stored; the "
                       f"computations cached in {out / 'cache'} are reused when you run the "
                       f"same command again\n")


def test_resume_hint_reads_the_store_of_any_folder_name(tmp_path):
    """The store was opened as 'file:{path}?mode=ro': a '?' or '#' in a folder name cut the
    path there, and SQLite created an empty file at the cut (read-write) and found no trial;
    without a cache the hint read "... none is stored when you run the same command again"."""
    import sqlite3

    from transync.cli._experiment import _resume_hint

    for name in ("a?b", "c#d", "e%41f", "g h"):
        out = tmp_path / name / "run"
        out.mkdir(parents=True)
        assert _resume_hint(out) == ("no trial had finished, so none is stored; run the same "
                                     "command again to start over")
        con = sqlite3.connect(out / "results.sqlite")
        con.execute("CREATE TABLE trials (x)")
        con.execute("INSERT INTO trials VALUES (1)")
        con.commit()
        con.close()
        assert _resume_hint(out).startswith(f"finished trials are saved in {out}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a?b", "c#d", "e%41f", "g h"]


def test_homography_report_says_why_rounds_did_not_converge():
    """The report said only "converged: False"; it now names the last change, the tolerance
    and the option that allows more rounds."""
    from transync.cli._homography import _unconverged_note
    from transync.homography import DenseOptions

    hist = [{"iteration": 1, "max_corner_change": 0.5}, {"iteration": 2, "max_corner_change": 0.25}]
    res = types.SimpleNamespace(converged=False, info={"history": hist,
                                                       "options": DenseOptions(tol=0.1)})
    assert _unconverged_note(res) == (" (the corners still moved 0.25 px in round 2, above the "
                                      "tolerance of 0.1 px; --max-iter allows more rounds)")
    assert _unconverged_note(types.SimpleNamespace(converged=True, info=res.info)) == ""


def test_sigterm_is_an_interrupt_with_its_resume_hint(monkeypatch, capsys, tmp_path):
    """SIGTERM (a scheduler's stop, `timeout`) killed the CLI silently with status 143, leaving
    the store's journal and lock file; it is now handled as Ctrl-C."""
    import signal

    import transync.experiments

    def stopped(*args, **kwargs):
        signal.raise_signal(signal.SIGTERM)
        raise AssertionError("SIGTERM did not interrupt")       # pragma: no cover

    before = signal.getsignal(signal.SIGTERM)
    monkeypatch.setattr(transync.experiments, "run_experiment", stopped)
    assert main(["demo", "--experiments", "sync", "--out", str(tmp_path / "demo")]) == 130
    err = capsys.readouterr().err
    assert err.startswith("transync: interrupted by SIGTERM; no trial had finished, so none is "
                          "stored")
    assert signal.getsignal(signal.SIGTERM) is before          # restored after the command


def test_an_empty_experiment_name_is_unknown(capsys):
    """`transync experiment ""` listed the experiments and exited 0."""
    assert main(["experiment", ""]) == 2
    assert "unknown experiment ''; choose from" in capsys.readouterr().err
    assert main(["experiment", "cmu", "--data", ""]) == 2          # read the current folder
    assert "--data: got an empty path" in capsys.readouterr().err


def test_json_outputs_are_checked_first_and_written_whole(tmp_path, capsys, monkeypatch):
    """--out was written in place (a full disk or a signal left a truncated JSON and destroyed
    the previous one), checked only after the computation, and could be an input (overwritten:
    the rerun failed). A MemoryError was called a bug."""
    import transync.synchronization

    data = tmp_path / "pairs.json"
    data.write_text(json.dumps({"pairs": [[0, 1, [1, 0]], [1, 2, [0, 1]], [0, 2, [1, 0]]]}))
    assert main(["sync", str(data), "--out", str(data)]) == 2
    assert "is also an input of the command" in capsys.readouterr().err
    assert json.loads(data.read_text())["pairs"][0] == [0, 1, [1, 0]]        # untouched
    assert main(["sync", str(tmp_path / "missing.json"), "--out",
                 str(tmp_path / "no" / "out.json")]) == 2                     # before reading
    assert "the folder" in capsys.readouterr().err
    out = tmp_path / "out.json"
    out.write_text('{"old": "complete"}\n')
    assert main(["sync", str(data), "--out", str(out)]) == 0
    assert json.loads(out.read_text())["labels"] == [[0, 1], [1, 0], [1, 0]]
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []

    def no_memory(*args, **kwargs):
        raise MemoryError()

    monkeypatch.setattr(transync.synchronization, "synchronize_permutations", no_memory)
    assert main(["sync", str(data)]) == 2
    err = capsys.readouterr().err
    assert "out of memory: the input is too large" in err and "please report" not in err
