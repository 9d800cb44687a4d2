"""Bad and degenerate input at every public entry point of matching and graphs (issues 9, 13)."""

from __future__ import annotations

import inspect
import re
import warnings

import networkx as nx
import numpy as np
import pytest
import scipy.sparse as sp

from transync.datasets import make_point_matching_problem
from transync.exceptions import ConvergenceWarning, DegenerateInputError
from transync.graphs import Graph
from transync.matching import (
    METHODS,
    DenseAffinity,
    FactorizedAffinity,
    SeparableAffinity,
    SparseAffinity,
    gaussian_edge_affinity,
    gaussian_edge_factors,
    gaussian_node_affinity,
    hungarian,
    match_graphs,
    rrwm,
    sinkhorn,
    sm,
    solver_options,
)
from transync.metrics import matching_accuracy

QUADRATIC = ("sm", "rrwm", "ipfp", "ga", "pf")


def _valid(assignment, n1, n2):
    a = np.asarray(assignment)
    matched = a[a >= 0]
    return (a.shape == (n1,) and a.dtype.kind == "i" and np.all(a >= -1) and np.all(a < n2)
            and np.unique(matched).size == matched.size and matched.size == min(n1, n2))


# --------------------------------------------------------------------------- front door options


@pytest.mark.parametrize("method", list(METHODS))
def test_unknown_solver_option_names_solver_and_lists_accepted(method, rng):
    g = Graph.from_points(rng.random((5, 2)), edges="full", node_features=rng.random((5, 3)))
    accepted = ", ".join(solver_options(method))
    msg = (f"match_graphs(method='{method}') got unknown solver option(s) 'maxiter'; "
           f"{method} accepts {accepted}")
    with pytest.raises(TypeError, match=re.escape(msg)):
        match_graphs(g, g, method=method, maxiter=5)


def test_unknown_option_suggests_close_name_and_refuses_n1(rng):
    g = Graph.from_points(rng.random((5, 2)), edges="full")
    with pytest.raises(TypeError, match=r"did you mean 'max_iter' for 'maxiter'\?"):
        match_graphs(g, g, method="rrwm", maxiter=5)
    with pytest.raises(TypeError, match=r"unknown solver option\(s\) 'n1'"):
        match_graphs(g, g, method="sm", n1=5)


@pytest.mark.parametrize("method", list(METHODS))
def test_solver_options_come_from_the_signature(method):
    params = inspect.signature(METHODS[method]).parameters.values()
    kw = [p.name for p in params if p.kind is p.KEYWORD_ONLY and p.name not in ("n1", "n2")]
    assert list(solver_options(method)) == kw and kw


def test_accepted_options_pass_through(rng):
    g1 = Graph.from_points(rng.random((6, 2)), edges="full")
    res = match_graphs(g1, g1, method="rrwm", max_iter=400, variant="original")
    assert res.assignment.tolist() == list(range(6))


@pytest.mark.parametrize("method", ["hungarian", "sinkhorn"])
def test_linear_method_on_edge_only_graphs_raises(method, rng):
    g = Graph.from_points(rng.random((5, 2)), edges="full")
    with pytest.raises(ValueError, match=f"method='{method}' needs a unary term"):
        match_graphs(g, g, method=method)


# --------------------------------------------------------------------------- numeric scale


@pytest.mark.parametrize("method", QUADRATIC)
def test_huge_coordinates_refused_with_sigma2_hint(method):
    p = make_point_matching_problem(12, 0, 0.02, edges="full", rng=3)
    g1 = Graph.from_points(1e9 * p.g1.points, edges="full")
    g2 = Graph.from_points(1e9 * p.g2.points, edges="full")
    with pytest.raises(DegenerateInputError, match=r"`sigma2`=0.15 is too small for edge "
                                                   r"attributes \('length'\).*Set `sigma2`"):
        match_graphs(g1, g2, method=method)


def test_edge_attributes_whose_square_overflows_are_refused_by_name():
    """Edge weights ~1e300: building the sigma2 hint (0.6 * scale**2) raised OverflowError; at
    1e308 the separable expansion raised numpy's LinAlgError. Weights and edge features are
    now held to the cap on edge lengths (1e150), before any affinity is built."""
    from transync import match_collection

    A = np.ones((3, 3)) - np.eye(3)
    with pytest.raises(ValueError, match=r"adjacency weights of `g1` overflow .*rescale them"):
        match_collection([Graph(A * 1e300 * (k + 1)) for k in range(3)], progress=False)
    for scale in (1e151, 1e308):
        g = Graph(A * scale)
        with pytest.raises(ValueError, match=r"adjacency weights of `g1` overflow"):
            match_graphs(g, g)
        h = Graph(A, edge_features=A * scale)
        with pytest.raises(ValueError, match=r"edge_features of `graphs\[0\]` overflow"):
            gaussian_edge_factors([h, h])
    g = Graph(A * 1e140)                    # below the cap: matched
    assert match_graphs(g, g, sigma2=1e280).objective > 0


