import json
import subprocess
import sys
import types

import numpy as np
import pytest

from transync.cli import main
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
    from transync.experiments._runner import Experiment, Sweep

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


def test_demo_writes_summary(tmp_path, toy_registry):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--experiments", "toy", "--no-progress"]) == 0
    text = (out / "summary.md").read_text()
    assert "# transync demo" in text and "| spectral | 1.000 |" in text
    assert (out / "toy" / "toy.png").exists()


def test_python_dash_m_entry_point():
    r = subprocess.run([sys.executable, "-m", "transync", "--version"], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.startswith("transync ")


def test_missing_input_file_is_a_clear_error(tmp_path):
    with pytest.raises(SystemExit, match="no such file"):
        main(["match", str(tmp_path / "nope.txt"), str(tmp_path / "nope2.txt")])
