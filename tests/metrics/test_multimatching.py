import itertools

import numpy as np
import pytest

from transync.datasets import make_subgraph_collection
from transync.metrics import multimatching_accuracy, multimatching_precision_recall
from transync.permutations import MultiMatching


def _brute(pred_maps, labels):
    """Plain loops over pairs i < j and nodes."""
    correct = n_pred = n_true = 0
    for i, j in itertools.combinations(range(len(labels)), 2):
        a = pred_maps.get((i, j))
        for u, lu in enumerate(labels[i]):
            true_v = [v for v, lv in enumerate(labels[j]) if lu >= 0 and lv == lu]
            n_true += len(true_v)
            if a is not None and a[u] >= 0:
                n_pred += 1
                correct += int(true_v == [a[u]])
    return correct / n_pred, correct / n_true


def _noisy_labels(truth, rng, p_move=0.3):
    d = truth.n_universe
    out = []
    for lab in truth.labels:
        lab = lab.copy()
        move = rng.random(lab.size) < p_move
        lab[move] = -1
        free = np.setdiff1d(np.arange(d + 3), lab)
        take = rng.permutation(free)[: int(move.sum())]
        lab[np.flatnonzero(move)] = take            # new slots, some beyond the universe
        out.append(lab)
    return out


@pytest.mark.parametrize("seed", range(3))
def test_matches_brute_force_and_multimatching_accuracy(seed):
    rng = np.random.default_rng(seed)
    c = make_subgraph_collection(n_graphs=5, n_universe=8, p_keep=(0.5, 1.0), n_outliers=2,
                                 rng=seed)
    pred = MultiMatching(_noisy_labels(c.ground_truth, rng))
    res = multimatching_precision_recall(pred, c.ground_truth)
    prec, rec = _brute(pred.pairwise_dict(), c.labels)
    np.testing.assert_allclose([res["precision"], res["recall"]], [prec, rec], rtol=1e-12)
    assert res["accuracy"] == res["recall"] == multimatching_accuracy(pred, c.ground_truth)
    np.testing.assert_allclose(res["f1"], 2 * prec * rec / (prec + rec), rtol=1e-12)
    # the same maps as a dict, an inconsistent dict with one pair reversed, and labels
    d = pred.pairwise_dict()
    assert multimatching_precision_recall(d, c.labels) == res
    assert multimatching_precision_recall(list(pred.labels), c.ground_truth) == res
    rev = dict(d)
    rev[(3, 1)] = pred.pairwise(3, 1)
    del rev[(1, 3)]
    assert multimatching_precision_recall(rev, c.ground_truth) == res


def test_perfect_and_outlier_matches():
    c = make_subgraph_collection(n_graphs=4, n_universe=6, n_outliers=2, rng=1)
    gt = c.ground_truth
    assert multimatching_precision_recall(gt, gt) == {"precision": 1.0, "recall": 1.0,
                                                      "f1": 1.0, "accuracy": 1.0}
    # outliers placed in one extra slot of their own: recall stays 1, precision drops
    labels = []
    for lab in gt.labels:
        lab = lab.copy()
        out = np.flatnonzero(lab < 0)
        lab[out] = 6 + np.arange(out.size)
        labels.append(lab)
    res = multimatching_precision_recall(labels, gt)
    assert res["recall"] == 1.0 and res["precision"] < 1.0
    n_true = sum(int((gt.pairwise(i, j) >= 0).sum()) for i, j in itertools.combinations(
        range(4), 2))
    np.testing.assert_allclose(res["precision"], n_true / (n_true + 6 * 2))


def test_empty_prediction_and_pairs():
    gt = MultiMatching([np.array([0, 1]), np.array([1, 0]), np.array([0])])
    res = multimatching_precision_recall({}, gt)
    assert res == {"precision": 1.0, "recall": 0.0, "f1": 0.0, "accuracy": 0.0}
    res = multimatching_precision_recall({(0, 2): np.array([0, -1])}, gt, pairs=[[0, 2]])
    assert res["precision"] == res["recall"] == 1.0


@pytest.mark.parametrize("pred, exc, match", [
    ([np.array([0, 1]), np.array([1, 0])], ValueError, "prediction"),
    ([np.array([0, 0]), np.array([1, 0]), np.array([0])], ValueError, "prediction"),
    ({(0, 1): np.array([0, 0])}, ValueError, "injective"),
])
def test_bad_input(pred, exc, match):
    gt = MultiMatching([np.array([0, 1]), np.array([1, 0]), np.array([0])])
    with pytest.raises(exc, match=match):
        multimatching_precision_recall(pred, gt)
    with pytest.raises(ValueError, match="pairs"):
        multimatching_precision_recall(gt, gt, pairs=[[0, 5]])


@pytest.mark.parametrize("key", [(0, 5), ("a", "b"), (1, 1), (0, 1, 2), (True, 1), -1])
def test_dict_prediction_keys_are_checked_by_both_metrics(key):
    """A key that is not a pair of distinct graph indices is refused by name, not ignored
    (before: the accuracy of ``{(0, 5): ...}`` on 3 objects was a silent 0.0)."""
    truth = [np.array([0, 1]), np.array([1, 0]), np.array([0, 1])]
    pred = {(0, 1): np.array([1, 0]), key: np.array([1, 0])}
    for metric in (multimatching_accuracy, multimatching_precision_recall):
        with pytest.raises(ValueError, match=r"`prediction` keys must be pairs \(i, j\) of "
                                             r"distinct object indices in \[0, 3\)"):
            metric(pred, truth)
    with pytest.raises(ValueError, match="`prediction` must hold 3 objects"):
        multimatching_accuracy([np.array([0, 1])] * 2, truth)
    good = {(0, 1): np.array([1, 0]), (2, 1): np.array([1, 0])}     # (2, 1): inverted for (1, 2)
    assert multimatching_accuracy(good, truth) == pytest.approx(2 / 3)


def test_truth_and_pairs_are_named():
    """Errors about `truth` said `labels`; a self-pair (0, 0) counted a perfect prediction's
    recall as 0; an unsynchronized result whose pairwise_dict() is None raised
    UnboundLocalError."""
    t = [np.array([0, 1]), np.array([1, 0])]
    with pytest.raises(TypeError, match=r"^`truth`: "):
        multimatching_accuracy([np.array([0])], None)
    with pytest.raises(ValueError, match=r"^`truth`: `labels\[0\]` must be injective"):
        multimatching_precision_recall([np.array([0, 1])], [np.array([0, 0])])
    with pytest.raises(ValueError, match=r"`pairs` must hold pairs of distinct objects, got "
                                         r"\(0, 0\)"):
        multimatching_precision_recall({(0, 1): np.array([1, 0])}, t, pairs=[[0, 0]])

    class Unsynced:
        matching = None

        def pairwise_dict(self):
            return None

    with pytest.raises(TypeError, match=r"`prediction.pairwise_dict\(\)` must return a dict"):
        multimatching_precision_recall(Unsynced(), t)
