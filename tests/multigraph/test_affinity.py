"""Batched pair affinities: every backend against the per-pair objects, layouts, validation."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse as sp

from transync.datasets import make_graph_collection
from transync.exceptions import DegenerateInputError
from transync.graphs import Graph
from transync.matching import (
    Affinity,
    DenseAffinity,
    FactorizedAffinity,
    SeparableAffinity,
    SparseAffinity,
    gaussian_edge_affinity,
)
from transync.matching import gaussian_edge_factors
from transync.multigraph import PairAffinities
from transync.multigraph._affinity import all_pairs

AFF = functools.partial(gaussian_edge_affinity, sigma2=0.05)


@pytest.fixture(scope="module")
def coll():
    return make_graph_collection(n_graphs=5, n_inliers=7, n_outliers=1, deformation=0.05,
                                 rng=3)


def _points(N=4, n=7, seed=0, edges="delaunay"):
    rng = np.random.default_rng(seed)
    base = rng.random((n, 2))
    return [Graph.from_points(base + 0.02 * rng.normal(size=base.shape), edges=edges)
            for _ in range(N)]


def _reference(affs, X):
    return np.stack([a.matvec(x) for a, x in zip(affs, X)])


class _Custom(Affinity):
    """An exotic user affinity (not one of the library's backends): the loop fallback."""

    def __init__(self, K, n):
        self.K, self.n1, self.n2 = K, n, n

    def matvec(self, X):
        return (self.K @ X.ravel(order="F")).reshape(self.n1, self.n2, order="F")

    def diag(self):
        return np.diag(self.K).reshape(self.n1, self.n2, order="F")

    def to_dense(self):
        return self.K


def test_default_per_graph_factors_match_per_pair_affinity(coll):
    g = coll.graphs
    A = PairAffinities.from_graphs(g, affinity=AFF)
    assert A.backend == "separable" and len(A) == 10 and (A.n1, A.n2) == (8, 8)
    np.testing.assert_array_equal(A.pairs, all_pairs(5))
    for p, (i, j) in enumerate(A.pairs):
        exact = gaussian_edge_affinity(g[i], g[j], sigma2=0.05, backend="dense").to_dense()
        per_pair = AFF(g[i], g[j]).to_dense()
        np.testing.assert_allclose(A.pair(p).to_dense(), per_pair, atol=1e-8, rtol=0)
        np.testing.assert_allclose(A.pair(p).to_dense(), exact, atol=1e-8, rtol=0)
    assert 0 < A.max_error < 1e-8


def test_default_affinity_is_sigma2_015(coll):
    g = coll.graphs
    A = PairAffinities.from_graphs(g, pairs=[(1, 3)])
    ref = gaussian_edge_affinity(g[1], g[3], sigma2=0.15, backend="dense").to_dense()
    np.testing.assert_allclose(A.pair(0).to_dense(), ref, atol=1e-8, rtol=0)


def test_products_scores_against_per_pair(coll, rng):
    g = coll.graphs
    A = PairAffinities.from_graphs(g, affinity=AFF)
    affs = [AFF(g[i], g[j]) for i, j in A.pairs]
    X = rng.random((len(A), 8, 8))
    np.testing.assert_allclose(A.matvec(X), _reference(affs, X), atol=1e-7)
    np.testing.assert_allclose(A.rmatvec(X), A.matvec(X), atol=1e-12)   # undirected
    np.testing.assert_allclose(A.score(X), [a.score(x) for a, x in zip(affs, X)], rtol=1e-8)
    np.testing.assert_allclose(A.diag(), np.stack([a.diag() for a in affs]), atol=1e-8)
    assert not A.asymmetric().any()


def _check_score_assignments(A, rng, c=12):
    n = A.n1
    p_idx = rng.integers(0, len(A), c)
    assign = np.stack([rng.permutation(n) for _ in range(c)])
    assign[0, :2] = -1                                    # unmatched nodes count nothing
    got = A.score_assignments(p_idx, assign)
    ref = []
    for p, a in zip(p_idx, assign):
        Xm = np.zeros((n, n))
        Xm[np.flatnonzero(a >= 0), a[a >= 0]] = 1.0
        ref.append(A.pair(int(p)).score(Xm))
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("kind", ["separable", "separable-pairs", "dense", "sparse", "loop"])
def test_every_backend(kind, coll, rng):
    g = coll.graphs
    pairs = all_pairs(5)
    if kind == "separable":
        A = PairAffinities.from_graphs(g, affinity=AFF)
        affs = [A.pair(p) for p in range(len(A))]
    else:
        if kind == "separable-pairs":
            affs = [AFF(g[i], g[j]) for i, j in pairs]
        elif kind == "dense":
            affs = [AFF(g[i], g[j], backend="dense") for i, j in pairs]
        elif kind == "sparse":
            affs = [AFF(g[i], g[j], backend="factorized") for i, j in pairs]
        else:
            affs = [_Custom(AFF(g[i], g[j], backend="dense").K, 8) for i, j in pairs]
        A = PairAffinities.from_affinities(affs, pairs)
    assert A.backend == kind.split("-")[0]
    X = rng.random((len(A), 8, 8))
    np.testing.assert_allclose(A.matvec(X), _reference(affs, X), atol=1e-10)
    for p in (0, 7):
        np.testing.assert_allclose(A.pair(p).matvec(X[p]), affs[p].matvec(X[p]), atol=1e-10)
    sub = A.subset([7, 2])
    np.testing.assert_array_equal(sub.pairs, pairs[[7, 2]])
    np.testing.assert_allclose(sub.matvec(X[[7, 2]]), A.matvec(X)[[7, 2]], atol=1e-12)
    np.testing.assert_allclose(A._product(X[[3, 1]], np.array([3, 1])), A.matvec(X)[[3, 1]],
                               atol=1e-12)
    _check_score_assignments(A, rng)


def test_factorized_length_angle_on_delaunay_graphs(rng):
    g = _points()
    aff = functools.partial(gaussian_edge_affinity, sigma2=0.1, attribute="length+angle")
    A = PairAffinities.from_graphs(g, affinity=aff)
    assert A.backend == "sparse"
    affs = [aff(g[i], g[j]) for i, j in A.pairs]
    X = rng.random((len(A), 7, 7))
    np.testing.assert_allclose(A.matvec(X), _reference(affs, X), atol=1e-12)
    np.testing.assert_allclose(A.rmatvec(X), np.stack([a.rmatvec(x) for a, x in zip(affs, X)]),
                               atol=1e-12)
    _check_score_assignments(A, rng)


@pytest.mark.parametrize("kind", ["dense", "sparse"])
def test_drop_conflicts(kind, coll):
    g = coll.graphs
    pairs = all_pairs(5)[:3]
    K = [AFF(g[i], g[j], backend="dense").K + 0.1 for i, j in pairs]   # conflicts non-zero
    wrap = DenseAffinity if kind == "dense" else (lambda k, a, b: SparseAffinity(
        sp.csr_matrix(k), a, b))
    A = PairAffinities.from_affinities([wrap(k, 8, 8) for k in K], pairs)
    assert A.backend == kind
    D = A.drop_conflicts()
    for p in range(3):
        ref = DenseAffinity(K[p], 8, 8).drop_conflicts().to_dense()
        np.testing.assert_array_equal(D.pair(p).to_dense(), ref)


def test_from_blocks_layouts(coll, rng):
    g = coll.graphs
    N, n = 5, 8
    blocks = np.zeros((N, N, n * n, n * n))
    for i in range(N):
        for j in range(N):
            if i != j:
                blocks[i, j] = AFF(g[i], g[j], backend="dense").K
    pairs = all_pairs(N)
    ref = [DenseAffinity(blocks[i, j], n, n) for i, j in pairs]
    X = rng.random((len(pairs), n, n))
    A = PairAffinities.from_blocks(blocks, n=n)
    assert A.backend == "dense"
    np.testing.assert_allclose(A.matvec(X), _reference(ref, X), atol=1e-12)
    # dict with only the (j, i) blocks, sparse: re-indexed to the (i, j) layout
    lower = {(int(j), int(i)): sp.csr_matrix(blocks[j, i]) for i, j in pairs}
    B = PairAffinities.from_blocks(lower, pairs, n=n)
    assert B.backend == "sparse"
    np.testing.assert_allclose(B.matvec(X), A.matvec(X), atol=1e-12)
    # nested list
    nested = [[blocks[i, j] for j in range(N)] for i in range(N)]
    C = PairAffinities.from_blocks(nested, pairs[:4], n=n)
    np.testing.assert_allclose(C.matvec(X[:4]), A.matvec(X)[:4], atol=1e-12)


def test_from_blocks_matches_pygmtools_layout(coll):
    pygm = pytest.importorskip("pygmtools")
    pygm.set_backend("numpy")
    g0, g1 = coll.graphs[0], coll.graphs[2]
    n = 8

    c0, e0 = pygm.utils.dense_to_sparse(g0.edge_features * g0.mask)
    c1, e1 = pygm.utils.dense_to_sparse(g1.edge_features * g1.mask)
    K = pygm.utils.build_aff_mat(None, e0, c0, None, e1, c1, np.array([n]), None, np.array([n]),
                                 None, edge_aff_fn=functools.partial(pygm.utils.gaussian_aff_fn,
                                                                     sigma=0.05))
    K = np.asarray(K).reshape(n * n, n * n)
    A = PairAffinities.from_blocks({(0, 1): K}, [(0, 1)], n=n)
    X = np.random.default_rng(0).random((1, n, n))
    np.testing.assert_allclose(A.matvec(X)[0], AFF(g0, g1).matvec(X[0]), atol=1e-8)


def test_gaussian_edge_factors_refuses_underflow():
    g = [Graph(np.ones((3, 3)) - np.eye(3), edge_features=(np.ones((3, 3)) - np.eye(3)) * s)
         for s in (1.0, 100.0)]
    with pytest.raises(DegenerateInputError, match="sigma2"):
        gaussian_edge_factors(g, sigma2=0.01)
    with pytest.raises(DegenerateInputError):
        PairAffinities.from_graphs(g, affinity=functools.partial(gaussian_edge_affinity,
                                                                 sigma2=0.01))


def test_validation(coll):
    g = coll.graphs
    A = PairAffinities.from_graphs(g, affinity=AFF)
    with pytest.raises(ValueError, match=r"`X` must have shape \(P, n1, n2\) = \(10, 8, 8\)"):
        A.matvec(np.ones((3, 8, 8)))
    with pytest.raises(ValueError, match="at least 2 graphs"):
        PairAffinities.from_graphs(g[:1])
    with pytest.raises(ValueError, match="same number of nodes"):
        PairAffinities.from_graphs([g[0], _points(1, 5)[0]])
    with pytest.raises(TypeError, match=r"`graphs\[1\]` must be a transync.graphs.Graph"):
        PairAffinities.from_graphs([g[0], "x"])
    with pytest.raises(ValueError, match="i < j"):
        PairAffinities.from_graphs(g, pairs=[(2, 1)])
    with pytest.raises(ValueError, match=r"\[0, 5\)"):
        PairAffinities.from_graphs(g, pairs=[(0, 5)])
    with pytest.raises(ValueError, match="repeat"):
        PairAffinities.from_graphs(g, pairs=[(0, 1), (0, 1)])
    with pytest.raises(TypeError, match="must return a transync.matching.Affinity"):
        PairAffinities.from_graphs(g, affinity=lambda a, b: np.eye(64))
    with pytest.raises(TypeError, match="callable"):
        PairAffinities.from_graphs(g, affinity=3)
    with pytest.raises(ValueError, match=r"\(N, N, n\*n, n\*n\)"):
        PairAffinities.from_blocks(np.ones((3, 3, 4, 4)), n=3)
    with pytest.raises(ValueError, match="non-negative"):
        PairAffinities.from_blocks(-np.ones((2, 2, 4, 4)), n=2)
    with pytest.raises(ValueError, match=r"no block for pair \(0, 2\)"):
        PairAffinities.from_blocks({(0, 1): np.ones((4, 4))}, [(0, 2)], n=2)
    with pytest.raises(TypeError, match="`n`"):
        PairAffinities.from_blocks(np.ones((2, 2, 4, 4)))
    with pytest.raises(TypeError, match="`pairs` must be an array of integer graph indices"):
        PairAffinities.from_blocks({(0, 1): np.eye(4)}, "ab", n=2)     # was a raw ufunc error
    for one in (np.zeros((1, 1, 4, 4)), [[np.eye(4)]]):                 # named `n_graphs` before
        with pytest.raises(ValueError, match="`K` must hold blocks for at least 2 graphs, got 1"):
            PairAffinities.from_blocks(one, n=2)
    with pytest.raises(ValueError, match=r"\[-1, 8\)"):
        A.score_assignments([0], [[9] + [0] * 7])
    with pytest.raises(ValueError, match=r"`assignments` must have shape \(c, n1\)"):
        A.score_assignments([0, 1], np.zeros((3, 8), int))


def test_directed_graphs_separable(rng):
    """Asymmetric edge attributes: K is not symmetric; products, transposes and scores hold."""
    graphs = []
    for _ in range(3):
        Adj = (rng.random((6, 6)) < 0.8).astype(float)
        np.fill_diagonal(Adj, 0.0)
        graphs.append(Graph(Adj, edge_features=rng.random((6, 6)) * Adj, directed=True))
    aff = functools.partial(gaussian_edge_affinity, sigma2=0.1, backend="separable")
    A = PairAffinities.from_graphs(graphs, affinity=aff)
    assert A.backend == "separable" and A.asymmetric().all()
    with pytest.raises(ValueError, match="`rtol` must be finite"):
        A.asymmetric(rtol=np.nan)               # NaN made every pair look symmetric
    affs = [aff(graphs[i], graphs[j]) for i, j in A.pairs]
    X = rng.random((3, 6, 6))
    np.testing.assert_allclose(A.matvec(X), _reference(affs, X), atol=1e-8)
    np.testing.assert_allclose(A.rmatvec(X), np.stack([a.rmatvec(x) for a, x in zip(affs, X)]),
                               atol=1e-8)
    _check_score_assignments(A, rng)


def test_from_factors_against_dense_pairs(rng):
    """Per-graph factors indexed by pairs: products, diag, scores against ``pair(p).to_dense()``
    and the explicit Kronecker sum (issue #12: the kernel's padded-adjacency affinity)."""
    Ng, R, n1, n2 = 4, 2, 5, 5
    F = rng.random((Ng, R, n1, n1))
    G = rng.random((Ng + 1, R, n2, n2))
    pairs = np.array([[0, 1], [3, 3], [0, 4], [2, 0], [0, 1]] * 15)   # > 64 pairs: grouped
    node = rng.random((len(pairs), n1, n2))
    A = PairAffinities.from_factors(F, G, pairs, node=node)
    assert A.backend == "separable" and len(A) == len(pairs) and (A.n1, A.n2) == (n1, n2)
    np.testing.assert_array_equal(A.pairs, pairs)
    X = rng.random((len(pairs), n1, n2))
    Y, D = A.matvec(X), A.diag()
    for p in (0, 1, 3, 72):
        i, j = pairs[p]
        K = sum(np.kron(G[j, r], F[i, r]) for r in range(R)) + np.diag(node[p].ravel("F"))
        np.testing.assert_allclose(A.pair(p).to_dense(), K, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(Y[p].ravel("F"), K @ X[p].ravel("F"), rtol=1e-12)
        np.testing.assert_allclose(D[p].ravel("F"), np.diag(K), rtol=1e-12)
    _check_score_assignments(A, rng)
    sub = A.subset([3, 0])
    np.testing.assert_allclose(sub.matvec(X[[3, 0]]), Y[[3, 0]], rtol=1e-12)
    no_node = PairAffinities.from_factors(F, G, pairs[:2])
    np.testing.assert_allclose(no_node.matvec(X[:2]) + node[:2] * X[:2], Y[:2], rtol=1e-12)
    rect = PairAffinities.from_factors(F, G[:, :, :3, :3], [[1, 2]])     # n1 = 5, n2 = 3
    Xr = rng.random((1, 5, 3))
    K = sum(np.kron(G[2, r, :3, :3], F[1, r]) for r in range(R))
    np.testing.assert_allclose(rect.matvec(Xr)[0].ravel("F"), K @ Xr[0].ravel("F"), rtol=1e-12)


@pytest.mark.parametrize("symmetric", [True, False])
@pytest.mark.parametrize("sizes", [(12, 12), (14, 9)])
def test_sparse_one_factor_products_run_on_csr_rows(symmetric, sizes, rng, monkeypatch):
    """One sparse factor per graph (the kernels' padded 0/1 adjacencies, here weighted and
    also asymmetric) takes the block-diagonal CSR product: the same products as the
    Kronecker matrices and as the dense GEMM path, transposed ones included, on the whole
    stack, on subsets and on the few-pair products that stay dense."""
    import transync.multigraph._affinity as backend

    def factors(Ng, n):
        M = (rng.random((Ng, 1, n, n)) < 0.08) * rng.uniform(0.5, 2.0, (Ng, 1, n, n))
        return M + np.swapaxes(M, 2, 3) if symmetric else M

    n1, n2 = sizes
    F, G = factors(5, n1), factors(6, n2)
    pairs = np.stack([rng.integers(0, 5, 90), rng.integers(0, 6, 90)], axis=1)
    node = rng.random((90, n1, n2))
    A = PairAffinities.from_factors(F, G, pairs, node=node)
    X = rng.random((90, n1, n2))
    Y, Yt = A.matvec(X), A.rmatvec(X)
    assert A._impl._csr not in (None, False)            # the CSR path was taken
    for p in (0, 7, 89):
        i, j = pairs[p]
        K = np.kron(G[j, 0], F[i, 0]) + np.diag(node[p].ravel("F"))
        np.testing.assert_allclose(Y[p].ravel("F"), K @ X[p].ravel("F"), rtol=1e-12)
        np.testing.assert_allclose(Yt[p].ravel("F"), K.T @ X[p].ravel("F"), rtol=1e-12)
    for idx in ([5, 1, 88, 5, 40], [3, 2]):             # a subset, then a few-pair product
        sub = A.subset(idx)
        np.testing.assert_allclose(sub.matvec(X[idx]), Y[idx], rtol=1e-12)
        np.testing.assert_allclose(sub.rmatvec(X[idx]), Yt[idx], rtol=1e-12)
    monkeypatch.setattr(backend, "_CSR_DENSITY", -1.0)  # the dense GEMM path, same products
    dense = PairAffinities.from_factors(F, G, pairs, node=node)
    np.testing.assert_allclose(dense.matvec(X), Y, rtol=1e-12)
    np.testing.assert_allclose(dense.rmatvec(X), Yt, rtol=1e-12)
    assert dense._impl._csr is False


def test_from_factors_validation(rng):
    F = rng.random((2, 1, 3, 3))
    with pytest.raises(ValueError, match="`F` must have shape"):
        PairAffinities.from_factors(F[:, :, :2], F, [[0, 1]])
    with pytest.raises(ValueError, match="`G` must have shape"):
        PairAffinities.from_factors(F, rng.random((2, 2, 3, 3)), [[0, 1]])
    with pytest.raises(ValueError, match=r"`pairs\[:, 1\]` must index `G` in \[0, 2\)"):
        PairAffinities.from_factors(F, F, [[0, 2]])
    with pytest.raises(ValueError, match=r"`pairs` must have shape \(P, 2\)"):
        PairAffinities.from_factors(F, F, [0, 1])
    with pytest.raises(ValueError, match=r"`node` must have shape \(P, n1, n2\)"):
        PairAffinities.from_factors(F, F, [[0, 1]], node=np.ones((1, 3, 2)))
    with pytest.raises(ValueError, match="must have 4 dimensions"):
        PairAffinities.from_factors(F[0], F, [[0, 1]])
    # factors whose products overflow (1e154^2 * 16 > 1e300): scores were NaN, products inf
    big = np.ones((3, 1, 4, 4)) * 1e154
    with pytest.raises(ValueError, match="`F, G` is too large to match on"):
        PairAffinities.from_factors(big, big, [[0, 1], [0, 2], [1, 2]])
    with pytest.raises(ValueError, match="`F, G, node` is too large to match on"):
        PairAffinities.from_factors(F, F, [[0, 1]], node=np.full((1, 3, 3), 1e300))
    ok = PairAffinities.from_factors(big * 1e-14, big * 1e-14, [[0, 1]])
    assert np.isfinite(ok.score(np.eye(4)[None])).all()


@pytest.mark.parametrize("with_node", [False, True])
def test_loop_backend_scores_factorized_and_separable_pairs_without_products(with_node, rng):
    """Mixed per-pair types (sparse graphs next to dense ones) take the per-pair backend; its
    candidate scores (each pair through a one-pair separable or sparse backend) must equal
    ``x^T K x``, with unmatched nodes (-1) and unary terms, and an edge list that repeats an
    edge (its entries summed)."""
    n = 6
    affs = []
    for k in range(6):
        node = rng.random((n, n)) if with_node else None
        if k % 3 == 0:
            affs.append(SeparableAffinity(node, rng.random((2, n, n)), rng.random((2, n, n))))
            continue
        e1 = np.array([(u, v) for u in range(n) for v in range(n) if u != v and rng.random() < .5])
        e2 = np.array([(u, v) for u in range(n) for v in range(n) if u != v and rng.random() < .5])
        if k == 5:
            e2 = np.vstack([e2, e2[:1]])                 # a repeated edge
        affs.append(FactorizedAffinity(node, rng.random((len(e1), len(e2))), e1, e2, n, n))
    A = PairAffinities.from_affinities(affs, all_pairs(4))
    assert A.backend == "loop"
    for _ in range(3):
        _check_score_assignments(A, rng, c=40)
