"""Tests of the baseline graph kernels (issue #12, item 5)."""

import itertools
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from transync.graphs import Graph
from transync.kernels._baselines import (
    grakel_kernel,
    graphlet3_counts,
    graphlet3_kernel,
    hks_mean_kernel,
    hks_oa_kernel,
    random_walk_kernel,
)
from transync.exceptions import ConvergenceWarning
from transync.kernels._evaluate import min_eigenvalue_ratio, spectrum


def _random_graph(rng, n, p):
    A = np.triu(rng.random((n, n)) < p, 1).astype(float)
    return A + A.T


def _relabel(A, perm):
    return A[np.ix_(perm, perm)]


# --------------------------------------------------------------------------- 3-graphlets

def test_graphlet3_counts_match_brute_force_over_triples():
    rng = np.random.default_rng(0)
    graphs = [_random_graph(rng, n, p) for n in (3, 4, 6, 8) for p in (0.0, 0.3, 0.7, 1.0)]
    got = graphlet3_counts(graphs)
    for A, row in zip(graphs, got):
        ref = np.zeros(4)
        for u, v, w in itertools.combinations(range(A.shape[0]), 3):
            ref[int(A[u, v] + A[u, w] + A[v, w])] += 1
        np.testing.assert_array_equal(row, ref)


def test_graphlet3_kernel_invariant_psd_and_small_graphs():
    rng = np.random.default_rng(1)
    graphs = [_random_graph(rng, n, 0.4) for n in (5, 7, 9, 7)]
    graphs.append(np.zeros((2, 2)))                               # no triple: zero row
    K = graphlet3_kernel(graphs)
    np.testing.assert_allclose(K, K.T, rtol=0, atol=0)
    np.testing.assert_allclose(np.diag(K)[:4], 1.0, rtol=1e-12)
    np.testing.assert_array_equal(K[4], 0.0)
    assert spectrum(K)[0] >= -1e-12
    perm = rng.permutation(9)
    K2 = graphlet3_kernel([graphs[0], graphs[1], _relabel(graphs[2], perm), graphs[3],
                           Graph(adjacency=np.zeros((2, 2)))])
    np.testing.assert_allclose(K2, K, rtol=1e-12, atol=1e-15)
    raw = graphlet3_kernel(graphs[:1], normalize=False)        # squared frequency norm
    f = graphlet3_counts(graphs[:1])[0] / 10.0                  # C(5, 3) triples
    np.testing.assert_allclose(raw, [[f @ f]], rtol=1e-12)


def test_graphlet3_validation():
    with pytest.raises(TypeError, match="graphs"):
        graphlet3_kernel(np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"graphs\[1\].*square"):
        graphlet3_kernel([np.zeros((3, 3)), np.zeros((3, 2))])
    with pytest.raises(ValueError, match=r"graphs\[0\].*symmetric"):
        graphlet3_kernel([np.triu(np.ones((3, 3)), 1)])
    with pytest.raises(ValueError, match="empty"):
        graphlet3_kernel([])


@pytest.mark.dataset("tu")
def test_graphlet3_on_mutag_vs_grakel_rank_one():
    """GraKeL 0.1.11's unsampled graphlet kernel is rank 1 on MUTAG; the exact counts are not."""
    from grakel.kernels import GraphletSampling

    from transync.datasets import load_tu

    graphs = load_tu("MUTAG").graphs[:15]
    K = graphlet3_kernel(graphs)
    w = spectrum(K)
    assert np.sum(w > 1e-9 * w[-1]) >= 2
    X = [[g.adjacency.astype(int), {i: 0 for i in range(g.n_nodes)}] for g in graphs]
    Kg = GraphletSampling(k=3, sampling=None, normalize=True).fit_transform(X)
    wg = np.linalg.eigvalsh(Kg)
    assert np.sum(wg > 1e-9 * wg[-1]) == 1


# --------------------------------------------------------------------------- HKS kernels

def _brute_oa(F, G, sigma2, la=None, lb=None):
    n = max(len(F), len(G))
    S = np.zeros((n, n))
    S[:len(F), :len(G)] = np.exp(-((F[:, None] - G[None]) ** 2).sum(-1) / sigma2)
    if la is not None:
        S[:len(F), :len(G)] *= la[:, None] == lb[None, :]
    return max(S[np.arange(n), list(p)].sum() for p in itertools.permutations(range(n)))


