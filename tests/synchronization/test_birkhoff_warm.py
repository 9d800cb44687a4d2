"""Warm start, vectorized k-hat step and stacked blocks of synchronize_doubly_stochastic
(issue #10: Birkhoff synchronization inside the online multi-graph solvers)."""

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from transync.datasets import make_permutation_collection
from transync.exceptions import ConvergenceWarning
from transync.permutations import assignment_to_matrix
from transync.synchronization import (
    BirkhoffSyncResult,
    synchronize_doubly_stochastic,
    synchronize_permutations,
)
from transync.synchronization._birkhoff import WARM_MAX_ATOMS, _maps_of, _Oracle


def _sinkhorn(K, n_iter=300):
    for _ in range(n_iter):
        K = K / K.sum(-1, keepdims=True)
        K = K / K.sum(-2, keepdims=True)
    return K


def _noisy(N, n, rng, corruption=0.3, noise=0.5):
    data = make_permutation_collection(N, n, corruption=corruption, rng=rng)
    keys = sorted(data.pairwise)
    P = np.stack([assignment_to_matrix(data.pairwise[k], n) for k in keys])
    X = _sinkhorn(P + noise * rng.random(P.shape) + 1e-3)
    return data, keys, X


def _mixture(N, n, lam, rng):
    """Soft blocks that are exactly a convex combination of consistent configurations."""
    configs = [[rng.permutation(n) for _ in range(N)] for _ in lam]
    keys = [(i, j) for i in range(N) for j in range(i + 1, N)]
    X = {}
    for i, j in keys:
        X[(i, j)] = sum(a * assignment_to_matrix(np.argsort(c[j])[c[i]], n)
                        for a, c in zip(lam, configs))
    return X


def _quiet(**kw):
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return synchronize_doubly_stochastic(**kw)


def _assert_ds(res, atol=1e-9):
    N = res.n_objects
    pairs = np.array([(i, j) for i in range(N) for j in range(N)])
    Y = res.stacked_blocks(pairs)
    np.testing.assert_allclose(Y.sum(1), 1.0, atol=atol)
    np.testing.assert_allclose(Y.sum(2), 1.0, atol=atol)
    assert Y.min() >= 0


def test_warm_start_same_input_is_no_worse_and_needs_no_iteration(rng):
    data, keys, X = _noisy(7, 5, rng)
    pw = dict(zip(keys, X))
    cold = _quiet(pairwise=pw, max_iter=8, tol=1e-12)
    warm = _quiet(pairwise=pw, max_iter=8, tol=1e-12, init=cold)
    assert warm.info["warm_start"] == min(cold.weights.size, WARM_MAX_ATOMS)
    # the re-fitted init alone already reaches the cold objective (0 iterations instead of 8)
    assert warm.objective_history[0] <= cold.objective + 1e-10
    assert warm.objective <= cold.objective + 1e-10
    h = warm.objective_history
    assert np.all(np.diff(h) <= 1e-12 * max(h[0], 1.0))
    _assert_ds(warm)
    assert data.accuracy(warm.labels) == data.accuracy(cold.labels)


def test_warm_start_of_a_converged_result_converges_at_once(rng):
    X = _mixture(5, 4, [0.6, 0.3, 0.1], rng)
    cold = synchronize_doubly_stochastic(X, fully_corrective=True, max_iter=50)
    assert cold.converged and cold.n_iter >= 1
    for fc in (False, True):
        warm = synchronize_doubly_stochastic(X, init=cold, fully_corrective=fc)
        assert warm.converged and warm.n_iter == 0 < cold.n_iter
        assert warm.objective <= cold.objective + 1e-12
    assert cold.objective == pytest.approx(0.0, abs=1e-9)


def test_warm_start_across_a_small_perturbation_reaches_the_cold_objective(rng):
    lam = np.array([0.5, 0.3, 0.2])
    X = _mixture(5, 4, lam, np.random.default_rng(1))
    X2 = _mixture(5, 4, lam + [0.04, -0.02, -0.02], np.random.default_rng(1))   # same atoms
    tol = 1e-6
    first = synchronize_doubly_stochastic(X, fully_corrective=True, max_iter=50, tol=tol)
    cold = synchronize_doubly_stochastic(X2, fully_corrective=True, max_iter=50, tol=tol)
    warm = synchronize_doubly_stochastic(X2, init=first, max_iter=50, tol=tol)
    assert cold.converged and warm.converged and warm.n_iter <= cold.n_iter
    norm = sum(float((B ** 2).sum()) for B in X2.values())
    assert warm.objective <= cold.objective + tol * norm
    for k in X2:
        np.testing.assert_allclose(warm.blocks[k], X2[k], atol=1e-6)


