"""Input validation shared by every public function.

Every check raises ``ValueError`` or ``TypeError`` whose message names the argument,
what was expected and what arrived. Internals trust validated inputs.
"""

from __future__ import annotations

import errno
import numbers
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = [
    "as_generator",
    "check_array",
    "check_bool",
    "check_finite",
    "check_int",
    "check_int_array",
    "check_nonnegative",
    "check_path",
    "check_positive",
    "check_probability",
    "check_shape",
    "check_square",
    "check_choice",
    "check_index_pairs",
    "check_homographies",
    "invertible_homographies",
    "check_affinity_scale",
    "check_affinity_magnitude",
    "frozen_copy",
    "MIN_AFFINITY_SCALE",
    "MAX_AFFINITY_SCALE",
]


def as_generator(rng, name: str = "rng") -> np.random.Generator:
    """Return a ``numpy.random.Generator`` from ``None``, an int seed or a Generator (SPEC 7);
    ``name``: the argument, for messages."""
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (bool, np.bool_)):
        raise TypeError(f"`{name}` must be None, an int or a numpy.random.Generator, got bool "
                        f"{rng!r}")
    if isinstance(rng, numbers.Integral) and rng < 0:
        raise ValueError(f"`{name}` must be None, a non-negative int seed or a "
                         f"numpy.random.Generator, got {rng}")
    if rng is None or isinstance(rng, (numbers.Integral, np.random.SeedSequence)):
        return np.random.default_rng(rng)
    if isinstance(rng, np.random.RandomState):
        return np.random.default_rng(rng.randint(2**31))
    raise TypeError(
        f"`{name}` must be None, an int or a numpy.random.Generator, got {type(rng).__name__}"
    )


def _describe(x) -> str:
    if isinstance(x, np.ndarray):
        return f"array of shape {x.shape} and dtype {x.dtype}"
    return f"{type(x).__name__}"


def check_array(x, name: str, *, ndim: int | Sequence[int] | None = None, dtype=float,
                finite: bool = True, copy: bool = False) -> np.ndarray:
    """Convert ``x`` to an array of ``dtype`` and check its number of dimensions and finiteness."""
    if x is None:
        raise TypeError(f"`{name}` must be an array, got None")
    if hasattr(x, "tocsr") and hasattr(x, "nnz"):       # scipy.sparse, without importing it
        raise TypeError(f"`{name}` must be a dense array, got the scipy.sparse "
                        f"{type(x).__name__} (convert it with .toarray())")
    try:
        is_complex = np.iscomplexobj(x)
    except (TypeError, ValueError):     # ragged nesting: reported below
        is_complex = False
    if is_complex and np.dtype(dtype).kind != "c":
        raise TypeError(f"`{name}` must be real, got complex values ({_describe(x)})")
    if isinstance(x, (str, bytes)):
        raise TypeError(f"`{name}` must be an array, got {type(x).__name__} {x!r:.40}")
    src = x
    if isinstance(x, (list, tuple)):         # read once: its dtype says whether it is text
        try:
            src = np.asarray(x)
        except (TypeError, ValueError):      # ragged nesting: the conversion below reports it
            pass
    if dtype is not None and np.dtype(dtype).kind in "biufc" and \
            isinstance(src, np.ndarray) and src.dtype.kind in "US":
        # numpy would parse "1" as 1.0, which hides a wrong argument
        raise TypeError(f"`{name}` must be numeric, got text ({_describe(x)})")
    try:
        with np.errstate(over="ignore"):     # a narrowing cast (float32): reported below
            arr = np.array(src, dtype=dtype, copy=copy) if copy else np.asarray(src, dtype=dtype)
    except OverflowError:                   # Python ints beyond the dtype's range
        raise ValueError(f"`{name}` must fit in {np.dtype(dtype)}, got integers beyond its "
                         "range") from None
    except (TypeError, ValueError) as exc:
        raise TypeError(f"`{name}` must be convertible to a {np.dtype(dtype)} array, "
                        f"got {_describe(x)}: {exc}") from None
    if ndim is not None:
        allowed = (ndim,) if isinstance(ndim, int) else tuple(ndim)
        if arr.ndim not in allowed:
            want = " or ".join(str(a) for a in allowed)
            raise ValueError(f"`{name}` must have {want} dimensions, got shape {arr.shape}")
    if finite and arr.dtype.kind in "fc" and not np.all(np.isfinite(arr)):
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        if (isinstance(src, np.ndarray) and src.dtype.kind in "fiu"
                and src.dtype.itemsize > arr.dtype.itemsize and np.all(np.isfinite(src))):
            raise ValueError(f"`{name}` must fit in {arr.dtype} (magnitudes up to "
                             f"{float(np.finfo(arr.dtype).max):.3g}), got {bad} entries beyond it "
                             f"(largest {float(np.abs(src).max()):.3g})")
        raise ValueError(f"`{name}` must be finite, got {bad} NaN or infinite entries")
    if (finite and arr.dtype.kind == "b" and isinstance(src, np.ndarray)
            and src.dtype.kind in "fc" and not np.all(np.isfinite(src))):
        # a mask read from floats: NaN would become True
        bad = int(np.size(src) - np.count_nonzero(np.isfinite(src)))
        raise ValueError(f"`{name}` must be finite, got {bad} NaN or infinite entries")
    return arr


