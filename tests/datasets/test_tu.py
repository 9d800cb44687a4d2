"""TU Dortmund text format: fixtures written by the tests (every optional file, isolated nodes,
one-direction edge lists, every error case, fuzzed lines) and the real sets (issue 12 item 1)."""

import pickle
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from transync.datasets import TUDataset, data_home, list_tu, load_tu
from transync.graphs import Graph

# three graphs: a triangle plus an isolated node; a one-node graph; a path listed one way only
NODES = [1, 1, 1, 1, 2, 3, 3, 3]
A_LINES = ["1, 2", "2, 1", "2, 3", "3, 2", "1, 3", "3, 1", "6, 7", "8, 7"]
EDGE_LABELS = [0, 0, 1, 1, 2, 2, 3, 1]
NODE_LABELS = [5, 6, 5, 7, 0, 1, 1, 2]
ATTRS = [[0.5, -1.0], [1.5, 2.0], [0.0, 0.0], [3.25, 1e-3], [7.0, 8.0], [-2.0, 4.0], [1.0, 1.0],
         [9.5, -9.5]]
GRAPH_LABELS = [-1, 1, 1]


def _lines(values):
    return "".join(f"{v}\n" for v in values)


def _write(folder, name="TOY", *, skip=(), **override):
    """Write a valid TU fixture into ``folder``; ``override[kind]`` replaces a file's text."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    files = dict(
        A=_lines(A_LINES),
        graph_indicator=_lines(NODES),
        graph_labels=_lines(GRAPH_LABELS),
        node_labels=_lines(NODE_LABELS),
        edge_labels=_lines(EDGE_LABELS),
        node_attributes=_lines(", ".join(f"{x:.6f}" for x in row) for row in ATTRS),
    )
    files.update(override)
    for kind, text in files.items():
        if kind not in skip:
            (folder / f"{name}_{kind}.txt").write_text(text)
    return folder


def _err(exc, folder, message):
    with pytest.raises(exc, match="^" + re.escape(message) + "$"):
        load_tu(folder)


# --------------------------------------------------------------------------- reading


def test_reads_every_file(tmp_path):
    ds = load_tu(_write(tmp_path / "TOY"))
    assert isinstance(ds, TUDataset) and ds.name == "TOY" and ds.path == tmp_path / "TOY"
    assert len(ds) == 3 and ds.sizes.tolist() == [4, 1, 3]
    assert ds.y.tolist() == [-1, 1, 1] and ds.y.dtype == np.int64
    assert ds.has_node_labels and ds.has_edge_labels and ds.has_node_attributes
    g1, g2, g3 = ds.graphs
    tri = np.zeros((4, 4))
    tri[:3, :3] = 1 - np.eye(3)
    np.testing.assert_array_equal(g1.adjacency, tri)
    assert g1.adjacency.dtype == np.float64
    np.testing.assert_array_equal(g2.adjacency, np.zeros((1, 1)))
    np.testing.assert_array_equal(g3.adjacency, [[0, 1, 0], [1, 0, 1], [0, 1, 0]])
    assert [g.node_labels.tolist() for g in ds.graphs] == [[5, 6, 5, 7], [0], [1, 1, 2]]
    assert g1.node_labels.dtype == np.int64
    np.testing.assert_allclose(np.concatenate([g.node_features for g in ds.graphs]), ATTRS,
                               rtol=0, atol=1e-6)
    E1 = np.zeros((4, 4))
    E1[0, 1] = E1[1, 0] = 0
    E1[1, 2] = E1[2, 1] = 1
    E1[0, 2] = E1[2, 0] = 2
    np.testing.assert_array_equal(g1.edge_features, E1)
    np.testing.assert_array_equal(g3.edge_features, [[0, 3, 0], [3, 0, 1], [0, 1, 0]])
    np.testing.assert_array_equal(g2.edge_features, [[0.0]])
    s = ds.summary()
    assert s == dict(name="TOY", n_graphs=3, n_classes=2, class_counts={-1: 1, 1: 2},
                     mean_nodes=8 / 3, min_nodes=1, max_nodes=4, mean_edges=5 / 3,
                     n_node_labels=6, has_node_labels=True, has_edge_labels=True,
                     has_node_attributes=True, isolated_nodes=2, dropped_self_loops=0,
                     ignored_files=[])


def test_optional_files_absent(tmp_path):
    ds = load_tu(_write(tmp_path / "T", skip=("node_labels", "edge_labels", "node_attributes")))
    assert not (ds.has_node_labels or ds.has_edge_labels or ds.has_node_attributes)
    assert all(g.node_labels is None and g.node_features is None and g.edge_features is None
               for g in ds.graphs)
    assert ds.summary()["n_node_labels"] is None
    assert "structure only" in repr(ds)


def test_planted_round_trip_one_or_both_directions(tmp_path, rng):
    """Random graphs written with shuffled edge lines, in one or both directions, load back."""
    sizes = rng.integers(1, 9, size=12)
    mats, lines, both, indicator = [], [], [], []
    base = 0
    for g, n in enumerate(sizes):
        M = np.triu(rng.random((n, n)) < 0.4, 1)
        M = M | M.T
        mats.append(M.astype(float))
        for i, j in np.argwhere(np.triu(M, 1)):
            ends = (base + i + 1, base + j + 1)
            lines.append(ends if rng.random() < 0.5 else ends[::-1])
            both += [ends, ends[::-1]]
        indicator += [g + 1] * int(n)
        base += int(n)
    for kind, edge_list in (("one", lines), ("both", both)):
        order = rng.permutation(len(edge_list))
        text = "".join(f"{edge_list[k][0]}, {edge_list[k][1]}\n" for k in order)
        folder = _write(tmp_path / kind, "R", A=text, graph_indicator=_lines(indicator),
                        graph_labels=_lines(rng.integers(0, 3, size=len(sizes))),
                        skip=("node_labels", "edge_labels", "node_attributes"))
        ds = load_tu(folder)
        assert ds.sizes.tolist() == sizes.tolist()
        for M, g in zip(mats, ds.graphs):
            np.testing.assert_array_equal(g.adjacency, M)
        assert ds.summary()["isolated_nodes"] == sum(int((~M.any(1)).sum()) for M in mats)


def test_whitespace_tolerance(tmp_path):
    folder = _write(tmp_path / "W",
                    A="1,2\r\n\t2 ,\t3 \r\n  1 3\r\n6,7\r\n7, 8",        # no final newline
                    edge_labels="0\n1\n2\n3\n1\n \n",
                    graph_indicator=" 1\n1 \n1\n1\n2\n3\n3\n3\n\n\t\n",
                    node_attributes="".join(f"{a}\t{b}\n" for a, b in ATTRS))
    ds = load_tu(folder)
    ref = load_tu(_write(tmp_path / "R"))
    for g, h in zip(ds.graphs, ref.graphs):
        np.testing.assert_array_equal(g.adjacency, h.adjacency)
        np.testing.assert_allclose(g.node_features, h.node_features, atol=1e-6)
        np.testing.assert_array_equal(g.edge_features, h.edge_features)


@pytest.mark.parametrize("kind, text, line", [
    ("graph_indicator", "1\n1\n1\n1\n\n2\n3\n3\n3\n", 5),
    ("graph_labels", "-1\n\n1\n1\n", 2),
    ("A", "\n" + _lines(A_LINES), 1),
    ("node_attributes", "0.5, -1\n \n" + "".join(f"{a}, {b}\n" for a, b in ATTRS[1:]), 2),
])
def test_a_blank_line_among_the_data_lines_is_named(tmp_path, kind, text, line):
    # blank lines were skipped: every later line moved up one, and the error (if any) named
    # another file's line (a blank line 20 of MUTAG's graph indicator: "MUTAG_A.txt, line 93")
    folder = _write(tmp_path / "B", **{kind: text})
    path = folder / f"TOY_{kind}.txt"
    with pytest.raises(ValueError, match=re.escape(f"{path}, line {line}: expected ") + r".*"
                       + re.escape("found a blank line among the data lines (blank lines may "
                                   "only follow the last one)")):
        load_tu(folder)


def test_lone_carriage_returns_end_lines(tmp_path):
    """Files saved with old-Mac line ends (a lone ``\\r``) were read as one long line and
    refused with a field count; lines now end at ``\\n``, ``\\r\\n`` or ``\\r`` as in the other
    text loaders, and messages count lines that way."""
    ref = load_tu(_write(tmp_path / "R"))
    cr = {kind: _lines(rows).replace("\n", "\r") for kind, rows in (
        ("A", A_LINES), ("graph_indicator", NODES), ("graph_labels", GRAPH_LABELS),
        ("node_labels", NODE_LABELS), ("edge_labels", EDGE_LABELS))}
    cr["node_attributes"] = "".join(f"{a}, {b}\r" for a, b in ATTRS)
    ds = load_tu(_write(tmp_path / "C", **cr))
    assert ds.sizes.tolist() == ref.sizes.tolist()
    np.testing.assert_array_equal(ds.y, ref.y)
    for g, h in zip(ds.graphs, ref.graphs):
        np.testing.assert_array_equal(g.adjacency, h.adjacency)
        np.testing.assert_array_equal(g.node_labels, h.node_labels)
        np.testing.assert_allclose(g.node_features, h.node_features, atol=1e-6)
        np.testing.assert_array_equal(g.edge_features, h.edge_features)
    folder = _write(tmp_path / "B", A="1, 2\r2, 1\r\n2, 3\r3, x\r")
    with pytest.raises(ValueError, match=r"TOY_A.txt, line 4: .*got '3, x'"):
        load_tu(folder)


def test_self_loops_dropped_and_counted(tmp_path):
    ds = load_tu(_write(tmp_path / "S", A=_lines(A_LINES + ["4, 4", "7, 7", "7, 7"]),
                        edge_labels=_lines(EDGE_LABELS + [1, 2, 2])))
    assert ds.summary()["dropped_self_loops"] == 3
    assert ds.self_loops.tolist() == [1, 0, 2]
    assert all(np.all(np.diag(g.adjacency) == 0) for g in ds.graphs)
    assert ds.summary()["isolated_nodes"] == 2                 # node 4 stays isolated
    assert ds.subset([2]).summary()["dropped_self_loops"] == 2


def test_no_edges_at_all_and_byte_order_mark(tmp_path):
    folder = _write(tmp_path / "N", A="", graph_indicator="\ufeff1\n2\n2\n",
                    graph_labels="0\n1\n",
                    skip=("node_labels", "edge_labels", "node_attributes"))
    ds = load_tu(folder)
    assert ds.sizes.tolist() == [1, 2] and all(g.n_edges == 0 for g in ds.graphs)
    assert ds.summary()["isolated_nodes"] == 3 and ds.summary()["mean_edges"] == 0.0


def test_ignored_files_listed(tmp_path):
    folder = _write(tmp_path / "I", edge_attributes=_lines(["0.5"] * len(A_LINES)),
                    graph_attributes=_lines([1.0, 2.0, 3.0]))
    assert load_tu(folder).summary()["ignored_files"] == ["TOY_edge_attributes.txt",
                                                          "TOY_graph_attributes.txt"]


def test_duplicate_edge_lines_are_one_edge(tmp_path):
    ds = load_tu(_write(tmp_path / "D", A=_lines(A_LINES + ["2, 1", "1, 2"]),
                        edge_labels=_lines(EDGE_LABELS + [0, 0])))
    assert ds.graphs[0].n_edges == 3 and ds.graphs[0].adjacency.max() == 1


# --------------------------------------------------------------------------- the data set


def test_subset_pickle_and_frozen(tmp_path):
    ds = load_tu(_write(tmp_path / "TOY"))
    sub = ds.subset([2, 0])
    assert sub.y.tolist() == [1, -1] and sub.sizes.tolist() == [3, 4]
    assert sub.graphs[0] is ds.graphs[2] and sub.name == "TOY" and sub.has_edge_labels
    assert ds.subset(np.array([False, True, True])).sizes.tolist() == [1, 3]
    back = pickle.loads(pickle.dumps(ds))
    assert back.y.tolist() == ds.y.tolist() and back.summary() == ds.summary()
    np.testing.assert_array_equal(back.graphs[0].edge_features, ds.graphs[0].edge_features)
    with pytest.raises(AttributeError):
        ds.name = "other"
    with pytest.raises(ValueError):
        ds.y[0] = 3


@pytest.mark.parametrize("indices, exc, message", [
    ([0, 3], ValueError, "`indices` must lie in range(3), got 3 at position 1"),
    ([-1], ValueError, "`indices` must lie in range(3), got -1 at position 0"),
    ([], ValueError, "`indices` must select at least one graph, got none"),
    ([[0, 1]], ValueError, "`indices` must be one-dimensional, got shape (1, 2)"),
    ([0.5], TypeError, "`indices` must be integer indices or a boolean mask, got float64 array "
                       "of shape (1,)"),
    ("01", TypeError, "`indices` must be integer indices or a boolean mask, got <U2 array of "
                      "shape ()"),
    ([True, False], ValueError, "`indices` as a boolean mask must have shape (3,), got (2,)"),
])
def test_subset_bad_indices(tmp_path, indices, exc, message):
    ds = load_tu(_write(tmp_path / "TOY"))
    with pytest.raises(exc, match="^" + re.escape(message) + "$"):
        ds.subset(indices)


def test_dataset_constructor_checks():
    g = Graph(np.zeros((1, 1)))
    with pytest.raises(TypeError, match=r"^`graphs\[1\]` must be a transync.graphs.Graph"):
        TUDataset("x", (g, np.zeros((2, 2))), y=[0, 1], path=".")
    with pytest.raises(ValueError, match=r"^`y` must be an int array of shape \(1,\)"):
        TUDataset("x", (g,), y=[0.5], path=".")


# --------------------------------------------------------------------------- finding sets


def test_names_in_data_home(tmp_path, monkeypatch):
    _write(tmp_path / "tu" / "TOY")
    _write(tmp_path / "tu" / "Other", "Other")
    (tmp_path / "tu" / "notes").mkdir()
    assert list_tu(tmp_path) == ["Other", "TOY"]
    assert load_tu("TOY", data_home=tmp_path).name == "TOY"
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path))
    assert list_tu() == ["Other", "TOY"]
    assert len(load_tu("Other")) == 3
    _err(FileNotFoundError, "toy",
         f"{tmp_path / 'tu' / 'toy'}: no TU data set 'toy' (names are case-sensitive; data "
         f"sets in {tmp_path / 'tu'}: Other, TOY)")
    assert list_tu(tmp_path / "tu" / "notes") == []           # a data home without tu/
    with pytest.raises(FileNotFoundError, match="no such folder"):
        list_tu(tmp_path / "missing")


def test_folder_given_as_string_or_relative(tmp_path, monkeypatch):
    _write(tmp_path / "TOY")
    monkeypatch.chdir(tmp_path)
    assert load_tu("./TOY").name == "TOY"
    assert load_tu(str(tmp_path / "TOY")).name == "TOY"


def test_bad_argument_types(tmp_path):
    with pytest.raises(TypeError, match=r"^`path_or_name` must be a folder path or a data set "
                                        r"name \(str\), got int$"):
        load_tu(3)
    with pytest.raises(ValueError, match="^`path_or_name` must be a folder path"):
        load_tu("")
    with pytest.raises(TypeError, match=r"^`data_home` must be a path \(str or os.PathLike\), "
                                        r"got int 5$"):
        load_tu("MUTAG", data_home=5)
    # pathlib's bare RuntimeError "Could not determine home directory" named nothing
    with pytest.raises(ValueError, match=r"`path_or_name`: cannot expand '~nosuchuser_x/TOY'"):
        load_tu("~nosuchuser_x/TOY")
    with pytest.raises(ValueError, match=r"`data_home`: cannot expand '~nosuchuser_x'"):
        list_tu("~nosuchuser_x")


# --------------------------------------------------------------------------- errors


def test_missing_folder_and_files(tmp_path):
    layout = ("expected the TU layout: {0}_A.txt, {0}_graph_indicator.txt and "
              "{0}_graph_labels.txt, optionally {0}_node_labels.txt, {0}_edge_labels.txt and "
              "{0}_node_attributes.txt")
    _err(FileNotFoundError, tmp_path / "nope",
         f"{tmp_path / 'nope'}: no such folder ({layout.format('DS')})")
    (tmp_path / "empty").mkdir()
    _err(FileNotFoundError, tmp_path / "empty",
         f"{tmp_path / 'empty'}: no `<DS>_A.txt` file ({layout.format('DS')})")
    for kind in ("graph_indicator", "graph_labels"):
        folder = _write(tmp_path / kind, skip=(kind,))
        _err(FileNotFoundError, folder,
             f"{folder}: missing TOY_{kind}.txt ({layout.format('TOY')})")
    folder = _write(tmp_path / "two")
    _write(folder, "TWO")
    _err(ValueError, folder, f"{folder}: several `*_A.txt` files (TOY_A.txt, TWO_A.txt); "
                             "expected one TU data set per folder")


@pytest.mark.parametrize("kind, text, line, message", [
    ("A", "1, 2\n2, x\n", 2, "expected one edge `i, j` (integers), got '2, x'"),
    ("A", "1, 2\n2, 1\n1, 2, 3\n", 3,
     "expected one edge `i, j` (2 fields), found 3, got '1, 2, 3'"),
    ("A", "1, 2\n7\n", 2, "expected one edge `i, j` (2 fields), found 1, got '7'"),
    ("A", "1,,2\n", 1, "expected one edge `i, j` (empty field), got '1,,2'"),
    ("A", "1, 2\n, 1, 2\n", 2, "expected one edge `i, j` (empty field), got ', 1, 2'"),
    ("A", "1, 2,\n", 1, "expected one edge `i, j` (empty field), got '1, 2,'"),
    ("A", "1.0, 2\n", 1, "expected one edge `i, j` (integers), got '1.0, 2'"),
    ("A", "1, -\n", 1, "expected one edge `i, j` (integers), got '1, -'"),
    ("A", "1, 2\n3, 1234567890123456\n", 2,
     "expected one edge `i, j` (integers of at most 15 digits), got '3, 1234567890123456'"),
    ("graph_indicator", "1\n1\n1\n1\n2\n3\n3\n3 3\n", 8,
     "expected one graph id (1 field), found 2, got '3 3'"),
    ("graph_labels", "-1\n1\none\n", 3, "expected one integer class label (integers), got 'one'"),
    ("node_labels", "5\n6\n5\n7\n0\n1\n1\n2.5\n", 8,
     "expected one integer node label (integers), got '2.5'"),
    ("edge_labels", "0\n0\n1\n1\n2\n2\n3\n\x00\n", 8,
     "expected one integer edge label (integers), got '\\x00'"),
    ("node_attributes", "1, 2\n" * 3 + "1, nan\n" + "1, 2\n" * 4, 4,
     "expected comma-separated node attributes (finite numbers), got '1, nan'"),
    ("node_attributes", "1, 2\n" * 3 + "1, 2e999\n" + "1, 2\n" * 4, 4,
     "expected comma-separated node attributes (finite numbers), got '1, 2e999'"),
    ("node_attributes", "1, 2\n" * 5 + "1, abc\n" + "1, 2\n" * 2, 6,
     "expected comma-separated node attributes (finite numbers), got '1, abc'"),
    ("node_attributes", "1, 2\n" * 5 + "1, 2, 3\n" + "1, 2\n" * 2, 6,
     "expected comma-separated node attributes (2 fields), found 3, got '1, 2, 3'"),
])
def test_bad_line_names_file_and_line(tmp_path, kind, text, line, message):
    folder = _write(tmp_path / "TOY", **{kind: text})
    _err(ValueError, folder, f"{folder / f'TOY_{kind}.txt'}, line {line}: {message}")


def test_binary_file(tmp_path):
    folder = _write(tmp_path / "TOY")
    (folder / "TOY_graph_labels.txt").write_bytes(b"1\n\xff\xfe\x81\n1\n")
    _err(ValueError, folder, f"{folder / 'TOY_graph_labels.txt'}, line 2: expected one integer "
                             "class label (integers), got '\ufffd\ufffd\ufffd'")


def test_inconsistent_files(tmp_path):
    f = _write(tmp_path / "TOY", graph_indicator="1\n1\n2\n1\n2\n3\n3\n3\n")
    _err(ValueError, f, f"{f / 'TOY_graph_indicator.txt'}, line 4: expected nondecreasing "
                        "graph ids (previous line: 2), got '1'")
    f = _write(tmp_path / "TOY", graph_indicator=_lines(NODES[:-1] + [4]))
    _err(ValueError, f, f"{f / 'TOY_graph_indicator.txt'}, line 8: graph id 4 out of range "
                        f"1..3 ({f / 'TOY_graph_labels.txt'} has 3 graph labels)")
    f = _write(tmp_path / "TOY", graph_indicator=_lines([1] * 5 + [3] * 3))
    _err(ValueError, f, f"{f / 'TOY_graph_indicator.txt'}: graph 2 has no nodes "
                        f"({f / 'TOY_graph_labels.txt'} has 3 graph labels; graph ids must be "
                        "1..3, each listed for at least one node)")
    f = _write(tmp_path / "TOY", graph_indicator=_lines([0] + NODES[1:]))
    _err(ValueError, f, f"{f / 'TOY_graph_indicator.txt'}, line 1: graph id 0 out of range 1..3 "
                        f"({f / 'TOY_graph_labels.txt'} has 3 graph labels)")
    f = _write(tmp_path / "TOY", graph_indicator="\n")
    _err(ValueError, f, f"{f / 'TOY_graph_indicator.txt'}: no nodes (expected one graph id per "
                        "node)")
    f = _write(tmp_path / "TOY", graph_labels="")
    _err(ValueError, f, f"{f / 'TOY_graph_labels.txt'}: no graphs (expected one class label per "
                        "graph)")


def test_graphs_too_large_to_build_are_named_before_allocating(tmp_path, monkeypatch):
    """A 2 MB indicator of one 10**6-node graph asked numpy for 7 TiB (a raw MemoryError); the
    dense adjacency total is checked first. Here the limit is lowered to the toy's size."""
    from transync.datasets import _tu

    f = _write(tmp_path / "TOY")
    total = sum(NODES.count(g) ** 2 for g in set(NODES))
    monkeypatch.setattr(_tu, "_MAX_DENSE_ENTRIES", total)
    assert len(load_tu(f).graphs) == 3
    monkeypatch.setattr(_tu, "_MAX_DENSE_ENTRIES", total - 1)
    big = max(set(NODES), key=NODES.count)
    with pytest.raises(ValueError, match=re.escape(
            f"{f / 'TOY_graph_indicator.txt'}: the graphs' dense adjacency matrices would hold "
            f"{total:.3g} entries") + rf".*graph {big}, has {NODES.count(big)} nodes"):
        load_tu(f)


