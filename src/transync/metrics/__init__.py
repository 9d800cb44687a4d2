"""Evaluation metrics: one home for every measure the library reports.

* Matchings (:mod:`._matching`, :mod:`._multimatching`): :func:`matching_accuracy`,
  :func:`matching_precision_recall`, :func:`affinity_score`, :func:`cycle_inconsistency`,
  :func:`multimatching_accuracy`, :func:`multimatching_precision_recall`.
* Constraint violations of multi-matchings (:mod:`._constraints`; methods page
  *Synthetic protocols and evaluation measures*):
  :func:`constraint_violations` (CVR, CVVR, ACVV for capacity and transitivity).
* Plane homographies (:mod:`._homography`): :func:`corner_error`, :func:`pairwise_corner_error`,
  :func:`corner_accuracy`, :func:`brenner_focus`, :func:`segmentation_scores`,
  :func:`misclassification_error` (multi-plane labels).

Examples
--------
>>> import numpy as np
>>> from transync.metrics import matching_accuracy, matching_precision_recall
>>> truth = np.array([0, 1, 2, -1])         # node 3 is an outlier
>>> pred = np.array([0, 2, 1, 3])
>>> matching_accuracy(pred, truth)
0.333...
>>> matching_precision_recall(pred, truth)
{'precision': 0.25, 'recall': 0.333..., 'f1': 0.285...}
"""

from ._constraints import ConstraintStats, ConstraintViolations, constraint_violations
from ._homography import (
    brenner_focus,
    corner_accuracy,
    corner_error,
    misclassification_error,
    pairwise_corner_error,
    segmentation_scores,
)
from ._matching import (
    affinity_score,
    cycle_inconsistency,
    matching_accuracy,
    matching_precision_recall,
    multimatching_accuracy,
)
from ._multimatching import multimatching_precision_recall

__all__ = [
    "ConstraintStats",
    "ConstraintViolations",
    "affinity_score",
    "brenner_focus",
    "constraint_violations",
    "corner_accuracy",
    "corner_error",
    "cycle_inconsistency",
    "matching_accuracy",
    "matching_precision_recall",
    "multimatching_accuracy",
    "misclassification_error",
    "multimatching_precision_recall",
    "pairwise_corner_error",
    "segmentation_scores",
]