def check_finite(x: np.ndarray, name: str) -> np.ndarray:
    if not np.all(np.isfinite(x)):
        raise ValueError(f"`{name}` must be finite, got NaN or infinite entries")
    return x


def check_shape(x: np.ndarray, shape: Sequence[int | str | None], name: str,
                dims: dict[str, int] | None = None) -> dict[str, int]:
    """Check ``x.shape`` against a pattern such as ``("n", "n")`` or ``(None, 2)``.

    Named dimensions must agree with each other and with ``dims``; returns the bound names.

    >>> check_shape(np.zeros((3, 3)), ("n", "n"), name="A")
    {'n': 3}
    """
    dims = dict(dims or {})
    if x.ndim != len(shape):
        raise ValueError(f"`{name}` must have shape {_pattern(shape)}, got shape {x.shape}")
    for size, want in zip(x.shape, shape):
        if want is None:
            continue
        if isinstance(want, str):
            if want in dims and dims[want] != size:
                raise ValueError(f"`{name}` must have shape {_pattern(shape)} with "
                                 f"{want}={dims[want]}, got shape {x.shape}")
            dims[want] = size
        elif size != want:
            raise ValueError(f"`{name}` must have shape {_pattern(shape)}, got shape {x.shape}")
    return dims


def _pattern(shape) -> str:
    return "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"


def check_square(x: np.ndarray, name: str) -> int:
    if x.ndim != 2 or x.shape[0] != x.shape[1]:
        raise ValueError(f"`{name}` must be a square matrix, got shape {x.shape}")
    return x.shape[0]


def nearly_equal(X: np.ndarray, Y: np.ndarray) -> bool:
    """Equal up to rounding, relative to ``X``'s scale: ``numpy.allclose`` with ``rtol=1e-5``
    and an absolute tolerance of ``1e-8`` times ``max |X|`` (its default absolute 1e-8 took any
    two arrays of tiny entries as equal: a directed 3-cycle of weights ~1e-9 as symmetric).
    The one symmetry-up-to-rounding test of the package.

    >>> A = np.array([[0.0, 4e-9], [1e-9, 0.0]])
    >>> bool(np.allclose(A, A.T)), nearly_equal(A, A.T)
    (True, False)
    """
    scale = float(np.abs(X).max()) if X.size else 0.0
    return bool(np.allclose(X, Y, rtol=1e-5, atol=1e-8 * scale))


def check_nonnegative(x: np.ndarray, name: str) -> np.ndarray:
    if x.size and np.min(x) < 0:
        raise ValueError(f"`{name}` must be non-negative, got minimum {float(np.min(x)):.6g}")
    return x


