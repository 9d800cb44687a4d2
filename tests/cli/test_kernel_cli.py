"""`transync kernel DATASET --out DIR` on a TU fixture the tests write (24 small graphs, 2
classes): outputs, and one-line errors for bad data sets, folders and options."""

import json

import numpy as np
import pytest

from transync.cli import main
from transync.kernels import min_eigenvalue_ratio


def write_tu(folder, name="TOY", n_per_class=12, seed=0):
    """Class 0: cycles, class 1: stars, 5-8 nodes each; node labels = degree capped at 3."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True)
    edges, indicator, glabels, nlabels = [], [], [], []
    offset = 0
    for g in range(2 * n_per_class):
        n = int(rng.integers(5, 9))
        e = [(k, (k + 1) % n) for k in range(n)] if g % 2 == 0 else [(0, k) for k in range(1, n)]
        deg = np.zeros(n, int)
        for u, v in e:
            edges += [(u + offset + 1, v + offset + 1), (v + offset + 1, u + offset + 1)]
            deg[[u, v]] += 1
        indicator += [g + 1] * n
        nlabels += np.minimum(deg, 3).tolist()
        glabels.append(g % 2)
        offset += n
    (folder / f"{name}_A.txt").write_text("".join(f"{u}, {v}\n" for u, v in edges))
    (folder / f"{name}_graph_indicator.txt").write_text("".join(f"{i}\n" for i in indicator))
    (folder / f"{name}_graph_labels.txt").write_text("".join(f"{c}\n" for c in glabels))
    (folder / f"{name}_node_labels.txt").write_text("".join(f"{c}\n" for c in nlabels))
    return folder


@pytest.fixture
def toy(tmp_path):
    return write_tu(tmp_path / "tu" / "TOY")


FAST = ["--folds", "3", "--repeats", "1", "--matcher", "node", "--no-progress"]


def test_kernel_command_writes_gram_and_report(toy, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["kernel", str(toy), "--out", str(out), *FAST]) == 0
    assert "accuracy" in capsys.readouterr().out
    z = np.load(out / "gram.npz")
    K, y, kept = z["K"], z["y"], z["kept"]
    assert K.shape == (24, 24) and kept.tolist() == list(range(24))
    np.testing.assert_allclose(K, K.T, atol=1e-12)
    np.testing.assert_allclose(np.diag(K), 1.0, atol=1e-9)            # cosine-normalized
    assert np.linalg.eigvalsh(K).min() >= -1e-9 * np.linalg.eigvalsh(K).max()
    assert y.tolist() == [0, 1] * 12
    assert json.loads(str(z["params"]))["matcher"] == "node"
    rep = json.loads((out / "report.json").read_text())
    assert rep["dataset"] == "TOY" and rep["kept"] == 24 and rep["psd"]["psd"] is True
    assert rep["accuracy"]["mean"] >= 0.9                    # cycles vs stars: separable
    assert rep["accuracy"]["folds"] == 3 and len(rep["accuracy"]["per_repeat"]) == 1
    assert "kept 24/24 graphs" in rep["pruning"] and rep["seconds"]["gram"] > 0
    md = (out / "report.md").read_text()
    assert "# transync kernel: TOY" in md and "PSD" in md and "transductive" in md
    # one repetition has no spread between repetitions: no "± 0.00" as if it were measured
    assert "±" not in md and "one 3-fold stratified CV: no spread between repetitions" in md


def test_a_failed_write_leaves_an_earlier_runs_files_unmixed(toy, tmp_path, capsys):
    # the three files were written one after another into the folder: a failure after the
    # first left this run's gram.npz beside an earlier run's report.json
    out = tmp_path / "out"
    assert main(["kernel", str(toy), "--out", str(out), *FAST]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    (out / "report.md").unlink()
    (out / "report.md").mkdir()                    # the last file cannot be replaced
    capsys.readouterr()
    assert main(["kernel", str(toy), "--out", str(out), *FAST, "--kernel", "gaussian"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "report.md: it exists and is not a file" in err, err
    assert sorted(p.name for p in out.iterdir()) == ["gram.npz", "report.json", "report.md"]
    for name in ("gram.npz", "report.json"):       # the earlier run's, unchanged
        assert (out / name).read_bytes() == before[name]
    (out / "report.md").rmdir()
    assert main(["kernel", str(toy), "--out", str(out), *FAST, "--kernel", "gaussian"]) == 0
    assert json.loads((out / "report.json").read_text())["params"]["kernel"] == "gaussian"
    assert sorted(p.name for p in out.iterdir()) == ["gram.npz", "report.json", "report.md"]


def test_an_interrupt_while_the_files_move_is_held_to_the_end(toy, tmp_path, capsys,
                                                              monkeypatch):
    # a SIGTERM between two renames left this run's gram.npz beside an earlier run's reports,
    # and said "nothing was written"
    import os
    import signal

    out = tmp_path / "out"
    assert main(["kernel", str(toy), "--out", str(out), *FAST]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    replace, calls = os.replace, []

    def interrupted_replace(src, dst):
        replace(src, dst)
        calls.append(dst)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGINT)      # Ctrl-C after the first of three moves

    monkeypatch.setattr(os, "replace", interrupted_replace)
    capsys.readouterr()
    assert main(["kernel", str(toy), "--out", str(out), *FAST, "--kernel", "gaussian"]) == 130
    err = capsys.readouterr().err
    assert err.strip() == f"transync: interrupted; the results were written to {out}", err
    assert len(calls) == 3 and sorted(p.name for p in out.iterdir()) == sorted(before)
    assert json.loads((out / "report.json").read_text())["params"]["kernel"] == "gaussian"
    assert all((out / name).read_bytes() != data for name, data in before.items())


def test_dataset_by_name_in_the_data_home(toy, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path))
    out = tmp_path / "by-name"
    assert main(["kernel", "TOY", "--out", str(out), *FAST, "--kernel", "gaussian"]) == 0
    assert json.loads((out / "report.json").read_text())["params"]["kernel"] == "gaussian"
    assert main(["kernel", "NOPE", "--out", str(tmp_path / "x"), *FAST]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("transync: error: data set 'NOPE'")
    assert "TOY" in err                                      # lists the sets that exist
    assert not (tmp_path / "x").exists()


def test_bad_folder_names_the_missing_file(toy, tmp_path, capsys):
    (toy / "TOY_graph_labels.txt").unlink()
    assert main(["kernel", str(toy), "--out", str(tmp_path / "o"), *FAST]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "TOY_graph_labels.txt" in err
    assert main(["kernel", str(tmp_path / "nowhere/"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nowhere" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("option, value, expected", [
    ("--folds", "1", "expected an integer >= 2"),
    ("--repeats", "0", "expected a positive integer"),
    ("--workers", "x", "expected a positive integer"),
    ("--seed", "-1", "expected an integer >= 0"),
    ("--matcher", "hungarian", "invalid choice: 'hungarian'"),
    ("--sync", "birkhoff", "invalid choice: 'birkhoff'"),
    ("--kernel", "rbf", "invalid choice: 'rbf'"),
])
def test_bad_option_values_are_one_line_usage_errors(toy, tmp_path, capsys, option, value,
                                                     expected):
    with pytest.raises(SystemExit) as info:
        main(["kernel", str(toy), "--out", str(tmp_path / "o"), option, value])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and expected in err and option in err


def test_too_many_folds_for_the_classes(toy, tmp_path, capsys):
    assert main(["kernel", str(toy), "--out", str(tmp_path / "o"), "--folds", "13",
                 "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "--folds 13" in err and "12 graphs" in err and not (tmp_path / "o").exists()


def test_library_limits_and_pruning_are_said_in_the_commands_terms(toy, tmp_path, capsys):
    """`--alignments 100000` printed "`n_alignments` must be <= 1000" (a name the command does
    not have); a set too small printed "prune_by_size keeps no graph" (an internal function)."""
    assert main(["kernel", str(toy), "--out", str(tmp_path / "o"), "--alignments", "100000",
                 *FAST]) == 2
    err = capsys.readouterr().err
    assert err == "transync: error: `--alignments` must be <= 1000, got 100000\n", err
    small = write_tu(tmp_path / "tu" / "SMALL", name="SMALL", n_per_class=4)
    assert main(["kernel", str(small), "--out", str(tmp_path / "o"), *FAST]) == 2
    err = capsys.readouterr().err
    assert err.startswith("transync: error: data set 'SMALL': the size pruning keeps no graph: "
                          "every class has fewer than 10 graphs"), err
    assert err.count("\n") == 1 and not (tmp_path / "o").exists()


def test_ctrl_c_exits_130_and_writes_nothing(toy, tmp_path, capsys, monkeypatch):
    from transync.kernels import TransitiveAssignmentKernel

    def interrupted(self, X, y=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(TransitiveAssignmentKernel, "fit", interrupted)
    assert main(["kernel", str(toy), "--out", str(tmp_path / "o"), *FAST]) == 130
    assert "interrupted" in capsys.readouterr().err and not (tmp_path / "o").exists()


@pytest.mark.parametrize("option, param, text", [
    ("--neighbors", "n_neighbors", "view graph, 3 nearest graphs"),
    ("--alignments", "n_alignments", "averaged over 3 alignments")])
def test_cli_kernel_view_graph_and_ensemble_options(toy, tmp_path, option, param, text):
    """--neighbors K / --alignments R: the estimator's n_neighbors / n_alignments, reported;
    the Gram matrix written is the estimator's and PSD; 0 is refused by argparse."""
    from transync.datasets import load_tu
    from transync.kernels import TransitiveAssignmentKernel

    out = tmp_path / "out"
    args = ["kernel", str(toy), "--out", str(out), "--matcher", "node", "--folds", "2",
            "--repeats", "1", "--no-progress"]
    assert main([*args, option, "3"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["params"][param] == 3
    assert text in (out / "report.md").read_text()
    with np.load(out / "gram.npz") as z:
        K, kept = z["K"], z["kept"]
    assert min_eigenvalue_ratio(K) >= -1e-9
    graphs = [load_tu(toy).graphs[k] for k in kept]
    want = TransitiveAssignmentKernel(matcher="node", random_state=0, **{param: 3})
    np.testing.assert_allclose(K, want.fit_transform(graphs), atol=1e-12)
    with pytest.raises(SystemExit) as err:                # argparse: bad option value
        main([*args, option, "0"])
    assert err.value.code == 2


def test_neighbors_beyond_the_data_set_reports_all_pairs(toy, tmp_path):
    """--neighbors 1000 on 24 graphs matched every pair but the report said "view graph, 1000
    nearest graphs + spanning tree"."""
    out = tmp_path / "out"
    assert main(["kernel", str(toy), "--out", str(out), *FAST, "--neighbors", "1000"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["params"]["n_neighbors"] == 1000 and report["view_graph_neighbors"] is None
    assert "pairs matched: all (--neighbors 1000 reaches every graph)" in (
        out / "report.md").read_text()
