"""CAO / CAO-C / CAO-UC / CAO-PC (transync.multigraph._cao) against pygmtools, a loop reference
written from the definitions, planted solutions, invariants and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from transync.multigraph import _cao
from transync.multigraph._cao import CAO_VARIANTS, CAOOutcome, cao

# --------------------------------------------------------------------------------------------
# helpers: dense pygmtools-layout affinities of a planted multi-graph problem


def _problem(N, n, *, noise, seed, sigma2=0.05, quantize=False):
    """Complete weighted graphs: one base graph, node orders shuffled, Gaussian weight noise.

    Returns K (N, N, n*n, n*n) in pygmtools layout (vec column-wise: X[u, a] at a*n + u),
    pairs (P, 2) in triu order and the true maps truth (P, n).
    """
    rng = np.random.default_rng(seed)
    base = rng.random((n, n))
    base = (base + base.T) / 2
    perms = [np.arange(n)] + [rng.permutation(n) for _ in range(N - 1)]
    E = []
    for g in range(N):
        W = base + noise * rng.standard_normal((n, n))
        W = (W + W.T) / 2
        Wg = np.empty_like(W)
        Wg[np.ix_(perms[g], perms[g])] = W          # base node u is node perms[g][u] of g
        E.append(Wg)
    off = ~np.eye(n, dtype=bool)
    mask = off[None, :, None, :] & off[:, None, :, None]
    K = np.empty((N, N, n * n, n * n))
    for i in range(N):
        for j in range(N):
            d = E[i][None, :, None, :] - E[j][:, None, :, None]      # (a, u, b, v)
            Kij = np.exp(-d ** 2 / sigma2) * mask
            K[i, j] = (np.round(10 * Kij) if quantize else Kij).reshape(n * n, n * n)
    iu, ju = np.triu_indices(N, 1)
    pairs = np.stack([iu, ju], axis=1)
    truth = np.empty((len(pairs), n), dtype=np.int64)
    for p, (i, j) in enumerate(pairs):
        truth[p, perms[i]] = perms[j]
    return K, pairs, truth


def _scorer(K, pairs, calls=None):
    """x^T K_p x of one-hot assignments, x in pygmtools layout (a tiny dense gather)."""
    n = int(round(np.sqrt(K.shape[2])))
    Kp = K[pairs[:, 0], pairs[:, 1]]

    def score(p_idx, assign):
        if calls is not None:
            calls.append((np.array(p_idx), np.array(assign)))
        idx = assign * n + np.arange(n)
        return Kp[p_idx[:, None, None], idx[:, :, None], idx[:, None, :]].sum(axis=(1, 2))
    return score


def _x0(assign, pairs, N, n):
    X = np.zeros((N, N, n, n))
    X[np.arange(N), np.arange(N)] = np.eye(n)
    for p, (i, j) in enumerate(pairs):
        M = np.zeros((n, n))
        M[np.arange(n), assign[p]] = 1.0
        X[i, j], X[j, i] = M, M.T
    return X


def _corrupt(truth, rng, *, frac, scramble=0.3):
    out = truth.copy()
    n = truth.shape[1]
    for p in range(len(out)):
        if rng.random() < scramble:
            out[p] = rng.permutation(n)
        elif rng.random() < frac:
            a, b = rng.choice(n, 2, replace=False)
            out[p, [a, b]] = out[p, [b, a]]
    return out


def _reference_cao(K, init, pairs, N, variant, *, lambda_init=0.3, lambda_step=1.1,
                   lambda_max=1.0, max_iter=6, immune_iter=2):
    """Jacobi CAO written from the definitions with (n, n) matrices and plain loops."""
    n = init.shape[1]
    X = _x0(init, pairs, N, n)

    def aff(Y, i, j):
        v = Y.T.reshape(-1)
        return v @ K[i, j] @ v

    def cp(Y, i, j):
        return 1.0 - sum(np.abs(Y - X[i, l] @ X[l, j]).sum() for l in range(N)) / (2 * n * N)

    lam = lambda_init
    for t in range(max_iter):
        if t >= immune_iter:
            lam = min(lam * lambda_step, lambda_max)
        use_con = variant != "cao" and t >= immune_iter
        norm = max(aff(X[i, j], i, j) for i, j in pairs)
        pc = np.array([[cp(X[i, j], i, j) for j in range(N)] for i in range(N)])
        cu = [1.0 - np.mean([np.abs(X[i, j] - X[i, k] @ X[k, j]).sum() for i, j in pairs])
              / (2 * n) for k in range(N)]
        new = X.copy()
        for i, j in pairs:
            best, best_fit = None, -np.inf
            for k in range(N):
                Y = X[i, k] @ X[k, j]
                fit = aff(Y, i, j) / norm
                if use_con:
                    con = {"cao-c": lambda: cp(Y, i, j),
                           "cao-uc": lambda: cu[k],
                           "cao-pc": lambda: np.sqrt(pc[i, k] * pc[k, j])}[variant]()
                    fit = fit * (1 - lam) + con * lam
                if fit > best_fit:
                    best, best_fit = Y, fit
            new[i, j], new[j, i] = best, best.T
        X = new
    return X[pairs[:, 0], pairs[:, 1]].argmax(axis=-1)


# --------------------------------------------------------------------------------------------
# reference values


@pytest.fixture(scope="module")
def pygm():
    return pytest.importorskip("pygmtools")            # imported once (about 1 s)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("mode, variant, update, lambda_init", [
    ("time", "cao-pc", "jacobi", 0.3),
    ("time", "cao", "jacobi", 0.0),            # lambda = 0 in pygmtools is plain CAO
    ("memory", "cao-c", "sequential", 0.3),
    ("memory", "cao", "sequential", 0.0),
])
def test_identical_to_pygmtools(pygm, seed, mode, variant, update, lambda_init):
    N, n = 5 + seed % 2, 5 + seed
    K, pairs, truth = _problem(N, n, noise=[0.2, 0.4, 1.0, 0.3][seed], seed=seed, sigma2=0.1)
    init = _corrupt(truth, np.random.default_rng(seed), frac=0.9)
    kw = dict(lambda_init=lambda_init)
    if seed % 2:
        kw.update(lambda_step=1.3, max_iter=8)
        pk = dict(kw, iter_boost=1)
        kw["immune_iter"] = 1
    else:
        pk = kw
    ref = pygm.cao(K, x0=_x0(init, pairs, N, n), mode=mode, backend="numpy", **pk)
    out = cao(init, pairs, N, _scorer(K, pairs), variant=variant, update=update, **kw)
    np.testing.assert_array_equal(out.assignments,
                                  ref[pairs[:, 0], pairs[:, 1]].argmax(axis=-1))
    assert out.history["changed"].sum() > 0          # the comparison is not trivial


@pytest.mark.parametrize("variant", CAO_VARIANTS)
@pytest.mark.parametrize("seed", range(2))
def test_jacobi_matches_loop_reference(variant, seed):
    # quantized (integer) affinities: every score is exact in both implementations
    N, n = 5, 5 + seed
    K, pairs, truth = _problem(N, n, noise=0.5, seed=10 + seed, sigma2=0.1, quantize=True)
    init = _corrupt(truth, np.random.default_rng(seed), frac=0.9, scramble=0.4)
    kw = dict(lambda_init=0.4, lambda_step=1.5, max_iter=5, immune_iter=1)
    out = cao(init, pairs, N, _scorer(K, pairs), variant=variant, **kw)
    np.testing.assert_array_equal(out.assignments,
                                  _reference_cao(K, init, pairs, N, variant, **kw))


# --------------------------------------------------------------------------------------------
# planted solutions


@pytest.mark.parametrize("update", ["jacobi", "sequential"])
@pytest.mark.parametrize("variant", CAO_VARIANTS)
def test_consistent_input_is_unchanged(variant, update):
    if update == "sequential" and variant not in ("cao", "cao-c"):
        pytest.skip("sequential sweep: cao and cao-c only")
    N, n = 6, 7
    K, pairs, truth = _problem(N, n, noise=0.3, seed=3)
    rng = np.random.default_rng(0)
    labels = [rng.permutation(n) for _ in range(N)]      # consistent, but not the truth
    init = np.array([np.argsort(labels[j])[labels[i]] for i, j in pairs])
    for start in (truth, init):
        out = cao(start, pairs, N, _scorer(K, pairs), variant=variant, update=update)
        np.testing.assert_array_equal(out.assignments, start)
        assert out.converged and out.n_iter == 0            # nothing can change: no sweep
        assert out.history["consistency"].tolist() == [1.0]
        assert out.history["changed"].tolist() == []
        np.testing.assert_allclose(out.scores,
                                   _scorer(K, pairs)(np.arange(len(pairs)), start), rtol=0)


@pytest.mark.parametrize("update", ["jacobi", "sequential"])
@pytest.mark.parametrize("variant", CAO_VARIANTS)
@pytest.mark.parametrize("bad", [0, 7, 14])
def test_one_corrupted_pair_is_repaired(variant, update, bad):
    if update == "sequential" and variant not in ("cao", "cao-c"):
        pytest.skip("sequential sweep: cao and cao-c only")
    N, n = 6, 8
    K, pairs, truth = _problem(N, n, noise=0.0, seed=bad)
    init = truth.copy()
    init[bad] = np.random.default_rng(bad).permutation(n)
    assert not np.array_equal(init[bad], truth[bad])
    out = cao(init, pairs, N, _scorer(K, pairs), variant=variant, update=update)
    np.testing.assert_array_equal(out.assignments, truth)
    assert out.converged
    assert out.history["consistency"][0] < 1.0 == out.history["consistency"][-1]
    assert out.history["changed"][0] == 1


def test_recovers_planted_truth_from_noisy_start():
    N, n = 8, 8
    K, pairs, truth = _problem(N, n, noise=0.05, seed=5)
    init = _corrupt(truth, np.random.default_rng(5), frac=0.5, scramble=0.2)
    out = cao(init, pairs, N, _scorer(K, pairs))
    assert np.mean(init == truth) < 0.8
    np.testing.assert_array_equal(out.assignments, truth)


# --------------------------------------------------------------------------------------------
# invariants and bookkeeping


@pytest.mark.parametrize("variant", CAO_VARIANTS)
def test_node_relabelling_permutes_the_output(variant):
    N, n = 5, 6
    K, pairs, truth = _problem(N, n, noise=0.6, seed=21, sigma2=0.1, quantize=True)
    rng = np.random.default_rng(4)
    init = _corrupt(truth, rng, frac=0.9, scramble=0.4)
    sig = [rng.permutation(n) for _ in range(N)]        # node u of graph g -> sig[g][u]
    # relabelled affinity: K'[(s_i u, s_j a), (s_i v, s_j b)] = K[(u, a), (v, b)]
    K2 = np.empty_like(K)
    for i in range(N):
        for j in range(N):
            idx = (sig[j][:, None] * n + sig[i][None, :]).reshape(-1)   # old (a, u) -> new
            K2[i, j][np.ix_(idx, idx)] = K[i, j]
    relabel = lambda m: np.array([sig[j][a[np.argsort(sig[i])]]       # noqa: E731
                                  for (i, j), a in zip(pairs, m)])
    out = cao(init, pairs, N, _scorer(K, pairs), variant=variant)
    out2 = cao(relabel(init), pairs, N, _scorer(K2, pairs), variant=variant)
    np.testing.assert_array_equal(out2.assignments, relabel(out.assignments))
    np.testing.assert_allclose(out2.scores, out.scores, rtol=0, atol=0)


def test_outcome_fields_and_scores():
    N, n = 6, 6
    K, pairs, truth = _problem(N, n, noise=0.4, seed=2)
    init = _corrupt(truth, np.random.default_rng(2), frac=0.8)
    score = _scorer(K, pairs)
    out = cao(init, pairs, N, score, variant="cao-c")
    assert isinstance(out, CAOOutcome) and out.variant == "cao-c"
    assert out.assignments.shape == (len(pairs), n) and out.assignments.dtype == np.int64
    np.testing.assert_allclose(out.scores, score(np.arange(len(pairs)), out.assignments),
                               rtol=1e-12)
    h = out.history
    assert len(h["score"]) == len(h["consistency"]) == out.n_iter + 1
    assert len(h["weight"]) == len(h["changed"]) == out.n_iter <= 6
    np.testing.assert_allclose(h["weight"][:3], [0.0, 0.0, 0.33], rtol=1e-12)
    np.testing.assert_allclose(h["score"][-1], out.scores.mean(), rtol=1e-12)
    assert out.converged == (h["changed"][-1] == 0)
    assert out.seconds > 0
    with pytest.raises(AttributeError):
        out.n_iter = 3                                     # frozen


def test_one_deduplicated_score_call_per_sweep():
    N, n = 6, 6
    K, pairs, truth = _problem(N, n, noise=0.4, seed=7)
    init = _corrupt(truth, np.random.default_rng(7), frac=0.8)
    calls = []
    out = cao(init, pairs, N, _scorer(K, pairs, calls), variant="cao-pc")
    assert len(calls) == 1 + out.n_iter                    # initial scores + one per sweep
    for p_idx, assign in calls[1:]:
        keys = np.column_stack([p_idx, assign])
        assert len(np.unique(keys, axis=0)) == len(keys)   # each candidate scored once
        assert len(keys) < len(pairs) * N


def test_distinct_rows_is_exact_even_on_hash_collisions():
    rng = np.random.default_rng(0)
    rows = np.array([rng.permutation(5) for _ in range(40)])[rng.integers(0, 40, 200)]
    pid = rng.integers(0, 3, 200)
    n_distinct = len(np.unique(np.column_stack([pid, rows]), axis=0))
    for mult in (None, np.ones(6, dtype=np.uint64)):     # ones: every permutation collides
        first, inverse = _cao._distinct_rows(pid, rows, mult)
        assert len(first) == n_distinct
        np.testing.assert_array_equal(rows[first][inverse], rows)
        np.testing.assert_array_equal(pid[first][inverse], pid)


@pytest.mark.parametrize("variant", CAO_VARIANTS)
def test_chunked_sweeps_give_the_same_output(variant, monkeypatch):
    N, n = 6, 7
    K, pairs, truth = _problem(N, n, noise=0.5, seed=8, sigma2=0.1)
    init = _corrupt(truth, np.random.default_rng(8), frac=0.9)
    whole = cao(init, pairs, N, _scorer(K, pairs), variant=variant)
    monkeypatch.setattr(_cao, "_CHUNK_ENTRIES", 4 * N * n)          # 4 pairs per chunk
    calls = []
    parts = cao(init, pairs, N, _scorer(K, pairs, calls), variant=variant)
    np.testing.assert_array_equal(parts.assignments, whole.assignments)
    np.testing.assert_array_equal(parts.history["changed"], whole.history["changed"])
    assert len(calls) == 1 + parts.n_iter * 4                      # 15 pairs -> 4 chunks


def test_two_graphs_and_zero_iterations():
    K, pairs, truth = _problem(2, 4, noise=0.0, seed=0)
    init = truth[:, ::-1].copy()
    out = cao(init, pairs, 2, _scorer(K, pairs))
    np.testing.assert_array_equal(out.assignments, init)   # only candidate: X_01 itself
    out = cao(init, pairs, 2, _scorer(K, pairs), max_iter=0)
    assert out.n_iter == 0 and not out.converged
    np.testing.assert_array_equal(out.assignments, init)


def test_progress_bar_runs(capsys):
    K, pairs, truth = _problem(4, 4, noise=0.0, seed=0)
    out = cao(truth, pairs, 4, _scorer(K, pairs), progress=True)
    assert out.converged


# --------------------------------------------------------------------------------------------
# bad input


def _small():
    K, pairs, truth = _problem(4, 4, noise=0.0, seed=0)
    return pairs, truth, _scorer(K, pairs)


def test_partial_view_graph_is_refused():
    pairs, truth, score = _small()
    with pytest.raises(ValueError, match=r"`pairs` must hold all 6 pairs of the 4 graphs.*"
                                         r"missing e.g. \(0, 1\)"):
        cao(truth[1:], pairs[1:], 4, score)


@pytest.mark.parametrize("bad, match", [
    (np.array([[1, 0], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]), r"i < j, got \(1, 0\) at row 0"),
    (np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [1, 4]]), r"indices in \[0, 4\)"),
    (np.array([[0, 1], [0, 1], [0, 3], [1, 2], [1, 3], [2, 3]]), "must not repeat a pair"),
    (np.zeros((6, 3), dtype=int), r"shape \(P, 2\)"),
])
def test_bad_pairs(bad, match):
    _, truth, score = _small()
    with pytest.raises(ValueError, match=match):
        cao(truth, bad, 4, score)
    with pytest.raises(TypeError, match="integer graph indices"):
        cao(truth, np.full((6, 2), 0.5), 4, score)


def test_bad_initial():
    pairs, truth, score = _small()
    with pytest.raises(ValueError, match=r"`initial` must have shape \(P, n\) with P=6"):
        cao(truth[:5], pairs, 4, score)
    bad = truth.copy()
    bad[2, 0] = bad[2, 1]
    with pytest.raises(ValueError, match=r"permutations of 0..3.*row 2"):
        cao(bad, pairs, 4, score)
    bad[2] = [-1, 0, 1, 2]
    with pytest.raises(ValueError, match="unmatched"):
        cao(bad, pairs, 4, score)
    with pytest.raises(TypeError, match="integer assignments"):
        cao(truth + 0.5, pairs, 4, score)


def test_bad_score_and_parameters():
    pairs, truth, score = _small()
    with pytest.raises(TypeError, match="`score` must be callable"):
        cao(truth, pairs, 4, None)
    with pytest.raises(ValueError, match=r"`score` must return an array of shape \(6,\)"):
        cao(truth, pairs, 4, lambda p, a: np.zeros(3))
    with pytest.raises(ValueError, match="`score` must return finite values"):
        cao(truth, pairs, 4, lambda p, a: np.full(len(p), np.nan))
    with pytest.raises(TypeError, match="`score` must return real values, got complex"):
        cao(truth, pairs, 4, lambda p, a: np.ones(len(p)) * 1j)     # ComplexWarning before
    with pytest.raises(TypeError, match="`score` must return real numbers"):
        cao(truth, pairs, 4, lambda p, a: ["x"] * len(p))
    with pytest.raises(ValueError, match="`variant` must be one of"):
        cao(truth, pairs, 4, score, variant="cdao")
    with pytest.raises(ValueError, match="`update`='sequential'.*got variant='cao-pc'"):
        cao(truth, pairs, 4, score, update="sequential")
    with pytest.raises(ValueError, match="`lambda_init` must lie in"):
        cao(truth, pairs, 4, score, lambda_init=1.5)
    with pytest.raises(ValueError, match="`lambda_step` must be >= 1"):
        cao(truth, pairs, 4, score, lambda_step=0.9)
    with pytest.raises(ValueError, match="`n_graphs` must be >= 2"):
        cao(truth[:0], pairs[:0], 1, score)
    with pytest.raises(TypeError, match="`max_iter` must be an int"):
        cao(truth, pairs, 4, score, max_iter=2.5)
    with pytest.raises(ValueError, match=r"`pairs` must hold graph indices in \[0, 3\)"):
        cao(truth, pairs, 3, score)


def test_sizes_beyond_what_can_run_are_refused():
    """max_iter = 2**70 built its schedule for ever; n_graphs = 2**70 reached numpy's
    "maximum allowed dimension"."""
    pairs = [(0, 1), (0, 2), (1, 2)]
    init = [[1, 0], [0, 1], [0, 1]]

    def score(p, a):
        return np.ones(len(p))

    with pytest.raises(ValueError, match=r"`max_iter` must be <= 100000"):
        cao(init, pairs, 3, score, max_iter=2**70)
    with pytest.raises(ValueError, match=r"`n_graphs` must be <= 10000000"):
        cao([[0, 1]] * 3, pairs, 2**70, score)


def test_progress_must_be_a_bool():
    """progress="no" showed a progress bar."""
    with pytest.raises(TypeError, match="`progress` must be a bool"):
        cao([[1, 0], [0, 1], [0, 1]], [(0, 1), (0, 2), (1, 2)], 3,
            lambda p, a: np.ones(len(p)), progress="no")
