"""Tests of synchronize_doubly_stochastic and birkhoff_von_neumann (ALGORITHMS.md §1.7, §4.2)."""

import numpy as np
import pytest

from transync.datasets import make_permutation_collection
from transync.exceptions import ConvergenceWarning
from transync.permutations import assignment_to_matrix
from transync.synchronization import (
    BirkhoffSyncResult,
    birkhoff_von_neumann,
    synchronize_doubly_stochastic,
)


def _sinkhorn(K, n_iter=500):
    for _ in range(n_iter):
        K = K / K.sum(1, keepdims=True)
        K = K / K.sum(0, keepdims=True)
    return K


def _soft_collection(N, n, noise, rng, corruption=0.0):
    data = make_permutation_collection(N, n, corruption=corruption, rng=rng)
    X = {}
    for (i, j), a in data.pairwise.items():
        P = assignment_to_matrix(a, n)
        X[(i, j)] = _sinkhorn(P + noise * rng.random((n, n)) + 1e-3)
    return data, X


def test_consistent_input_gives_one_atom():
    data = make_permutation_collection(6, 5, rng=0)
    X = {k: assignment_to_matrix(a, 5) for k, a in data.pairwise.items()}
    res = synchronize_doubly_stochastic(X)
    assert isinstance(res, BirkhoffSyncResult)
    assert res.converged and res.n_iter == 0
    np.testing.assert_allclose(res.weights, [1.0])
    assert res.atoms.shape == (1, 6, 5)
    for k, block in res.blocks.items():
        np.testing.assert_allclose(block, X[k], atol=1e-12)
    assert res.objective == pytest.approx(0.0, abs=1e-12)
    assert data.accuracy(res.labels) == 1.0


@pytest.mark.parametrize("fully_corrective", [False, True])
def test_blocks_doubly_stochastic_and_objective_monotone(rng, fully_corrective):
    data, X = _soft_collection(6, 5, 0.6, rng, corruption=0.2)
    with pytest.warns(ConvergenceWarning):          # FW rarely closes the gap in 8 steps
        res = synchronize_doubly_stochastic(X, max_iter=8, fully_corrective=fully_corrective,
                                            tol=1e-12)
    assert res.n_iter == 8
    np.testing.assert_allclose(res.weights.sum(), 1.0, atol=1e-12)
    assert np.all(res.weights > 0)
    for i in range(6):
        for j in range(6):
            B = res.block(i, j)
            np.testing.assert_allclose(B.sum(0), 1.0, atol=1e-9)
            np.testing.assert_allclose(B.sum(1), 1.0, atol=1e-9)
            assert B.min() >= 0
    h = res.objective_history
    assert np.all(np.diff(h) <= 1e-12 * max(h[0], 1))
    assert h[-1] < h[0]
    # blocks dict agrees with block(i, j) and the atoms are consistent configurations
    np.testing.assert_allclose(res.blocks[(0, 1)], res.block(0, 1), atol=1e-12)
    np.testing.assert_array_equal(res.atoms[:, 0], np.tile(np.arange(5), (len(res.weights), 1)))


def test_map_configuration_recovers_truth_under_noise(rng):
    data, X = _soft_collection(8, 6, 0.3, rng)
    with pytest.warns(ConvergenceWarning):
        res = synchronize_doubly_stochastic(X, max_iter=3, tol=1e-12)
    assert data.accuracy(res.labels) == 1.0
    np.testing.assert_array_equal(res.pairwise(2, 5), data.true_pairwise(2, 5))


def test_two_objects_reduce_to_bvn(rng):
    n = 5
    P = [rng.permutation(n) for _ in range(3)]
    wts = np.array([0.5, 0.3, 0.2])
    X01 = sum(a * assignment_to_matrix(p, n) for a, p in zip(wts, P))
    res = synchronize_doubly_stochastic({(0, 1): X01}, fully_corrective=True, max_iter=20)
    assert res.converged
    np.testing.assert_allclose(res.block(0, 1), X01, atol=1e-8)
    # like a BvN decomposition (not unique): every atom is a permutation inside the support
    for lab in res.atoms:
        assert np.all(X01[np.arange(n), np.argsort(lab[1])[lab[0]]] > 0)
    assert res.weights.size <= n * n - 2 * n + 2


