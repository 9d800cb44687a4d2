"""Heat kernel signature (transync.kernels._hks), issue #12 item 2."""

import numpy as np
import pytest
from scipy.linalg import block_diag, expm

from transync.graphs import Graph
from transync.kernels import _hks
from transync.kernels._hks import HKS_TIMES, heat_kernel_signature, hks_features


def _random_graph(rng, n, p=0.4):
    A = np.triu(rng.random((n, n)) < p, 1).astype(float)
    return A + A.T


def _reference(A, times):
    """HKS from the matrix exponential of Chung's normalized Laplacian (no eigendecomposition)."""
    d = A.sum(1)
    inv = np.where(d > 0, 1.0 / np.sqrt(np.where(d > 0, d, 1.0)), 0.0)
    L = np.diag((d > 0).astype(float)) - inv[:, None] * A * inv[None, :]
    return np.stack([np.diag(expm(-t * L)) for t in times], axis=1)


def test_default_grid():
    np.testing.assert_allclose(HKS_TIMES, np.logspace(-1, np.log10(30), 10), rtol=0, atol=0)
    assert HKS_TIMES[0] == pytest.approx(0.1) and HKS_TIMES[-1] == pytest.approx(30.0)


def test_matches_matrix_exponential(rng):
    A = _random_graph(rng, 9)
    A[3, :] = A[:, 3] = 0.0                              # an isolated node
    A[A > 0] *= rng.uniform(0.5, 2.0, size=int((A > 0).sum()))   # weights
    A = np.triu(A, 1) + np.triu(A, 1).T
    times = np.array([0.05, 0.7, 4.0, 25.0])
    np.testing.assert_allclose(heat_kernel_signature(A, times), _reference(A, times),
                               rtol=0, atol=1e-12)


def test_closed_forms():
    t = np.array([0.1, 1.0, 10.0])
    K2 = np.array([[0.0, 1.0], [1.0, 0.0]])
    np.testing.assert_allclose(heat_kernel_signature(K2, t),
                               np.tile((1 + np.exp(-2 * t)) / 2, (2, 1)), rtol=0, atol=1e-14)
    # complete graph K_n: eigenvalues 0 (once) and n / (n - 1) (n - 1 times)
    n = 5
    Kn = np.ones((n, n)) - np.eye(n)
    expected = 1 / n + (n - 1) / n * np.exp(-t * n / (n - 1))
    np.testing.assert_allclose(heat_kernel_signature(Kn, t), np.tile(expected, (n, 1)),
                               rtol=0, atol=1e-14)


def test_relabelling_permutes_rows(rng):
    A = _random_graph(rng, 10)
    perm = rng.permutation(10)
    h = heat_kernel_signature(A)
    hp = heat_kernel_signature(A[np.ix_(perm, perm)])
    np.testing.assert_allclose(hp, h[perm], rtol=0, atol=1e-12)


def test_disjoint_components_are_independent(rng):
    A1, A2 = _random_graph(rng, 6, 0.6), _random_graph(rng, 4, 0.8)
    h = heat_kernel_signature(block_diag(A1, A2))
    np.testing.assert_allclose(h, np.vstack([heat_kernel_signature(A1),
                                             heat_kernel_signature(A2)]), rtol=0, atol=1e-12)


def test_isolated_nodes_are_exactly_one():
    A = np.zeros((4, 4))
    A[0, 1] = A[1, 0] = 1.0
    h = heat_kernel_signature(A)
    assert np.all(np.isfinite(h))
    assert np.array_equal(h[2:], np.ones((2, len(HKS_TIMES))))
    assert np.array_equal(heat_kernel_signature(np.zeros((1, 1))), np.ones((1, 10)))


def test_small_time_limit_and_range(rng):
    A = _random_graph(rng, 8)
    h0 = heat_kernel_signature(A, times=[1e-10])
    np.testing.assert_allclose(h0, 1.0, rtol=0, atol=1e-9)
    h = heat_kernel_signature(A)
    assert np.all(h > 0) and np.all(h <= 1 + 1e-12)
    assert np.all(np.diff(h, axis=1) <= 1e-12)          # non-increasing in t


