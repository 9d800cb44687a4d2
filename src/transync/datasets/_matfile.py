"""Real numeric matrices out of MATLAB .mat files, safely, for the loaders that read them.

``scipy.io.loadmat`` trusts a MAT-file's tags: a corrupted data-type code makes its compiled
reader crash the interpreter (a segmentation fault, scipy 1.16; found by fuzzing the Willow
loader), which no ``except`` can turn into an error naming the file. MAT-files v5 (also the
compressed ones MATLAB writes by default, v7) are therefore read here by a small reader of their
own that checks every tag before it reads: the top-level variables, each a matrix with array
flags, dimensions, a name and its real data, inside compressed elements or not. Only what the
loaders need is decoded: real numeric arrays (double, single, integers) in the type they are
stored in, as ``loadmat`` returns them (MATLAB stores small integral doubles as uint8; the twelve
AdelaideRMF files read identically by both). Any other variable (char, cell, struct, sparse,
complex) is named but not decoded, and asking for one is a :class:`MatFieldError`. v4 files (no
text header) go through ``scipy.io.loadmat`` (fuzzed too: its failures there are exceptions and
warnings, turned into :class:`MatFileError`); v7.3 files (HDF5) are refused.
"""

from __future__ import annotations

import math
import struct
import warnings
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["MatFieldError", "MatFileError", "read_mat"]

#: MAT-file v5 numeric data types and their NumPy codes (miINT8 .. miUINT64)
_MI_NUMERIC = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 9: "f8",
               12: "i8", 13: "u8"}
_MI_INT8, _MI_INT32, _MI_UINT32, _MI_MATRIX, _MI_COMPRESSED = 1, 5, 6, 14, 15
#: every MAT-file v5 data type (8, 10 and 11 are reserved)
_MI_TYPES = frozenset(_MI_NUMERIC) | {_MI_MATRIX, _MI_COMPRESSED, 16, 17, 18}
#: MATLAB array classes; 6 .. 15 are the numeric ones
_MX_CLASSES = {1: "cell", 2: "struct", 3: "object", 4: "char", 5: "sparse", 6: "double",
               7: "single", 8: "int8", 9: "uint8", 10: "int16", 11: "uint16", 12: "int32",
               13: "uint32", 14: "int64", 15: "uint64", 16: "function", 17: "opaque"}
_MX_NUMERIC = frozenset(range(6, 16))
_MX_COMPLEX = 0x800                  # the complex bit of the array flags word
#: decompressed bytes of one compressed element that the reader accepts (256 MiB)
_MAX_INFLATED = 1 << 28


class MatFileError(ValueError):
    """A file that cannot be read as a MAT-file (the message does not name the file)."""


class MatFieldError(MatFileError):
    """A requested variable that is not a real numeric array; ``what`` says what it is."""

    def __init__(self, field: str, what: str):
        super().__init__(f"variable {field!r} is {what}, not a real numeric array")
        self.field, self.what = field, what


def read_mat(path, fields: Sequence[str]) -> tuple[dict[str, np.ndarray], list[str]]:
    """The real numeric arrays ``fields`` of the MAT-file ``path``, and every variable's name.

    Parameters
    ----------
    path : str or Path
        The file.
    fields : sequence of str
        The variables to decode; those the file does not hold are absent from the result.

    Returns
    -------
    arrays : dict
        ``{name: ndarray}`` (the stored type in native byte order, the MATLAB dimensions in
        Fortran order: what ``scipy.io.loadmat`` gives).
    names : list of str
        The names of every variable in the file.

    Raises
    ------
    MatFileError
        An unreadable, malformed or v7.3 file (a ``ValueError``; the message says why).
    MatFieldError
        A requested variable that is a char, cell, struct, sparse or complex array.

    Examples
    --------
    >>> import io, tempfile
    >>> from pathlib import Path
    >>> from scipy.io import savemat
    >>> f = Path(tempfile.mkdtemp()) / "a.mat"
    >>> savemat(f, {"xy": np.arange(6.0).reshape(2, 3), "note": "text"}, do_compression=True)
    >>> arrays, names = read_mat(f, ["xy"])
    >>> arrays["xy"].tolist(), sorted(names)
    ([[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]], ['note', 'xy'])
    """
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise MatFileError(f"cannot read ({exc.strerror or exc})") from None
    wanted = set(fields)
    if len(data) < 128 or 0 in data[:4]:            # scipy's test: v4 has a zero up front
        return _read_v4(path, wanted)
    if data[126:128] in (b"IM", b"MI") and data[124 + (data[126] == ord("I"))] == 2:
        raise MatFileError("a MATLAB v7.3 (HDF5) .mat file, which is not supported; save it "
                           "with -v7 (or -v6)")
    out, names = {}, []
    try:
        for name, buf, sub, order in _v5_matrices(data):
            names.append(name)
            if name in wanted:
                out[name] = _v5_numeric(name, buf, sub, order)
    except MatFieldError:
        raise
    except MatFileError as exc:
        raise MatFileError(f"cannot read as a MATLAB .mat file ({exc})") from None
    return out, names