def test_bvn_reconstructs(rng):
    n = 6
    perms = [rng.permutation(n) for _ in range(4)]
    lam = rng.dirichlet(np.ones(4))
    X = sum(a * assignment_to_matrix(p, n) for a, p in zip(lam, perms))
    w, P = birkhoff_von_neumann(X)
    assert P.shape == (w.size, n) and w.size <= n * n - 2 * n + 2
    recon = sum(a * assignment_to_matrix(p, n) for a, p in zip(w, P))
    np.testing.assert_allclose(recon, X, atol=1e-9)
    np.testing.assert_allclose(w.sum(), 1.0, atol=1e-9)
    # a Sinkhorn matrix with full support also decomposes
    Y = _sinkhorn(rng.random((n, n)) + 0.1)
    w, P = birkhoff_von_neumann(Y, tol=1e-12)
    recon = sum(a * assignment_to_matrix(p, n) for a, p in zip(w, P))
    np.testing.assert_allclose(recon, Y, atol=1e-8)


@pytest.mark.parametrize("X, match", [
    (np.array([[0.5, 0.4], [0.5, 0.5]]), "doubly stochastic"),
    (np.array([[1.5, -0.5], [-0.5, 1.5]]), "non-negative"),
    (np.ones((2, 3)) / 3, "square"),
])
def test_bvn_bad_input(X, match):
    with pytest.raises(ValueError, match=match):
        birkhoff_von_neumann(X)


def test_ds_bad_input():
    with pytest.raises(ValueError, match="doubly stochastic"):
        synchronize_doubly_stochastic({(0, 1): np.full((3, 3), 0.5)})
    with pytest.raises(ValueError, match="at most 1"):       # partial model: sub-DS blocks
        synchronize_doubly_stochastic({(0, 1): np.full((2, 3), 0.6), (1, 2): np.eye(3)})
    with pytest.raises(ValueError, match="n_universe"):
        synchronize_doubly_stochastic({(0, 1): np.eye(3)}, n_universe=2)
    with pytest.raises(ValueError, match="i == j"):
        synchronize_doubly_stochastic({(1, 1): np.eye(3)})
    with pytest.raises(ValueError, match="solver"):
        synchronize_doubly_stochastic({(0, 1): np.eye(3)}, solver="eigs")


def _partial_soft(data, rng, noise):
    X = {}
    for (i, j), a in data.pairwise.items():
        P = assignment_to_matrix(a, int(data.sizes[j]))
        if noise:
            # mix with a random partial permutation of the same pair: stays sub-DS
            b = -np.ones_like(a)
            k = min(a.size, int(data.sizes[j]))
            b[rng.permutation(a.size)[:k]] = rng.permutation(int(data.sizes[j]))[:k]
            P = (1 - noise) * P + noise * assignment_to_matrix(b, int(data.sizes[j]))
        X[(i, j)] = P
    return X


def test_partial_consistent_gives_one_atom(rng):
    """Multi-simplex model (§5): objects of different sizes, consistent input -> exact, 1 atom."""
    data = make_permutation_collection(7, 6, visibility=0.7, n_universe=8, rng=rng)
    assert len(set(data.sizes.tolist())) > 1
    X = _partial_soft(data, rng, 0.0)
    for kw in ({"n_universe": 8}, {}):
        res = synchronize_doubly_stochastic(X, **kw)
        assert res.converged and res.weights.tolist() == [1.0]
        assert res.n_universe == 8
        assert data.accuracy(res.labels) == 1.0
        for k, block in res.blocks.items():
            np.testing.assert_array_equal(block, X[k])
        assert res.objective == 0.0
    assert "gap" in res.info["n_universe_rule"]


def test_partial_noisy_sub_doubly_stochastic_and_monotone(rng):
    data = make_permutation_collection(7, 6, visibility=0.7, n_universe=8, rng=rng)
    X = _partial_soft(data, rng, 0.3)
    with pytest.warns(ConvergenceWarning):
        res = synchronize_doubly_stochastic(X, n_universe=8, max_iter=6, tol=1e-12,
                                            fully_corrective=True)
    h = res.objective_history
    assert np.all(np.diff(h) <= 1e-12 * max(h[0], 1)) and h[-1] < h[0]
    for i in range(7):
        for j in range(7):
            B = res.block(i, j)
            assert B.shape == (data.sizes[i], data.sizes[j]) and B.min() >= 0
            assert B.sum(0).max() <= 1 + 1e-9 and B.sum(1).max() <= 1 + 1e-9
    # every atom is a partial configuration: injective labels per object, padding -1
    for lab in res.atoms:
        for g in range(7):
            row = lab[g, : data.sizes[g]]
            assert row.min() >= 0 and np.unique(row).size == row.size
            assert np.all(lab[g, data.sizes[g]:] == -1)
    assert data.accuracy(res.labels) == 1.0


