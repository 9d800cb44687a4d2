"""Graph-classification sets in the TU Dortmund text format (Morris et al., 2020).

A data set ``DS`` is a folder of comma-separated text files
(https://chrsmrrs.github.io/datasets/docs/format/)::

    DS_A.txt                 one edge ``i, j`` per line; 1-based node ids numbered across the whole
                             set; undirected graphs list both directions (one is enough here)
    DS_graph_indicator.txt   one line per node: the 1-based id of its graph (nondecreasing)
    DS_graph_labels.txt      one line per graph: its integer class label (e.g. -1/1 or 0..k)
    DS_node_labels.txt       optional, one integer per node (categorical)
    DS_edge_labels.txt       optional, one integer per line of DS_A.txt
    DS_node_attributes.txt   optional, one line of comma-separated floats per node

``DS_edge_attributes.txt`` and ``DS_graph_attributes.txt`` are not read (a :class:`Graph` holds
one scalar per edge, taken by the edge labels); :meth:`TUDataset.summary` lists them under
``ignored_files`` when present.

Reading is lenient about layout: fields may be separated by commas and/or blanks, blank lines
after the last data line are ignored, Windows line ends are accepted, and an undirected edge
given in one direction only is symmetrized. Self-loops (``i, i``) are dropped (a :class:`Graph`
has a zero diagonal) and counted in :meth:`TUDataset.summary`; the sets shipped in the data
home have none. Nodes that appear in no edge (isolated nodes, and one-node graphs) are kept.

Every error on malformed input names the file, and the line for a bad line (``FileNotFoundError``
for a missing folder or file): a line without the expected fields, a number that does not parse,
a blank line among the data lines (a lost value: skipping it shifted every later line, and
the error, if any, named another file), a node id out of range, an edge joining two graphs, a
decreasing or non-contiguous graph indicator, files whose line counts disagree, and an
undirected edge whose two directions carry different labels.
"""

from __future__ import annotations

import codecs
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._validation import check_bool, check_path, frozen_copy
from ..graphs import Graph
from ._home import data_home as _data_home
from ._home import no_folder
from ._text import NUMBER_BYTES, unix_newlines

__all__ = ["TUDataset", "list_tu", "load_tu"]

_REQUIRED = ("A", "graph_indicator", "graph_labels")
_OPTIONAL = ("node_labels", "edge_labels", "node_attributes")
_IGNORED = ("edge_attributes", "graph_attributes")
#: Most entries, summed over graphs, of the dense adjacency matrices load_tu builds (8 GiB of
#: float64; NCI1, the largest set of the thesis, needs 4.4 * 10**6)
_MAX_DENSE_ENTRIES = 2**30
_MAX_DIGITS = 15                  # integers up to 10**15 - 1 are parsed exactly (float64 sums)


def _layout(ds: str) -> str:
    return (f"expected the TU layout: {ds}_A.txt, {ds}_graph_indicator.txt and "
            f"{ds}_graph_labels.txt, optionally {ds}_node_labels.txt, {ds}_edge_labels.txt and "
            f"{ds}_node_attributes.txt")


# --------------------------------------------------------------------------- the data set


