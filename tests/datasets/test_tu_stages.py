"""The private stages of ``load_tu`` on tiny hand-made inputs (edge folding and graph building)."""

from pathlib import Path

import numpy as np
import pytest

from transync.datasets._tu import _build_graphs, _undirected_edges

# two graphs: nodes 0..2 (graph 1) and 3..4 (graph 2), 0-based ids as the stage receives them
INDICATOR = np.array([1, 1, 1, 2, 2])
# 1-0 twice (both directions), a self-loop in each graph, 2-1 in one direction, 4-3 once
EDGES = np.array([[1, 0], [0, 1], [2, 2], [2, 1], [4, 3], [3, 3]])


def test_undirected_edges_fold_dedupe_and_count_self_loops():
    lo, hi, labels, loops = _undirected_edges(EDGES, INDICATOR, 2, None, None, Path("E.txt"))
    assert lo.tolist() == [0, 1, 3] and hi.tolist() == [1, 2, 4]
    assert labels is None and loops.tolist() == [1, 1]


def test_undirected_edges_labels_kept_once_and_clash_named():
    labels = np.array([7, 7, 0, 8, 9, 0])
    lines = np.arange(1, 7)
    lo, hi, lab, _ = _undirected_edges(EDGES, INDICATOR, 2, labels, lines, Path("E.txt"))
    assert lab.tolist() == [7, 8, 9]
    labels[1] = 5
    with pytest.raises(ValueError, match=r"^E\.txt, lines 1 and 2: edge 1, 2 has labels 7 and 5;"):
        _undirected_edges(EDGES, INDICATOR, 2, labels, lines, Path("E.txt"))


def test_build_graphs_symmetric_with_isolated_nodes():
    counts = np.array([3, 2])
    node_labels = np.arange(5)
    graphs = _build_graphs(INDICATOR, counts, np.array([0, 3]), np.array([1, 4]),
                           np.array([0, 6]), node_labels, None)
    assert [g.n_nodes for g in graphs] == [3, 2]
    assert graphs[0].adjacency.tolist() == [[0, 1, 0], [1, 0, 0], [0, 0, 0]]    # node 2 isolated
    assert graphs[1].adjacency.tolist() == [[0, 1], [1, 0]]
    assert graphs[1].edge_features.tolist() == [[0, 6], [6, 0]]
    assert graphs[1].node_labels.tolist() == [3, 4] and graphs[0].node_features is None