def test_hks_oa_matches_brute_force_with_and_without_labels():
    rng = np.random.default_rng(2)
    F = [rng.random((n, 2)) for n in (3, 5, 4, 1, 5)]
    labels = [rng.integers(0, 2, len(f)) for f in F]
    K = hks_oa_kernel(F, sigma2=0.3, normalize=False)
    KL = hks_oa_kernel(F, sigma2=0.3, node_labels=labels, normalize=False)
    for i, j in itertools.product(range(5), repeat=2):
        assert K[i, j] == pytest.approx(_brute_oa(F[i], F[j], 0.3), rel=1e-12)
        assert KL[i, j] == pytest.approx(_brute_oa(F[i], F[j], 0.3, labels[i], labels[j]),
                                         rel=1e-12)
    Kn = hks_oa_kernel(F, sigma2=0.3)
    np.testing.assert_allclose(Kn, K / np.sqrt(np.outer(np.diag(K), np.diag(K))), rtol=1e-12)
    with ThreadPoolExecutor(2) as pool:             # chunked through an executor: same values
        np.testing.assert_allclose(hks_oa_kernel(F, sigma2=0.3, executor=pool), Kn, rtol=0,
                                   atol=0)


def test_hks_oa_is_indefinite_on_a_synthetic_set_and_mean_kernel_is_psd():
    """Four one-node/two-node graphs whose optimal bijections disagree (Vert 2008)."""
    F = [np.array([[2.0], [0.0]]), np.array([[0.0]]), np.array([[2.0]]), np.array([[1.0]])]
    assert min_eigenvalue_ratio(hks_oa_kernel(F, sigma2=2.0)) < -1e-2
    for kw in ({"kernel": "linear"}, {"kernel": "rbf", "gamma": 0.5}):
        assert min_eigenvalue_ratio(hks_mean_kernel(F, **kw)) >= -1e-12


def test_hks_mean_kernel_matches_definition_and_is_invariant():
    rng = np.random.default_rng(3)
    F = [rng.random((n, 3)) for n in (2, 4, 3, 6)]
    lab = [rng.integers(0, 3, len(f)) for f in F]
    lin = hks_mean_kernel(F, normalize=False)
    rbf = hks_mean_kernel(F, kernel="rbf", gamma=2.0, normalize=False, block_nodes=5)
    rbfl = hks_mean_kernel(F, kernel="rbf", gamma=2.0, node_labels=lab, normalize=False)
    linl = hks_mean_kernel(F, node_labels=lab, normalize=False)
    for i, j in itertools.product(range(4), repeat=2):
        D = ((F[i][:, None] - F[j][None]) ** 2).sum(-1)
        same = lab[i][:, None] == lab[j][None, :]
        n2 = len(F[i]) * len(F[j])
        assert lin[i, j] == pytest.approx(F[i].mean(0) @ F[j].mean(0), rel=1e-12)
        assert rbf[i, j] == pytest.approx(np.exp(-2.0 * D).sum() / n2, rel=1e-12)
        assert rbfl[i, j] == pytest.approx((np.exp(-2.0 * D) * same).sum() / n2, rel=1e-12)
        assert linl[i, j] == pytest.approx(((F[i] @ F[j].T) * same).sum() / n2, rel=1e-12)
    perm = rng.permutation(6)
    F2 = F[:3] + [F[3][perm]]
    np.testing.assert_allclose(hks_mean_kernel(F2, kernel="rbf"), hks_mean_kernel(F, kernel="rbf"),
                               rtol=1e-12)
    assert spectrum(hks_mean_kernel(F, kernel="rbf"))[0] >= -1e-12


def test_hks_kernel_validation():
    F = [np.ones((2, 3)), np.ones((3, 3))]
    with pytest.raises(ValueError, match=r"features\[1\].*3 columns"):
        hks_oa_kernel([np.ones((2, 3)), np.ones((3, 2))])
    with pytest.raises(ValueError, match="sigma2"):
        hks_oa_kernel(F, sigma2=-1.0)
    with pytest.raises(ValueError, match=r"node_labels\[1\]"):
        hks_oa_kernel(F, node_labels=[np.zeros(2, int), np.zeros(2, int)])
    with pytest.raises(ValueError, match="kernel"):
        hks_mean_kernel(F, kernel="poly")
    with pytest.raises(TypeError, match="features"):
        hks_mean_kernel(np.ones((2, 3)))
    with pytest.raises(ValueError, match=r"features\[0\].*finite"):
        hks_mean_kernel([np.full((2, 3), np.nan)])
    # gamma was ignored silently by the linear kernel
    with pytest.raises(ValueError, match=r"`gamma` applies to kernel='rbf' only, got gamma=1.0"):
        hks_mean_kernel(F, kernel="linear", gamma=1.0)
    assert hks_mean_kernel(F, kernel="rbf", gamma=1.0).shape == (2, 2)


@pytest.mark.dataset("tu")
def test_hks_oa_indefinite_on_mutag():
    """The non-transitive kernel the transitive kernel replaces is indefinite on real data."""
    from transync.datasets import load_tu
    from transync.kernels._hks import hks_features

    graphs = load_tu("MUTAG").graphs[:80]          # (the first 60 alone give a PSD matrix)
    F = hks_features(graphs)
    assert min_eigenvalue_ratio(hks_oa_kernel(F)) < -1e-6
    assert min_eigenvalue_ratio(hks_mean_kernel(F, kernel="rbf")) >= -1e-9