@dataclass(frozen=True, eq=False)
class TUDataset:
    """Graphs of a TU data set with their class labels.

    Attributes
    ----------
    name : str
        The data set's prefix ``DS`` (``"MUTAG"``).
    graphs : tuple of Graph
        One per graph, in file order: ``adjacency`` float64 0/1 symmetric (``n, n``),
        ``node_labels`` int64 ``(n,)`` or None, ``node_features`` float64 ``(n, f)`` (the node
        attributes) or None, ``edge_features`` float64 ``(n, n)`` holding each edge's label on the
        edge and 0 elsewhere, or None (TU edge labels are often 0-based: a label 0 reads like "no
        edge" there, so find edges with ``adjacency != 0`` / ``Graph.mask``, never with
        ``edge_features != 0``, as :class:`~transync.graphs.Graph` prescribes). Node ``u`` of
        graph ``g`` is the ``u``-th node of ``g`` in
        ``DS_graph_indicator.txt``.
    y : ndarray of shape (n_graphs,), int64
        The class labels as written in ``DS_graph_labels.txt`` (not re-encoded).
    path : Path
        The folder read.
    has_node_labels, has_edge_labels, has_node_attributes : bool
        Whether the optional files were present.
    self_loops : ndarray of shape (n_graphs,), int64
        Self-loop lines (``i, i``) of ``DS_A.txt`` dropped, per graph.
    ignored_files : tuple of str
        Files of the format present but not read (``DS_edge_attributes.txt``,
        ``DS_graph_attributes.txt``).

    Examples
    --------
    >>> import numpy as np
    >>> from transync.graphs import Graph
    >>> ds = TUDataset("toy", (Graph(np.zeros((1, 1))), Graph(np.ones((2, 2)) - np.eye(2))),
    ...                y=[0, 1], path=".")
    >>> len(ds), ds.sizes.tolist(), ds.subset([1]).y.tolist()
    (2, [1, 2], [1])
    """

    name: str
    graphs: tuple
    y: np.ndarray
    path: Path
    has_node_labels: bool = False
    has_edge_labels: bool = False
    has_node_attributes: bool = False
    self_loops: np.ndarray | None = None
    ignored_files: tuple = ()
    _sizes: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if not isinstance(self.name, str):
            raise TypeError(f"`name` must be a str, got {type(self.name).__name__}")
        if isinstance(self.graphs, Graph) or not isinstance(self.graphs, (list, tuple)):
            raise TypeError(f"`graphs` must be a list or tuple of transync.graphs.Graph, got "
                            f"{type(self.graphs).__name__}")
        graphs = tuple(self.graphs)
        for k, g in enumerate(graphs):
            if not isinstance(g, Graph):
                raise TypeError(f"`graphs[{k}]` must be a transync.graphs.Graph, got "
                                f"{type(g).__name__}")
        if not graphs:
            raise ValueError("`graphs` must hold at least one graph, got none")
        y = np.asarray(self.y)
        if y.dtype.kind not in "iu" or y.shape != (len(graphs),):
            raise ValueError(f"`y` must be an int array of shape ({len(graphs)},), got "
                             f"{y.dtype} array of shape {y.shape}")
        if y.dtype.kind == "u" and y.size and int(y.max()) > np.iinfo(np.int64).max:
            raise ValueError(f"`y` must fit in int64, got {int(y.max())}")     # would wrap
        for flag, attr in (("has_node_labels", "node_labels"),
                           ("has_node_attributes", "node_features")):
            k = next((i for i, g in enumerate(graphs) if getattr(g, attr) is None), None)
            if check_bool(getattr(self, flag), flag) and k is not None:
                raise ValueError(f"`{flag}` is True but `graphs[{k}]` has no {attr}")
        check_bool(self.has_edge_labels, "has_edge_labels")
        loops = np.zeros(len(graphs), np.int64) if self.self_loops is None else self.self_loops
        loops = np.asarray(loops)
        if loops.shape != (len(graphs),) or loops.dtype.kind not in "iu":
            raise ValueError(f"`self_loops` must be an int array of shape ({len(graphs)},), got "
                             f"{loops.dtype} array of shape {loops.shape}")
        object.__setattr__(self, "graphs", graphs)
        object.__setattr__(self, "y", frozen_copy(y.astype(np.int64)))
        object.__setattr__(self, "path", check_path(self.path, "path"))
        object.__setattr__(self, "self_loops", frozen_copy(loops.astype(np.int64)))
        object.__setattr__(self, "ignored_files", tuple(self.ignored_files))
        object.__setattr__(self, "_sizes",
                           frozen_copy(np.array([g.n_nodes for g in graphs], dtype=np.int64)))

    def __len__(self) -> int:
        return len(self.graphs)

    def __repr__(self) -> str:
        extras = [k for k in ("node_labels", "edge_labels", "node_attributes")
                  if getattr(self, f"has_{k}")]
        return (f"TUDataset(name={self.name!r}, n_graphs={len(self)}, "
                f"n_classes={np.unique(self.y).size}, "
                f"with={'+'.join(extras) or 'structure only'}, path={str(self.path)!r})")

    @property
    def sizes(self) -> np.ndarray:
        """Number of nodes of each graph, int64 ``(n_graphs,)`` (read-only)."""
        return self._sizes

    def subset(self, indices) -> TUDataset:
        """The graphs at ``indices`` (ints in ``range(len(self))`` or a boolean mask), in order.

        Raises
        ------
        TypeError
            ``indices`` are not integers or booleans.
        ValueError
            An index out of range, a mask of the wrong length, or not one-dimensional.
        """
        idx = np.asarray(indices)
        if isinstance(indices, (str, bytes)) or idx.dtype.kind not in "iub":
            if not (idx.size == 0 and idx.dtype.kind == "f"):        # [] -> float64 array
                raise TypeError("`indices` must be integer indices or a boolean mask, got "
                                f"{idx.dtype} array of shape {idx.shape}")
            idx = idx.astype(np.int64)
        if idx.ndim != 1:
            raise ValueError(f"`indices` must be one-dimensional, got shape {idx.shape}")
        if idx.dtype.kind == "b":
            if idx.shape != (len(self),):
                raise ValueError(f"`indices` as a boolean mask must have shape ({len(self)},), "
                                 f"got {idx.shape}")
            idx = np.flatnonzero(idx)
        bad = np.flatnonzero((idx < 0) | (idx >= len(self)))
        if bad.size:
            raise ValueError(f"`indices` must lie in range({len(self)}), got {int(idx[bad[0]])} "
                             f"at position {int(bad[0])}")
        if idx.size == 0:
            raise ValueError("`indices` must select at least one graph, got none")
        idx = idx.astype(np.int64)
        return TUDataset(self.name, tuple(self.graphs[i] for i in idx.tolist()), self.y[idx],
                         self.path, self.has_node_labels, self.has_edge_labels,
                         self.has_node_attributes, self.self_loops[idx], self.ignored_files)

    def summary(self) -> dict:
        """Counts describing the set (plain Python numbers; compare with the data set's manifest).

        Returns
        -------
        dict
            ``name``, ``n_graphs``, ``n_classes``, ``class_counts`` ({label: count}),
            ``mean_nodes``, ``min_nodes``, ``max_nodes``, ``mean_edges`` (undirected edges per
            graph), ``n_node_labels`` (distinct node labels, or None), ``has_node_labels``,
            ``has_edge_labels``, ``has_node_attributes``, ``isolated_nodes`` (nodes in no edge,
            one-node graphs included), ``dropped_self_loops`` (``i, i`` lines of ``DS_A.txt``
            not kept), ``ignored_files``.
        """
        classes, counts = np.unique(self.y, return_counts=True)
        edges = np.array([g.n_edges for g in self.graphs])
        isolated = sum(int(np.count_nonzero(~g.mask.any(axis=1))) for g in self.graphs)
        n_labels = None
        if self.has_node_labels:
            n_labels = int(np.unique(np.concatenate([g.node_labels for g in self.graphs])).size)
        return dict(
            name=self.name, n_graphs=len(self), n_classes=int(classes.size),
            class_counts={int(c): int(k) for c, k in zip(classes, counts)},
            mean_nodes=float(self.sizes.mean()), min_nodes=int(self.sizes.min()),
            max_nodes=int(self.sizes.max()), mean_edges=float(edges.mean()),
            n_node_labels=n_labels, has_node_labels=bool(self.has_node_labels),
            has_edge_labels=bool(self.has_edge_labels),
            has_node_attributes=bool(self.has_node_attributes), isolated_nodes=isolated,
            dropped_self_loops=int(self.self_loops.sum()), ignored_files=list(self.ignored_files))


