"""Transitive alignments and assignment kernels (issue #12 items 3; ALGORITHMS.md §2)."""

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from transync.exceptions import DegenerateInputError
from transync.kernels import (
    Alignment,
    aligned_features,
    assignment_kernel,
    cosine_normalize,
    median_gamma,
    min_eigenvalue_ratio,
    pairwise_assignment_kernel,
    place_graphs,
    prune_by_size,
    relaxed_features,
    synchronize_alignments,
)


def _planted(N, n, rng):
    """Universe labels (N, n) and all pairwise permutations P_ij they induce."""
    labels = np.array([rng.permutation(n) for _ in range(N)])
    inv = np.argsort(labels, axis=1)                     # inv[j, slot] = node
    iu, ju = np.triu_indices(N, 1)
    pairs = np.column_stack([iu, ju])
    A = inv[ju[:, None], labels[iu]]                     # a[u] = node of j in u's slot
    return labels, pairs, A


def _random_features(N, f, rng, low=2, high=6):
    return [rng.random((int(rng.integers(low, high + 1)), f)) for _ in range(N)]


def _oa_assignments(Fp):
    """Pairwise-optimal (non-transitive) assignments: Hungarian on <F_i[u], F_j[v]>."""
    N, n, _ = Fp.shape
    iu, ju = np.triu_indices(N, 1)
    A = np.empty((iu.size, n), dtype=np.int64)
    for p, (i, j) in enumerate(zip(iu, ju)):
        r, c = linear_sum_assignment(Fp[i] @ Fp[j].T, maximize=True)
        A[p, r] = c
    return np.column_stack([iu, ju]), A


def _padded(feats, n):
    out = np.zeros((len(feats), n, feats[0].shape[1] + 1))
    for g, F in enumerate(feats):
        out[g, : len(F), :-1] = F
        out[g, : len(F), -1] = 1
    return out


# ---------------------------------------------------------------------------------------------
# synchronize_alignments
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("method", ["orthogonal", "spectral"])
def test_planted_alignment_is_recovered(method, rng):
    labels, pairs, A = _planted(7, 5, rng)
    al = synchronize_alignments(A, pairs, 7, n=5, method=method, rng=0)
    assert isinstance(al, Alignment) and al.labels.shape == (7, 5)
    assert al.n_graphs == 7 and al.n_universe == 5
    for p, (i, j) in enumerate(pairs):
        np.testing.assert_array_equal(al.pairwise(i, j), A[p])
    assert al.objective == A.size
    assert al.embedding is None


def test_corrupted_pairs_are_repaired_and_output_is_transitive(rng):
    labels, pairs, A = _planted(10, 6, rng)
    noisy = A.copy()
    bad = rng.choice(len(A), 6, replace=False)
    for p in bad:
        noisy[p] = rng.permutation(6)
    al = synchronize_alignments(noisy, pairs, 10, n=6, rng=0)
    for p, (i, j) in enumerate(pairs):
        np.testing.assert_array_equal(al.pairwise(i, j), A[p])
    # transitivity: P_ik = P_jk o P_ij
    np.testing.assert_array_equal(al.pairwise(0, 2), al.pairwise(1, 2)[al.pairwise(0, 1)])


def test_embedding_is_kept_on_request(rng):
    _, pairs, A = _planted(5, 4, rng)
    al = synchronize_alignments(A, pairs, 5, n=4, keep_embedding=True)
    Q = al.embedding
    assert Q.shape == (5, 4, 4)
    np.testing.assert_allclose(Q[0] @ Q[1].T, np.eye(4)[A[0]], atol=1e-6)
    assert "embedding" not in al.info


def test_one_graph_and_pair_order(rng):
    al = synchronize_alignments(np.zeros((0, 3), dtype=int), np.zeros((0, 2), dtype=int), 1, n=3)
    np.testing.assert_array_equal(al.labels, [[0, 1, 2]])
    # pairs given as (j, i) with the inverse map mean the same
    labels, pairs, A = _planted(4, 4, rng)
    inv = np.argsort(A, axis=1)
    al = synchronize_alignments(inv, pairs[:, ::-1], 4, n=4)
    for p, (i, j) in enumerate(pairs):
        np.testing.assert_array_equal(al.pairwise(i, j), A[p])