@pytest.mark.parametrize("kind, values, rows, against", [
    ("node_labels", NODE_LABELS[:-1], 8, "graph_indicator"),
    ("node_attributes", ["1, 2"] * 9, 8, "graph_indicator"),
    ("edge_labels", EDGE_LABELS + [0], 8, "A"),
])
def test_count_mismatch_names_both_files(tmp_path, kind, values, rows, against):
    f = _write(tmp_path / "TOY", **{kind: _lines(values)})
    _err(ValueError, f, f"{f / f'TOY_{kind}.txt'} has {len(values)} data lines but "
                        f"{f / f'TOY_{against}.txt'} has {rows}; expected one line per line of "
                        f"TOY_{against}.txt")


def test_edge_errors(tmp_path):
    a, ind = "TOY_A.txt", "TOY_graph_indicator.txt"
    f = _write(tmp_path / "TOY", A=_lines(A_LINES[:3] + ["3, 9"] + A_LINES[4:]))
    _err(ValueError, f, f"{f / a}, line 4: edge 3, 9 names a node out of range 1..8 "
                        f"({f / ind} lists 8 nodes)")
    f = _write(tmp_path / "TOY", A=_lines(A_LINES[:3] + ["0, 1"] + A_LINES[4:]))
    _err(ValueError, f, f"{f / a}, line 4: edge 0, 1 names a node out of range 1..8 "
                        f"({f / ind} lists 8 nodes)")
    f = _write(tmp_path / "TOY", A=_lines(A_LINES[:-1] + ["4, 5"]))
    _err(ValueError, f, f"{f / a}, line 8: edge 4, 5 joins graph 1 and graph 2 (per {f / ind}); "
                        "an edge must stay within one graph")
    f = _write(tmp_path / "TOY", edge_labels=_lines([0, 0, 1, 2, 2, 2, 3, 1]))
    _err(ValueError, f, f"{f / 'TOY_edge_labels.txt'}, lines 3 and 4: edge 2, 3 has labels 1 "
                        "and 2; an undirected edge listed twice (e.g. in both directions) must "
                        "carry one label")


