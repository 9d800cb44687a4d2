"""benchmarks/verify_auto.py: its generator and a tiny run of the script end to end."""

import numpy as np
import pytest


@pytest.fixture(scope="module")
def bench(load_benchmark):
    return load_benchmark("verify_auto", "verify_auto_bench")


def test_jitter_collection_is_partial_and_labelled(bench):
    graphs, truth = bench.jitter_collection(3, 0.0, n_points=12, n_views=5)
    assert len(graphs) == 5 and len({g.n_nodes for g in graphs}) > 1
    assert all(g.points.shape == (len(lab), 2) for g, lab in zip(graphs, truth.labels))
    assert truth.n_universe == 12 and all(np.unique(lab).size == lab.size
                                          for lab in truth.labels)


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
def test_script_reports_one_row_per_setting(bench, capsys):
    bench.main(["--parts", "jitter", "--sigmas", "0", "0.1", "--collections", "1",
                "--points", "10", "--views", "4", "--method", "RRWM+spectral"])
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("| 10 points")]
    assert len(rows) == 2 and "method RRWM+spectral" in out
    cells = rows[0].strip("|").split("|")
    assert 0.0 <= float(cells[3]) <= 1.0 and cells[-1].strip() in ("0", "1")