def test_synchronize_alignments_validation(rng):
    _, pairs, A = _planted(4, 3, rng)
    with pytest.raises(ValueError, match="permutations of range"):
        synchronize_alignments(np.where(A == 2, 1, A), pairs, 4, n=3)
    with pytest.raises(ValueError, match="shape"):
        synchronize_alignments(A[:, :2], pairs, 4, n=3)
    with pytest.raises(ValueError, match=r"i != j"):
        synchronize_alignments(A[:1], np.array([[1, 1]]), 4, n=3)
    with pytest.raises(ValueError, match=r"indices in \[0, 3\)"):
        synchronize_alignments(A, pairs, 3, n=3)
    with pytest.raises(ValueError, match="method"):
        synchronize_alignments(A, pairs, 4, n=3, method="birkhoff")
    with pytest.raises(TypeError, match="integers"):
        synchronize_alignments(A.astype(float), pairs, 4, n=3)
    with pytest.raises(ValueError, match="at least one pair"):
        synchronize_alignments(A[:0], pairs[:0], 4, n=3)
    # {0, 1} and {2, 3}: the synchronization's message offered disconnected='separate', an
    # option synchronize_alignments does not have
    with pytest.raises(DegenerateInputError, match=r"`pairs` must connect all 4 graphs, got 2 "
                                                   r"groups.*view_graph") as exc:
        synchronize_alignments(A[[0, 5]], pairs[[0, 5]], 4, n=3)
    assert "separate" not in str(exc.value)


def _planted_padded(sizes, n, rng):
    """Planted real-node slots and padded pairwise permutations whose matches into dummies are
    scrambled (real-to-real matches follow the truth)."""
    N = len(sizes)
    labels = np.array([rng.permutation(n) for _ in range(N)])   # real nodes: first sizes[g]
    _, pairs, A = _planted(N, n, np.random.default_rng(0))      # shapes only
    inv = np.argsort(labels, axis=1)
    A = inv[pairs[:, 1][:, None], labels[pairs[:, 0]]]
    for p, (i, j) in enumerate(pairs):
        free = np.flatnonzero(A[p] >= sizes[j])            # the nodes sent to dummies of j
        A[p, free] = rng.permutation(A[p, free])
    return labels, pairs, A


@pytest.mark.parametrize("method", ["orthogonal", "spectral"])
def test_real_only_synchronization_ignores_dummy_matches(method, rng):
    sizes = np.array([6, 4, 5, 6, 3, 5, 6, 4])
    labels, pairs, A = _planted_padded(sizes, 6, rng)
    al = synchronize_alignments(A, pairs, 8, n=6, sizes=sizes, method=method,
                                keep_embedding=True, rng=0)
    assert np.array_equal(np.sort(al.labels, axis=1), np.tile(np.arange(6), (8, 1)))
    for p, (i, j) in enumerate(pairs):
        got = al.pairwise(i, j)[: sizes[i]]
        want = A[p, : sizes[i]]
        real = want < sizes[j]
        np.testing.assert_array_equal(got[real], want[real])
    E = al.embedding
    assert E.shape == (8, 6, 6) and not E[1, 4:].any() and not E[4, 3:].any()
    # inductive placement with sizes: a copy of graph 1 (4 real nodes) comes back to its slots
    inv = np.argsort(al.labels, axis=1)
    new = inv[:, al.labels[1]][None]                       # consistent maps to every graph
    lab, Q = place_graphs(new, al.labels, sizes=[4], fitted_sizes=sizes, embedding=E,
                          method=method, degrees=al.info["degrees"],
                          eigenvalues=al.info["eigenvalues"])
    np.testing.assert_array_equal(lab[0, :4], al.labels[1, :4])
    assert not Q[0, 4:].any()
    np.testing.assert_allclose(Q[0], E[1], atol=1e-6)      # the values, not only the zeros
    with pytest.raises(ValueError, match="together"):
        place_graphs(new, al.labels, sizes=[4])
    with pytest.raises(ValueError, match="node counts"):
        synchronize_alignments(A, pairs, 8, n=6, sizes=sizes + 1)


# ---------------------------------------------------------------------------------------------
# aligned / relaxed features
# ---------------------------------------------------------------------------------------------

def test_aligned_features_by_hand(rng):
    feats = _random_features(4, 3, rng, 1, 5)
    n = 5
    labels = np.array([rng.permutation(n) for _ in range(4)])
    X = aligned_features(feats, labels, n)
    assert X.shape == (4, n, 4)
    for g, F in enumerate(feats):
        for u in range(n):
            want = np.r_[F[u], 1.0] if u < len(F) else np.zeros(4)
            np.testing.assert_array_equal(X[g, labels[g, u]], want)


