"""The `multigraph` experiment (thesis Figs. 6.1, 6.2, 6.3, 6.5): registry, grid, metrics on a
planted problem, and the quick mode end to end (stored, resumed, figures)."""

import dataclasses
import functools

import numpy as np
import pytest

from transync.datasets import make_graph_collection
from transync.experiments import REGISTRY
from transync.experiments.multigraph import (
    FIGURES,
    HARD_DEFORMATION,
    METHODS,
    build,
    collection_metrics,
    run_method,
    trial,
)
from transync.matching import gaussian_edge_affinity

SWEEPS = {"deformation", "density", "outliers", "flip", "nodes", "graphs", "nodes_hard",
          "graphs_hard"}


def test_registered_and_builds():
    assert REGISTRY["multigraph"] == "transync.experiments.multigraph"
    for quick in (True, False):
        exp = build(quick=quick)
        assert exp.name == "multigraph" and {s.name for s in exp.sweeps} == SWEEPS
        assert all(tuple(s.methods) == tuple(METHODS) for s in exp.sweeps)
    full = {s.name: s for s in build().sweeps}
    assert build().trials >= 20
    assert full["deformation"].base["n_graphs"] == 8 and full["deformation"].base["sigma2"] == 0.05
    assert max(full["graphs"].values) == 32 and min(full["density"].values) == 0.3
    for name in ("nodes", "graphs"):          # the hard twins differ from them only in deformation
        easy, hard = full[name], full[name + "_hard"]
        assert hard.values == easy.values and hard.variable == easy.variable
        assert hard.base == {**easy.base, "deformation": HARD_DEFORMATION} != easy.base


def test_figures_name_known_methods_and_sweeps():
    for _fname, methods, sweeps, _metrics in FIGURES.values():
        assert set(methods) <= set(METHODS) and set(sweeps) <= SWEEPS
    assert FIGURES["6.1"][1] == ("GA", "S-GA", "PF", "S-PF", "CAO")
    assert FIGURES["6.2"][1] == ("RRWM", "S-RRWM", "PF", "S-PF")


def test_unknown_method_is_refused():
    prob = make_graph_collection(3, 4, rng=0)
    with pytest.raises(ValueError, match="`method` must be one of"):
        run_method("SGA", prob.graphs, None, np.random.default_rng(0))


@pytest.mark.parametrize("method", ["RRWM", "S-RRWM", "GA", "S-GA", "PF", "S-PF", "RRWM+sync",
                                    "CAO"])
def test_planted_zero_noise_is_recovered(method):
    """No deformation, complete graphs: the truth is the unique best matching of every pair
    (all its edge pairs score exp(0) = 1), so every method finds it and the metrics say so."""
    cfg = dict(n_graphs=3, n_inliers=6, n_outliers=0, deformation=0.0, density=1.0, flip=0.0,
               sigma2=0.05, method=method)
    out = trial(cfg, np.random.default_rng(3))
    assert out["accuracy"] == 1.0
    assert out["objective"] == pytest.approx(1.0)
    assert out["consistency"] == pytest.approx(1.0)
    assert out["seconds"] > 0 and 0.0 <= out["input_consistency"] <= 1.0


def test_metrics_of_a_wrong_answer_are_below_one():
    """Heavy deformation: plain pairwise RRWM loses accuracy and consistency; the relative
    objective stays positive and the accuracy agrees with transync.metrics."""
    from transync.metrics import multimatching_accuracy

    prob = make_graph_collection(5, 8, deformation=0.3, rng=1)
    aff = functools.partial(gaussian_edge_affinity, sigma2=0.05)
    res, sec = run_method("RRWM", prob.graphs, aff, np.random.default_rng(0))
    m = collection_metrics(res, prob, aff, sec)
    assert m["accuracy"] < 1.0 and m["consistency"] < 1.0
    assert m["accuracy"] == pytest.approx(
        multimatching_accuracy(res.pairwise_dict(), prob.ground_truth))
    assert m["objective"] > 0


def _small(exp):
    """The quick experiment cut to two sweeps, four methods (a CI-sized end-to-end run)."""
    keep = {"deformation": [0.0, 0.2], "graphs": [3]}
    methods = ("RRWM", "S-RRWM", "RRWM+sync", "CAO")
    sweeps = [dataclasses.replace(sw, values=keep[sw.name], methods=methods)
              for sw in exp.sweeps if sw.name in keep]
    return dataclasses.replace(exp, sweeps=sweeps)


def _end_to_end(run_twice, exp, folder, trials, plot):
    first, again = run_twice(exp, folder, trials, plot)
    acc = {(r["sweep"], r["value"], r["method"]): r["mean"] for r in again.summary
           if r["metric"] == "accuracy"}
    assert acc[("deformation", 0.0, "S-RRWM")] == 1.0
    return first


def test_small_run_end_to_end_and_resumes(tmp_path, run_twice):
    _end_to_end(run_twice, _small(build(quick=True)), tmp_path, trials=1, plot=False)


def test_finish_draws_the_thesis_figures_from_the_sweeps_that_ran(monkeypatch, tmp_path):
    """Figure subsets of methods and sweeps; Fig. 6.3 plots the density sweep against the
    fraction of edges removed (plotting itself is the runner's, tested there)."""
    import transync.experiments._plot as plot_module

    exp = build(quick=True)
    summary = [dict(sweep=sw.name, variable=sw.variable, value=v, method=m, metric=k, mean=0.5,
                    se=0.1, n=2, failed=0)
               for sw in exp.sweeps if sw.name in ("density", "graphs")
               for v in sw.values for m in sw.methods for k in sw.metrics]
    drawn = {}

    def fake(sub, rows, path):
        drawn[path.name] = (sub, rows)
        return path

    monkeypatch.setattr(plot_module, "plot_experiment", fake)
    paths = exp.finish([], summary, tmp_path)
    assert [p.name for p in paths] == ["fig_6_1.png", "fig_6_2.png", "fig_6_3_edges_removed.png",
                                       "fig_6_5_nodes_graphs.png"]
    sub, _rows = drawn["fig_6_1.png"]
    assert [sw.name for sw in sub.sweeps] == ["density"]          # the others did not run
    assert tuple(sub.sweeps[0].methods) == FIGURES["6.1"][1]
    sub, rows = drawn["fig_6_3_edges_removed.png"]
    assert sub.sweeps[0].values == [0.5, 0.0]                      # quick density 0.5, 1.0
    assert {r["value"] for r in rows if r["sweep"] == "density"} == {0.5, 0.0}
    sub, _rows = drawn["fig_6_5_nodes_graphs.png"]
    assert [sw.name for sw in sub.sweeps] == ["graphs"]
    assert tuple(sub.sweeps[0].metrics) == ("accuracy", "consistency", "seconds")


@pytest.mark.slow
def test_quick_mode_end_to_end(tmp_path, run_twice):
    rep = _end_to_end(run_twice, build(quick=True), tmp_path, trials=None, plot=True)
    assert (tmp_path / "multigraph.png").stat().st_size > 0
    assert {p.name for p in rep.extra_files} == {f[0] for f in FIGURES.values()}
    assert all(p.stat().st_size > 0 for p in rep.extra_files)