def check_int(value, name: str, *, minimum: int | None = None, maximum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"`{name}` must be an int, got {type(value).__name__} {value!r}")
    value = int(value)
    if minimum is not None and value < minimum:
        raise ValueError(f"`{name}` must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise ValueError(f"`{name}` must be <= {maximum}, got {value}")
    return value


def check_int_array(x, name: str, *, ndim: int | Sequence[int] | None = None,
                    integral_floats: bool = False, allow_bool: bool = False,
                    finite: bool = False, what: str = "integers", keep_dtype: bool = False,
                    copy: bool = False) -> np.ndarray:
    """Check that ``x`` is an array of integers and return it as ``int64``.

    The one "integer array" check of the package; each caller states its policy through the
    keywords (range checks on the values stay with the caller). An empty array of any dtype
    passes (as an empty ``int64`` array of its shape).

    Parameters
    ----------
    x : array_like
        The argument to check.
    name : str
        Its name, for the messages.
    ndim : int or sequence of int, optional
        Allowed numbers of dimensions; any other raises ``ValueError``.
    integral_floats : bool, default=False
        Accept a float array whose entries are all finite integers (``2.0``). Otherwise any
        float dtype is refused.
    allow_bool : bool, default=False
        Accept a boolean array (as 0 and 1).
    finite : bool, default=False
        A float array with NaN or infinite entries raises ``ValueError`` (as
        :func:`check_array`) before the integer check; by default such an array raises
        ``TypeError`` like any other non-integer.
    what : str, default="integers"
        What the entries must be, as the messages say it (``"integer node indices"``).
    keep_dtype : bool, default=False
        A signed integer array keeps its own dtype (no int64 copy of a large int32 array).
    copy : bool, default=False
        Always return a new array; otherwise an ``int64`` array comes back as it is.

    Returns
    -------
    ndarray of int64 (or the input's signed integer dtype with ``keep_dtype``)

    Raises
    ------
    TypeError
        ``None``, a string, ragged nesting, or entries that are not integers: the message
        names the dtype that arrived, or the first non-integral or NaN float and its position.
    ValueError
        The wrong number of dimensions, NaN or infinite entries with ``finite``, or integers
        outside the ``int64`` range.

    Examples
    --------
    >>> check_int_array([2, 0, -1], "assignment")
    array([ 2,  0, -1])
    >>> check_int_array(np.array([2.0, 0.0]), "assignment")
    Traceback (most recent call last):
        ...
    TypeError: `assignment` must hold integers, got dtype float64
    >>> check_int_array(np.array([2.0, 0.0]), "assignment", integral_floats=True)
    array([2, 0])
    >>> check_int_array([[0, 1], [1, 0.5]], "pairs", integral_floats=True,
    ...                 what="integer graph indices")
    Traceback (most recent call last):
        ...
    TypeError: `pairs` must hold integer graph indices, got 0.5 at position (1, 1)
    >>> check_int_array(np.array([], dtype=str), "pairs")
    array([], dtype=int64)
    """
    if x is None:
        raise TypeError(f"`{name}` must be an array, got None")
    if isinstance(x, (str, bytes)):
        raise TypeError(f"`{name}` must be an array of {what}, got {type(x).__name__} {x!r:.40}")
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError) as exc:     # ragged nesting
        raise TypeError(f"`{name}` must be an array of {what}, got {_describe(x)}: {exc}"
                        ) from None
    kind = arr.dtype.kind
    if kind == "c" and arr.size:               # before the dimensions, as check_array
        raise TypeError(f"`{name}` must hold {what}, got dtype {arr.dtype}")
    if ndim is not None:
        allowed = (ndim,) if isinstance(ndim, int) else tuple(ndim)
        if arr.ndim not in allowed:
            want = " or ".join(str(a) for a in allowed)
            raise ValueError(f"`{name}` must have {want} dimensions, got shape {arr.shape}")
    if finite and kind == "f" and not np.all(np.isfinite(arr)):
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        raise ValueError(f"`{name}` must be finite, got {bad} NaN or infinite entries")
    if arr.size == 0:
        return np.empty(arr.shape, dtype=np.int64)
    if kind == "f" and integral_floats:
        bad = ~np.isfinite(arr) | (arr != np.round(arr))
        if bad.any():
            raise TypeError(f"`{name}` must hold {what}, got {_first(arr, bad)}")
        top = np.float64(2.0**63)                # a float64 bound: no float16 overflow
        big = (arr >= top) | (arr < -top)
        if big.any():
            raise ValueError(f"`{name}` must hold {what} in the int64 range, got "
                             f"{_first(arr, big)}")
        return arr.astype(np.int64)
    if kind == "b" and allow_bool:
        return arr.astype(np.int64)
    if kind not in "iu":
        raise TypeError(f"`{name}` must hold {what}, got dtype {arr.dtype}")
    if kind == "u" and arr.dtype.itemsize >= 8 and arr.max() > np.iinfo(np.int64).max:
        raise ValueError(f"`{name}` must hold {what} in the int64 range, got {int(arr.max())}")
    if keep_dtype and kind == "i":
        return arr.copy() if copy else arr
    return arr.astype(np.int64, copy=copy)