# --------------------------------------------------------------------------- fuzzing

_KINDS = ("A", "graph_indicator", "graph_labels", "node_labels", "edge_labels",
          "node_attributes")
_FIELD = st.text(alphabet="0123456789-+., \tex\x00", max_size=8)


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(_KINDS), op=st.sampled_from(["replace", "insert", "delete", "dup"]),
       where=st.integers(0, 20), text=_FIELD)
def test_fuzzed_lines_give_a_dataset_or_a_named_error(kind, op, where, text):
    with tempfile.TemporaryDirectory() as tmp:
        folder = _write(Path(tmp) / "TOY")
        path = folder / f"TOY_{kind}.txt"
        lines = path.read_text().splitlines()
        k = where % (len(lines) + (op == "insert"))
        if op == "replace":
            lines[k] = text
        elif op == "insert":
            lines.insert(k, text)
        elif op == "delete":
            del lines[k]
        else:
            lines.insert(k, lines[k])
        path.write_text("\n".join(lines) + "\n")
        try:
            ds = load_tu(folder)
        except ValueError as exc:
            message = str(exc)
            assert message.startswith(str(folder / "TOY_")), message
            assert re.match(r"^\S+TOY_\w+\.txt(, lines? \d+|: | has )", message), message
        else:
            assert isinstance(ds, TUDataset) and len(ds) == ds.y.size >= 1
            assert all(np.array_equal(g.adjacency, g.adjacency.T) for g in ds.graphs)


