"""Property-based contract of the public API (issue 13 item 5).

Every public function, on any input, either

* returns a valid result -- assignments injective and in range, maps and scores finite, blocks
  (sub-)doubly stochastic, labels within the universe, results cycle-consistent where promised,
  each as the function documents it -- or
* raises one of the library's documented exceptions: ``ValueError``/``TypeError`` whose message
  names the argument (a backquoted name, the project's message style), or a
  :class:`transync.exceptions.TransyncError`.

Never ``IndexError``/``KeyError``/``LinAlgError``/``ZeroDivisionError``/``MemoryError``/numpy's
``UFuncTypeError``/``cv2.error``, never a silent NaN, never a warning other than the library's own
(``ConvergenceWarning``, ``UnlinkedViewsWarning``), never a hang (each call is bounded in time).

One test per function or contract, so that a violation in one place hides no other. Inputs are
small; the settings are reproducible (``derandomize=True``) and sized so that the module runs in
about 30 s on one core.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import transync
from transync import geometry, metrics, permutations
from transync.exceptions import ConvergenceWarning, TransyncError, UnlinkedViewsWarning

_COMMON = dict(deadline=None, derandomize=True, database=None, print_blob=True,
               suppress_health_check=list(HealthCheck))
CHEAP = settings(max_examples=60, **_COMMON)
MEDIUM = settings(max_examples=30, **_COMMON)
COSTLY = settings(max_examples=20, **_COMMON)

CALL_LIMIT_S = 20          # a call running longer counts as a hang
OUR_WARNINGS = (ConvergenceWarning, UnlinkedViewsWarning)
REFUSED = object()         # the call raised a documented exception
STATS: dict = {}           # function -> [returned, raised]; printed with TRANSYNC_CONTRACT_STATS=1
MESSAGES: dict = {}        # function -> distinct refusal messages (same switch)


@pytest.fixture(scope="module", autouse=True)
def _report_stats():
    yield
    if os.environ.get("TRANSYNC_CONTRACT_STATS"):
        for name, (ok, raised) in sorted(STATS.items()):
            print(f"{name:60s} returned {ok:5d}  raised {raised:5d}")
            if os.environ["TRANSYNC_CONTRACT_STATS"] == "2":
                for msg in list(MESSAGES.get(name, ()))[:6]:
                    print(f"    {msg}")


# ----------------------------------------------------------------------------------- harness

class ContractViolation(AssertionError):
    pass


@contextlib.contextmanager
def _time_limit(seconds):
    if not hasattr(signal, "SIGALRM"):      # pragma: no cover - Windows
        yield
        return

    def handler(signum, frame):
        raise ContractViolation(f"call did not return within {seconds} s (hang)")

    old = signal.signal(signal.SIGALRM, handler)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _forbidden(exc, fn_name="") -> str | None:
    """Why ``exc`` breaks the contract, or None when it is a documented exception.

    A ``ValueError``/``TypeError`` must name what was wrong: a backquoted argument (the project's
    message style) or the function called.
    """
    name = type(exc).__name__
    if isinstance(exc, (IndexError, KeyError, ZeroDivisionError, MemoryError, AttributeError,
                        AssertionError, OverflowError, FloatingPointError, RecursionError)):
        return f"undocumented {name}"
    if isinstance(exc, np.linalg.LinAlgError) or "UFunc" in name or name == "error":
        return f"low-level {type(exc).__module__}.{name}"
    if isinstance(exc, TransyncError):
        return None
    if isinstance(exc, (ValueError, TypeError)):
        if "`" not in str(exc) and not (fn_name and fn_name in str(exc)):
            return f"{name} that names no argument"
        return None
    return f"undocumented {name}"


def call(fn, *args, **kwargs):
    """Call ``fn``; return its value, or REFUSED after a documented exception.

    Raise ContractViolation on an undocumented exception, a foreign warning or a hang. A
    foreign warning before a refusal counts too: the input reached the numerics before it was
    refused (NaN arithmetic, then an internal array's check).
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            with _time_limit(CALL_LIMIT_S):
                out = fn(*args, **kwargs)
        except ContractViolation:
            raise
        except Exception as exc:  # noqa: BLE001 - the contract is about which ones
            why = _forbidden(exc, getattr(fn, "__name__", ""))
            foreign = [w for w in caught if not issubclass(w.category, OUR_WARNINGS)]
            if why is None and foreign:
                why = (f"refused after a foreign warning {foreign[0].category.__name__}: "
                       f"{foreign[0].message}")
            STATS.setdefault(getattr(fn, "__qualname__", str(fn)), [0, 0])[1] += 1
            MESSAGES.setdefault(getattr(fn, "__qualname__", str(fn)), {}).setdefault(
                str(exc)[:90], 0)
            if why is not None:
                raise ContractViolation(f"{getattr(fn, '__qualname__', fn)}: {why}: "
                                        f"{str(exc)[:300]}") from exc
            return REFUSED
    STATS.setdefault(getattr(fn, "__qualname__", str(fn)), [0, 0])[0] += 1
    foreign = [w for w in caught if not issubclass(w.category, OUR_WARNINGS)]
    if foreign:
        w = foreign[0]
        raise ContractViolation(f"{getattr(fn, '__qualname__', fn)}: foreign warning "
                                f"{w.category.__name__}: {w.message}")
    return out


def check(cond, what):
    if not cond:
        raise ContractViolation(what)


def check_assignment(a, n1, n2, what="assignment"):
    a = np.asarray(a)
    check(a.shape == (n1,), f"{what}: shape {a.shape}, expected ({n1},)")
    check(a.dtype.kind in "iu", f"{what}: dtype {a.dtype}, expected integers")
    check(bool(np.all((a >= -1) & (a < n2))), f"{what}: entries outside [-1, {n2}): {a}")
    m = a[a >= 0]
    check(len(np.unique(m)) == len(m), f"{what}: not injective: {a}")


def check_finite_array(x, what):
    x = np.asarray(x)
    if x.size == 0:
        return
    check(x.dtype.kind in "biuf", f"{what}: accepted a non-numeric array of dtype {x.dtype}")
    x = x.astype(float)
    check(bool(np.all(np.isfinite(x))), f"{what}: NaN or infinite entries (silent NaN)")


def check_finite_scalar(x, what):
    check(isinstance(x, (float, int, np.floating, np.integer)) and np.isfinite(x),
          f"{what}: expected a finite number, got {x!r}")


# ----------------------------------------------------------------------------------- strategies

SPECIAL = [0.0, -0.0, 1.0, -1.0, 0.5, np.nan, np.inf, -np.inf, 1e300, -1e300, 1e-300, 5e-324,
           1e9, -1e9, 1e-9]
nasty_floats = st.one_of(st.floats(-10, 10, allow_nan=False, width=64), st.sampled_from(SPECIAL))
tame_floats = st.floats(0, 1, allow_nan=False, width=64)
SCALES = st.sampled_from([1.0] * 12 + [0.0, 1e-300, 1e-30, 1e-8, 1e8, 1e30, 1e300, np.nan,
                          np.inf, -1.0])
small = st.integers(0, 4)


def float_arrays(shape, elements=nasty_floats):
    return hnp.arrays(np.float64, shape, elements=elements)


def arrays_of_kind(kind, shape):
    """Strategy: arrays of ``shape`` of one kind: "f" nasty floats, "f01" floats in [0, 1],
    "i" small int64, "i16", "u8", "b" bool, "c" complex, "U" strings."""
    if kind == "f":
        return float_arrays(shape)
    if kind == "f01":
        return float_arrays(shape, elements=tame_floats)
    if kind == "i":
        return hnp.arrays(np.int64, shape, elements=st.integers(-3, 6))
    if kind in ("i16", "u8", "b"):
        return hnp.arrays({"i16": np.int16, "u8": np.uint8, "b": np.bool_}[kind], shape)
    if kind == "c":
        return hnp.arrays(np.complex128, shape,
                          elements=st.complex_numbers(max_magnitude=5, allow_nan=False))
    return hnp.arrays(np.dtype("U3"), shape, elements=st.text("ab1.", max_size=3))


@st.composite
def any_arrays(draw, max_dims=3, max_side=4):
    """Arrays of any small shape and a dtype the API might meet: float (nasty), int, bool,
    complex, object/str."""
    shape = draw(hnp.array_shapes(min_dims=0, max_dims=max_dims, min_side=0, max_side=max_side))
    return draw(arrays_of_kind(draw(st.sampled_from(["f", "f", "f", "i", "b", "c", "U"])),
                               shape))


@st.composite
def assignments(draw, n1=None, n2=None, valid=None):
    """An assignment (n1,) into n2; valid (injective, in range) or not."""
    n1 = draw(small) if n1 is None else n1
    n2 = draw(small) if n2 is None else n2
    valid = draw(st.booleans()) if valid is None else valid
    if valid:
        perm = draw(st.permutations(list(range(max(n1, n2)))))
        a = np.array(perm[:n1], dtype=np.int64)
        a[a >= n2] = -1
        if draw(st.integers(0, 3)) == 0:                   # partial: drop some nodes
            a[draw(hnp.arrays(np.bool_, n1))] = -1
        return a, n2
    return draw(hnp.arrays(np.int64, n1, elements=st.integers(-3, n2 + 2))), n2


@st.composite
def partial_permutation_matrices(draw):
    a, n2 = draw(assignments(valid=True))
    X = np.zeros((a.size, n2))
    X[np.flatnonzero(a >= 0), a[a >= 0]] = 1.0
    return X


@st.composite
def dense_affinities(draw):
    """(K, n1, n2): a symmetric non-negative K times a nasty scale, sometimes raw junk."""
    n1, n2 = draw(small), draw(small)
    n = n1 * n2
    if draw(st.integers(0, 4)) == 0:
        return draw(float_arrays((n, n))), n1, n2
    base = draw(float_arrays((n, n), elements=tame_floats))
    K = (base + base.T) / 2
    with np.errstate(all="ignore"):
        K = K * draw(SCALES)
    return K, n1, n2


@st.composite
def point_graph_pairs(draw):
    """(points, perm, scale): g2 is g1 with nodes permuted, coordinates times ``scale``."""
    n = draw(st.integers(0, 5))
    pts = draw(float_arrays((n, 2), elements=st.floats(-1, 1, width=64)))
    perm = np.array(draw(st.permutations(list(range(n)))), dtype=np.int64)
    scale = draw(st.sampled_from([1.0, 1.0, 1e-9, 1e-3, 1e3, 1e6, 1e9, 1e12]))
    return pts, perm, scale


@st.composite
def pairwise_dicts(draw, soft=False):
    """{(i, j): assignment or matrix} over up to 4 objects of up to 4 nodes, some entries junk."""
    n_obj = draw(st.sampled_from([2, 3, 4] * 3 + [0, 1]))
    sizes = [draw(st.sampled_from([1, 2, 3, 4] * 2 + [0])) for _ in range(n_obj)]
    out = {}
    pairs = [(i, j) for i in range(n_obj) for j in range(n_obj) if i != j]
    chosen = draw(st.lists(st.sampled_from(pairs), unique=True, min_size=1,
                           max_size=len(pairs))) if pairs else []
    clean = draw(st.booleans())
    if clean:
        sizes = [max(n, 1) for n in sizes]
    for i, j in chosen:
        kind = "valid" if clean else draw(st.sampled_from(
            ["valid"] * 8 + ["junk_assign", "matrix", "junk_array"]))
        if kind == "valid":
            a, _ = draw(assignments(n1=sizes[i], n2=sizes[j], valid=True))
            if soft:
                a = np.zeros((sizes[i], sizes[j])) if a.size == 0 else \
                    np.eye(max(sizes[j], 1))[np.where(a >= 0, a, 0)][:, :sizes[j]] \
                    * (a >= 0)[:, None]
            out[(i, j)] = a
        elif kind == "junk_assign":
            out[(i, j)] = draw(assignments(n1=sizes[i], n2=sizes[j], valid=False))[0]
        elif kind == "matrix":
            out[(i, j)] = draw(float_arrays((sizes[i], sizes[j]), elements=tame_floats))
        else:
            out[(i, j)] = draw(any_arrays(max_dims=2))
    return out, sizes


N_UNIVERSE = st.sampled_from([None] * 10 + [0, 1, 3, 4, 8, 10**9, -1])


# ----------------------------------------------------------------------------------- permutations

@CHEAP
@given(assignments(), st.sampled_from([None, -1, 0, 2, 10**12]))
def test_assignment_to_matrix(a_n2, n2_override):
    a, n2 = a_n2
    n2 = n2 if n2_override is None else n2_override
    X = call(permutations.assignment_to_matrix, a, n2)
    if X is REFUSED:
        return
    check(X.shape == (a.size, n2), f"shape {X.shape}")
    check(bool(np.all(X.sum(0) <= 1) and np.all(X.sum(1) <= 1)), "not a partial permutation")
    check(bool(np.array_equal(np.flatnonzero(X.sum(1)), np.flatnonzero(a >= 0))),
          "rows do not follow the assignment")


@CHEAP
@given(st.one_of(partial_permutation_matrices(), any_arrays(max_dims=2)))
def test_matrix_to_assignment(X):
    a = call(permutations.matrix_to_assignment, X)
    if a is REFUSED:
        return
    X = np.asarray(X)
    check(X.ndim == 2, f"accepted a {X.ndim}-d array")
    check_assignment(a, X.shape[0], X.shape[1])
    back = permutations.assignment_to_matrix(a, X.shape[1])
    # 0/1 to the documented tolerance (atol 1e-8): entries within it round to 0 or 1
    check(bool(np.allclose(back, X.astype(float), rtol=0, atol=1e-8)),
          "accepted a matrix that is not a partial permutation (no round trip)")


@CHEAP
@given(st.one_of(assignments(), st.tuples(any_arrays(max_dims=2), small)),
       st.sampled_from([None, 0, 3, -1]))
def test_check_assignment(a_n2, n2):
    a, _ = a_n2
    out = call(permutations.check_assignment, a, n2=n2)
    if out is REFUSED:
        return
    arr = np.asarray(a)
    check(arr.ndim == 1, "accepted a non-1-d assignment")
    check_assignment(out, arr.size, n2 if n2 is not None else max(int(out.max(initial=-1)) + 1,
                                                                  0))


@CHEAP
@given(assignments(), assignments())
def test_compose(first_n, second_n):
    first, second = first_n[0], second_n[0]
    out = call(permutations.compose, first, second)
    if out is REFUSED:
        return
    n2 = second_n[1]
    check_assignment(out, first.size, max(n2, int(second.max(initial=-1)) + 1))
    for i, a in enumerate(first):
        want = second[a] if 0 <= a < second.size else -1
        check(out[i] == want, f"compose[{i}] = {out[i]}, expected {want}")


@CHEAP
@given(assignments(), st.sampled_from([None, -1, 0, 10**12]))
def test_invert(a_n2, n2_override):
    a, n2 = a_n2
    n2 = n2 if n2_override is None else n2_override
    inv = call(permutations.invert, a, n2)
    if inv is REFUSED:
        return
    check_assignment(a, a.size, n2, "input accepted by invert")
    check_assignment(inv, n2, a.size, "invert")
    for i, t in enumerate(a):
        if t >= 0:
            check(inv[t] == i, "invert is not the inverse")


@CHEAP
@given(st.one_of(st.tuples(small, small).flatmap(lambda s: float_arrays(s)), any_arrays()),
       st.booleans(), st.sampled_from([None, None, 0.0, 0.5, np.nan]))
def test_solve_lap(score, maximize, min_score):
    a = call(permutations.solve_lap, score, maximize=maximize, min_score=min_score)
    if a is REFUSED:
        return
    S = np.asarray(score)
    check(S.ndim == 2, f"accepted a {S.ndim}-d score")
    check_finite_array(S, "accepted score")
    check_assignment(a, S.shape[0], S.shape[1])
    if min_score is None and S.size:
        from scipy.optimize import linear_sum_assignment
        r, c = linear_sum_assignment(S, maximize=maximize)
        best = S[r, c].sum()
        got = S[np.flatnonzero(a >= 0), a[a >= 0]].sum()
        check(bool(np.isclose(got, best, rtol=1e-9, atol=1e-9)),
              f"not optimal: {got} vs {best}")


@MEDIUM
@given(pairwise_dicts(), st.sampled_from([200000, 1, 0, -1]))
def test_cycle_inconsistency(pw_sizes, max_triangles):
    pw, _ = pw_sizes
    for fn in (permutations.cycle_inconsistency, metrics.cycle_inconsistency):
        out = call(fn, pw, max_triangles=max_triangles, rng=0)
        if out is REFUSED:
            continue
        check(isinstance(out["n_triangles"], (int, np.integer)) and out["n_triangles"] >= 0,
              f"n_triangles {out['n_triangles']!r}")
        for key in ("inconsistent_triangles", "cycle_error"):
            check_finite_scalar(out[key], key)
            check(0 <= out[key] <= 1, f"{key} = {out[key]} outside [0, 1]")


@CHEAP
@given(st.one_of(st.integers(-3, 6), st.sampled_from([10**12, 2.5, "3", None, np.nan])))
def test_identity_and_random_permutation(n):
    for fn in (permutations.identity, lambda n: permutations.random_permutation(n, rng=0)):
        p = call(fn, n)
        if p is REFUSED:
            continue
        check(isinstance(n, (int, np.integer)) and 0 <= n, f"accepted n={n!r}")
        check_assignment(p, n, n)
        check(bool(np.all(p >= 0)), "a permutation has no -1")


@CHEAP
@given(st.one_of(partial_permutation_matrices(), any_arrays()))
def test_is_partial_permutation_matrix(X):
    out = call(permutations.is_partial_permutation_matrix, X)
    if out is REFUSED:
        return
    check(isinstance(out, (bool, np.bool_)), f"returned {type(out).__name__}, expected bool")


# ----------------------------------------------------------------------------------- metrics

@CHEAP
@given(st.integers(0, 5).flatmap(lambda n: st.tuples(assignments(n1=n), assignments(n1=n))),
       st.booleans())
def test_matching_accuracy_and_precision_recall(pair, mismatched):
    (a, _), (t, _) = pair
    if mismatched:
        t = np.append(t, 0)
    acc = call(metrics.matching_accuracy, a, t)
    if acc is not REFUSED:
        check(a.size == t.size, "accepted assignments of different lengths")
        check_finite_scalar(acc, "matching_accuracy")
        check(0 <= acc <= 1, f"accuracy {acc} outside [0, 1]")
    pr = call(metrics.matching_precision_recall, a, t)
    if pr is not REFUSED:
        check(a.size == t.size, "accepted assignments of different lengths")
        for k, v in pr.items():
            if isinstance(v, float):
                check_finite_scalar(v, k)
                check(0 <= v <= 1, f"{k} = {v} outside [0, 1]")


@MEDIUM
@given(dense_affinities(), assignments())
def test_affinity_score(K_n, a_n2):
    K, n1, n2 = K_n
    a, _ = a_n2
    s = call(metrics.affinity_score, K, a, n2=n2)
    if s is REFUSED:
        return
    check_finite_scalar(s, "affinity_score")


H_ARRAYS = st.one_of(
    float_arrays((3, 3)),
    st.integers(0, 3).flatmap(lambda n: float_arrays((n, 3, 3))),
    st.integers(0, 3).flatmap(lambda n: float_arrays((n, 3, 3), elements=tame_floats)),
    any_arrays(),
)
SIZES = st.one_of(st.tuples(st.integers(-2, 50), st.integers(-2, 50)),
                  st.sampled_from([(np.nan, 4), (1e300, 1e300), (4,), "ab", None]))


@MEDIUM
@given(H_ARRAYS, H_ARRAYS, SIZES)
def test_corner_errors(H_est, H_true, size):
    for fn in (metrics.corner_error, metrics.pairwise_corner_error):
        out = call(fn, H_est, H_true, image_size=size)
        if out is REFUSED:
            continue
        out = np.asarray(out, dtype=float)
        # a corner sent to infinity is an infinitely wrong estimate (documented: inf), never NaN
        check(not np.isnan(out).any(), f"{fn.__name__}: silent NaN")
        check(bool(np.all(out >= 0)), f"{fn.__name__}: negative error")


@CHEAP
@given(st.one_of(float_arrays(st.integers(0, 5)), any_arrays(max_dims=1)),
       st.sampled_from([(1.0, 3.0, 5.0), (), (-1.0,), (np.nan,), "x", (1.0, 1.0000002),
                        (3.0, 1.0, 3.0)]))
def test_corner_accuracy(errors, thresholds):
    out = call(metrics.corner_accuracy, errors, thresholds)
    if out is REFUSED:
        return
    # one key per distinct threshold: close ones printed alike and one was lost
    check(len(out) == len(set(thresholds)), f"corner_accuracy: {len(out)} keys for {thresholds}")
    for k, v in out.items():
        if isinstance(v, (float, np.floating)):
            check(0 <= v <= 1 or np.isnan(v) and np.size(errors) == 0, f"{k} = {v}")


@CHEAP
@given(any_arrays(), any_arrays())
def test_segmentation_scores(pred, truth):
    out = call(metrics.segmentation_scores, pred, truth)
    if out is REFUSED:
        return
    for k, v in out.items():
        v = np.asarray(v, dtype=float)
        check_finite_array(v, f"segmentation_scores[{k!r}]")
        check(bool(np.all((v >= 0) & (v <= 1))), f"{k} outside [0, 1]")


@CHEAP
@given(st.one_of(float_arrays(st.tuples(small, small)), any_arrays()))
def test_brenner_focus(image):
    out = call(metrics.brenner_focus, image)
    if out is REFUSED:
        return
    check_finite_scalar(out, "brenner_focus")


# ----------------------------------------------------------------------------------- matching

def _check_matching_result(res, n1, n2, K=None):
    check(isinstance(res, transync.MatchingResult), f"returned {type(res).__name__}")
    check_assignment(res.assignment, n1, n2)
    check_finite_scalar(res.objective, "objective")
    if res.soft is not None:
        check(np.shape(res.soft) == (n1, n2), f"soft shape {np.shape(res.soft)}")
        check_finite_array(res.soft, "soft")
    check(isinstance(res.n_iter, (int, np.integer)) and res.n_iter >= 0, f"n_iter {res.n_iter}")
    check(isinstance(res.converged, (bool, np.bool_)), "converged is not a bool")
    if K is not None and n1 * n2:
        x = np.zeros(n1 * n2)
        rows = np.flatnonzero(res.assignment >= 0)
        x[res.assignment[rows] * n1 + rows] = 1.0
        want = float(x @ np.asarray(K, dtype=float) @ x)
        check(bool(np.isclose(res.objective, want, rtol=1e-6, atol=1e-12 * max(1, abs(want)))),
              f"objective {res.objective} is not vec(X)^T K vec(X) = {want}")


@pytest.mark.parametrize("method", ["sm", "rrwm", "ipfp", "ga", "pf"])
@COSTLY
@given(K_n=dense_affinities(), wrap=st.booleans(), lie=st.sampled_from([None, None, (1, 0)]))
def test_quadratic_solvers(method, K_n, wrap, lie):
    from transync import matching

    K, n1, n2 = K_n
    if lie is not None:                                    # wrong declared sizes
        n1, n2 = n1 + lie[0], n2 + lie[1]
    if wrap:
        A = call(matching.DenseAffinity, K, n1, n2)
        if A is REFUSED:
            return
        check_finite_array(K, "DenseAffinity accepted K")
        check(K.shape == (n1 * n2, n1 * n2), f"DenseAffinity accepted K {K.shape} for "
                                             f"n1={n1}, n2={n2}")
        res = call(getattr(matching, method), A)
    else:
        res = call(getattr(matching, method), K, n1=n1, n2=n2)
    if res is REFUSED:
        return
    check_finite_array(K, "accepted K")
    _check_matching_result(res, n1, n2, K)


@pytest.mark.parametrize("method", ["hungarian", "sinkhorn"])
@MEDIUM
@given(scores=st.one_of(st.tuples(small, small).flatmap(lambda s: float_arrays(s)),
                        st.tuples(small, small).flatmap(
                            lambda s: float_arrays(s, elements=tame_floats)).map(
                                lambda S: S * 1e300),
                        any_arrays()))
def test_linear_solvers(method, scores):
    from transync import matching

    res = call(getattr(matching, method), scores)
    if res is REFUSED:
        return
    S = np.asarray(scores)
    check(S.ndim == 2, f"accepted a {S.ndim}-d score")
    check_finite_array(S, "accepted scores")
    _check_matching_result(res, *S.shape)


@pytest.mark.parametrize("method", ["sm", "rrwm", "ipfp", "ga", "pf", "hungarian", "sinkhorn"])
@settings(COSTLY, max_examples=10)
@given(case=point_graph_pairs(), use_unary=st.booleans())
@example(case=(np.array([[0.0, 0.0], [1.0, 0.1], [0.2, 0.9], [0.8, 0.7], [0.4, 0.3]]),
               np.array([2, 0, 4, 1, 3]), 1e9), use_unary=False)      # issue 13 item 7
def test_match_graphs_on_permuted_points(method, case, use_unary):
    """g2 is g1 permuted (and both scaled): a quadratic answer of objective 0 means the affinity
    underflowed (issue 13 item 7) and must be rescaled, refused or at least warned about."""
    from transync import match_graphs
    from transync.graphs import Graph

    pts, perm, scale = case
    g1 = call(Graph.from_points, pts * scale, edges="full")
    if g1 is REFUSED:
        return
    g2 = call(Graph.from_points, (pts * scale)[np.argsort(perm)] if pts.size else pts,
              edges="full")
    if g2 is REFUSED:
        return
    n = pts.shape[0]
    unary = np.ones((n, n)) if use_unary else None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = call(match_graphs, g1, g2, method=method, node_affinity=unary)
    if res is REFUSED:
        return
    _check_matching_result(res, n, n)
    if method not in ("hungarian", "sinkhorn") and g1.n_edges > 0 and not caught:
        check(res.objective > 0, f"objective {res.objective} on graphs with {g1.n_edges} "
                                 f"edges at scale {scale}: the affinity underflowed silently")


@MEDIUM
@given(data=st.data(), model=st.sampled_from(["affine", "similarity", "homography", "bogus"]),
       threshold=st.sampled_from([0.5] * 6 + [0.0, -1.0, 1e-12, 1e9, np.inf, np.nan, "x"]),
       min_inliers=st.sampled_from([None] * 6 + [0, 2, 4, 100, 2.5]))
def test_verify_assignment(data, model, threshold, min_inliers):
    """Points of any scale (coincident, collinear, huge, NaN), any putative map: a verified map
    that is an injective partial map with only finite transforms, or a named refusal."""
    from transync.matching import verify_assignment

    n1, n2 = data.draw(st.integers(0, 7)), data.draw(st.integers(0, 7))
    kind = data.draw(st.sampled_from(["random"] * 4 + ["same", "collinear", "nasty", "junk"]))
    scale = data.draw(st.sampled_from([1.0, 1.0, 1e-300, 1e-160, 1e-12, 1e-6, 1e6, 1e11, 1e13]))
    if kind == "junk":
        p1, p2 = data.draw(any_arrays(max_dims=2)), data.draw(any_arrays(max_dims=2))
    elif kind == "nasty":
        p1, p2 = data.draw(float_arrays((n1, 2))), data.draw(float_arrays((n2, 2)))
    else:
        p1 = data.draw(float_arrays((n1, 2), elements=tame_floats)) * scale
        p2 = data.draw(float_arrays((n2, 2), elements=tame_floats)) * scale
        if kind == "same":
            p2 = np.ones((n2, 2)) * scale
        elif kind == "collinear":
            p1[:, 1] = p1[:, 0]
    a, _ = data.draw(assignments(n1=np.shape(p1)[0] if np.ndim(p1) else 0,
                                 n2=np.shape(p2)[0] if np.ndim(p2) else 0))
    res = call(verify_assignment, p1, p2, a, model=model, threshold=threshold,
               min_inliers=min_inliers, rng=0)
    if res is REFUSED:
        return
    P1, P2 = np.asarray(p1, dtype=float), np.asarray(p2, dtype=float)
    check(P1.ndim == 2 and P1.shape[1] == 2 and P2.ndim == 2 and P2.shape[1] == 2,
          f"accepted points of shapes {P1.shape}, {P2.shape}")
    check_finite_array(P1, "accepted points1")
    check_finite_array(P2, "accepted points2")
    out = res.assignment
    check(out.shape == (len(P1),) and out.dtype.kind == "i", f"assignment shape {out.shape}")
    m = out[out >= 0]
    check(bool(np.all(out >= -1)) and bool(np.all(m < len(P2))), "assignment out of range")
    check(np.unique(m).size == m.size, "verified map not injective")
    check(res.n_inliers == m.size, f"n_inliers {res.n_inliers} for {m.size} matches")
    check(res.verified == (m.size > 0), f"verified={res.verified} with {m.size} matches")
    if res.verified:
        check_finite_array(res.transform, "transform of a verified map")
    check(res.transform.shape == (3, 3) and np.isfinite(res.threshold) and res.threshold >= 0,
          "transform shape or threshold")


@COSTLY
@given(method=st.sampled_from(["rrwm", "sm", "hungarian", "bogus"]),
       options=st.dictionaries(st.sampled_from(["maxiter", "max_iter", "tol", "n1", "variant",
                                                "beta", "warm_start"]),
                               st.sampled_from([5, -1, 0, np.nan, "x", 1e-6, True, False,
                                                "pygmtools"]), max_size=2))
@example(method="rrwm", options={"maxiter": 5})                      # issue 9 item 10
def test_match_graphs_options(method, options):
    """Unknown or bad options are refused at the front door with the accepted ones listed."""
    from transync import match_graphs
    from transync.graphs import Graph

    g = Graph.from_points(np.array([[0.0, 0.0], [1.0, 0.2], [0.3, 1.0], [0.9, 0.8]]),
                          edges="full")
    res = call(match_graphs, g, g, method=method, node_affinity=np.eye(4), **options)
    if res is REFUSED:
        return
    check(method != "bogus", "accepted method='bogus'")
    _check_matching_result(res, 4, 4)


@MEDIUM
@given(A=st.one_of(st.tuples(st.integers(1, 3), st.integers(1, 4), st.integers(1, 4)).flatmap(
           lambda shape: float_arrays(shape, elements=st.floats(1e-3, 1e3))), any_arrays()),
       warm=st.one_of(st.none(), st.just("same"), any_arrays(max_dims=2)),
       domain=st.sampled_from(["scaling", "scaling", "log"]))
def test_sinkhorn_batch(A, warm, domain):
    """Kernels and warm starts of any kind: normalised stacks with their scalings, or refused."""
    from transync.matching import sinkhorn_batch

    if isinstance(warm, str):     # a valid warm start for A, when A is a stack
        shape = np.shape(A)
        warm = np.ones((shape[0], max(shape[1:]))) * 2.0 if len(shape) == 3 else None
    res = call(sinkhorn_batch, A, tol=1e-6, max_iter=50, domain=domain, warm_start=warm)
    if res is REFUSED:
        return
    X, n_sweeps, converged, scaling = res
    A = np.asarray(A)
    check(A.ndim == 3 and X.shape == A.shape, f"accepted A of shape {A.shape}")
    check_finite_array(X, "X")
    check(bool(np.all(X >= 0)), "negative entries in X")
    check(n_sweeps.shape == converged.shape == (A.shape[0],), "per-matrix counts")
    if domain == "log":
        check(scaling is None and warm is None, "log domain with a scaling / warm start")
    else:
        check(scaling.shape == (A.shape[0], max(A.shape[1:])), f"scaling {scaling.shape}")
        check_finite_array(scaling, "scaling")


def _clean_adjacency(n):
    """Symmetric non-negative weights with a zero diagonal, at a nasty scale."""
    def build(W, scale):
        W = np.triu(W, 1)
        with np.errstate(all="ignore"):
            return (W + W.T) * scale
    return st.builds(build, float_arrays((n, n), elements=tame_floats), SCALES)


@MEDIUM
@given(method=st.sampled_from(["rrwm", "sm", "ipfp", "hungarian", "sinkhorn"]),
       sigma2=st.sampled_from([0.15] * 8 + [0.0, -1.0, np.nan, np.inf, 1e-300, 1e300, "x"]),
       node_affinity=st.one_of(st.none(), st.none(), float_arrays((4, 4), elements=tame_floats),
                               float_arrays((4, 4)), any_arrays(max_dims=2)))
def test_match_graphs_sigma2_and_node_affinity(method, sigma2, node_affinity):
    from transync import match_graphs
    from transync.graphs import Graph

    g = Graph.from_points(np.array([[0.0, 0.0], [1.0, 0.2], [0.3, 1.0], [0.9, 0.8]]),
                          edges="full")
    res = call(match_graphs, g, g, method=method, sigma2=sigma2, node_affinity=node_affinity)
    if res is REFUSED:
        return
    check(isinstance(sigma2, float) and np.isfinite(sigma2) and sigma2 > 0,
          f"accepted sigma2={sigma2!r}")
    if node_affinity is not None:
        check_finite_array(node_affinity, "accepted node_affinity")
        check(np.shape(node_affinity) == (4, 4), f"accepted node_affinity of shape "
                                                 f"{np.shape(node_affinity)}")
    _check_matching_result(res, 4, 4)


@MEDIUM
@given(adj=st.one_of(st.integers(0, 4).flatmap(lambda n: float_arrays((n, n))), any_arrays(),
                    *[st.integers(1, 5).flatmap(_clean_adjacency)] * 3),
       points=st.one_of(st.none(), any_arrays(max_dims=2)),
       directed=st.booleans())
def test_graph_construction(adj, points, directed):
    from transync.graphs import Graph

    g = call(Graph, adj, points=points, directed=directed)
    if g is REFUSED:
        return
    A = np.asarray(g.adjacency)
    check(A.ndim == 2 and A.shape[0] == A.shape[1], f"adjacency shape {A.shape}")
    check_finite_array(A, "adjacency")
    check(g.n_nodes == A.shape[0], "n_nodes")
    check(bool(np.all(np.diag(A) == 0)), "self-loops accepted")
    if not directed:
        check(bool(np.array_equal(A, A.T)), "undirected graph with asymmetric adjacency")
    if g.points is not None:
        check(np.shape(g.points)[0] == g.n_nodes, "points do not match the nodes")
        check_finite_array(g.points, "points")


@MEDIUM
@given(points=st.one_of(st.integers(0, 6).flatmap(lambda n: float_arrays((n, 2))), any_arrays()),
       edges=st.sampled_from(["delaunay", "full", "knn", "bogus"]),
       k=st.sampled_from([5, 1, 0, -1, 100]))
def test_graph_from_points(points, edges, k):
    from transync.graphs import Graph

    g = call(Graph.from_points, points, edges=edges, k=k)
    if g is REFUSED:
        return
    check_finite_array(points, "accepted points")
    A = np.asarray(g.adjacency)
    check(A.shape == (len(points),) * 2, f"adjacency shape {A.shape}")
    check_finite_array(A, "adjacency")


# ------------------------------------------------------------------------------- synchronization

def _check_labels(labels, sizes, d, what="labels"):
    check(len(labels) == len(sizes), f"{what}: {len(labels)} objects, expected {len(sizes)}")
    for g, (lab, n) in enumerate(zip(labels, sizes)):
        lab = np.asarray(lab)
        check(lab.shape == (n,), f"{what}[{g}]: shape {lab.shape}, expected ({n},)")
        check_assignment(lab, n, d, f"{what}[{g}]")


@pytest.mark.parametrize("method", ["spectral", "orthogonal", "matcheig"])
@COSTLY
@given(pw_sizes=pairwise_dicts(), n_universe=N_UNIVERSE, pass_sizes=st.booleans())
@example(pw_sizes=({(0, 1): np.array([np.nan, 0, 1])}, [3, 3]), n_universe=None,
         pass_sizes=False)                                           # issue 13 item 6
@example(pw_sizes=({(0, 1): np.array(["a", "b"])}, [2, 2]), n_universe=None, pass_sizes=False)
@example(pw_sizes=({(0, 1): np.array([1, 0])}, [2, 2]), n_universe=10**9,
         pass_sizes=False)                                           # issue 13 item 5
@example(pw_sizes=({(2, 1): np.array([0]), (0, 1): np.array([-1])}, [1, 1, 1, 0]),
         n_universe=None, pass_sizes=False)
def test_synchronize_permutations(method, pw_sizes, n_universe, pass_sizes):
    from transync import synchronize_permutations

    pw, sizes = pw_sizes
    res = call(synchronize_permutations, pw, method=method, n_universe=n_universe, max_iter=10,
               sizes=sizes if pass_sizes else None)
    if res is REFUSED:
        return
    d = res.n_universe
    check(isinstance(d, (int, np.integer)) and d >= 0, f"n_universe {d!r}")
    if pass_sizes:
        check([len(lab) for lab in res.labels] == sizes, "labels do not follow `sizes`")
    check(d <= max(sum(len(lab) for lab in res.labels), 0) or d == n_universe,
          f"universe {d} larger than the number of nodes")
    _check_labels(res.labels, [len(lab) for lab in res.labels], d)
    for (i, j), obs in pw.items():
        n_i, n_j = len(res.labels[i]), len(res.labels[j])
        p = call(res.pairwise, i, j)
        check(p is not REFUSED, f"pairwise({i}, {j}) refused on an observed pair")
        check_assignment(p, n_i, n_j, f"pairwise({i}, {j})")
        if res.cycle_consistent:
            li, lj = np.asarray(res.labels[i]), np.asarray(res.labels[j])
            want = np.array([int(np.flatnonzero(lj == u)[0]) if u >= 0 and np.any(lj == u)
                             else -1 for u in li], dtype=np.int64)
            check(bool(np.array_equal(p, want)), f"pairwise({i}, {j}) disagrees with labels")
    check_finite_scalar(res.objective, "objective")
    check(res.cycle_consistent or method == "matcheig", "cycle_consistent is False")


@MEDIUM
@given(method=st.sampled_from(["spectral", "orthogonal", "matcheig"]),
       weights=st.one_of(st.none(), float_arrays((3, 3)), float_arrays((3, 3),
                                                                       elements=tame_floats),
                         any_arrays(max_dims=2)),
       mask=st.one_of(st.none(), hnp.arrays(np.bool_, (3, 3)), any_arrays(max_dims=2)))
def test_synchronize_permutations_weights_and_mask(method, weights, mask):
    from transync import synchronize_permutations

    pw = {(0, 1): np.array([1, 0, 2]), (1, 2): np.array([2, 0, 1]), (0, 2): np.array([2, 1, 0])}
    res = call(synchronize_permutations, pw, method=method, weights=weights, mask=mask)
    if res is REFUSED:
        return
    if weights is not None:
        check_finite_array(weights, "accepted weights")
        w = np.asarray(weights, dtype=float)
        check(w.size == 0 or bool(np.all(w >= 0)), "accepted negative weights")
    _check_labels(res.labels, [3, 3, 3], res.n_universe)
    check_finite_scalar(res.objective, "objective")


@COSTLY
@given(pw_sizes=pairwise_dicts(soft=True), n_universe=N_UNIVERSE,
       max_iter=st.sampled_from([20, 3, 1, 0, -1]))
@example(pw_sizes=({(0, 1): 0.8 * np.eye(3) + 0.2 * np.eye(3)[[1, 0, 2]], (1, 2): np.eye(3)},
                   [3, 3, 3]), n_universe=None, max_iter=0)          # issue 13 item 16
def test_synchronize_doubly_stochastic(pw_sizes, n_universe, max_iter):
    from transync import synchronize_doubly_stochastic

    pw, sizes = pw_sizes
    res = call(synchronize_doubly_stochastic, pw, n_universe=n_universe, max_iter=max_iter)
    if res is REFUSED:
        return
    w = np.asarray(res.weights, dtype=float)
    check_finite_array(w, "weights")
    check(bool(np.all(w >= 0)) and abs(w.sum() - 1) < 1e-6, f"weights {w} not convex")
    d = res.n_universe
    _check_labels(res.labels, [len(lab) for lab in res.labels], d)
    for (i, j), Y in res.blocks.items():
        Y = np.asarray(Y, dtype=float)
        check_finite_array(Y, f"block {(i, j)}")
        check(bool(np.all(Y >= -1e-9)), f"block {(i, j)} has negative entries")
        check(bool(np.all(Y.sum(0) <= 1 + 1e-6) and np.all(Y.sum(1) <= 1 + 1e-6)),
              f"block {(i, j)} is not sub-doubly-stochastic")
        ni, nj = Y.shape
        if ni == nj == d:
            check(bool(np.allclose(Y.sum(0), 1, atol=1e-6) and np.allclose(Y.sum(1), 1,
                                                                           atol=1e-6)),
                  f"block {(i, j)} is not doubly stochastic (equal sizes, d = n)")
    if max_iter == 0:
        check(res.n_iter == 0, "n_iter > max_iter")


@MEDIUM
@given(X=st.one_of(*[st.integers(1, 4).flatmap(
    lambda n: st.lists(st.tuples(st.permutations(list(range(n))), tame_floats), min_size=1,
                       max_size=3).map(lambda terms: _mix(terms, n)))] * 3,
    any_arrays(max_dims=2)),
    max_terms=st.sampled_from([None] * 8 + [0, 1, -1, 10**9]),
    tol=st.sampled_from([1e-9] * 8 + [0.0, -1.0, np.nan, 0.5]))
@example(X=np.full((3, 3), 1 / 3), max_terms=0, tol=1e-9)           # issue 13 item 16
def test_birkhoff_von_neumann(X, max_terms, tol):
    from transync import birkhoff_von_neumann

    out = call(birkhoff_von_neumann, X, max_terms=max_terms, tol=tol)
    if out is REFUSED:
        return
    w, P = out
    X = np.asarray(X, dtype=float)
    n = X.shape[0]
    w = np.asarray(w, dtype=float)
    check_finite_array(w, "weights")
    check(bool(np.all(w > 0)), f"non-positive weights {w}")
    check(abs(w.sum() - 1) <= max(n * tol, 1e-6) + 1e-6, f"weights sum to {w.sum()}, not 1")
    recon = np.zeros((n, n))
    for wk, p in zip(w, np.asarray(P)):
        check_assignment(p, n, n, "permutation")
        check(bool(np.all(p >= 0)), "partial permutation in a BvN decomposition")
        recon += wk * permutations.assignment_to_matrix(p, n)
    check(bool(np.allclose(recon, X, atol=1e-5)), "decomposition does not reconstruct X")


def _mix(terms, n):
    w = np.array([t[1] for t in terms]) + 1e-3
    w = w / w.sum()
    X = np.zeros((n, n))
    for wk, (p, _) in zip(w, terms):
        X[np.arange(n), p] += wk
    return X


MAPS = st.one_of(
    st.integers(0, 4).flatmap(lambda n: float_arrays((n, n, 3, 3))),
    st.integers(0, 4).flatmap(lambda n: float_arrays((n, n, 3, 3), elements=tame_floats)),
    st.integers(0, 4).flatmap(lambda n: st.sampled_from([0.0, np.nan, 1e-300, 1e300]).map(
        lambda v: np.full((n, n, 3, 3), v))),
    st.integers(1, 4).flatmap(lambda n: float_arrays((n, n, 2, 2), elements=tame_floats)),
    any_arrays(max_dims=4),
)


def _planted_maps(n, rng_seed, d=3):
    rng = np.random.default_rng(rng_seed)
    M = np.eye(d) + 0.1 * rng.standard_normal((n, d, d))
    return np.einsum("iab,jbc->ijac", M, np.linalg.inv(M))


@pytest.mark.parametrize("fn_name", ["synchronize_linear_maps", "synchronize_homographies"])
@COSTLY
@given(T=st.one_of(MAPS, *[st.integers(1, 4).flatmap(
    lambda n: st.integers(0, 10).map(lambda s: _planted_maps(n, s)))] * 5),
       reference=st.sampled_from([0] * 6 + [1, -1, 5]), robust=st.booleans(),
       disconnected=st.sampled_from(["raise", "component"]))
@example(T=np.zeros((3, 3, 3, 3)), reference=0, robust=False,
         disconnected="raise")                                       # issue 13 item 4
@example(T=np.zeros((0, 0, 3, 3)), reference=0, robust=False, disconnected="raise")
@example(T=np.full((2, 2, 3, 3), np.nan), reference=0, robust=False, disconnected="raise")
def test_synchronize_maps(fn_name, T, reference, robust, disconnected):
    fn = getattr(transync, fn_name)
    res = call(fn, T, reference=reference, robust=robust, disconnected=disconnected)
    if res is REFUSED:
        return
    maps = np.asarray(res.maps, dtype=float)
    N = maps.shape[0]
    excluded = set(np.asarray(res.info.get("excluded", []), dtype=int).tolist())
    keep = [i for i in range(N) if i not in excluded]
    check(len(keep) > 0, "no object kept")
    check_finite_array(maps[keep], "maps")
    check(bool(np.allclose(maps[res.reference], np.eye(maps.shape[-1]), atol=1e-8)),
          "maps[reference] is not the identity")
    for i in keep:
        check(abs(np.linalg.det(maps[i])) > 0, f"maps[{i}] is singular")
    kept = (res.weights > 0) & res.mask
    if np.isfinite(res.residuals[kept]).any() or not kept.any():   # inf: every corner residual
        check_finite_scalar(res.objective, "objective")              # at infinity (documented)


# ----------------------------------------------------------------------------------- datasets

# mostly legal values, so that a good share of calls reaches the result checks
BAD_INTS = st.sampled_from([2, 3, 4] * 8 + [-1, 0, 1, 2.5, np.nan, None, "3", 10**9])
BAD_FRACTIONS = st.sampled_from([0.0, 0.3, 1.0] * 8 + [-0.1, 1.5, np.nan, np.inf, "x"])


@MEDIUM
@given(n_objects=BAD_INTS, n_nodes=BAD_INTS, corruption=BAD_FRACTIONS, visibility=BAD_FRACTIONS,
       observed=BAD_FRACTIONS, n_universe=N_UNIVERSE)
def test_make_permutation_collection(n_objects, n_nodes, corruption, visibility, observed,
                                     n_universe):
    from transync.datasets import make_permutation_collection

    pc = call(make_permutation_collection, n_objects, n_nodes, corruption=corruption,
              visibility=visibility, observed=observed, n_universe=n_universe, rng=0)
    if pc is REFUSED:
        return
    check(pc.n_objects == n_objects, "n_objects")
    sizes = [int(n) for n in pc.sizes]
    _check_labels(pc.labels, sizes, pc.n_universe, "truth labels")
    for (i, j), a in pc.pairwise.items():
        check(0 <= i < n_objects and 0 <= j < n_objects and i != j, f"pair {(i, j)}")
        check_assignment(a, sizes[i], sizes[j], f"observed {(i, j)}")


@COSTLY
@given(n_graphs=BAD_INTS, n_inliers=BAD_INTS,
       n_outliers=st.sampled_from([0] * 6 + [1, -1, 2.5]),
       deformation=BAD_FRACTIONS, density=BAD_FRACTIONS)
def test_make_graph_collection(n_graphs, n_inliers, n_outliers, deformation, density):
    from transync.datasets import make_graph_collection

    if isinstance(n_graphs, int) and isinstance(n_inliers, int) and n_graphs * n_inliers > 200:
        n_graphs = 3
    gc = call(make_graph_collection, n_graphs, n_inliers, n_outliers, deformation, density, rng=0)
    if gc is REFUSED:
        return
    check(len(gc.graphs) == n_graphs, "number of graphs")
    for g in gc.graphs:
        check_finite_array(g.adjacency, "adjacency")
    _check_labels(gc.labels, [g.n_nodes for g in gc.graphs], gc.n_universe, "truth labels")


@MEDIUM
@given(generator=st.sampled_from(["make_pairwise_problem", "make_point_matching_problem"]),
       n_inliers=BAD_INTS, n_outliers=st.sampled_from([0] * 6 + [1, -1, 2.5, None]),
       deformation=BAD_FRACTIONS)
def test_make_pairwise_problems(generator, n_inliers, n_outliers, deformation):
    from transync import datasets

    if n_inliers == 10**9:
        n_inliers = 5
    pp = call(getattr(datasets, generator), n_inliers, n_outliers, deformation, rng=0)
    if pp is REFUSED:
        return
    n1, n2 = pp.g1.n_nodes, pp.g2.n_nodes
    check_assignment(pp.truth, n1, n2, "truth")
    check_finite_array(pp.g1.adjacency, "g1.adjacency")


@MEDIUM
@given(generator=st.sampled_from(["make_noisy_linear_maps", "make_noisy_homographies"]),
       n=BAD_INTS, noise=BAD_FRACTIONS, outliers=BAD_FRACTIONS, density=BAD_FRACTIONS)
def test_make_noisy_maps(generator, n, noise, outliers, density):
    from transync import datasets

    if n == 10**9:
        n = 4
    tp = call(getattr(datasets, generator), n, noise=noise, outlier_fraction=outliers,
              density=density, rng=0)
    if tp is REFUSED:
        return
    check_finite_array(tp.truth, "truth")
    mask = np.asarray(tp.mask, dtype=bool)
    check_finite_array(np.asarray(tp.observed)[mask], "observed maps")


@COSTLY
@given(n_views=st.sampled_from([2] * 5 + [1, 0, -1, 2.5]),
       image_size=st.sampled_from([(64, 48)] * 5 + [(0, 0), (-5, 10), (np.nan, 10), (3, 3),
                                                     "ab"]),
       difficulty=st.sampled_from(["easy", "moderate"] * 3 + ["bogus"]),
       noise=st.sampled_from([2.0, 0.0] * 3 + [-1.0, np.nan]))
def test_make_planar_scene(n_views, image_size, difficulty, noise):
    from transync.datasets import make_planar_scene

    sc = call(make_planar_scene, n_views, image_size=image_size, difficulty=difficulty,
              noise=noise, rng=0)
    if sc is REFUSED:
        return
    check(len(sc.images) == n_views, "number of images")
    check_finite_array(sc.homographies, "homographies")


# ----------------------------------------------------------------------------------- geometry

@CHEAP
@given(H_ARRAYS)
def test_normalize_determinant(A):
    out = call(geometry.normalize_determinant, A)
    if out is REFUSED:
        return
    A = np.asarray(A, dtype=float)
    check(out.shape == A.shape, "shape changed")
    if A.ndim < 2 or A.size == 0:
        return
    flat_A, flat_out = A.reshape(-1, *A.shape[-2:]), out.reshape(-1, *A.shape[-2:])
    for a, o in zip(flat_A, flat_out):
        if not np.all(np.isfinite(a)):
            check(bool(np.all(np.isnan(o))), f"non-finite input {a.tolist()} came back as "
                                             f"{o.tolist()} (documented: NaN)")
            continue
        sv = np.linalg.svd(a, compute_uv=False)
        if sv[-1] <= sv[0] * 1e-15:     # singular beyond the documented 1e14 condition number
            check(bool(np.all(np.isnan(o))), f"singular input {a.tolist()} came back as "
                                             f"{o.tolist()} (documented: NaN)")
            continue
        if sv[-1] <= sv[0] * 1e-13 and np.all(np.isnan(o)):     # at the threshold: either
            continue
        check_finite_array(o, f"normalize_determinant({a.tolist()})")
        sign, logdet = np.linalg.slogdet(o)
        # documented: for even d a negative determinant cannot be scaled to +1 and becomes -1
        want_sign = 1.0 if a.shape[-1] % 2 else float(np.sign(np.linalg.det(a)))
        check(sign == want_sign and abs(logdet) < 1e-6, f"normalize_determinant({a.tolist()}) has "
                                               f"determinant {sign * np.exp(logdet)}, not 1")


@CHEAP
@given(SIZES)
def test_image_corners_and_normalization_matrix(size):
    for fn in (geometry.image_corners, geometry.normalization_matrix):
        out = call(fn, size)
        if out is REFUSED:
            continue
        check_finite_array(out, fn.__name__)
        check(isinstance(size, tuple) and len(size) == 2 and min(size) >= 1,
              f"{fn.__name__} accepted size {size!r}")


@CHEAP
@given(H_ARRAYS, st.one_of(st.integers(0, 4).flatmap(lambda k: float_arrays((k, 2))),
                           any_arrays()))
def test_transfer_points(H, points):
    out = call(geometry.transfer_points, H, points)
    if out is REFUSED:
        return
    check(np.shape(out)[-1] == 2, f"output shape {np.shape(out)}")


@CHEAP
@given(st.one_of(st.integers(0, 5).flatmap(lambda k: float_arrays((k, 2))), any_arrays()))
def test_hartley_normalization(points):
    out = call(geometry.hartley_normalization, points)
    if out is REFUSED:
        return
    T, x = out
    check_finite_array(T, "T")
    check_finite_array(x, "normalized points")
    # T = [[s, 0, tx], [0, s, ty], [0, 0, 1]]: regular when s != 0 (its determinant s^2
    # overflows for point sets of 1e-175, which the normalization handles)
    check(T[0, 0] != 0 and T[1, 1] != 0 and T[2, 2] == 1 and T[1, 0] == T[0, 1] == 0,
          "singular normalization")


@CHEAP
@given(nasty_floats, st.one_of(nasty_floats, st.sampled_from(["1", None])))
def test_translation(tx, ty):
    out = call(geometry.translation, tx, ty)
    if out is REFUSED:
        return
    check_finite_array(out, "translation")


# ----------------------------------------------------------------------------------- kernels

@st.composite
def node_feature_lists(draw):
    """(features, n): up to 4 graphs' node features (some nasty or empty), a padded size n."""
    N = draw(st.integers(0, 4))
    f = draw(st.integers(1, 2))
    sizes = [draw(st.sampled_from([1, 2, 3] * 3 + [0])) for _ in range(N)]
    nasty = draw(st.integers(0, 3)) == 0
    feats = [draw(float_arrays((m, f), elements=nasty_floats if nasty else
                               st.floats(-2, 2, allow_nan=False, width=64))) for m in sizes]
    n = max(sizes, default=1) + draw(st.sampled_from([0, 0, 0, 1, -1]))
    return feats, n


@st.composite
def slot_maps(draw, N, n):
    """(pairs, assignments, kind): all pairs of N graphs with a map of range(n) each -- induced
    by one labelling ("transitive"), arbitrary permutations ("random", pairs possibly reversed),
    or "junk" that must be refused (non-permutations, a missing or a repeated pair)."""
    kind = draw(st.sampled_from(["transitive", "random", "random", "junk"]))
    iu, ju = np.triu_indices(N, 1)
    pairs = np.column_stack([iu, ju]).astype(np.int64)
    m = max(n, 0)
    if kind == "transitive":
        labels = np.array([draw(st.permutations(list(range(m)))) for _ in range(N)],
                          dtype=np.int64).reshape(N, m)
        inv = np.argsort(labels, axis=1)
        A = inv[ju[:, None], labels[iu]] if len(pairs) else np.zeros((0, m), np.int64)
    else:
        A = np.array([draw(st.permutations(list(range(m)))) for _ in range(len(pairs))],
                     dtype=np.int64).reshape(len(pairs), m)
    if kind == "junk":
        what = draw(st.sampled_from(["entries", "drop", "repeat", "flip"]))
        if what == "entries" and A.size:
            A = draw(hnp.arrays(np.int64, A.shape, elements=st.integers(-1, m + 1)))
            if np.all(np.sort(A, axis=1) == np.arange(m)):
                kind = "random"                    # drew valid maps after all
        elif what == "drop" and len(pairs):
            pairs, A = pairs[1:], A[1:]
        elif what == "repeat" and len(pairs):
            pairs, A = np.r_[pairs, pairs[:1, ::-1]], np.r_[A, A[:1]]
        elif what == "flip" and len(pairs):
            pairs = pairs[:, ::-1].copy()          # valid: the maps read the other way
            kind = "random"
        else:
            kind = "random"                        # nothing to spoil: no pairs, no entries
    return pairs, A, kind


def _check_kernel_matrix(K, N, what, psd=False):
    check_finite_array(K, what)
    check(K.shape == (N, N), f"{what}: shape {K.shape}, expected ({N}, {N})")
    check(bool(np.array_equal(K, K.T)), f"{what}: not exactly symmetric")
    if psd and N:
        ev = np.linalg.eigvalsh(K)
        check(ev[0] >= -1e-9 * max(abs(ev).max(), 1.0), f"{what}: not PSD (lambda_min {ev[0]})")


@MEDIUM
@given(node_feature_lists(), st.data(), st.sampled_from(["linear", "gaussian", "relaxed"]),
       st.sampled_from([None] * 4 + [1.0, 0.0, -1.0, np.nan, np.inf, 1e300]),
       st.sampled_from([True, True, False]))
def test_transitive_kernel_stages(feats_n, data, kernel, gamma, normalize):
    """aligned_features -> median_gamma -> assignment_kernel on any features and labels: a
    finite, exactly symmetric, PSD Gram matrix, or a named refusal."""
    from transync import kernels as tk

    feats, n = feats_n
    N = len(feats)
    if data.draw(st.booleans()):
        labels = np.array([data.draw(st.permutations(list(range(max(n, 0)))))
                           for _ in range(N)], dtype=np.int64).reshape(N, max(n, 0))
    else:
        labels = data.draw(hnp.arrays(np.int64, (N, max(n, 0)), elements=st.integers(-1, n)))
    X = call(tk.aligned_features, feats, labels, n)
    if X is REFUSED:
        return
    check_finite_array(X, "aligned_features")
    check(X.shape == (N, n, feats[0].shape[1] + 1), f"aligned_features: shape {X.shape}")
    check(bool(np.all(X[..., -1].sum(1) == [len(F) for F in feats])),
          "aligned_features: real-node indicators do not count each graph's nodes")
    g = call(tk.median_gamma, X)
    if g is not REFUSED:
        check_finite_scalar(g, "median_gamma")
        check(g > 0, f"median_gamma: {g} <= 0")
    gam = gamma if kernel == "gaussian" else data.draw(st.sampled_from([None, None, 1.0]))
    K = call(tk.assignment_kernel, X, kernel=kernel, gamma=gam, normalize=normalize)
    if K is REFUSED:
        return
    _check_kernel_matrix(K, N, "assignment_kernel", psd=True)


@MEDIUM
@given(node_feature_lists(), st.data(), st.sampled_from(["linear", "gaussian", "relaxed"]),
       st.sampled_from([None] * 4 + [1.0, 0.0, -1.0, np.nan, 1e300]),
       st.sampled_from([True, True, False]))
def test_pairwise_assignment_kernel(feats_n, data, kernel, gamma, normalize):
    """Any maps: a finite, exactly symmetric matrix (PSD when the maps are transitive), or a
    named refusal -- missing, repeated or non-permutation maps among them."""
    from transync import kernels as tk

    feats, n = feats_n
    pairs, A, kind = data.draw(slot_maps(len(feats), n))
    K = call(tk.pairwise_assignment_kernel, feats, A, pairs, kernel=kernel,
             gamma=gamma if kernel == "gaussian" else None, normalize=normalize)
    if K is REFUSED:
        return
    check(kind != "junk", "pairwise_assignment_kernel: accepted junk maps or pairs")
    _check_kernel_matrix(K, len(feats), "pairwise_assignment_kernel",
                         psd=kind == "transitive" and bool(np.isfinite(
                             np.concatenate([F.ravel() for F in feats])).all()))


@MEDIUM
@given(node_feature_lists(), st.sampled_from([None] * 3 + [1.0, 0.0, -1.0, np.nan, 1e-300]),
       st.booleans())
def test_hks_baseline_kernels(feats_n, sigma2, labelled):
    """hks_oa_kernel and hks_mean_kernel on any features (and labels)."""
    from transync import kernels as tk

    feats, _ = feats_n
    labels = [np.arange(len(F)) % 2 for F in feats] if labelled else None
    K = call(tk.hks_oa_kernel, feats, sigma2=sigma2, node_labels=labels)
    if K is not REFUSED:
        _check_kernel_matrix(K, len(feats), "hks_oa_kernel")
        check(bool(np.allclose(np.diag(K), 1.0)), "hks_oa_kernel: diagonal not 1")
    K = call(tk.hks_mean_kernel, feats, node_labels=labels)
    if K is not REFUSED:
        _check_kernel_matrix(K, len(feats), "hks_mean_kernel", psd=True)


@MEDIUM
@given(st.one_of(any_arrays(max_dims=2, max_side=5),
                 hnp.arrays(np.float64, st.integers(1, 5).map(lambda m: (m, m)),
                            elements=st.sampled_from([0.0, 0.0, 1.0, 2.0, -1.0, np.nan]))),
       st.sampled_from([None, None, [0.1, 1.0], [1.0], [], [0.0, 1.0], [-1.0], [np.nan],
                        [1e300]]))
def test_heat_kernel_signature(adj, times):
    """Any adjacency (asymmetric, negative, NaN, non-square, any dtype) and time grid."""
    from transync import kernels as tk

    H = call(tk.heat_kernel_signature, adj, times)
    if H is REFUSED:
        return
    check_finite_array(H, "heat_kernel_signature")
    check(H.ndim == 2 and H.shape[0] == np.shape(adj)[0],
          f"heat_kernel_signature: shape {H.shape} for an adjacency of shape {np.shape(adj)}")


@st.composite
def small_graphs(draw, labelled=None):
    """An undirected graph of 0..5 nodes (isolated nodes and components allowed), labelled or
    not."""
    from transync.graphs import Graph

    n = draw(st.sampled_from([1, 2, 3, 4, 5] * 3 + [0]))
    upper = draw(hnp.arrays(np.bool_, (n, n)))
    A = np.triu(upper, 1)
    A = (A | A.T).astype(float)
    labelled = draw(st.booleans()) if labelled is None else labelled
    labels = draw(hnp.arrays(np.int64, n, elements=st.integers(0, 2))) if labelled else None
    return Graph(A, node_labels=labels) if n else A


@COSTLY
@given(st.booleans().flatmap(lambda lab: st.tuples(
           st.lists(small_graphs(labelled=lab), min_size=0, max_size=5),
           st.lists(small_graphs(), min_size=0, max_size=2))),
       st.sampled_from(["node", "sm", "rrwm"]), st.sampled_from(["orthogonal", "spectral"]),
       st.sampled_from(["linear", "gaussian", "relaxed"]),
       st.sampled_from([None, None, 1, 3]), st.sampled_from([1, 1, 2]))
def test_transitive_assignment_kernel_estimator(collections, matcher, sync, kernel, k, R):
    """fit_transform on any small graphs: a finite, symmetric, PSD Gram matrix with unit
    diagonal; transform of new graphs: finite rows in [-1, 1]; or a named refusal (empty
    collections, graphs without nodes, graphs larger than the fitted universe)."""
    from transync.kernels import TransitiveAssignmentKernel

    graphs, new = collections
    est = TransitiveAssignmentKernel(matcher=matcher, sync=sync, kernel=kernel, n_neighbors=k,
                                     n_alignments=R, random_state=0)
    K = call(est.fit_transform, graphs)
    if K is REFUSED:
        return
    N = len(graphs)
    _check_kernel_matrix(K, N, "TransitiveAssignmentKernel.fit_transform", psd=True)
    check(bool(np.allclose(np.diag(K), 1.0)), f"fit_transform: diagonal {np.diag(K)}")
    T = call(est.transform, new)
    if T is REFUSED:
        return
    check_finite_array(T, "TransitiveAssignmentKernel.transform")
    check(T.shape == (len(new), N), f"transform: shape {T.shape}, expected ({len(new)}, {N})")
    check(bool(np.all(np.abs(T) <= 1 + 1e-9)), "transform: normalized entries outside [-1, 1]")


INT_ARGS = [0, -1, 1, 2, 3, 10**9, 1.5, True, np.int64(2), None, "2"]


def _check_permutation_rows(a, n, what):
    a = np.asarray(a)
    check(a.dtype.kind in "iu", f"{what}: dtype {a.dtype}, expected integers")
    check(a.shape[-1:] == (n,), f"{what}: shape {a.shape}, rows of length {n} expected")
    check(bool(np.all(np.sort(a.reshape(-1, n), axis=1) == np.arange(n))),
          f"{what}: a row is not a permutation of range({n})")


def _is_connected(pairs, N):
    if N <= 1:
        return True
    parent = list(range(N))

    def find(x):
        while parent[x] != x:
            x = parent[x]
        return x

    for i, j in np.asarray(pairs).reshape(-1, 2):
        parent[find(int(i))] = find(int(j))
    return len({find(v) for v in range(N)}) == 1


# ----------------------------------------------------------------------------------- view graph

descriptor_arrays = st.one_of(
    any_arrays(max_dims=2, max_side=5),
    st.tuples(st.integers(1, 6), st.integers(1, 3)).flatmap(
        lambda s: float_arrays(s, elements=st.one_of(
            st.floats(-2, 2, width=64), st.sampled_from([0.0, 1e300, -1e300, 5e-324, 1e-300]))))
)


@MEDIUM
@given(descriptor_arrays, st.data(), st.sampled_from(INT_ARGS))
@example(np.array([[0.0], [1e300], [-1e300]]), np.array([[1e300]]), 1)
def test_nearest_graphs_and_view_graph(descriptors, queries, k):
    """nearest_graphs: (M, min(k, N)) distinct in-range indices, nearest first; view_graph:
    sorted unique pairs i < j that connect all graphs; or a named refusal."""
    from transync import kernels as tk

    if not isinstance(queries, np.ndarray):            # drawn: usually the same columns
        d = np.shape(descriptors)[-1] if np.ndim(descriptors) == 2 else 1
        queries = queries.draw(st.one_of(
            float_arrays(st.tuples(st.integers(0, 3), st.just(d)), elements=st.one_of(
                st.floats(-2, 2, width=64), st.sampled_from([1e300, -1e300, 5e-324]))),
            float_arrays(st.tuples(st.integers(0, 3), st.just(d))),
            any_arrays(max_dims=2, max_side=3)))
    P = call(tk.view_graph, descriptors, k)
    if P is not REFUSED:
        N = np.shape(descriptors)[0]
        P = np.asarray(P)
        check(P.dtype == np.int64 and P.ndim == 2 and P.shape[1] == 2,
              f"view_graph: shape {P.shape}, dtype {P.dtype}")
        check(bool(np.all((P[:, 0] < P[:, 1]) & (P[:, 0] >= 0) & (P[:, 1] < N))),
              f"view_graph: pairs outside 0 <= i < j < {N}: {P.tolist()}")
        check(len(np.unique(P, axis=0)) == len(P), "view_graph: repeated pairs")
        check(_is_connected(P, N), f"view_graph: pairs do not connect the {N} graphs")
        if k is None:
            check(len(P) == N * (N - 1) // 2, "view_graph: n_neighbors=None, not all pairs")
    nn = call(tk.nearest_graphs, descriptors, queries, k)
    if nn is REFUSED:
        return
    D = np.asarray(descriptors, dtype=float)
    Q = np.asarray(queries, dtype=float)
    kk = min(int(k), D.shape[0])
    check(nn.shape == (Q.shape[0], kk) and nn.dtype.kind == "i",
          f"nearest_graphs: shape {nn.shape} dtype {nn.dtype}, expected ({Q.shape[0]}, {kk})")
    check(bool(np.all((nn >= 0) & (nn < D.shape[0]))), "nearest_graphs: indices out of range")
    for row in nn:
        check(len(set(row.tolist())) == len(row), f"nearest_graphs: repeated index {row}")


@MEDIUM
@given(node_feature_lists(), st.data(),
       st.sampled_from([None, [0, 1, 2], [0, 1, 2], [2], [1, 0], [], [[0, 1]], [0.0, 1.0],
                        [0, np.nan], ["a", "b"], [None, 1], [1j, 2], [0, 2**40]]))
@example(([np.ones((2, 1))], 2), None, [0, np.nan])
@example(([np.ones((2, 1))], 2), None, [None, 1])
def test_graph_descriptors(feats_n, data, label_values):
    """(N, f + B): finite mean features, then label shares in [0, 1] summing to at most 1."""
    from transync import kernels as tk

    feats, _ = feats_n
    labels = None
    if data is None or data.draw(st.booleans()):
        labels = [np.arange(len(F)) % 3 for F in feats]
    elif data.draw(st.booleans()):
        labels = [data.draw(any_arrays(max_dims=1, max_side=3)) for _ in feats]
    D = call(tk.graph_descriptors, feats, labels, label_values)
    if D is REFUSED:
        return
    check_finite_array(D, "graph_descriptors")
    f = np.asarray(feats[0]).reshape(len(feats[0]), -1).shape[1]
    B = 0 if labels is None else len(label_values)
    check(D.shape == (len(feats), f + B), f"graph_descriptors: shape {D.shape}")
    if B:
        check(np.asarray(label_values).dtype.kind in "iu",
              f"graph_descriptors: accepted non-integer label_values {label_values!r}")
        H = D[:, f:]
        check(bool(np.all((H >= 0) & (H <= 1)) and np.all(H.sum(1) <= 1 + 1e-12)),
              "graph_descriptors: label shares outside [0, 1] or summing above 1")


# ----------------------------------------------------------------------------------- pruning

@MEDIUM
@given(st.one_of(any_arrays(max_dims=2, max_side=5),
                 hnp.arrays(np.int64, st.integers(1, 6), elements=st.integers(1, 9)),
                 hnp.arrays(np.int64, st.integers(1, 6), elements=st.integers(1, 9))),
       st.data(),
       st.sampled_from([0.95, None, 1.0, 0.5, 0.0, -0.1, 1.5, np.nan, 5e-324, "0.5"]),
       st.sampled_from([None, None, 3, 1, 0, -1, 10**30, 2.5]),
       st.sampled_from([0, 1, 2, 10, 0, 1, -1, 1.0, 10**30]))
@example(np.array([1, 2]), [None, None], None, None, 0)
@example(np.array([1, 2]), np.array([1, "a"], dtype=object), None, None, 0)
@example(np.array([1]), [0], None, 10**30, 0)
def test_prune_by_size(sizes, data, quantile, max_nodes, min_class_size):
    """keep: sorted distinct indices whose sizes respect the caps; rule: a str."""
    from transync import kernels as tk

    if isinstance(data, (list, np.ndarray)):
        y = data
    else:
        m = np.shape(sizes)[0] if np.ndim(sizes) else 0
        y = data.draw(st.one_of(hnp.arrays(np.int64, m, elements=st.integers(0, 2)),
                                hnp.arrays(np.int64, m, elements=st.integers(0, 2)),
                                hnp.arrays(np.dtype("U2"), m, elements=st.sampled_from(["a",
                                                                                       "b"])),
                                hnp.arrays(np.float64, m, elements=nasty_floats),
                                any_arrays(max_dims=2, max_side=4)))
    out = call(tk.prune_by_size, sizes, y, quantile=quantile, max_nodes=max_nodes,
               min_class_size=min_class_size)
    if out is REFUSED:
        return
    keep, rule = out
    s = np.asarray(sizes)
    check(isinstance(rule, str), "prune_by_size: rule not a str")
    check(keep.dtype == np.int64 and keep.ndim == 1 and keep.size >= 1,
          f"prune_by_size: keep {keep!r}")
    check(bool(np.all(np.diff(keep) > 0) and keep[0] >= 0 and keep[-1] < s.shape[0]),
          "prune_by_size: keep not sorted distinct indices in range")
    if max_nodes is not None:
        check(bool(np.all(s[keep] <= max_nodes)), "prune_by_size: kept a graph above max_nodes")


# ------------------------------------------------------------------------------- synchronization

@st.composite
def alignment_problems(draw):
    """(assignments, pairs, N, n, sizes, node_labels, kind) for synchronize_alignments."""
    N = draw(st.sampled_from([1, 2, 3, 4, 2, 3]))
    n = draw(st.sampled_from([1, 2, 3, 3, 4]))
    pairs, A, kind = draw(slot_maps(N, n))
    if kind == "junk" and not (A.size and np.any(np.sort(A, axis=1) != np.arange(n))):
        kind = "random"          # a dropped or repeated pair: junk for the kernel, not here
    if draw(st.integers(0, 3)) == 0 and len(pairs) > 1:          # a sparser view graph
        keep = draw(st.lists(st.integers(0, len(pairs) - 1), min_size=1, unique=True))
        pairs, A = pairs[sorted(keep)], A[sorted(keep)]
        kind = "sparse" if kind != "junk" else kind
    sizes = labels = None
    if draw(st.booleans()):
        sizes = np.array([draw(st.integers(1, n)) for _ in range(N)], dtype=np.int64)
        if draw(st.integers(0, 4)) == 0:
            sizes = draw(any_arrays(max_dims=1, max_side=4))
            kind = "junk-sizes"
        elif draw(st.booleans()):
            labels = [np.array([draw(st.integers(0, 1)) for _ in range(s)]) for s in sizes]
    return A, pairs, N, n, sizes, labels, kind


@COSTLY
@given(alignment_problems(), st.sampled_from(["orthogonal", "spectral"]), st.booleans(),
       st.sampled_from([None, None, 0, 2, -1]),
       st.sampled_from([(None, None), (None, None), ("n", 0), ("n", -2), ("n", 2.0),
                        ("n_graphs", 0), ("n_graphs", True), ("max_iter", 0), ("tol", np.nan),
                        ("assignments", np.zeros((1, 3), np.float64))]))
def test_synchronize_alignments(problem, method, keep, refine, spoil):
    """Alignment: (N, n) permutation rows, a finite objective and embedding; consistent maps
    come back exactly; or a named refusal."""
    from transync import kernels as tk

    A, pairs, N, n, sizes, labels, kind = problem
    args = dict(assignments=A, pairs=pairs, n_graphs=N, n=n)
    if spoil[0] is not None:
        args[spoil[0]] = spoil[1]
    al = call(tk.synchronize_alignments, args.pop("assignments"), args.pop("pairs"),
              args.pop("n_graphs"), sizes=sizes, node_labels=labels, method=method,
              keep_embedding=keep, refine=refine, **args)
    if al is REFUSED:
        return
    check(kind != "junk", f"synchronize_alignments: accepted junk maps ({spoil})")
    _check_permutation_rows(al.labels, n, "Alignment.labels")
    check(al.labels.shape == (N, n), f"Alignment.labels: shape {al.labels.shape}")
    check_finite_scalar(al.objective, "Alignment.objective")
    if keep:
        check(al.embedding is not None and al.embedding.shape[:2] == (N, n),
              "Alignment.embedding: missing or wrong shape")
        check_finite_array(al.embedding, "Alignment.embedding")
    else:
        check(al.embedding is None, "Alignment.embedding kept without keep_embedding")
    if kind == "transitive" and sizes is None and spoil[0] is None:
        for (i, j), a in zip(pairs, A):
            check(bool(np.array_equal(al.pairwise(int(i), int(j)), a)),
                  "synchronize_alignments: consistent maps not recovered")


@st.composite
def placement_problems(draw):
    N = draw(st.integers(0, 3))
    n = draw(st.sampled_from([1, 2, 3, 3, 0]))
    M = draw(st.integers(0, 2))
    m = max(n, 0)
    lab = np.array([draw(st.permutations(list(range(m)))) for _ in range(N)],
                   dtype=np.int64).reshape(N, m)
    K = N
    fitted = None
    if N and draw(st.booleans()):
        K = draw(st.integers(0, N))
        fitted = np.array([draw(st.permutations(list(range(N))))[:K] for _ in range(M)],
                          dtype=np.int64).reshape(M, K)
        if draw(st.integers(0, 4)) == 0:
            fitted = draw(hnp.arrays(np.int64, (M, K), elements=st.integers(-1, N)))
    A = np.array([draw(st.permutations(list(range(m)))) for _ in range(M * K)],
                 dtype=draw(st.sampled_from([np.int64, np.int32]))).reshape(M, K, m)
    if draw(st.integers(0, 4)) == 0:
        A = draw(st.one_of(any_arrays(max_dims=3, max_side=3),
                           hnp.arrays(np.int64, (M, K, m), elements=st.integers(-1, m))))
    return A, lab, fitted, N, n, M


@COSTLY
@given(placement_problems(), st.data(), st.sampled_from(["orthogonal", "spectral"]))
@example((np.array([[[0, 1], [0, 1]]]), np.array([[0, 1], [1, 0]]), None, 2, 2, 1), None,
         "orthogonal")
@example((np.zeros((1, 1, 0), np.int64), np.zeros((1, 0), np.int64), None, 1, 0, 1), None,
         "orthogonal")
@example((np.array([[[0, 1], [0, 1]]]), np.array([[0, 1], [1, 0]]), None, 2, 2, 1), "spectral",
         "spectral")
@example((np.zeros((0, 0, 1), np.int64), np.zeros((0, 1), np.int64), None, 0, 1, 0), "sizes",
         "orthogonal")
def test_place_graphs(problem, data, method):
    """(M, n) permutation rows and a finite (M, n, d) relaxed embedding (zero rows on the
    dummies with sizes), or a named refusal."""
    from transync import kernels as tk

    A, lab, fitted, N, n, M = problem
    m = max(n, 0)
    kw = {}
    if data is None:                                   # explicit examples: huge embeddings, ...
        kw = dict(embedding=np.full((N, m, 2), 1e308))
    elif data == "spectral":
        kw = dict(embedding=np.full((N, m, 2), 1e300), degrees=np.full((N, m), 1e-300),
                  eigenvalues=[1e-11, 1.0])
    elif data == "sizes":                              # ... no new and no fitted graph
        kw = dict(sizes=np.zeros(0, np.int64), fitted_sizes=np.zeros(0, np.int64))
    else:
        if data.draw(st.booleans()):
            d = data.draw(st.integers(0, 3))
            kw["embedding"] = data.draw(float_arrays((N, m, d)) if data.draw(st.booleans())
                                        else any_arrays(max_dims=3, max_side=3))
            if method == "spectral" and data.draw(st.integers(0, 4)):
                kw["degrees"] = data.draw(float_arrays((N, m)))
                kw["eigenvalues"] = data.draw(float_arrays(d + data.draw(st.integers(-1, 1))
                                                           if d else 0))
        if data.draw(st.booleans()):
            kw["sizes"] = np.array([data.draw(st.integers(0, m)) for _ in range(M)], np.int64)
            kw["fitted_sizes"] = np.array([data.draw(st.integers(1, max(m, 1)))
                                           for _ in range(N)], np.int64)
            if data.draw(st.booleans()):
                kw["node_labels"] = [np.arange(k) % 2 for k in kw["sizes"]]
                kw["fitted_node_labels"] = [np.arange(k) % 2 for k in kw["fitted_sizes"]]
    out = call(tk.place_graphs, A, lab, method=method, fitted=fitted, **kw)
    if out is REFUSED:
        return
    labels, Q = out
    M, _, m = np.shape(A)                              # junk assignments: their own shape
    check(labels.shape == (M, m), f"place_graphs: labels shape {labels.shape}")
    _check_permutation_rows(labels, m, "place_graphs labels")
    if "embedding" not in kw:
        check(Q is None, "place_graphs: an embedding without `embedding`")
        return
    d = np.shape(kw["embedding"])[-1]
    check(Q.shape == (M, m, d), f"place_graphs: embedding shape {Q.shape}")
    check_finite_array(Q, "place_graphs embedding")
    if "sizes" in kw:
        dummy = np.arange(m)[None, :] >= kw["sizes"][:, None]
        check(bool(np.all(Q[dummy] == 0)), "place_graphs: dummies with non-zero rows")


# ----------------------------------------------------------------------------------- matching

@st.composite
def matching_problems(draw):
    """(features, adjacencies, pairs, node_labels, nmax) for match_pairs; some junk."""
    from transync.kernels import hks_features

    graphs = draw(st.lists(small_graphs(), min_size=0, max_size=4))
    adjs = [getattr(g, "adjacency", g) for g in graphs]
    sizes = [np.shape(a)[0] for a in adjs]
    if draw(st.booleans()) and all(sizes):
        feats = hks_features(adjs, times=[0.5, 2.0])
    else:
        feats = [draw(float_arrays((k, draw(st.integers(1, 2))) if draw(st.integers(0, 5))
                                   else (k,), elements=nasty_floats
                                   if draw(st.integers(0, 3)) == 0 else
                                   st.floats(-2, 2, width=64)))
                 for k in sizes]
    N = len(adjs)
    if draw(st.integers(0, 4)):
        pairs = np.array(draw(st.lists(st.tuples(st.integers(0, max(N - 1, 0)),
                                                 st.integers(0, max(N - 1, 0))),
                                       min_size=0, max_size=5)), dtype=np.int64).reshape(-1, 2)
    else:
        pairs = draw(any_arrays(max_dims=2, max_side=3))
    labels = None
    if draw(st.booleans()):
        labels = [np.arange(k) % 2 for k in sizes]
    return feats, adjs, pairs, labels, max(sizes, default=0)


@COSTLY
@given(matching_problems(), st.sampled_from(["node", "sm", "rrwm"]),
       st.sampled_from([0, 0, 0, 1, -1, "n0", "n-1", 2.0, 5000]),
       st.sampled_from([None, None, 1.0, 0.0, -1.0, np.nan, 1e-300, 1e300]),
       st.sampled_from([None, None, 0.0, 1.0, -1.0, 1e200, 1e300, np.inf]),
       st.sampled_from([None, None, 1, 0, 2.5]))
@example(([np.ones((2, 1)), np.ones((1, 1))], [np.array([[0, 1], [1, 0.]]), np.zeros((1, 1))],
          np.array([[0, 1]]), None, 2), "sm", 1, None, 1e300, None)
@example(([np.ones((2, 1)), np.ones((1, 1))], [np.array([[0, 1], [1, 0.]]), np.zeros((1, 1))],
          np.array([[0, 1], [1, 0]]), None, 2), "rrwm", 5000, None, None, None)
def test_match_pairs(problem, matcher, n_off, sigma2, dummy, chunk_size):
    """(P, n) int rows, each a permutation of range(n); or a named refusal."""
    from transync import kernels as tk

    feats, adjs, pairs, labels, nmax = problem
    n = {"n0": 0, "n-1": -1}.get(n_off, n_off) if isinstance(n_off, str) else (
        n_off if isinstance(n_off, float) else nmax + n_off)
    out = call(tk.match_pairs, feats, adjs, pairs, n=n, matcher=matcher, sigma2=sigma2,
               node_labels=labels, dummy_affinity=dummy, chunk_size=chunk_size)
    if out is REFUSED:
        return
    P = np.asarray(pairs).reshape(-1, 2).shape[0]
    check(out.shape == (P, n), f"match_pairs: shape {out.shape}, expected ({P}, {n})")
    _check_permutation_rows(out, n, "match_pairs")


# ----------------------------------------------------------------------------------- baselines

graph_lists = st.one_of(
    st.lists(small_graphs(), min_size=0, max_size=4),
    st.lists(any_arrays(max_dims=2, max_side=3), min_size=1, max_size=2),
    st.lists(hnp.arrays(np.float64, st.integers(1, 4).map(lambda m: (m, m)),
                        elements=st.sampled_from([0.0, 1.0, 2.0, 1e300, 5e-324, 1e308])
                        ).map(lambda a: np.triu(a, 1) + np.triu(a, 1).T),
             min_size=1, max_size=3),
    any_arrays(max_dims=3, max_side=3))


@MEDIUM
@given(graph_lists)
def test_graphlet3_counts(graphs):
    """(N, 4) non-negative integer counts summing to C(n_g, 3)."""
    from math import comb

    from transync import kernels as tk

    C = call(tk.graphlet3_counts, graphs)
    if C is REFUSED:
        return
    check_finite_array(C, "graphlet3_counts")
    check(C.shape == (len(graphs), 4), f"graphlet3_counts: shape {C.shape}")
    check(bool(np.all(C >= 0) and np.all(C == np.rint(C))),
          "graphlet3_counts: negative or non-integer counts")
    for g, c in zip(graphs, C):
        k = np.shape(getattr(g, "adjacency", g))[0]
        check(c.sum() == comb(k, 3), f"graphlet3_counts: {c} does not sum to C({k}, 3)")


@MEDIUM
@given(graph_lists, st.sampled_from([1e-2, 1e-2, 0.1, 0.3, 0.0, -1.0, np.nan, 5e-324, 1e300]),
       st.sampled_from([(1e-12, 500), (1e-12, 500), (1e300, 1), (5e-324, 20), (0.0, 5),
                        (1e-12, 0), (1e-12, 2.0)]),
       st.sampled_from([None, None, "alt", "junk"]), st.booleans())
def test_random_walk_kernel(graphs, lamda, tol_iter, labels, normalize):
    """A finite, exactly symmetric, PSD (to rounding) kernel; or a named refusal."""
    from transync import kernels as tk

    tol, max_iter = tol_iter
    sizes = [np.shape(getattr(g, "adjacency", g))[0] if np.ndim(getattr(g, "adjacency", g))
             else 0 for g in (graphs if isinstance(graphs, list) else [])]
    node_labels = {None: None, "alt": [np.arange(k) % 2 for k in sizes],
                   "junk": [np.full(k, 0.5) for k in sizes]}[labels]
    K = call(tk.random_walk_kernel, graphs, lamda=lamda, node_labels=node_labels,
             normalize=normalize, tol=tol, max_iter=max_iter)
    if K is REFUSED:
        return
    _check_kernel_matrix(K, len(graphs), "random_walk_kernel", psd=True)


# ----------------------------------------------------------------------------------- evaluation

@st.composite
def kernel_matrices(draw):
    """Square matrices: PSD Grams times a nasty scale, symmetric junk, or any array."""
    kind = draw(st.sampled_from(["psd", "psd", "sym", "any"]))
    if kind == "any":
        return draw(any_arrays(max_dims=3, max_side=4))
    n = draw(st.integers(0, 4))
    if kind == "psd":
        X = draw(float_arrays((n, draw(st.integers(1, 3))), elements=st.floats(-2, 2,
                                                                               width=64)))
        K = X @ X.T
    else:
        B = draw(float_arrays((n, n)))
        with np.errstate(all="ignore"):
            K = np.triu(B) + np.triu(B, 1).T
    with np.errstate(all="ignore"):
        return K * draw(st.sampled_from([1.0, 1.0, 1e-300, 5e-324, 1e300, 1e308, -1.0, 0.0]))


@MEDIUM
@given(kernel_matrices())
@example(np.full((2, 2), 1e308))
@example(np.diag([-1.0, 1e-320]))
def test_spectrum_and_min_eigenvalue_ratio(K):
    """spectrum: n finite ascending eigenvalues; min_eigenvalue_ratio: a finite number <= 1."""
    from transync import kernels as tk

    w = call(tk.spectrum, K)
    if w is not REFUSED:
        check_finite_array(w, "spectrum")
        check(w.shape == (np.shape(K)[0],), f"spectrum: shape {w.shape}")
        check(bool(np.all(np.diff(w) >= 0)), "spectrum: not ascending")
    r = call(tk.min_eigenvalue_ratio, K)
    if r is REFUSED:
        return
    check_finite_scalar(r, "min_eigenvalue_ratio")
    check(r <= 1 + 1e-12, f"min_eigenvalue_ratio: {r} > 1")


@MEDIUM
@given(kernel_matrices(), st.sampled_from(["none", "none", "own", "rect", "junk"]), st.data())
def test_cosine_normalize(K, diags, data):
    """Same shape, finite; a symmetric K stays exactly symmetric; a PSD K gets entries in
    [-1, 1] and a diagonal of ones (zero for a zero self-similarity)."""
    from transync import kernels as tk

    kw = {}
    if diags == "own" and np.ndim(K) == 2 and np.shape(K)[0] == np.shape(K)[1] \
            and np.asarray(K).dtype.kind in "biuf":
        d = np.diag(np.asarray(K, dtype=float))
        kw = dict(diag_rows=d, diag_cols=d)
    elif diags == "rect":
        K = data.draw(float_arrays(st.tuples(st.integers(0, 3), st.integers(0, 3))))
        kw = dict(diag_rows=data.draw(float_arrays(K.shape[0])),
                  diag_cols=data.draw(float_arrays(K.shape[1])))
    elif diags == "junk":
        kw = dict(diag_rows=data.draw(any_arrays(max_dims=2)))
        if data.draw(st.booleans()):
            kw["diag_cols"] = data.draw(any_arrays(max_dims=2))
    out = call(tk.cosine_normalize, K, **kw)
    if out is REFUSED:
        return
    check_finite_array(out, "cosine_normalize")
    K = np.asarray(K, dtype=float)
    check(out.shape == K.shape, f"cosine_normalize: shape {out.shape} for {K.shape}")
    if not kw and K.size:
        if np.array_equal(K, K.T):
            check(bool(np.array_equal(out, out.T)), "cosine_normalize: lost symmetry")
        # Cauchy-Schwarz, in logs (no under- or overflow): where |K_ij| <= sqrt(K_ii K_jj),
        # the normalized entry is at most 1
        d = np.diag(K)
        with np.errstate(divide="ignore"):
            la, ld = np.log(np.abs(K)), np.log(np.where(d > 0, d, 0.0))
        cs = (K != 0) & (2 * la <= ld[:, None] + ld[None, :] - 1e-9)
        check(bool(np.all(np.abs(out[cs]) <= 1 + 1e-9)),
              "cosine_normalize: |entry| > 1 where |K_ij| <= sqrt(K_ii K_jj)")


@MEDIUM
@given(node_feature_lists(), st.data(), st.sampled_from([1.0, 1.0, 1e300, 1e-300, 0.0]))
@example(([np.full((2, 1), 1e100)], 2), np.full((1, 2, 2), 1.0), 1e300)
def test_relaxed_features(feats_n, E, scale):
    """(N, d, f + 1) finite relaxed features, or a named refusal."""
    from transync import kernels as tk

    feats, n = feats_n
    if not isinstance(E, np.ndarray):                  # drawn: usually (N, n, d) that fits
        E = E.draw(st.one_of(
            st.tuples(st.just(len(feats)), st.just(max(n, 0)), st.integers(0, 3)).flatmap(
                lambda sh: float_arrays(sh, elements=st.floats(-1, 1, width=64))),
            st.tuples(st.just(len(feats)), st.just(max(n, 0)), st.integers(0, 3)).flatmap(
                float_arrays),
            st.tuples(st.integers(0, 4), st.integers(0, 4), st.integers(0, 3)).flatmap(
                float_arrays),
            any_arrays()))
    with np.errstate(all="ignore"):
        E = np.asarray(E) * scale if np.asarray(E).dtype.kind == "f" else E
    R = call(tk.relaxed_features, feats, E)
    if R is REFUSED:
        return
    check_finite_array(R, "relaxed_features")
    f = np.asarray(feats[0]).shape[1]
    check(R.shape == (len(feats), np.shape(E)[2], f + 1), f"relaxed_features: shape {R.shape}")


@MEDIUM
@given(graph_lists, st.sampled_from([None, None, [0.1, 1.0], [1.0], [], [0.0], [-1.0],
                                     [np.nan], [1e300], [5e-324], [[1.0]]]))
@example([np.array([[0, 1e308, 1e308], [1e308, 0, 0], [1e308, 0, 0]])], None)
def test_hks_features(graphs, times):
    """One (n_g, T) array per graph with values in [0, 1]; or a named refusal."""
    from transync import kernels as tk

    H = call(tk.hks_features, graphs, times)
    if H is REFUSED:
        return
    T = 10 if times is None else len(times)
    check(isinstance(H, list) and len(H) == len(graphs), "hks_features: not one entry per graph")
    for g, h in zip(graphs, H):
        check_finite_array(h, "hks_features")
        k = np.shape(getattr(g, "adjacency", g))[0]
        check(h.shape == (k, T), f"hks_features: shape {h.shape}, expected ({k}, {T})")
        check(bool(np.all((h >= 0) & (h <= 1 + 1e-9))), "hks_features: values outside [0, 1]")


_CV_CACHE: dict = {}


def _cv_results():
    """Three repeated_cv results on the same folds (tiny PSD Grams) and one on other folds."""
    if not _CV_CACHE:
        from transync.kernels import repeated_cv

        rng = np.random.default_rng(0)
        y = np.repeat([0, 1], 4)
        out = []
        for shift in (0.0, 1.0, 3.0):
            X = rng.normal(size=(8, 2)) + shift * y[:, None]
            out.append(repeated_cv(X @ X.T, y, n_splits=2, n_repeats=2, C_grid=[1.0],
                                   inner_splits=2))
        out.append(repeated_cv(X @ X.T, y, n_splits=2, n_repeats=2, C_grid=[1.0],
                               inner_splits=2, random_state=1))
        _CV_CACHE["r"] = out
    return _CV_CACHE["r"]


@st.composite
def cv_results(draw):
    """A CVResult from repeated_cv, one built by hand (any accuracies), or not a CVResult."""
    from dataclasses import replace

    kind = draw(st.sampled_from(["cv", "cv", "cv", "hand", "hand", "other"]))
    res = _cv_results()
    if kind == "cv":
        return res[draw(st.integers(0, len(res) - 1))]
    if kind == "other":
        return draw(st.sampled_from([None, 1.0, "cv", res[0].accuracies]))
    base = res[0]
    shape = draw(st.sampled_from([base.accuracies.shape] * 3 + [(2, 1), (1, 2), (3, 2), (4,)]))
    acc = draw(st.one_of(float_arrays(shape, elements=st.sampled_from([0.0, 0.5, 1.0, 0.75])),
                         float_arrays(shape),
                         st.just(np.full(shape, 0.5) + 1e-11 * np.arange(np.prod(shape))
                                 .reshape(shape))))
    with np.errstate(all="ignore"):
        per_repeat = acc.mean(axis=-1) if acc.ndim == 2 else acc
    return replace(base, accuracies=acc, per_repeat=per_repeat)


@MEDIUM
@given(cv_results(), cv_results(), st.sampled_from(["corrected", "repeats", "folds", "x", None]))
def test_paired_ttest(a, b, over):
    """(t, p): p in [0, 1], t finite or +-inf with p = 0; or a named refusal."""
    from transync import kernels as tk

    out = call(tk.paired_ttest, a, b, over=over)
    if out is REFUSED:
        return
    t, p = out
    check_finite_scalar(p, "paired_ttest p")
    check(0.0 <= p <= 1.0, f"paired_ttest: p = {p} outside [0, 1]")
    check(isinstance(t, float) and not np.isnan(t), f"paired_ttest: t = {t!r}")
    check(np.isfinite(t) or p == 0.0, f"paired_ttest: t = {t} with p = {p}")


def test_paired_ttest_hand_built_results():
    """Regression: hand-built CVResults with one pair, one split, mismatched shapes or NaN
    accuracies used to raise unnamed ValueErrors or ZeroDivisionError."""
    from dataclasses import replace

    from transync import kernels as tk

    base = _cv_results()[0]
    for acc, over in ((np.full((2, 1), 0.5), "corrected"), (np.full((1, 2), 0.5), "repeats"),
                      (np.full((3, 2), 0.5), "folds"), (np.full((2, 2), np.nan), "folds"),
                      (np.full((2, 2), 2.0), "folds")):
        with np.errstate(all="ignore"):
            b = replace(base, accuracies=acc, per_repeat=acc.mean(1))
        check(call(tk.paired_ttest, b, base if acc.shape[0] == 3 else b, over=over)
              is REFUSED, f"paired_ttest: accepted accuracies of shape {acc.shape} ({over})")


def test_match_pairs_checks_rng():
    """Regression: a junk ``rng`` was accepted silently unless ``sigma2`` was given."""
    from transync import kernels as tk

    A = np.array([[0, 1], [1, 0.0]])
    check(call(tk.match_pairs, [np.ones((2, 1))] * 2, [A, A], [[0, 1]], n=2, rng="x")
          is REFUSED, "match_pairs: accepted rng='x'")


@MEDIUM
@given(small_graphs(), st.one_of(any_arrays(max_dims=2), st.just([2, 0, 1]), st.just(None)))
def test_graph_permute_and_views(g, perm):
    """Graph.permute on any permutation-like input, and the derived views (distances, angles,
    edge_index, networkx round trip) on any small graph."""
    from transync.graphs import Graph

    if not isinstance(g, Graph):
        return
    n = g.n_nodes
    p = call(g.permute, perm)
    if p is not REFUSED:
        arr = np.asarray(perm)
        check(arr.shape == (n,) and sorted(arr.tolist()) == list(range(n)),
              f"permute accepted {perm!r} for {n} nodes")
        check(p.n_nodes == n, "permute changed the number of nodes")
    E = call(g.edge_index)
    if E is not REFUSED:
        E = np.asarray(E)
        check(E.size == 0 or (E.min() >= 0 and E.max() < n), "edge_index out of range")
    for view in (g.distances, g.angles):
        out = call(view)
        if out is not REFUSED:
            check_finite_array(out, view.__name__)
    G = call(g.to_networkx)
    if G is not REFUSED:
        back = call(Graph.from_networkx, G)
        check(back is REFUSED or back.n_nodes == n, "networkx round trip changed the size")


@MEDIUM
@given(st.data(), st.sampled_from([None, (2, 3), (3, 3), (0, 2), (3, 2), (1.5, 2), 2, "x"]),
       st.sampled_from(["auto", "auto", "none", "x", None]), st.booleans())
def test_landmark_sequence_graphs(data, keep, normalize, shuffle):
    """LandmarkSequence.graphs / normalized_points on any frame list and keep range."""
    from transync.datasets import LandmarkSequence

    rng = np.random.default_rng(0)
    seq = LandmarkSequence(name="toy", points=rng.uniform(0, 100, (4, 5, 2)),
                           frames=np.arange(4), image_paths=None, image_sizes=None,
                           source=None)
    frames = data.draw(st.one_of(st.just([0, 1, 2]), st.just([0]), st.just([]),
                                 st.just([0, 0, 1]), st.just([0, 9]), st.just([-1, 1]),
                                 any_arrays(max_dims=1)))
    out = call(seq.graphs, frames, keep=keep, normalize=normalize, shuffle=shuffle, rng=0)
    if out is not REFUSED:
        sizes = [gr.n_nodes for gr in out.graphs]
        check(len(sizes) == np.asarray(frames).size, "one graph per frame")
        check(all(1 <= s <= 5 for s in sizes), f"graph sizes {sizes}")
        _check_labels(out.ground_truth.labels, sizes, out.ground_truth.n_universe, "truth")
    P = call(seq.normalized_points, frames, normalize=normalize)
    if P is not REFUSED:
        check_finite_array(P, "normalized_points")


# ----------------------------------------------------------------------------------- multigraph

PAIR_SOLVERS = ["rrwm", "ga", "pf", "sm", "ipfp", "cao", "cao-pc"]


@st.composite
def point_collections(draw):
    """(graphs, sizes): up to 4 graphs of 1..5 nodes on points, sizes equal or not, coordinates
    sometimes nasty; sometimes a junk entry instead of a graph."""
    from transync.graphs import Graph

    N = draw(st.sampled_from([2, 3, 3, 4, 4] * 3 + [0, 1]))
    equal = draw(st.booleans())
    n0 = draw(st.integers(1, 5))
    graphs, sizes = [], []
    for _ in range(N):
        n = n0 if equal else draw(st.integers(1, 5))
        elems = st.floats(-1, 1, width=64) if draw(st.integers(0, 15)) else nasty_floats
        pts = draw(float_arrays((n, 2), elements=elems))
        kind = draw(st.sampled_from(["full"] * 14 + ["delaunay", "delaunay", "junk", "adj",
                                                     "adj"]))
        if kind == "adj":
            A = draw(float_arrays((n, n), elements=st.sampled_from([0.0, 0.0, 1.0, 0.3, 2.0])))
            sym = draw(st.booleans())
            graphs.append(call(Graph, np.maximum(A, A.T) if sym else A))
            if graphs[-1] is REFUSED:
                graphs[-1] = Graph(np.ones((n, n)) - np.eye(n))
        elif kind == "junk":
            graphs.append(draw(st.sampled_from([None, pts, "g", np.zeros((0, 0))])))
        else:
            graphs.append(call(Graph.from_points, pts, edges=kind))
            if graphs[-1] is REFUSED:
                graphs[-1] = Graph(np.ones((n, n)) - np.eye(n))
        sizes.append(n)
    return graphs, sizes


@st.composite
def view_graphs(draw, N):
    kind = draw(st.sampled_from([None] * 12 + ["path", "path", "subset", "junk", "self", "range"]))
    all_p = [(i, j) for i in range(N) for j in range(i + 1, N)]
    if kind is None:
        return None
    if kind == "path":
        return [(i, i + 1) for i in range(N - 1)]
    if kind == "subset":
        return draw(st.lists(st.sampled_from(all_p), unique=True)) if all_p else []
    if kind == "self":
        return [(0, 0)] + all_p
    if kind == "range":
        return all_p + [(0, N + 3)]
    return draw(any_arrays(max_dims=2))


@st.composite
def affinities_for(draw, graphs):
    import functools

    from transync.matching import gaussian_edge_affinity

    kind = draw(st.sampled_from(["default"] * 8 + ["sigma", "blocks", "blocks", "bad_blocks",
                                                   "junk"]))
    if kind == "default":
        return None
    if kind == "sigma":
        s = draw(st.sampled_from([0.05, 0.05, 1e-300, 1e300, 1e-9]))
        return functools.partial(gaussian_edge_affinity, sigma2=s)
    if kind == "junk":
        return draw(st.one_of(any_arrays(max_dims=4), st.just("aff"), st.just({(0, 1): 3})))
    sizes = [getattr(g, "n_nodes", 0) for g in graphs]
    out = {}
    for i in range(len(graphs)):
        for j in range(i + 1, len(graphs)):
            m = sizes[i] * sizes[j]
            if kind == "bad_blocks" and draw(st.booleans()):
                out[(i, j)] = draw(float_arrays((m, max(m - 1, 0))))
            else:
                B = draw(float_arrays((m, m), elements=tame_floats))
                out[(i, j)] = (B + B.T) / 2
    return out


def _check_result(res, sizes, synced, what="match_collection"):
    N = len(sizes)
    check(list(np.asarray(res.sizes)) == sizes, f"{what}: sizes {res.sizes} != {sizes}")
    for p, (i, j) in enumerate(np.asarray(res.pairs).tolist()):
        a = np.asarray(res.pairwise(i, j))
        check_assignment(a, sizes[i], sizes[j], f"{what}: pairwise({i}, {j})")
    check_finite_array(res.scores, f"{what}: scores")
    check_finite_scalar(res.total_score, f"{what}: total_score")
    for name in ("consistency", "input_consistency"):
        v = getattr(res, name)
        if v is not None:
            check_finite_scalar(v, f"{what}: {name}")
            check(0 <= v <= 1, f"{what}: {name} {v} outside [0, 1]")
    if synced:
        check(res.matching is not None, f"{what}: synchronized but no matching")
        _check_labels(res.matching.labels, sizes, res.matching.n_universe,
                      f"{what}: matching")
        for i in range(N):
            for j in range(N):
                if i != j:
                    check(bool(np.array_equal(res.pairwise(i, j), res.matching.pairwise(i, j))),
                          f"{what}: pairwise({i}, {j}) disagrees with the universe labels")
    M = res.to_matrix()
    check(M.shape == (sum(sizes), sum(sizes)), f"{what}: to_matrix shape {M.shape}")


@COSTLY
@given(point_collections(), st.data(),
       st.sampled_from(PAIR_SOLVERS),
       st.sampled_from(["auto", "auto", "birkhoff", "spectral", "orthogonal", None, "x"]),
       st.sampled_from(["online", "online", "offline", "x"]),
       st.sampled_from(["universe", "universe", "dummies", "x"]),
       N_UNIVERSE)
def test_match_collection(gs, data, solver, sync, mode, partial, n_universe):
    """Any small collection, any method, view graph, affinity and universe: a valid result
    (cycle-consistent where synchronized) or a named refusal."""
    from transync import match_collection

    graphs, sizes = gs
    pairs = data.draw(view_graphs(len(graphs)))
    affinity = data.draw(affinities_for(graphs))
    extra = data.draw(st.sampled_from([{}] * 8 + [
        {"sync_every": 1}, {"sync_every": 0}, {"sync_every": 2.5}, {"damping": 0.5},
        {"damping": 0.0}, {"damping": np.nan}, {"refine": False}, {"refine": 1},
        {"options": {"max_iter": 1}}, {"options": {"bogus": 1}}, {"options": 3},
        {"executor": "serial"}, {"rng": -1}, {"progress": "no"},
        {"verify": "affine"}, {"verify": "similarity"}, {"verify": "homography"},
        {"verify": "affine", "verify_threshold": 3.0}, {"verify": "x"},
        {"verify": "affine", "verify_threshold": 0.0}, {"verify_threshold": 0.5},
        {"verify": None}, {"verify": None, "verify_threshold": 0.5}, {"verify": "auto"}]))
    if affinity is None and data.draw(st.integers(0, 9)) == 0 and len(set(sizes)) == 1:
        m = sizes[0] ** 2
        affinity = np.abs(data.draw(float_arrays((len(sizes), len(sizes), m, m))))
    kwargs = dict(solver=solver, sync=sync, mode=mode, pairs=pairs, affinity=affinity,
                  n_universe=n_universe, partial=partial, progress=False, rng=0)
    kwargs.update(extra)
    res = call(match_collection, graphs, **kwargs)
    if res is REFUSED:
        return
    synced = sync is not None and not (sync == "auto" and solver.startswith("cao"))
    _check_result(res, sizes, synced)
    if n_universe is not None and synced:
        check(res.n_universe == n_universe, f"n_universe {res.n_universe} != {n_universe}")


@MEDIUM
@given(st.integers(1, 4), st.integers(1, 4), st.data())
def test_multimatching_metrics(N, d, data):
    """multimatching_accuracy / _precision_recall on any labels, dicts and pairs."""
    from transync.permutations import MultiMatching

    sizes = [data.draw(st.integers(0, d)) for _ in range(N)]

    def labels(n_obj, sizes=sizes):
        out = []
        for g in range(n_obj):
            n = sizes[g] if g < len(sizes) else 1
            perm = np.array(data.draw(st.permutations(list(range(d)))), dtype=np.int64)[:n]
            if data.draw(st.booleans()):
                perm[data.draw(hnp.arrays(np.bool_, n))] = -1
            out.append(perm)
        return out

    truth = labels(N) if data.draw(st.integers(0, 6)) else data.draw(any_arrays(max_dims=2))
    kind = data.draw(st.sampled_from(["labels"] * 4 + ["dict", "dict", "junk"]))
    if kind == "labels":
        pred = labels(data.draw(st.sampled_from([N] * 6 + [N + 1])))
    elif kind == "dict":
        pred = {}
        for i in range(N):
            for j in range(N):
                if i != j and data.draw(st.booleans()):
                    valid = data.draw(st.integers(0, 5)) > 0
                    pred[(i, j)] = data.draw(assignments(n1=sizes[i], n2=sizes[j],
                                                         valid=valid))[0]
    else:
        pred = data.draw(any_arrays(max_dims=2))
    pairs = data.draw(st.one_of(st.none(), st.none(), st.none(), any_arrays(max_dims=2),
                                st.just([(0, N - 1)]), st.just([(0, 0)])))
    acc = call(metrics.multimatching_accuracy, pred, truth, pairs=pairs)
    if acc is not REFUSED:
        check_finite_scalar(acc, "multimatching_accuracy")
        check(0 <= acc <= 1, f"multimatching_accuracy {acc}")
    pr = call(metrics.multimatching_precision_recall, pred, truth, pairs=pairs)
    if pr is not REFUSED:
        for k, v in pr.items():
            check_finite_scalar(v, f"multimatching_precision_recall[{k}]")
            check(0 <= v <= 1, f"multimatching_precision_recall[{k}] = {v}")
    if isinstance(truth, list) and kind:
        mm = call(MultiMatching, truth)
        if mm is not REFUSED:
            _check_labels(mm.labels, [len(t) for t in truth], mm.n_universe, "MultiMatching")


@MEDIUM
@given(pw_sizes=pairwise_dicts(soft=False), soft=st.booleans(),
       max_triples=st.sampled_from([10**6] * 6 + [0, 1, -1, 2.5]),
       tol=st.sampled_from([1e-9] * 6 + [0.0, -1.0, np.nan]), pass_sizes=st.booleans())
def test_constraint_violations(pw_sizes, soft, max_triples, tol, pass_sizes):
    pw, sizes = pw_sizes
    if soft:
        pw = {k: (v * 0.7 if np.ndim(v) == 2 and np.asarray(v).dtype.kind == "f" else v)
              for k, v in pw.items()}
    out = call(metrics.constraint_violations, pw, sizes=sizes if pass_sizes else None,
               max_triples=max_triples, tol=tol, rng=0)
    if out is REFUSED:
        return
    for name in ("capacity", "transitivity"):
        st_ = getattr(out, name)
        for k in ("cvr", "cvvr", "acvv"):
            v = getattr(st_, k)
            check_finite_scalar(v, f"constraint_violations.{name}.{k}")
            check(v >= 0, f"{name}.{k} = {v} < 0")
        check(st_.cvr <= 1, f"{name}.cvr {st_.cvr} > 1")


@MEDIUM
@given(n_graphs=BAD_INTS, n_universe=BAD_INTS,
       p_keep=st.sampled_from([(0.6, 1.0)] * 6 + [0.5, 1.0, 0.0, -0.1, 1.5, np.nan, (0.8, 0.5),
                                                    (0.0, 0.5), (0.5,), "x", (0.5, np.inf)]),
       n_outliers=st.sampled_from([0] * 6 + [1, -1, 2.5, None]),
       deformation=BAD_FRACTIONS, density=BAD_FRACTIONS, flip=BAD_FRACTIONS)
def test_make_subgraph_collection(n_graphs, n_universe, p_keep, n_outliers, deformation,
                                  density, flip):
    from transync.datasets import make_subgraph_collection

    if n_universe == 10**9:
        n_universe = 6
    c = call(make_subgraph_collection, n_graphs, n_universe, p_keep, n_outliers, deformation,
             density, flip, rng=0)
    if c is REFUSED:
        return
    check(len(c.graphs) == n_graphs, "number of graphs")
    sizes = [g.n_nodes for g in c.graphs]
    check(min(sizes) >= 1, f"a graph without nodes: sizes {sizes}")
    for g in c.graphs:
        check_finite_array(g.adjacency, "adjacency")
    truth = c.ground_truth
    _check_labels(truth.labels, sizes, truth.n_universe, "ground truth")


@MEDIUM
@given(pw_sizes=pairwise_dicts(), pass_sizes=st.booleans(),
       weights=st.one_of(st.none(), st.none(), float_arrays((3, 3)), any_arrays(max_dims=2)))
def test_estimate_universe(pw_sizes, pass_sizes, weights):
    from transync.synchronization import estimate_universe

    pw, sizes = pw_sizes
    est = call(estimate_universe, pw, sizes=sizes if pass_sizes else None, weights=weights)
    if est is REFUSED:
        return
    d = est.n_universe
    check(isinstance(d, (int, np.integer)), f"estimate_universe: n_universe {d!r}")
    seen = [len(v) if np.ndim(v) == 1 else np.shape(v)[0] for v in pw.values()]
    check(d >= max(seen + [0]), f"estimate_universe: {d} below the largest object")


@st.composite
def block_collections(draw):
    """(K, N, n): an (N, N, n*n, n*n) array of symmetric non-negative blocks times a nasty scale
    (sometimes raw junk)."""
    N, n = draw(st.integers(2, 4)), draw(st.integers(1, 3))
    m = n * n
    if draw(st.integers(0, 5)) == 0:
        return draw(float_arrays((N, N, m, m))), N, n
    B = draw(float_arrays((N, N, m, m), elements=tame_floats))
    K = (B + np.swapaxes(B, 2, 3)) / 2
    with np.errstate(all="ignore"):
        K = K * draw(SCALES)
    return K, N, n


@COSTLY
@given(block_collections(), st.sampled_from(["rrwm", "ga", "pf", "sm", "x"]),
       st.sampled_from([{}] * 6 + [{"sync_every": 1}, {"sync_every": 0}, {"damping": 0.5},
                                   {"damping": 2.0}, {"options": {"max_iter": 0}},
                                   {"options": {"bogus": 1}}, {"sync": 3}]),
       st.booleans())
def test_run_lockstep(Kn, solver, extra, with_sync):
    """PairAffinities.from_blocks -> run_lockstep on any blocks: valid assignments, finite
    soft iterates and scores, or a named refusal."""
    from transync.multigraph import PairAffinities, run_lockstep

    K, N, n = Kn
    aff = call(PairAffinities.from_blocks, K, n=n)
    if aff is REFUSED:
        return
    kw = dict(extra)
    if with_sync and "sync" not in kw:
        kw["sync"] = lambda X: np.broadcast_to(X.mean(0), X.shape).copy()
    out = call(run_lockstep, aff, solver=solver, **kw)
    if out is REFUSED:
        return
    P = len(aff)
    A = np.asarray(out.assignments)
    check(A.shape == (P, n), f"run_lockstep: assignments shape {A.shape}")
    for p in range(P):
        check_assignment(A[p], n, n, f"run_lockstep: assignments[{p}]")
    check_finite_array(out.soft, "run_lockstep: soft")
    check_finite_array(out.scores, "run_lockstep: scores")


@COSTLY
@given(block_collections(), st.data(),
       st.sampled_from(["cao-pc", "cao", "cao-c", "cao-uc", "x"]),
       st.sampled_from([{}] * 6 + [{"lambda_init": -0.1}, {"lambda_init": np.nan},
                                   {"lambda_step": 0.5}, {"lambda_max": 2.0},
                                   {"max_iter": 0}, {"max_iter": -1}, {"immune_iter": 10},
                                   {"update": "sequential"}, {"update": "x"}]))
def test_cao(Kn, data, variant, extra):
    """cao on any blocks and any initial maps: permutation maps and finite scores, or a named
    refusal (non-permutation initial maps, missing pairs, bad parameters)."""
    from transync.multigraph import PairAffinities, cao

    K, N, n = Kn
    aff = call(PairAffinities.from_blocks, np.abs(np.nan_to_num(K)), n=n)
    if aff is REFUSED:
        return
    pairs = np.asarray(aff.pairs)
    kind = data.draw(st.sampled_from(["perm"] * 6 + ["junk", "drop", "nan_score"]))
    if kind == "junk":
        initial = data.draw(hnp.arrays(np.int64, (len(pairs), n), elements=st.integers(-1, n)))
    else:
        initial = np.array([data.draw(st.permutations(list(range(n)))) for _ in pairs],
                           dtype=np.int64).reshape(len(pairs), n)
    if kind == "drop":
        pairs, initial = pairs[1:], initial[1:]
    def nan_score(p_idx, a):
        return np.full(len(p_idx), np.nan)

    score = nan_score if kind == "nan_score" else aff.score_assignments
    out = call(cao, initial, pairs, N, score, variant=variant, **extra)
    if out is REFUSED:
        return
    A = np.asarray(out.assignments)
    check(A.shape == initial.shape, f"cao: assignments shape {A.shape}")
    for p in range(len(A)):
        check(sorted(A[p].tolist()) == list(range(n)), f"cao: row {p} not a permutation")
    check_finite_array(out.scores, "cao: scores")


@MEDIUM
@given(n_items=st.sampled_from([0, 1, 3, 10, 100, -1, 2.5, None, "3"]),
       executor=st.sampled_from([None, "serial", 1, 2, 0, -1, "x", 2.5, object()]),
       min_chunk=st.sampled_from([8, 1, 0, -1, 2.5]),
       chunks_per_worker=st.sampled_from([4, 1, 0, -1]))
def test_split_chunks(n_items, executor, min_chunk, chunks_per_worker):
    from transync.parallel import split_chunks

    out = call(split_chunks, n_items, executor, min_chunk=min_chunk,
               chunks_per_worker=chunks_per_worker)
    if out is REFUSED:
        return
    flat = np.concatenate(out) if out else np.zeros(0, np.int64)
    check(sorted(flat.tolist()) == list(range(n_items)), "split_chunks: not a partition")


IDX = st.sampled_from([0, 1, 2, -1, 3, 10**12, 1.0, 1.5, "0", None, True, np.int64(1)])


@MEDIUM
@given(i=IDX, j=IDX, g=IDX, k=IDX,
       pairs=st.one_of(st.none(), any_arrays(max_dims=2), st.just([(0, 1), (1, 2)])),
       other=st.one_of(st.just("same"), any_arrays(max_dims=2),
                       st.just([np.array([0, 1]), np.array([1, 0])])),
       max_size=st.sampled_from([20000, 0, -1, 2.5, 10**12]))
def test_result_accessors(i, j, g, k, pairs, other, max_size):
    """The accessors of every result type (pairwise, absolute, block, atom, pairwise_dict,
    stacked_blocks, maps_from, accuracy, to_matrix) on any index: a valid value or a named
    refusal, never an IndexError."""
    from transync import match_collection, synchronize_doubly_stochastic, synchronize_permutations
    from transync.graphs import Graph
    from transync.permutations import MultiMatching

    m = MultiMatching([np.array([0, 1, 2]), np.array([2, 0, -1]), np.array([1, 2])])
    pw = {(0, 1): np.array([1, 2, 0]), (1, 2): np.array([0, 2, 1]), (0, 2): np.array([2, 1, 0])}
    ps = synchronize_permutations(pw, rng=0)
    bs = synchronize_doubly_stochastic({key: np.eye(3)[v] for key, v in pw.items()}, rng=0)
    pts = np.random.default_rng(0).random((3, 4, 2))
    mc = match_collection([Graph.from_points(p) for p in pts], progress=False, rng=0)
    sizes = {"m": [3, 3, 2], "ps": [3, 3, 3], "bs": [3, 3, 3], "mc": [4, 4, 4]}
    for name, obj in (("m", m), ("ps", ps), ("bs", bs), ("mc", mc)):
        n = sizes[name]
        a = call(obj.pairwise, i, j)
        if a is not REFUSED:
            check(isinstance(i, (int, np.integer)) and isinstance(j, (int, np.integer))
                  and not isinstance(i, bool) and not isinstance(j, bool),
                  f"{name}.pairwise accepted indices {i!r}, {j!r}")
            check_assignment(a, n[i], n[j], f"{name}.pairwise({i}, {j})")
        if hasattr(obj, "absolute"):
            X = call(obj.absolute, g)
            if X is not REFUSED:
                check(np.shape(X)[0] == n[g], f"{name}.absolute({g}): shape {np.shape(X)}")
        if hasattr(obj, "block"):
            B = call(obj.block, i, j)
            if B is not REFUSED:
                check_finite_array(B, f"{name}.block")
        if hasattr(obj, "atom"):
            call(obj.atom, k)
        if hasattr(obj, "stacked_blocks"):
            S = call(obj.stacked_blocks, pairs)
            if S is not REFUSED:
                check_finite_array(S, f"{name}.stacked_blocks")
        if name in ("m", "ps"):
            D = call(obj.pairwise_dict, pairs)
            if D is not REFUSED:
                for (u, v), av in D.items():
                    check_assignment(av, n[u], n[v], f"{name}.pairwise_dict[{(u, v)}]")
        if name in ("m", "mc"):
            acc = call(obj.accuracy, m if isinstance(other, str) and name == "m" else
                       (mc.matching if isinstance(other, str) else other))
            if acc is not REFUSED:
                check_finite_scalar(acc, f"{name}.accuracy")
                check(0 <= acc <= 1, f"{name}.accuracy {acc}")
    M = call(m.to_matrix, max_size=max_size)
    if M is not REFUSED:
        check(M.shape == (8, 8), f"MultiMatching.to_matrix: shape {M.shape}")
    F = call(m.maps_from, {(0, 1): np.array([1, 0, 2])}, pairs)
    if F is not REFUSED:
        check(np.asarray(F).dtype.kind in "iu", "MultiMatching.maps_from: dtype")


def test_hunted_cases():
    """Inputs that contract hunts (derandomize=False, hundreds of examples) found breaking the
    contract; each failed on the code before its fix."""
    from transync import match_collection
    from transync.graphs import Graph
    from transync.matching import ga, ipfp, pf, rrwm, sinkhorn_batch, sm, verify_assignment
    from transync.multigraph import PairAffinities, cao, run_lockstep
    from transync.permutations import MultiMatching

    # a 1-d `pairs` of odd length: a reshape error that named nothing
    m = MultiMatching([np.array([0, 1]), np.array([1, 0])])
    check(call(m.check_pairs, np.array([0.0])) is REFUSED, "odd 1-d pairs accepted")
    # an assignment into a node the other block does not have: the message named no argument
    check(call(metrics.constraint_violations, {(0, 1): np.array([0]), (1, 0): np.array([1])})
          is REFUSED, "inconsistent sizes accepted")
    # CAO with unequal sizes, sm online: the messages named `partial` / `mode` without quotes
    pts = np.random.default_rng(0).random((3, 2))
    g2, g3 = Graph.from_points(pts[:2]), Graph.from_points(pts)
    check(call(match_collection, [g2, g3], solver="cao", progress=False) is REFUSED, "cao sizes")
    check(call(match_collection, [g3, g3], solver="sm", progress=False) is REFUSED, "sm online")
    # a negative seed: numpy's "expected non-negative integer" named nothing
    check(call(match_collection, [g3, g3], rng=-1, progress=False) is REFUSED, "rng=-1")
    # subnormal affinities: NaN and RuntimeWarnings inside every scaled solver
    # (RRWM's pygmtools variant, match_collection's offline default, was missed at first)
    for solver, kw in ((rrwm, {}), (rrwm, dict(variant="pygmtools")), (ga, {}), (pf, {}),
                       (sm, {}), (ipfp, {})):
        check(call(solver, np.full((4, 4), 1e-310), n1=2, n2=2, **kw) is REFUSED,
              f"{solver.__name__} {kw} on a subnormal K")
    # entries near float64's largest: every solver overflowed (RuntimeWarnings, NaN)
    for solver in (rrwm, ga, pf, sm, ipfp):
        check(call(solver, np.full((4, 4), 1.7e308), n1=2, n2=2) is REFUSED,
              f"{solver.__name__} on a huge K")
    check(call(PairAffinities.from_blocks, np.full((3, 3, 4, 4), 1e300), n=2) is REFUSED,
          "huge K blocks accepted")
    tiny = PairAffinities.from_blocks(np.full((2, 2, 1, 1), 5e-324), n=1)
    for solver, kw in (("rrwm", {}), ("rrwm", dict(options={"variant": "pygmtools"})),
                       ("ga", {}), ("pf", {})):
        check(call(run_lockstep, tiny, solver=solver, **kw) is REFUSED,
              f"lock-step {solver} {kw}, tiny K")
    # a million graphs of which three are observed: the components of the observation graph
    # were gathered one comparison pass per component (quadratic: a hang)
    from transync.kernels import synchronize_alignments
    check(call(synchronize_alignments, np.array([[1, 0, 2], [1, 2, 0], [2, 1, 0]]),
               np.array([[0, 1], [0, 2], [1, 2]]), 10**6, n=3) is REFUSED,
          "disconnected alignments accepted")
    # a subnormal kernel in the scaling domain: 1 / (A v) overflowed with a RuntimeWarning
    check(call(sinkhorn_batch, np.array([[[5e-324]]])) is REFUSED, "subnormal kernel accepted")
    # point sets 1e311 apart in scale: verified=True with an inf / NaN transform
    q = np.random.default_rng(0).random((12, 2))
    check(call(verify_assignment, q * 1e-300, q * 1e11, np.arange(12), rng=0) is REFUSED,
          "a transform that overflows accepted")
    # subnormal points: a divide-by-zero RuntimeWarning before the named refusal
    check(call(verify_assignment, np.zeros((1, 2)), np.array([[5e-324, 0.0], [0.0, 0.0]]),
               np.array([0])) is REFUSED, "subnormal points accepted")
    # view centres near float64's largest: np.linalg.norm overflowed with a RuntimeWarning
    from transync.homography import segment_plane_evidence, view_graph_pairs
    H = np.full((2, 3, 3), 5.5e-263)
    H[0, 0, 0] = 1.0
    check(call(view_graph_pairs, H, [(40, 30), (40, 30)], reference=0, k=3) is not REFUSED,
          "far view centres refused")
    # a float64 image beyond float32's range: an 'overflow in cast' warning, then "not finite";
    # now rescaled to grey levels 0..255 as to_gray does (the pipeline's one intensity rule)
    ev = call(segment_plane_evidence, [np.full((8, 8), 1e300)], np.eye(3)[None])
    check(ev is not REFUSED and np.isfinite(ev.median).all() and ev.median.max() <= 255,
          "an image beyond float32 not brought to grey levels")
    from transync.homography import mean_warped_image
    check(call(mean_warped_image, [np.array([[1e300]])], np.eye(3)[None], size=(16, 12))
          is REFUSED, "mean_warped_image: an image beyond float32 accepted")
    # a homography sending a unit-square corner to infinity: the objective was inf (one
    # infinite corner residual in the mean) after an 'invalid value' RuntimeWarning
    T = np.ones((2, 2, 3, 3))
    T[0, 1] = [[0, 1, 1], [1, 0, 1], [1, 1, 1]]
    T[1, 0] = [[0, 1, 1], [1, 1, 1], [1, 0, 1]]
    for robust in (False, True):
        out = call(transync.synchronize_homographies, T, robust=robust)
        check(np.isfinite(out.objective) and np.isinf(out.residuals[1, 0]),
              f"infinite corner residual, robust={robust}: objective {out.objective}")
    # scores near the float64 limit: CAO's mean score overflowed (RuntimeWarning, inf history);
    # blocks beyond MAX_AFFINITY_SCALE are refused now, the largest accepted must still work
    check(call(PairAffinities.from_blocks, np.full((3, 3, 1, 1), 1.7976931348623157e308), n=1)
          is REFUSED, "K blocks at float64's largest accepted")
    huge = PairAffinities.from_blocks(np.full((3, 3, 1, 1), 1e300), n=1)
    out = call(cao, np.zeros((3, 1), np.int64), np.asarray(huge.pairs), 3,
               huge.score_assignments)
    check(out is not REFUSED and bool(np.isfinite(out.history["score"]).all()),
          "cao history not finite")


# ----------------------------------------------------------------------------------- homography

@st.composite
def images(draw, min_side=0, max_side=24):
    """An image of any small shape (gray, 1/3/4/2 channels, or junk dims) and dtype."""
    h = draw(st.integers(min_side, max_side))
    w = draw(st.integers(min_side, max_side))
    shape = draw(st.sampled_from([(h, w)] * 4 + [(h, w, 3)] * 3
                                 + [(h, w, 1), (h, w, 4), (h, w, 2), (h,), (2, h, w, 3)]))
    kind = draw(st.sampled_from(["u8"] * 5 + ["f01"] * 3 + ["f", "b", "i16", "c", "U"]))
    return draw(arrays_of_kind(kind, shape))


def textured(rng, h=64, w=64):
    """A random blocky texture (SIFT finds features on it)."""
    small = rng.integers(0, 256, (h // 8, w // 8)).astype(np.uint8)
    return np.kron(small, np.ones((8, 8), np.uint8))


HOMOGRAPHIES = st.one_of(
    st.sampled_from([np.eye(3), np.diag([2.0, 2.0, 1.0]), np.array([[1, 0, 3], [0, 1, -2],
                                                                   [0, 0, 1.0]]),
                     np.zeros((3, 3)), np.full((3, 3), np.nan), np.eye(3)[:2],
                     np.array([[1, 0, 0], [0, 1, 0], [1e-300, 0, 1e-300]]),
                     np.array([[1e300, 0, 0], [0, 1e300, 0], [0, 0, 1.0]])]),
    float_arrays((3, 3)), any_arrays(max_dims=2))


@MEDIUM
@given(images())
def test_to_gray_and_sift(image):
    from transync import homography as hg

    g = call(hg.to_gray, image)
    if g is REFUSED:
        return
    g = np.asarray(g)
    check(g.ndim == 2 and g.shape == np.shape(image)[:2], f"to_gray: shape {g.shape}")
    check_finite_array(g, "to_gray")
    out = call(hg.sift_features, g, n_features=50)
    if out is REFUSED:
        return
    kp, desc = out
    check_finite_array(kp, "sift_features: keypoints")
    check(len(kp) == len(desc), "sift_features: keypoints and descriptors differ in number")


@MEDIUM
@given(images(), HOMOGRAPHIES,
       st.sampled_from([(16, 16), (1, 1), (0, 5), (-1, 4), (2.5, 3), (10**6, 10**6), "x"]),
       st.sampled_from([(0, 0), (3, -2), (np.nan, 0), "x"]),
       st.sampled_from([1, 0, 3, 99]))
def test_warp_to_reference(image, H, size, offset, interpolation):
    from transync import homography as hg

    if isinstance(size, tuple) and size == (10**6, 10**6):
        size = (10**6, 1)
    out = call(hg.warp_to_reference, image, H, size, offset=offset, interpolation=interpolation)
    if out is REFUSED:
        return
    out = np.asarray(out)
    check_finite_array(out, "warp_to_reference")
    check(out.shape[:2] == (size[1], size[0]) or out.shape[:2] == tuple(size),
          f"warp_to_reference: shape {out.shape} for size {size}")


@COSTLY
@given(st.lists(images(min_side=1), min_size=0, max_size=3), st.data(),
       st.sampled_from([(16, 12), (0, 3), (3.5, 2), None]), st.booleans())
def test_mean_warped_image(imgs, data, size, normalize):
    from transync import homography as hg

    Hs = [data.draw(HOMOGRAPHIES) for _ in imgs]
    if data.draw(st.booleans()):
        Hs = np.stack([np.eye(3)] * len(imgs)) if imgs else np.zeros((0, 3, 3))
    out = call(hg.mean_warped_image, imgs, Hs, size=size, normalize=normalize)
    if out is REFUSED:
        return
    mean, count = out
    check_finite_array(count, "mean_warped_image: count")
    check(np.shape(mean) == np.shape(count), "mean_warped_image: mean and count differ")
    check_finite_array(np.asarray(mean)[np.asarray(count) > 0], "mean_warped_image: mean")
    check(bool(np.all(np.isnan(np.asarray(mean)[np.asarray(count) == 0]))),
          "mean_warped_image: a value where no view contributes")


@COSTLY
@given(st.integers(0, 2**16), HOMOGRAPHIES, st.sampled_from([1, 2, 3, 0, -1]),
       st.sampled_from([60, 1, 0, -1]), st.sampled_from([1e-5, 0.0, -1.0, np.nan]),
       st.sampled_from([3, 1, 0, 4, -3]), st.booleans())
def test_refine_homography_ecc(seed, H, levels, max_iter, eps, gauss_size, junk_image):
    from transync import homography as hg

    rng = np.random.default_rng(seed)
    t = textured(rng, 32, 32)
    img = t if not junk_image else rng.random((32, 32)) * np.nan
    out = call(hg.refine_homography_ecc, t, img, H, levels=levels, max_iter=max_iter, eps=eps,
               gauss_size=gauss_size)
    if out is REFUSED:
        return
    H_out, ok = out
    check_finite_array(H_out, "refine_homography_ecc")
    check(np.shape(H_out) == (3, 3), f"refine_homography_ecc: shape {np.shape(H_out)}")


@MEDIUM
@given(st.integers(0, 40), st.data(), st.sampled_from([5.0, 0.0, -1.0, np.nan, 1e300]),
       st.sampled_from([10, 4, 3, 0, -1, 2.5]), st.sampled_from([None, 1, 0, -1, 5]),
       st.sampled_from(["ransac", "magsac", "lmeds", "x"]))
def test_extract_planes(n, data, threshold, min_inliers, max_planes, method):
    from transync import homography as hg

    x1 = data.draw(float_arrays((n, 2), elements=st.floats(0, 100, width=64)))
    if data.draw(st.booleans()):
        x2 = x1 + data.draw(st.sampled_from([0.0, 1.0, 50.0]))
    else:
        x2 = data.draw(st.one_of(float_arrays((n, 2)), any_arrays(max_dims=2)))
    out = call(hg.extract_planes, x1, x2, threshold=threshold, min_inliers=min_inliers,
               max_planes=max_planes, method=method, max_iter=200, rng=0)
    if out is REFUSED:
        return
    for H in out.homographies:
        check_finite_array(H, "extract_planes: homography")
    lab = np.asarray(out.labels)
    check(lab.shape == (n,), f"extract_planes: labels shape {lab.shape}")
    check(bool(np.all((lab >= 0) & (lab <= len(out.homographies)))),
          f"extract_planes: labels outside [0, {len(out.homographies)}]")


@MEDIUM
@given(st.one_of(any_arrays(max_dims=2), hnp.arrays(np.int64, 6, elements=st.integers(-1, 2))),
       st.one_of(any_arrays(max_dims=2), hnp.arrays(np.int64, 6, elements=st.integers(-1, 2))))
def test_misclassification_error(pred, truth):
    from transync import homography as hg

    e = call(hg.misclassification_error, pred, truth)
    if e is REFUSED:
        return
    check_finite_scalar(e, "misclassification_error")
    check(0 <= e <= 1, f"misclassification_error {e}")


@MEDIUM
@given(st.integers(1, 4), st.data(),
       st.sampled_from([(64, 48), (0, 48), (1, 1), (np.nan, 3), "x"]),
       st.sampled_from([0.05, 0.0, 1.0, -0.1, np.nan]))
def test_pairwise_corner_error(N, data, size, min_overlap):
    from transync import homography as hg

    Ht = np.stack([data.draw(st.sampled_from([np.eye(3), np.diag([1.1, 0.9, 1.0]),
                                              np.array([[1, 0, 5], [0, 1, 0], [0, 0, 1.0]])]))
                   for _ in range(N)])
    He = Ht.copy() if data.draw(st.booleans()) else data.draw(
        st.one_of(float_arrays((N, 3, 3)), any_arrays(max_dims=3)))
    E = call(hg.pairwise_corner_error, He, Ht, image_size=size, min_overlap=min_overlap)
    if E is REFUSED:
        return
    E = np.asarray(E, dtype=float)
    check(E.ndim == 1 and len(E) <= N * (N - 1), f"pairwise_corner_error: shape {E.shape}")
    check(bool(np.all(E >= 0)), f"pairwise_corner_error: negative or NaN errors {E}")


@MEDIUM
@given(st.integers(0, 5), st.data(), st.sampled_from([0, 1, -1, 7, 2.5]),
       st.sampled_from([3, 1, 0, -1, 100]))
def test_view_graph_pairs(N, data, reference, k):
    from transync import homography as hg

    H = np.stack([np.array([[1, 0, 10.0 * g], [0, 1, 0], [0, 0, 1]]) for g in range(N)]) \
        if N else np.zeros((0, 3, 3))
    if data.draw(st.integers(0, 4)) == 0:
        H = data.draw(st.one_of(float_arrays((N, 3, 3)), any_arrays(max_dims=3)))
    sizes = data.draw(st.sampled_from([[(40, 30)] * N, (40, 30), [(0, 30)] * N, "x",
                                       [(40, 30)] * (N + 1)]))
    out = call(hg.view_graph_pairs, H, sizes, reference=reference, k=k)
    if out is REFUSED:
        return
    for p in out:
        i, j = p
        check(0 <= i < N and 0 <= j < N and i != j, f"view_graph_pairs: pair {p}")


@COSTLY
@given(st.integers(0, 2**16), st.sampled_from([2, 3, 1, 0]), st.data())
def test_estimate_pairwise_homographies(seed, n_views, data):
    """On tiny textures (few or no features) and junk: pairwise maps finite or absent, never a
    cv2.error."""
    from transync import homography as hg

    rng = np.random.default_rng(seed)
    imgs = [textured(rng, 48, 48) for _ in range(n_views)]
    if imgs and data.draw(st.booleans()):
        imgs[-1] = data.draw(images())
    kw = data.draw(st.sampled_from([{}, {"min_inliers": 4}, {"ratio": 1.5},
                                    {"threshold": -1.0}, {"method": "x"}, {"pairs": [(0, 0)]},
                                    {"max_iter": 0}, {"confidence": 1.5}, {"refine": False}]))
    out = call(hg.estimate_pairwise_homographies, imgs, n_features=200, rng=0, **kw)
    if out is REFUSED:
        return
    H, mask = np.asarray(out.H), np.asarray(out.mask)
    check(H.shape == (n_views, n_views, 3, 3), f"estimate_pairwise_homographies: H {H.shape}")
    check_finite_array(H[mask], "estimate_pairwise_homographies: H of successful pairs")
    check(bool(np.array_equal(mask, mask.T)), "estimate_pairwise_homographies: mask asymmetric")


@COSTLY
@given(st.integers(0, 2**16), st.sampled_from([1, 2, 3]), st.data())
def test_segment_plane_evidence(seed, n_views, data):
    from transync import homography as hg

    rng = np.random.default_rng(seed)
    side = data.draw(st.sampled_from([24, 24, 9, 7]))
    imgs = [textured(rng, 32, 32)[:side, :side].astype(np.float32) for _ in range(n_views)]
    H = np.stack([np.array([[1, 0, data.draw(st.sampled_from([0.0, 1.0, 3.0]))], [0, 1, 0],
                            [0, 0, 1.0]]) for _ in range(n_views)])
    if data.draw(st.integers(0, 4)) == 0:
        H = data.draw(st.one_of(HOMOGRAPHIES, float_arrays((n_views, 3, 3))))
    if data.draw(st.integers(0, 4)) == 0:
        imgs[0] = data.draw(images())
    kw = data.draw(st.sampled_from([{}, {"window": 3}, {"window": 0}, {"margin": 3.0},
                                    {"smooth": 0.0}, {"min_views": 5}, {"threshold": 1.5},
                                    {"reference": n_views}, {"window": 2}]))
    out = call(hg.segment_plane_evidence, imgs, H, rng=0, **kw)
    if out is REFUSED:
        return
    check(len(out.masks) == n_views, "segment_plane_evidence: one mask per view")
    for k, m in enumerate(out.masks):
        check(np.shape(m) == np.shape(imgs[k]), f"segment_plane_evidence: masks[{k}] shape")
        check(np.asarray(m).dtype == bool, f"segment_plane_evidence: masks[{k}] not boolean")


@COSTLY
@given(st.integers(0, 2**16), st.sampled_from([2, 3]), st.data())
def test_to_reference_and_chained_homographies(seed, n_views, data):
    """Tiny views (few features): finite homographies, NaN for views without an estimate, or a
    named refusal."""
    from transync import homography as hg

    rng = np.random.default_rng(seed)
    base = textured(rng, 64, 64)
    imgs = [base] + [np.roll(base, (2 * k, 3 * k), axis=(0, 1)) for k in range(1, n_views)]
    if data.draw(st.integers(0, 3)) == 0:
        imgs[-1] = textured(rng, 64, 64)
    ref = data.draw(st.sampled_from([0, 0, 1, -1, n_views]))
    for fn in (hg.to_reference_homographies, hg.chained_homographies):
        H = call(fn, imgs, reference=ref, n_features=200)
        if H is REFUSED:
            continue
        H = np.asarray(H)
        check(H.shape == (n_views, 3, 3), f"{fn.__name__}: shape {H.shape}")
        ok = np.isfinite(H).all(axis=(1, 2))
        check(bool(np.all(ok | np.isnan(H).all(axis=(1, 2)))),
              f"{fn.__name__}: a homography partly NaN or infinite")


@COSTLY
@given(st.integers(0, 2**16), st.sampled_from([2, 3]), st.data())
def test_estimate_plane_homographies(seed, n_views, data):
    """The pipeline on small views (often too few features) and junk options: homographies
    finite or NaN per view, boolean masks of the views' shapes, or a named refusal."""
    from transync import homography as hg

    rng = np.random.default_rng(seed)
    base = textured(rng, 96, 96)
    shifts = [(0, 0)] + [(2 * k, 3 * k) for k in range(1, n_views)]
    imgs = [np.roll(base, s, axis=(0, 1)) for s in shifts]
    if data.draw(st.integers(0, 3)) == 0:
        imgs[-1] = data.draw(st.one_of(images(), st.just(textured(rng, 96, 96))))
    kw = data.draw(st.sampled_from([{}, {}, {"dense": False}, {"segment": False},
                                    {"rectify": False}, {"robust": False},
                                    {"pairs": [(0, 1)]}, {"pairs": "all"}, {"pairs": "x"},
                                    {"pairs": [(0, 0)]}, {"reference": n_views},
                                    {"threshold": -1.0}, {"n_neighbors": 0},
                                    {"max_iter": 0}, {"tol": np.nan}, {"bogus": 1},
                                    {"dense": "yes"}, {"callback": 3}]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnlinkedViewsWarning)
        res = call(hg.estimate_plane_homographies, imgs, **{"n_features": 300, "max_iter": 1,
                                                            "rng": 0, **kw})
    if res is REFUSED:
        return
    H = np.asarray(res.homographies)
    check(H.shape == (n_views, 3, 3), f"estimate_plane_homographies: shape {H.shape}")
    ok = np.isfinite(H).all(axis=(1, 2))
    check(bool(np.all(ok | np.isnan(H).all(axis=(1, 2)))),
          "estimate_plane_homographies: a homography partly NaN")
    check(bool(ok[kw.get("reference", 0)]), "the reference view has no homography")
    for k, m in enumerate(res.masks):
        check(np.shape(m) == np.shape(imgs[k])[:2] and np.asarray(m).dtype == bool,
              f"estimate_plane_homographies: masks[{k}]")


@MEDIUM
@given(st.lists(st.one_of(images(min_side=14, max_side=20), st.just("nofile.png"),
                          st.none(), st.integers()), min_size=0, max_size=3))
def test_load_images(items):
    from transync import homography as hg

    out = call(hg.load_images, items)
    if out is REFUSED:
        return
    check(len(items) > 0, "load_images([]): documented ValueError, returned []")
    check(len(out) == len(items), "load_images: one image per item")
    for im in out:
        check_finite_array(im, "load_images")


@COSTLY
@given(st.integers(0, 2**16), st.sampled_from([2, 3]), st.data())
def test_rectified_pairwise_and_evaluate_alignment(seed, n_views, data):
    """estimate_rectified_pairwise and evaluate_alignment on small shifted textures, junk
    homographies, masks and options: finite results or a named refusal."""
    from transync import homography as hg
    from transync.geometry import translation

    rng = np.random.default_rng(seed)
    base = textured(rng, 96, 96)
    shifts = [(0, 0)] + [(2 * k, 3 * k) for k in range(1, n_views)]
    imgs = [np.roll(base, s, axis=(0, 1)) for s in shifts]
    H = np.stack([translation(-s[1], -s[0]) for s in shifts])
    if data.draw(st.integers(0, 3)) == 0:
        H = data.draw(st.one_of(HOMOGRAPHIES, float_arrays((n_views, 3, 3))))
    pairs = data.draw(st.sampled_from([[(0, 1)], [(0, 1), (1, 0)], [], [(0, 0)], [(0, 5)],
                                       "all", None]))
    kw = data.draw(st.sampled_from([{}, {"margin": -1.0}, {"radius": 0.0}, {"guided": "no"},
                                    {"reference": 9}, {"min_inliers": 4}, {"ratio": 2.0}]))
    out = call(hg.estimate_rectified_pairwise, imgs, H, pairs, n_features=300, rng=0, **kw)
    if out is not REFUSED:
        mask = np.asarray(out.mask)
        check_finite_array(np.asarray(out.H)[mask], "estimate_rectified_pairwise: H")
    masks = [np.ones(im.shape, bool) for im in imgs]
    if data.draw(st.integers(0, 3)) == 0:
        masks = data.draw(st.sampled_from([None, masks[:1], [np.ones((3, 3), bool)] * n_views]))
    H_est = H + data.draw(st.sampled_from([0.0, 0.0, 1e-3, np.nan])) \
        if np.asarray(H).dtype.kind == "f" else H
    res = call(hg.evaluate_alignment, imgs, H_est, H, masks_true=masks,
               pairwise=data.draw(st.booleans()))
    if res is not REFUSED:
        for key, v in res.items():
            check(isinstance(v, (float, int, np.floating, np.integer)), f"{key}: {v!r}")
            check(not np.isnan(v) or key.startswith("pairwise"), f"evaluate_alignment[{key}] NaN")


def test_hunted_homography_cases():
    """Inputs that contract hunts found breaking the contract in the homography layer; each
    failed on the code before its fix."""
    from transync import homography as hg

    H = np.array([[-1e300, -2.65, 4.31], [-2.65, -2.65, 5e-324], [-2.65, -2.65, -2.65]])
    # a 4-d array as an image: OpenCV's warpPerspective crashed the interpreter (SIGSEGV)
    check(call(hg.mean_warped_image, [np.zeros((2, 18, 3, 3), np.float32)], H[None],
               size=(3, 2)) is REFUSED, "a 4-d image accepted")
    check(call(hg.warp_to_reference, np.zeros((2, 18, 3, 3), np.float32), H, (3, 2))
          is REFUSED, "a 4-d image accepted")
    # colour images in mean_warped_image: a numpy broadcasting error that named nothing
    check(call(hg.mean_warped_image, [np.zeros((5, 5, 3))], np.eye(3)[None], size=(8, 8))
          is REFUSED, "a colour image accepted by mean_warped_image")
    # empty and float images: cv2.error from to_gray and sift_features
    check(call(hg.to_gray, np.zeros((0, 5), np.uint8)) is REFUSED, "an empty image")
    check(call(hg.sift_features, np.zeros((20, 20))) is REFUSED, "a float image for SIFT")
    # huge floats: float32 overflow warnings in to_gray and extract_planes
    g = call(hg.to_gray, np.array([[0.0, 1e300], [3.0, 4.0]]))
    check(g is not REFUSED and np.asarray(g).dtype == np.uint8, "to_gray on huge floats")
    check(call(hg.extract_planes, np.full((6, 2), 1e300), np.ones((6, 2))) is REFUSED,
          "extract_planes on coordinates beyond float32")
    # an initial warp whose inverse has a zero [2, 2] entry: divide by zero, then NaN
    t = textured(np.random.default_rng(0), 32, 32)
    check(call(hg.refine_homography_ecc, t, t, np.eye(3)[[1, 2, 0]], levels=1) is REFUSED,
          "ECC from a warp sending the origin to infinity")
    # view_graph_pairs on junk: IndexError / unpacking errors
    for sizes in ((40, 30), [(40, 30)], "x"):
        check(call(hg.view_graph_pairs, np.stack([np.eye(3)] * 2), sizes, reference=0)
              is REFUSED, f"view_graph_pairs accepted sizes={sizes!r}")
    # evaluate_alignment on one (3, 3) estimate instead of a stack: numpy's AxisError; and
    # estimate_rectified_pairwise on non-numeric homographies: a float() conversion error
    imgs = [t, np.roll(t, 2, axis=1)]
    check(call(hg.evaluate_alignment, imgs, np.eye(3), np.stack([np.eye(3)] * 2),
               masks_true=[np.ones((32, 32), bool)] * 2) is REFUSED, "H_est of one matrix")
    check(call(hg.estimate_rectified_pairwise, imgs, np.full((2, 3, 3), "a"), [(0, 1)])
          is REFUSED, "string homographies")
    # pairwise_corner_error on NaN estimates: RuntimeWarning from the matrix product
    E = call(hg.pairwise_corner_error, np.full((2, 3, 3), np.nan), np.stack([np.eye(3)] * 2),
             image_size=(64, 48))
    check(E is not REFUSED and bool(np.all(np.isinf(E))), "NaN estimates: infinite errors")
    # a canvas of 32767 x 32767 pixels: a MemoryError (or the kernel's OOM killer) after
    # allocating 17 GB for the mean image's sum and count; now refused by its pixel count
    check(call(hg.mean_warped_image, [t], np.eye(3)[None], size=(32767, 32767)) is REFUSED,
          "a canvas of 1.07 billion pixels")


def test_harness_flags_low_level_errors():
    """The harness itself: documented errors pass, low-level ones are violations."""
    def named():
        raise ValueError("`x` must be finite, got nan")

    def unnamed():
        raise ValueError("cannot convert float NaN to integer")

    def index():
        raise IndexError("index 5 is out of bounds")

    def warns():
        warnings.warn("overflow encountered", RuntimeWarning)
        return 1

    assert call(named) is REFUSED
    for fn, what in ((unnamed, "names no argument"), (index, "undocumented IndexError"),
                     (warns, "foreign warning RuntimeWarning")):
        with pytest.raises(ContractViolation, match=re.escape(what)):
            call(fn)
