"""Multi-graph matching on Yan et al.'s synthetic collections (thesis Figs. 6.1, 6.2, 6.3, 6.5).

Every trial generates one collection with :func:`transync.datasets.make_graph_collection` (node
orders shuffled) and matches it with one method through :func:`transync.match_collection`, on Yan
et al.'s edge affinity ``exp(-(e - e')^2 / 0.05)`` (methods page *Synthetic protocols and
evaluation measures*). All methods of a trial see the same collection. Methods (:data:`METHODS`):

* ``GA``, ``RRWM``, ``PF`` - every pair matched on its own (no synchronization);
* ``S-GA``, ``S-RRWM``, ``S-PF`` - the same solvers run in lock-step on all pairs, their
  doubly-stochastic iterates synchronized over the Birkhoff polytope during the optimization
  (``mode="online"``, the thesis's method);
* ``GA+sync``, ``RRWM+sync``, ``PF+sync`` - the pairwise solutions synchronized once afterwards
  (``mode="offline"``, Birkhoff synchronization);
* ``CAO``, ``CAO-PC`` - Yan et al.'s composition-based multi-graph baseline on pairwise RRWM
  (affinity only, and with pairwise consistency).

Sweeps, one variable at a time around N = 8 graphs, 10 inliers, no outliers, deformation 0.05,
complete graphs (the grid is described in ``docs/experiments/multigraph/README.md``):
``deformation`` (edge-weight noise), ``density`` (edge density; Fig. 6.3 plots it as the fraction
of edges removed), ``outliers`` (outlier nodes per graph), ``flip`` (topological noise: every
inlier node pair's edge toggled with this probability), ``nodes`` (inliers per graph) and
``graphs`` (number of graphs); ``nodes_hard`` and ``graphs_hard`` repeat the last two at
deformation :data:`HARD_DEFORMATION` (at 0.05 every method is exact there).

Metrics: ``accuracy`` (mean over pairs of the fraction of inliers matched correctly,
:meth:`MultiMatchingResult.accuracy`), ``objective`` (total affinity score of the output over
all pairs, relative to the ground truth's; outliers of the truth completed by any matching
among themselves), ``consistency`` (of the output; 1 = cycle-consistent) and ``seconds`` (the
matching, affinities included). Trials also store ``input_consistency`` (of the pairwise stage)
and ``sync_seconds`` (the synchronization stage's share).

Besides the standard plot, a run writes ``fig_6_1.png`` (GA, S-GA, PF, S-PF, CAO),
``fig_6_2.png`` (RRWM, S-RRWM, PF, S-PF), ``fig_6_3_edges_removed.png`` and
``fig_6_5_nodes_graphs.png`` from the stored trials.
"""

from __future__ import annotations

import dataclasses
import functools
import time
import warnings
from pathlib import Path

import numpy as np

from ..datasets import make_graph_collection
from ..exceptions import ConvergenceWarning
from ..matching import gaussian_edge_affinity
from ..multigraph import PairAffinities, match_collection
from ._runner import Experiment, Sweep
from .pairwise import _complete

#: method name -> keyword arguments of :func:`transync.match_collection`
METHODS = {
    "GA": {"solver": "ga", "sync": None},
    "S-GA": {"solver": "ga", "sync": "birkhoff", "mode": "online"},
    "GA+sync": {"solver": "ga", "sync": "birkhoff", "mode": "offline"},
    "RRWM": {"solver": "rrwm", "sync": None},
    "S-RRWM": {"solver": "rrwm", "sync": "birkhoff", "mode": "online"},
    "RRWM+sync": {"solver": "rrwm", "sync": "birkhoff", "mode": "offline"},
    "PF": {"solver": "pf", "sync": None},
    "S-PF": {"solver": "pf", "sync": "birkhoff", "mode": "online"},
    "PF+sync": {"solver": "pf", "sync": "birkhoff", "mode": "offline"},
    "CAO": {"solver": "cao"},
    "CAO-PC": {"solver": "cao-pc"},
}
#: Yan et al.'s kernel width on U(0, 1) edge weights
SIGMA2 = 0.05
METRICS = ("accuracy", "objective", "consistency", "seconds")
#: deformation of the "nodes_hard" and "graphs_hard" sweeps: at the default 0.05 every method is
#: exact at every N and n (those sweeps show cost only); at 0.15 pairwise matching of 10-node
#: graphs is right about half the time (accuracy 0.51-0.53 at N = 8)
HARD_DEFORMATION = 0.15

