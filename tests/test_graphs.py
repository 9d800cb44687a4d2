import networkx as nx
import numpy as np
import pytest

from transync.graphs import Graph


def test_from_points_variants(rng):
    P = rng.random((12, 2))
    full = Graph.from_points(P, edges="full")
    assert full.n_edges == 12 * 11 // 2
    dela = Graph.from_points(P, edges="delaunay")
    # planar triangulation: at most 3n - 6 edges, connected
    assert 12 - 1 <= dela.n_edges <= 3 * 12 - 6
    knn = Graph.from_points(P, edges="knn", k=3)
    assert np.all(knn.mask.sum(1) >= 3)
    assert np.allclose(knn.adjacency, knn.adjacency.T)


def test_from_points_delaunay_on_degenerate_sets():
    """Collinear points are joggled into a triangulation; points all at one place are refused
    with a named error (scipy's QhullError never escapes)."""
    line = Graph.from_points(np.c_[np.arange(5.0), np.zeros(5)], edges="delaunay")
    assert line.n_edges >= 4
    for where in (1.0, 0.0, 1e-300):    # at the origin joggling "triangulated" them anyway
        with pytest.raises(ValueError, match="`points` admit no Delaunay triangulation .*all at "
                                             "one place"):
            Graph.from_points(np.full((6, 2), where), edges="delaunay")
    assert Graph.from_points(np.ones((4, 2)), edges="full").n_edges == 6


def test_from_points_knn_scale_free_and_bad_dimensions():
    """k-NN graphs do not depend on the scale of the points (no overflow at 1e300); points
    without coordinates are refused by name."""
    P = np.random.default_rng(0).random((10, 2))
    ref = Graph.from_points(P, edges="knn", k=3).adjacency > 0
    for scale in (1e-300, 1e6, 1e300):
        np.testing.assert_array_equal(Graph.from_points(P * scale, edges="knn", k=3).adjacency > 0,
                                      ref)
    with pytest.raises(ValueError, match="`points` must have at least one coordinate"):
        Graph.from_points(np.zeros((3, 0)), edges="knn")


def test_distances_and_weighted(rng):
    P = np.array([[0.0, 0.0], [3.0, 4.0]])
    g = Graph.from_points(P, edges="full", weighted=True)
    assert g.adjacency[0, 1] == pytest.approx(5.0)
    assert g.distances()[1, 0] == pytest.approx(5.0)
    assert g.angles()[0, 1] == pytest.approx(np.arctan2(4, 3))


def test_permute_relabels_everything(rng):
    P = rng.random((6, 2))
    E = rng.random((6, 6))
    E = E + E.T
    g = Graph(Graph.from_points(P, edges="full").adjacency, points=P,
              node_features=rng.random((6, 3)), edge_features=E, node_labels=np.arange(6))
    perm = rng.permutation(6)
    h = g.permute(perm)
    np.testing.assert_allclose(h.points, P[perm])
    np.testing.assert_allclose(h.edge_features, E[np.ix_(perm, perm)])
    np.testing.assert_array_equal(h.node_labels, perm)


def test_networkx_round_trip(rng):
    g = Graph.from_points(rng.random((5, 2)), edges="delaunay", node_labels=np.arange(5))
    G = g.to_networkx()
    assert isinstance(G, nx.Graph) and G.number_of_edges() == g.n_edges
    h = Graph.from_networkx(G, label="label")
    np.testing.assert_allclose(h.adjacency, g.adjacency)
    np.testing.assert_allclose(h.points, g.points)
    np.testing.assert_array_equal(h.node_labels, np.arange(5))


@pytest.mark.parametrize("adj, msg", [
    (np.zeros((2, 3)), "square"),
    (np.zeros((0, 0)), "non-empty"),
    (np.array([[1.0, 0], [0, 0]]), "zero diagonal"),
    (np.array([[0, -1.0], [-1.0, 0]]), "non-negative"),
    (np.array([[0, 1.0], [0, 0]]), "symmetric"),
    (np.array([[0, np.nan], [np.nan, 0]]), "finite"),
])
def test_graph_validation(adj, msg):
    with pytest.raises(ValueError, match=msg):
        Graph(adj)


def test_graph_attribute_shapes():
    with pytest.raises(ValueError, match="points"):
        Graph(np.zeros((3, 3)), points=np.zeros((2, 2)))
    with pytest.raises(ValueError, match="edge_features"):
        Graph(np.zeros((3, 3)), edge_features=np.zeros((2, 2)))
    with pytest.raises(ValueError, match="edges"):
        Graph.from_points(np.zeros((4, 2)), edges="ring")
    with pytest.raises(ValueError, match="at least one"):
        Graph.from_points(np.zeros((0, 2)))