def test_aligned_features_are_invariant_to_relabelling(rng):
    feats = _random_features(3, 2, rng)
    n = 6
    labels = np.array([rng.permutation(n) for _ in range(3)])
    X = aligned_features(feats, labels)
    # relabel graph 1's real nodes: node pi[u'] of the old graph becomes u'
    k = len(feats[1])
    pi = rng.permutation(k)
    feats2 = list(feats)
    feats2[1] = feats[1][pi]
    labels2 = labels.copy()
    labels2[1, :k] = labels[1, pi]
    np.testing.assert_array_equal(aligned_features(feats2, labels2), X)


def test_relaxed_features_with_hard_embedding_equal_aligned(rng):
    feats = _random_features(4, 2, rng)
    n = 6
    labels = np.array([rng.permutation(n) for _ in range(4)])
    E = np.eye(n)[labels]                                # Q_i[u] = e_{labels[i, u]}
    np.testing.assert_allclose(relaxed_features(feats, E), aligned_features(feats, labels))


def test_feature_validation(rng):
    feats = _random_features(2, 2, rng, 2, 3)
    labels = np.array([[0, 1, 2], [2, 1, 0]])
    with pytest.raises(ValueError, match="shape"):
        aligned_features(feats, labels[:1])
    with pytest.raises(ValueError, match="permutations"):
        aligned_features(feats, np.array([[0, 0, 1], [2, 1, 0]]))
    with pytest.raises(ValueError, match="more than the universe"):
        aligned_features([np.ones((4, 2)), feats[1]], labels)
    with pytest.raises(ValueError, match="columns"):
        aligned_features([feats[0], np.ones((2, 3))], labels)
    with pytest.raises(TypeError, match="sequence"):
        aligned_features("features", labels)
    with pytest.raises(TypeError, match="sequence"):               # padded: rows not all real
        aligned_features(np.ones((2, 3, 2)), labels)
    with pytest.raises(ValueError, match="one \\(n, d\\) block per graph"):
        relaxed_features(feats, np.zeros((3, 3, 3)))


# ---------------------------------------------------------------------------------------------
# kernels
# ---------------------------------------------------------------------------------------------

def test_linear_and_gaussian_kernels_by_hand(rng):
    feats = _random_features(5, 3, rng)
    n = 6
    labels = np.array([rng.permutation(n) for _ in range(5)])
    X = aligned_features(feats, labels, n)
    K = assignment_kernel(X, normalize=False)
    gamma = 0.7
    G = assignment_kernel(X, kernel="gaussian", gamma=gamma, normalize=False)
    for i in range(5):
        for j in range(5):
            assert K[i, j] == pytest.approx(float(np.sum(X[i] * X[j])), rel=1e-12)
            want = sum(X[i, a, -1] * X[j, a, -1]
                       * np.exp(-gamma * np.sum((X[i, a] - X[j, a]) ** 2)) for a in range(n))
            assert G[i, j] == pytest.approx(want, rel=1e-12, abs=1e-14)
    np.testing.assert_allclose(np.diag(G), [len(F) for F in feats])
    Kn = assignment_kernel(X)
    np.testing.assert_allclose(Kn, K / np.sqrt(np.outer(np.diag(K), np.diag(K))), rtol=1e-12)


@pytest.mark.parametrize("kernel", ["linear", "gaussian", "relaxed"])
def test_cross_gram_matches_the_full_gram(kernel, rng):
    feats = _random_features(7, 2, rng)
    n = 6
    labels = np.array([rng.permutation(n) for _ in range(7)])
    if kernel == "relaxed":
        Q = np.linalg.qr(rng.normal(size=(7, n, n)))[0]
        X = relaxed_features(feats, Q)
    else:
        X = aligned_features(feats, labels, n)
    gamma = 1.3 if kernel == "gaussian" else None
    full = assignment_kernel(X, kernel=kernel, gamma=gamma)
    cross = assignment_kernel(X[5:], X[:5], kernel=kernel, gamma=gamma)
    np.testing.assert_allclose(cross, full[5:, :5], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.diag(full), 1.0)


def _non_transitive_kernel(Fp, pairs, A, kernel, gamma=None):
    """The kernel built from pairwise maps P_ij directly (no synchronization), normalized."""
    N = Fp.shape[0]
    Fi, Fj = Fp[pairs[:, 0]], Fp[pairs[:, 1][:, None], A]          # (P, n, f + 1)
    if kernel == "linear":
        vals, diag = np.einsum("puf,puf->p", Fi, Fj), np.einsum("guf,guf->g", Fp, Fp)
    else:
        vals = (Fi[..., -1] * Fj[..., -1] * np.exp(-gamma * ((Fi - Fj) ** 2).sum(-1))).sum(1)
        diag = Fp[..., -1].sum(1)
    K = np.zeros((N, N))
    K[pairs[:, 0], pairs[:, 1]] = vals
    return cosine_normalize(K + K.T + np.diag(diag))