#: thesis figure -> (file name, methods, sweeps, metrics)
FIGURES = {
    "6.1": ("fig_6_1.png", ("GA", "S-GA", "PF", "S-PF", "CAO"),
            ("deformation", "density", "outliers", "flip"), ("accuracy", "objective")),
    "6.2": ("fig_6_2.png", ("RRWM", "S-RRWM", "PF", "S-PF"),
            ("deformation", "density", "outliers", "flip"), ("accuracy", "objective")),
    "6.3": ("fig_6_3_edges_removed.png", ("GA", "S-GA", "RRWM", "S-RRWM", "PF", "S-PF", "CAO"),
            ("density",), ("accuracy", "objective", "consistency")),
    "6.5": ("fig_6_5_nodes_graphs.png", ("GA", "S-GA", "RRWM", "S-RRWM", "PF", "S-PF", "CAO"),
            ("nodes", "graphs", "nodes_hard", "graphs_hard"),
            ("accuracy", "consistency", "seconds")),
}


def run_method(method: str, graphs, affinity, rng: np.random.Generator):
    """Match ``graphs`` with one of :data:`METHODS`; returns ``(result, seconds)``."""
    if method not in METHODS:
        raise ValueError(f"`method` must be one of {', '.join(METHODS)}, got {method!r}")
    seed = int(rng.integers(2**31))
    t0 = time.perf_counter()
    with warnings.catch_warnings():     # pairs stopped at their budget: stored as `converged`
        warnings.simplefilter("ignore", ConvergenceWarning)
        res = match_collection(graphs, affinity=affinity, rng=seed, progress=False,
                               **METHODS[method])
    return res, time.perf_counter() - t0


def collection_metrics(res, problem, affinity, seconds: float) -> dict:
    """Accuracy, relative objective, output / input consistency and times of one result.

    ``problem`` is a :class:`~transync.datasets.GraphCollectionProblem`; ``affinity`` the
    callable ``(g_i, g_j) -> Affinity`` the result was computed with: the ground truth's scores
    are computed on the same batched pair affinities (evaluation only, not timed).
    """
    pairs = np.asarray(res.pairs, dtype=np.int64)
    n = problem.graphs[0].n_nodes
    truth = np.stack([_complete(problem.truth(i, j), n) for i, j in pairs.tolist()])
    affs = PairAffinities.from_graphs(problem.graphs, pairs, affinity)
    truth_score = float(np.sum(affs.score_assignments(np.arange(len(pairs)), truth)))
    score = float(np.sum(res.scores))
    timings = dict(res.timings)
    return {
        "accuracy": float(res.accuracy(problem.ground_truth)),
        "objective": score / truth_score if truth_score > 0 else float("nan"),
        "consistency": float(res.consistency),
        "input_consistency": float(res.input_consistency),
        "seconds": float(seconds),
        "sync_seconds": float(timings.get("sync", 0.0)),
        "converged": float(res.converged),
    }


def trial(config: dict, rng: np.random.Generator) -> dict:
    """One generated collection, one method (``config["method"]``, a key of :data:`METHODS`)."""
    problem = make_graph_collection(
        n_graphs=config["n_graphs"], n_inliers=config["n_inliers"],
        n_outliers=config["n_outliers"], deformation=config["deformation"],
        density=config["density"], flip=config["flip"], shuffle=True, rng=rng)
    affinity = functools.partial(gaussian_edge_affinity, sigma2=config.get("sigma2", SIGMA2))
    res, seconds = run_method(config["method"], problem.graphs, affinity, rng)
    return collection_metrics(res, problem, affinity, seconds)


