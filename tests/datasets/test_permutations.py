"""make_permutation_collection: ground truth as a MultiMatching, validated parameters."""

import pickle

import numpy as np
import pytest

from transync.datasets import make_permutation_collection
from transync.permutations import MultiMatching


def test_ground_truth_is_a_multimatching_and_generates_the_clean_pairs():
    c = make_permutation_collection(6, 5, visibility=0.7, n_universe=8, observed=0.6, rng=0)
    truth = c.ground_truth
    assert isinstance(truth, MultiMatching) and truth.n_universe == 8
    np.testing.assert_array_equal(truth.sizes, c.sizes)
    for (i, j), a in c.pairwise.items():               # no corruption: observed = truth
        np.testing.assert_array_equal(a, truth.pairwise(i, j))
        np.testing.assert_array_equal(c.true_pairwise(i, j), truth.pairwise(i, j))
    assert c.accuracy(truth) == 1.0 == c.accuracy(c.labels)
    observed = np.array(list(c.pairwise))
    assert c.accuracy(dict(c.pairwise), pairs=observed) == 1.0
    assert c.accuracy(dict(c.pairwise)) < 1.0              # unobserved pairs recover nothing
    back = pickle.loads(pickle.dumps(c))
    assert back.ground_truth == truth


def test_corrupted_pairs_are_counted():
    c = make_permutation_collection(8, 6, corruption=0.25, rng=1)
    wrong = [k for k, a in c.pairwise.items() if not np.array_equal(a, c.true_pairwise(*k))]
    assert len(wrong) <= c.info["n_corrupted"] == 7
    assert all(c.corrupted[k] for k in wrong)
    assert c.accuracy(dict(c.pairwise)) < 1.0


def test_degenerate_but_legal_sizes():
    c = make_permutation_collection(2, 1, rng=0)         # two objects, one node each
    assert c.pairwise == {(0, 1): np.array([0])} or c.pairwise[(0, 1)].tolist() == [0]
    assert make_permutation_collection(3, 2, n_universe=6, rng=0).n_universe == 6


@pytest.mark.parametrize("args, kwargs, exc, match", [
    ((1, 3), {}, ValueError, "`n_objects` must be >= 2, got 1"),
    ((3, 0), {}, ValueError, "`n_nodes` must be >= 1, got 0"),
    ((3.0, 2), {}, TypeError, "`n_objects` must be an int"),
    ((3, 2), {"corruption": 1.5}, ValueError, r"`corruption` must lie in \[0, 1\], got 1.5"),
    ((3, 2), {"visibility": np.nan}, ValueError, "`visibility` must be finite"),
    ((3, 2), {"observed": -0.1}, ValueError, "`observed` must be finite and >= 0"),
    ((3, 2), {"n_universe": 1}, ValueError, "`n_universe` must be >= n_nodes=2, got 1"),
    ((3, 2), {"n_universe": 10**9}, ValueError,
     r"`n_universe` must be <= n_objects \* n_nodes = 6"),
    ((10**6, 5), {}, ValueError, r"would generate .* assignment entries"),
    ((3, 2), {"ensure_connected": "yes"}, TypeError, "`ensure_connected` must be a bool"),
    ((3, 2), {"rng": "seed"}, TypeError, "`rng` must be None, an int or a numpy.random.Generator"),
])
def test_parameters_are_validated(args, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        make_permutation_collection(*args, **kwargs)