def test_transitive_kernels_are_psd_where_pairwise_optimal_is_not():
    """The same kernels built from the unsynchronized pairwise-optimal maps are indefinite."""
    rng = np.random.default_rng(7)
    feats = _random_features(12, 2, rng, 2, 5)
    n = max(len(F) for F in feats)
    Fp = _padded(feats, n)
    pairs, A = _oa_assignments(Fp)
    gamma = median_gamma(Fp)
    assert min_eigenvalue_ratio(_non_transitive_kernel(Fp, pairs, A, "linear")) < -5e-4
    assert min_eigenvalue_ratio(_non_transitive_kernel(Fp, pairs, A, "gaussian", gamma)) < -1e-3
    # the public non-transitive kernel is this one
    np.testing.assert_allclose(pairwise_assignment_kernel(feats, A, pairs),
                               _non_transitive_kernel(Fp, pairs, A, "linear"), atol=1e-13)
    np.testing.assert_allclose(pairwise_assignment_kernel(feats, A, pairs, kernel="gaussian",
                                                          gamma=gamma),
                               _non_transitive_kernel(Fp, pairs, A, "gaussian", gamma),
                               atol=1e-13)
    al = synchronize_alignments(A, pairs, 12, n=n, keep_embedding=True, rng=0)
    X = aligned_features(feats, al.labels)
    for K in (assignment_kernel(X), assignment_kernel(X, kernel="gaussian", gamma=gamma),
              assignment_kernel(relaxed_features(feats, al.embedding), kernel="relaxed")):
        np.testing.assert_array_equal(K, K.T)
        assert min_eigenvalue_ratio(K) >= -1e-9


@pytest.mark.parametrize("seed", range(3))
def test_kernels_psd_on_random_alignments(seed):
    rng = np.random.default_rng(100 + seed)
    feats = _random_features(20, 4, rng, 1, 9)
    labels = np.array([rng.permutation(9) for _ in range(20)])
    X = aligned_features(feats, labels)
    Q = np.linalg.qr(rng.normal(size=(20, 9, 9)))[0]
    for K in (assignment_kernel(X), assignment_kernel(X, kernel="gaussian"),
              assignment_kernel(relaxed_features(feats, Q), kernel="relaxed"),
              assignment_kernel(X, kernel="gaussian", gamma=50.0, normalize=False)):
        assert min_eigenvalue_ratio(K) >= -1e-9


# ---------------------------------------------------------------------------------------------
# pairwise_assignment_kernel (the non-transitive counterpart)
# ---------------------------------------------------------------------------------------------

def _random_maps(N, n, rng):
    pairs = np.column_stack(np.triu_indices(N, 1))
    return pairs, np.array([rng.permutation(n) for _ in range(len(pairs))])


@pytest.mark.parametrize("kernel", ["linear", "gaussian"])
def test_pairwise_assignment_kernel_by_brute_force(kernel, rng):
    """Entry by entry with loops over pairs and nodes: padded node u of i against the node
    of j it is mapped to; dummies are zero features with indicator 0."""
    feats = _random_features(6, 3, rng, 1, 5)
    n = 7
    pairs, A = _random_maps(6, n, rng)
    gamma = 0.8

    def node(g, u):
        F = feats[g]
        return np.r_[F[u], 1.0] if u < len(F) else np.zeros(F.shape[1] + 1)

    def k(x, y):
        if kernel == "linear":
            return float(x @ y)
        return float(x[-1] * y[-1] * np.exp(-gamma * ((x - y) ** 2).sum()))

    K = np.zeros((6, 6))
    for (i, j), a in zip(pairs, A):
        K[i, j] = K[j, i] = sum(k(node(i, u), node(j, a[u])) for u in range(n))
    for g in range(6):
        K[g, g] = sum(k(node(g, u), node(g, u)) for u in range(n))
    got = pairwise_assignment_kernel(feats, A, pairs, kernel=kernel,
                                     gamma=gamma if kernel == "gaussian" else None,
                                     normalize=False)
    np.testing.assert_allclose(got, K, rtol=1e-12)
    normed = pairwise_assignment_kernel(feats, A, pairs, kernel=kernel,
                                        gamma=gamma if kernel == "gaussian" else None)
    np.testing.assert_allclose(normed, cosine_normalize(K), rtol=1e-12)
    np.testing.assert_array_equal(normed, normed.T)


