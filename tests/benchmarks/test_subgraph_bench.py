"""The multi-subgraph benchmark's fairness-critical helpers (benchmarks/subgraph.py, issue #11).

What every method is given and how its output is scored decide what the benchmark's table
means, so these are checked on small planted problems; the full runs are the script's job.
"""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from transync.datasets import make_subgraph_collection

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "subgraph.py"


@pytest.fixture(scope="module")
def bench():
    path, had = list(sys.path), "multigraph" in sys.modules
    spec = importlib.util.spec_from_file_location("subgraph_bench", _PATH)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["subgraph_bench"] = mod
    spec.loader.exec_module(mod)          # puts benchmarks/ on sys.path for its sibling import
    yield mod
    sys.modules.pop("subgraph_bench", None)
    if not had:
        sys.modules.pop("multigraph", None)
    sys.path[:] = path


def test_gamgm_inputs_are_the_centred_attributes_padded(bench):
    c = make_subgraph_collection(4, 7, p_keep=(0.5, 1.0), n_outliers=1, rng=3)
    A, W, ns = bench.gamgm_inputs(c.graphs)
    assert ns.tolist() == c.sizes.tolist() and len(set(ns.tolist())) > 1
    assert A.shape == (4, ns.max(), ns.max()) and W.shape == (4, 4, ns.max(), ns.max())
    assert not W.any()
    for k, g in enumerate(c.graphs):
        n = ns[k]
        E, M = np.asarray(g.edge_features), np.asarray(g.adjacency) != 0
        np.testing.assert_allclose(A[k, :n, :n][M], E[M] - 0.5)
        assert not A[k, :n, :n][~M].any()
        assert not A[k, n:].any() and not A[k, :, n:].any()      # padding stays zero


def test_k_blocks_follow_the_pygmtools_layout(bench):
    c = make_subgraph_collection(3, 6, p_keep=(0.5, 1.0), deformation=0.0, rng=5)
    pairs = bench.all_pairs(3)
    K = bench.k_blocks(c.graphs, pairs, 0.05)
    for i, j in pairs.tolist():
        ni, nj = c.sizes[i], c.sizes[j]
        assert K[(i, j)].shape == (ni * nj, ni * nj)
        truth = c.truth(i, j)
        x = np.zeros((ni, nj))
        x[np.flatnonzero(truth >= 0), truth[truth >= 0]] = 1.0
        v = x.ravel(order="F")                     # candidate (u, a) at index u + n_i a
        common = int(np.sum(truth >= 0))
        # zero deformation, complete graphs: every ordered pair of true matches scores exp(0)
        assert v @ K[(i, j)] @ v == pytest.approx(common * (common - 1))
    assert bench.mgm_edges(c.sizes, pairs) == pytest.approx(
        sum(c.sizes[i] * c.sizes[j] * (c.sizes[i] - 1) * (c.sizes[j] - 1) / 2
            for i, j in pairs.tolist()))


def test_evaluate_scores_the_truth_perfectly_and_a_broken_map_less(bench):
    c = make_subgraph_collection(4, 8, p_keep=(0.6, 1.0), n_outliers=1, rng=2)
    pairs = bench.all_pairs(4)
    maps = {(i, j): c.truth(i, j) for i, j in pairs.tolist()}
    ev = bench.evaluate(maps, c, pairs)
    assert ev["f1"] == ev["precision"] == ev["recall"] == 1.0
    assert ev["cvr_transitivity"] == 0.0 and ev["cvr_capacity"] == 0.0
    broken = dict(maps)
    a = broken[(0, 1)].copy()
    hit = np.flatnonzero(a >= 0)[:2]
    a[hit] = a[hit[::-1]]                                   # swap two true matches
    broken[(0, 1)] = a
    ev2 = bench.evaluate(broken, c, pairs)
    assert ev2["f1"] < 1.0 and ev2["cvr_transitivity"] > 0.0


def test_transync_and_matcheig_recover_a_planted_collection(bench):
    import functools

    from transync.matching import gaussian_edge_affinity

    c = make_subgraph_collection(4, 7, p_keep=1.0, deformation=0.0, rng=0)
    pairs = bench.all_pairs(4)
    aff = functools.partial(gaussian_edge_affinity, sigma2=0.05)
    for method in ("ts-rrwm+spectral@d", "ts-matcheig@d"):
        maps, stages, extra = bench.run_method(method, c.graphs, aff, 7, pairs, 0, 0.05, 1)
        assert bench.evaluate(maps, c, pairs)["f1"] == 1.0, method
        assert extra["n_universe"] == 7 and extra["universe_given"]


def test_summary_ratios_are_transync_over_peer(bench):
    base = {"family": "def0.05", "N": 8, "d": 20, "status": "ok", "universe_given": True,
            "mem_trim": True, "cvr_transitivity": 0.0}
    rows = [{**base, "trial": 0, "method": "ts-s-rrwm", "f1": 0.9, "accuracy": 0.9,
             "precision": 0.9, "recall": 0.9, "time_s": 1.0, "peak_mib": 10.0},
            {**base, "trial": 0, "method": "pg-gamgm@d", "f1": 0.5, "accuracy": 0.5,
             "precision": 0.5, "recall": 0.5, "time_s": 10.0, "peak_mib": 5.0}]
    s = {x["method"]: x for x in bench.summary(rows)}
    assert s["pg-gamgm@d"]["time_ratio_ref"] == pytest.approx(0.1)
    assert s["pg-gamgm@d"]["memory_ratio_ref"] == pytest.approx(2.0)
    assert s["pg-gamgm@d"]["f1_diff_ref"] == pytest.approx(0.4)
    table = bench.target_table(rows)
    assert "| pg-gamgm@d | 0.500 | 10.00 s | 0.900 | 1.00 s (0.10x) | met |" in table


@pytest.mark.slow
def test_a_tiny_run_stores_rows_and_a_report(bench, tmp_path):
    import json

    out = tmp_path / "sub.json"
    bench.main(["--graphs", "4", "--universes", "6", "--trials", "1", "--families", "def0.05",
                "--methods", "ts-s-rrwm", "ts-matcheig@d", "pg-gamgm@d", "--out", str(out)])
    data = json.loads(out.read_text())
    assert {r["method"] for r in data["rows"]} == {"ts-s-rrwm", "ts-matcheig@d", "pg-gamgm@d"}
    assert all(r["status"] == "ok" for r in data["rows"])
    assert all(r["cvr_transitivity"] == 0.0 for r in data["rows"] if r["method"] != "ts-matcheig@d")
    md = out.with_suffix(".md").read_text()
    assert "### Issue target" in md and "| def0.05 | 4 | 6 | pg-gamgm@d |" in md