def check_index_pairs(pairs, n: int, name: str = "pairs", *, what: str = "object indices",
                      distinct: bool = False, ordered: bool = False, unique: bool = False,
                      nonempty: bool = False, complete: str | None = None) -> np.ndarray:
    """Check that ``pairs`` is a list of index pairs into ``n`` objects; return ``(P, 2)`` int64.

    The one "pairs of indices" check of the package (view graphs, the pairs a result is asked
    for, the pairs a kernel compares). Integral floats pass (``2.0``); a 1-d input of two
    entries is one pair; an empty input is no pair.

    Parameters
    ----------
    pairs : array_like of shape (P, 2)
        The pairs ``(i, j)``.
    n : int
        Number of objects: every index must lie in ``[0, n)``.
    name : str, default="pairs"
        The argument's name, for the messages.
    what : str, default="object indices"
        What the entries are, as the messages say it (``"graph indices"``).
    distinct : bool, default=False
        Refuse a pair ``(i, i)``.
    ordered : bool, default=False
        Every row must be ``(i, j)`` with ``i < j`` (implies ``distinct``).
    unique : bool, default=False
        Refuse a pair given twice, in either orientation.
    nonempty : bool, default=False
        Refuse an input without pairs.
    complete : str, optional
        Require every unordered pair of the ``n`` objects (either orientation); the string
        says why, in the message (e.g. ``"CAO composes every pair through every third
        graph"``). Use it with ``unique`` (a repeat would stand in for a missing pair).

    Returns
    -------
    ndarray of int64, shape (P, 2)

    Raises
    ------
    TypeError
        Entries that are not integers (the message names the first).
    ValueError
        Any other shape than ``(P, 2)``, indices outside ``[0, n)``, and what the flags refuse.

    Examples
    --------
    >>> check_index_pairs([[0, 1], [2.0, 1]], 3)
    array([[0, 1],
           [2, 1]])
    >>> check_index_pairs([0, 3], 3, what="graph indices")
    Traceback (most recent call last):
        ...
    ValueError: `pairs` must hold graph indices in [0, 3), got range [0, 3]
    >>> check_index_pairs([[0, 1], [1, 0]], 3, unique=True)
    Traceback (most recent call last):
        ...
    ValueError: `pairs` must not repeat a pair, got (1, 0) at row 1 after (0, 1)
    >>> check_index_pairs([[0, 1], [2, 1]], 3, unique=True, complete="all are compared")
    Traceback (most recent call last):
        ...
    ValueError: `pairs` must hold all 3 pairs of the 3 objects (all are compared), got 2; ...
    """
    arr = check_int_array(pairs, name, integral_floats=True, what=f"integer {what}")
    if arr.ndim == 1 and arr.size in (0, 2):
        arr = arr.reshape(-1, 2)
    elif arr.ndim == 2 and arr.shape[0] == 0:
        arr = arr.reshape(0, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"`{name}` must have shape (P, 2), got shape {np.shape(pairs)}")
    if not len(arr):
        if nonempty:
            raise ValueError(f"`{name}` must hold at least one pair, got none")
        if complete is not None:
            _check_complete(arr, n, name, what, complete)
        return arr
    lo, hi = int(arr.min()), int(arr.max())
    if lo < 0 or hi >= n:
        raise ValueError(f"`{name}` must hold {what} in [0, {n}), got range [{lo}, {hi}]")
    bad = np.flatnonzero(arr[:, 0] >= arr[:, 1] if ordered else
                         (arr[:, 0] == arr[:, 1] if distinct else np.zeros(len(arr), bool)))
    if bad.size:
        row = tuple(arr[bad[0]].tolist())
        rule = "(i, j) with i < j" if ordered else "(i, j) with i != j"
        raise ValueError(f"`{name}` rows must be {rule}, got {row} at row {int(bad[0])}")
    if unique:
        key = np.sort(arr, axis=1)
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.reshape(-1)
        rep = np.flatnonzero(first[inverse] != np.arange(len(arr)))
        if rep.size:
            k = int(rep[0])
            raise ValueError(f"`{name}` must not repeat a pair, got {tuple(arr[k].tolist())} at "
                             f"row {k} after {tuple(arr[first[inverse[k]]].tolist())}")
    if complete is not None:
        _check_complete(arr, n, name, what, complete)
    return arr