# --------------------------------------------------------------------------- real data

_MANIFEST = re.compile(r"graphs=(\d+) .*classes=\{([^}]*)\} nodes=(\d+) .*"
                       r"undirected_edges=(\d+) .*self_loops=(\d+) node_label_values=(\d+)")


def _manifest(name):
    text = (data_home(subfolder="tu") / name / "MANIFEST.md").read_text()
    g, classes, nodes, edges, loops, labels = _MANIFEST.search(text).groups()
    counts = {int(k): int(v) for k, v in (c.split(":") for c in classes.split(","))}
    return int(g), counts, int(nodes), int(edges), int(loops), int(labels)


def _check_against_manifest(ds):
    n_graphs, counts, nodes, edges, loops, n_labels = _manifest(ds.name)
    s = ds.summary()
    assert s["n_graphs"] == n_graphs and s["class_counts"] == counts
    assert int(ds.sizes.sum()) == nodes
    assert sum(g.n_edges for g in ds.graphs) == edges
    assert s["dropped_self_loops"] == loops and s["n_node_labels"] == n_labels
    for g in ds.graphs:
        A = g.adjacency
        assert np.array_equal(A, A.T) and set(np.unique(A)) <= {0.0, 1.0}
        assert g.node_labels.dtype == np.int64 and g.node_labels.shape == (g.n_nodes,)


