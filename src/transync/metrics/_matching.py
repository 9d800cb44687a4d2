"""Metrics for matchings: accuracy, precision/recall/F1, affinity score, cycle inconsistency.

Assignments follow :mod:`transync.permutations`: ``assignment[u] = v``, ``-1`` = unmatched.
A ground truth ``truth`` has the same form; ``truth[u] = -1`` marks an outlier node of the first
object (no true partner).
"""

from __future__ import annotations

import numpy as np

from ..permutations import (
    MultiMatching,
    assignment_to_matrix,
    check_assignment,
    cycle_inconsistency,
)

__all__ = [
    "affinity_score",
    "cycle_inconsistency",
    "matching_accuracy",
    "matching_precision_recall",
    "multimatching_accuracy",
]


def _pair(assignment, truth):
    a = check_assignment(assignment, "assignment")
    t = check_assignment(truth, "truth")
    if a.shape != t.shape:
        raise ValueError(f"`assignment` and `truth` must have the same length, got {a.shape[0]} "
                         f"and {t.shape[0]}")
    return a, t


def matching_accuracy(assignment, truth) -> float:
    """Fraction of inlier nodes matched to their true partner (Cho et al. 2010; Yan et al.).

    Inliers are the nodes with ``truth[u] >= 0``; matches of outlier nodes are ignored, as in
    Cho et al.'s accuracy and Yan et al.'s ``cal_acc``. Returns 1.0 when there are no inliers.
    """
    a, t = _pair(assignment, truth)
    inl = t >= 0
    if not inl.any():
        return 1.0
    return float(np.mean(a[inl] == t[inl]))


def multimatching_accuracy(prediction, truth, *, pairs=None) -> float:
    """Fraction of the true correspondences of a multi-matching that ``prediction`` recovers.

    Summed over the pairs ``i < j`` (or the ``(P, 2)`` ``pairs``): a correspondence is two nodes
    that ``truth`` puts in the same universe slot. ``truth`` is a
    :class:`~transync.permutations.MultiMatching` (or its labels); ``prediction`` a
    ``MultiMatching``, labels, a result carrying ``.matching``, or a dict
    ``{(i, j): assignment}``. One implementation: :meth:`MultiMatching.accuracy`.

    >>> import numpy as np
    >>> truth = [np.array([0, 1]), np.array([1, 0])]
    >>> multimatching_accuracy([np.array([0, 1]), np.array([0, 1])], truth)
    0.0
    >>> multimatching_accuracy({(0, 1): np.array([1, 0])}, truth)
    1.0
    """
    return MultiMatching.from_labels(truth).accuracy(prediction, pairs=pairs)


def matching_precision_recall(assignment, truth) -> dict[str, float]:
    """Precision, recall and F1 of a partial matching.

    precision = correct / predicted matches, recall = correct / true matches, where a predicted
    match of an outlier node counts as wrong.
    """
    a, t = _pair(assignment, truth)
    pred = a >= 0
    true = t >= 0
    correct = int(np.count_nonzero(pred & true & (a == t)))
    n_pred, n_true = int(pred.sum()), int(true.sum())
    precision = correct / n_pred if n_pred else 1.0
    recall = correct / n_true if n_true else 1.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {"precision": float(precision), "recall": float(recall), "f1": float(f1)}


def affinity_score(affinity, assignment, *, n2: int | None = None,
                   normalize_by=None) -> float:
    """QAP objective ``vec(X)^T K vec(X)`` of an assignment.

    ``affinity`` is anything with a ``score(X)`` method (a :class:`transync.matching.Affinity`) or a
    dense ``K`` in pygmtools' layout. With ``normalize_by`` (e.g. the ground truth assignment) the
    score is divided by that assignment's score, as in Cho et al.'s relative objective.
    """
    a = check_assignment(assignment, "assignment")
    if hasattr(affinity, "score"):
        n2 = affinity.n2
        score = affinity.score
    else:
        K = np.asarray(affinity, dtype=float)
        if n2 is None:
            raise TypeError("`n2` is required when `affinity` is a matrix")
        if K.shape != (a.shape[0] * n2, a.shape[0] * n2):
            raise ValueError(f"`affinity` must have shape ({a.shape[0] * n2}, {a.shape[0] * n2}), "
                             f"got {K.shape}")

        def score(X):
            x = X.ravel(order="F")
            return float(x @ K @ x)
    value = score(assignment_to_matrix(a, n2))
    if normalize_by is not None:
        ref = score(assignment_to_matrix(check_assignment(normalize_by, "normalize_by"), n2))
        value = value / ref if ref else float("nan")
    return float(value)