def _check_complete(arr: np.ndarray, n: int, name: str, what: str, why: str) -> None:
    """Refuse a list of valid pairs that misses a pair of the ``n`` objects."""
    total = n * (n - 1) // 2
    have = np.zeros((n, n), dtype=bool)
    have[arr.min(axis=1), arr.max(axis=1)] = True
    iu, ju = np.triu_indices(n, 1)
    missing = np.flatnonzero(~have[iu, ju])
    if missing.size:
        ex = ", ".join(f"({iu[m]}, {ju[m]})" for m in missing[:3])
        noun = what.removesuffix(" indices") + "s"
        raise ValueError(f"`{name}` must hold all {total} pairs of the {n} {noun} ({why}), got "
                         f"{total - missing.size}; missing e.g. {ex}")


def check_homographies(H, name: str, ndim: int | Sequence[int] = (2, 3)) -> np.ndarray:
    """A finite homography ``(3, 3)`` or stack ``(N, 3, 3)`` (as ``ndim`` allows) of invertible
    matrices (smallest singular value above ``1e-14`` times the largest); returns it as float.

    >>> check_homographies(np.zeros((3, 3)), "H")
    Traceback (most recent call last):
        ...
    ValueError: `H` must hold invertible homographies, got a singular matrix at index 0
    """
    H = check_array(H, name, ndim=ndim)
    H3 = H[None] if H.ndim == 2 else H
    if H3.shape[1:] != (3, 3):
        want = " or ".join({2: "(3, 3)", 3: "(N, 3, 3)"}[d] for d in
                           ((ndim,) if isinstance(ndim, int) else ndim))
        raise ValueError(f"`{name}` must have shape {want}, got shape {H.shape}")
    singular = np.flatnonzero(~invertible_homographies(H3))
    if singular.size:
        raise ValueError(f"`{name}` must hold invertible homographies, got a singular matrix "
                         f"at index {int(singular[0])}")
    return H


def invertible_homographies(H: np.ndarray) -> np.ndarray:
    """Which matrices of a finite ``(N, 3, 3)`` stack are invertible: smallest singular value
    above ``1e-14`` times the largest (the test of :func:`check_homographies`)."""
    if not len(H):
        return np.zeros(0, dtype=bool)
    with np.errstate(all="ignore"):
        sv = np.linalg.svd(H, compute_uv=False)
    return sv[:, -1] > 1e-14 * sv[:, 0]


#: smallest positive scale (largest column sum of ``K``) an affinity may have: below it the
#: solvers' products run among subnormal floats, lose their digits and end in NaN
MIN_AFFINITY_SCALE = 1e-300


def check_affinity_scale(top, name: str = "K") -> None:
    """Refuse an affinity whose largest column sum ``top`` (a scalar, or one per pair) is
    positive but below :data:`MIN_AFFINITY_SCALE`; an all-zero affinity (``top == 0``) passes.

    >>> check_affinity_scale(1e-310)
    Traceback (most recent call last):
        ...
    ValueError: `K` is too small to match on: its largest column sum 1e-310 is below 1e-300 ...
    """
    top = np.asarray(top, dtype=float)
    small = (top > 0) & (top < MIN_AFFINITY_SCALE)
    if small.any():
        raise ValueError(f"`{name}` is too small to match on: its largest column sum "
                         f"{float(top[small].min()):.3g} is below {MIN_AFFINITY_SCALE:g} (its "
                         f"products lose their digits); rescale the affinity")


#: largest sum of affinity entries the solvers meet: an affinity whose largest entry times its
#: number of candidates (a bound on every column sum, product ``K x`` and matching score) is
#: above it is refused, so that no product overflows float64
MAX_AFFINITY_SCALE = 1e300