# --------------------------------------------------------------------------- text parsing


def _line_text(data: bytes, lineno: int) -> str:
    line = unix_newlines(data).split(b"\n")[lineno - 1]
    return line.decode("utf-8", "replace").strip()


def _bad_line(path: Path, data: bytes, lineno: int, what: str) -> ValueError:
    return ValueError(f"{path}, line {lineno}: {what}, got {_line_text(data, lineno)!r:.60}")


def _bad_byte(path: Path, data: bytes, b: np.ndarray, at: int, what: str) -> ValueError:
    """:func:`_bad_line` for the line holding byte ``at`` of ``b`` (the file's bytes)."""
    return _bad_line(path, data, int(np.count_nonzero(b[:at] == 10)) + 1, what)


def _read_table(path: Path, *, columns: int | None, kind: str, what: str):
    """Parse a TU text file into ``(values (rows, k), line numbers (rows,))``, vectorized.

    Fields are separated by commas and/or blanks; blank lines after the last data line are
    ignored, one before it is an error (the line of a lost value). ``columns=None``
    takes the field count of the first data line for every line. ``kind`` is ``"int"`` or
    ``"float"`` (finite). ``what`` names the expected content in messages.
    """
    data = path.read_bytes()
    if data.startswith(codecs.BOM_UTF8):
        data = b" " * len(codecs.BOM_UTF8) + data[len(codecs.BOM_UTF8):]
    data = unix_newlines(data)              # lines end at \n, \r\n or \r, as in text_lines
    b = np.frombuffer(data, dtype=np.uint8)
    newline = b == 10
    comma = b == 44
    blank = (b == 32) | (b == 9) | (b == 11) | (b == 12)
    tok = ~(newline | comma | blank)
    index = np.int32 if b.size < 2**31 - 1 else np.int64      # halves the scan's memory
    line = np.cumsum(newline, dtype=index)    # 0-based line of each byte (a newline ends it)
    n_lines = int(line[-1]) + 1 if b.size else 1
    start = tok.copy()
    start[1:] &= ~tok[:-1]
    # every comma sits between two fields of its line
    dense = ~blank
    d, dline = b[dense], line[dense] - newline[dense]
    dc = d == 44
    if dc.any():
        dt = ~(dc | (d == 10))
        prev_ok = np.zeros_like(dc)
        prev_ok[1:] = dt[:-1] & (dline[1:] == dline[:-1])
        next_ok = np.zeros_like(dc)
        next_ok[:-1] = dt[1:] & (dline[:-1] == dline[1:])
        bad = np.flatnonzero(dc & ~(prev_ok & next_ok))
        if bad.size:
            raise _bad_line(path, data, int(dline[bad[0]]) + 1, f"expected {what} (empty field)")
    token_line = line[start]
    per_line = np.bincount(token_line, minlength=n_lines)
    rows = np.flatnonzero(per_line)
    if rows.size == 0:
        return np.zeros((0, columns or 0), np.int64 if kind == "int" else float), rows
    if rows[-1] + 1 > rows.size:            # a blank line before the last data line
        gap = int(np.flatnonzero(per_line[:rows[-1]] == 0)[0]) + 1
        raise _bad_line(path, data, gap, f"expected {what}, found a blank line among the data "
                                         "lines (blank lines may only follow the last one)")
    if columns is None:             # the common field count (a bad first line is the one blamed)
        counts, freq = np.unique(per_line[rows], return_counts=True)
        k = int(counts[np.argmax(freq)])
    else:
        k = columns
    wrong = np.flatnonzero(per_line[rows] != k)
    if wrong.size:
        lineno = int(rows[wrong[0]]) + 1
        got = int(per_line[rows[wrong[0]]])
        raise _bad_line(path, data, lineno, f"expected {what} ({k} field{'s' * (k > 1)}), "
                                            f"found {got}")
    linenos = rows + 1
    if kind == "int":
        values = _parse_ints(path, data, b, tok, start, token_line, what)
    else:
        values = _parse_floats(path, data, b, tok, token_line, what)
    return values.reshape(rows.size, k), linenos


