"""Loaders of real homography data: Oxford affine sequences, HPatches, graf 1->3, AdelaideRMF.

Formats:

* Oxford (Mikolajczyk et al.): ``img1.ppm .. imgN.ppm`` (or .png/.jpg/.pgm) and text files
  ``H1to2p .. H1toNp`` with a 3x3 matrix mapping pixels of image 1 into image k.
* HPatches sequences: ``1.ppm .. 6.ppm`` and text files ``H_1_2 .. H_1_6`` (image 1 into k).
* graf 1->3 (``oxford-graf/``): ``graf1.png``, ``graf3.png`` and ``H1to3p.xml``
  (OpenCV FileStorage, maps graf1 into graf3); the Oxford text file ``H1to3p`` is read when the
  XML file is absent.
* AdelaideRMF (``adelaidermf/*.mat``): ``data`` 6xN (x1, y1, 1, x2, y2, 1), ``label``
  (0 = outlier, k = plane k), ``img1``, ``img2``.

Every sequence loader returns a :class:`HomographySequence` whose ``homographies[k]`` maps pixels of
view ``k`` into view 0 (the convention of :func:`transync.estimate_plane_homographies` with
``reference=0``), determinant 1. Images of one sequence may differ in size.

Every error on a malformed file is a ``ValueError`` (``FileNotFoundError`` for a missing file or
folder) whose message names the file, and the line or field where the format has one.
OpenCV is imported only when an image is decoded.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import check_path
from ..geometry import normalize_determinant, rescale_homogeneous
from ._home import data_home
from ._matfile import MatFieldError, MatFileError, read_mat
from ._text import is_number, text_lines

__all__ = [
    "AdelaideRMFPair",
    "HomographySequence",
    "list_adelaidermf",
    "load_adelaidermf",
    "load_graf",
    "load_hpatches_sequence",
    "load_oxford_sequence",
    "read_image",
]

_EXTS = (".ppm", ".png", ".jpg", ".jpeg", ".pgm", ".bmp", ".tif", ".tiff")
# a homography whose singular values span more than this is refused as singular
_MAX_CONDITION = 1e12


@dataclass(frozen=True)
class HomographySequence:
    """Images of a planar scene with ground-truth homographies into the first image.

    Attributes
    ----------
    images : list of ndarray (RGB or grey, uint8)
    homographies : ndarray (N, 3, 3)
        ``homographies[k]`` maps pixels of image ``k`` into image 0 (determinant 1).
    names : list of str
    info : dict

    Examples
    --------
    See :func:`load_oxford_sequence`, which builds one from files.

    >>> import numpy as np
    >>> seq = HomographySequence(images=[np.zeros((8, 8))] * 2,
    ...                          homographies=np.stack([np.eye(3)] * 2), names=["a", "b"])
    >>> seq.n_views
    2
    """

    images: list
    homographies: np.ndarray
    names: list
    info: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def n_views(self) -> int:
        return len(self.images)


def _check_homography(H: np.ndarray, where: str) -> np.ndarray:
    """Refuse non-finite or singular 3x3 matrices read from ``where``; return the matrix
    rescaled where its entries are huge or tiny (subnormal entries passed the checks, then the
    inverse overflowed and the loader returned NaN homographies without a word)."""
    if not np.all(np.isfinite(H)):
        raise ValueError(f"{where}: expected a finite 3x3 homography, got NaN or infinite entries")
    H = rescale_homogeneous(H)
    s = np.linalg.svd(H, compute_uv=False)
    if s[0] == 0 or s[-1] <= s[0] / _MAX_CONDITION:
        raise ValueError(f"{where}: expected an invertible 3x3 homography, got a singular matrix "
                         f"(singular values {s[0]:.3g} .. {s[-1]:.3g})")
    return H


def _read_matrix_text(path) -> np.ndarray:
    """A 3x3 matrix written as three lines of three numbers (blank lines ignored)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"`{path}`: ground-truth homography file not found")
    try:
        text = path.read_text(encoding="utf-8-sig", errors="strict")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"`{path}`: cannot read the homography as text ({exc})") from None
    rows = []
    for lineno, line in enumerate(text_lines(text), start=1):
        tokens = [t for t in re.split(r"[\s,;]+", line.strip()) if t]
        if not tokens:
            continue
        if not all(is_number(t) for t in tokens):        # strict: no `1_5`, no NaN, no NUL
            raise ValueError(f"`{path}`, line {lineno}: expected 3 finite numbers, "
                             f"got {line.strip()!r:.80}")
        values = [float(t) for t in tokens]
        if len(values) != 3:
            raise ValueError(f"`{path}`, line {lineno}: expected 3 numbers, got {len(values)} "
                             f"({line.strip()!r:.80})")
        if not all(np.isfinite(values)):
            raise ValueError(f"`{path}`, line {lineno}: expected finite numbers, "
                             f"got {line.strip()!r:.80}")
        rows.append(values)
    if len(rows) != 3:
        raise ValueError(f"`{path}`: expected a 3x3 matrix (3 lines of 3 numbers), "
                         f"got {len(rows)} non-empty lines")
    return _check_homography(np.array(rows), f"`{path}`")