def check_affinity_magnitude(top_entry, n_candidates: int, name: str = "K") -> None:
    """Refuse an affinity whose largest entry ``top_entry`` times ``n_candidates`` (``n1 n2``)
    exceeds :data:`MAX_AFFINITY_SCALE`.

    >>> check_affinity_magnitude(1e299, 100)
    Traceback (most recent call last):
        ...
    ValueError: `K` is too large to match on: its largest entry 1e+299 times its 100 candidates ...
    """
    top = float(top_entry)
    if top > MAX_AFFINITY_SCALE / max(int(n_candidates), 1):
        raise ValueError(f"`{name}` is too large to match on: its largest entry {top:.3g} times "
                         f"its {int(n_candidates)} candidates exceeds {MAX_AFFINITY_SCALE:g} "
                         f"(its products overflow float64); rescale the affinity")


def _first(arr: np.ndarray, bad: np.ndarray) -> str:
    """The first flagged entry of ``arr`` and its position, for a message."""
    pos = tuple(int(i) for i in np.argwhere(bad)[0])
    value = f"{float(arr[pos])!r}"
    if not pos:
        return value
    return f"{value} at position {pos[0] if len(pos) == 1 else pos}"


def check_bool(value, name: str) -> bool:
    """``value`` as a bool; anything but ``bool`` / ``numpy.bool_`` (``1``, ``"yes"``, ``None``)
    is a ``TypeError`` naming ``name``.

    >>> check_bool(1, "progress")
    Traceback (most recent call last):
        ...
    TypeError: `progress` must be a bool, got int 1
    """
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"`{name}` must be a bool, got {type(value).__name__} "
                        f"{short_repr(value, 60)}")
    return bool(value)


def check_path(value, name: str) -> Path:
    """``value`` (a ``str`` or ``os.PathLike``) as a ``Path`` with ``~`` expanded; named errors
    for other types, for ``''`` (which ``Path`` would read as the working directory) and for a
    ``~user`` that does not exist (pathlib's bare ``RuntimeError``).

    >>> check_path("", "out_dir")
    Traceback (most recent call last):
        ...
    ValueError: `out_dir` must be a path, got '' (write '.' for the working folder)
    """
    if isinstance(value, bool) or not isinstance(value, (str, os.PathLike)):
        raise TypeError(f"`{name}` must be a path (str or os.PathLike), got "
                        f"{type(value).__name__} {value!r:.40}")
    text = os.fspath(value)
    if not isinstance(text, str):
        raise TypeError(f"`{name}` must be a path given as text, got {type(text).__name__} "
                        f"{text!r:.40}")
    if not text:
        raise ValueError(f"`{name}` must be a path, got '' (write '.' for the working folder)")
    try:
        path = Path(text).expanduser()
    except RuntimeError as exc:             # "~nosuchuser/...": no such home folder
        raise ValueError(f"`{name}`: cannot expand {text!r:.80} ({exc})") from None
    try:
        os.stat(path)
    except OSError as exc:                  # a missing path is the caller's to judge, but a
        if exc.errno == errno.ENAMETOOLONG:  # name too long made is_dir() raise raw OSError
            raise ValueError(f"`{name}` is not a usable path: {exc.strerror} "
                             f"({len(text)} characters: {text!r:.60}...)") from None
    except ValueError as exc:               # an embedded NUL byte
        raise ValueError(f"`{name}` is not a usable path ({exc}): {text!r:.60}") from None
    return path


def frozen_copy(a) -> np.ndarray:
    """A read-only copy of ``a``, for the arrays of frozen results (nobody can edit them
    through the result, nor through the array they were built from)."""
    out = np.array(a)
    out.flags.writeable = False
    return out


def short_repr(x, limit: int = 80) -> str:
    """``repr(x)`` cut to ``limit`` characters; safe for ints too long for ``str`` (Python
    refuses more than 4300 digits)."""
    try:
        text = repr(x)
    except ValueError:
        text = f"<{type(x).__name__} with an integer of about 10^{int_magnitude(x)}>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def int_magnitude(x) -> int:
    """Order of magnitude of the largest int inside ``x`` (an int, or a flat sequence)."""
    ints = [x] if isinstance(x, int) else [v for v in x if isinstance(v, int)]
    return int(max(abs(v).bit_length() for v in ints) * 0.30103) if ints else 0


#: Largest iteration count any solver takes (10**12 with a tolerance of 1e-300 looped for good).
MAX_ITER = 10**6


