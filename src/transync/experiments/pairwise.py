"""Pairwise graph matching on Cho et al.'s synthetic protocol (ECCV 2010), all seven solvers.

Three sweeps, one variable at a time (methods page *Synthetic protocols and evaluation measures*):
deformation noise (20 inliers, no outliers, complete graphs), outlier nodes (20 inliers, no noise)
and edge density (20 inliers, deformation 0.05). Affinity ``exp(-(a_ij - a_ab)^2 / 0.15)`` on the
random edge attributes. Metrics: accuracy over inliers, objective relative to the ground truth's,
run time.

The graphs carry no node attributes, so the linear baselines (``hungarian``, ``sinkhorn``) are
given the first-order linearization of the QAP as their unary term: the total affinity ``(K 1)[i,
a]`` of each candidate pair (scaled to a maximum of 1), i.e. how well the edge attributes around
``i`` and ``a`` agree, without any pairwise consistency.
"""

from __future__ import annotations

import time

import numpy as np

from ..datasets import make_pairwise_problem
from ..matching import gaussian_edge_affinity, match_graphs
from ..metrics import affinity_score, matching_accuracy
from ._runner import Experiment, Sweep

METHODS = ("hungarian", "sinkhorn", "sm", "rrwm", "ipfp", "ga", "pf")
LINEAR = ("hungarian", "sinkhorn")
SIGMA2 = 0.15


def trial(config: dict, rng: np.random.Generator) -> dict:
    """One problem, one method: accuracy, relative objective and time."""
    p = make_pairwise_problem(n_inliers=config["n_inliers"], n_outliers=config["n_outliers"],
                              deformation=config["deformation"], density=config["density"],
                              rng=rng)
    t0 = time.perf_counter()
    aff = gaussian_edge_affinity(p.g1, p.g2, sigma2=SIGMA2)
    unary = None
    if config["method"] in LINEAR:
        unary = aff.matvec(np.ones((aff.n1, aff.n2)))
        unary /= max(float(unary.max()), 1e-300)      # scores in [0, 1], as Sinkhorn's tau expects
    res = match_graphs(p.g1, p.g2, method=config["method"], affinity=aff, node_affinity=unary)
    seconds = time.perf_counter() - t0
    return {
        "accuracy": matching_accuracy(res.assignment, p.truth),
        "objective": affinity_score(aff, res.assignment, normalize_by=_complete(p.truth,
                                                                                 aff.n2)),
        "seconds": seconds,
        "converged": float(res.converged),
    }


def _complete(truth: np.ndarray, n2: int) -> np.ndarray:
    """Ground truth with outliers matched among themselves (any injective completion; the
    pairwise and multigraph experiments' objective is normalized by its score)."""
    out = np.array(truth, dtype=np.int64)
    free = np.setdiff1d(np.arange(n2), out[out >= 0])
    rows = np.flatnonzero(out < 0)
    k = min(rows.size, free.size)
    out[rows[:k]] = free[:k]
    return out


def build(*, quick: bool = False) -> Experiment:
    base = dict(n_inliers=20, n_outliers=0, deformation=0.0, density=1.0)
    if quick:
        deform = [0.0, 0.1, 0.2, 0.3]
        outliers = [0, 5, 10]
        density = [0.4, 0.7, 1.0]
        trials = 3
        base["n_inliers"] = 15
    else:
        deform = [round(0.05 * k, 2) for k in range(9)]
        outliers = list(range(0, 21, 4))
        density = [round(0.3 + 0.1 * k, 1) for k in range(8)]
        trials = 30
    metrics = ("accuracy", "objective", "seconds")
    sweeps = [
        Sweep(name="deformation", variable="deformation", values=deform, methods=METHODS,
              base=base, metrics=metrics, xlabel="deformation noise σ"),
        Sweep(name="outliers", variable="n_outliers", values=outliers, methods=METHODS,
              base=base, metrics=metrics, xlabel="outlier nodes"),
        Sweep(name="density", variable="density", values=density, methods=METHODS,
              base={**base, "deformation": 0.05}, metrics=metrics, xlabel="edge density ρ"),
    ]
    return Experiment(name="pairwise", sweeps=sweeps, trial=trial, trials=trials,
                      description="Cho et al. synthetic graphs, seven pairwise solvers")
