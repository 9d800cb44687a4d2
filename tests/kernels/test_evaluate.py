"""Tests of the kernel evaluation protocol (issue #12, item 6): normalization, spectra, CV."""

import numpy as np
import pytest
from scipy.stats import ttest_rel

from transync.kernels import _evaluate as ev
from transync.kernels._evaluate import (
    CVResult,
    cosine_normalize,
    min_eigenvalue_ratio,
    paired_ttest,
    repeated_cv,
    spectrum,
)


def _gram(rng, n=30, f=4, shift=None, y=None):
    X = rng.normal(size=(n, f))
    if shift is not None:
        X = X + shift * y[:, None]
    return X @ X.T


# --------------------------------------------------------------------------- cosine_normalize

def test_cosine_normalize_unit_diagonal_and_psd():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(12, 3))
    K = X @ X.T
    Kn = cosine_normalize(K)
    np.testing.assert_allclose(np.diag(Kn), 1.0, rtol=0, atol=1e-12)
    Xn = X / np.linalg.norm(X, axis=1, keepdims=True)
    np.testing.assert_allclose(Kn, Xn @ Xn.T, rtol=0, atol=1e-12)
    assert spectrum(Kn)[0] >= -1e-12


def test_cosine_normalize_zero_diagonal_gives_zero_row():
    X = np.array([[1.0, 0.0], [0.0, 0.0], [2.0, 2.0]])
    Kn = cosine_normalize(X @ X.T)
    np.testing.assert_array_equal(Kn[1], 0.0)
    np.testing.assert_array_equal(Kn[:, 1], 0.0)
    assert np.all(np.isfinite(Kn))
    np.testing.assert_allclose(Kn[0, 2], 1 / np.sqrt(2), rtol=1e-12)


