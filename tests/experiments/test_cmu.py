"""The `cmu` experiment (thesis Table 6.1) on a tiny sequence in the CMU layout that the tests
write: quick mode through the command line, the table, the data-folder errors."""

import numpy as np
import pytest

from transync.cli import main
from transync.experiments import REGISTRY, run_experiment
from transync.experiments.cmu import METHODS, build, frame_gaps, load_sequence, trial
from transync.experiments.subgraph import build as build_subgraph

N_FRAMES, N_LANDMARKS = 8, 10


@pytest.fixture()
def sequence(tmp_path, write_sequence):
    return write_sequence(tmp_path / "seq", n_frames=N_FRAMES, n_landmarks=N_LANDMARKS)


def test_registered_and_builds_on_the_folder(sequence):
    assert REGISTRY["cmu"] == "transync.experiments.cmu"
    exp = build(quick=True, data=sequence)
    (sw,) = exp.sweeps
    assert exp.name == "cmu" and tuple(sw.methods) == METHODS and len(METHODS) == 7
    assert "data" not in sw.base and sw.base["n_frames"] == 4
    assert exp.trial.keywords["data"] == str(sequence.resolve())
    assert sw.values == [1, 2]                       # 4 frames fit 7 positions apart at most 2
    full = build(data=sequence)
    assert full.trials >= 20 and full.sweeps[0].base["n_frames"] == N_FRAMES
    assert full.sweeps[0].values == [1]


def test_stored_key_does_not_depend_on_the_folder(sequence, tmp_path):
    """Moving the data folder keeps the configuration (and so the stored trials); changing the
    landmarks changes it."""
    import shutil

    moved = tmp_path / "elsewhere"
    shutil.copytree(sequence, moved)
    a, b = build(quick=True, data=sequence), build(quick=True, data=moved)
    assert a.sweeps[0].base == b.sweeps[0].base
    label = next((moved / "label").iterdir())
    label.write_text(label.read_text().replace("0", "1", 1))
    c = build(quick=True, data=moved)
    assert c.sweeps[0].base["fingerprint"] != a.sweeps[0].base["fingerprint"]
    with pytest.raises(ValueError, match="not the one"):
        a.trial.func(dict(a.sweeps[0].base, gap=1, method="GA"), np.random.default_rng(0),
                     data=str(moved))


def test_frame_gaps():
    assert frame_gaps(111, 20) == [1, 2, 3, 4, 5]
    assert frame_gaps(101, 20, count=3) == [1, 3, 5]
    assert frame_gaps(5, 5) == [1]
    with pytest.raises(ValueError, match="n_frames"):
        frame_gaps(5, 6)


def test_missing_folder_names_path_and_transync_data(tmp_path, monkeypatch):
    missing = tmp_path / "nowhere"
    with pytest.raises(FileNotFoundError, match="TRANSYNC_DATA") as info:
        build(quick=True, data=missing)
    assert str(missing) in str(info.value)
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path))          # no cmu-house in it
    with pytest.raises(FileNotFoundError, match="TRANSYNC_DATA") as info:
        load_sequence()
    assert str(tmp_path / "cmu-house") in str(info.value)


def test_cli_errors_are_one_line(tmp_path, capsys):
    assert main(["experiment", "cmu", "--quick", "--data", str(tmp_path / "nowhere"),
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "TRANSYNC_DATA" in err and "nowhere" in err
    assert not (tmp_path / "out").exists()
    assert main(["experiment", "sync", "--quick", "--data", str(tmp_path)]) == 2
    assert "takes no --data" in capsys.readouterr().err


def test_unmatchable_sequences_fail_before_any_trial(tmp_path, write_sequence, capsys):
    """One landmark per frame, or a frame whose landmarks all coincide, failed every trial
    (exit 1 after running them); now the build refuses it, naming the folder and the frame."""
    one = write_sequence(tmp_path / "one", n_frames=4, n_landmarks=1)
    assert main(["experiment", "cmu", "--quick", "--data", str(one),
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "1 landmark per frame" in err and str(one) in err
    assert not (tmp_path / "out").exists()
    flat = write_sequence(tmp_path / "flat", n_frames=4, n_landmarks=3, jitter=0.0)
    (flat / "label" / "toy3").write_text("5.0 6.0\n" * 3)
    for build_ in (build, build_subgraph):
        with pytest.raises(ValueError, match=r"flat: all 3 landmarks of frame 2 \(label file number 3\) coincide"):
            build_(quick=True, data=flat)


def test_trial_spreads_frames(sequence):
    cfg = dict(sequence="toy", n_frames=4, gap=2, method="S-RRWM")
    out = trial(cfg, np.random.default_rng(0), data=str(sequence))
    assert out["first_frame"] in (0.0, 1.0)           # 4 frames 2 apart span 7 of 8 positions
    assert out["accuracy"] == 1.0 and out["consistency"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="need 10 frames"):
        trial(dict(cfg, gap=3), np.random.default_rng(0), data=str(sequence))


def test_quick_run_through_the_cli(tmp_path, capsys, write_sequence):
    sequence = write_sequence(tmp_path / "short", n_frames=5, n_landmarks=N_LANDMARKS)  # gap 1
    out = tmp_path / "out"
    assert main(["experiment", "cmu", "--quick", "--data", str(sequence), "--out", str(out),
                 "--no-progress", "--trials", "1"]) == 0
    assert "table_6_1.md" in capsys.readouterr().out
    table = (out / "table_6_1.md").read_text()
    for m in METHODS:
        assert f"| {m} |" in table
    assert (out / "table_6_1.png").stat().st_size > 0 and (out / "cmu.png").exists()
    again = run_experiment(build(quick=True, data=sequence), out, trials=1, progress=False,
                           plot=False)
    assert again.n_new == 0 and len(again.records) == len(METHODS)
    acc = [r["metrics"]["accuracy"] for r in again.records]
    assert min(acc) > 0.9                               # sub-pixel jitter: an easy sequence