def test_consistent_input_one_atom_cold_and_warm(rng):
    data = make_permutation_collection(6, 5, rng=rng)
    X = {k: assignment_to_matrix(a, 5) for k, a in data.pairwise.items()}
    noisy = {k: _sinkhorn(v + 0.4 * rng.random((5, 5))) for k, v in X.items()}
    prev = _quiet(pairwise=noisy, max_iter=5)
    assert prev.weights.size > 1
    for init in (None, prev):
        res = synchronize_doubly_stochastic(X, init=init)
        assert res.converged and res.n_iter == 0
        assert res.weights.tolist() == [1.0] and res.atoms.shape == (1, 6, 5)
        assert res.objective == pytest.approx(0.0, abs=1e-12)
        for k, block in res.blocks.items():
            np.testing.assert_allclose(block, X[k], atol=1e-12)
        assert data.accuracy(res.labels) == 1.0


@pytest.mark.parametrize("fully_corrective", [False, True])
def test_warm_chain_doubly_stochastic_and_monotone(rng, fully_corrective):
    """A chain of warm-started calls on drifting input (an online solver's use)."""
    data, keys, X = _noisy(8, 5, rng, corruption=0.2, noise=0.3)
    res = None
    for t in range(4):
        Xt = _sinkhorn(X + 0.03 * t * rng.random(X.shape))
        res = _quiet(pairwise=dict(zip(keys, Xt)), init=res, max_iter=3, tol=1e-12,
                     fully_corrective=fully_corrective)
        assert res.n_iter == 3 and res.weights.size <= WARM_MAX_ATOMS + 3 * 10
        h = res.objective_history
        assert np.all(np.diff(h) <= 1e-12 * max(h[0], 1.0))
        np.testing.assert_allclose(res.weights.sum(), 1.0, atol=1e-12)
        assert np.all(res.weights > 0)
        _assert_ds(res)
    assert data.accuracy(res.labels) == 1.0


def test_warm_start_keeps_at_most_the_heaviest_atoms(rng):
    data, keys, X = _noisy(6, 5, rng)
    pw = dict(zip(keys, X))
    cold = _quiet(pairwise=pw, max_iter=WARM_MAX_ATOMS + 8, tol=1e-12)
    assert cold.weights.size > WARM_MAX_ATOMS
    warm = _quiet(pairwise=pw, max_iter=0, init=cold)
    assert warm.info["warm_start"] == WARM_MAX_ATOMS
    assert warm.weights.size <= WARM_MAX_ATOMS and warm.n_iter == 0
    heavy = cold.atoms[np.argsort(-cold.weights, kind="stable")[:WARM_MAX_ATOMS]]
    assert all((heavy == a).all((1, 2)).any() for a in warm.atoms)


def test_warm_start_partial_model(rng):
    data = make_permutation_collection(6, 5, visibility=0.7, n_universe=7, rng=rng)
    X = {}
    for (i, j), a in data.pairwise.items():
        P = assignment_to_matrix(a, int(data.sizes[j]))
        X[(i, j)] = 0.8 * P + 0.2 * np.full(P.shape, 1.0 / max(P.shape)) * (P.sum() > 0)
    cold = _quiet(pairwise=X, n_universe=7, max_iter=4, tol=1e-12)
    warm = _quiet(pairwise=X, max_iter=2, tol=1e-12, init=cold)     # universe taken from init
    assert warm.n_universe == 7 and warm.objective <= cold.objective + 1e-10
    Y = warm.stacked_blocks(np.array(sorted(X)))
    assert Y.shape == (len(X), int(data.sizes.max()), int(data.sizes.max()))
    for p, (i, j) in enumerate(sorted(X)):
        np.testing.assert_allclose(Y[p, : data.sizes[i], : data.sizes[j]], warm.block(i, j))
        assert Y[p, data.sizes[i]:].sum() == 0 and Y[p, :, data.sizes[j]:].sum() == 0