@pytest.mark.parametrize("kernel", ["linear", "gaussian"])
def test_pairwise_assignment_kernel_on_transitive_maps_is_the_transitive_kernel(kernel, rng):
    """Maps induced by one labelling: the pairwise kernel is the assignment kernel of the
    aligned features, default Gaussian widths included (the same median rule)."""
    feats = _random_features(9, 2, rng, 2, 6)
    labels, pairs, A = _planted(9, 6, rng)
    X = aligned_features(feats, labels)
    np.testing.assert_allclose(pairwise_assignment_kernel(feats, A, pairs, kernel=kernel),
                               assignment_kernel(X, kernel=kernel), rtol=1e-12)
    assert min_eigenvalue_ratio(pairwise_assignment_kernel(feats, A, pairs, kernel=kernel)) \
        >= -1e-9


def test_pairwise_assignment_kernel_ignores_pair_order_and_orientation(rng):
    feats = _random_features(7, 2, rng, 2, 5)
    pairs, A = _random_maps(7, 5, rng)
    K = pairwise_assignment_kernel(feats, A, pairs, kernel="gaussian")
    order = rng.permutation(len(pairs))
    flip = rng.random(len(pairs)) < 0.5
    p2, A2 = pairs[order].copy(), A[order].copy()
    p2[flip] = p2[flip, ::-1]
    A2[flip] = np.argsort(A2[flip], axis=1)                  # the inverse maps
    np.testing.assert_allclose(pairwise_assignment_kernel(feats, A2, p2, kernel="gaussian"), K,
                               rtol=1e-12)


def test_pairwise_assignment_kernel_validation(rng):
    feats = _random_features(4, 2, rng, 2, 3)
    pairs, A = _random_maps(4, 3, rng)
    with pytest.raises(ValueError, match="all 6 pairs of the 4 graphs.*missing e.g. \\(2, 3\\)"):
        pairwise_assignment_kernel(feats, A[:-1], pairs[:-1])
    with pytest.raises(ValueError, match=r"not repeat a pair.*\(1, 0\) at row 5 after \(0, 1\)"):
        pairwise_assignment_kernel(feats, A, np.r_[pairs[:5], [[1, 0]]])
    with pytest.raises(ValueError, match=r"i != j, got \(3, 3\) at row 2"):
        pairwise_assignment_kernel(feats, A, np.r_[pairs[:2], [[3, 3]], pairs[3:]])
    with pytest.raises(ValueError, match=r"graph indices in \[0, 4\), got range"):
        pairwise_assignment_kernel(feats, A, np.r_[pairs[:5], [[2, 4]]])
    with pytest.raises(ValueError, match=r"shape \(P, 2\)"):
        pairwise_assignment_kernel(feats, A, pairs[:, :1])
    with pytest.raises(ValueError, match=r"\(6, n\), one row per pair.*\(5, 3\)"):
        pairwise_assignment_kernel(feats, A[:5], pairs)
    bad = A.copy()
    bad[2] = [0, 0, 1]
    with pytest.raises(ValueError, match="row 2 is not one"):
        pairwise_assignment_kernel(feats, bad, pairs)
    feats = [np.ones((2, 2))] * 4
    feats[1] = np.ones((3, 2))
    with pytest.raises(ValueError, match=r"features\[1\]` has 3 nodes, more than.*n=2"):
        pairwise_assignment_kernel(feats, np.tile([1, 0], (6, 1)), pairs)
    with pytest.raises(TypeError, match="assignments"):
        pairwise_assignment_kernel(feats, A.astype(float), pairs)
    with pytest.raises(ValueError, match="kernel"):
        pairwise_assignment_kernel(feats, A, pairs, kernel="relaxed")
    with pytest.raises(ValueError, match="gamma"):
        pairwise_assignment_kernel(feats, A, pairs, gamma=1.0)
    with pytest.raises(ValueError, match="gamma"):
        pairwise_assignment_kernel(feats, A, pairs, kernel="gaussian", gamma=0.0)
    with pytest.raises(TypeError, match="normalize"):
        pairwise_assignment_kernel(feats, A, pairs, normalize=1)
    # one graph: no pairs, the diagonal only
    K = pairwise_assignment_kernel(feats[:1], np.zeros((0, 3), int), np.zeros((0, 2), int))
    np.testing.assert_allclose(K, [[1.0]], rtol=1e-15)


def test_median_gamma_rule(rng):
    feats = _random_features(6, 2, rng)
    X = aligned_features(feats, np.array([rng.permutation(6) for _ in range(6)]))
    g = median_gamma(X)
    assert g > 0 and g == median_gamma(X)
    both = X[:, :, -1][:, None] * X[:, :, -1][None]
    d2 = ((X[:, None] - X[None]) ** 2).sum(-1)
    iu, ju = np.triu_indices(6, 1)
    assert g == pytest.approx(1 / np.median(d2[iu, ju][both[iu, ju] > 0]))
    same = aligned_features([np.ones((2, 1))] * 3, np.tile(np.arange(2), (3, 1)))
    assert median_gamma(same) == 1.0


