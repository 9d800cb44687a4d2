"""The loaders' own MAT-file v5 reader against scipy.io.loadmat: the same arrays wherever both
read, a named error where scipy's compiled reader crashes."""

import glob
import os

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.io import loadmat, savemat

from transync.datasets import data_home
from transync.datasets._matfile import MatFieldError, MatFileError, read_mat

NUMERIC = {"xy": np.arange(20.0).reshape(2, 10), "i16": np.arange(5, dtype=np.int16),
           "logical": np.array([True, False]), "empty": np.zeros((0, 3)), "scalar": 3.5,
           "cube": np.arange(24.0).reshape(2, 3, 4), "f32": np.ones((2, 2), np.float32),
           "i8": np.array([-3, 4], np.int8), "u64": np.arange(3, dtype=np.uint64),
           "small_doubles": np.array([[1.0, 2.0, 255.0]])}         # stored as uint8 by savemat
OTHER = {"text": "hello", "complex": np.array([1 + 2j]), "sparse": sp.csc_matrix(np.eye(3)),
         "cell": np.array([np.arange(3), "ab"], dtype=object), "struct": {"a": 1}}


@pytest.mark.parametrize("compress", [False, True])
def test_same_arrays_as_scipy_and_named_refusals(tmp_path, compress):
    f = tmp_path / "all.mat"
    savemat(f, {**NUMERIC, **OTHER}, do_compression=compress)
    ref = loadmat(f)
    arrays, names = read_mat(f, list(NUMERIC))
    assert sorted(names) == sorted({**NUMERIC, **OTHER})
    for k in NUMERIC:
        assert arrays[k].dtype == ref[k].dtype and arrays[k].shape == ref[k].shape
        np.testing.assert_array_equal(arrays[k], ref[k])
    for k, what in (("text", "char"), ("complex", "double (complex)"), ("sparse", "sparse"),
                    ("cell", "cell"), ("struct", "struct")):
        with pytest.raises(MatFieldError, match=rf"variable '{k}' is MATLAB class "):
            read_mat(f, [k])
        try:
            read_mat(f, [k])
        except MatFieldError as exc:
            assert exc.field == k and exc.what == f"MATLAB class {what}"
    assert read_mat(f, ["absent"])[0] == {}


def test_a_corrupted_data_type_is_an_error_not_a_crash(tmp_path):
    """This file crashes scipy.io.loadmat (scipy 1.16: segmentation fault)."""
    f = tmp_path / "bad.mat"
    savemat(f, {"xy": np.random.default_rng(0).random((2, 10))})
    data = bytearray(f.read_bytes())
    tag = data.find(b"\x09\x00\x00\x00\xa0\x00\x00\x00")          # miDOUBLE, 160 bytes
    data[tag:tag + 4] = (777).to_bytes(4, "little")
    f.write_bytes(bytes(data))
    with pytest.raises(MatFileError, match=r"cannot read as a MATLAB \.mat file \(an unknown "
                                           r"data type 777 at byte \d+\)"):
        read_mat(f, ["xy"])


def test_truncated_files_and_v4(tmp_path):
    f = tmp_path / "a.mat"
    savemat(f, {"xy": np.eye(3)})
    full = f.read_bytes()
    for cut in (0, 10, 127, 130, len(full) - 5):
        f.write_bytes(full[:cut])
        with pytest.raises(MatFileError, match=r"cannot read"):
            read_mat(f, ["xy"])
    savemat(f, {"xy": np.eye(3)}, format="4")
    np.testing.assert_array_equal(read_mat(f, ["xy"])[0]["xy"], np.eye(3))


def test_real_adelaidermf_files_read_as_scipy_reads_them():
    folder = data_home(required=False, subfolder="adelaidermf")
    files = sorted(glob.glob(os.path.join(folder, "*.mat"))) if folder else []
    if not files:
        pytest.skip("AdelaideRMF not found in the data home")
    for path in files[:4]:                                # MATLAB-written, v5 (~2 MB each)
        ref = loadmat(path)
        keys = [k for k in ref if not k.startswith("__")]
        arrays, names = read_mat(path, keys)
        assert sorted(names) == sorted(keys)
        for k in keys:
            assert arrays[k].dtype == ref[k].dtype, (path, k)
            np.testing.assert_array_equal(arrays[k], ref[k])