def test_bad_init():
    X = {(0, 1): np.eye(3), (1, 2): np.eye(3)}
    res = synchronize_doubly_stochastic(X)
    with pytest.raises(TypeError, match="`init` must be a BirkhoffSyncResult"):
        synchronize_doubly_stochastic(X, init={"atoms": res.atoms})
    with pytest.raises(TypeError, match="`init` must be a BirkhoffSyncResult"):
        synchronize_doubly_stochastic(X, init=synchronize_permutations(
            {k: np.arange(3) for k in X}))
    with pytest.raises(ValueError, match="`init` must be a result on the same objects: it has "
                                         "3 objects, `pairwise` has 4"):
        synchronize_doubly_stochastic({**X, (2, 3): np.eye(3)}, init=res)
    with pytest.raises(ValueError, match="same sizes: object 0 has 3 nodes in `init`, 4"):
        synchronize_doubly_stochastic({(0, 1): np.eye(4), (1, 2): np.eye(4)}, init=res)
    with pytest.raises(ValueError, match="same universe: its n_universe is 3, got "
                                         "n_universe=4"):
        synchronize_doubly_stochastic(X, init=res, n_universe=4)


def test_stacked_blocks_any_order_transpose_and_identity(rng):
    data, keys, X = _noisy(6, 4, rng)
    res = _quiet(pairwise=dict(zip(keys, X)), max_iter=4)
    pairs = np.array([(0, 1), (4, 2), (3, 3), (5, 0), (1, 0)])
    Y = res.stacked_blocks(pairs)
    assert Y.shape == (5, 4, 4)
    for p, (i, j) in enumerate(pairs.tolist()):
        want = sum(w * assignment_to_matrix(res.atom(k).pairwise(i, j), 4)
                   for k, w in enumerate(res.weights))
        np.testing.assert_allclose(Y[p], want, atol=1e-12)
    np.testing.assert_allclose(Y[2], np.eye(4), atol=1e-12)
    np.testing.assert_allclose(Y[4], Y[0].T, atol=1e-12)
    obs = np.array(keys)
    np.testing.assert_allclose(res.stacked_blocks(obs), np.stack([res.blocks[k] for k in keys]),
                               atol=1e-12)
    assert res.stacked_blocks(np.zeros((0, 2), int)).shape == (0, 4, 4)
    with pytest.raises(ValueError, match="object indices in \\[0, 6\\)"):
        res.stacked_blocks([[0, 6]])
    with pytest.raises(ValueError, match="\\(P, 2\\)"):
        res.stacked_blocks(np.zeros((2, 3)))


def test_khat_sweeps_end_in_a_block_coordinate_maximum(rng):
    """The vectorized Gauss-Seidel sweeps stop where no single object's Hungarian update (built
    here pair by pair, the loop the sweeps replace) improves ``<G, X X^T>``."""
    data, keys, X = _noisy(7, 5, rng, corruption=0.5, noise=1.0)
    pairs = np.array(keys)
    G = X - X.mean()
    w = rng.random(len(keys)) + 0.5
    oracle = _Oracle(pairs, np.full(7, 5), 5, sweeps=100, rng=0, solver="dense")
    found = oracle(G, w, [np.tile(np.arange(5), (7, 1))])
    assert len(found) >= 1
    for lab, score in found:
        maps = _maps_of(lab, pairs, 5)
        ref = sum(w[q] * G[q, np.arange(5), maps[q]].sum() for q in range(len(keys)))
        assert score == pytest.approx(ref, rel=1e-12)
        for g in range(7):
            S = np.zeros((5, 5))
            for q, (i, j) in enumerate(keys):
                if i == g:
                    S[:, lab[j]] += w[q] * G[q]
                elif j == g:
                    S[:, lab[i]] += w[q] * G[q].T
            r, c = linear_sum_assignment(S, maximize=True)
            assert S[r, c].sum() <= S[np.arange(5), lab[g]].sum() + 1e-9
    assert [s for _, s in found] == sorted((s for _, s in found), reverse=True)


def test_result_type_and_pickle_with_warm_start(rng):
    import pickle
    data, keys, X = _noisy(5, 4, rng)
    res = _quiet(pairwise=dict(zip(keys, X)), max_iter=2)
    warm = _quiet(pairwise=dict(zip(keys, X)), max_iter=2, init=pickle.loads(pickle.dumps(res)))
    assert type(warm) is BirkhoffSyncResult
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(warm)).weights, warm.weights)
