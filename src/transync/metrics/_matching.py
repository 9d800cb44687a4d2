"""Metrics for matchings: accuracy, precision/recall/F1, affinity score, cycle inconsistency.

Assignments follow :mod:`transync.permutations`: ``assignment[u] = v``, ``-1`` = unmatched.
A ground truth ``truth`` has the same form; ``truth[u] = -1`` marks an outlier node of the first
object (no true partner).
"""

from __future__ import annotations

import numpy as np

from .._validation import check_affinity_magnitude, check_array, check_int
from ..permutations import assignment_to_matrix, check_assignment, cycle_inconsistency
from ._multimatching import multimatching_precision_recall

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
    Cho et al.'s accuracy and Yan et al.'s ``cal_acc``.

    Parameters
    ----------
    assignment : array_like of shape (n1,), int
        Predicted assignment (``-1``: unmatched).
    truth : array_like of shape (n1,), int
        True partner of every node, ``-1`` for outliers.

    Returns
    -------
    float
        Accuracy in [0, 1]; 1.0 when there are no inliers.

    Raises
    ------
    ValueError, TypeError
        Invalid assignments, or of different lengths.

    Examples
    --------
    >>> matching_accuracy([0, 2, 1, 3], [0, 1, 2, -1])
    0.333...
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
    ``{(i, j): assignment}``. The ``"accuracy"`` (= recall) of
    :func:`multimatching_precision_recall`, which see for how a dict is read.

    Parameters
    ----------
    prediction : MultiMatching, sequence of label arrays, result with ``.matching``, or dict
        The multi-matching to score.
    truth : MultiMatching or sequence of label arrays
        Ground-truth universe labels (``-1``: node without a true partner).
    pairs : array_like of shape (P, 2), int, optional
        The object pairs to count (default: every ``i < j``).

    Returns
    -------
    float
        Recovered fraction in [0, 1]; 1.0 when ``truth`` has no correspondence on ``pairs``
        (nothing to recover, as :func:`matching_accuracy` with no inliers).

    Raises
    ------
    ValueError, TypeError
        Invalid labels or assignments, mismatched numbers of objects or nodes, bad ``pairs``.

    Examples
    --------
    >>> import numpy as np
    >>> truth = [np.array([0, 1]), np.array([1, 0])]
    >>> multimatching_accuracy([np.array([0, 1]), np.array([0, 1])], truth)
    0.0
    >>> multimatching_accuracy({(0, 1): np.array([1, 0])}, truth)
    1.0
    """
    return multimatching_precision_recall(prediction, truth, pairs=pairs)["accuracy"]


def matching_precision_recall(assignment, truth) -> dict[str, float]:
    """Precision, recall and F1 of a partial matching.

    precision = correct / predicted matches, recall = correct / true matches, where a predicted
    match of an outlier node counts as wrong.

    Parameters
    ----------
    assignment : array_like of shape (n1,), int
        Predicted assignment (``-1``: unmatched).
    truth : array_like of shape (n1,), int
        True partner of every node, ``-1`` for outliers.

    Returns
    -------
    dict
        ``{"precision", "recall", "f1"}``, floats; precision (recall) is 1.0 when nothing is
        predicted (to recover).

    Raises
    ------
    ValueError, TypeError
        Invalid assignments, or of different lengths.

    Examples
    --------
    >>> matching_precision_recall([0, -1, 1], [0, 1, 2])
    {'precision': 0.5, 'recall': 0.333..., 'f1': 0.4}
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

    Parameters
    ----------
    affinity : Affinity or array_like of shape (n1 n2, n1 n2)
        The affinity; a matrix uses pygmtools' layout (candidate ``(u, a)`` at ``a n1 + u``).
    assignment : array_like of shape (n1,), int
        The assignment to score.
    n2 : int, optional
        Size of the second graph; required when ``affinity`` is a matrix.
    normalize_by : array_like of shape (n1,), int, optional
        Reference assignment whose score divides the result (NaN when that score is 0).

    Returns
    -------
    float
        The objective (relative to the reference with ``normalize_by``).

    Raises
    ------
    TypeError
        A matrix ``affinity`` without ``n2``; invalid assignments.
    ValueError
        A matrix ``affinity`` of the wrong shape or with non-finite entries; invalid
        assignments.

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4))                 # n1 = n2 = 2: every pair of candidates scores 1
    >>> affinity_score(K, [0, 1], n2=2)
    4.0
    """
    a = check_assignment(assignment, "assignment")
    if hasattr(affinity, "score"):
        if not isinstance(getattr(affinity, "n2", None), (int, np.integer)):
            raise TypeError(f"`affinity` must be an Affinity (with .score and an int .n2) or a "
                            f"matrix, got {type(affinity).__name__} without .n2")
        n2 = int(affinity.n2)
        n1 = getattr(affinity, "n1", None)
        if isinstance(n1, (int, np.integer)) and a.shape[0] != n1:
            raise ValueError(f"`assignment` must have one entry per node of the affinity's "
                             f"first graph ({int(n1)}), got {a.shape[0]}")
        score = affinity.score
    else:
        if n2 is None:
            raise TypeError("`n2` is required when `affinity` is a matrix")
        n2 = check_int(n2, "n2", minimum=1)
        K = check_array(affinity, "affinity", ndim=2)         # finite: no silent NaN score
        if K.shape != (a.shape[0] * n2, a.shape[0] * n2):
            raise ValueError(f"`affinity` must have shape ({a.shape[0] * n2}, {a.shape[0] * n2}), "
                             f"got {K.shape}")
        if K.size:
            check_affinity_magnitude(np.abs(K).max(), K.shape[0], "affinity")

        def score(X):
            x = X.ravel(order="F")
            return float(x @ K @ x)
    a = check_assignment(a, "assignment", n2=n2)
    value = score(assignment_to_matrix(a, n2))
    if normalize_by is not None:
        b = check_assignment(normalize_by, "normalize_by", n2=n2)
        if b.shape != a.shape:
            raise ValueError(f"`normalize_by` must be an assignment of the same {a.shape[0]} "
                             f"nodes as `assignment`, got shape {b.shape}")
        ref = score(assignment_to_matrix(b, n2))
        value = value / ref if ref else float("nan")
    return float(value)
