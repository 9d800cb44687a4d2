import numpy as np
import pytest

from transync.datasets import (
    make_graph_collection,
    make_pairwise_problem,
    make_point_matching_problem,
    make_subgraph_collection,
)
from transync.permutations import check_assignment


def test_pairwise_problem_truth_is_an_isomorphism_at_zero_noise():
    p = make_pairwise_problem(n_inliers=12, n_outliers=3, deformation=0.0, density=0.6, rng=1)
    t = check_assignment(p.truth, n2=p.g2.n_nodes)
    inl = np.flatnonzero(t >= 0)
    assert inl.size == 12
    np.testing.assert_allclose(p.g1.adjacency[np.ix_(inl, inl)],
                               p.g2.adjacency[np.ix_(t[inl], t[inl])])
    np.testing.assert_allclose(p.g1.edge_features[np.ix_(inl, inl)],
                               p.g2.edge_features[np.ix_(t[inl], t[inl])])


def test_pairwise_problem_deformation_scale():
    p = make_pairwise_problem(n_inliers=30, deformation=0.1, rng=2)
    t = p.truth
    diff = (p.g1.edge_features - p.g2.edge_features[np.ix_(t, t)])[np.triu_indices(30, 1)]
    assert 0.08 < diff.std() < 0.12


def test_pairwise_problem_is_reproducible():
    a = make_pairwise_problem(rng=5)
    b = make_pairwise_problem(rng=5)
    np.testing.assert_array_equal(a.truth, b.truth)
    np.testing.assert_allclose(a.g2.edge_features, b.g2.edge_features)


def test_point_problem_truth():
    p = make_point_matching_problem(n_inliers=10, n_outliers=2, deformation=0.0, rng=3)
    t = p.truth
    inl = np.flatnonzero(t >= 0)
    np.testing.assert_allclose(p.g1.distances()[np.ix_(inl, inl)],
                               p.g2.distances()[np.ix_(t[inl], t[inl])], atol=1e-12)


def test_graph_collection_labels_and_truth():
    c = make_graph_collection(n_graphs=4, n_inliers=6, n_outliers=2, deformation=0.0, rng=0)
    assert len(c.graphs) == 4 and c.n_universe == 6
    for lab in c.labels:
        assert sorted(lab[lab >= 0].tolist()) == list(range(6))
        assert (lab < 0).sum() == 2
    t = c.truth(0, 2)
    g0, g2 = c.graphs[0], c.graphs[2]
    inl = np.flatnonzero(t >= 0)
    np.testing.assert_allclose(g0.edge_features[np.ix_(inl, inl)],
                               g2.edge_features[np.ix_(t[inl], t[inl])])


def test_graph_collection_flip_changes_topology():
    c0 = make_graph_collection(n_graphs=2, n_inliers=20, flip=0.0, rng=4, shuffle=False)
    c1 = make_graph_collection(n_graphs=2, n_inliers=20, flip=0.3, rng=4, shuffle=False)
    assert np.all(c0.graphs[0].mask == c0.graphs[1].mask)
    changed = (c1.graphs[0].mask != c1.graphs[1].mask).sum() / (20 * 19)
    assert 0.3 < changed < 0.6      # two independent flips of p=0.3: 2p(1-p) = 0.42


@pytest.mark.parametrize("kw, msg", [
    (dict(n_inliers=0), "n_inliers"),
    (dict(deformation=-1.0), "deformation"),
    (dict(density=1.5), "density"),
    (dict(n_outliers=1.5), "n_outliers"),
])
def test_generator_validation(kw, msg):
    with pytest.raises((ValueError, TypeError), match=msg):
        make_pairwise_problem(**kw)


@pytest.mark.parametrize("make", [make_pairwise_problem, make_point_matching_problem,
                                  make_graph_collection, make_subgraph_collection])
def test_a_deformation_too_large_is_named(make):
    """deformation=1e308 was refused later as "`edge_features` must be finite" (or as a point
    magnitude), depending on the seed."""
    with pytest.raises(ValueError, match=r"`deformation` must be at most 1e\+100 .* got 1e\+308"):
        make(deformation=1e308, rng=0)
    assert make(deformation=1e100, rng=0) is not None


def test_collection_ground_truth_is_a_multimatching():
    c = make_graph_collection(n_graphs=3, n_inliers=5, n_outliers=2, rng=1)
    from transync.permutations import MultiMatching
    assert isinstance(c.ground_truth, MultiMatching) and c.ground_truth.n_universe == 5
    for i in range(3):
        for j in range(3):
            np.testing.assert_array_equal(c.truth(i, j), c.ground_truth.pairwise(i, j))
    assert int((c.truth(0, 1) >= 0).sum()) == 5            # outliers have no partner


@pytest.mark.parametrize("fn, kwargs, exc, match", [
    (make_graph_collection, {"n_graphs": 1}, ValueError, "`n_graphs` must be >= 2"),
    (make_graph_collection, {"n_graphs": 10**4, "n_inliers": 1000}, ValueError,
     "dense adjacency entries"),
    (make_graph_collection, {"flip": 2.0}, ValueError, r"`flip` must lie in \[0, 1\]"),
    (make_graph_collection, {"shuffle": 1}, TypeError, "`shuffle` must be a bool"),
    (make_graph_collection, {"rng": 1.5}, TypeError, "`rng` must be None"),
    (make_pairwise_problem, {"n_inliers": 0}, ValueError, "`n_inliers` must be >= 1"),
    (make_pairwise_problem, {"density": -1.0}, ValueError, "`density` must be finite"),
    (make_pairwise_problem, {"n_inliers": 10**5}, ValueError, "dense adjacency entries"),
    (make_point_matching_problem, {"deformation": np.inf}, ValueError,
     "`deformation` must be finite"),
    (make_point_matching_problem, {"rotate": "no"}, TypeError, "`rotate` must be a bool"),
    (make_point_matching_problem, {"n_outliers": -1}, ValueError, "`n_outliers` must be >= 0"),
])
def test_generator_parameters_are_validated(fn, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        fn(**kwargs)


def test_negative_zero_widths_are_zero():
    """``deformation=-0.0`` passed the >= 0 check and then NumPy refused a scale of -0.0."""
    a = make_point_matching_problem(n_inliers=8, deformation=-0.0, rng=1)
    b = make_point_matching_problem(n_inliers=8, deformation=0.0, rng=1)
    np.testing.assert_array_equal(a.g1.points, b.g1.points)
    np.testing.assert_array_equal(a.g2.points, b.g2.points)