def test_assignment_kernel_validation(rng):
    X = aligned_features(_random_features(3, 2, rng, 2, 3), np.tile(np.arange(3), (3, 1)))
    with pytest.raises(ValueError, match="kernel"):
        assignment_kernel(X, kernel="rbf")
    with pytest.raises(ValueError, match="gamma"):
        assignment_kernel(X, gamma=1.0)
    with pytest.raises(ValueError, match="gamma"):
        assignment_kernel(X, kernel="gaussian", gamma=-1.0)
    with pytest.raises(ValueError, match="other"):
        assignment_kernel(X, X[:, :2])
    with pytest.raises(ValueError, match="dimensions"):
        assignment_kernel(X[0])
    with pytest.raises(ValueError, match=r"`aligned` must have shape \(N, n, f\) with N, n, "
                                         r"f >= 1"):
        assignment_kernel(np.zeros((0, 3, 2)))                  # was a reshape error
    with pytest.raises(ValueError, match="`other` must hold at least one graph"):
        assignment_kernel(X, X[:0])
    with pytest.raises(ValueError, match="the values of `other` are too large"):
        assignment_kernel(X, np.full_like(X, 1e200))           # was named `aligned`
    # gamma = 1e300 is allowed by the bound the message states (was refused "at most 1e+300,
    # got 1e+300": the bound was computed as 1 / 1e-300, one ulp below)
    K = assignment_kernel(X, kernel="gaussian", gamma=1e300)
    assert np.isfinite(K).all()
    with pytest.raises(ValueError, match=r"`gamma` must be at most 1e\+300"):
        assignment_kernel(X, kernel="gaussian", gamma=1.01e300)


# ---------------------------------------------------------------------------------------------
# inductive placement
# ---------------------------------------------------------------------------------------------

def test_place_graphs_recovers_fitted_labels(rng):
    labels, pairs, A = _planted(6, 5, rng)
    al = synchronize_alignments(A, pairs, 6, n=5, keep_embedding=True)
    inv = np.argsort(al.labels, axis=1)
    # copies of fitted graphs 2 and 4, matched (consistently) to every fitted graph
    new = np.stack([inv[:, al.labels[t]] for t in (2, 4)])          # (2, N, n)
    lab, Q = place_graphs(new, al.labels, embedding=al.embedding)
    np.testing.assert_array_equal(lab, al.labels[[2, 4]])
    np.testing.assert_allclose(Q, al.embedding[[2, 4]], atol=1e-8)
    # a relabelled copy: node u' of the new graph is node pi[u'] of graph 2
    pi = rng.permutation(5)
    lab, _ = place_graphs(new[:1, :, pi], al.labels)
    np.testing.assert_array_equal(lab[0], al.labels[2, pi])
    with pytest.raises(ValueError, match="labels"):
        place_graphs(new, al.labels[:3])


def _copy_of(t, A, pairs, N, n):
    """The maps of a copy of fitted graph ``t`` to every fitted graph: ``t``'s observed maps
    (inverted where ``t`` is the second graph of the pair) and the identity to ``t`` itself."""
    new = np.empty((N, n), dtype=np.int64)
    for p, (i, j) in enumerate(pairs):
        if i == t:
            new[j] = A[p]
        if j == t:
            new[i] = np.argsort(A[p])
    new[t] = np.arange(n)
    return new


@pytest.mark.parametrize("real_only", [False, True])
@pytest.mark.parametrize("method", ["orthogonal", "spectral"])
def test_copies_are_placed_on_their_originals_on_noisy_input(method, real_only, rng):
    """Labels: the refined fitted labels are a fixed point of the placement rule (both methods).
    Embedding: spectral placement solves the degree-normalized eigenvector equation, exact for a
    copy; orthogonal placement is one more polar block update, exact at the polar fixed point."""
    N, n = 10, 6
    sizes = rng.integers(3, n + 1, N)
    sizes[0] = n
    _, pairs, A = _planted(N, n, rng)
    for p in rng.choice(len(A), 8, replace=False):         # inconsistent input
        A[p] = rng.permutation(n)
    sz = sizes if real_only else None
    al = synchronize_alignments(A, pairs, N, n=n, sizes=sz, method=method, keep_embedding=True,
                                tol=1e-12, max_iter=2000, rng=0)
    ts = [0, 3, 7]
    new = np.stack([_copy_of(t, A, pairs, N, n) for t in ts])
    kw = dict(sizes=sizes[ts], fitted_sizes=sizes) if real_only else {}
    lab, Q = place_graphs(new, al.labels, embedding=al.embedding, method=method,
                          degrees=al.info["degrees"], eigenvalues=al.info["eigenvalues"], **kw)
    for r, t in enumerate(ts):
        k = sizes[t] if real_only else n
        np.testing.assert_array_equal(lab[r, :k], al.labels[t, :k])
    np.testing.assert_allclose(Q, al.embedding[ts], atol=1e-9 if method == "spectral" else 1e-5)