@pytest.mark.parametrize("scale", [1e-310, 1e-300, 1e-180, 1e-100, 1.0, 1e80, 1e300])
def test_delaunay_edges_do_not_depend_on_units(scale):
    # Qhull's tolerances are absolute: points at 1e80 were refused, at 1e-180 triangulated
    # differently (joggled); subnormal spans (1e-310) overflowed the power-of-two scale to inf
    # (NaN distances, NaN points given to Qhull)
    P = np.random.default_rng(0).random((12, 2))
    ref = Graph.from_points(P).mask
    np.testing.assert_array_equal(Graph.from_points(P * scale).mask, ref)
    np.testing.assert_allclose(Graph.from_points(P * scale, weighted=True).adjacency / scale,
                               Graph.from_points(P, weighted=True).adjacency, rtol=1e-12)


def test_delaunay_gives_a_repeated_point_edges():
    # Qhull keeps one copy of a repeated point and leaves the other out of every triangle: it
    # was an isolated node
    P = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [0.5, 0.4], [0.5, 0.4]])
    assert np.all(Graph.from_points(P).mask.sum(1) > 0)


def test_tiny_distances_and_angles_of_1d_points():
    g = Graph.from_points(np.array([[0.0, 0.0], [3.0, 4.0], [6.0, 0.0]]) * 1e-170,
                          edges="full", weighted=True)
    assert g.n_edges == 3                                  # squares underflowed: 0 edges
    np.testing.assert_allclose(g.distances()[0, 1], 5e-170, rtol=1e-12)
    with pytest.raises(ValueError, match="angles need points of at least 2 coordinates"):
        Graph.from_points(np.array([[0.0], [1.0], [3.0]]), edges="full").angles()


def test_to_networkx_keeps_object_labels():
    """Labels Graph accepts (None, ints beyond int64: what from_networkx builds from mixed node
    data) crashed to_networkx on `.item()`."""
    A = np.array([[0, 1], [1, 0.0]])
    G = Graph(A, node_labels=[None, None]).to_networkx()
    assert [G.nodes[v]["label"] for v in G] == [None, None]
    G = Graph(A, node_labels=[2**70, 1]).to_networkx()
    assert [G.nodes[v]["label"] for v in G] == [2**70, 1]
    G = Graph(A, node_labels=[3, 1]).to_networkx()
    assert [type(G.nodes[v]["label"]) for v in G] == [int, int]


def test_from_points_weighted_must_be_a_bool():
    """weighted="no" was read by truthiness and built a weighted graph."""
    P = np.random.default_rng(0).random((6, 2))
    with pytest.raises(TypeError, match="`weighted` must be a bool"):
        Graph.from_points(P, edges="full", weighted="no")


@pytest.mark.parametrize("edges", ["full", "knn", "delaunay"])
def test_weighted_graph_of_coincident_points_is_refused(edges):
    """The weight of an edge is its length: two coincident points lost their edge silently (6
    edges unweighted, 5 weighted)."""
    P = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match="`weighted=True` .* points 0 and 1 coincide"):
        Graph.from_points(P, edges=edges, weighted=True)
    assert Graph.from_points(P[1:], edges=edges, weighted=True).adjacency.min() == 0.0


def test_from_networkx_weight_beyond_float64_is_named():
    import networkx as nx

    G = nx.Graph()
    G.add_edge(0, 1, weight=10**400)
    with pytest.raises(ValueError, match="`G`'s edge attribute 'weight' .* must hold numbers"):
        Graph.from_networkx(G)


def test_graph_owns_its_arrays(rng):
    """A frozen Graph does not change when the caller edits the arrays it was built from (it
    kept references: zeroing a row of the caller's adjacency made the graph asymmetric)."""
    A = np.ones((4, 4)) - np.eye(4)
    P, F, L, E = rng.random((4, 2)), rng.random((4, 3)), np.arange(4), A * 2.0
    g = Graph(A, points=P, node_features=F, node_labels=L, edge_features=E)
    before = [x.copy() for x in (g.adjacency, g.points, g.node_features, g.node_labels,
                                 g.edge_features)]
    for x in (A, P, F, L, E):
        x[0] = 7
    after = (g.adjacency, g.points, g.node_features, g.node_labels, g.edge_features)
    for b, a in zip(before, after):
        assert np.array_equal(a, b) and not a.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        g.adjacency[0, 1] = 3.0
    h = Graph(np.asarray(A[1:, 1:]), node_features=F[1:, 0])      # views of the caller's memory
    A[1, 2] = A[2, 1] = 0.0
    F[1, 0] = -5.0
    assert h.adjacency[0, 1] == 1.0 and h.node_features[0, 0] != -5.0
