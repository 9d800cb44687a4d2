"""The core input checks of :mod:`transync._validation` (here: :func:`check_int_array`)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from transync import _validation
from transync._validation import check_int_array

_SETTINGS = settings(deadline=None, derandomize=True, database=None, max_examples=60)

_INT_DTYPES = st.sampled_from([np.int8, np.int16, np.int32, np.int64,
                               np.uint8, np.uint16, np.uint32, np.uint64])
_FLOAT_DTYPES = st.sampled_from([np.float16, np.float32, np.float64])
_SHAPES = hnp.array_shapes(min_dims=0, max_dims=3, min_side=1, max_side=4)
_NAMES = st.from_regex(r"[a-z_][a-z0-9_]{0,8}(\[[0-9]\])?", fullmatch=True)


def _ints(draw_dtype=_INT_DTYPES):
    """Int arrays of any int dtype, every value within the int64 range (uint64 included)."""
    def arrays(dt):
        top = min(int(np.iinfo(dt).max), int(np.iinfo(np.int64).max))
        return hnp.arrays(dt, _SHAPES, elements=st.integers(int(np.iinfo(dt).min), top))
    return draw_dtype.flatmap(arrays)


def _integral_floats():
    return _FLOAT_DTYPES.flatmap(lambda dt: hnp.arrays(
        dt, _SHAPES, elements=st.integers(-1000, 1000).map(float)))


def _with_fraction():
    """A float array (integral values) with one entry made non-integral, and that entry."""
    @st.composite
    def build(draw):
        arr = draw(_integral_floats()).astype(np.float64)
        flat = arr.reshape(-1)
        k = draw(st.integers(0, flat.size - 1))
        flat[k] = draw(st.integers(-1000, 999)) + draw(st.sampled_from([0.5, 0.25, 0.125]))
        return arr, k
    return build()


# ----------------------------------------------------------------------------- properties

@_SETTINGS
@given(_ints(), _NAMES)
def test_int_arrays_pass_unchanged_in_value(arr, name):
    out = check_int_array(arr, name)
    assert out.dtype == np.int64 and out.shape == arr.shape
    assert np.array_equal(out, arr)                      # exact, uint64 included


@_SETTINGS
@given(_ints(st.sampled_from([np.int8, np.int16, np.int32, np.int64])))
def test_keep_dtype_keeps_a_signed_int_array(arr):
    out = check_int_array(arr, "a", keep_dtype=True)
    assert out is arr
    copied = check_int_array(arr, "a", keep_dtype=True, copy=True)
    assert copied.dtype == arr.dtype and copied is not arr and np.array_equal(copied, arr)


@_SETTINGS
@given(_with_fraction(), _NAMES, st.booleans())
def test_non_integral_floats_raise_type_error_naming_the_argument(built, name, integral_floats):
    arr, k = built
    with pytest.raises(TypeError, match=re.escape(f"`{name}` must hold integers")) as err:
        check_int_array(arr, name, integral_floats=integral_floats)
    if integral_floats:                                  # the first offending value and where
        first = int(np.flatnonzero(arr.reshape(-1) != np.round(arr.reshape(-1)))[0])
        assert first == k
        pos = np.unravel_index(k, arr.shape)
        where = pos[0] if len(pos) == 1 else tuple(int(i) for i in pos)
        assert f"got {float(arr.reshape(-1)[k])!r}" in str(err.value)
        if arr.ndim:
            assert f"at position {where}" in str(err.value)
    else:
        assert "got dtype float64" in str(err.value)


@_SETTINGS
@given(_integral_floats(), _NAMES)
def test_integral_floats_pass_only_when_allowed(arr, name):
    out = check_int_array(arr, name, integral_floats=True)
    assert out.dtype == np.int64 and np.array_equal(out, arr)
    with pytest.raises(TypeError, match=re.escape(f"`{name}` must hold integers, got dtype "
                                                  f"{arr.dtype}")):
        check_int_array(arr, name)


@_SETTINGS
@given(_integral_floats(), st.sampled_from([np.nan, np.inf, -np.inf]), st.data())
def test_nan_and_infinity_raise(arr, bad, data):
    arr = arr.astype(np.float64)
    k = data.draw(st.integers(0, arr.size - 1))
    arr.reshape(-1)[k] = bad
    for integral_floats in (False, True):
        with pytest.raises(TypeError, match=r"`x` must hold integers, got "):
            check_int_array(arr, "x", integral_floats=integral_floats)
    with pytest.raises(TypeError, match=re.escape(f"got {float(bad)!r}")):
        check_int_array(arr, "x", integral_floats=True)
    with pytest.raises(ValueError, match=r"`x` must be finite, got 1 NaN or infinite entries"):
        check_int_array(arr, "x", integral_floats=True, finite=True)


@_SETTINGS
@given(st.one_of(
    hnp.arrays(hnp.unicode_string_dtypes(max_len=3), _SHAPES),
    hnp.arrays(hnp.byte_string_dtypes(max_len=3), _SHAPES),
    _ints().map(lambda a: a.astype(object)),
    hnp.arrays(np.complex128, _SHAPES),
    hnp.arrays(np.bool_, _SHAPES),
), _NAMES)
def test_strings_objects_complex_and_bools_raise_type_error(arr, name):
    with pytest.raises(TypeError, match=re.escape(f"`{name}` must hold integers, got dtype "
                                                  f"{arr.dtype}")):
        check_int_array(arr, name, integral_floats=True)


@_SETTINGS
@given(st.sampled_from([np.int32, np.uint8, np.float64, np.float32, np.bool_, np.complex128,
                        object, "U3", "S2"]),
       hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=3).filter(
           lambda s: 0 in s), st.booleans())
def test_empty_arrays_of_any_dtype_pass(dtype, shape, integral_floats):
    out = check_int_array(np.empty(shape, dtype=dtype), "x", integral_floats=integral_floats)
    assert out.dtype == np.int64 and out.shape == shape


# ----------------------------------------------------------------------------- examples

def test_lists_scalars_and_bools():
    assert check_int_array([[0, 1], [2, 3]], "p").tolist() == [[0, 1], [2, 3]]
    assert check_int_array([], "p").dtype == np.int64
    assert check_int_array(3, "p").shape == ()
    with pytest.raises(TypeError, match=r"`p` must hold integers, got 2.5$"):
        check_int_array(2.5, "p", integral_floats=True)                     # 0-d: no position
    assert check_int_array([True, False], "m", allow_bool=True).tolist() == [1, 0]
    with pytest.raises(TypeError, match="`m` must hold integers, got dtype bool"):
        check_int_array([True, False], "m")


def test_messages_name_the_argument_and_what_arrived():
    with pytest.raises(TypeError, match=r"`p` must hold integer graph indices, got 0.5 at "
                                        r"position \(1, 0\)"):
        check_int_array([[0, 1], [0.5, 2]], "p", integral_floats=True,
                        what="integer graph indices")
    with pytest.raises(TypeError, match="`p` must be an array, got None"):
        check_int_array(None, "p")
    with pytest.raises(TypeError, match="`p` must be an array of integers, got str '01'"):
        check_int_array("01", "p")
    with pytest.raises(TypeError, match="`p` must be an array of integers, got list"):
        check_int_array([[0, 1], [2]], "p")                                   # ragged
    with pytest.raises(TypeError, match="`p` must hold integers, got dtype complex128"):
        check_int_array([1j], "p", ndim=2)                     # before the dimensions
    with pytest.raises(TypeError, match="`p` must hold integers, got dtype <U1"):
        check_int_array(np.array(["1"]), "p", integral_floats=True)


def test_dimensions():
    with pytest.raises(ValueError, match=r"`p` must have 2 dimensions, got shape \(2,\)"):
        check_int_array([0, 1], "p", ndim=2)
    with pytest.raises(ValueError, match=r"`p` must have 1 or 2 dimensions, got shape \(\)"):
        check_int_array(0, "p", ndim=(1, 2))
    with pytest.raises(ValueError, match="must have 2 dimensions"):
        check_int_array(np.empty(0, dtype=object), "p", ndim=2)       # empty: still checked
    assert check_int_array(np.zeros((2, 2), np.int32), "p", ndim=(1, 2)).dtype == np.int64


def test_int64_range():
    with pytest.raises(ValueError, match=r"`p` must hold integers in the int64 range, got "
                                         r"1e\+19 at position 1"):
        check_int_array([0.0, 1e19], "p", integral_floats=True)
    big = np.array([0, 2**63], dtype=np.uint64)
    with pytest.raises(ValueError, match="`p` must hold integers in the int64 range, got "
                                         "9223372036854775808"):
        check_int_array(big, "p")
    edge = np.array([-(2.0**63)])
    assert check_int_array(edge, "p", integral_floats=True)[0] == np.iinfo(np.int64).min


def test_copy_and_identity():
    a = np.arange(3)
    assert check_int_array(a, "a") is a
    b = check_int_array(a, "a", copy=True)
    assert b is not a and not np.shares_memory(a, b)
    assert check_int_array(a.astype(np.int32), "a").dtype == np.int64


def test_core_module_imports_no_subpackage():
    tree = ast.parse(Path(_validation.__file__).read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            assert node.level == 0, f"relative import from {node.module!r}"
            assert not (node.module or "").startswith("transync")
        elif isinstance(node, ast.Import):
            assert not any(a.name.startswith("transync") for a in node.names)


def test_check_array_refuses_text_for_numeric_dtypes():
    """numpy parses "1" as 1.0; a numeric argument given as text is refused by name."""
    from transync._validation import check_array

    for text in (np.array([["1", "2"]]), [["1", "2"]], (b"1",)):
        with pytest.raises(TypeError, match="`x` must be numeric, got text"):
            check_array(text, "x")
    np.testing.assert_array_equal(check_array(np.array([1, 2], dtype=object), "x"), [1.0, 2.0])
    assert check_array(np.array(["a"]), "x", dtype=None).dtype.kind == "U"    # no dtype asked


@settings(max_examples=40, deadline=None, derandomize=True)
@given(n=st.integers(1, 7), data=st.data())
def test_complete_pairs_accepts_every_pair_once_in_any_order_and_names_a_missing_one(n, data):
    """``check_index_pairs(complete=...)``: every unordered pair, either orientation, any row
    order, passes; dropping any one is refused with that pair named (brute force)."""
    from transync._validation import check_index_pairs

    iu, ju = np.triu_indices(n, 1)
    pairs = np.column_stack([iu, ju])
    flip = np.array(data.draw(st.lists(st.booleans(), min_size=len(pairs),
                                       max_size=len(pairs))), dtype=bool)
    pairs[flip] = pairs[flip][:, ::-1]
    pairs = pairs[data.draw(st.permutations(range(len(pairs))))]
    out = check_index_pairs(pairs, n, unique=True, complete="test")
    np.testing.assert_array_equal(out, pairs.reshape(-1, 2))
    if len(pairs):
        k = data.draw(st.integers(0, len(pairs) - 1))
        lo, hi = sorted(pairs[k].tolist())
        with pytest.raises(ValueError, match=rf"all {len(pairs)} pairs of the {n} objects "
                                             rf"\(test\), got {len(pairs) - 1}; missing e\.g\. "
                                             rf"\({lo}, {hi}\)"):
            check_index_pairs(np.delete(pairs, k, axis=0), n, unique=True, complete="test")


def test_as_generator_refuses_bools_and_names_the_argument():
    """``rng=True`` is not seed 1 (``n_universe=True`` is refused likewise)."""
    for bad in (True, np.bool_(False)):
        with pytest.raises(TypeError, match="`random_state` must be None, an int .* got bool"):
            _validation.as_generator(bad, "random_state")
    with pytest.raises(ValueError, match="`rng` must be None, a non-negative int"):
        _validation.as_generator(-3)
    assert isinstance(_validation.as_generator(np.int64(3)), np.random.Generator)