def check_real(value, name: str) -> float:
    """A finite real number of any sign (``bool`` refused; ints beyond float64 named).

    >>> check_real(float("nan"), "min_score")
    Traceback (most recent call last):
        ...
    ValueError: `min_score` must be a finite real number, got nan
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"`{name}` must be a finite real number, got {type(value).__name__} "
                        f"{short_repr(value, 40)}")
    try:
        f = float(value)
    except OverflowError:                   # an int beyond float64
        f = np.inf
    if not np.isfinite(f):
        raise ValueError(f"`{name}` must be a finite real number, got {short_repr(value, 40)}")
    return f


def check_positive(value, name: str, *, allow_zero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"`{name}` must be a real number, got {type(value).__name__} {value!r}")
    try:
        value = float(value)
    except OverflowError:                   # an int beyond float64
        raise ValueError(f"`{name}` must be finite, got an integer of about "
                         f"10^{int_magnitude(int(value))} (beyond float64)") from None
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        rel = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"`{name}` must be finite and {rel}, got {value!r}")
    return abs(value)       # -0.0 -> 0.0 (NumPy samplers refuse a scale of -0.0)


def check_image_size(size, name: str = "image_size", *, minimum: int = 1,
                     maximum: int = 2**16) -> tuple[int, int]:
    """``(width, height)`` in pixels: two integers (or integral floats) in [minimum, maximum]."""
    if isinstance(size, (str, bytes)) or not isinstance(size, (Sequence, np.ndarray)):
        raise TypeError(f"`{name}` must be (width, height), got {type(size).__name__} {size!r}")
    if len(size) != 2:
        raise ValueError(f"`{name}` must be (width, height), got {len(size)} value(s): {size!r}")
    out = []
    for v in size:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
            raise TypeError(f"`{name}` must be (width, height) in pixels, got "
                            f"{type(v).__name__} {short_repr(v, 40)} in {short_repr(size)}")
        if isinstance(v, numbers.Integral):     # ints beyond float64 compare exactly
            ok = minimum <= v <= maximum
        else:
            try:
                f = float(v)
            except OverflowError:
                f = float("inf")
            ok = bool(np.isfinite(f)) and f.is_integer() and minimum <= f <= maximum
        if not ok:
            raise ValueError(f"`{name}` must be (width, height) in whole pixels, each in "
                             f"[{minimum}, {maximum}], got {short_repr(size)}")
        out.append(int(v))
    return out[0], out[1]


def check_probability(value, name: str, *, allow_zero: bool = True) -> float:
    """``value`` as a float in ``[0, 1]``, or in ``(0, 1]`` without ``allow_zero`` (then every
    real value outside it, NaN included, is named with that interval)."""
    if not allow_zero and isinstance(value, numbers.Real) and not isinstance(value, bool):
        try:
            inside = 0 < float(value) <= 1
        except OverflowError:                   # an int beyond float64
            inside = False
        if not inside:
            raise ValueError(f"`{name}` must lie in (0, 1], got {value!r:.40}")
    value = check_positive(value, name, allow_zero=True)
    if value > 1:
        raise ValueError(f"`{name}` must lie in [0, 1], got {value!r}")
    return value


def check_choice(value, name: str, choices) -> str:
    if not isinstance(value, str) or value not in choices:
        opts = ", ".join(repr(c) for c in choices)
        raise ValueError(f"`{name}` must be one of {opts}, got {value!r}")
    return value


def check_choices(value, name: str, choices, *, what: str = "") -> tuple[str, ...]:
    """``value`` as a tuple of names from ``choices``: one name, or a non-empty tuple or list
    of distinct ones (``what``: what a sequence means and what else is accepted, for the
    message)."""
    opts = ", ".join(repr(c) for c in choices)
    names = (value,) if isinstance(value, str) else value
    if not isinstance(names, (tuple, list)) or not names:
        raise TypeError(f"`{name}` must be one of {opts} or a non-empty sequence of distinct "
                        f"ones{what}, got {value!r}")
    names = tuple(names)
    if not all(isinstance(m, str) and m in choices for m in names):
        raise ValueError(f"`{name}` must be one of {opts} or a sequence of distinct ones"
                         f"{what}, got {value!r}")
    if len(set(names)) < len(names):
        raise ValueError(f"`{name}` names a choice twice, got {value!r}")
    return names
