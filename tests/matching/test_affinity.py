"""Affinity backends: agreement with each other, separable error bound, validation."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from transync.graphs import Graph
from transync.matching import (
    DenseAffinity,
    FactorizedAffinity,
    SeparableAffinity,
    SparseAffinity,
    as_affinity,
    gaussian_edge_affinity,
)

BACKENDS = ("dense", "sparse", "factorized", "separable")


@pytest.fixture
def rng():
    return np.random.default_rng(7)


def _graphs(rng, n1=6, n2=8, edges="full"):
    return (Graph.from_points(rng.random((n1, 2)), edges=edges),
            Graph.from_points(rng.random((n2, 2)), edges=edges))


@pytest.mark.parametrize("edges", ["full", "delaunay"])
def test_backends_agree(edges, rng):
    g1, g2 = _graphs(rng, edges=edges)
    node = rng.random((6, 8))
    affs = {b: gaussian_edge_affinity(g1, g2, sigma2=0.1, node_affinity=node, backend=b)
            for b in BACKENDS}
    assert isinstance(affs["dense"], DenseAffinity)
    assert isinstance(affs["sparse"], SparseAffinity)
    assert isinstance(affs["factorized"], FactorizedAffinity)
    assert isinstance(affs["separable"], SeparableAffinity)
    K = affs["dense"].to_dense()
    X = rng.random((6, 8))
    x = X.ravel(order="F")
    ref = (K @ x).reshape((6, 8), order="F")
    tol = affs["separable"].max_error * K.shape[0] * np.abs(X).max() + 1e-12
    for b, aff in affs.items():
        atol = tol if b == "separable" else 1e-12
        np.testing.assert_allclose(aff.matvec(X), ref, atol=atol, err_msg=b)
        np.testing.assert_allclose(aff.rmatvec(X), (K.T @ x).reshape((6, 8), order="F"),
                                   atol=atol, err_msg=b)
        np.testing.assert_allclose(aff.diag(), node, atol=atol, err_msg=b)
        np.testing.assert_allclose(aff.to_dense(), K, atol=atol, err_msg=b)
        np.testing.assert_allclose(aff.score(X), x @ K @ x, rtol=1e-8, err_msg=b)


def test_dense_entries_are_cho_formula(rng):
    g1, g2 = _graphs(rng, 4, 5)
    K = gaussian_edge_affinity(g1, g2, sigma2=0.15, backend="dense").to_dense()
    D1, D2 = g1.distances(), g2.distances()
    for (i, a, j, b) in [(0, 1, 2, 3), (3, 4, 1, 0), (2, 2, 0, 1)]:
        expected = np.exp(-(D1[i, j] - D2[a, b]) ** 2 / 0.15)
        np.testing.assert_allclose(K[a * 4 + i, b * 4 + j], expected, rtol=1e-12)
    assert K[0 * 4 + 1, 2 * 4 + 1] == 0.0          # i == j: no edge (no self-loops)


@pytest.mark.parametrize("sigma2", [0.05, 0.15, 1.0])
@pytest.mark.parametrize("n", [5, 30])
def test_separable_max_error_bound_holds_on_entries(sigma2, n, rng):
    g1, g2 = _graphs(rng, n, n + 3)
    sep = gaussian_edge_affinity(g1, g2, sigma2=sigma2, backend="separable")
    exact = gaussian_edge_affinity(g1, g2, sigma2=sigma2, backend="factorized").to_dense()
    err = np.abs(sep.to_dense() - exact).max()
    assert err <= sep.max_error
    assert sep.max_error < 1e-8


def test_auto_never_materializes_and_picks_separable_for_full_graphs(rng):
    g1, g2 = _graphs(rng, 40, 40)
    assert isinstance(gaussian_edge_affinity(g1, g2), SeparableAffinity)
    d1, d2 = _graphs(rng, 40, 40, edges="delaunay")
    assert isinstance(gaussian_edge_affinity(d1, d2), (SeparableAffinity, FactorizedAffinity))


@pytest.mark.parametrize("n1, n2", [(5, 5), (2, 2), (3, 6)])
def test_separable_expansion_of_one_attribute_value_is_exact(n1, n2):
    # unweighted graphs with attribute="weight": every edge attribute is 1.0; the interpolation
    # interval was widened by 1e-21, which rounds away, all Chebyshev nodes coincided and every
    # edge-pair entry came out as p = 12 (144 for two such graphs) instead of exp(0) = 1
    from transync.matching import gaussian_edge_factors

    g1 = Graph(np.ones((n1, n1)) - np.eye(n1))
    g2 = Graph(np.ones((n2, n2)) - np.eye(n2))
    exact = gaussian_edge_affinity(g1, g2, attribute="weight", backend="dense").to_dense()
    for backend in ("auto", "separable"):
        aff = gaussian_edge_affinity(g1, g2, attribute="weight", backend=backend)
        err = np.abs(aff.to_dense() - exact).max()
        assert err <= max(aff.max_error, 1e-12) if backend == "separable" else err < 1e-8
        assert getattr(aff, "max_error", 0.0) < 1e-8
    fac = gaussian_edge_factors([g1, g1], attribute="weight")
    assert fac.max_error < 1e-8
    K = np.einsum("rij,rab->aibj", fac.F[0], fac.G[1]).reshape(n1 * n1, n1 * n1)
    np.testing.assert_allclose(K, gaussian_edge_affinity(g1, g1, attribute="weight",
                                                         backend="dense").to_dense(), atol=1e-8)


def test_auto_uses_no_coarse_expansion():
    # attributes over thousands of kernel widths: 200 interpolation points cannot follow the
    # Gaussian, so "auto" builds the exact factorized form; "separable" reports its error
    rng = np.random.default_rng(0)
    W = np.triu(rng.uniform(0, 1000, (12, 12)), 1)
    g = Graph(W + W.T)
    auto = gaussian_edge_affinity(g, g, attribute="weight", sigma2=0.01)
    sep = gaussian_edge_affinity(g, g, attribute="weight", sigma2=0.01, backend="separable")
    assert sep.max_error > 1e-6
    assert isinstance(auto, FactorizedAffinity)


def test_drop_conflicts_of_factorized_and_separable_with_self_loops(rng):
    # a self-loop paired with an edge links conflicting candidates; both backends returned self
    # and RRWM answered differently than on the same K given densely (74 / 200 problems)
    n1, n2 = 3, 4
    e1 = np.array([[0, 1], [1, 1], [2, 0], [2, 2]])
    e2 = np.array([[0, 0], [1, 2], [3, 1], [2, 2], [0, 3]])
    fac = FactorizedAffinity(rng.random((n1, n2)), rng.random((4, 5)), e1, e2, n1, n2)
    sep = SeparableAffinity(rng.random((n1, n2)), rng.random((2, n1, n1)), rng.random((2, n2, n2)))
    for aff in (fac, sep):
        want = as_affinity(aff.to_dense(), n1=n1, n2=n2).drop_conflicts().to_dense()
        np.testing.assert_allclose(aff.drop_conflicts().to_dense(), want, atol=1e-12)
        assert not np.allclose(want, aff.to_dense())
    g1, g2 = _graphs(rng)
    for backend in ("factorized", "separable"):                  # no self-loops: unchanged
        aff = gaussian_edge_affinity(g1, g2, backend=backend)
        assert aff.drop_conflicts() is aff


def test_drop_conflicts_dense_and_sparse(rng):
    n1, n2 = 3, 4
    K = rng.random((n1 * n2, n1 * n2))
    for aff in (as_affinity(K, n1=n1, n2=n2), as_affinity(sp.csr_matrix(K), n1=n1, n2=n2)):
        Kd = aff.drop_conflicts().to_dense()
        for p in range(n1 * n2):
            for q in range(n1 * n2):
                i, a, j, b = p % n1, p // n1, q % n1, q // n1
                conflict = (i == j) != (a == b)
                assert (Kd[p, q] == 0) if conflict else (Kd[p, q] == K[p, q])


def test_as_affinity_validation(rng):
    K = rng.random((6, 6))
    with pytest.raises(TypeError, match="`n1` and `n2` are required"):
        as_affinity(K)
    with pytest.raises(ValueError, match=r"`K` must have shape \(n1\*n2, n1\*n2\) = \(4, 4\), got \(6, 6\)"):
        as_affinity(K, n1=2, n2=2)
    with pytest.raises(ValueError, match="must have 2 dimensions"):
        as_affinity(np.ones(36), n1=2, n2=3)
    bad = K.copy()
    bad[1, 1] = np.inf
    with pytest.raises(ValueError, match="`K` must be finite"):
        as_affinity(bad, n1=2, n2=3)
    with pytest.raises(ValueError, match="`K` must be finite"):
        as_affinity(sp.csr_matrix(bad), n1=2, n2=3)
    bad[1, 1] = -0.5
    with pytest.raises(ValueError, match="`K` must be non-negative, got minimum -0.5"):
        as_affinity(bad, n1=2, n2=3)
    with pytest.raises(ValueError, match="`K` must be non-negative"):
        as_affinity(sp.csr_matrix(bad), n1=2, n2=3)
    with pytest.raises(ValueError, match=r"must have shape \(n1\*n2, n1\*n2\)"):
        as_affinity(sp.csr_matrix(K), n1=3, n2=3)
    with pytest.raises(ValueError, match="`n1` must be >= 1, got 0"):
        as_affinity(np.zeros((0, 0)), n1=0, n2=3)
    with pytest.raises(TypeError, match="`n2` must be an int"):
        as_affinity(K, n1=2, n2=3.0)
    aff = as_affinity(K, n1=2, n2=3)
    assert as_affinity(aff) is aff
    with pytest.raises(ValueError, match="n1=3"):
        as_affinity(aff, n1=3)


def test_gaussian_edge_affinity_validation(rng):
    g1, g2 = _graphs(rng, 3, 4)
    with pytest.raises(TypeError, match="`g1` and `g2` must be Graph"):
        gaussian_edge_affinity(np.eye(3), g2)
    with pytest.raises(ValueError, match="`sigma2` must be finite and > 0"):
        gaussian_edge_affinity(g1, g2, sigma2=0.0)
    with pytest.raises(ValueError, match="`backend` must be one of"):
        gaussian_edge_affinity(g1, g2, backend="gpu")
    with pytest.raises(ValueError, match=r"`node_affinity` must have shape \(3, 4\)"):
        gaussian_edge_affinity(g1, g2, node_affinity=np.ones((4, 3)))
    with pytest.raises(ValueError, match="`node_affinity` must be non-negative"):
        gaussian_edge_affinity(g1, g2, node_affinity=-np.ones((3, 4)))
    with pytest.raises(ValueError, match="`node_affinity` must be finite"):
        gaussian_edge_affinity(g1, g2, node_affinity=np.full((3, 4), np.nan))


def test_expanded_affinity_round_trips_through_as_affinity():
    """A separable expansion's round-off below zero (within its error bound) is not a negative
    affinity: the library takes back the matrix it hands out."""
    from transync.datasets import make_subgraph_collection
    from transync.matching import as_affinity, gaussian_edge_affinity

    found = False
    for seed in range(6):
        c = make_subgraph_collection(n_graphs=2, n_universe=20, rng=seed)
        a = gaussian_edge_affinity(c.graphs[0], c.graphs[1], sigma2=0.05)
        if a.max_error == 0:
            continue
        found = True
        K = a.to_dense()
        assert K.min() >= 0
        back = as_affinity(K, n1=a.n1, n2=a.n2)
        X = np.random.default_rng(seed).random(a.shape)
        np.testing.assert_allclose(back.matvec(X), a.matvec(X), atol=10 * a.max_error * K.size)
    assert found