def _elements(buf: bytes, start: int, end: int, order: str):
    """The data elements ``(type, offset of the data, nbytes)`` of ``buf[start:end]``, every
    tag checked (a known type, a size within the container)."""
    pos = start
    while pos < end:
        if pos + 8 > end:
            raise MatFileError(f"a truncated data element tag at byte {pos}")
        typ, nbytes = struct.unpack_from(order + "II", buf, pos)
        if typ >> 16:                                       # small element: <= 4 bytes inline
            typ, nbytes = typ & 0xFFFF, typ >> 16
            if typ not in _MI_TYPES or nbytes > 4:
                raise MatFileError(f"a malformed small data element at byte {pos}")
            yield typ, pos + 4, nbytes
            pos += 8
            continue
        if typ not in _MI_TYPES:
            raise MatFileError(f"an unknown data type {typ} at byte {pos}")
        if pos + 8 + nbytes > end:
            raise MatFileError(f"a data element at byte {pos} runs past its end "
                               f"({nbytes} bytes)")
        yield typ, pos + 8, nbytes
        pos += 8 + nbytes + (0 if typ == _MI_COMPRESSED else -nbytes % 8)


def _v5_matrices(data: bytes):
    """``(name, buffer, sub-elements, byte order)`` of every top-level matrix of a v5 file."""
    order = {b"IM": "<", b"MI": ">"}.get(data[126:128])
    if order is None:
        raise MatFileError("a bad endian indicator in the header")
    for typ, off, nbytes in _elements(data, 128, len(data), order):
        buf, elements = data, [(typ, off, nbytes)]
        if typ == _MI_COMPRESSED:
            try:
                buf = zlib.decompressobj().decompress(data[off:off + nbytes], _MAX_INFLATED)
            except zlib.error as exc:
                raise MatFileError(f"a compressed element at byte {off - 8} does not inflate "
                                   f"({exc})") from None
            elements = list(_elements(buf, 0, len(buf), order))
        for t, o, n in elements:
            if t != _MI_MATRIX:
                continue
            sub = list(_elements(buf, o, o + n, order))
            if (len(sub) < 3 or sub[0][0] != _MI_UINT32 or sub[0][2] != 8
                    or sub[1][0] != _MI_INT32 or sub[1][2] < 8 or sub[1][2] % 4
                    or sub[2][0] != _MI_INT8):
                raise MatFileError(f"a matrix at byte {o - 8} without array flags, dimensions "
                                   f"and a name")
            name = buf[sub[2][1]:sub[2][1] + sub[2][2]].decode("latin-1")
            yield name, buf, sub, order


def _v5_numeric(name: str, buf: bytes, sub: list, order: str) -> np.ndarray:
    """The real numeric array of one matrix (its sub-elements ``sub`` already checked)."""
    flags = struct.unpack_from(order + "I", buf, sub[0][1])[0]
    cls = flags & 0xFF
    if cls not in _MX_CLASSES:
        raise MatFileError(f"matrix {name!r} has an unknown class {cls}")
    if cls not in _MX_NUMERIC or flags & _MX_COMPLEX:
        raise MatFieldError(name, f"MATLAB class {_MX_CLASSES[cls]}"
                            + (" (complex)" if cls in _MX_NUMERIC else ""))
    dims = np.frombuffer(buf, dtype=order + "i4", count=sub[1][2] // 4, offset=sub[1][1])
    if len(sub) < 4 or sub[3][0] not in _MI_NUMERIC or np.any(dims < 0):
        raise MatFileError(f"matrix {name!r} has no real numeric data")
    typ, off, nbytes = sub[3]
    stored = np.dtype(order + _MI_NUMERIC[typ])       # MATLAB may store a double as uint8
    count = math.prod(int(d) for d in dims)          # Python ints: no wrap-around
    if nbytes != count * stored.itemsize:
        raise MatFileError(f"matrix {name!r}: {nbytes} bytes of data for dimensions "
                           f"{dims.tolist()}")
    values = np.frombuffer(buf, dtype=stored, count=count, offset=off)
    return values.astype(stored.newbyteorder("=")).reshape(tuple(int(d) for d in dims),
                                                           order="F")


def _read_v4(path, wanted: set) -> tuple[dict[str, np.ndarray], list[str]]:
    """A v4 file (or none at all) through ``scipy.io.loadmat``, its failures named."""
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    try:
        with warnings.catch_warnings():             # "data may be corrupt": refused
            warnings.simplefilter("error")
            found = loadmat(path)
    except (MatReadError, ValueError, TypeError, OSError, IndexError, KeyError, EOFError,
            OverflowError, UnicodeDecodeError, NotImplementedError, MemoryError, struct.error,
            zlib.error, Warning) as exc:            # what scipy's reader raises on bad data
        raise MatFileError(f"cannot read as a MATLAB .mat file ({type(exc).__name__}: {exc})"
                           ) from None
    names = [k for k in found if not k.startswith("__")]
    out = {}
    for k in names:
        if k in wanted:
            arr = np.asarray(found[k])
            if arr.dtype.kind not in "uifb":
                raise MatFieldError(k, f"an array of dtype {arr.dtype}")
            out[k] = arr
    return out, names