def test_graph_input_equals_adjacency(rng):
    A = _random_graph(rng, 7)
    np.testing.assert_array_equal(heat_kernel_signature(Graph(adjacency=A)),
                                  heat_kernel_signature(A))


def test_batched_equals_single(rng, monkeypatch):
    graphs = [_random_graph(rng, n) for n in (5, 3, 5, 1, 7, 3, 5)]
    graphs[1][:] = 0.0
    single = [heat_kernel_signature(A) for A in graphs]
    batched = hks_features(graphs)
    assert [b.shape for b in batched] == [(len(A), 10) for A in graphs]
    for s, b in zip(single, batched):
        np.testing.assert_allclose(b, s, rtol=0, atol=1e-12)
    monkeypatch.setattr(_hks, "_STACK_BYTES", 8 * 25)      # one graph per stack
    for s, b in zip(single, hks_features([Graph(adjacency=A) for A in graphs])):
        np.testing.assert_allclose(b, s, rtol=0, atol=1e-12)


def test_custom_times_shape(rng):
    feats = hks_features([_random_graph(rng, 4)], times=(0.5, 1.5, 3.0))
    assert feats[0].shape == (4, 3)


@pytest.mark.parametrize("bad, match", [
    (np.zeros((2, 3)), "square"),
    (np.array([[0.0, 1.0], [0.0, 0.0]]), "symmetric"),
    (np.array([[0.0, -1.0], [-1.0, 0.0]]), "non-negative"),
    (np.array([[0.0, np.nan], [np.nan, 0.0]]), "finite"),
    (np.zeros((0, 0)), "square"),
])
def test_invalid_adjacency(bad, match):
    with pytest.raises(ValueError, match=match):
        heat_kernel_signature(bad)


def test_invalid_inputs():
    A = np.array([[0.0, 1.0], [1.0, 0.0]])
    with pytest.raises(ValueError, match="directed"):
        heat_kernel_signature(Graph(adjacency=np.array([[0.0, 1.0], [0.0, 0.0]]), directed=True))
    with pytest.raises(ValueError, match="`times` must be positive"):
        heat_kernel_signature(A, times=[1.0, 0.0])
    with pytest.raises(ValueError, match="`times` must hold at least one"):
        heat_kernel_signature(A, times=[])
    with pytest.raises(ValueError, match="`times` must have 1 dimensions"):
        heat_kernel_signature(A, times=[[1.0]])
    with pytest.raises(TypeError, match="`graphs` must be a sequence"):
        hks_features(A)
    with pytest.raises(ValueError, match=r"`graphs\[1\]` must be symmetric"):
        hks_features([A, np.array([[0.0, 1.0], [0.0, 0.0]])])


@pytest.mark.dataset("tu")
def test_mutag_features_are_fast_and_valid(require_dataset):
    datasets = pytest.importorskip("transync.datasets")
    try:
        data = datasets.load_tu("MUTAG")
    except (ImportError, AttributeError):   # the loader (issue #12 item 1) is not there yet
        pytest.skip("transync.datasets.load_tu unavailable")
    feats = hks_features(list(data.graphs))
    assert len(feats) == len(data.graphs)
    for g, h in zip(data.graphs, feats):
        assert h.shape == (g.n_nodes, 10)
        assert np.all((h > 0) & (h <= 1 + 1e-12))


def test_boolean_times_are_refused():
    """times=[True] was read as t = 1.0 (TransitiveAssignmentKernel(times=[True]) accepted)."""
    path = np.diag(np.ones(3), 1)
    path = path + path.T
    with pytest.raises(TypeError, match="`times` must hold positive numbers, got booleans"):
        hks_features([Graph(path)], [True])
    with pytest.raises(TypeError, match="`times`"):
        hks_features([Graph(path)], [[0.1], [0.1, 1.0]])          # ragged: named too
