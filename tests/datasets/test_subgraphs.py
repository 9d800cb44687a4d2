import numpy as np
import pytest

from transync.datasets import (
    GraphCollectionProblem,
    SubgraphCollectionProblem,
    make_subgraph_collection,
)
from transync.permutations import MultiMatching


def test_truth_matches_planted_graphs_at_zero_noise():
    c = make_subgraph_collection(n_graphs=5, n_universe=12, p_keep=(0.4, 0.9), n_outliers=2,
                                 deformation=0.0, density=1.0, rng=3)
    assert isinstance(c, SubgraphCollectionProblem) and isinstance(c, GraphCollectionProblem)
    assert isinstance(c.ground_truth, MultiMatching) and c.ground_truth.n_universe == 12
    for i in range(5):
        for j in range(5):
            t = c.truth(i, j)
            u = np.flatnonzero(t >= 0)
            lab_i, lab_j = c.labels[i], c.labels[j]
            np.testing.assert_array_equal(lab_i[u], lab_j[t[u]])
            # every shared universe node is matched
            assert u.size == np.intersect1d(lab_i[lab_i >= 0], lab_j[lab_j >= 0]).size
            gi, gj = c.graphs[i], c.graphs[j]
            np.testing.assert_array_equal(gi.edge_features[np.ix_(u, u)],
                                          gj.edge_features[np.ix_(t[u], t[u])])
            np.testing.assert_array_equal(gi.adjacency[np.ix_(u, u)],
                                          gj.adjacency[np.ix_(t[u], t[u])])


def test_outliers_are_unlabeled_and_sizes_add_up():
    c = make_subgraph_collection(n_graphs=6, n_universe=10, p_keep=0.7, n_outliers=3, rng=1)
    for g, lab in enumerate(c.labels):
        assert (lab == -1).sum() == 3
        kept = lab[lab >= 0]
        assert np.unique(kept).size == kept.size and kept.max(initial=0) < 10
        assert c.graphs[g].n_nodes == lab.size == c.sizes[g]
        A = c.graphs[g].adjacency
        np.testing.assert_array_equal(A, A.T)
        assert np.all(np.diag(A) == 0)
    # outliers have no partner anywhere
    for i in range(1, 6):
        t = c.truth(0, i)
        np.testing.assert_array_equal(t[c.labels[0] < 0], -1)


def test_size_distribution_follows_p_keep():
    c = make_subgraph_collection(n_graphs=200, n_universe=20, p_keep=(0.6, 1.0), rng=2)
    kept = c.sizes
    assert kept.max() <= 20 and kept.min() >= 1
    assert abs(kept.mean() - 16.0) < 0.6          # E = 20 * 0.8; sd of the mean ~ 0.2
    probs = np.array(c.params["keep_probabilities"])
    assert probs.min() >= 0.6 and probs.max() <= 1.0
    assert np.corrcoef(probs, kept)[0, 1] > 0.5
    full = make_subgraph_collection(n_graphs=3, n_universe=7, p_keep=1.0, rng=0)
    assert full.sizes.tolist() == [7, 7, 7]


def test_every_graph_has_a_node_and_one_node_graphs_occur():
    c = make_subgraph_collection(n_graphs=50, n_universe=3, p_keep=0.05, rng=0)
    assert c.sizes.min() == 1 and c.graphs[int(np.argmin(c.sizes))].n_nodes == 1


def test_deformation_and_density():
    c = make_subgraph_collection(n_graphs=2, n_universe=30, p_keep=1.0, deformation=0.1,
                                 shuffle=False, rng=4)
    diff = (c.graphs[0].edge_features - c.graphs[1].edge_features)[np.triu_indices(30, 1)]
    assert 0.11 < diff.std() < 0.17                 # difference of two N(0, 0.1^2): sd 0.141
    s = make_subgraph_collection(n_graphs=4, n_universe=30, p_keep=1.0, density=0.3, rng=4)
    frac = np.mean([g.adjacency[np.triu_indices(30, 1)].mean() for g in s.graphs])
    assert 0.25 < frac < 0.35
    f = make_subgraph_collection(n_graphs=2, n_universe=30, p_keep=1.0, flip=0.3,
                                 shuffle=False, rng=4)
    assert 0.2 < np.mean(f.graphs[0].adjacency != f.graphs[1].adjacency) < 0.6


def test_seeds_reproduce():
    a = make_subgraph_collection(n_outliers=2, deformation=0.05, density=0.8, rng=7)
    b = make_subgraph_collection(n_outliers=2, deformation=0.05, density=0.8,
                                 rng=np.random.default_rng(7))
    assert a.ground_truth == b.ground_truth
    for ga, gb in zip(a.graphs, b.graphs):
        np.testing.assert_array_equal(ga.edge_features, gb.edge_features)
    c = make_subgraph_collection(n_outliers=2, deformation=0.05, density=0.8, rng=8)
    assert c.ground_truth != a.ground_truth


def test_accuracy_convenience():
    c = make_subgraph_collection(n_graphs=4, n_universe=8, rng=5)
    assert c.accuracy(c.ground_truth) == 1.0
    assert c.accuracy(c.ground_truth.pairwise_dict()) == 1.0
    empty = [np.full(n, -1) for n in c.sizes]
    assert c.accuracy(empty) == 0.0


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(p_keep=0.0), ValueError, "p_keep"),
    (dict(p_keep=1.2), ValueError, "p_keep"),
    (dict(p_keep=(0.0, 0.5)), ValueError, "p_keep"),
    (dict(p_keep=1.5), ValueError, r"`p_keep` must lie in \(0, 1\], got 1.5"),
    (dict(p_keep=float("nan")), ValueError, r"`p_keep` must lie in \(0, 1\], got nan"),
    (dict(p_keep=(0.9, 0.5)), ValueError, "p_keep"),
    (dict(p_keep=(0.1, 0.5, 0.9)), TypeError, "p_keep"),
    (dict(p_keep="high"), TypeError, "p_keep"),
    (dict(n_universe=0), ValueError, "n_universe"),
    (dict(n_universe=10.0), TypeError, "n_universe"),
    (dict(n_graphs=1), ValueError, "n_graphs"),
    (dict(n_outliers=-1), ValueError, "n_outliers"),
    (dict(deformation=-0.1), ValueError, "deformation"),
    (dict(density=1.5), ValueError, "density"),
    (dict(flip=-0.5), ValueError, "flip"),
    (dict(shuffle=1), TypeError, "shuffle"),
])
def test_bad_input(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        make_subgraph_collection(**kwargs)
