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


def test_perspective_sequence_is_a_cmu_layout_sequence(bench, tmp_path):
    """The generated sequence loads with the CMU loader: 101 frames of 30 landmarks, the views
    related by no affine map (perspective), close frames nearly so."""
    from transync.datasets import load_cmu_sequence

    seq = load_cmu_sequence(bench.perspective_sequence(tmp_path / "s", 0, 20.0, noise=0.0))
    assert seq.n_frames == 101 and seq.n_landmarks == 30 and seq.name == "persp"

    def affine_residual(a, b):
        A = np.column_stack([a, np.ones(len(a))])
        M = np.linalg.lstsq(A, b, rcond=None)[0]
        return np.linalg.norm(A @ M - b, axis=1).mean() / np.linalg.norm(np.ptp(b, axis=0))

    far = affine_residual(seq.points[0], seq.points[-1])
    assert 0.03 < far < 0.06 and affine_residual(seq.points[0], seq.points[1]) < 0.01 * far


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
def test_script_perspective_part(bench, capsys):
    bench.main(["--parts", "perspective", "--yaws", "10", "--frames", "4", "--draws", "1",
                "--method", "RRWM+spectral"])
    rows = [line for line in capsys.readouterr().out.splitlines()
            if line.startswith("| generated, yaw 10 deg")]
    assert len(rows) == 1
    cells = [c.strip() for c in rows[0].strip("|").split("|")]
    assert len(cells) == 10 and all(0.0 <= float(c) <= 1.0 for c in cells[3:7])
