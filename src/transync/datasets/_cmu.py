"""Landmark sequences: the CMU House / Hotel layout, and the graphs built on them.

CMU layout (House: 111 frames, Hotel: 101 frames, 30 hand-labelled landmarks each)::

    <folder>/label/<name><N>          text, one landmark per row: ``x y`` in pixels
    <folder>/images/<name>.seq<k>.png optional; frame k

Label file ``<name><N>`` belongs to frame ``N - 1`` (``house1`` is ``house.seq0.png``). The name
prefix (``house``, ``hotel``, ...) is read from the files, never assumed. Landmark ``k`` is the
same physical point in every frame, so the ground truth of any set of frames is the identity.

Graphs (:meth:`LandmarkSequence.graphs`) are Delaunay triangulations of the landmarks, with
coordinates divided by the image diagonal when the image sizes are known (PNG headers, read
without decoding) and by the diagonal of the frame's landmark bounding box otherwise, so that
the Yan et al. affinity scale (``Scale = 0.05``) is meaningful; see
:data:`LANDMARK_AFFINITY`, the keyword arguments of
:func:`transync.matching.gaussian_edge_affinity` for it (``gaussian_edge_affinity(g1, g2,
**LANDMARK_AFFINITY)``).

Every error on malformed input is a ``ValueError`` (``FileNotFoundError`` for a missing folder)
naming the file and, for text files, the line.
"""

from __future__ import annotations

import math
import numbers
import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._validation import (as_generator, check_array, check_bool, check_choice, check_int,
                           check_int_array, check_path, frozen_copy)
from ..graphs import Graph
from ._graphs import GraphCollectionProblem
from ._home import data_home, no_folder
from ._text import is_number, text_lines

__all__ = ["LANDMARK_AFFINITY", "LandmarkSequence", "load_cmu_sequence"]

#: Keyword arguments of :func:`transync.matching.gaussian_edge_affinity` for the length + angle
#: edge affinity of Yan et al. on diagonal-normalized landmarks (Yan et al., TPAMI 2016):
#: ``exp(-(0.9 dd^2 + 0.1 dtheta^2) / 0.05)`` (``dd`` edge-length difference, ``dtheta`` wrapped
#: angle difference in radians), written as ``exp(-(dd^2 + angle_weight dtheta^2) / sigma2)``.
LANDMARK_AFFINITY = {"attribute": "length+angle", "sigma2": 0.05 / 0.9, "angle_weight": 0.1 / 0.9}

# `<name><N>`: the name ends at the trailing digits and may hold digits itself (`cam2_1`)
_LABEL_RE = re.compile(r"^(?P<name>[A-Za-z_](?:[\w.\-]*[A-Za-z_.\-])?)(?P<number>\d+)$", re.ASCII)
_PNG_MAX_SIDE = 2**31 - 1          # the PNG specification's limit on width and height
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_size(path: Path) -> tuple[int, int]:
    """(width, height) from a PNG header, without decoding the image."""
    with open(path, "rb") as f:
        head = f.read(24)
    if len(head) < 24 or head[:8] != _PNG_SIGNATURE or head[12:16] != b"IHDR":
        raise ValueError(f"{path}: not a PNG image (cannot read its size from the header)")
    width, height = struct.unpack(">II", head[16:24])
    if width == 0 or height == 0:
        raise ValueError(f"{path}: PNG header gives an empty image ({width} x {height})")
    if max(width, height) > _PNG_MAX_SIDE:
        raise ValueError(f"{path}: PNG header gives {width} x {height} pixels, beyond the "
                         f"format's limit of {_PNG_MAX_SIDE} (a damaged header)")
    return int(width), int(height)