@pytest.mark.dataset("tu")
def test_real_mutag():
    ds = load_tu("MUTAG")
    assert ds.name == "MUTAG" and len(ds) == 188
    assert ds.has_node_labels and ds.has_edge_labels and not ds.has_node_attributes
    _check_against_manifest(ds)
    assert ds.summary()["n_classes"] == 2 and set(ds.y.tolist()) == {-1, 1}
    labels = set()
    for g in ds.graphs:
        E = g.edge_features
        np.testing.assert_array_equal(E, E.T)
        assert np.all(E[g.adjacency == 0] == 0)
        labels |= set(E[g.adjacency != 0].tolist())
    assert labels == {0.0, 1.0, 2.0, 3.0}              # aromatic, single, double, triple
    assert "MUTAG" in list_tu()


@pytest.mark.slow                                   # importing GraKeL alone takes seconds
@pytest.mark.dataset("tu")
def test_real_mutag_matches_grakel_reader(monkeypatch):
    """GraKeL 0.1.11's own TU reader (``read_data``, a line-by-line parser) as the reference."""
    read_data = pytest.importorskip("grakel.datasets.base").read_data
    ds = load_tu("MUTAG")
    monkeypatch.chdir(data_home(subfolder="tu"))             # read_data reads ./MUTAG/...
    ref = read_data("MUTAG", with_classes=True)
    np.testing.assert_array_equal(ds.y, ref.target)
    first = 1
    for g, (edges, node_labels, edge_labels) in zip(ds.graphs, ref.data):
        ours = {(int(i) + first, int(j) + first) for i, j in np.argwhere(g.adjacency)}
        assert ours == edges
        assert dict(zip(range(first, first + g.n_nodes), g.node_labels.tolist())) == node_labels
        assert {e: int(g.edge_features[e[0] - first, e[1] - first]) for e in ours} == edge_labels
        first += g.n_nodes


