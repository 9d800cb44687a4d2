"""Fixtures shared by the experiment tests."""

import json

import numpy as np
import pytest

from transync.experiments import run_experiment


@pytest.fixture()
def write_sequence():
    """Factory: ``write(root, n_frames=8, n_landmarks=10, name="toy", jitter=0.3)`` writes a
    landmark sequence in the CMU layout (``root/label/<name><k>``, pixels, slowly translated
    and jittered from frame to frame) and returns ``root``."""
    def write(root, *, n_frames=8, n_landmarks=10, name="toy", jitter=0.3):
        rng = np.random.default_rng(7)
        base = rng.uniform(0, 300, size=(n_landmarks, 2))
        label = root / "label"
        label.mkdir(parents=True)
        for k in range(n_frames):
            P = base + 2.0 * k + rng.normal(0, jitter, base.shape)
            (label / f"{name}{k + 1}").write_text("".join(f"{x:.6f} {y:.6f}\n" for x, y in P))
        return root

    return write


@pytest.fixture()
def run_twice():
    """``run(exp, folder, trials, plot) -> (first, again)``: an experiment run that must
    finish every trial, then its rerun, which must resume with nothing new to compute and
    report the very same stored metrics."""
    def run(exp, folder, trials, plot):
        first = run_experiment(exp, folder, trials=trials, progress=False, plot=plot)
        assert first.n_failed == 0, [r["error"] for r in first.records if r["error"]][:1]
        n = (trials or exp.trials) * sum(len(s.values) * len(s.methods) for s in exp.sweeps)
        assert first.n_new == n == len(first.records)
        again = run_experiment(exp, folder, trials=trials, progress=False, plot=False)
        assert again.n_new == 0 and len(again.records) == n

        def key(r):
            return r["sweep"], json.dumps(r["config"], sort_keys=True), r["trial"]

        stored = {key(r): r["metrics"] for r in first.records}
        assert all(stored[key(r)] == r["metrics"] for r in again.records)   # nothing recomputed
        return first, again

    return run