def build(*, quick: bool = False) -> Experiment:
    """The sweeps of thesis ch. 6 (grid: ``docs/experiments/multigraph/README.md``): six at the
    defaults, and the nodes and graphs sweeps again at :data:`HARD_DEFORMATION`.

    ``quick``: two values per sweep, N = 3 graphs of 5 inliers, one trial (about half a
    minute: the eleven methods run 12 times); full: 20 trials per point (hours, see
    ``docs/experiments/multigraph/README.md``).
    """
    base = dict(n_graphs=8, n_inliers=10, n_outliers=0, deformation=0.05, density=1.0,
                flip=0.0, sigma2=SIGMA2)
    methods = tuple(METHODS)
    if quick:
        base.update(n_graphs=3, n_inliers=5)
        deform = [0.0, 0.2]
        density = [0.5, 1.0]
        outliers = [0, 2]
        flip = [0.0, 0.2]
        nodes = [5, 7]
        graphs = [3, 4]
        trials = 1
    else:
        deform = [round(0.05 * k, 2) for k in range(6)]
        density = [round(0.3 + 0.1 * k, 1) for k in range(8)]
        outliers = list(range(0, 11, 2))
        flip = [round(0.05 * k, 2) for k in range(7)]
        nodes = [10, 15, 20, 25, 30]
        graphs = [3, 4, 6, 8, 12, 16, 24, 32]
        trials = 20
    hard = {**base, "deformation": HARD_DEFORMATION}
    sweeps = [
        Sweep(name="deformation", variable="deformation", values=deform, methods=methods,
              base=base, metrics=METRICS, xlabel="deformation noise σ"),
        Sweep(name="density", variable="density", values=density, methods=methods,
              base=base, metrics=METRICS, xlabel="edge density ρ"),
        Sweep(name="outliers", variable="n_outliers", values=outliers, methods=methods,
              base=base, metrics=METRICS, xlabel="outlier nodes per graph"),
        Sweep(name="flip", variable="flip", values=flip, methods=methods,
              base=base, metrics=METRICS, xlabel="topological noise (edge flip probability)"),
        Sweep(name="nodes", variable="n_inliers", values=nodes, methods=methods,
              base=base, metrics=METRICS, xlabel="inlier nodes per graph"),
        Sweep(name="graphs", variable="n_graphs", values=graphs, methods=methods,
              base=base, metrics=METRICS, xlabel="number of graphs N"),
        Sweep(name="nodes_hard", variable="n_inliers", values=nodes, methods=methods,
              base=hard, metrics=METRICS,
              xlabel=f"inlier nodes per graph (deformation {HARD_DEFORMATION:g})"),
        Sweep(name="graphs_hard", variable="n_graphs", values=graphs, methods=methods,
              base=hard, metrics=METRICS,
              xlabel=f"number of graphs N (deformation {HARD_DEFORMATION:g})"),
    ]
    return Experiment(name="multigraph", sweeps=sweeps, trial=trial, trials=trials,
                      description="Yan et al. synthetic collections, synchronized vs "
                                  "unsynchronized solvers and CAO",
                      finish=functools.partial(finish, experiment_sweeps=tuple(sweeps)))


def finish(records, summary, out_dir, *, experiment_sweeps) -> list[Path]:
    """The thesis figures 6.1, 6.2, 6.3 and 6.5 from the summary (method subsets per figure)."""
    from ._plot import plot_experiment

    out = Path(out_dir)
    ran = {r["sweep"] for r in summary if r["n"]}
    by_name = {sw.name: sw for sw in experiment_sweeps if sw.name in ran}
    paths = []
    for fig, (fname, methods, sweep_names, metrics) in FIGURES.items():
        sweeps, rows = [], list(summary)
        for name in sweep_names:
            sw = by_name.get(name)
            if sw is None:
                continue
            kept = tuple(m for m in methods if m in sw.methods
                         and any(r["sweep"] == name and r["method"] == m and r["n"]
                                 for r in summary))
            if not kept:
                continue
            sw = dataclasses.replace(sw, methods=kept, metrics=metrics)
            if fig == "6.3":           # edges removed = 1 - density
                sw = dataclasses.replace(sw, values=[round(1 - v, 6) for v in sw.values],
                                         xlabel="fraction of edges removed (1 - ρ)")
                rows = [dict(r, value=round(1 - r["value"], 6)) if r["sweep"] == name else r
                        for r in rows]
            sweeps.append(sw)
        if not sweeps:
            continue
        sub = Experiment(name=f"Fig. {fig}", sweeps=sweeps, trial=trial,
                         description=", ".join(methods) + " (mean ± s.e.)")
        paths.append(plot_experiment(sub, rows, out / fname))
    return paths
