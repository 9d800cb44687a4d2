"""transync.graphs.canonical_node_order: a node order that renumbering does not change."""

import itertools

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from transync.graphs import Graph, canonical_node_order


def _form(A, colors, order):
    """The graph in the given order: its adjacency and colours."""
    return A[np.ix_(order, order)], None if colors is None else np.asarray(colors)[order]


def _same_form_after_renumbering(A, colors, perm):
    B = A[np.ix_(perm, perm)]
    c2 = None if colors is None else np.asarray(colors)[perm]
    a, b = canonical_node_order(A, colors), canonical_node_order(B, c2)
    (fa, ca), (fb, cb) = _form(A, colors, a), _form(B, c2, b)
    return np.array_equal(fa, fb) and (ca is None or np.array_equal(ca, cb))


@st.composite
def coloured_trees(draw):
    """A random tree (Prüfer-like parent choice) with colours from a few values, and a random
    renumbering of its nodes."""
    n = draw(st.integers(1, 14))
    parents = [draw(st.integers(0, v - 1)) for v in range(1, n)]
    A = np.zeros((n, n))
    for v, u in enumerate(parents, start=1):
        A[u, v] = A[v, u] = 1
    colors = draw(st.one_of(st.none(), st.lists(st.integers(0, 2), min_size=n, max_size=n)))
    perm = draw(st.permutations(range(n)))
    return A, colors, np.array(perm, dtype=np.int64)


@settings(max_examples=200, deadline=None)
@given(coloured_trees())
def test_trees_get_one_form_under_every_numbering(case):
    """On trees colour refinement finds the orbits, so the order is canonical: the reordered
    adjacency and colours are the same matrix whatever the input numbering."""
    A, colors, perm = case
    assert _same_form_after_renumbering(A, colors, perm)


@pytest.mark.parametrize("name, A", [
    ("cycle", nx.to_numpy_array(nx.cycle_graph(9))),
    ("complete", nx.to_numpy_array(nx.complete_graph(6))),
    ("petersen", nx.to_numpy_array(nx.petersen_graph())),
    ("hypercube", nx.to_numpy_array(nx.hypercube_graph(3))),
    ("empty", np.zeros((5, 5))),
    ("ladder", nx.to_numpy_array(nx.ladder_graph(5))),
])
def test_symmetric_graphs_get_one_form(name, A):
    """Vertex-transitive and other symmetric graphs: every individualized class is an orbit."""
    rng = np.random.default_rng(0)
    for _ in range(10):
        assert _same_form_after_renumbering(A, None, rng.permutation(len(A))), name


def test_weighted_and_directed_graphs():
    """Weights are compared exactly and directed edges by side: random weighted digraphs get
    one form; a weight or an edge direction changes the form."""
    rng = np.random.default_rng(1)
    for _ in range(50):
        n = int(rng.integers(2, 12))
        A = (rng.random((n, n)) < 0.3) * rng.integers(1, 4, (n, n)).astype(float)
        np.fill_diagonal(A, 0)
        assert _same_form_after_renumbering(A, rng.integers(0, 2, n), rng.permutation(n))
    path = np.diag([1.0, 1.0], 1)          # 0 -> 1 -> 2: the direction tells the ends apart,
    first = set()                          # so one end (the same one) comes first every time
    for perm in itertools.permutations(range(3)):
        p = np.array(perm)
        first.add(int(p[canonical_node_order(path[np.ix_(p, p)])[0]]))
    assert len(first) == 1
    a = canonical_node_order(np.array([[0, 1.0], [1.0, 0]]))
    b = canonical_node_order(np.array([[0, 2.0], [2.0, 0]]))
    assert a.tolist() == b.tolist() == [0, 1]


def test_self_loops_are_part_of_the_colour():
    """A self-loop tells its node apart (it is not an edge to a same-coloured neighbour): a
    looped node beside the edge 1 - 2 gets one form under all six numberings, and a loop's
    weight counts."""
    A = np.zeros((3, 3))
    A[0, 0] = 1
    A[1, 2] = A[2, 1] = 1
    forms = set()
    for perm in itertools.permutations(range(3)):
        p = np.array(perm)
        B = A[np.ix_(p, p)]
        o = canonical_node_order(B)
        forms.add(B[np.ix_(o, o)].tobytes())
    assert len(forms) == 1
    rng = np.random.default_rng(5)
    for _ in range(50):
        n = int(rng.integers(2, 10))
        A = np.triu(rng.random((n, n)) < 0.3, 1) * rng.integers(1, 3, (n, n)).astype(float)
        A = A + A.T + np.diag((rng.random(n) < 0.4) * rng.integers(1, 3, n))
        assert _same_form_after_renumbering(A, None, rng.permutation(n))


