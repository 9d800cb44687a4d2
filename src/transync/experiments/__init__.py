"""Thesis experiments: one module per figure or table, run by a resumable runner.

``REGISTRY`` maps an experiment name to the module that builds it (``build(quick=...)``);
:func:`run_experiment` runs (or resumes) an :class:`Experiment` into a folder's
``results.sqlite``.
"""

from ._runner import (  # noqa: F401
    Experiment,
    ExperimentReport,
    ExperimentStore,
    Sweep,
    mean_se,
    run_experiment,
    summarize,
)

REGISTRY = {
    "pairwise": "transync.experiments.pairwise",
    "homography": "transync.experiments.homography",
    "sync": "transync.experiments.sync",
    "multigraph": "transync.experiments.multigraph",
    "cmu": "transync.experiments.cmu",
    "kernels": "transync.experiments.kernels",
    "subgraph": "transync.experiments.subgraph",
}

__all__ = ["REGISTRY", "Experiment", "ExperimentReport", "ExperimentStore", "Sweep", "mean_se",
           "run_experiment", "summarize"]