def test_oracle_sparse_block_matrix_equals_the_dense_one():
    """Objects of different sizes (padding excluded), a view graph that is not complete."""
    from transync.synchronization._birkhoff import _Oracle

    rng = np.random.default_rng(4)
    sizes = np.array([3, 5, 2, 5, 4])
    pairs = np.array([[0, 1], [0, 3], [1, 2], [1, 4], [2, 3], [3, 4]])
    o = _Oracle(pairs, sizes, 6, sweeps=1, rng=0, solver="matrix_free")
    wG = np.zeros((len(pairs), 5, 5))
    for p, (i, j) in enumerate(pairs):
        wG[p, : sizes[i], : sizes[j]] = rng.random((sizes[i], sizes[j]))
    B = o.block_matrix(wG)
    S = o.sparse_block_matrix(o.directed(wG))
    assert B.shape == S.shape == (sizes.sum(), sizes.sum())
    assert S.dtype == np.float32
    np.testing.assert_array_equal(S.toarray(), B.astype(np.float32))
    np.testing.assert_array_equal(B, B.T)


@pytest.mark.parametrize("operator", ["dense array", "sparse matrix"])
def test_matrix_free_branch_matches_dense(rng, operator, monkeypatch):
    """The k-hat step's matrix-free eigensolver (used above 2000 nodes) on a small problem, with
    its product through the dense block matrix (views covering a quarter of it, as all pairs
    here) and through the sparse one (sparser views)."""
    from transync.synchronization import _birkhoff

    if operator == "sparse matrix":
        monkeypatch.setattr(_birkhoff, "DENSE_OPERATOR_MAX", 0)
    data, X = _soft_collection(10, 6, 0.3, rng, corruption=0.1)
    # the initial vertex (spectral start on X, no sweeps) is the same for both eigensolvers
    init = {s: synchronize_doubly_stochastic(X, max_iter=0, inner_sweeps=0, solver=s, rng=0)
            for s in ("dense", "matrix_free")}
    np.testing.assert_array_equal(init["dense"].atoms, init["matrix_free"].atoms)
    assert data.accuracy(init["matrix_free"].labels) == 1.0
    # the full method: later k-hat vertices may differ (the LMO is a heuristic), the guarantees not
    out = {}
    for solver in ("dense", "matrix_free"):
        with pytest.warns(ConvergenceWarning):
            out[solver] = synchronize_doubly_stochastic(X, max_iter=4, tol=1e-12, solver=solver,
                                                        fully_corrective=True, rng=0)
        res = out[solver]
        assert res.info["solver"] == solver
        assert np.all(np.diff(res.objective_history) <= 1e-12 * res.objective_history[0])
        for B in res.blocks.values():
            np.testing.assert_allclose(B.sum(0), 1.0, atol=1e-9)
            np.testing.assert_allclose(B.sum(1), 1.0, atol=1e-9)
    d, m = out["dense"], out["matrix_free"]
    np.testing.assert_array_equal(np.asarray(d.labels), np.asarray(m.labels))
    assert m.objective == pytest.approx(d.objective, rel=0.05)


def test_block_is_the_weighted_sum_of_the_atoms_maps():
    """``block(i, j)`` (vectorized over atoms) equals sum_k w_k P_ij^k built atom by atom."""
    from transync.datasets import make_permutation_collection
    from transync.permutations import assignment_to_matrix
    from transync.synchronization import synchronize_doubly_stochastic

    c = make_permutation_collection(6, 5, corruption=0.4, rng=3)
    with pytest.warns(ConvergenceWarning):           # a few iterations leave several atoms
        res = synchronize_doubly_stochastic(c.pairwise, max_iter=10)
    assert res.weights.size >= 2
    for i, j in [(0, 1), (3, 2), (5, 0), (2, 2)]:
        want = sum(w * assignment_to_matrix(res.atom(k).pairwise(i, j), 5)
                   for k, w in enumerate(res.weights))
        np.testing.assert_allclose(res.block(i, j), want, atol=1e-12)


# ---------------------------------------------------------------- estimate_universe

def _partial_collection(rng, d, sizes):
    """Objects keeping ``sizes[g]`` of ``d`` universe nodes (shuffled): exact partial maps."""
    labels = [rng.permutation(d)[:k] for k in sizes]
    blocks = {}
    for i in range(len(sizes)):
        for j in range(i + 1, len(sizes)):
            X = (labels[i][:, None] == labels[j][None, :]).astype(float)
            blocks[(i, j)] = X
    return labels, blocks