@dataclass(frozen=True)
class LandmarkSequence:
    """Frames of one object with the same landmarks in every frame.

    Attributes
    ----------
    name : str
        The sequence's name (``"house"``, ``"hotel"``; the class folder's name for Willow).
    points : ndarray of shape (n_frames, n_landmarks, 2), float
        Pixel coordinates ``x, y``; landmark ``k`` is the same point in every frame.
    frames : ndarray of shape (n_frames,), int
        Frame number of each row of ``points`` (CMU: label file ``<name><N>`` is frame ``N - 1``;
        Willow: position in the sorted file list).
    image_paths : tuple of Path, or None
        The image of each frame, when every frame has one.
    image_sizes : ndarray of shape (n_frames, 2), int, or None
        ``(width, height)`` of each image, with ``image_paths``.
    source : Path
        The folder read.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> from transync.datasets import load_cmu_sequence
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> (d / "label").mkdir()
    >>> pts = np.random.default_rng(0).random((5, 2)) * 100
    >>> for k in (1, 2, 3):
    ...     np.savetxt(d / "label" / f"house{k}", pts + k)
    >>> seq = load_cmu_sequence(d)
    >>> seq.n_frames, seq.n_landmarks, len(seq.graphs([0, 2]).graphs)
    (3, 5, 2)
    """

    name: str
    points: np.ndarray
    frames: np.ndarray
    image_paths: tuple | None
    image_sizes: np.ndarray | None
    source: Path
    _position: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if not isinstance(self.name, str):
            raise TypeError(f"`name` must be a str, got {type(self.name).__name__}")
        P = check_array(self.points, "points", ndim=3)
        if P.shape[2] != 2 or P.shape[0] < 1 or P.shape[1] < 1:
            raise ValueError(f"`points` must have shape (n_frames, n_landmarks, 2) with at least "
                             f"one frame and one landmark, got shape {P.shape}")
        F = check_int_array(self.frames, "frames", ndim=1)
        if F.shape != (P.shape[0],):
            raise ValueError(f"`frames` must hold one frame number per row of `points` "
                             f"({P.shape[0]}), got shape {F.shape}")
        if np.unique(F).size != F.size:
            raise ValueError(f"`frames` must not repeat a frame number, got {F.tolist()!r:.80}")
        object.__setattr__(self, "points", frozen_copy(P))
        object.__setattr__(self, "frames", frozen_copy(F.astype(np.int64)))
        if (self.image_paths is None) != (self.image_sizes is None):
            raise ValueError("`image_paths` and `image_sizes` must be given together")
        if self.image_sizes is not None:
            S = check_int_array(self.image_sizes, "image_sizes", ndim=2)
            if S.shape != (P.shape[0], 2) or (S.size and S.min() < 1):
                raise ValueError(f"`image_sizes` must hold a positive (width, height) per frame, "
                                 f"shape ({P.shape[0]}, 2), got shape {S.shape}")
            if len(self.image_paths) != P.shape[0]:
                raise ValueError(f"`image_paths` must hold one path per frame ({P.shape[0]}), got "
                                 f"{len(self.image_paths)}")
            object.__setattr__(self, "image_paths", tuple(Path(p) for p in self.image_paths))
            object.__setattr__(self, "image_sizes", frozen_copy(S.astype(np.int64)))
        if self.source is not None:
            object.__setattr__(self, "source", check_path(self.source, "source"))
        object.__setattr__(self, "_position",
                           {int(f): p for p, f in enumerate(self.frames.tolist())})

    @property
    def n_frames(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_landmarks(self) -> int:
        return int(self.points.shape[1])

    def __repr__(self) -> str:
        images = "with images" if self.image_paths is not None else "no images"
        return (f"LandmarkSequence(name={self.name!r}, n_frames={self.n_frames}, "
                f"n_landmarks={self.n_landmarks}, {images}, source={str(self.source)!r})")

    def normalized_points(self, frames=None, *, normalize: str = "auto") -> np.ndarray:
        """Landmarks of ``frames`` (default: all) divided by a diagonal: (len, n_landmarks, 2).

        ``normalize``: ``"image"`` divides by each frame's image diagonal (needs the images),
        ``"bbox"`` by the diagonal of the frame's landmark bounding box, ``"auto"`` is
        ``"image"`` when the image sizes are known, else ``"bbox"``; ``"none"`` keeps pixels.
        """
        pos = self._positions(list(self.frames) if frames is None else frames)
        check_choice(normalize, "normalize", ("auto", "image", "bbox", "none"))
        if normalize == "auto":
            normalize = "image" if self.image_sizes is not None else "bbox"
        P = self.points[pos]
        if normalize == "none":
            return P.copy()
        if normalize == "image":
            if self.image_sizes is None:
                raise ValueError("`normalize='image'` needs the image sizes, but this sequence "
                                 "has no images; use normalize='bbox'")
            diag = np.hypot(*self.image_sizes[pos].T.astype(float))
        else:
            diag = np.hypot(*(P.max(axis=1) - P.min(axis=1)).T)
            bad = np.flatnonzero(diag <= 0)
            if bad.size:
                raise ValueError(f"frame {int(self.frames[pos[bad[0]]])}: all landmarks coincide, "
                                 "cannot normalize by the bounding-box diagonal")
        return P / diag[:, None, None]

    def _positions(self, frames) -> list[int]:
        if (isinstance(frames, (str, bytes)) or not isinstance(frames, (Sequence, np.ndarray))
                or np.ndim(frames) == 0):
            what = (f"an array of shape {np.shape(frames)}" if isinstance(frames, np.ndarray)
                    else type(frames).__name__)
            raise TypeError(f"`frames` must be a sequence of frame numbers, got {what}")
        out = []
        for k, f in enumerate(list(np.asarray(frames).ravel()) if isinstance(frames, np.ndarray)
                              else frames):
            if isinstance(f, (bool, np.bool_)) or not isinstance(f, numbers.Integral):
                raise TypeError(f"`frames[{k}]` must be an int frame number, got "
                                f"{type(f).__name__} {f!r}")
            if int(f) not in self._position:
                raise ValueError(f"`frames[{k}]` must be a frame of {self.name!r} (frame numbers "
                                 f"{int(self.frames.min())}..{int(self.frames.max())}), got "
                                 f"{int(f)}")
            out.append(self._position[int(f)])
        if not out:
            raise ValueError("`frames` must name at least one frame, got none")
        return out

    def graphs(self, frames, *, shuffle: bool = True, keep=None, rng=None,
               normalize: str = "auto") -> GraphCollectionProblem:
        """Delaunay graphs on the landmarks of ``frames``, shuffled, with their ground truth.

        Parameters
        ----------
        frames : sequence of int
            Frame numbers (values of :attr:`frames`); a frame may appear twice.
        shuffle : bool, default=True
            Randomly reorder the nodes of every graph.
        keep : int or (int, int), optional
            Landmarks kept per frame: a number, or a ``(min, max)`` range from which each frame's
            count is drawn uniformly; which landmarks are kept is drawn with ``rng``. Default:
            all (the partial protocol keeps e.g. ``(20, 25)`` of 30).
        rng : None, int or Generator
        normalize : {"auto", "image", "bbox", "none"}, default="auto"
            Coordinate scaling (:meth:`normalized_points`): the image diagonal when the image
            sizes are known, else the frame's landmark bounding-box diagonal.

        Returns
        -------
        GraphCollectionProblem
            ``graphs[g]`` built by ``Graph.from_points(..., edges="delaunay")``; node ``u`` of
            graph ``g`` is landmark ``labels[g][u]``, i.e. ``ground_truth``
            (a :class:`~transync.permutations.MultiMatching`) puts landmark ``k`` in universe
            slot ``k`` (``n_universe = n_landmarks``). ``params`` records the frames, ``keep``,
            ``shuffle`` and ``normalize``.

        Examples
        --------
        >>> import numpy as np
        >>> P = np.array([[[0, 0], [4, 0], [0, 3], [4, 3], [2, 5]]] * 3, dtype=float)
        >>> seq = LandmarkSequence("toy", P, [0, 1, 2], None, None, source=".")
        >>> prob = seq.graphs([0, 2], rng=0)
        >>> [g.n_nodes for g in prob.graphs]
        [5, 5]
        >>> t = prob.truth(0, 1)                           # node u of graph 0 -> node t[u] of 1
        >>> bool(np.array_equal(prob.labels[0], prob.labels[1][t]))
        True
        >>> sub = seq.graphs([0, 1, 2], keep=(3, 4), rng=0)
        >>> all(3 <= g.n_nodes <= 4 for g in sub.graphs)
        True
        """
        pos = self._positions(frames)
        check_bool(shuffle, "shuffle")
        lo, hi = self._keep_range(keep)
        rng = as_generator(rng)
        P = self.normalized_points([int(self.frames[p]) for p in pos], normalize=normalize)
        n = self.n_landmarks
        graphs, labels = [], []
        for Pg in P:
            size = n if keep is None else int(rng.integers(lo, hi + 1))
            kept = np.arange(n) if size == n else np.sort(rng.choice(n, size, replace=False))
            order = kept[rng.permutation(size)] if shuffle else kept
            graphs.append(Graph.from_points(Pg[order], edges="delaunay"))
            labels.append(order.astype(np.int64))
        return GraphCollectionProblem(graphs, labels, n, params=dict(
            name=self.name, frames=[int(self.frames[p]) for p in pos], keep=keep,
            shuffle=bool(shuffle), normalize=normalize))

    def _keep_range(self, keep) -> tuple[int, int]:
        n = self.n_landmarks
        if keep is None:
            return n, n
        if isinstance(keep, numbers.Integral) and not isinstance(keep, (bool, np.bool_)):
            k = check_int(keep, "keep", minimum=1, maximum=n)
            return k, k
        if (isinstance(keep, (tuple, list)) and len(keep) == 2
                and all(isinstance(v, numbers.Integral) and not isinstance(v, (bool, np.bool_))
                        for v in keep)):
            lo, hi = int(keep[0]), int(keep[1])
            if not 1 <= lo <= hi <= n:
                raise ValueError(f"`keep` must be a range (min, max) with 1 <= min <= max <= {n}, "
                                 f"got {tuple(keep)}")
            return lo, hi
        raise TypeError(f"`keep` must be None, an int or a (min, max) pair of ints, got "
                        f"{type(keep).__name__} {keep!r}")


def _read_label_file(path: Path) -> np.ndarray:
    try:
        text = path.read_text(encoding="utf-8-sig")          # a byte-order mark is allowed
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file (expected rows `x y`)") from None
    rows, blank = [], None
    for lineno, line in enumerate(text_lines(text), start=1):
        fields = line.split(None)
        if not fields:
            blank = blank or lineno
            continue
        if blank is not None:       # skipped, it shifted every later landmark's number
            raise ValueError(f"{path}, line {blank}: a blank line among the landmark rows "
                             "(blank lines may only follow the last row)")
        if len(fields) != 2:
            raise ValueError(f"{path}, line {lineno}: expected 2 columns `x y`, got "
                             f"{len(fields)}: {line.strip()!r:.60}")
        if not all(is_number(v) for v in fields):
            finite = all(_is_float(v) for v in fields)
            raise ValueError(f"{path}, line {lineno}: expected "
                             f"{'finite coordinates' if finite else 'two numbers `x y`'}, got "
                             f"{line.strip()!r:.60}")
        xy = [float(v) for v in fields]
        if not all(math.isfinite(v) for v in xy):        # 1e999
            raise ValueError(f"{path}, line {lineno}: expected finite coordinates, got "
                             f"{line.strip()!r:.60}")
        if max(abs(v) for v in xy) > _MAX_COORDINATE:    # 1e308: finite, distances are not
            raise ValueError(f"{path}, line {lineno}: expected coordinates of magnitude <= "
                             f"{_MAX_COORDINATE:g} (their distances must be finite), got "
                             f"{line.strip()!r:.60}")
        rows.append(xy)
    if not rows:
        raise ValueError(f"{path}: no landmark rows (expected rows `x y`)")
    return np.array(rows, dtype=float)


#: largest landmark coordinate read (the bound of :class:`~transync.graphs.Graph`'s points): a
#: frame at +-1e308 has finite coordinates but an infinite bounding box, and normalized to zero
_MAX_COORDINATE = 1e300


def _is_float(token: str) -> bool:
    """A number or a spelled-out NaN / infinity: a row of these gets "expected finite
    coordinates" rather than "expected two numbers"."""
    return is_number(token) or token.lower().lstrip("+-") in ("nan", "inf", "infinity")


def _label_files(folder: Path) -> tuple[str, dict[int, Path]]:
    found: dict[str, dict[int, Path]] = {}
    entries = sorted(folder.iterdir())      # listed once, read twice below
    for p in entries:
        if p.name.startswith(".") or not p.is_file():
            continue
        m = _LABEL_RE.match(p.name)
        if m is None:
            continue
        by_number = found.setdefault(m["name"], {})
        number = int(m["number"])
        if number >= 2**62:                                   # frames are stored as int64
            raise ValueError(f"{p}: frame number {m['number']:.30} out of range (at most "
                             f"{2**62 - 1})")
        if number in by_number:
            raise ValueError(f"{p}: duplicate frame number {number} (also {by_number[number]})")
        by_number[number] = p
    if not found:
        raise ValueError(f"{folder}: no label files (expected text files `<name><N>`, e.g. "
                         "`house1`, one `x y` row per landmark)")
    if len(found) > 1:
        names = ", ".join(repr(n) for n in sorted(found))
        raise ValueError(f"{folder}: label files of several sequences ({names}); expected one "
                         "name prefix")
    (name, by_number), = found.items()
    for p in entries:                       # `house6.txt` beside house1..5: not silently skipped
        stem = re.fullmatch(re.escape(name) + r"(\d+)\..*", p.name, re.ASCII)
        if stem and not p.name.startswith("."):
            raise ValueError(f"{p}: looks like frame {int(stem[1])} of {name!r} but label files "
                             f"are named `{name}<N>` without an extension; rename or remove it")
        frame = re.fullmatch(re.escape(name) + r"(\d+)", p.name, re.ASCII)
        if frame and not p.is_file():       # skipped above: the frame would vanish silently
            what = ("a folder" if p.is_dir() else "a broken link" if p.is_symlink()
                    and not p.exists() else "not a regular file")
            raise ValueError(f"{p}: label file of frame {int(frame[1]) - 1} of {name!r} is "
                             f"{what}; expected a text file of `x y` rows")
    if 0 in by_number:
        raise ValueError(f"{by_number[0]}: frame numbers in the CMU layout start at 1 (file "
                         "`<name><N>` is frame N-1), got 0")
    return name, by_number


def load_cmu_sequence(path=None) -> LandmarkSequence:
    """Load a landmark sequence in the CMU House / Hotel layout.

    Parameters
    ----------
    path : str or Path, optional
        Folder holding ``label/`` (text files ``<name><N>``, one ``x y`` row per landmark;
        file ``N`` is frame ``N - 1``) and optionally ``images/`` (``<name>.seq<k>.png``).
        Default: ``data_home() / "cmu-house"``. The name prefix is read from the files.

    Returns
    -------
    LandmarkSequence
        Frames in increasing frame number; ``image_paths`` / ``image_sizes`` when every frame
        has its PNG image, else ``None``.

    Raises
    ------
    FileNotFoundError
        No such folder, or no ``label/`` folder in it.
    ValueError
        No label files, label files of several name prefixes, a duplicate frame number, a file
        named like a frame but with an extension (``house6.txt``), a row without exactly two
        numbers (ASCII decimal literals), a NaN or infinite coordinate, files with different
        numbers of landmarks, an unreadable PNG header: the message names the file (and line).
    TypeError
        ``path`` not a ``str`` or ``os.PathLike``.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> tmp = tempfile.TemporaryDirectory()
    >>> (Path(tmp.name) / "label").mkdir()
    >>> for n in (1, 2, 3):
    ...     _ = (Path(tmp.name) / "label" / f"toy{n}").write_text("0 0\\n4 0\\n0 3\\n4 3\\n")
    >>> seq = load_cmu_sequence(tmp.name)
    >>> seq.name, seq.points.shape, seq.frames.tolist(), seq.image_paths
    ('toy', (3, 4, 2), [0, 1, 2], None)
    >>> tmp.cleanup()
    """
    if path is None:
        folder = data_home(subfolder="cmu-house")
    else:
        folder = check_path(path, "path")
        if not folder.is_dir():
            raise FileNotFoundError(f"{folder}: {no_folder(folder)} (expected a folder in the CMU "
                                    "layout, holding `label/`)")
    labels = folder / "label"
    if not labels.is_dir():
        raise FileNotFoundError(f"{folder}: no `label` folder (expected `label/<name><N>` text "
                                "files, one `x y` row per landmark)")
    name, by_number = _label_files(labels)
    numbers_ = sorted(by_number)
    points, first = [], None
    for number in numbers_:
        P = _read_label_file(by_number[number])
        if first is None:
            first = (by_number[number], P.shape[0])
        elif P.shape[0] != first[1]:
            raise ValueError(f"{by_number[number]}: {P.shape[0]} landmarks, but {first[0]} has "
                             f"{first[1]}; every frame must have the same landmarks")
        points.append(P)
    frames = np.array(numbers_, dtype=np.int64) - 1
    image_paths = image_sizes = None
    images = folder / "images"
    if images.is_dir():
        paths = [images / f"{name}.seq{k}.png" for k in frames.tolist()]
        if all(p.is_file() for p in paths):
            image_paths = tuple(paths)
            image_sizes = np.array([_png_size(p) for p in paths], dtype=np.int64)
    return LandmarkSequence(name, np.stack(points), frames, image_paths, image_sizes, folder)