# --------------------------------------------------------------------------- GraKeL

def _labelled_graphs():
    tri = Graph(adjacency=np.ones((3, 3)) - np.eye(3), node_labels=np.array([0, 0, 1]))
    path = Graph(adjacency=np.array([[0, 1, 0, 0], [1, 0, 1, 0], [0, 1, 0, 0], [0, 0, 0, 0.0]]),
                 node_labels=np.array([1, 0, 1, 2]))             # node 3 isolated
    star = Graph(adjacency=np.array([[0, 1, 1, 1], [1, 0, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0.0]]),
                 node_labels=np.array([0, 1, 1, 0]))
    return [tri, path, star]


def _wl_features(graphs, h):
    """Hand-made WL subtree features: label histograms of iterations 0..h (shared dictionary)."""
    labels = [tuple(int(v) for v in g.node_labels) for g in graphs]
    feats = [[] for _ in graphs]
    for it in range(h + 1):
        for k, lab in enumerate(labels):
            feats[k].extend((it, x) for x in lab)
        new = []
        for g, lab in zip(graphs, labels):
            nb = [tuple(sorted(lab[v] for v in np.flatnonzero(g.adjacency[u])))
                  for u in range(g.n_nodes)]
            new.append(tuple(hash((lab[u], nb[u])) for u in range(g.n_nodes)))
        labels = new
    keys = sorted({f for fs in feats for f in fs}, key=repr)
    return np.array([[fs.count(key) for key in keys] for fs in feats], dtype=float)


@pytest.mark.parametrize("h", [0, 1, 2])
def test_grakel_wl_equals_hand_computed_histograms(h):
    graphs = _labelled_graphs()
    Phi = _wl_features(graphs, h)
    np.testing.assert_allclose(grakel_kernel(graphs, "wl", n_iter=h, normalize=False),
                               Phi @ Phi.T, rtol=1e-12)


def test_grakel_kernels_symmetric_psd_and_relabelling_invariant():
    rng = np.random.default_rng(4)
    graphs = _labelled_graphs()
    for k in range(4):
        A = _random_graph(rng, 5 + k, 0.4)
        A[-1] = A[:, -1] = 0                                          # an isolated node
        graphs.append(Graph(adjacency=A, node_labels=rng.integers(0, 2, 5 + k)))
    perm = rng.permutation(graphs[5].n_nodes)
    moved = Graph(adjacency=_relabel(graphs[5].adjacency, perm),
                  node_labels=graphs[5].node_labels[perm])
    for name in ("wl", "wl-oa", "sp", "rw"):
        K = grakel_kernel(graphs, name, n_iter=2, lamda=1e-2)
        assert K.shape == (7, 7)
        np.testing.assert_allclose(K, K.T, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.diag(K), 1.0, rtol=1e-9)
        # GraKeL's random walk solves each pair by conjugate gradients to a loose tolerance
        assert min_eigenvalue_ratio(K) >= (-1e-5 if name == "rw" else -1e-12), name
        K2 = grakel_kernel(graphs[:5] + [moved] + graphs[6:], name, n_iter=2, lamda=1e-2)
        np.testing.assert_allclose(K2, K, rtol=1e-7, atol=1e-9, err_msg=name)


def test_grakel_degree_labels_when_graphs_have_none():
    tri = np.ones((3, 3)) - np.eye(3)
    path = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0.0]])
    K = grakel_kernel([tri, path, Graph(adjacency=tri)], "wl", n_iter=0, normalize=False)
    # degrees: triangle (2, 2, 2), path (1, 2, 1)
    np.testing.assert_allclose(K, [[9, 3, 9], [3, 5, 3], [9, 3, 9]])
    Kl = grakel_kernel([tri, path], "wl", n_iter=0, normalize=False,
                       node_labels=[np.zeros(3, int), np.zeros(3, int)])
    np.testing.assert_allclose(Kl, 9.0)


