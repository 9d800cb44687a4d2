"""Precision, recall and F1 of a multi-matching against a universe ground truth.

Definitions: methods page *Synthetic protocols and evaluation measures* of the documentation.

Real-to-real correspondences are pooled over the pairs of objects: a *true* correspondence is two
nodes of different objects that the ground truth puts in the same universe slot; a *predicted*
one is a match ``u -> v`` of the prediction between two real nodes (a dummy-node baseline drops
its dummies before it is scored). A predicted match of an outlier (a node without a universe
slot) is wrong. The pairwise maps of both sides come from
:class:`~transync.permutations.MultiMatching` (the one place where labels become pairs).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..permutations import MultiMatching

__all__ = ["multimatching_precision_recall"]

_CHUNK = 20_000          # pairs per gather


def _prediction(prediction, truth: MultiMatching):
    """A :class:`MultiMatching` or a mapping of pairwise assignments, sizes checked."""
    if isinstance(prediction, Mapping):
        return prediction
    if (not isinstance(prediction, MultiMatching) and getattr(prediction, "matching", 0) is None
            and callable(getattr(prediction, "pairwise_dict", None))):
        maps = prediction.pairwise_dict()     # an unsynchronized result: its observed pairs
        if not isinstance(maps, Mapping):
            raise TypeError(f"`prediction.pairwise_dict()` must return a dict {{(i, j): "
                            f"assignment}}, got {type(maps).__name__}")
        return maps
    if (not isinstance(prediction, MultiMatching)
            and isinstance(getattr(prediction, "matching", None), MultiMatching)):
        prediction = prediction.matching
    if not isinstance(prediction, MultiMatching):
        try:
            prediction = MultiMatching.from_labels(prediction)
        except (TypeError, ValueError) as exc:
            raise type(exc)(f"`prediction`: {exc}") from None
    if (prediction.n_objects != truth.n_objects
            or not np.array_equal(prediction.sizes, truth.sizes)):
        raise ValueError(f"`prediction` must hold {truth.n_objects} objects of sizes "
                         f"{truth.sizes.tolist()[:10]}, got {prediction.n_objects} objects of "
                         f"sizes {prediction.sizes.tolist()[:10]}")
    return prediction


def multimatching_precision_recall(prediction, truth, *, pairs=None) -> dict[str, float]:
    """Precision, recall, F1 and accuracy of a multi-matching, pooled over pairs of objects.

    Over the pairs ``i < j`` (or the ``(P, 2)`` ``pairs``, each counted in its given direction):

    * precision = correct predicted matches / predicted matches between real nodes;
    * recall = correct predicted matches / true correspondences;
    * F1 = their harmonic mean;
    * accuracy = the matching accuracy (MA) of the thesis's ch. 7, ``sum |M_ij & GT_ij| /
      sum |GT_ij|``: the same number as ``recall`` and as
      :func:`~transync.metrics.multimatching_accuracy`, reported under the thesis's name.

    Precision is 1.0 when nothing is predicted and recall 1.0 when there is nothing to recover
    (as in :func:`~transync.metrics.matching_precision_recall`).

    Parameters
    ----------
    prediction : MultiMatching, labels, result with ``.matching``, or dict
        A multi-matching (consistent by construction), or a dict ``{(i, j): assignment}`` of
        pairwise outputs that need not be consistent (a missing pair predicts nothing;
        ``(j, i)`` is used, inverted, when only it is given). A
        :class:`~transync.multigraph.MultiMatchingResult` without universe labels
        (``sync=None``, CAO) is scored on its matched pairs (``pairwise_dict()``).
    truth : MultiMatching or labels
        The ground truth (``-1`` = outlier), e.g. a generator's ``.ground_truth``.
    pairs : (P, 2) array_like of int, optional
        The pairs to score; default every ``i < j``.

    Returns
    -------
    dict
        ``{"precision", "recall", "f1", "accuracy"}`` as floats.

    Raises
    ------
    ValueError, TypeError
        A prediction with other objects or sizes than ``truth``, invalid labels or assignments,
        pairs out of range.

    Examples
    --------
    >>> import numpy as np
    >>> truth = [np.array([0, 1, -1]), np.array([1, 0]), np.array([2, 0])]
    >>> pred = {(0, 1): np.array([1, 0, -1]), (0, 2): np.array([1, -1, 0]),
    ...         (1, 2): np.array([1, -1])}     # 0 -> 2 matches an outlier; 1 -> 2 is wrong
    >>> multimatching_precision_recall(pred, truth)
    {'precision': 0.6, 'recall': 0.75, 'f1': 0.666..., 'accuracy': 0.75}
    """
    try:
        truth = MultiMatching.from_labels(truth)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"`truth`: {exc}") from None
    pairs = truth.check_pairs(pairs)
    if pairs.size and np.any(pairs[:, 0] == pairs[:, 1]):
        i = int(pairs[np.flatnonzero(pairs[:, 0] == pairs[:, 1])[0], 0])
        raise ValueError(f"`pairs` must hold pairs of distinct objects, got ({i}, {i})")
    pred = _prediction(prediction, truth)
    if isinstance(pred, Mapping):
        # one implementation of dict -> pairwise maps: the one behind MultiMatching.accuracy
        maps = truth.maps_from(pred, pairs, name="prediction")
    correct = n_true = n_pred = 0
    for start in range(0, pairs.shape[0], _CHUNK):
        chunk = pairs[start:start + _CHUNK]
        true_v = truth.pairwise_array(chunk)
        pred_v = (pred.pairwise_array(chunk) if isinstance(pred, MultiMatching)
                  else maps[start:start + _CHUNK])
        has_true = true_v >= 0
        n_true += int(has_true.sum())
        n_pred += int((pred_v >= 0).sum())
        correct += int((has_true & (pred_v == true_v)).sum())
    precision = correct / n_pred if n_pred else 1.0
    recall = correct / n_true if n_true else 1.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {"precision": float(precision), "recall": float(recall), "f1": float(f1),
            "accuracy": float(recall)}