def _parse_ints(path, data, b, tok, start, token_line, what) -> np.ndarray:
    digit = (b >= 48) & (b <= 57)
    sign = (b == 43) | (b == 45)
    next_digit = np.zeros_like(digit)
    next_digit[:-1] = digit[1:]
    bad = np.flatnonzero(tok & ~digit & ~(sign & start & next_digit))
    if bad.size:
        raise _bad_byte(path, data, b, int(bad[0]), f"expected {what} (integers)")
    token_id = np.cumsum(start, dtype=token_line.dtype) - 1
    ends = np.flatnonzero(tok & ~np.append(tok[1:], False))
    pos = np.flatnonzero(digit)
    tid = token_id[pos]
    power = ends[tid] - pos
    # digits that count: from the first non-zero digit of a token (`0000000000000001` is 1)
    significant = (b[pos] != 48) | (power == 0)
    if power.size and np.any(significant & (power >= _MAX_DIGITS)):
        t = int(tid[np.argmax(significant & (power >= _MAX_DIGITS))])
        raise _bad_line(path, data, int(token_line[t]) + 1,
                        f"expected {what} (integers of at most {_MAX_DIGITS} digits)")
    # leading zeros weigh 0 whatever their place (10.0 ** 309 is inf, and 0 * inf is NaN)
    weight = 10.0 ** np.where(power < _MAX_DIGITS, power, 0)
    values = np.bincount(tid, weights=(b[pos] - 48) * weight, minlength=token_line.size)
    values = np.rint(values).astype(np.int64)
    values[b[np.flatnonzero(start)] == 45] *= -1
    return values


_NUMBER_BYTE = np.zeros(256, bool)
_NUMBER_BYTE[list(NUMBER_BYTES)] = True


def _parse_floats(path, data, b, tok, token_line, what) -> np.ndarray:
    # ASCII decimal literals only: numpy and Python would also read `1_5` as 15, drop trailing
    # NUL bytes (`2\x00\x00` as 2.0) and take full-width digits
    bad = np.flatnonzero(tok & ~_NUMBER_BYTE[b])
    if bad.size:
        raise _bad_byte(path, data, b, int(bad[0]), f"expected {what} (finite numbers)")
    tokens = data.replace(b",", b" ").split()     # the same fields as the byte scan above
    try:
        values = np.array(tokens).astype(np.float64)
        bad = np.flatnonzero(~np.isfinite(values))
    except (ValueError, OverflowError):
        bad = []
        for t, s in enumerate(tokens):
            try:
                float(s)
            except ValueError:
                bad = [t]
                break
        else:                                     # numpy refused what Python accepts
            values = np.array([float(s) for s in tokens])
            bad = np.flatnonzero(~np.isfinite(values))
    if len(bad):
        raise _bad_line(path, data, int(token_line[bad[0]]) + 1, f"expected {what} (finite "
                                                                 "numbers)")
    return values


