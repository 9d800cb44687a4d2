"""The `sync` experiment module: registry entry, build() and one trial per method."""

import numpy as np
import pytest

from transync.experiments import REGISTRY
from transync.experiments.sync import METHODS, build, trial


def test_registered_and_builds():
    assert REGISTRY["sync"] == "transync.experiments.sync"
    exp = build(quick=True)
    assert exp.name == "sync" and {s.name for s in exp.sweeps} == {
        "corruption", "objects", "observed", "time"}


@pytest.mark.parametrize("method", METHODS)
def test_trial_metrics(method):
    cfg = dict(n_objects=8, n_nodes=6, corruption=0.2, observed=1.0, method=method)
    out = trial(cfg, np.random.default_rng(0))
    assert set(out) == {"accuracy", "cycle_error", "seconds"}
    assert 0.0 <= out["accuracy"] <= 1.0
    if method in ("spectral", "orthogonal"):
        assert out["accuracy"] == 1.0 and out["cycle_error"] == 0.0
    if method == "none":
        assert out["accuracy"] < 1.0 and out["cycle_error"] > 0.0