@pytest.mark.dataset("tu")
def test_real_ppi_has_no_node_labels():
    ds = load_tu("PPI")
    assert len(ds) == 86 and ds.summary()["class_counts"] == {1: 40, 2: 46}
    assert not (ds.has_node_labels or ds.has_edge_labels or ds.has_node_attributes)
    assert all(g.node_labels is None for g in ds.graphs)
    assert ds.sizes.max() == 232 and ds.sizes.min() == 3
    assert abs(ds.summary()["mean_nodes"] - 109.60) < 0.01
    assert abs(ds.summary()["mean_edges"] - 432.19) < 0.01


@pytest.mark.dataset("tu")
def test_real_ptc_mr():
    _check_against_manifest(load_tu("PTC_MR"))


@pytest.mark.slow
@pytest.mark.dataset("tu")
@pytest.mark.parametrize("name", ["ENZYMES", "NCI1"])
def test_real_large_sets(name):
    ds = load_tu(name)
    _check_against_manifest(ds)
    if name == "NCI1":
        assert len(ds) == 4110 and ds.summary()["isolated_nodes"] > 0
    else:
        assert ds.has_node_attributes
        assert all(g.node_features.shape == (g.n_nodes, 18) for g in ds.graphs)


def test_damaged_numbers_and_files_are_named(tmp_path):
    """Trailing NUL bytes (`2\\x00\\x00` read as 2.0) and `1_5` (read as 15) in node attributes;
    an optional file that is a folder was taken as absent, a required one reported missing."""
    rows = [", ".join(f"{x:.6f}" for x in row) for row in ATTRS]
    for token in ("2\x00\x00", "1_5", "\uff11"):
        bad = rows[:3] + [f"{token}, 1.0"] + rows[4:]
        folder = _write(tmp_path / f"T{len(token)}{ord(token[-1])}", node_attributes=_lines(bad))
        f = folder / "TOY_node_attributes.txt"
        with pytest.raises(ValueError, match=re.escape(f"{f}, line 4: expected comma-separated "
                                                       "node attributes (finite numbers)")):
            load_tu(folder)
    folder = _write(tmp_path / "DIR", skip=("node_labels",))
    (folder / "TOY_node_labels.txt").mkdir()
    _err(ValueError, folder, f"{folder / 'TOY_node_labels.txt'}: not a readable file (a folder); "
                             "remove it or put the file there")
    folder = _write(tmp_path / "LINK", skip=("edge_labels",))
    (folder / "TOY_edge_labels.txt").symlink_to(tmp_path / "nowhere")
    _err(ValueError, folder, f"{folder / 'TOY_edge_labels.txt'}: not a readable file (a broken "
                             "link); remove it or put the file there")
    folder = _write(tmp_path / "REQ", skip=("graph_indicator",))
    (folder / "TOY_graph_indicator.txt").mkdir()
    with pytest.raises(ValueError, match=re.escape(f"{folder / 'TOY_graph_indicator.txt'}: is a "
                                                   "folder, not a file")):
        load_tu(folder)