def _read_matrix_xml(path) -> np.ndarray:
    """The first ``opencv-matrix`` of an OpenCV FileStorage XML file, as a 3x3 array."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        line, col = exc.position
        raise ValueError(f"`{path}`, line {line}, column {col}: malformed XML "
                         f"({str(exc).split(':')[0]})") from None
    except OSError as exc:
        raise ValueError(f"`{path}`: cannot read the file ({exc})") from None
    node = next((el for el in root.iter() if el.get("type_id") == "opencv-matrix"), None)
    if node is None:
        raise ValueError(f"`{path}`: expected an element with type_id=\"opencv-matrix\", "
                         "found none")
    fields = {}
    for name in ("rows", "cols", "data"):
        child = node.find(name)
        if child is None or child.text is None or not child.text.strip():
            raise ValueError(f"`{path}`, field <{node.tag}><{name}>: missing or empty")
        fields[name] = child.text.strip()
    try:
        if not all(t.isascii() and t.isdigit() for t in (fields["rows"], fields["cols"])):
            raise ValueError
        rows, cols = int(fields["rows"]), int(fields["cols"])
    except ValueError:
        raise ValueError(f"`{path}`, fields <rows>/<cols>: expected integers, got "
                         f"{fields['rows']!r:.20} and {fields['cols']!r:.20}") from None
    if (rows, cols) != (3, 3):
        raise ValueError(f"`{path}`, fields <rows>/<cols>: expected a 3x3 matrix, "
                         f"got {rows}x{cols}")
    tokens = fields["data"].split()
    bad = next((t for t in tokens if not is_number(t)), None)   # strict, as the text reader:
    if bad is not None:                                         # float() read `1_0` as 10
        raise ValueError(f"`{path}`, field <data>: expected 9 numbers, got {bad!r:.40} in "
                         f"{fields['data']!r:.80}")
    values = [float(t) for t in tokens]
    if len(values) != 9:
        raise ValueError(f"`{path}`, field <data>: expected 9 numbers, got {len(values)}")
    return _check_homography(np.array(values).reshape(3, 3), f"`{path}`, field <data>")


def read_image(path) -> np.ndarray:
    """Decode an image file into a grey or RGB array (the one image reader of the package).

    The file is decoded from its bytes (``cv2.imdecode``), which refuses a damaged file that
    ``cv2.imread`` would return half decoded (a truncated JPEG came back with a grey lower half,
    and only a line on stderr said so). OpenCV's own log stays silent: the error says it.

    Parameters
    ----------
    path : str or path-like
        An image file in a format OpenCV reads (PNG, JPEG, PPM/PGM, BMP, TIFF, ...).

    Returns
    -------
    ndarray of shape (H, W) or (H, W, 3)
        Grey (one channel, or grey + alpha) or RGB (the alpha channel dropped), in the file's
        depth (uint8, or uint16 for 16-bit files).

    Raises
    ------
    ValueError
        The file cannot be read, is empty, or cannot be decoded (unknown or damaged format);
        the message names the file.

    Examples
    --------
    >>> import os, tempfile
    >>> import cv2, numpy as np
    >>> from transync.datasets import read_image
    >>> path = os.path.join(tempfile.mkdtemp(), "im.png")
    >>> bgr = np.zeros((4, 5, 3), np.uint8); bgr[..., 2] = 255          # red, in OpenCV's BGR
    >>> _ = cv2.imwrite(path, bgr)
    >>> im = read_image(path); im.shape, im[0, 0].tolist()
    ((4, 5, 3), [255, 0, 0])
    """
    import cv2

    path = check_path(path, "path")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"`{path}`: cannot read the image file ({exc})") from None
    arr = None
    if raw:
        log = cv2.utils.logging
        level = log.getLogLevel()
        log.setLogLevel(log.LOG_LEVEL_SILENT)   # a damaged file is reported below, not on stderr
        try:
            arr = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_UNCHANGED)
        except cv2.error:
            arr = None
        finally:
            log.setLogLevel(level)
    if arr is None or arr.size == 0:
        why = "empty file" if not raw else f"{len(raw)} bytes, unknown or corrupt format"
        raise ValueError(f"`{path}`: cannot decode the image file ({why})")
    if arr.ndim == 3:
        channels = arr.shape[2]
        if channels <= 2:                 # grey (+ alpha)
            arr = arr[..., 0]
        else:                             # BGR(A) -> RGB
            arr = arr[..., 2::-1]
        arr = np.ascontiguousarray(arr)
    return arr


def _find_image(folder: Path, stem: str) -> Path:
    for ext in _EXTS:
        for p in (folder / f"{stem}{ext}", folder / f"{stem}{ext.upper()}"):
            if p.is_file():
                return p
    raise FileNotFoundError(f"`{folder}`: no image {stem}.* ({', '.join(_EXTS)})")


def _check_folder(folder) -> Path:
    folder = check_path(folder, "folder")
    if not folder.is_dir():
        raise FileNotFoundError(f"`folder` must be an existing directory, got {str(folder)!r}")
    return folder


def _image_files(folder: Path, pattern: str) -> dict:
    """``{k: path}`` for the image files whose name matches ``pattern`` (group 1 = index ``k``,
    ASCII digits), sorted by ``k``; when one index has several files of one name
    (``img1.ppm``, ``img1.png``) the first extension of ``_EXTS`` wins; two spellings of one
    index (``img1.png``, ``img01.png``) are refused (which one is view 1?)."""
    found: dict = {}
    for p in sorted(folder.iterdir()):
        m = re.fullmatch(pattern, p.name, re.ASCII)
        if m and p.suffix.lower() in _EXTS and p.is_file():
            found.setdefault(int(m.group(1)), []).append(p)
    for k, ps in found.items():
        stems = sorted({p.stem for p in ps})
        if len(stems) > 1:
            raise ValueError(f"`{folder}`: image {k} is given twice ({', '.join(stems)}); keep "
                             "one spelling of each image number")
    return {k: min(ps, key=lambda p: (_EXTS.index(p.suffix.lower()), p.name))
            for k, ps in sorted(found.items())}


def _sequence(folder: Path, files: dict, h_name) -> HomographySequence:
    if min(files) < 1:               # image 1 is the reference every ground truth starts from
        raise ValueError(f"{files[min(files)]}: image index {min(files)}, but the format "
                         f"numbers images from 1 (image 1 is the reference of the ground "
                         f"truth {h_name(2)}, ...); rename or remove it")
    paths = list(files.values())
    images = [read_image(p) for p in paths]
    Hs = [np.eye(3)]
    for k in list(files)[1:]:
        H1k = _read_matrix_text(folder / h_name(k))     # image 1 -> image k
        Hs.append(normalize_determinant(np.linalg.inv(H1k)))
    return HomographySequence(images=images, homographies=np.stack(Hs),
                              names=[p.name for p in paths], info={"folder": str(folder)})


def load_oxford_sequence(folder) -> HomographySequence:
    """Oxford affine-covariant sequence (``img1.ppm ..``, ``H1to2p ..``).

    Parameters
    ----------
    folder : path
        Folder holding ``img1.*``, ``img2.*``, ... and ``H1to2p``, ``H1to3p``, ...

    Returns
    -------
    HomographySequence
        The images and the ground-truth homographies of every image into the first.

    Raises
    ------
    FileNotFoundError
        The folder, ``img1.*`` or a ground-truth file is missing.
    ValueError
        A file is malformed (named with its line), an image cannot be decoded, or a homography
        is not finite or singular.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np, cv2
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> for k in (1, 2):
    ...     _ = cv2.imwrite(str(d / f"img{k}.png"), np.zeros((8, 8), np.uint8))
    >>> _ = (d / "H1to2p").write_text("1 0 2\\n0 1 0\\n0 0 1\\n")
    >>> seq = load_oxford_sequence(d)
    >>> seq.n_views, float(seq.homographies[1][0, 2])
    (2, -2.0)
    """
    folder = _check_folder(folder)
    files = _image_files(folder, r"img(\d+)\.\w+")
    if 1 not in files:
        raise FileNotFoundError(f"`{folder}`: no Oxford sequence (img1.*, img2.*, ...) found")
    return _sequence(folder, files, lambda k: f"H1to{k}p")


def load_hpatches_sequence(folder) -> HomographySequence:
    """HPatches full-image sequence: images ``1.ppm`` to ``6.ppm``, ground truth ``H_1_2`` to
    ``H_1_6``.

    Parameters
    ----------
    folder : path
        Folder holding ``1.*``, ``2.*``, ... and ``H_1_2``, ``H_1_3``, ...

    Returns
    -------
    HomographySequence
        The images and the ground-truth homographies of every image into the first.

    Raises
    ------
    FileNotFoundError
        The folder, ``1.*`` or a ground-truth file is missing.
    ValueError
        As :func:`load_oxford_sequence`.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np, cv2
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> for k in (1, 2):
    ...     _ = cv2.imwrite(str(d / f"{k}.png"), np.zeros((8, 8), np.uint8))
    >>> _ = (d / "H_1_2").write_text("1 0 0\\n0 1 3\\n0 0 1\\n")
    >>> seq = load_hpatches_sequence(d)
    >>> seq.names, float(seq.homographies[1][1, 2])
    (['1.png', '2.png'], -3.0)
    """
    folder = _check_folder(folder)
    files = _image_files(folder, r"(\d+)\.\w+")
    if 1 not in files:
        raise FileNotFoundError(f"`{folder}`: no HPatches sequence (1.ppm, 2.ppm, ...) found")
    return _sequence(folder, files, lambda k: f"H_1_{k}")


def load_graf(folder=None) -> HomographySequence:
    """Oxford graf images 1 and 3 with the ground truth ``H1to3p.xml`` (data home by default).

    The ground truth is read from ``H1to3p.xml`` (OpenCV FileStorage) or, when that file is
    absent, from the Oxford text file ``H1to3p``.

    Parameters
    ----------
    folder : path, optional
        Folder holding ``graf1.*``, ``graf3.*`` and the ground truth; default the data home's
        ``oxford-graf``.

    Returns
    -------
    HomographySequence
        Two views; ``homographies[1]`` maps graf3 into graf1.

    Raises
    ------
    FileNotFoundError
        The folder, an image or the ground truth is missing.
    ValueError
        As :func:`load_oxford_sequence`.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np, cv2
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> for k in (1, 3):
    ...     _ = cv2.imwrite(str(d / f"graf{k}.png"), np.zeros((8, 8), np.uint8))
    >>> _ = (d / "H1to3p").write_text("1 0 5\\n0 1 0\\n0 0 1\\n")
    >>> float(load_graf(d).homographies[1][0, 2])
    -5.0
    """
    folder = _check_folder(folder) if folder is not None else data_home(subfolder="oxford-graf")
    xml, text = folder / "H1to3p.xml", folder / "H1to3p"
    if xml.is_file():
        H13 = _read_matrix_xml(xml)
    elif text.is_file():
        H13 = _read_matrix_text(text)
    else:
        raise FileNotFoundError(f"`{folder}`: no ground truth H1to3p.xml or H1to3p")
    paths = [_find_image(folder, "graf1"), _find_image(folder, "graf3")]
    images = [read_image(p) for p in paths]
    return HomographySequence(images=images,
                              homographies=np.stack([np.eye(3),
                                                     normalize_determinant(np.linalg.inv(H13))]),
                              names=[p.name for p in paths], info={"folder": str(folder)})


@dataclass(frozen=True)
class AdelaideRMFPair:
    """One AdelaideRMF image pair: correspondences ``x1 -> x2`` (pixels) with plane labels.


    Attributes
    ----------
    name : str
        The sequence name (file stem).
    x1, x2 : ndarray of shape (n, 2)
        Corresponding points in image 1 and image 2, pixels.
    labels : ndarray of shape (n,), int
        Plane of every correspondence (0: outlier).
    img1, img2 : ndarray
        The two images.

    Examples
    --------
    See :func:`load_adelaidermf`.

    >>> AdelaideRMFPair.__dataclass_fields__.keys() >= {"x1", "x2", "labels"}
    True
    """

    name: str
    x1: np.ndarray
    x2: np.ndarray
    labels: np.ndarray
    img1: np.ndarray = field(repr=False)
    img2: np.ndarray = field(repr=False)

    @property
    def n_planes(self) -> int:
        return int(self.labels.max()) if self.labels.size else 0


def _adelaide_folder(folder) -> Path:
    return _check_folder(folder) if folder is not None else data_home(subfolder="adelaidermf")


def list_adelaidermf(folder=None) -> list:
    """Names of the AdelaideRMF sequences available (``.mat`` files; empty list if none).

    Parameters
    ----------
    folder : path, optional
        Folder of the ``.mat`` files; default the data home's ``adelaidermf``.

    Returns
    -------
    list of str
        Sorted file stems, the names :func:`load_adelaidermf` accepts.

    Raises
    ------
    FileNotFoundError
        The folder does not exist.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "johnsona.mat").write_bytes(b"")
    >>> list_adelaidermf(d)
    ['johnsona']
    """
    folder = _adelaide_folder(folder)
    return sorted(p.stem for p in folder.glob("*.mat") if p.is_file())


def _mat_field(m: dict, names: list, key: str, path: Path) -> np.ndarray:
    if key not in m:
        raise ValueError(f"`{path}`: field {key!r} missing (expected data, label, img1, img2; "
                         f"found {', '.join(sorted(names)) or 'none'})")
    return np.asarray(m[key])


def _mat_image(m: dict, names: list, key: str, path: Path) -> np.ndarray:
    img = _mat_field(m, names, key, path)
    if img.dtype.kind not in "uif" or img.ndim not in (2, 3) or min(img.shape[:2], default=0) < 1 \
            or (img.ndim == 3 and img.shape[2] not in (1, 3, 4)):
        raise ValueError(f"`{path}`, field {key!r}: expected an image (H, W) or (H, W, 3), "
                         f"got shape {img.shape} and dtype {img.dtype}")
    finite = img.dtype.kind != "f" or bool(np.isfinite(img).all())
    if img.dtype.kind == "f" and not (finite and img.min() >= 0):
        got = "NaN or infinite" if not finite else "negative"
        raise ValueError(f"`{path}`, field {key!r}: expected an image of finite non-negative "
                         f"intensities, got {got} values")
    return img


def load_adelaidermf(name, folder=None) -> AdelaideRMFPair:
    """Load one AdelaideRMF pair (a MATLAB .mat file).

    Parameters
    ----------
    name : str
        Sequence name, the ``.mat`` file's stem (see :func:`list_adelaidermf`).
    folder : path, default=None
        Folder of the ``.mat`` files (the data home's ``adelaidermf`` by default).

    Returns
    -------
    AdelaideRMFPair
        The two images, the correspondences and their plane labels (0 = gross outlier).

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        The file cannot be read as MATLAB data, or a field is missing or malformed (``data``
        6xN and finite with non-zero homogeneous rows, ``label`` N non-negative integers,
        ``img1``/``img2`` images); the message names the file and the field.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> from scipy.io import savemat
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> x = np.array([[10.0, 20.0], [5.0, 6.0], [1, 1], [11.0, 21.0], [5.0, 7.0], [1, 1]])
    >>> img = np.zeros((4, 4, 3), np.uint8)
    >>> savemat(d / "pair.mat", {"data": x, "label": np.array([[1, 0]]), "img1": img,
    ...                          "img2": img})
    >>> p = load_adelaidermf("pair", d)
    >>> p.x2.tolist(), p.labels.tolist()
    ([[11.0, 5.0], [21.0, 7.0]], [1, 0])
    """
    if not isinstance(name, str) or not name or Path(name).name != name:
        raise ValueError(f"`name` must be a sequence name (a file stem without folder), "
                         f"got {name!r:.60}")
    folder = _adelaide_folder(folder)
    path = check_path(folder / f"{name}.mat", "name")     # a name too long: a named error
    if not path.is_file():
        raise FileNotFoundError(f"`name`: no AdelaideRMF file {path}")
    try:
        m, names = read_mat(path, ("data", "label", "img1", "img2"))
    except MatFieldError as exc:
        expect = {"data": "a 6xN array (x1, y1, 1, x2, y2, 1)",
                  "label": "one integer label per column of 'data'"}.get(
                      exc.field, "an image (H, W) or (H, W, 3)")
        raise ValueError(f"`{path}`, field {exc.field!r}: expected {expect}, got "
                         f"{exc.what}") from None
    except MatFileError as exc:
        raise ValueError(f"`{path}`: {exc}") from None
    data = _mat_field(m, names, "data", path)
    if data.dtype.kind not in "uif" or data.ndim != 2 or data.shape[0] != 6:
        raise ValueError(f"`{path}`, field 'data': expected a 6xN array (x1, y1, 1, x2, y2, 1), "
                         f"got shape {data.shape} and dtype {data.dtype}")
    data = data.astype(float)
    if not np.all(np.isfinite(data)):
        raise ValueError(f"`{path}`, field 'data': expected finite values, got NaN or infinite "
                         "entries")
    if np.any(data[2] == 0) or np.any(data[5] == 0):
        raise ValueError(f"`{path}`, field 'data': homogeneous rows 3 and 6 must be non-zero")
    with np.errstate(over="ignore"):
        x1, x2 = (data[:2] / data[2]).T, (data[3:5] / data[5]).T
    if not (np.isfinite(x1).all() and np.isfinite(x2).all()):
        raise ValueError(f"`{path}`, field 'data': the points (x / w, y / w) overflow float64 "
                         "(homogeneous entries near zero)")
    n = data.shape[1]
    raw = _mat_field(m, names, "label", path)
    labels = raw.ravel()
    if raw.dtype.kind not in "uif" or labels.size != n or sum(d > 1 for d in raw.shape) > 1:
        raise ValueError(f"`{path}`, field 'label': expected {n} labels (one per column of "
                         f"'data'), got shape {raw.shape} and dtype {raw.dtype}")
    if labels.dtype.kind == "f" and not np.all(np.isfinite(labels) & (labels == np.round(labels))):
        raise ValueError(f"`{path}`, field 'label': expected integer labels, got non-integer "
                         "values")
    if labels.size and (labels.min() < 0 or labels.max() >= 2**62):
        bad = labels.min() if labels.min() < 0 else labels.max()
        raise ValueError(f"`{path}`, field 'label': expected labels from 0 (outlier) to "
                         f"{2**62 - 1}, got {bad:.6g}")
    labels = labels.astype(np.int64)
    img1, img2 = _mat_image(m, names, "img1", path), _mat_image(m, names, "img2", path)
    return AdelaideRMFPair(name=name, x1=x1, x2=x2, labels=labels, img1=img1, img2=img2)