def test_suggested_sigma2_recovers_the_unit_scale_result():
    p = make_point_matching_problem(12, 0, 0.02, edges="full", rng=3)
    g1 = Graph.from_points(1e6 * p.g1.points, edges="full")
    g2 = Graph.from_points(1e6 * p.g2.points, edges="full")
    with pytest.raises(ValueError, match=r"e\.g\. sigma2=([0-9.e+]+)") as err:   # also a ValueError
        match_graphs(g1, g2)
    sigma2 = float(re.search(r"e\.g\. sigma2=([0-9.e+]+)", str(err.value)).group(1))
    big = match_graphs(g1, g2, sigma2=sigma2)
    assert big.objective > 0
    small = match_graphs(p.g1, p.g2, sigma2=sigma2 / 1e12)    # the same problem at unit scale
    np.testing.assert_array_equal(big.assignment, small.assignment)
    assert matching_accuracy(big.assignment, p.truth) == 1.0


def test_huge_node_features_refused():
    g1 = Graph.from_points(np.zeros((3, 2)) + [[0, 0], [1, 0], [0, 1]],
                           node_features=1e9 * np.arange(3.0))
    g2 = g1.permute([2, 0, 1])
    g2 = Graph(g2.adjacency, points=g2.points, node_features=g2.node_features + 5e8)
    with pytest.raises(DegenerateInputError, match=r"`sigma2`=1 is too small for node features"):
        gaussian_node_affinity(g1, g2)
    with pytest.raises(DegenerateInputError, match="pass `node_affinity=gaussian_node_affinity"):
        match_graphs(g1, g2, method="hungarian")


def test_exact_copies_at_huge_scale_still_match():
    """Underflow is refused only when the affinity is dead; exact copies keep their edges."""
    P = 1e9 * np.random.default_rng(5).random((8, 2))
    g1 = Graph.from_points(P, edges="full")
    perm = np.random.default_rng(6).permutation(8)
    res = match_graphs(g1, g1.permute(perm), method="rrwm")
    assert np.all(perm[res.assignment] == np.arange(8))


# --------------------------------------------------------------------------- Affinity constructors


def test_dense_affinity_validation():
    with pytest.raises(ValueError, match=r"`K` must have shape \(n1\*n2, n1\*n2\) = \(9, 9\), "
                                         r"got \(4, 4\)"):
        sm(DenseAffinity(np.ones((4, 4)), 3, 3))
    with pytest.raises(ValueError, match="`K` must be finite, got 81 NaN or infinite entries"):
        DenseAffinity(np.full((9, 9), np.nan), 3, 3)
    with pytest.raises(ValueError, match="`K` must be non-negative, got minimum -1"):
        DenseAffinity(-np.ones((9, 9)), 3, 3)
    with pytest.raises(TypeError, match="`K` must be real, got complex values"):
        DenseAffinity(np.ones((9, 9)) + 1j, 3, 3)
    with pytest.raises(TypeError, match="`K` must be an array, got str"):
        DenseAffinity("abc", 3, 3)
    with pytest.raises(ValueError, match="`n1` must be >= 1, got 0"):
        DenseAffinity(np.ones((0, 0)), 0, 3)
    with pytest.raises(TypeError, match="`n2` must be an int, got float 3.0"):
        DenseAffinity(np.ones((9, 9)), 3, 3.0)


def test_sparse_affinity_validation():
    with pytest.raises(ValueError, match=r"= \(9, 9\), got \(4, 4\)"):
        SparseAffinity(sp.eye(4, format="csr"), 3, 3)
    K = sp.eye(9, format="csr") * np.nan
    with pytest.raises(ValueError, match="`K` must be finite"):
        SparseAffinity(K, 3, 3)
    with pytest.raises(ValueError, match="must be non-negative"):
        SparseAffinity(-sp.eye(9, format="csr"), 3, 3)
    with pytest.raises(TypeError, match="`K` must be a real sparse matrix, got dtype complex128"):
        SparseAffinity(sp.eye(9, format="csr", dtype=complex), 3, 3)
    with pytest.raises(TypeError, match="`K` must be a real sparse matrix"):
        rrwm(sp.eye(9, format="csr", dtype=complex), n1=3, n2=3)


