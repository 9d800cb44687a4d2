"""Willow-ObjectClass (Cho, Alahari & Ponce, ICCV 2013) in its documented layout.

A class folder (``Car``, ``Duck``, ``Face``, ``Motorbike``, ``Winebottle``) holds images
``<name>.png``, each with an annotation ``<name>.mat`` whose field ``pts_coord`` is a 2 x 10
float array: the x coordinates in row 0, the y coordinates in row 1 (pixels), column ``k`` the
``k``-th keypoint of the class — the same keypoint in every image. The same layout is read by
pygmtools' ``WillowObject`` benchmark.

Every error on malformed input is a ``ValueError`` (``FileNotFoundError`` for a missing folder)
naming the file and the field.

MAT-files v5 (also compressed, v7) are read by a small reader of their own (one numeric, real
matrix by name, every tag checked), not ``scipy.io.loadmat``: scipy's compiled reader trusts the
file's tags, and one corrupted data-type code made it crash the interpreter (a segmentation
fault, scipy 1.16). v4 files go through scipy; v7.3 (HDF5) files are refused.
"""

from __future__ import annotations

import math
import struct
import warnings
import zlib
from pathlib import Path

import numpy as np

from ._cmu import LandmarkSequence, _png_size

__all__ = ["load_willow_class"]

_FIELD = "pts_coord"


#: MAT-file v5 numeric data types and their NumPy codes (miINT8 .. miUINT64)
_MI_NUMERIC = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 9: "f8",
               12: "i8", 13: "u8"}
_MI_MATRIX, _MI_COMPRESSED = 14, 15
#: every MAT-file v5 data type (8, 10 and 11 are reserved)
_MI_TYPES = frozenset(_MI_NUMERIC) | {_MI_MATRIX, _MI_COMPRESSED, 16, 17, 18}
#: MATLAB array classes (mxCELL_CLASS = 1 .. mxUINT64_CLASS = 15); 6 .. 15 are numeric
_MX_CLASSES = {1: "cell", 2: "struct", 3: "object", 4: "char", 5: "sparse", 6: "double",
               7: "single", 8: "int8", 9: "uint8", 10: "int16", 11: "uint16", 12: "int32",
               13: "uint32", 14: "int64", 15: "uint64"}
#: decompressed bytes of one compressed element that the reader accepts
_MAT_MAX_INFLATED = 1 << 28


class _MatError(ValueError):
    """A malformed MAT-file."""


class _MatFieldError(_MatError):
    """A well-formed MAT-file whose field is not what the loader needs."""


def _mat_elements(buf: bytes, start: int, end: int, order: str):
    """The data elements ``(type, offset of the data, nbytes)`` of ``buf[start:end]``, every
    tag checked (a known type, a size within the container)."""
    pos = start
    while pos < end:
        if pos + 8 > end:
            raise _MatError(f"a truncated data element tag at byte {pos}")
        typ, nbytes = struct.unpack_from(order + "II", buf, pos)
        if typ >> 16:                                       # small element: <= 4 bytes inline
            typ, nbytes = typ & 0xFFFF, typ >> 16
            if typ not in _MI_TYPES or nbytes > 4:
                raise _MatError(f"a malformed small data element at byte {pos}")
            yield typ, pos + 4, nbytes
            pos += 8
            continue
        if typ not in _MI_TYPES:
            raise _MatError(f"an unknown data type {typ} at byte {pos}")
        if pos + 8 + nbytes > end:
            raise _MatError(f"a data element at byte {pos} runs past its end ({nbytes} bytes)")
        yield typ, pos + 8, nbytes
        pos += 8 + nbytes + (0 if typ == _MI_COMPRESSED else -nbytes % 8)


