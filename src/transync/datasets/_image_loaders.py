"""Loaders of real homography data: Oxford affine sequences, HPatches, graf 1->3, AdelaideRMF.

Formats:

* Oxford (Mikolajczyk et al.): ``img1.ppm .. imgN.ppm`` (or .png/.jpg/.pgm) and text files
  ``H1to2p .. H1toNp`` with a 3x3 matrix mapping pixels of image 1 into image k.
* HPatches sequences: ``1.ppm .. 6.ppm`` and text files ``H_1_2 .. H_1_6`` (image 1 into k).
* graf 1->3 (``oxford-graf/``): ``graf1.png``, ``graf3.png`` and ``H1to3p.xml``
  (OpenCV FileStorage, maps graf1 into graf3).
* AdelaideRMF (``adelaidermf/*.mat``): ``data`` 6xN (x1, y1, 1, x2, y2, 1), ``label``
  (0 = outlier, k = plane k), ``img1``, ``img2``.

Every sequence loader returns a :class:`HomographySequence` whose ``homographies[k]`` maps pixels of
view ``k`` into view 0 (the convention of :func:`transync.estimate_plane_homographies` with
``reference=0``), determinant 1.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ._home import data_home

__all__ = [
    "AdelaideRMFPair",
    "HomographySequence",
    "list_adelaidermf",
    "load_adelaidermf",
    "load_graf",
    "load_hpatches_sequence",
    "load_oxford_sequence",
]

_EXTS = (".ppm", ".png", ".jpg", ".jpeg", ".pgm", ".bmp", ".tif", ".tiff")


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
    """

    images: list
    homographies: np.ndarray
    names: list
    info: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def n_views(self) -> int:
        return len(self.images)


def _normalize(H):
    H = np.asarray(H, dtype=float)
    return H / np.cbrt(np.linalg.det(H))


def _read_matrix_text(path) -> np.ndarray:
    vals = [float(v) for v in re.split(r"[\s,;]+", Path(path).read_text().strip()) if v]
    if len(vals) != 9:
        raise ValueError(f"{path}: expected a 3x3 matrix (9 numbers), got {len(vals)} numbers")
    return np.array(vals).reshape(3, 3)


def _read_image(path) -> np.ndarray:
    arr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if arr is None:
        raise ValueError(f"cannot read image file {str(path)!r}")
    if arr.ndim == 3:
        arr = cv2.cvtColor(arr[..., :3], cv2.COLOR_BGR2RGB)
    return arr


def _find_image(folder: Path, stem: str) -> Path:
    for ext in _EXTS:
        p = folder / f"{stem}{ext}"
        if p.is_file():
            return p
    raise FileNotFoundError(f"no image {stem}.* ({', '.join(_EXTS)}) in {folder}")


def _sequence(folder, stems, h_files) -> HomographySequence:
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"`folder` must be an existing directory, got {str(folder)!r}")
    paths = [_find_image(folder, s) for s in stems]
    images = [_read_image(p) for p in paths]
    Hs = [np.eye(3)]
    for hf in h_files:
        H1k = _read_matrix_text(folder / hf)     # image 1 -> image k
        Hs.append(_normalize(np.linalg.inv(H1k)))
    return HomographySequence(images=images, homographies=np.stack(Hs),
                              names=[p.name for p in paths], info={"folder": str(folder)})


def load_oxford_sequence(folder) -> HomographySequence:
    """Oxford affine-covariant sequence (``img1.ppm ..``, ``H1to2p ..``).

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
    folder = Path(folder)
    ks = sorted(int(m.group(1)) for p in folder.glob("img*")
                if (m := re.fullmatch(r"img(\d+)\.\w+", p.name)))
    if not ks or ks[0] != 1:
        raise FileNotFoundError(f"no Oxford sequence (img1.*, img2.*, ...) in {folder}")
    return _sequence(folder, [f"img{k}" for k in ks], [f"H1to{k}p" for k in ks[1:]])


def load_hpatches_sequence(folder) -> HomographySequence:
    """HPatches full-image sequence (``1.ppm .. 6.ppm``, ``H_1_2 .. H_1_6``)."""
    folder = Path(folder)
    ks = sorted(int(m.group(1)) for p in folder.iterdir()
                if (m := re.fullmatch(r"(\d+)\.\w+", p.name))) if folder.is_dir() else []
    if not ks or ks[0] != 1:
        raise FileNotFoundError(f"no HPatches sequence (1.ppm, 2.ppm, ...) in {folder}")
    return _sequence(folder, [str(k) for k in ks], [f"H_1_{k}" for k in ks[1:]])


def load_graf(folder=None) -> HomographySequence:
    """Oxford graf images 1 and 3 with the ground truth ``H1to3p.xml`` (data home by default)."""
    folder = Path(folder) if folder is not None else data_home(subfolder="oxford-graf")
    fs = cv2.FileStorage(str(folder / "H1to3p.xml"), cv2.FILE_STORAGE_READ)
    if not fs.isOpened():
        raise FileNotFoundError(f"cannot read {folder / 'H1to3p.xml'}")
    node = fs.getFirstTopLevelNode()
    H13 = node.mat()
    fs.release()
    images = [_read_image(folder / "graf1.png"), _read_image(folder / "graf3.png")]
    return HomographySequence(images=images,
                              homographies=np.stack([np.eye(3), _normalize(np.linalg.inv(H13))]),
                              names=["graf1.png", "graf3.png"], info={"folder": str(folder)})


@dataclass(frozen=True)
class AdelaideRMFPair:
    """One AdelaideRMF image pair: correspondences ``x1 -> x2`` (pixels) with plane labels."""

    name: str
    x1: np.ndarray
    x2: np.ndarray
    labels: np.ndarray
    img1: np.ndarray = field(repr=False)
    img2: np.ndarray = field(repr=False)

    @property
    def n_planes(self) -> int:
        return int(self.labels.max())


def list_adelaidermf(folder=None) -> list:
    """Names of the AdelaideRMF sequences available (``.mat`` files)."""
    folder = Path(folder) if folder is not None else data_home(subfolder="adelaidermf")
    return sorted(p.stem for p in folder.glob("*.mat"))


def load_adelaidermf(name, folder=None) -> AdelaideRMFPair:
    """Load one AdelaideRMF pair (``scipy.io.loadmat``)."""
    from scipy.io import loadmat

    folder = Path(folder) if folder is not None else data_home(subfolder="adelaidermf")
    path = folder / f"{name}.mat"
    if not path.is_file():
        raise FileNotFoundError(f"`name`: no AdelaideRMF file {path}")
    m = loadmat(str(path))
    data = np.asarray(m["data"], dtype=float)
    labels = np.asarray(m["label"]).ravel().astype(int)
    return AdelaideRMFPair(name=name, x1=(data[:2] / data[2]).T, x2=(data[3:5] / data[5]).T,
                           labels=labels, img1=np.asarray(m["img1"]), img2=np.asarray(m["img2"]))