def test_factorized_affinity_validation():
    e = np.array([[0, 1], [1, 0]])
    FactorizedAffinity(None, np.ones((2, 2)), e, e, 2, 2)          # valid
    with pytest.raises(ValueError, match=r"`edge` must have shape \(m1, m2\) = \(2, 2\)"):
        FactorizedAffinity(None, np.ones((3, 2)), e, e, 2, 2)
    with pytest.raises(ValueError, match=r"`edges1` must hold node indices in \[0, 2\), got "
                                         r"range \[0, 5\]"):
        FactorizedAffinity(None, None, [[0, 5]], e, 2, 2)
    with pytest.raises(TypeError, match="`edges2` must hold integer node indices"):
        FactorizedAffinity(None, None, e, [[0.5, 1]], 2, 2)
    with pytest.raises(ValueError, match=r"`edges1` must have shape \(m, 2\)"):
        FactorizedAffinity(None, None, [0, 1, 1], e, 2, 2)
    with pytest.raises(ValueError, match="`edge` must be finite"):
        FactorizedAffinity(None, np.full((2, 2), np.nan), e, e, 2, 2)
    with pytest.raises(ValueError, match=r"`node` must have shape \(n1, n2\) = \(2, 2\)"):
        FactorizedAffinity(np.ones((3, 2)), None, e, e, 2, 2)
    with pytest.raises(ValueError, match="`node` must be non-negative"):
        FactorizedAffinity(-np.ones((2, 2)), None, e, e, 2, 2)


def test_separable_affinity_validation():
    F, G = np.ones((2, 3, 3)), np.ones((2, 4, 4))
    assert SeparableAffinity(None, F, G).shape == (3, 4)
    with pytest.raises(ValueError, match=r"`F` must have shape \(R, n1, n1\)"):
        SeparableAffinity(None, np.ones((2, 3, 4)), G)
    with pytest.raises(ValueError, match=r"`G` must have shape \(R, n2, n2\) with R=2"):
        SeparableAffinity(None, F, np.ones((3, 4, 4)))
    with pytest.raises(ValueError, match="`F` must have 3 dimensions"):
        SeparableAffinity(None, np.ones((3, 3)), G)
    with pytest.raises(ValueError, match="`G` must be finite"):
        SeparableAffinity(None, F, np.full((2, 4, 4), np.inf))
    with pytest.raises(ValueError, match=r"`node` must have shape \(n1, n2\) = \(3, 4\)"):
        SeparableAffinity(np.ones((4, 3)), F, G)
    with pytest.raises(ValueError, match="`max_error` must be finite and >= 0"):
        SeparableAffinity(None, F, G, max_error=-1.0)


@pytest.mark.parametrize("method", QUADRATIC)
def test_solver_k_n1_n2_validation(method):
    solver = METHODS[method]
    K = np.ones((4, 4))
    with pytest.raises(TypeError, match="`n1` and `n2` are required when `K` is a matrix"):
        solver(K)
    with pytest.raises(ValueError, match=r"must have shape \(n1\*n2, n1\*n2\) = \(9, 9\)"):
        solver(K, n1=3, n2=3)
    with pytest.raises(ValueError, match="is an Affinity of shape"):
        solver(DenseAffinity(K, 2, 2), n1=3, n2=2)
    with pytest.raises(TypeError, match="`K` must be real"):
        solver(K + 0j, n1=2, n2=2)
    with pytest.raises(ValueError, match="`K` must be finite"):
        solver(np.full((4, 4), np.nan), n1=2, n2=2)


@pytest.mark.parametrize("solver", [hungarian, sinkhorn])
def test_linear_solvers_refuse_complex_and_nan(solver):
    with pytest.raises(TypeError, match="`scores` must be real"):
        solver(np.ones((2, 2)) + 1j)
    with pytest.raises(ValueError, match="`scores` must be finite"):
        solver(np.array([[1.0, np.nan], [0.0, 1.0]]))
    with pytest.raises(TypeError, match="`scores` must be an array, got str"):
        solver("ab")


# --------------------------------------------------------------------------- Graph