def _mat_v5_matrices(data: bytes):
    """``(name, buffer, sub-elements, order)`` of every top-level matrix of a MAT-file v5
    (compressed or not)."""
    order = {b"IM": "<", b"MI": ">"}.get(data[126:128])
    if order is None:
        raise _MatError("a bad endian indicator in the header")
    for typ, off, nbytes in _mat_elements(data, 128, len(data), order):
        buf, elements = data, [(typ, off, nbytes)]
        if typ == _MI_COMPRESSED:
            try:
                buf = zlib.decompressobj().decompress(data[off:off + nbytes], _MAT_MAX_INFLATED)
            except zlib.error as exc:
                raise _MatError(f"a compressed element at byte {off - 8} does not inflate "
                                f"({exc})") from None
            elements = list(_mat_elements(buf, 0, len(buf), order))
        for t, o, n in elements:
            if t != _MI_MATRIX:
                continue
            sub = list(_mat_elements(buf, o, o + n, order))
            if len(sub) < 3 or sub[2][0] != 1:
                raise _MatError(f"a matrix at byte {o - 8} without flags, dimensions and name")
            name = buf[sub[2][1]:sub[2][1] + sub[2][2]].decode("latin-1")
            yield name, buf, sub, order


def _read_mat_v5_field(data: bytes, field: str):
    """The numeric matrix ``field`` of a MAT-file v5 as an ndarray, or ``None`` when the file
    holds no matrix of that name (then also the names it holds).

    A small reader for the one thing a Willow annotation needs, instead of ``scipy.io.loadmat``:
    scipy's compiled reader trusts the file's tags, and a corrupted tag crashed the interpreter
    (segmentation fault, scipy 1.16) where this reader raises ``ValueError``.
    """
    names = []
    for name, buf, sub, order in _mat_v5_matrices(data):
        names.append(name)
        if name != field:
            continue
        (ft, fo, fn), (dt, do, dn) = sub[0], sub[1]
        if ft != 6 or fn != 8 or dt != 5 or dn < 8 or dn % 4:
            raise _MatError(f"matrix {name!r} has malformed array flags or dimensions")
        flags = struct.unpack_from(order + "I", buf, fo)[0]
        cls = flags & 0xFF
        if cls not in _MX_CLASSES:
            raise _MatError(f"matrix {name!r} has an unknown class {cls}")
        if not 6 <= cls <= 15 or flags & 0x800:             # numeric and real only
            what = "complex" if flags & 0x800 else _MX_CLASSES[cls]
            raise _MatFieldError(f"expected a numeric 2 x K array, got MATLAB class {what}")
        dims = np.frombuffer(buf, dtype=order + "i4", count=dn // 4, offset=do)
        if len(sub) < 4 or sub[3][0] not in _MI_NUMERIC or np.any(dims < 0):
            raise _MatError(f"matrix {name!r} has no real numeric data")
        rt, ro, rn = sub[3]
        dtype = np.dtype(order + _MI_NUMERIC[rt])
        count = math.prod(int(d) for d in dims)          # Python ints: no wrap-around
        if rn != count * dtype.itemsize:
            raise _MatError(f"matrix {name!r}: {rn} bytes of data for dimensions "
                            f"{dims.tolist()}")
        return np.frombuffer(buf, dtype=dtype, count=count, offset=ro).reshape(
            tuple(dims), order="F").astype(float), names
    return None, names


def _read_annotation(path: Path) -> np.ndarray:
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read ({exc.strerror or exc})") from None
    v4 = len(data) < 128 or 0 in data[:4]          # scipy's test: v4 has a zero up front
    if not v4 and data[126:128] in (b"IM", b"MI") and data[124 + (data[126] == 73)] == 2:
        raise ValueError(f"{path}: a MATLAB v7.3 (HDF5) .mat file; save the annotation with "
                         "-v7 (or -v6)")
    if not v4:                                      # v5 / v7 (or junk): our own reader
        try:
            raw, names = _read_mat_v5_field(data, _FIELD)
        except _MatFieldError as exc:
            raise ValueError(f"{path}, field {_FIELD!r}: {exc}") from None
        except _MatError as exc:
            raise ValueError(f"{path}: cannot read as a MATLAB .mat file ({exc})") from None
    else:                                           # v4 (or junk): scipy's reader
        try:
            with warnings.catch_warnings():         # "data may be corrupt": it is refused
                warnings.simplefilter("error")
                fields = loadmat(path)
        except (MatReadError, ValueError, TypeError, OSError, IndexError, KeyError, EOFError,
                OverflowError, UnicodeDecodeError, NotImplementedError, MemoryError,
                struct.error, zlib.error, Warning) as exc:   # scipy's reader on bad data
            raise ValueError(f"{path}: cannot read as a MATLAB .mat file "
                             f"({type(exc).__name__}: {exc})") from None
        names = [k for k in fields if not k.startswith("__")]
        raw = np.asarray(fields[_FIELD]) if _FIELD in fields else None
    if raw is None:
        present = ", ".join(repr(k) for k in sorted(names)) or "none"
        raise ValueError(f"{path}: no field {_FIELD!r} (expected a 2 x K array of keypoints; "
                         f"fields present: {present})")
    if raw.dtype.kind not in "iuf":
        raise ValueError(f"{path}, field {_FIELD!r}: expected a numeric 2 x K array, got dtype "
                         f"{raw.dtype}")
    if raw.ndim != 2 or raw.shape[0] != 2 or raw.shape[1] == 0:
        raise ValueError(f"{path}, field {_FIELD!r}: expected a 2 x K array (x row, y row), got "
                         f"shape {raw.shape}")
    pts = raw.astype(float).T
    if not np.all(np.isfinite(pts)):
        k = int(np.flatnonzero(~np.isfinite(pts).all(axis=1))[0])
        raise ValueError(f"{path}, field {_FIELD!r}: expected finite coordinates, got "
                         f"{raw[:, k].tolist()} in column {k}")
    return pts


def load_willow_class(folder) -> LandmarkSequence:
    """Load one Willow-ObjectClass class folder as a :class:`LandmarkSequence`.

    Parameters
    ----------
    folder : str or Path
        A class folder: ``<name>.mat`` annotations (field ``pts_coord``, 2 x K: x row, y row),
        each beside its ``<name>.png`` image.

    Returns
    -------
    LandmarkSequence
        One frame per annotation, in sorted file-name order (``frames`` = 0, 1, ...);
        ``name`` is the folder's name; ``image_paths`` / ``image_sizes`` when every annotation
        has its PNG image (sizes read from the PNG header), else ``None``. Landmark ``k`` is
        column ``k`` of ``pts_coord`` in every image.

    Raises
    ------
    FileNotFoundError
        No such folder.
    ValueError
        No ``.mat`` files, an unreadable file, a missing ``pts_coord`` field, one not of shape
        2 x K, not numeric or not finite, annotations with different K (the message names the
        file and the field), an unreadable PNG header.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from scipy.io import savemat
    >>> tmp = tempfile.TemporaryDirectory()
    >>> xy = np.array([[10.0, 50, 30, 70], [20, 25, 60, 65]])        # x row, y row
    >>> for name in ("duck_a", "duck_b"):
    ...     savemat(Path(tmp.name) / f"{name}.mat", {"pts_coord": xy})
    >>> seq = load_willow_class(tmp.name)
    >>> seq.points.shape, seq.points[0, 1].tolist(), seq.image_paths
    ((2, 4, 2), [50.0, 25.0], None)
    >>> tmp.cleanup()
    """
    folder = Path(folder).expanduser()
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: no such folder (expected a Willow-ObjectClass class "
                                "folder of `<name>.png` + `<name>.mat` files)")
    mats = sorted(p for p in folder.iterdir()
                  if p.suffix.lower() == ".mat" and p.is_file() and not p.name.startswith("."))
    if not mats:
        raise ValueError(f"{folder}: no annotation files (expected `<name>.mat` files with a "
                         f"{_FIELD!r} field beside `<name>.png` images)")
    points, first = [], None
    for mat in mats:
        P = _read_annotation(mat)
        if first is None:
            first = (mat, P.shape[0])
        elif P.shape[0] != first[1]:
            raise ValueError(f"{mat}, field {_FIELD!r}: {P.shape[0]} keypoints, but {first[0]} "
                             f"has {first[1]}; every image must have the same keypoints")
        points.append(P)
    image_paths = image_sizes = None
    pngs = [mat.with_suffix(".png") for mat in mats]
    if all(p.is_file() for p in pngs):
        image_paths = tuple(pngs)
        image_sizes = np.array([_png_size(p) for p in pngs], dtype=np.int64)
    return LandmarkSequence(folder.name, np.stack(points), np.arange(len(mats)), image_paths,
                            image_sizes, folder)