def test_blame_the_odd_line_and_count_significant_digits(tmp_path):
    """A first attribute line with 3 fields blamed line 2; `0000000000000001` (1) was refused as
    longer than 15 digits."""
    rows = [", ".join(f"{x:.6f}" for x in row) for row in ATTRS]
    folder = _write(tmp_path / "ODD", node_attributes=_lines([rows[0] + ", 1.0"] + rows[1:]))
    with pytest.raises(ValueError, match=re.escape(f"{folder / 'TOY_node_attributes.txt'}, line 1:"
                                                   " expected comma-separated node attributes "
                                                   "(2 fields), found 3")):
        load_tu(folder)
    folder = _write(tmp_path / "ZEROS", node_labels=_lines(["0000000000000005"] + NODE_LABELS[1:]))
    assert load_tu(folder).graphs[0].node_labels[0] == 5
    # 400 leading zeros: 10.0 ** 400 is inf and 0 * inf NaN, read as -2**63 (found by review)
    folder = _write(tmp_path / "Z400", graph_labels=_lines(["0" * 400 + "1"] + GRAPH_LABELS[1:]))
    assert load_tu(folder).y.tolist() == [1] + GRAPH_LABELS[1:]


def test_dataset_constructor_refuses_what_it_cannot_hold():
    """y = 2**63 (uint64) wrapped to -2**63; one Graph for `graphs` and path=None raised raw
    errors; has_node_labels=True without labels broke summary() later."""
    g = Graph(np.zeros((1, 1)))
    with pytest.raises(ValueError, match="`y` must fit in int64, got 9223372036854775808"):
        TUDataset("t", (g,), y=np.array([2**63], np.uint64), path=".")
    with pytest.raises(TypeError, match="`graphs` must be a list or tuple of transync.graphs"):
        TUDataset("t", g, y=[0], path=".")
    with pytest.raises(TypeError, match=r"`path` must be a path \(str or os.PathLike\), got "
                                        "NoneType"):
        TUDataset("t", (g,), y=[0], path=None)
    with pytest.raises(ValueError, match="`has_node_labels` is True but `graphs.0.` has no "
                                         "node_labels"):
        TUDataset("t", (g,), y=[0], path=".", has_node_labels=True)
    with pytest.raises(TypeError, match="`has_edge_labels` must be a bool, got str"):
        TUDataset("t", (g,), y=[0], path=".", has_edge_labels="no")
