"""Evaluation of graph kernels: normalization, spectra, repeated nested cross-validation, t-tests.

The protocol (methods page *Synthetic protocols and evaluation measures*) is the field
standard: a C-SVM on the precomputed kernel,
stratified 10-fold cross-validation repeated 10 times, C picked from ``10^-3 .. 10^3`` by an
inner stratified cross-validation on the training folds only. The folds depend only on the
labels ``y`` and ``random_state``, so every kernel evaluated with the same ``y`` and
``random_state`` sees the *same* folds, and two results can be compared with a paired t-test
(:func:`paired_ttest` checks this through the folds' fingerprint).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._progress import progress_bar
from .._validation import check_array, check_bool, check_choice, check_int, check_square
from ._checks import class_labels

__all__ = [
    "CVResult",
    "DEFAULT_C_GRID",
    "MAX_KERNEL_TIMES_C",
    "cosine_normalize",
    "min_eigenvalue_ratio",
    "paired_ttest",
    "repeated_cv",
    "spectrum",
]

DEFAULT_C_GRID = 10.0 ** np.arange(-3, 4)
"""The default SVM ``C`` grid, ``10^-3, 10^-2, ..., 10^3`` (the field's protocol)."""


# --------------------------------------------------------------------------- kernel matrices

def cosine_normalize(K, diag_rows=None, diag_cols=None) -> np.ndarray:
    r"""Cosine-normalize a kernel matrix: :math:`K_{ij} / \sqrt{K_{ii} K_{jj}}`.

    The normalized kernel is the Gram matrix of the unit-length feature vectors, so it keeps
    positive semidefiniteness and has a unit diagonal. A graph whose self-similarity is zero
    (a zero feature vector) has no direction: its row and column are set to 0 (and its
    diagonal entry too), which is still PSD.

    Parameters
    ----------
    K : array_like of shape (n, n) or (m, n)
        Kernel matrix. Square form: the self-similarities are its diagonal. Rectangular form
        (test-vs-train Gram matrix): pass the self-similarities explicitly.
    diag_rows : array_like of shape (m,), optional
        Self-similarities :math:`k(x_i, x_i)` of the row objects (required with ``diag_cols``
        for a rectangular ``K``).
    diag_cols : array_like of shape (n,), optional
        Self-similarities of the column objects.

    Returns
    -------
    ndarray of shape (n, n) or (m, n)
        The normalized kernel (float64, a new array).

    Raises
    ------
    ValueError
        ``K`` not 2-d or not finite, a square ``K`` given without both diagonals when it is
        rectangular, diagonals of the wrong length, or negative self-similarities.

    Examples
    --------
    >>> K = np.array([[4.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    >>> cosine_normalize(K)
    array([[1., 1., 0.],
           [1., 1., 0.],
           [0., 0., 0.]])
    >>> cosine_normalize(np.array([[2.0, 1.0]]), diag_rows=[1.0], diag_cols=[4.0, 1.0])
    array([[1., 1.]])
    """
    K = check_array(K, "K", ndim=2)
    if (diag_rows is None) != (diag_cols is None):
        raise ValueError("`diag_rows` and `diag_cols` must be given together, got only "
                         f"{'diag_rows' if diag_cols is None else 'diag_cols'}")
    if diag_rows is None:
        check_square(K, "K")
        d_rows = d_cols = np.diag(K).copy()
    else:
        d_rows = check_array(diag_rows, "diag_rows", ndim=1)
        d_cols = check_array(diag_cols, "diag_cols", ndim=1)
        if d_rows.shape[0] != K.shape[0] or d_cols.shape[0] != K.shape[1]:
            raise ValueError(f"`diag_rows` and `diag_cols` must have lengths {K.shape}, got "
                             f"{d_rows.shape[0]} and {d_cols.shape[0]}")
    for d, name in ((d_rows, "diag_rows"), (d_cols, "diag_cols")):
        if d.size and d.min() < 0:
            label = "the diagonal of `K`" if diag_rows is None else f"`{name}`"
            raise ValueError(f"{label} must be non-negative (self-similarities), got minimum "
                             f"{float(d.min()):.6g}")
    a_rows, a_cols = _inv_sqrt(d_rows), _inv_sqrt(d_cols)
    with np.errstate(over="ignore", invalid="ignore"):
        # one outer product: a symmetric K stays exactly symmetric
        out = K * np.outer(a_rows, a_cols)
    if np.isfinite(out).all():
        return out
    # self-similarities near the float64 limits (tiny features): scale one side at a time,
    # then restore exact symmetry
    with np.errstate(over="ignore", invalid="ignore", under="ignore"):
        out = (K * a_rows[:, None]) * a_cols[None, :]
    if diag_rows is None and np.array_equal(K, K.T):
        out = 0.5 * (out + out.T)
    if not np.isfinite(out).all():
        raise ValueError("`K` cannot be cosine-normalized in float64: its entries are too large "
                         "for its self-similarities (not a kernel matrix?)")
    return out


def _inv_sqrt(d: np.ndarray) -> np.ndarray:
    out = np.zeros_like(d)
    pos = d > 0
    out[pos] = 1.0 / np.sqrt(d[pos])
    return out


def spectrum(K) -> np.ndarray:
    """Eigenvalues of the symmetric part ``(K + K.T) / 2`` of a square kernel, ascending.

    Parameters
    ----------
    K : array_like of shape (n, n)
        Square kernel matrix (its symmetric part is used).

    Returns
    -------
    ndarray of shape (n,)
        The eigenvalues, in ascending order.

    Examples
    --------
    >>> spectrum(np.array([[1.0, 2.0], [2.0, 1.0]]))
    array([-1.,  3.])
    """
    K = check_array(K, "K", ndim=2)
    check_square(K, "K")
    w = np.linalg.eigvalsh(0.5 * K + 0.5 * K.T)             # no K + K.T overflow
    if not np.isfinite(w).all():
        raise ValueError("`K` is too large: its eigenvalues overflow float64; rescale it")
    return w


def min_eigenvalue_ratio(K) -> float:
    r"""Smallest over largest eigenvalue, :math:`\lambda_{\min} / \lambda_{\max}`.

    A kernel is PSD up to rounding when this is ``>= -1e-9``; a clearly negative value shows an
    indefinite kernel. An all-zero matrix gives 0.

    Parameters
    ----------
    K : array_like of shape (n, n)
        Symmetric kernel (its symmetric part is used).

    Returns
    -------
    float
        ``lambda_min / lambda_max`` of the symmetric part (0 for an all-zero matrix).

    Raises
    ------
    ValueError
        When ``K`` has no positive eigenvalue but is not zero (not a kernel matrix).

    Examples
    --------
    >>> min_eigenvalue_ratio(np.array([[1.0, 2.0], [2.0, 1.0]]))
    -0.333...
    >>> min_eigenvalue_ratio(np.eye(3))
    1.0
    """
    w = spectrum(K)
    if w.size == 0 or (w[0] == 0 and w[-1] == 0):
        return 0.0
    if w[-1] <= 0:
        raise ValueError(f"`K` must have a positive eigenvalue, got largest {w[-1]:.6g}")
    if abs(w[0]) / np.finfo(float).max > w[-1]:
        raise ValueError(f"`K` must have a positive eigenvalue within float64 range of its "
                         f"negative ones (not a kernel matrix?), got lambda_min {w[0]:.6g} and "
                         f"lambda_max {w[-1]:.6g}")
    return float(w[0] / w[-1])


# --------------------------------------------------------------------------- cross-validation

@dataclass(frozen=True, eq=False)
class CVResult:
    """Accuracies of repeated nested stratified cross-validation (:func:`repeated_cv`).

    Attributes
    ----------
    accuracies : ndarray of shape (n_repeats, n_splits)
        Test accuracy of each outer fold.
    per_repeat : ndarray of shape (n_repeats,)
        Mean of the fold accuracies of each repetition.
    mean : float
        Mean of ``per_repeat`` (equal to the mean over all folds).
    std : float
        Sample standard deviation (``ddof=1``; 0 for one repetition) of ``per_repeat``, the
        spread *between repetitions* ("mean ± std over 10 runs", as the experiment's tables);
        the fold-level spread is ``accuracies.std()``.
    chosen_C : ndarray of shape (n_repeats, n_splits)
        The ``C`` picked by the inner cross-validation for each outer fold.
    chosen_kernel : ndarray of shape (n_repeats, n_splits)
        Index of the kernel picked for each outer fold (all 0 for a single kernel).
    folds : ndarray of shape (n_repeats, n_samples)
        Outer test fold of each sample in each repetition.
    fingerprint : str
        Hash of ``folds``: equal for two results exactly when they used the same folds.
    C_grid : ndarray
        The candidate values of ``C``.
    info : dict
        ``inner_splits``, ``random_state``.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.kernels import repeated_cv
    >>> y = np.repeat([0, 1], 6)
    >>> X = np.c_[y, 1 - y] + 0.1 * np.random.default_rng(0).normal(size=(12, 2))
    >>> res = repeated_cv(X @ X.T, y, n_splits=3, n_repeats=2, C_grid=[1.0])
    >>> res.n_repeats, res.n_splits, res.per_repeat.shape, float(res.mean)
    (2, 3, (2,), 1.0)
    """

    accuracies: np.ndarray
    per_repeat: np.ndarray
    mean: float
    std: float
    chosen_C: np.ndarray
    chosen_kernel: np.ndarray
    folds: np.ndarray
    fingerprint: str
    C_grid: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def n_repeats(self) -> int:
        return int(self.accuracies.shape[0])

    @property
    def n_splits(self) -> int:
        return int(self.accuracies.shape[1])

    def __str__(self) -> str:
        return (f"{100 * self.mean:.1f} ± {100 * self.std:.1f} "
                f"({self.n_repeats} x {self.n_splits}-fold)")


def _check_accuracies(res: CVResult, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(accuracies, per_repeat)`` of a CVResult, checked: an (n_repeats, n_splits) and an
    (n_repeats,) array of accuracies in [0, 1] (a hand-built CVResult may hold anything)."""
    acc = check_array(res.accuracies, f"{name}.accuracies", ndim=2)
    per = check_array(res.per_repeat, f"{name}.per_repeat", ndim=1)
    if per.shape[0] != acc.shape[0]:
        raise ValueError(f"`{name}.per_repeat` must have one entry per repetition "
                         f"({acc.shape[0]}), got shape {per.shape}")
    for arr, what in ((acc, "accuracies"), (per, "per_repeat")):
        if arr.size and (arr.min() < 0 or arr.max() > 1):
            raise ValueError(f"`{name}.{what}` must hold accuracies in [0, 1], got range "
                             f"[{arr.min():.6g}, {arr.max():.6g}]")
    return acc, per


def _fingerprint(folds: np.ndarray) -> str:
    h = hashlib.sha1(np.ascontiguousarray(folds, dtype=np.int32).tobytes())
    h.update(str(folds.shape).encode())
    return h.hexdigest()[:16]


def _stratified_folds(y: np.ndarray, n_splits: int, rng: np.random.Generator) -> np.ndarray:
    """Fold index of each sample: each class shuffled, then dealt round-robin over the folds.

    Class sizes differ by at most one between folds, and so do fold sizes (each class starts
    dealing where the previous one stopped).
    """
    fold = np.empty(y.shape[0], dtype=np.int64)
    start = 0
    for c in np.unique(y):
        idx = np.flatnonzero(y == c)
        idx = idx[rng.permutation(idx.shape[0])]
        fold[idx] = (start + np.arange(idx.shape[0])) % n_splits
        start = (start + idx.shape[0]) % n_splits
    return fold


def _fit_correct(K: np.ndarray, y: np.ndarray, train: np.ndarray, test: np.ndarray,
                 C: float) -> int:
    """Number of ``test`` samples an SVM trained on ``train`` classifies right."""
    from sklearn.svm import SVC

    # a fixed seed: libsvm uses it only for probability estimates (off here), and without it
    # every fit drew one from NumPy's global generator, moving the user's random stream
    clf = SVC(kernel="precomputed", C=C, random_state=0)
    clf.fit(K[np.ix_(train, train)], y[train])
    return int(np.count_nonzero(clf.predict(K[np.ix_(test, train)]) == y[test]))


def _select_C(K_train: np.ndarray, y_train: np.ndarray, C_grid: np.ndarray,
              inner_splits: int, rng: np.random.Generator) -> tuple[int, float]:
    """(kernel index, ``C``) with the best mean inner-CV accuracy; sees training data only.

    ``K_train`` is a stack ``(n_kernels, m, m)``; ties go to the first kernel, then the
    smallest ``C``.
    """
    fold = _stratified_folds(y_train, inner_splits, rng)
    # the mean inner accuracy, exactly: sum_k correct_k / n_k on the common denominator
    # lcm(n_k), an integer; float sums broke exact ties by rounding (C = 1000 over an equal
    # C = 100 on one PTC_MR fold)
    sizes = [int(np.count_nonzero(fold == k)) for k in range(inner_splits)]
    lcm = math.lcm(*[max(n, 1) for n in sizes])
    scores = np.zeros((K_train.shape[0], C_grid.shape[0]), dtype=object)
    for k in range(inner_splits):
        tr = np.flatnonzero(fold != k)
        va = np.flatnonzero(fold == k)
        if not va.size:
            continue
        for q, Kq in enumerate(K_train):
            for c, C in enumerate(C_grid):
                scores[q, c] += _fit_correct(Kq, y_train, tr, va, float(C)) * (lcm // va.size)
    flat = scores.ravel().tolist()
    q, c = np.unravel_index(flat.index(max(flat)), scores.shape)   # first maximum on ties
    return int(q), float(C_grid[c])


MAX_KERNEL_TIMES_C = 1e12
"""Largest ``max |K| * max(C_grid)`` :func:`repeated_cv` accepts.

Scaling a kernel by ``s`` is the same SVM as scaling ``C`` by ``s``; libsvm's absolute
stopping tolerance then needs ever more iterations (20 samples: 1 s at 1e12, 9 s at 1e13,
minutes beyond 1e14)."""


def _check_svm_kernels(Ks: np.ndarray, stack: bool, c_max: float) -> None:
    """Refuse kernels libsvm cannot fit in reasonable time: asymmetric or too large.

    An asymmetric precomputed kernel makes libsvm's solver cycle forever; the tolerance is
    relative, ``1e-8`` of the largest entry, so round-off asymmetry passes.
    """
    for q, Kq in enumerate(Ks):
        name = f"K[{q}]" if stack else "K"
        top = float(np.abs(Kq).max(initial=0.0))
        asym = float(np.abs(Kq - Kq.T).max(initial=0.0))
        if asym > 1e-8 * top:
            i, j = np.unravel_index(int(np.argmax(np.abs(Kq - Kq.T))), Kq.shape)
            raise ValueError(f"`{name}` must be symmetric (an SVM kernel), got "
                             f"{name}[{i}, {j}] = {Kq[i, j]:.6g} but {name}[{j}, {i}] = "
                             f"{Kq[j, i]:.6g}; symmetrize it, e.g. (K + K.T) / 2")
        if top * c_max > MAX_KERNEL_TIMES_C:
            raise ValueError(f"`{name}` is too large for the SVM: its largest entry, {top:.3g}, "
                             f"times the largest C, {c_max:.3g}, exceeds "
                             f"{MAX_KERNEL_TIMES_C:.0e} (scaling K is scaling C; libsvm would "
                             "run for hours); normalize it, e.g. with cosine_normalize, or lower "
                             "`C_grid`")


#: most repetitions :func:`repeated_cv` runs (10**9 spawned that many seeds before any work:
#: a hang)
MAX_REPEATS = 1000


def repeated_cv(K, y, *, n_splits: int = 10, n_repeats: int = 10, C_grid=None,
                inner_splits: int = 3, random_state: int = 0,
                progress: bool = False) -> CVResult:
    """Repeated stratified k-fold accuracy of an SVM on a precomputed kernel, nested choice of C.

    For each of ``n_repeats`` repetitions the samples are split into ``n_splits`` stratified
    folds. For each outer fold, ``C`` is chosen from ``C_grid`` by an inner stratified
    ``inner_splits``-fold cross-validation on the *training folds only* (the test fold's rows
    and columns of ``K`` are never read for that choice), an ``SVC(kernel="precomputed")`` is
    fitted on the training folds with that ``C`` and scored on the test fold.

    The folds depend only on ``y`` and ``random_state`` (not on ``K``): every kernel evaluated
    with the same labels and seed gets identical folds, recorded in ``CVResult.folds`` and
    ``CVResult.fingerprint``.

    Parameters
    ----------
    K : array_like of shape (n_samples, n_samples) or (n_kernels, n_samples, n_samples)
        Kernel matrix (symmetric; used as given, so normalize it first if wanted), or a stack
        (or list) of candidate kernels -- e.g. WL for h = 0..10 -- from which the inner
        cross-validation picks one jointly with ``C`` (ties: the earlier kernel).
    y : array_like of shape (n_samples,)
        Class labels (any integer or string labels).
    n_splits : int, default=10
        Outer folds, >= 2; every class needs at least ``n_splits`` samples.
    n_repeats : int, default=10
        Repetitions with different shuffles, 1 to :data:`MAX_REPEATS` (1000).
    C_grid : array_like, optional
        Candidate ``C`` values (> 0); default ``10^-3, ..., 10^3`` (:data:`DEFAULT_C_GRID`).
    inner_splits : int, default=3
        Folds of the inner cross-validation, >= 2.
    random_state : int, default=0
        Seed of the fold shuffles (outer and inner).
    progress : bool, default=False
        Show a progress bar over the outer folds.

    Returns
    -------
    CVResult
        Fold accuracies, their mean and spread, and the ``C`` (and kernel) chosen per fold.

    Raises
    ------
    ValueError
        ``K`` not square (nor a stack of square matrices), not finite, not symmetric, or
        so large that ``max |K| * max(C_grid)`` exceeds :data:`MAX_KERNEL_TIMES_C`; ``y`` of
        the wrong length, a single class, a class with fewer than ``n_splits`` samples (or too
        few for the inner folds), bad ``C_grid``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> y = np.repeat([0, 1], 10)
    >>> X = rng.normal(size=(20, 3)) + 3 * y[:, None]
    >>> res = repeated_cv(X @ X.T, y, n_splits=5, n_repeats=2, C_grid=[0.1, 1.0])
    >>> res.accuracies.shape, res.mean
    ((2, 5), 1.0)
    """
    K = check_array(K, "K", ndim=(2, 3))
    Ks = K[None] if K.ndim == 2 else K
    if Ks.shape[0] == 0 or Ks.shape[1] != Ks.shape[2]:
        raise ValueError(f"`K` must be a square matrix or a non-empty stack of square matrices, "
                         f"got shape {K.shape}")
    n = Ks.shape[1]
    y = np.asarray(y)
    if y.ndim != 1 or y.shape[0] != n:
        raise ValueError(f"`y` must have shape ({n},) to match `K`, got shape {y.shape}")
    n_splits = check_int(n_splits, "n_splits", minimum=2)
    n_repeats = check_int(n_repeats, "n_repeats", minimum=1, maximum=MAX_REPEATS)
    progress = check_bool(progress, "progress")
    inner_splits = check_int(inner_splits, "inner_splits", minimum=2)
    random_state = check_int(random_state, "random_state", minimum=0)
    if C_grid is None:
        C_grid = DEFAULT_C_GRID
    C_grid = check_array(C_grid, "C_grid", ndim=1)
    if C_grid.size == 0 or C_grid.min() <= 0:
        raise ValueError(f"`C_grid` must be a non-empty list of values > 0, got {C_grid}")
    _check_svm_kernels(Ks, K.ndim == 3, float(C_grid.max()))
    classes, y_idx = class_labels(y, "y")
    if classes.shape[0] < 2:
        raise ValueError(f"`y` must contain at least 2 classes, got {classes.shape[0]}")
    counts = np.bincount(y_idx)
    small = int(counts.min())
    if small < n_splits:
        bad = classes[counts < n_splits]
        raise ValueError(f"every class in `y` needs at least n_splits={n_splits} samples for "
                         f"stratified folds; class(es) {bad.tolist()} have {small} (prune small "
                         "classes or lower n_splits)")
    if small - (-(-small // n_splits)) < inner_splits:
        raise ValueError(f"every class in `y` needs enough samples for {inner_splits} inner folds "
                         f"in each training set; the smallest class has {small}")
    C_grid = np.sort(C_grid)

    seeds = np.random.SeedSequence(random_state).spawn(n_repeats)
    folds = np.empty((n_repeats, n), dtype=np.int64)
    acc = np.empty((n_repeats, n_splits))
    chosen = np.empty((n_repeats, n_splits))
    chosen_k = np.zeros((n_repeats, n_splits), dtype=np.int64)
    with progress_bar(n_repeats * n_splits, "nested CV folds", enabled=progress) as bar:
        for r in range(n_repeats):
            outer_seed, inner_seed = seeds[r].spawn(2)
            folds[r] = _stratified_folds(y_idx, n_splits, np.random.default_rng(outer_seed))
            inner_rngs = [np.random.default_rng(s) for s in inner_seed.spawn(n_splits)]
            for k in range(n_splits):
                train = np.flatnonzero(folds[r] != k)
                test = np.flatnonzero(folds[r] == k)
                q, C = _select_C(Ks[:, train][:, :, train], y_idx[train], C_grid, inner_splits,
                                 inner_rngs[k])
                chosen[r, k], chosen_k[r, k] = C, q
                acc[r, k] = _fit_correct(Ks[q], y_idx, train, test, C) / test.size
                bar.update(1)
    per_repeat = acc.mean(axis=1)
    return CVResult(accuracies=acc, per_repeat=per_repeat, mean=float(per_repeat.mean()),
                    std=float(per_repeat.std(ddof=1)) if n_repeats > 1 else 0.0,
                    chosen_C=chosen, chosen_kernel=chosen_k,
                    folds=folds,
                    fingerprint=_fingerprint(folds), C_grid=C_grid,
                    info={"inner_splits": inner_splits, "random_state": random_state})


def paired_ttest(a: CVResult, b: CVResult, *, over: str = "corrected") -> tuple[float, float]:
    """Paired two-sided t-test between the accuracies of two kernels on the same folds.

    Parameters
    ----------
    a, b : CVResult
        Results of :func:`repeated_cv` with the same folds (same ``y``, ``n_splits``,
        ``n_repeats`` and ``random_state``).
    over : {"corrected", "repeats", "folds"}, default="corrected"
        ``"corrected"``: Nadeau and Bengio's corrected resampled t-test (Machine Learning
        2003; Bouckaert and Frank 2004) over the ``n_repeats * n_splits`` fold differences,
        whose variance is inflated by ``1 / (r k) + n_test / n_train`` because the folds share
        training samples -- the honest choice for repeated cross-validation. ``"repeats"``: a
        plain paired t-test of the per-repetition mean accuracies (the field's habit;
        optimistic, the repetitions reuse the same samples). ``"folds"``: a plain test over
        the individual folds (more optimistic still).

    Returns
    -------
    t : float
        The t statistic, positive when ``a`` is more accurate (``±inf`` for a constant
        non-zero difference).
    p : float
        Two-sided p-value (1.0 when all differences are zero).

    Raises
    ------
    TypeError
        Arguments that are not :class:`CVResult`.
    ValueError
        Results from different folds, or fewer than 2 pairs.

    Examples
    --------
    >>> y = np.repeat([0, 1], 10)
    >>> X = np.random.default_rng(0).normal(size=(20, 3)) + 2 * y[:, None]
    >>> a = repeated_cv(X @ X.T, y, n_splits=5, n_repeats=3, C_grid=[1.0])
    >>> paired_ttest(a, a)
    (0.0, 1.0)
    """
    for r, name in ((a, "a"), (b, "b")):
        if not isinstance(r, CVResult):
            raise TypeError(f"`{name}` must be a CVResult, got {type(r).__name__}")
    over = check_choice(over, "over", ("corrected", "repeats", "folds"))
    if a.fingerprint != b.fingerprint or np.shape(a.folds) != np.shape(b.folds):
        raise ValueError("`a` and `b` must come from the same folds (same y, n_splits, n_repeats "
                         f"and random_state), got fold fingerprints {a.fingerprint} and "
                         f"{b.fingerprint}")
    acc = [_check_accuracies(r, name) for r, name in ((a, "a"), (b, "b"))]
    if acc[0][0].shape != acc[1][0].shape:
        raise ValueError(f"`a` and `b` must hold accuracies of the same shape (same folds), got "
                         f"{acc[0][0].shape} and {acc[1][0].shape}")
    if over == "repeats":
        x, z = acc[0][1], acc[1][1]
    else:
        x, z = acc[0][0].ravel(), acc[1][0].ravel()
    if x.shape[0] < 2:
        raise ValueError(f"`a` and `b` must hold at least 2 paired accuracies for a t-test, got "
                         f"{x.shape[0]} ({over})")
    if over == "corrected" and acc[0][0].shape[1] < 2:
        raise ValueError(f"`a` and `b` must come from n_splits >= 2 folds for the corrected "
                         f"t-test, got {acc[0][0].shape[1]}")
    d = x - z
    if np.ptp(d) <= 1e-12 * max(1.0, float(np.abs(d).max())):
        # (numerically) zero variance: scipy would warn and return NaN
        if np.all(np.abs(d) <= 1e-12):
            return 0.0, 1.0
        return float(np.copysign(np.inf, d.mean())), 0.0
    from scipy.stats import t as student_t, ttest_rel

    if over != "corrected":
        res = ttest_rel(x, z)
        return float(res.statistic), float(res.pvalue)
    n_splits = acc[0][0].shape[1]
    m = d.shape[0]
    ratio = 1.0 / (n_splits - 1)              # n_test / n_train of k-fold CV
    var = float(np.var(d, ddof=1))
    t = float(d.mean() / np.sqrt((1.0 / m + ratio) * var))
    return t, float(2 * student_t.sf(abs(t), df=m - 1))