def test_cosine_normalize_rectangular_matches_square_block():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(9, 3))
    K = X @ X.T
    full = cosine_normalize(K)
    d = np.diag(K)
    rect = cosine_normalize(K[6:, :6], diag_rows=d[6:], diag_cols=d[:6])
    np.testing.assert_allclose(rect, full[6:, :6], rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("kwargs, match", [
    (dict(K=np.ones((2, 3))), "square"),
    (dict(K=np.array([[np.nan, 0], [0, 1.0]])), "finite"),
    (dict(K=np.array([[-1.0, 0], [0, 1.0]])), "non-negative"),
    (dict(K=np.ones((2, 2)), diag_rows=[1.0, 1.0]), "together"),
    (dict(K=np.ones((2, 3)), diag_rows=[1.0, 1.0], diag_cols=[1.0]), "lengths"),
    (dict(K=np.ones((1, 2)), diag_rows=[1.0], diag_cols=[1.0, -2.0]), "diag_cols"),
])
def test_cosine_normalize_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        cosine_normalize(**kwargs)


# --------------------------------------------------------------------------- spectra

def test_spectrum_and_ratio():
    K = np.array([[2.0, 1.0], [1.0, 2.0]])
    np.testing.assert_allclose(spectrum(K), [1.0, 3.0], rtol=1e-12)
    assert min_eigenvalue_ratio(K) == pytest.approx(1 / 3)
    assert min_eigenvalue_ratio(np.zeros((3, 3))) == 0.0
    # non-symmetric input: the symmetric part is used
    np.testing.assert_allclose(spectrum(np.array([[0.0, 2.0], [0.0, 0.0]])), [-1.0, 1.0])
    with pytest.raises(ValueError, match="positive eigenvalue"):
        min_eigenvalue_ratio(-np.eye(2))
    with pytest.raises(ValueError, match="square"):
        spectrum(np.ones((2, 3)))


# --------------------------------------------------------------------------- repeated_cv

def test_repeated_cv_planted_separable_kernel_is_perfect():
    rng = np.random.default_rng(2)
    y = np.repeat([0, 1, 2], 12)
    K = cosine_normalize(_gram(rng, 36, 3) + 50.0 * (y[:, None] == y[None, :]))
    res = repeated_cv(K, y, n_splits=4, n_repeats=2, C_grid=[1.0, 10.0])
    assert isinstance(res, CVResult)
    assert res.accuracies.shape == (2, 4) and res.chosen_C.shape == (2, 4)
    assert res.mean == 1.0 and res.std == 0.0
    np.testing.assert_array_equal(res.per_repeat, res.accuracies.mean(1))
    assert set(np.unique(res.chosen_C)) <= {1.0, 10.0}


def test_repeated_cv_folds_identical_for_every_kernel_and_stratified():
    rng = np.random.default_rng(3)
    y = np.array([0] * 14 + [1] * 11 + [2] * 10)
    a = repeated_cv(_gram(rng, 35), y, n_splits=5, n_repeats=3, C_grid=[1.0])
    b = repeated_cv(cosine_normalize(_gram(rng, 35, 6)), y, n_splits=5, n_repeats=3,
                    C_grid=[0.1, 1.0])
    np.testing.assert_array_equal(a.folds, b.folds)
    assert a.fingerprint == b.fingerprint
    for r in range(3):
        assert not np.array_equal(a.folds[0], a.folds[r]) or r == 0
        for c in np.unique(y):       # each class spread evenly over the folds
            counts = np.bincount(a.folds[r][y == c], minlength=5)
            assert counts.max() - counts.min() <= 1
        sizes = np.bincount(a.folds[r], minlength=5)
        assert sizes.max() - sizes.min() <= 1
    c = repeated_cv(_gram(rng, 35), y, n_splits=5, n_repeats=3, C_grid=[1.0], random_state=1)
    assert c.fingerprint != a.fingerprint


def test_repeated_cv_selects_C_on_training_folds_only(monkeypatch):
    """No leakage: the inner selection of C receives exactly K[train, train] and y[train]."""
    rng = np.random.default_rng(4)
    y = np.repeat([0, 1], 15)
    K = cosine_normalize(_gram(rng, 30, 3, shift=1.0, y=y))
    seen = []
    real = ev._select_C

    def spy(K_train, y_train, *args):
        seen.append((K_train[0].copy(), y_train.copy()))
        return real(K_train, y_train, *args)

    monkeypatch.setattr(ev, "_select_C", spy)
    res = repeated_cv(K, y, n_splits=5, n_repeats=2, C_grid=[0.01, 1.0, 100.0])
    assert len(seen) == 10
    for (K_tr, y_tr), (r, k) in zip(seen, np.ndindex(2, 5)):
        train = np.flatnonzero(res.folds[r] != k)
        np.testing.assert_array_equal(K_tr, K[np.ix_(train, train)])
        np.testing.assert_array_equal(y_tr, y[train])


def test_repeated_cv_choice_of_C_ignores_test_fold_entries():
    """A kernel that would leak: the test fold's rows carry the labels, C must not react."""
    rng = np.random.default_rng(5)
    y = np.repeat([0, 1], 15)
    X = rng.normal(size=(30, 4))
    base = repeated_cv(X @ X.T, y, n_splits=5, n_repeats=1, C_grid=[0.001, 0.1, 10.0])
    test = base.folds[0] == 0
    X2 = X.copy()
    X2[test] = 5.0 * (2 * y[test, None] - 1)      # test rows now perfectly separable
    leaky = repeated_cv(X2 @ X2.T, y, n_splits=5, n_repeats=1, C_grid=[0.001, 0.1, 10.0])
    assert leaky.chosen_C[0, 0] == base.chosen_C[0, 0]


def test_repeated_cv_validation():
    K = np.eye(20)
    y = np.array([0] * 16 + [1] * 4)
    with pytest.raises(ValueError, match="at least n_splits=5 samples.*class.*\\[1\\]"):
        repeated_cv(K, y, n_splits=5)
    with pytest.raises(ValueError, match="shape \\(20,\\)"):
        repeated_cv(K, y[:-1])
    with pytest.raises(ValueError, match="2 classes"):
        repeated_cv(K, np.zeros(20))
    with pytest.raises(ValueError, match="C_grid"):
        repeated_cv(K, np.repeat([0, 1], 10), n_splits=2, C_grid=[0.0, 1.0])
    with pytest.raises(ValueError, match="inner folds"):
        repeated_cv(K, np.repeat([0, 1], 10), n_splits=2, inner_splits=8)
    with pytest.raises(ValueError, match="square"):
        repeated_cv(np.ones((20, 3)), np.repeat([0, 1], 10))
    with pytest.raises(TypeError, match="n_splits"):
        repeated_cv(K, np.repeat([0, 1], 10), n_splits=2.5)
    # checked like every other option (accepted before); 10**9 repeats spawned 10**9 seeds
    y2 = np.repeat([0, 1], 10)
    with pytest.raises(TypeError, match="`progress` must be a bool, got str 'x'"):
        repeated_cv(K, y2, n_splits=2, progress="x")
    with pytest.raises(ValueError, match="`n_repeats` must be <= 1000"):
        repeated_cv(K, y2, n_splits=2, n_repeats=10**9)
    with pytest.raises(ValueError, match="`y` must hold class labels, got NaN"):
        repeated_cv(K, np.where(y2 == 1, np.nan, 0.0), n_splits=2)    # NaN was a class


def test_repeated_cv_refuses_kernels_libsvm_cannot_fit():
    """An asymmetric kernel made libsvm cycle forever, a huge one made it crawl (scaling K is
    scaling C) or fail with sklearn's "dual coefficients not finite": both refused by name,
    before any fit; round-off asymmetry passes."""
    rng = np.random.default_rng(0)
    X = rng.random((20, 5))
    y = [0, 1] * 10
    asym = X @ X.T + np.triu(np.ones((20, 20)))
    with pytest.raises(ValueError, match=r"`K` must be symmetric.*K\[\d+, \d+\] = "):
        repeated_cv(asym, y, n_splits=3, n_repeats=1, C_grid=[1.0])
    with pytest.raises(ValueError, match=r"`K\[1\]` must be symmetric"):
        repeated_cv(np.stack([X @ X.T, asym]), y, n_splits=3, n_repeats=1, C_grid=[1.0])
    for scale, C_grid in ((1e300, None), (1e10, [1e3]), (1e15, [1.0])):
        with pytest.raises(ValueError, match="`K` is too large for the SVM.*cosine_normalize"):
            repeated_cv(X @ X.T * scale, y, n_splits=3, n_repeats=1, C_grid=C_grid)
    K = X @ X.T
    K = K + 1e-14 * rng.standard_normal(K.shape)        # round-off asymmetry
    assert 0 <= repeated_cv(K * 1e8, y, n_splits=3, n_repeats=1, C_grid=[1e3]).mean <= 1


# --------------------------------------------------------------------------- paired_ttest

def test_paired_ttest_matches_scipy_and_checks_folds():
    rng = np.random.default_rng(6)
    y = np.repeat([0, 1], 15)
    good = cosine_normalize(_gram(rng, 30, 3, shift=1.2, y=y))
    bad = cosine_normalize(_gram(rng, 30, 3))
    a = repeated_cv(good, y, n_splits=3, n_repeats=4, C_grid=[1.0])
    b = repeated_cv(bad, y, n_splits=3, n_repeats=4, C_grid=[1.0])
    t, p = paired_ttest(a, b, over="repeats")
    ref = ttest_rel(a.per_repeat, b.per_repeat)
    assert t == pytest.approx(ref.statistic) and p == pytest.approx(ref.pvalue)
    assert t > 0
    # default: Nadeau-Bengio's corrected resampled test, by its formula; never more significant
    # than the plain test over the same fold differences
    from scipy.stats import t as student_t

    d = (a.accuracies - b.accuracies).ravel()
    tc = d.mean() / np.sqrt((1 / d.size + 1 / (3 - 1)) * d.var(ddof=1))
    t3, p3 = paired_ttest(a, b)
    assert t3 == pytest.approx(tc) and p3 == pytest.approx(2 * student_t.sf(abs(tc), d.size - 1))
    assert p3 >= ttest_rel(a.accuracies.ravel(), b.accuracies.ravel()).pvalue
    t2, p2 = paired_ttest(a, b, over="folds")
    ref2 = ttest_rel(a.accuracies.ravel(), b.accuracies.ravel())
    assert t2 == pytest.approx(ref2.statistic) and p2 == pytest.approx(ref2.pvalue)
    assert paired_ttest(a, a) == (0.0, 1.0)
    other = repeated_cv(bad, y, n_splits=3, n_repeats=4, C_grid=[1.0], random_state=7)
    with pytest.raises(ValueError, match="same folds"):
        paired_ttest(a, other)
    with pytest.raises(TypeError, match="CVResult"):
        paired_ttest(a, a.per_repeat)
    with pytest.raises(ValueError, match="over"):
        paired_ttest(a, b, over="samples")


@pytest.mark.dataset("tu")
def test_repeated_cv_on_mutag_simple_counts():
    """Real data: node/edge counts and a label histogram classify MUTAG above the majority."""
    from transync.datasets import load_tu

    ds = load_tu("MUTAG")
    X = np.stack([np.r_[g.adjacency.sum() / 2, g.n_nodes, np.bincount(g.node_labels, minlength=7)]
                  for g in ds.graphs])
    res = repeated_cv(cosine_normalize(X @ X.T), ds.y, n_splits=10, n_repeats=1,
                      C_grid=[1.0, 100.0])
    assert res.mean > np.mean(ds.y == 1) + 0.1


def test_repeated_cv_selects_the_kernel_jointly_with_C():
    """A stack of candidate kernels (e.g. WL for several h): the informative one is picked."""
    rng = np.random.default_rng(8)
    y = np.repeat([0, 1], 15)
    noise = cosine_normalize(_gram(rng, 30, 5))
    good = cosine_normalize(_gram(rng, 30, 3, shift=3.0, y=y))
    res = repeated_cv(np.stack([noise, good]), y, n_splits=3, n_repeats=2, C_grid=[1.0])
    np.testing.assert_array_equal(res.chosen_kernel, 1)
    single = repeated_cv(good, y, n_splits=3, n_repeats=2, C_grid=[1.0])
    np.testing.assert_array_equal(res.accuracies, single.accuracies)
    np.testing.assert_array_equal(single.chosen_kernel, 0)
    with pytest.raises(ValueError, match="stack of square"):
        repeated_cv(np.zeros((2, 30, 29)), y)


def test_cosine_normalize_tiny_self_similarities():
    """Self-similarities near the smallest float64 (the outer product of their inverse square
    roots overflows): still the cosine, exactly symmetric, no warning."""
    import warnings

    x = np.array([[1e-160], [2e-160], [3e-160]])
    K = x @ x.T                                     # entries ~1e-320, subnormal
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Kn = cosine_normalize(K)
    np.testing.assert_allclose(Kn, 1.0, rtol=1e-6)
    np.testing.assert_array_equal(Kn, Kn.T)


def test_exact_ties_go_to_the_first_kernel(monkeypatch):
    # inner folds of 104, 103, 103 samples: 64 + 64 + 58 and 64 + 65 + 57 correct are the same
    # mean accuracy exactly, but float sums of the fold accuracies differ in the last digit and
    # the later candidate won (1 of 100 outer folds on PTC_MR)
    y = np.repeat([0, 1], [155, 155])
    assert sorted(np.bincount(ev._stratified_folds(y, 3, np.random.default_rng(0)))) \
        == [103, 103, 104]
    calls = {0: [], 1: []}

    def fake(K, y_, train, test, C):
        q, n = int(K[0, 0]), len(test)                # the candidate is encoded in K
        calls[q].append(n)
        if n == 104:
            return 64
        i = calls[q].count(103) - 1
        return (64, 58)[i] if q == 0 else (65, 57)[i]

    monkeypatch.setattr(ev, "_fit_correct", fake)
    K = np.stack([np.zeros((310, 310)), np.ones((310, 310))])
    q, C = ev._select_C(K, y, np.array([1.0]), 3, np.random.default_rng(0))
    assert q == 0
    assert 64 / 104 + 64 / 103 + 58 / 103 != 64 / 104 + 65 / 103 + 57 / 103   # the trap


def test_repeated_cv_leaves_numpys_global_random_state_alone():
    """Every SVC fit drew its libsvm seed from NumPy's global generator (random_state=None),
    moving the caller's random stream; the accuracies never depended on it."""
    rng = np.random.default_rng(3)
    K = _gram(rng, 30)
    y = np.repeat([0, 1], 15)
    np.random.seed(0)
    expected = np.random.random()
    np.random.seed(0)
    res = repeated_cv(K, y, n_splits=3, n_repeats=2, C_grid=[1.0, 10.0])
    assert np.random.random() == expected
    assert res.accuracies.shape == (2, 3)
