"""Thesis experiments: one module per figure or table, run by a resumable runner.

``REGISTRY`` maps an experiment name to the module that builds it (``build(quick=...)``).
"""

REGISTRY = {
    "pairwise": "transync.experiments.pairwise",
    "homography": "transync.experiments.homography",
    "sync": "transync.experiments.sync",
}