def test_label_mismatches_are_not_synchronized_nor_voted(rng):
    """A real-to-real match between different node labels is dropped from the synchronization
    (objective, degrees) and from the placement vote."""
    N, n = 4, 4
    _, pairs, A = _planted(N, n, rng)
    sizes = np.full(N, n)
    node_labels = [np.zeros(n, dtype=np.int64) for _ in range(N)]
    full = synchronize_alignments(A, pairs, N, n=n, sizes=sizes, node_labels=node_labels)
    assert full.objective == pairs.shape[0] * n            # consistent: every match kept
    node_labels[3] = np.r_[1, np.zeros(n - 1, dtype=np.int64)]   # node 0 of graph 3 differs
    al = synchronize_alignments(A, pairs, N, n=n, sizes=sizes, node_labels=node_labels)
    assert al.objective == full.objective - (pairs[:, 1] == 3).sum()
    assert al.info["degrees"][3, 0] == 1.0                 # no kept correspondence
    np.testing.assert_array_equal(al.info["degrees"][3, 1:], N)
    # placement: a copy of graph 3 votes only with its same-label nodes
    new = _copy_of(3, A, pairs, N, n)[None]
    lab, _ = place_graphs(new, al.labels, sizes=[n], fitted_sizes=sizes,
                          node_labels=[node_labels[3]], fitted_node_labels=node_labels)
    np.testing.assert_array_equal(lab[0], al.labels[3])
    # labels seen nowhere: no vote at all, every slot scores 0 (identity, ties by index)
    lab, _ = place_graphs(new, al.labels, sizes=[n], fitted_sizes=sizes,
                          node_labels=[np.full(n, 9)], fitted_node_labels=node_labels)
    np.testing.assert_array_equal(lab[0], np.arange(n))
    assert not np.array_equal(al.labels[3], np.arange(n))
    with pytest.raises(ValueError, match="needs `sizes`"):
        synchronize_alignments(A, pairs, N, n=n, node_labels=node_labels)
    with pytest.raises(ValueError, match="together"):
        place_graphs(new, al.labels, sizes=[n], fitted_sizes=sizes, node_labels=node_labels)
    with pytest.raises(TypeError, match=r"`node_labels\[1\]` must hold integer labels"):
        synchronize_alignments(A, pairs, N, n=n, sizes=sizes,
                               node_labels=[np.zeros(n, dtype=int), np.zeros(n) + 0.5] * 2)
    with pytest.raises(ValueError, match="eigenvalues"):
        place_graphs(new, al.labels, embedding=np.zeros((N, n, n)), method="spectral")
    with pytest.raises(ValueError, match="refine"):
        synchronize_alignments(A, pairs, N, n=n, refine=-1)


# ---------------------------------------------------------------------------------------------
# pruning
# ---------------------------------------------------------------------------------------------

def test_prune_by_size():
    sizes = np.array([10] * 18 + [11, 60, 12, 12, 9])
    y = np.array([0] * 12 + [1] * 8 + [2] * 3)
    keep, rule = prune_by_size(sizes, y, quantile=0.95, min_class_size=4)
    cap = np.floor(np.quantile(sizes, 0.95))
    assert cap == 12
    np.testing.assert_array_equal(keep, np.flatnonzero((sizes <= cap) & (y < 2)))
    assert "n_i <= 12" in rule and "dropped classes [2]" in rule and "2/3 classes" in rule
    keep, rule = prune_by_size(sizes, y, quantile=None, max_nodes=11, min_class_size=0)
    np.testing.assert_array_equal(keep, np.flatnonzero(sizes <= 11))
    assert "max_nodes 11" in rule
    keep, rule = prune_by_size(sizes, y, quantile=None, min_class_size=0)
    assert keep.size == sizes.size and "no size cap" in rule


