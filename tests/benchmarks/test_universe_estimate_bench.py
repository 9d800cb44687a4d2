"""benchmarks/universe_estimate.py: its interval and a tiny run of the script end to end."""

import math

import pytest


@pytest.fixture(scope="module")
def bench(load_benchmark):
    return load_benchmark("universe_estimate", "universe_estimate_bench")


def test_wilson_interval(bench):
    lo, hi = bench.wilson(93, 100)
    assert lo == pytest.approx(0.8625, abs=1e-3) and hi == pytest.approx(0.9657, abs=1e-3)
    lo, hi = bench.wilson(0, 10)
    assert lo == 0.0 and 0.0 < hi < 0.35
    assert all(math.isnan(x) for x in bench.wilson(5, 0))    # no trials: no interval


def test_script_runs_and_reports_every_method(bench, capsys):
    bench.main(["--collections", "2", "--graphs", "4", "--universe", "6",
                "--methods", "RRWM+spectral", "S-RRWM"])
    out = capsys.readouterr().out
    assert "2 collections" in out
    assert out.count("estimate = truth") == 2 and "RRWM+spectral" in out
