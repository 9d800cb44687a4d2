"""Willow-ObjectClass (Cho, Alahari & Ponce, ICCV 2013) in its documented layout.

A class folder (``Car``, ``Duck``, ``Face``, ``Motorbike``, ``Winebottle``) holds images
``<name>.png``, each with an annotation ``<name>.mat`` whose field ``pts_coord`` is a 2 x 10
float array: the x coordinates in row 0, the y coordinates in row 1 (pixels), column ``k`` the
``k``-th keypoint of the class — the same keypoint in every image. The same layout is read by
pygmtools' ``WillowObject`` benchmark.

Every error on malformed input is a ``ValueError`` (``FileNotFoundError`` for a missing folder)
naming the file and the field.
The annotations are read by :func:`transync.datasets._matfile.read_mat` (why not
``scipy.io.loadmat`` directly: see there).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._validation import check_path
from ._cmu import LandmarkSequence, _png_size
from ._home import no_folder
from ._matfile import MatFieldError, MatFileError, read_mat

__all__ = ["load_willow_class"]

_FIELD = "pts_coord"


def _read_annotation(path: Path) -> np.ndarray:
    try:
        fields, names = read_mat(path, (_FIELD,))
    except MatFieldError as exc:
        raise ValueError(f"{path}, field {_FIELD!r}: expected a numeric 2 x K array, got "
                         f"{exc.what}") from None
    except MatFileError as exc:
        raise ValueError(f"{path}: {exc}") from None
    raw = fields.get(_FIELD)
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
    folder = check_path(folder, "folder")
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: {no_folder(folder)} (expected a Willow-ObjectClass "
                                "class folder of `<name>.png` + `<name>.mat` files)")
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