# --------------------------------------------------------------------------- locating sets


def _tu_root(data_home, *, required: bool) -> Path | None:
    if data_home is None:
        return _data_home(required=required, subfolder="tu")
    home = check_path(data_home, "data_home")
    if not home.is_dir():
        raise FileNotFoundError(f"{home}: {no_folder(home)} (`data_home` must be the folder "
                                "holding `tu/`)")
    root = home / "tu"
    if not root.is_dir():
        if required:
            raise FileNotFoundError(f"{root}: {no_folder(root)} (expected TU data sets in "
                                    "`<data_home>/tu/<NAME>/`)")
        return None
    return root


def _a_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.glob("?*_A.txt") if p.is_file())


def list_tu(data_home=None) -> list[str]:
    """Names of the TU data sets in ``<data_home>/tu``: sub-folders holding a ``*_A.txt`` file.

    Parameters
    ----------
    data_home : str or Path, optional
        The data home (the folder holding ``tu/``); default :func:`~transync.datasets.data_home`.

    Returns
    -------
    list of str
        Sorted folder names (empty when there is no ``tu`` folder).

    Raises
    ------
    FileNotFoundError
        ``data_home`` is given and is not a folder.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> tmp = tempfile.TemporaryDirectory()
    >>> (Path(tmp.name) / "tu" / "TOY").mkdir(parents=True)
    >>> _ = (Path(tmp.name) / "tu" / "TOY" / "TOY_A.txt").write_text("1, 2\\n")
    >>> (Path(tmp.name) / "tu" / "empty").mkdir()
    >>> list_tu(tmp.name)
    ['TOY']
    >>> tmp.cleanup()
    """
    root = _tu_root(data_home, required=False)
    return [] if root is None else _names(root)


def _names(root: Path) -> list[str]:
    return sorted(p.name for p in root.iterdir()
                  if p.is_dir() and not p.name.startswith(".") and _a_files(p))


def _resolve(path_or_name, data_home) -> Path:
    if isinstance(path_or_name, os.PathLike):
        spec, is_path = os.fspath(path_or_name), True
    elif isinstance(path_or_name, str):
        spec = path_or_name
        seps = tuple(s for s in (os.sep, os.altsep) if s)
        is_path = any(s in spec for s in seps) or spec.startswith((".", "~"))
    else:
        raise TypeError(f"`path_or_name` must be a folder path or a data set name (str), got "
                        f"{type(path_or_name).__name__}")
    if not spec:
        raise ValueError("`path_or_name` must be a folder path or a data set name, got ''")
    if is_path:
        folder = check_path(spec, "path_or_name")
        if not folder.is_dir():
            raise FileNotFoundError(f"{folder}: {no_folder(folder)} ({_layout('DS')})")
        return folder
    root = _tu_root(data_home, required=True)
    names = _names(root)
    if spec not in names:
        found = ", ".join(names) or "none"
        try:
            here = Path(spec).is_dir()
        except (OSError, ValueError):       # a name too long for a file, a NUL byte
            here = False
        local = f"; a folder here is given as ./{spec}" if here else ""
        raise FileNotFoundError(f"{root / spec}: no TU data set {spec!r} (names are "
                                f"case-sensitive; data sets in {root}: {found}{local})")
    return root / spec


# --------------------------------------------------------------------------- loading stages


def _locate(path_or_name, data_home) -> tuple[Path, str, dict]:
    """Find the set's folder, its prefix ``DS`` and the path of every file of the format.

    Returns ``(folder, DS, {kind: folder / "DS_<kind>.txt"})`` for every kind of
    ``_REQUIRED + _OPTIONAL + _IGNORED``; the required files exist, the others may not.
    """
    folder = _resolve(path_or_name, data_home)
    a_files = _a_files(folder)
    if not a_files:
        raise FileNotFoundError(f"{folder}: no `<DS>_A.txt` file ({_layout('DS')})")
    if len(a_files) > 1:
        names = ", ".join(p.name for p in a_files)
        raise ValueError(f"{folder}: several `*_A.txt` files ({names}); expected one TU data set "
                         "per folder")
    ds = a_files[0].name[: -len("_A.txt")]
    files = {k: folder / f"{ds}_{k}.txt" for k in _REQUIRED + _OPTIONAL + _IGNORED}
    for k in _REQUIRED:
        if not files[k].is_file():
            what = ("is a folder, not a file" if files[k].is_dir() else
                    "is a broken link" if files[k].is_symlink() else "missing")
            if what == "missing":
                raise FileNotFoundError(f"{folder}: missing {files[k].name} ({_layout(ds)})")
            raise ValueError(f"{files[k]}: {what} ({_layout(ds)})")
    return folder, ds, files