@pytest.mark.parametrize("kwargs, error, msg", [
    ({"adjacency": np.zeros((2, 3))}, ValueError,
     r"`adjacency` must be square, got shape \(2, 3\)"),
    ({"adjacency": np.array([[0, 1], [0, 0.0]])}, ValueError,
     "must be symmetric for an undirected"),
    ({"adjacency": np.zeros((0, 0))}, ValueError, "must describe a non-empty graph"),
    ({"adjacency": np.zeros((2, 2)) + 1j}, TypeError, "`adjacency` must be real"),
    ({"adjacency": [["a", "b"], ["c", "d"]]}, TypeError, "`adjacency` must be numeric"),
    ({"adjacency": np.full((2, 2), np.nan)}, ValueError, "`adjacency` must be finite"),
    ({"adjacency": np.zeros((2, 2)), "points": [[0, np.nan], [1, 1]]}, ValueError,
     "`points` must be finite"),
    ({"adjacency": np.zeros((2, 2)), "points": np.zeros((3, 2))}, ValueError,
     r"`points` must have shape \(2, \*\)"),
    ({"adjacency": np.zeros((2, 2)), "node_features": np.zeros((3, 4))}, ValueError,
     r"`node_features` must have shape \(2, \*\)"),
    ({"adjacency": np.zeros((2, 2)), "node_features": np.zeros((2, 4)) + 1j}, TypeError,
     "`node_features` must be real"),
    ({"adjacency": np.zeros((2, 2)), "edge_features": np.zeros((2, 3))}, ValueError,
     r"`edge_features` must have shape \(2, 2\)"),
    ({"adjacency": np.zeros((2, 2)), "node_labels": [1, 2, 3]}, ValueError,
     r"`node_labels` must have shape \(2,\)"),
    ({"adjacency": np.zeros((2, 2)), "node_labels": [1j, 2]}, TypeError,
     "`node_labels` must be integer labels, got complex"),
    ({"adjacency": np.zeros((2, 2)), "node_labels": [np.nan, 2]}, ValueError,
     "`node_labels` must be finite"),
    ({"adjacency": np.zeros((2, 2)), "directed": "yes"}, TypeError,
     "`directed` must be a bool, got str 'yes'"),
    ({"adjacency": np.zeros((2, 2)), "meta": None}, TypeError, "`meta` must be a dict"),
])
def test_graph_constructor_refuses(kwargs, error, msg):
    with pytest.raises(error, match=msg):
        Graph(**kwargs)


def test_graph_other_entry_points_refuse(rng):
    g = Graph.from_points(rng.random((4, 2)))
    with pytest.raises(TypeError, match=r"`perm` must hold integer node indices"):
        g.permute([0.5, 1.2, 2.0, 3.0])
    assert np.array_equal(g.permute([3.0, 2.0, 1.0, 0.0]).adjacency,
                          g.permute([3, 2, 1, 0]).adjacency)     # integer-valued floats: indices
    with pytest.raises(ValueError, match=r"`perm` must be a permutation of range\(4\)"):
        g.permute([0, 1, 2])
    with pytest.raises(TypeError, match="`perm` must be real"):
        g.permute(np.arange(4) + 0j)
    with pytest.raises(TypeError, match="`G` must be a networkx graph, got ndarray"):
        Graph.from_networkx(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="`G` must have at least one node"):
        Graph.from_networkx(nx.Graph())
    huge = np.array([[-1.7e308, 0], [1.7e308, 0], [0, 1], [0, -1.0]])     # finite, far apart
    for make in (Graph.from_points, lambda P: Graph(np.ones((4, 4)) - np.eye(4), points=P)):
        with pytest.raises(ValueError, match=r"`points` must have coordinates of magnitude <= "
                                             r"1e\+300 .*got 1.7e\+308"):
            make(huge)          # distances were inf with an overflow warning; delaunay misreported
    g = Graph.from_points(huge / 1.7e8, edges="full")
    assert np.isfinite(g.distances()).all() and g.distances().max() == pytest.approx(2e300)
    # weighted, points 2 and 3 (1.2e-8 apart beside a spread of 2e300) lost their edge
    with pytest.raises(ValueError, match="points 2 and 3 are closer than float64 resolves"):
        Graph.from_points(huge / 1.7e8, edges="full", weighted=True)
    G = nx.Graph()
    G.add_edge(0, 1, weight="a")            # these three were numpy's or Python's words
    with pytest.raises(ValueError, match=r"`G`'s edge attribute 'weight' \(`weight`\) must hold"):
        Graph.from_networkx(G)
    G = nx.Graph()
    G.add_node(0, pos=(0, 0))
    G.add_node(1, pos=(1,))
    G.add_edge(0, 1)
    with pytest.raises(ValueError, match=r"node attribute 'pos' \(`points`\) must have one shape"):
        Graph.from_networkx(G)
    with pytest.raises(TypeError, match=r"`weight` must be an attribute name \(str\) or None"):
        Graph.from_networkx(nx.path_graph(3), weight=[])
    with pytest.raises(TypeError, match="`points` must be real"):
        Graph.from_points(np.zeros((3, 2)) + 1j)
    with pytest.raises(ValueError, match="`points` must hold at least one point, got 0"):
        Graph.from_points(np.zeros((0, 2)))
    with pytest.raises(ValueError, match="`points` must be finite"):
        Graph.from_points([[0, 0], [np.inf, 1]])