def test_colours_come_first():
    """The order sorts the nodes by their initial colours (integers, strings, booleans),
    then refines within a colour."""
    rng = np.random.default_rng(2)
    A = np.triu(rng.random((12, 12)) < 0.3, 1).astype(float)
    A = A + A.T
    colors = rng.integers(0, 4, 12)
    order = canonical_node_order(A, colors)
    assert sorted(order.tolist()) == list(range(12))
    assert np.all(np.diff(colors[order]) >= 0)
    words = np.array(["c", "a", "b", "a"])
    assert words[canonical_node_order(np.zeros((4, 4)), words)].tolist() == ["a", "a", "b", "c"]
    assert canonical_node_order(np.zeros((3, 3)), [True, False, True])[0] == 1
    assert canonical_node_order(np.zeros((0, 0))).shape == (0,)
    assert canonical_node_order(np.zeros((1, 1))).tolist() == [0]


def test_refinement_splits_by_structure():
    """A star's centre (degree 4) sorts apart from its leaves, whatever its number."""
    A = np.zeros((5, 5))
    A[3, [0, 1, 2, 4]] = A[[0, 1, 2, 4], 3] = 1
    order = canonical_node_order(A)
    assert order[0] == 3 or order[-1] == 3


def test_not_a_full_canonical_labelling():
    """The documented limit: colour refinement cannot tell a 6-cycle from two triangles (every
    node has degree 2), and individualizing "the first node" then depends on the numbering.
    The order is still a valid permutation every time."""
    A = np.zeros((12, 12))
    for cyc in ([0, 1, 2, 3, 4, 5], [6, 7, 8], [9, 10, 11]):
        for u, v in zip(cyc, cyc[1:] + cyc[:1]):
            A[u, v] = A[v, u] = 1
    rng = np.random.default_rng(3)
    forms = set()
    for _ in range(20):
        p = rng.permutation(12)
        B = A[np.ix_(p, p)]
        o = canonical_node_order(B)
        assert sorted(o.tolist()) == list(range(12))
        forms.add(B[np.ix_(o, o)].tobytes())
    assert len(forms) > 1


def test_graph_permute_round_trip():
    """Graph.permute(order) is the canonical graph: it carries labels and features along."""
    rng = np.random.default_rng(4)
    g = Graph(nx.to_numpy_array(nx.path_graph(6)), node_labels=np.array([0, 1, 1, 0, 1, 0]),
              node_features=rng.random((6, 2)))
    order = canonical_node_order(g.adjacency, g.node_labels)
    h = g.permute(order)
    np.testing.assert_array_equal(h.node_labels, g.node_labels[order])
    np.testing.assert_array_equal(h.node_features, g.node_features[order])


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(adjacency=np.zeros((2, 3))), ValueError, r"`adjacency` must have shape \(n, n\)"),
    (dict(adjacency=np.array([[0, np.nan], [np.nan, 0]])), ValueError, "`adjacency` must be "
                                                                        "finite"),
    (dict(adjacency="abc"), TypeError, "`adjacency` must be an array"),
    (dict(adjacency=None), TypeError, "`adjacency` must be an array"),
    (dict(adjacency=np.zeros((3, 3)), colors=[1, 2]), ValueError,
     r"`colors` must have shape \(3,\)"),
    (dict(adjacency=np.zeros((3, 3)), colors=[np.nan, 1, 2]), ValueError,
     "`colors` must be finite"),
    (dict(adjacency=np.zeros((3, 3)), colors=[1j, 1, 1]), TypeError, "`colors`"),
    (dict(adjacency=np.zeros((3, 3)), colors=np.array([1, "a", 2], dtype=object)), TypeError,
     "`colors` must be values of one comparable kind"),
])
def test_bad_input(kwargs, error, match):
    with pytest.raises(error, match=match):
        canonical_node_order(**kwargs)