def _read_column(path: Path, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Parse a file of one integer per line into ``(values (rows,), line numbers (rows,))``."""
    values, lines = _read_table(path, columns=1, kind="int", what=what)
    return values[:, 0], lines


def _check_indicator(indicator: np.ndarray, ind_lines: np.ndarray, n_graphs: int,
                     files: dict) -> np.ndarray:
    """Check the graph indicator against the graph labels; return the node count of each graph.

    The indicator must be nonempty and nondecreasing, and name every graph id ``1..n_graphs``
    (``n_graphs`` graph labels, at least one) for at least one node.
    """
    f_ind, f_lab = files["graph_indicator"], files["graph_labels"]
    if indicator.size == 0:
        raise ValueError(f"{f_ind}: no nodes (expected one graph id per node)")
    if n_graphs == 0:
        raise ValueError(f"{f_lab}: no graphs (expected one class label per graph)")
    down = np.flatnonzero(np.diff(indicator) < 0)
    if down.size:
        raise _bad_line(f_ind, f_ind.read_bytes(), int(ind_lines[down[0] + 1]),
                        f"expected nondecreasing graph ids (previous line: "
                        f"{int(indicator[down[0]])})")
    out = np.flatnonzero((indicator < 1) | (indicator > n_graphs))
    if out.size:
        raise ValueError(f"{f_ind}, line {int(ind_lines[out[0]])}: graph id "
                         f"{int(indicator[out[0]])} out of range 1..{n_graphs} ({f_lab} has "
                         f"{n_graphs} graph labels)")
    counts = np.bincount(indicator - 1, minlength=n_graphs)
    empty = np.flatnonzero(counts == 0)
    if empty.size:
        raise ValueError(f"{f_ind}: graph {int(empty[0]) + 1} has no nodes ({f_lab} has "
                         f"{n_graphs} graph labels; graph ids must be 1..{n_graphs}, each "
                         "listed for at least one node)")
    entries = int(np.sum(counts.astype(np.float64) ** 2))
    if entries > _MAX_DENSE_ENTRIES:     # a 2 MB indicator asked for 7 TiB (one 10**6-node graph)
        big = int(np.argmax(counts))
        raise ValueError(f"{f_ind}: the graphs' dense adjacency matrices would hold "
                         f"{entries:.3g} entries ({8 * entries / 2**30:.3g} GiB; the largest, "
                         f"graph {big + 1}, has {int(counts[big])} nodes), more than the "
                         f"{_MAX_DENSE_ENTRIES:.3g} that load_tu builds")
    return counts


def _check_edges(edges: np.ndarray, a_lines: np.ndarray, indicator: np.ndarray,
                 files: dict) -> np.ndarray:
    """Check that every edge of ``DS_A.txt`` joins two nodes of one graph; return them 0-based."""
    f_a, f_ind = files["A"], files["graph_indicator"]
    n = indicator.size
    bad = np.flatnonzero(((edges < 1) | (edges > n)).any(axis=1))
    if bad.size:
        i, j = edges[bad[0]].tolist()
        raise ValueError(f"{f_a}, line {int(a_lines[bad[0]])}: edge {i}, {j} names a node out "
                         f"of range 1..{n} ({f_ind} lists {n} nodes)")
    edges = edges - 1
    gi, gj = indicator[edges[:, 0]], indicator[edges[:, 1]]
    bad = np.flatnonzero(gi != gj)
    if bad.size:
        i, j = (edges[bad[0]] + 1).tolist()
        raise ValueError(f"{f_a}, line {int(a_lines[bad[0]])}: edge {i}, {j} joins graph "
                         f"{int(gi[bad[0]])} and graph {int(gj[bad[0]])} (per {f_ind}); an edge "
                         "must stay within one graph")
    return edges


def _read_optional(path: Path, columns, kind: str, what: str, rows: int, against: Path):
    """Parse an optional file (``(None, None)`` when absent) holding one line per ``against`` row.

    Returns ``(values (rows, k), line numbers (rows,))`` as :func:`_read_table`.
    """
    if not path.is_file():
        if path.exists() or path.is_symlink():       # a folder, or a link to nothing
            what = ("a folder" if path.is_dir() else "a broken link" if not path.exists()
                    else "not a regular file")
            raise ValueError(f"{path}: not a readable file ({what}); remove it or put the file "
                             "there")
        return None, None
    values, lines = _read_table(path, columns=columns, kind=kind, what=what)
    if values.shape[0] != rows:
        raise ValueError(f"{path} has {values.shape[0]} data lines but {against} has {rows}; "
                         f"expected one line per line of {against.name}")
    return values, lines


def _read_extras(files: dict, n: int, m: int) -> tuple:
    """Read the optional node labels, node attributes and edge labels (``n`` nodes, ``m`` edges).

    Returns ``(node_labels (n,), attributes (n, f), edge_labels (m,), edge label line numbers
    (m,))``, each None when its file is absent.
    """
    f_ind, f_a = files["graph_indicator"], files["A"]
    node_labels, _ = _read_optional(files["node_labels"], 1, "int", "one integer node label", n,
                                    f_ind)
    attributes, _ = _read_optional(files["node_attributes"], None, "float",
                                   "comma-separated node attributes", n, f_ind)
    edge_labels, el_lines = _read_optional(files["edge_labels"], 1, "int",
                                           "one integer edge label", m, f_a)
    return (None if node_labels is None else node_labels[:, 0], attributes,
            None if edge_labels is None else edge_labels[:, 0], el_lines)


def _undirected_edges(edges: np.ndarray, indicator: np.ndarray, n_graphs: int, edge_labels,
                      el_lines, f_el: Path) -> tuple:
    """Fold the edge list into undirected edges: self-loops dropped, each edge kept once.

    ``edges`` are 0-based ``(m, 2)`` node ids; an edge listed several times (e.g. in both
    directions) is kept once, and its labels (``edge_labels`` ``(m,)`` read from ``f_el`` at
    lines ``el_lines``, or None) must agree.

    Returns
    -------
    lo, hi : ndarray of shape (k,), int64
        The endpoints of each undirected edge, ``lo < hi``, sorted by ``(lo, hi)``.
    labels : ndarray of shape (k,), int64, or None
        The label of each edge, None without edge labels.
    self_loops : ndarray of shape (n_graphs,), int64
        Self-loops dropped, per graph.
    """
    n = indicator.size
    loop = edges[:, 0] == edges[:, 1]
    self_loops = np.bincount(indicator[edges[loop, 0]] - 1, minlength=n_graphs)
    keep = ~loop
    lo = np.minimum(edges[keep, 0], edges[keep, 1])
    hi = np.maximum(edges[keep, 0], edges[keep, 1])
    key = lo * n + hi
    order = np.argsort(key, kind="stable")
    key = key[order]
    first = np.ones(key.size, bool)
    first[1:] = key[1:] != key[:-1]
    lab = None
    if edge_labels is not None:
        lab = edge_labels[keep][order]
        clash = np.flatnonzero(~first & (lab != np.roll(lab, 1)))
        if clash.size:
            c = int(clash[0])
            rows = el_lines[keep][order]
            raise ValueError(f"{f_el}, lines {int(rows[c - 1])} and "
                             f"{int(rows[c])}: edge {int(lo[order][c]) + 1}, "
                             f"{int(hi[order][c]) + 1} has labels {int(lab[c - 1])} and "
                             f"{int(lab[c])}; an undirected edge listed twice (e.g. in both "
                             "directions) must carry one label")
        lab = lab[first]
    return lo[order][first], hi[order][first], lab, self_loops


def _build_graphs(indicator: np.ndarray, counts: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  labels, node_labels, attributes) -> tuple:
    """Build one :class:`Graph` per graph from the undirected edges of :func:`_undirected_edges`.

    Both directions of every edge are set by one scatter into a flat buffer shared by all the
    adjacencies (and one shared by the edge-label matrices); nodes in no edge are kept.
    ``node_labels`` ``(n,)`` and ``attributes`` ``(n, f)`` (or None) are split by graph.
    """
    # one flat buffer holds every adjacency; graph g's nodes are start[g] .. start[g] + n_g - 1
    n_graphs = counts.size
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    offset = np.concatenate([[0], np.cumsum(counts * counts)])
    g = indicator[lo] - 1
    li, lj, ng = lo - start[g], hi - start[g], counts[g]
    flat = np.concatenate([offset[g] + li * ng + lj, offset[g] + lj * ng + li])
    buf = np.zeros(int(offset[-1]))
    buf[flat] = 1.0
    ebuf = None
    if labels is not None:
        ebuf = np.zeros(int(offset[-1]))
        ebuf[flat] = np.concatenate([labels, labels])
    bounds = np.cumsum(counts)[:-1]
    labels_g = np.split(node_labels, bounds) if node_labels is not None else [None] * n_graphs
    attrs_g = np.split(attributes, bounds) if attributes is not None else [None] * n_graphs
    graphs = []
    for k, size in enumerate(counts.tolist()):
        sl = slice(int(offset[k]), int(offset[k + 1]))
        graphs.append(Graph(buf[sl].reshape(size, size), node_labels=labels_g[k],
                            node_features=attrs_g[k],
                            edge_features=None if ebuf is None else ebuf[sl].reshape(size, size)))
    return tuple(graphs)


# --------------------------------------------------------------------------- loading


def load_tu(path_or_name, *, data_home=None) -> TUDataset:
    """Load a graph-classification set in the TU Dortmund text format.

    Parameters
    ----------
    path_or_name : str or Path
        A folder holding one set (``DS`` is the prefix of its only ``*_A.txt`` file), or the bare
        name of a set in ``<data_home>/tu/<name>`` (case-sensitive, as on disk). A ``Path``, or a
        string with a path separator or starting with ``.``/``~``, is a folder; any other string
        is a name (write ``./MUTAG`` for a folder in the working directory).
    data_home : str or Path, optional
        The data home holding ``tu/``; default :func:`~transync.datasets.data_home`.

    Returns
    -------
    TUDataset
        The graphs in file order with their class labels; node labels, edge labels and node
        attributes when their files are present (else ``None`` in every graph).

    Raises
    ------
    FileNotFoundError
        No such folder or data set, no ``*_A.txt`` file, or a missing required file (the
        message names the folder, the file and the expected layout).
    ValueError
        Several ``*_A.txt`` files in the folder; a malformed line (the message names the file,
        the line and its text); a node id out of range or an edge joining two graphs (names
        ``DS_A.txt``'s line and the graph indicator); a decreasing graph indicator, graph ids
        not ``1..n_graphs`` each with a node, files whose line counts disagree (names both files
        and the counts); the two directions of an edge with different labels.
    TypeError
        ``path_or_name`` is neither a str nor a path.

    Notes
    -----
    Parsing is vectorized (a few NumPy passes over the bytes of each file, no Python loop over
    lines or edges; the first bad line is located only on failure); every adjacency is filled
    by one scatter into a shared buffer, and one :class:`Graph` is built per graph.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> tmp = tempfile.TemporaryDirectory()
    >>> d = Path(tmp.name) / "TOY"
    >>> d.mkdir()
    >>> _ = (d / "TOY_A.txt").write_text("1, 2\\n2, 3\\n")        # one direction is enough
    >>> _ = (d / "TOY_graph_indicator.txt").write_text("1\\n1\\n1\\n2\\n")
    >>> _ = (d / "TOY_graph_labels.txt").write_text("1\\n-1\\n")
    >>> ds = load_tu(d)
    >>> ds.name, len(ds), ds.sizes.tolist(), ds.y.tolist()
    ('TOY', 2, [3, 1], [1, -1])
    >>> ds.graphs[0].adjacency.tolist()
    [[0.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 0.0]]
    >>> ds.graphs[1].node_labels is None, ds.summary()["isolated_nodes"]
    (True, 1)
    >>> tmp.cleanup()
    """
    folder, ds, files = _locate(path_or_name, data_home)
    indicator, ind_lines = _read_column(files["graph_indicator"], "one graph id")
    y, _ = _read_column(files["graph_labels"], "one integer class label")
    counts = _check_indicator(indicator, ind_lines, y.size, files)
    edges, a_lines = _read_table(files["A"], columns=2, kind="int", what="one edge `i, j`")
    edges = _check_edges(edges, a_lines, indicator, files)
    node_labels, attributes, edge_labels, el_lines = _read_extras(files, indicator.size,
                                                                  edges.shape[0])
    lo, hi, labels, self_loops = _undirected_edges(edges, indicator, counts.size, edge_labels,
                                                   el_lines, files["edge_labels"])
    graphs = _build_graphs(indicator, counts, lo, hi, labels, node_labels, attributes)
    ignored = tuple(files[k].name for k in _IGNORED if files[k].is_file())
    return TUDataset(ds, graphs, y, folder, node_labels is not None, edge_labels is not None,
                     attributes is not None, self_loops, ignored)