def test_grakel_validation_and_missing_dependency(monkeypatch):
    graphs = _labelled_graphs()
    with pytest.raises(ValueError, match="name"):
        grakel_kernel(graphs, "graphlet")
    with pytest.raises(ValueError, match="n_iter"):
        grakel_kernel(graphs, "wl-oa", n_iter=0)
    with pytest.raises(ValueError, match="lamda"):
        grakel_kernel(graphs, "rw", lamda=1.5)
    with pytest.raises(ValueError, match=r"node_labels\[0\]"):
        grakel_kernel(graphs, "wl", node_labels=[np.zeros(2, int)] * 3)
    # n_jobs=0 reached joblib ("n_jobs == 0 in Parallel has no meaning"), -5 passed silently
    with pytest.raises(ValueError, match=r"`n_jobs` must be a positive number of jobs or -1"):
        grakel_kernel(graphs, "rw", n_jobs=0)
    with pytest.raises(ValueError, match=r"`n_jobs` must be >= -1, got -5"):
        grakel_kernel(graphs, "wl", n_jobs=-5)
    # GraKeL's shortest path has no parallel code and warned (an error under this suite)
    assert grakel_kernel(graphs, "sp", n_jobs=2).shape == (len(graphs), len(graphs))
    monkeypatch.setitem(sys.modules, "grakel", None)
    with pytest.raises(ImportError, match=r"transync\[bench\]"):
        grakel_kernel(graphs, "wl")


# --------------------------------------------------------------------------- random walk

def test_random_walk_kernel_equals_grakel_exact_inverse():
    """Reference: GraKeL's labelled geometric walk by explicit inverse of I - lamda W_x."""
    from grakel.kernels import RandomWalkLabeled

    rng = np.random.default_rng(5)
    graphs = [_random_graph(rng, n, 0.5) for n in (3, 5, 6, 4, 7, 1)]
    labels = [rng.integers(0, 2, len(a)) for a in graphs]
    X = [[A.astype(int), {i: int(v) for i, v in enumerate(lab)}]
         for A, lab in zip(graphs, labels)]
    ref = RandomWalkLabeled(lamda=0.05, method_type="baseline").fit_transform(X)
    K = random_walk_kernel(graphs, lamda=0.05, node_labels=labels, normalize=False)
    np.testing.assert_allclose(K, ref, rtol=1e-10)
    with ThreadPoolExecutor(2) as pool:
        np.testing.assert_allclose(
            random_walk_kernel(graphs, lamda=0.05, node_labels=labels, normalize=False,
                               executor=pool), K, rtol=0, atol=0)


def test_random_walk_kernel_psd_invariant_and_validation():
    rng = np.random.default_rng(6)
    graphs = [Graph(adjacency=_random_graph(rng, n, 0.4), node_labels=rng.integers(0, 3, n))
              for n in (4, 6, 8, 5, 9)]
    K = random_walk_kernel(graphs)
    np.testing.assert_allclose(np.diag(K), 1.0, rtol=1e-12)
    assert min_eigenvalue_ratio(K) >= -1e-12
    perm = rng.permutation(6)
    moved = Graph(adjacency=_relabel(graphs[1].adjacency, perm),
                  node_labels=graphs[1].node_labels[perm])
    np.testing.assert_allclose(random_walk_kernel([graphs[0], moved] + graphs[2:]), K,
                               rtol=1e-12)
    with pytest.raises(ValueError, match="1 / rho_max"):
        random_walk_kernel([np.ones((4, 4)) - np.eye(4)], lamda=0.2)     # rho = 3
    with pytest.warns(ConvergenceWarning, match="max_iter=1"):
        random_walk_kernel(graphs[:2], max_iter=1)


def test_hks_mean_kernel_of_tiny_embeddings_is_the_cosine():
    """Mean embeddings near the smallest float64 (self-similarities subnormal): the normalized
    kernel is still the cosine, PSD (found by the property-based contract test)."""
    from transync.kernels import hks_mean_kernel

    F = [np.array([[0.0]]), np.array([[1.0]]), np.array([[5.2914389e-160]])]
    K = hks_mean_kernel(F)
    np.testing.assert_array_equal(K, [[0.0, 0.0, 0.0], [0.0, 1.0, 1.0], [0.0, 1.0, 1.0]])
    assert min_eigenvalue_ratio(K) >= -1e-9


@pytest.mark.parametrize("kernel", ["graphlet3", "hks_oa", "hks_mean", "random_walk", "grakel"])
def test_normalize_must_be_a_bool(kernel):
    """`normalize="no"` was accepted (and normalized), `normalize=None` too (and did not)."""
    tri = np.ones((3, 3)) - np.eye(3)
    g = Graph(adjacency=tri)
    F = [np.zeros((3, 2)), np.ones((3, 2))]
    call = {"graphlet3": lambda **kw: graphlet3_kernel([tri, tri], **kw),
            "hks_oa": lambda **kw: hks_oa_kernel(F, **kw),
            "hks_mean": lambda **kw: hks_mean_kernel(F, **kw),
            "random_walk": lambda **kw: random_walk_kernel([g, g], **kw),
            "grakel": lambda **kw: grakel_kernel([g, g], "wl", **kw)}[kernel]
    for bad in ("no", None, 1):
        with pytest.raises(TypeError, match="`normalize` must be a bool"):
            call(normalize=bad)