@pytest.mark.parametrize("seed", range(4))
def test_estimate_universe_exact_at_zero_noise_and_invariant_to_relabelling(seed):
    from transync.synchronization import estimate_universe
    rng = np.random.default_rng(seed)
    d = 15
    sizes = rng.integers(8, 14, size=7)
    labels, blocks = _partial_collection(rng, d, sizes)
    used = len(set(np.concatenate(labels).tolist()))        # nodes kept by at least one object
    est = estimate_universe(blocks)
    assert est.n_universe == used and est.sizes.tolist() == sizes.tolist()
    assert "eigengap" in est.rule and est.eigenvalues[0] == pytest.approx(1.0)
    perm = rng.permutation(sizes[2])                         # relabel object 2's nodes
    relabelled = {k: (X[perm] if k[0] == 2 else X[:, perm] if k[1] == 2 else X)
                  for k, X in blocks.items()}
    assert estimate_universe(relabelled).n_universe == used
    # the same rule as synchronize_doubly_stochastic's, on the same soft input
    soft = {k: 0.9 * X + 0.1 / X.size for k, X in blocks.items()}     # rows, columns <= 1
    ref = synchronize_doubly_stochastic(soft, max_iter=0).info["n_universe"]
    assert estimate_universe(soft).n_universe == ref


def test_eigengap_split_step():
    """The split-gap step of the soft estimate: one slot more when the gap after the largest is
    at least ``split`` times it, never otherwise, and the plain rule without ``split``."""
    from transync.synchronization._spectral import estimate_universe as rule

    # a node kept by few objects sits between the plateau and the noise: two comparable gaps
    vals = np.array([1.0, 1.0, 1.0, 0.55, 0.2, 0.18, 0.17])
    assert rule(vals, 3)[0] == 3                                   # largest gap: after l_3
    d, why = rule(vals, 3, split=0.6)                              # 0.35 >= 0.6 * 0.45
    assert d == 4 and "split gap" in why
    assert rule(vals, 3, split=0.8)[0] == 3                        # 0.35 < 0.8 * 0.45
    clean = np.array([1.0, 1.0, 1.0, 0.2, 0.18, 0.17])             # one clean gap: unchanged
    assert rule(clean, 3, split=0.6)[0] == 3
    last = np.array([1.0, 1.0, 0.1])                               # the gap is the last one
    assert rule(last, 2, split=0.6)[0] == 2
    flat = np.zeros(6)                                             # no gap at all: no step
    d, why = rule(flat, 3, split=0.6)
    assert d == 3 and "split" not in why


def test_estimate_universe_bad_input():
    from transync.synchronization import estimate_universe
    X = np.array([[0.5, 0.5], [0.0, 0.0]])
    with pytest.raises(ValueError, match="non-negative"):
        estimate_universe({(0, 1): -X})
    with pytest.raises(ValueError, match="at most 1"):
        estimate_universe({(0, 1): 2.0 * X})
    with pytest.raises(ValueError, match="at least one observed pair"):
        estimate_universe({})
    est = estimate_universe({(0, 1): X}, sizes=[2, 2, 3])     # object 2 in no pair
    assert est.n_universe >= 3


@pytest.mark.parametrize("scale", [5e-324, 1e-310, 1e-300, 0.01, 0.05, 0.2, 1e290])
def test_universe_estimate_ignores_a_uniform_weight_scale(scale):
    # consistent partial input: one eigenvalue 1 per universe node whatever the weights; the
    # identity blocks once weighed 1 against the pairs' c, and at c = 0.05 the spectrum after
    # the ones (0.905, 0.826, ...) split the gap and the estimate became 9 instead of 8
    from transync.synchronization import estimate_universe

    rng = np.random.default_rng(8)
    N, d = 5, 8
    labs = []
    for _ in range(N):
        keep = rng.random(d) < 0.7
        if keep.sum() < 2:
            keep[:2] = True
        labs.append(rng.permutation(np.flatnonzero(keep)))
    X = {(i, j): (labs[i][:, None] == labs[j][None, :]).astype(float)
         for i in range(N) for j in range(i + 1, N)}
    W = np.full((N, N), scale)
    assert estimate_universe(X, weights=W).n_universe == 8
    res = synchronize_doubly_stochastic(X, weights=W)
    assert res.n_universe == 8
    for (i, j), blk in X.items():
        np.testing.assert_allclose(res.block(i, j), blk, atol=1e-9)