def test_prune_by_size_validation():
    with pytest.raises(ValueError, match="`y`"):
        prune_by_size([3, 4], [0])
    with pytest.raises(ValueError, match="quantile"):
        prune_by_size([3, 4], [0, 1], quantile=1.5)
    with pytest.raises(ValueError, match="positive"):
        prune_by_size([0, 4], [0, 1])
    with pytest.raises(ValueError, match=r"the size pruning keeps no graph: every class has "
                                         r"fewer than 5 graphs with n_i <= 3 \(0.95 size "):
        prune_by_size([3, 4], [0, 1], min_class_size=5)
    with pytest.raises(TypeError, match="max_nodes"):
        prune_by_size([3, 4], [0, 1], max_nodes=2.5)


def test_gaussian_gram_is_exact_far_from_the_origin(rng):
    """The per-slot Gaussian Gram uses the expansion ||x||^2 + ||y||^2 - 2<x, y>; its rounding
    grows with the norms. Features 1e6 from the origin (spread 1) must still give the direct
    form's kernel (the slots are centered first); uncentered, the error was ~1e-4."""
    feats = [F + 1e6 for F in _random_features(6, 3, rng)]
    n = max(len(F) for F in feats)
    labels = np.array([np.r_[rng.permutation(len(F)), -np.ones(n - len(F), int)]
                       for F in feats])
    labels = np.array([np.argsort(np.where(lab < 0, n + np.arange(n), lab)) for lab in labels])
    X = aligned_features(feats, labels)
    gamma = 0.7
    got = assignment_kernel(X, kernel="gaussian", gamma=gamma, normalize=False)
    d = X[..., -1]
    want = np.einsum("ia,ja,ija->ij", d, d,
                     np.exp(-gamma * ((X[:, None] - X[None, :]) ** 2).sum(-1)))
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("matcher", ["node", "sm", "rrwm"])
def test_gaussian_kernel_of_identical_graphs_is_psd(matcher):
    """Found by a contract hunt: two copies of one graph have node features equal up to
    rounding (1e-16); the median width was that rounding (1e-30), the Gaussian of width 1e30
    ran on the Gram expansion's noise, and the cosine-normalized Gram was [[1, 1.67], [1.67,
    1]]. Rounding-level distances are 0 now: the copies are identical, K is all ones."""
    from transync.graphs import Graph
    from transync.kernels import TransitiveAssignmentKernel

    A = np.array([[0, 0, 1, 1, 1], [0, 0, 1, 1, 1], [1, 1, 0, 0, 1], [1, 1, 0, 0, 1],
                  [1, 1, 1, 1, 0]], float)
    est = TransitiveAssignmentKernel(matcher=matcher, kernel="gaussian", random_state=0)
    K = est.fit_transform([Graph(A), Graph(A)])
    np.testing.assert_allclose(K, np.ones((2, 2)), atol=1e-12)
    assert est.gamma_ == 1.0


def test_median_gamma_sampling_seed_is_checked_by_name(rng):
    """Above its sample size median_gamma draws pairs with ``rng``: a bad seed is named (numpy's
    own message named nothing), a good one reproduces."""
    X = aligned_features(_random_features(400, 2, rng), np.tile(np.arange(6), (400, 1)))
    assert median_gamma(X, rng=3) == median_gamma(X, rng=3)
    with pytest.raises(ValueError, match="`rng` must be None, a non-negative int seed"):
        median_gamma(X, rng=-1)


def test_alignment_checks_its_labels_and_indices():
    """`pairwise(0, 9)` and `pairwise(0.5, 0)` raised raw IndexErrors, `pairwise(-1, 0)`
    silently returned the last graph's map, and `Alignment(labels=[[0, 1]], ...)` failed later
    with an AttributeError."""
    from transync.kernels import Alignment

    al = Alignment(labels=[[0, 1, 2], [2, 0, 1]], embedding=None, objective=0.0)
    assert al.n_graphs == 2 and al.pairwise(0, 1).tolist() == [1, 2, 0]
    for i, j, exc, match in [(0, 9, ValueError, "`j` must be <= 1, got 9"),
                             (-1, 0, ValueError, "`i` must be >= 0, got -1"),
                             (0.5, 0, TypeError, "`i` must be an int")]:
        with pytest.raises(exc, match=match):
            al.pairwise(i, j)
    with pytest.raises(ValueError, match=r"permutation of range\(3\) in every row, row 1"):
        Alignment(labels=[[0, 1, 2], [0, 0, 1]], embedding=None, objective=0.0)
    with pytest.raises(ValueError, match=r"`embedding` must have shape \(2, 3, k\)"):
        Alignment(labels=[[0, 1, 2], [2, 0, 1]], embedding=np.zeros((2, 2, 3)), objective=0.0)