@pytest.mark.parametrize("P", [np.array([[0, 0], [1, 1], [2, 2], [3, 3.0]]),
                               np.array([[0, 0], [0, 0], [1, 0], [0, 1.0]])])
def test_degenerate_delaunay_gives_a_graph(P):
    g = Graph.from_points(P)                      # repeated or collinear points: joggled
    assert g.n_nodes == 4 and g.n_edges >= 3
    assert np.array_equal(g.adjacency, g.adjacency.T) and not np.any(np.diag(g.adjacency))
    # all at one place: refused wherever they sit (joggling "triangulated" them at the origin
    # only; tests/test_graphs.py)
    with pytest.raises(ValueError, match="all at one place"):
        Graph.from_points(np.zeros((4, 2)))


# --------------------------------------------------------------------------- degenerate but legal

CASES = {
    "one-one": (np.zeros((1, 2)), np.zeros((1, 2))),
    "one-three": (np.zeros((1, 2)), np.array([[0, 0], [1, 0], [0, 1.0]])),
    "three-one": (np.array([[0, 0], [1, 0], [0, 1.0]]), np.zeros((1, 2))),
    "two-identical": (np.zeros((2, 2)), np.zeros((2, 2))),
    "2v3": (np.array([[0, 0], [1, 0.0]]), np.array([[0, 0], [1, 0], [5, 5.0]])),
    "6v4": (np.array([[0, 0], [1, 0], [0, 1], [1, 1], [3, 3], [2, 0.5]]),
            np.array([[0, 0], [1, 0], [0, 1], [1, 1.0]])),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("method", list(METHODS))
def test_degenerate_legal_input_gives_valid_assignment(case, method):
    P1, P2 = CASES[case]
    g1 = Graph.from_points(P1, edges="full", node_features=P1)
    g2 = Graph.from_points(P2, edges="full", node_features=P2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # a ConvergenceWarning is a legal answer here
        res = match_graphs(g1, g2, method=method)
    assert _valid(res.assignment, len(P1), len(P2)), res.assignment
    assert np.isfinite(res.objective)


@pytest.mark.parametrize("method", QUADRATIC)
def test_rectangular_planted_valid_both_ways(method, rng):
    p = make_point_matching_problem(7, 0, 0.0, edges="full", rng=rng)
    sub = Graph.from_points(p.g2.points[:5], edges="full")
    for a, b in ((p.g1, sub), (sub, p.g1)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = match_graphs(a, b, method=method)
        assert _valid(res.assignment, a.n_nodes, b.n_nodes)


def test_points_of_different_dimensions_refused(rng):
    g2d = Graph.from_points(rng.random((5, 2)), edges="full")
    g3d = Graph.from_points(rng.random((5, 3)), edges="full")
    with pytest.raises(ValueError, match="`g1` and `g2` must have points of the same dimension "
                                         "for attribute='length', got 2 and 3"):
        match_graphs(g2d, g3d)
    with pytest.raises(ValueError, match="`g1.points` and `g2.points` must have the same width"):
        gaussian_node_affinity(g2d, g3d, attribute="points")
    with pytest.raises(TypeError, match="`g1` and `g2` must be Graph objects, got ndarray"):
        gaussian_node_affinity(np.zeros((2, 2)), g2d)
    # attributes that do not use the points still work
    aff = gaussian_edge_affinity(g2d, g3d, attribute="weight")
    assert aff.shape == (5, 5)


def test_hungarian_maximize_must_be_bool():
    with pytest.raises(TypeError, match="`maximize` must be a bool, got str 'no'"):
        hungarian(np.eye(2), maximize="no")
    assert hungarian(np.eye(2), maximize=False).assignment.tolist() == [1, 0]


def test_overflowing_edge_lengths_refused():
    g1 = Graph.from_points(1e300 * np.array([[0, 0], [1, 0], [0, 1.0]]), edges="full")
    g2 = Graph.from_points(np.array([[0, 0], [1, 0], [0, 1.0]]), edges="full")
    with pytest.raises(ValueError, match="the edge lengths of `g1` overflow"):
        match_graphs(g1, g2)


def test_nearly_symmetric_adjacency_stored_exactly_symmetric():
    A = np.array([[0, 1, 2], [1, 0, 3], [2, 3 * (1 + 1e-12), 0]])
    g = Graph(A)
    assert np.array_equal(g.adjacency, g.adjacency.T)
    np.testing.assert_allclose(g.adjacency, A, rtol=1e-11)
    B = np.array([[0, 1.0], [1.0, 0]])
    assert Graph(B).adjacency[0, 1] == 1.0                 # exact input kept bit for bit


@pytest.mark.parametrize("scale", [1e-300, 1e200, 1e298])
@pytest.mark.parametrize("method", list(METHODS))
def test_extreme_affinity_scale_same_answer_no_overflow(scale, method):
    """Every solver ranks matchings by vec(X)^T K vec(X): a positive factor changes nothing."""
    K = np.ones((4, 4)) + 3 * np.eye(4)
    K[1, 2] = K[2, 1] = 0.0
    res = METHODS[method](scale * K, n1=2, n2=2)       # warnings are errors in the test suite
    assert res.assignment.tolist() == [0, 1]
    assert res.objective == pytest.approx(10 * scale, rel=1e-12)
    if method == "sm":
        ref = METHODS[method](K, n1=2, n2=2).info["eigenvalue"]
        assert res.info["eigenvalue"] == pytest.approx(scale * ref, rel=1e-9)


def test_gaussian_edge_affinity_scalar_options_validated(rng):
    g = Graph.from_points(rng.random((4, 2)), edges="full")
    with pytest.raises(ValueError, match="`angle_weight` must be finite and >= 0, got -1.0"):
        gaussian_edge_affinity(g, g, attribute="length+angle", angle_weight=-1.0)
    with pytest.raises(ValueError, match="`tol` must be finite and > 0, got nan"):
        gaussian_edge_affinity(g, g, tol=float("nan"))
    with pytest.raises(ValueError, match="`sigma2` must be finite and > 0, got 0.0"):
        match_graphs(g, g, sigma2=0.0)


@pytest.mark.parametrize("method", ["hungarian", "sinkhorn", "rrwm"])
def test_sigma2_checked_for_every_method(method, rng):
    g = Graph.from_points(rng.random((4, 2)), edges="full")
    with pytest.raises(TypeError, match="`sigma2` must be a real number, got str 'x'"):
        match_graphs(g, g, method=method, sigma2="x", node_affinity=np.eye(4))


# ---------------------------------------------------------------------------------------------
# found by a contract fuzz of the public entry points (2026-11-27)

def test_linear_solvers_refuse_scores_whose_objective_overflows():
    """Scores near float64's limit: refused by name, never an infinite objective."""
    for solver in (hungarian, sinkhorn):
        with pytest.raises(ValueError, match="`scores` is too large to match on"):
            solver(np.full((2, 2), 1e308))
    g = Graph.from_points(np.random.default_rng(0).random((2, 2)), edges="full")
    for method in ("hungarian", "rrwm"):
        with pytest.raises(ValueError, match="`node_affinity` is too large to match on"):
            match_graphs(g, g, method=method, node_affinity=np.full((2, 2), 1e308))
    with pytest.raises(TypeError, match="`n1` must be an int, got bool"):
        hungarian(np.ones((1, 1)), n1=True, n2=True)


def test_sinkhorn_tau_beyond_float64_is_refused_or_reported():
    """``scores / tau`` overflowing: a ValueError naming ``tau``; spanning beyond float64's
    precision (the potentials' own test cancels to 0): not converged, with the real error."""
    with pytest.raises(ValueError, match="`tau`=1e-308 makes scores / tau overflow"):
        sinkhorn(np.full((3, 3), 2.0), tau=1e-308)
    S = np.random.default_rng(0).random((4, 4))
    with pytest.warns(ConvergenceWarning, match="beyond float64's precision; pass a larger"):
        res = sinkhorn(S, tau=1e-20)
    real = float(np.max(np.abs(res.soft.sum(1) - 1.0)))
    assert not res.converged and res.info["marginal_error"] == real > 1e-6
    ok = sinkhorn(S, tau=0.05)                     # an ordinary tau: exact marginals, converged
    assert ok.converged and np.allclose(ok.soft.sum(1), 1.0, atol=1e-6)


def test_solver_messages_name_the_users_argument():
    K = np.random.default_rng(1).random((16, 16))
    K = K + K.T
    with pytest.raises(ValueError, match="`amplification` must be <= 500 with variant='orig"):
        rrwm(K, n1=4, n2=4, amplification=1000)
    assert rrwm(K, n1=4, n2=4, amplification=1000, variant="pygmtools").assignment.shape == (4,)
    from transync.matching import ipfp

    with pytest.raises(ValueError, match="`init` must have 2 dimensions"):
        ipfp(K, n1=4, n2=4, init=[0, 1, 2, 3])
    g = Graph.from_points(np.random.default_rng(0).random((2, 2)), edges="full")
    for method in ("rrwm", "sm", "ga", "ipfp", "pf"):      # given as `affinity`, not `K`
        with pytest.raises(ValueError, match="`affinity` is too small to match on"):
            match_graphs(g, g, method=method, affinity=np.full((4, 4), 1e-320))


def test_sixth_fuzz_matching_contract():
    """What a fuzz of transync.matching / transync.permutations found (each line failed before):
    unchecked flags and thresholds, unbounded iteration counts and sizes, overflow warnings."""
    from transync.matching import as_affinity, ipfp
    from transync.permutations import (
        check_assignment, cycle_inconsistency, is_partial_permutation_matrix, solve_lap)

    S = np.array([[0.1, 0.9], [0.8, 0.2]])
    with pytest.raises(ValueError, match="`min_score` must be a finite real number, got nan"):
        solve_lap(S, min_score=np.nan)                      # dropped every pair silently
    with pytest.raises(TypeError, match="`min_score` must be a finite real number, got str"):
        solve_lap(S, min_score="x")
    with pytest.raises(TypeError, match="`maximize` must be a bool, got str 'no'"):
        solve_lap(S, maximize="no")                         # maximized
    with pytest.raises(ValueError, match=r"`atol` must be < 0.5"):
        is_partial_permutation_matrix(np.full((2, 2), 0.5), atol=10)    # answered True
    with pytest.raises(ValueError, match="`atol` must be finite and >= 0"):
        is_partial_permutation_matrix(np.eye(2), atol=-1)
    with pytest.raises(TypeError, match="`n1` must be an int"):
        check_assignment([0, 1], n1=2.0)
    with pytest.raises(TypeError, match="`n2` must be an int"):
        check_assignment([0, 1], n2="3")
    with pytest.raises(TypeError, match="`rng`"):
        cycle_inconsistency({(0, 1): np.array([1, 0])}, rng="x")
    with pytest.raises(ValueError, match="`max_triangles` must be <= 100000000"):
        cycle_inconsistency({(0, 1): np.array([1, 0])}, max_triangles=10**9)
    K = np.ones((4, 4)) + 3 * np.eye(4)
    with pytest.raises(ValueError, match="`max_iter` must be <= 1000000"):
        sm(K, n1=2, n2=2, max_iter=10**12, tol=1e-300)      # looped for good
    with pytest.raises(ValueError, match=r"`init` must have entries in \[0, 1\]"):
        ipfp(K, n1=2, n2=2, init=np.eye(2) * 1e200)         # overflow warning
    aff = as_affinity(K, n1=2, n2=2)
    with pytest.raises(ValueError, match="`X` must be finite"):
        aff.score(np.full((2, 2), np.nan))                  # NaN returned silently
    with pytest.raises(TypeError, match="`X` must be real"):
        aff.score(np.eye(2) + 0j)
    with pytest.raises(ValueError, match=r"`X` must have shape \(n1, n2\) = \(2, 2\)"):
        aff.score(np.eye(3))
    with pytest.raises(ValueError, match="the objective of `X` overflows float64"):
        aff.score(np.eye(2) * 1e200)
    with pytest.raises(ValueError, match="`F, G` is too large to match on"):
        SeparableAffinity(None, np.full((1, 2, 2), 1e300), np.full((1, 3, 3), 1e300))
    with pytest.raises(ValueError, match="`n1` x `n2` must be at most"):
        FactorizedAffinity(None, None, [[0, 1]], [[0, 1]], 10**12, 10**12)
    with pytest.raises(ValueError, match=r"to_dense\(\) would build a 100000000 x"):
        FactorizedAffinity(None, None, [[0, 1]], [[0, 1]], 10**4, 10**4).to_dense()
    with pytest.raises(TypeError, match="must be a dense array, got the scipy.sparse"):
        solve_lap(sp.csr_matrix(np.eye(3)))
    rng = np.random.default_rng(0)
    g1, g2 = (Graph.from_points(rng.random((4, 2)) * 1e200) for _ in range(2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")                      # an overflow RuntimeWarning before
        with pytest.raises(DegenerateInputError, match="`sigma2`=1e\\+300 is too small"):
            gaussian_node_affinity(g1, g2, attribute="points", sigma2=1e300)
    with pytest.warns(ConvergenceWarning, match="tol=1e-300 is below what float64 row sums "
                                                "reach"):                   # blamed `tau`
        sinkhorn(rng.random((4, 5)), tol=1e-300)


def test_rrwm_warm_start_scale_does_not_drift():
    """3200 warm-started RRWM steps on a valid asymmetric K: the Sinkhorn column scalings
    handed from step to step drifted until `overflow encountered in dot`; they are now brought
    to [0.5, 1) by a power of two, which changes no iterate."""
    from transync.matching import RRWMStepper, gaussian_edge_affinity

    rng = np.random.default_rng(0)
    g1 = Graph.from_points(rng.random((6, 2)), edges="full")
    g2 = g1.permute(rng.permutation(6))
    K = gaussian_edge_affinity(g1, g2, backend="dense").to_dense()
    st = RRWMStepper(np.triu(K) * 3 + 0.01, n1=6, n2=6, max_iter=3200, variant="original")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        while not st.step():
            pass
    assert st.n_iter > 3085 and np.isfinite(st.iterate).all() and np.isfinite(st._scaling).all()


def test_subnormal_sigma2_refused_without_overflow_warnings():
    """sigma2=5e-324 (positive, finite) leaked four "overflow encountered in divide" warnings
    from the separable expansion; the underflow refusal names no library function or default
    (the CLI's commands have their own)."""
    rng = np.random.default_rng(0)
    g1, g2 = (Graph.from_points(rng.random((6, 2)), edges="full") for _ in range(2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(DegenerateInputError, match="`sigma2`=4.94066e-324 is too small") as e:
            gaussian_edge_affinity(g1, g2, sigma2=5e-324)
    assert "default" not in str(e.value) and "match_graphs" not in str(e.value)
    P = rng.random((6, 2))              # a shifted copy: equal lengths keep affinity 1
    h1, h2 = Graph.from_points(P, edges="full"), Graph.from_points(P[::-1] + 0.01, edges="full")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the factorized path's exp(-d2 / sigma2) overflowed
        for backend in ("factorized", "dense"):
            K = gaussian_edge_affinity(h1, h2, sigma2=5e-324, backend=backend).to_dense()
            assert np.isfinite(K).all() and K.max() == 1.0


def _user_affinity(kind):
    """A user's Affinity subclass whose matvec returns NaN, None or a wrong shape."""
    from transync.matching import Affinity

    class Faulty(Affinity):
        def __init__(self, n1, n2):
            self.n1, self.n2 = n1, n2

        def matvec(self, X):
            Y = np.ones((self.n1, self.n2))
            if kind == "nan":
                Y[0, 0] = np.nan
            return {"nan": Y, "none": None, "shape": Y[:1], "ok": Y}[kind]

        def diag(self):
            return np.ones((self.n1, self.n2))

        def to_dense(self):
            return np.ones((self.n1 * self.n2,) * 2)

    return Faulty


@pytest.mark.parametrize("method", ["rrwm", "ga", "pf", "sm", "ipfp"])
@pytest.mark.parametrize("kind, exc, match", [
    ("nan", ValueError, r"`affinity`\.matvec\(\) \(a Faulty\) returned 1 NaN or infinite"),
    ("none", TypeError, r"`affinity`\.matvec\(\) \(a Faulty\) must return a float array of "
                        r"shape \(4, 4\), got None"),
    ("shape", ValueError, r"`affinity`\.matvec\(\) \(a Faulty\) must return an array of shape "
                          r"\(4, 4\), got shape \(1, 4\)"),
])
def test_a_user_affinity_with_bad_output_is_named(method, kind, exc, match):
    """A user's Affinity subclass returning NaN, None or a wrong shape from matvec surfaced as
    "`score` must be finite", "float() argument must be ... NoneType" or a reshape error."""
    from transync.matching import as_affinity

    rng = np.random.default_rng(0)
    g1 = Graph.from_points(rng.random((4, 2)), edges="full")
    with pytest.raises(exc, match=match):
        match_graphs(g1, g1, method=method, affinity=_user_affinity(kind)(4, 4))
    ok = _user_affinity("ok")(4, 4)
    assert match_graphs(g1, g1, method=method, affinity=ok).assignment.shape == (4,)
    # the library's own affinities pass through as they are; a user's is wrapped, and keeps
    # its own attributes reachable
    own = as_affinity(np.eye(16), n1=4, n2=4)
    assert as_affinity(own) is own
    ok.tag = "mine"
    wrapped = as_affinity(ok)
    assert wrapped is not ok and wrapped.tag == "mine" and wrapped.score(np.eye(4)) == 4.0
