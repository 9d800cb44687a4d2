"""Permutation synchronization on corrupted collections.

Four sweeps, one variable at a time, on :func:`transync.datasets.make_permutation_collection`:
the fraction of corrupted pairs, the number of objects, the fraction of observed pairs, and run
time against the number of objects. Methods: ``spectral``, ``orthogonal``, ``matcheig`` of
:func:`transync.synchronization.synchronize_permutations`, plus ``none`` (the raw input, no
synchronization) for reference.

Metrics: ``accuracy`` (fraction of ground-truth correspondences over all pairs ``i < j`` that the
output recovers; for ``none`` and ``matcheig`` from their pairwise maps, for the others from the
labels), ``cycle_error`` (fraction of inconsistent triangles of the output, 0 by construction for
the consistent methods) and ``seconds``.
"""

from __future__ import annotations

import time

import numpy as np

from ..datasets import make_permutation_collection
from ..permutations import cycle_inconsistency
from ..synchronization import synchronize_permutations
from ._runner import Experiment, Sweep

METHODS = ("none", "spectral", "orthogonal", "matcheig")


def trial(config: dict, rng: np.random.Generator) -> dict:
    """One generated collection, one method: accuracy, output cycle error and time."""
    data = make_permutation_collection(
        config["n_objects"], config["n_nodes"], corruption=config["corruption"],
        visibility=config.get("visibility", 1.0), observed=config["observed"],
        n_universe=config.get("n_universe"), rng=rng)
    method = config["method"]
    t0 = time.perf_counter()
    if method == "none":
        seconds = 0.0
        out = dict(data.pairwise)
        acc = data.ground_truth.accuracy(out)
    else:
        res = synchronize_permutations(data.pairwise, method=method,
                                       n_universe=config.get("n_universe"),
                                       rng=int(rng.integers(2**31)))
        seconds = time.perf_counter() - t0
        if res.cycle_consistent:
            acc = data.ground_truth.accuracy(res.matching)
            out = None
        else:
            maps = res.pairwise_dict()
            acc = data.ground_truth.accuracy(maps)
            # every N (sampled beyond 20,000 triangles); above N = 60 it was skipped and 0
            out = maps
    if out is None:             # consistent by construction
        cyc = 0.0
    else:
        cyc = cycle_inconsistency(out, max_triangles=20_000, rng=0)["inconsistent_triangles"]
    return {"accuracy": acc, "cycle_error": cyc, "seconds": seconds}


def build(*, quick: bool = False) -> Experiment:
    base = dict(n_objects=30, n_nodes=20, corruption=0.3, observed=1.0)
    if quick:
        base = dict(n_objects=12, n_nodes=10, corruption=0.3, observed=1.0)
        corruption = [0.0, 0.3, 0.6]
        objects = [4, 8, 16]
        observed = [0.3, 0.6, 1.0]
        sizes = [10, 20, 40]
        trials = 3
    else:
        corruption = [round(0.1 * k, 1) for k in range(9)]
        objects = [4, 8, 16, 32, 64]
        observed = [0.1, 0.2, 0.3, 0.5, 0.7, 1.0]
        sizes = [25, 50, 100, 200]
        trials = 20
    metrics = ("accuracy", "cycle_error", "seconds")
    sweeps = [
        Sweep(name="corruption", variable="corruption", values=corruption, methods=METHODS,
              base=base, metrics=metrics, xlabel="fraction of corrupted pairs"),
        Sweep(name="objects", variable="n_objects", values=objects, methods=METHODS,
              base=base, metrics=metrics, xlabel="number of objects N"),
        Sweep(name="observed", variable="observed", values=observed, methods=METHODS,
              base={**base, "corruption": 0.1}, metrics=metrics,
              xlabel="fraction of observed pairs"),
        Sweep(name="time", variable="n_objects", values=sizes, methods=METHODS[1:],
              base={**base, "corruption": 0.2}, metrics=("seconds", "accuracy"),
              xlabel="number of objects N (time)"),
    ]
    return Experiment(name="sync", sweeps=sweeps, trial=trial, trials=trials,
                      description="permutation synchronization vs corruption, N, observed "
                                  "pairs; time vs N")
