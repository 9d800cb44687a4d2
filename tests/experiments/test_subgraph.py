"""The `subgraph` experiment (thesis ch. 7, issue #11): registry, grid, metrics on planted
problems and on hand-made results, the tables, the CMU partial sweep on a sequence the tests
write, and a small run end to end (stored, resumed)."""

import dataclasses
import functools
from types import SimpleNamespace

import numpy as np
import pytest

from transync.datasets import make_subgraph_collection
from transync.experiments import REGISTRY
from transync.experiments.subgraph import (
    DEFAULT_METHOD,
    DUMMY_PAIRS,
    FIGURES,
    GRAPH_METHODS,
    METHODS,
    SYNCHRONIZED,
    VERIFIED,
    build,
    cmu_keep_range,
    run_method,
    subgraph_metrics,
    trial,
)
from transync.matching import gaussian_edge_affinity
from transync.permutations import MultiMatching

SWEEPS = {"deformation", "flip", "range", "equal_deformation", "equal_flip"}
SMALL = dict(n_graphs=4, n_universe=8, p_low=1.0, p_high=1.0, n_outliers=0, deformation=0.0,
             density=1.0, flip=0.0, sigma2=0.05)


@pytest.fixture()
def no_data(monkeypatch, tmp_path):
    """A data home without `cmu-house`: the cmu sweep is left out."""
    (tmp_path / "data").mkdir()
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path / "data"))


def test_registered_and_builds(no_data):
    assert REGISTRY["subgraph"] == "transync.experiments.subgraph"
    for quick in (True, False):
        exp = build(quick=quick)
        assert exp.name == "subgraph" and {s.name for s in exp.sweeps} == SWEEPS
        assert all(tuple(s.methods) == GRAPH_METHODS for s in exp.sweeps)
        assert "left out" in exp.description
    full = {s.name: s for s in build().sweeps}
    assert build().trials >= 20
    b = full["deformation"].base
    assert (b["n_graphs"], b["n_universe"], b["p_low"], b["p_high"]) == (8, 20, 0.6, 1.0)
    assert full["range"].variable == "p_low" and min(full["range"].values) <= 0.3
    assert max(full["range"].values) == 1.0
    assert full["equal_flip"].base["p_low"] == 1.0 and full["equal_flip"].base["n_outliers"] > 0


def test_figures_and_pairs_name_known_methods_and_sweeps():
    for _fname, methods, sweeps, _metrics in FIGURES.values():
        assert set(methods) <= set(METHODS) and set(sweeps) <= SWEEPS
    for a, b in DUMMY_PAIRS.items():
        assert METHODS[b]["partial"] == "dummies" and "partial" not in METHODS[a]
        assert {k: v for k, v in METHODS[b].items() if k != "partial"} == METHODS[a]
    assert "RRWM" not in SYNCHRONIZED and len(SYNCHRONIZED) == len(METHODS) - 1
    assert VERIFIED and set(VERIFIED) <= set(SYNCHRONIZED)
    assert set(GRAPH_METHODS) | set(VERIFIED) == set(METHODS)
    def unverified(kw):
        return {k: v for k, v in kw.items() if k != "verify"}

    for m in GRAPH_METHODS:               # verification off explicitly ("auto" would run it)
        assert "verify" in METHODS[m] and METHODS[m]["verify"] is None
    for m in VERIFIED:                    # each is a graph method with the verification added
        assert unverified(METHODS[m]) in [unverified(METHODS[g]) for g in GRAPH_METHODS]


def test_unknown_method_and_missing_universe_are_refused():
    prob = make_subgraph_collection(3, 4, p_keep=1.0, rng=0)
    with pytest.raises(ValueError, match="`method` must be one of"):
        run_method("SRRWM", prob.graphs, None, np.random.default_rng(0))
    with pytest.raises(ValueError, match="pass `n_universe`"):
        run_method("S-RRWM known d", prob.graphs, None, np.random.default_rng(0))


@pytest.mark.parametrize("method", list(GRAPH_METHODS))
def test_planted_zero_noise_equal_sizes_is_recovered(method):
    """p_keep = 1, no outliers, no deformation, complete graphs: every pair's truth scores
    exp(0) = 1 on all its edge pairs, so every method finds it; the synchronized ones place the
    graphs in a universe of the true size without violating any constraint."""
    out = trial(dict(SMALL, method=method), np.random.default_rng(3))
    assert out["f1"] == out["precision"] == out["recall"] == out["accuracy"] == 1.0
    assert out["capacity_cvr"] == out["transitivity_cvr"] == 0.0
    assert out["n_universe_true"] == 8 and out["size_min"] == out["size_max"] == 8
    if method in SYNCHRONIZED:
        assert out["n_universe"] == 8 and out["universe_ok"] == 1.0
        assert out["universe_error"] == 0.0
    else:
        assert np.isnan(out["n_universe"]) and np.isnan(out["universe_ok"])
    assert out["seconds"] > 0


@pytest.mark.parametrize("method", ["S-RRWM", "RRWM+spectral", "S-RRWM known d",
                                    "S-RRWM dummies"])
def test_different_sizes_give_consistent_output(method):
    """Graphs of different sizes: the synchronized outputs stay exactly consistent and every
    score lies in [0, 1]; the known-universe line uses d."""
    cfg = dict(SMALL, n_graphs=5, p_low=0.5, deformation=0.02, method=method)
    out = trial(cfg, np.random.default_rng(1))
    assert out["size_min"] < out["size_max"]
    assert out["capacity_cvr"] == out["transitivity_cvr"] == 0.0
    assert all(0.0 <= out[k] <= 1.0 for k in ("f1", "precision", "recall"))
    assert out["n_universe"] >= out["size_max"]
    if method == "S-RRWM known d":
        assert out["n_universe"] == 8
    # the soft output (res.info["soft"]) is sub-doubly stochastic: capacity holds up to rounding
    assert 0.0 <= out["soft_transitivity_cvr"] <= 1.0 and out["soft_capacity_cvvr"] < 1e-6


def test_outliers_leave_the_universe_unjudged():
    """With outliers every node still takes a slot: no universe size is right or wrong."""
    out = trial(dict(SMALL, n_outliers=1, method="S-RRWM"), np.random.default_rng(0))
    assert out["n_universe"] >= 9 and np.isnan(out["universe_ok"])
    assert np.isnan(out["universe_error"]) and out["transitivity_cvr"] == 0.0


def _fake(pairs, maps, n_universe=None, soft=None):
    """A stand-in result: ``pairs``, ``pairwise(i, j)``, ``n_universe``, ``info``."""
    lookup = dict(zip(map(tuple, pairs), maps))
    return SimpleNamespace(pairs=np.array(pairs), pairwise=lambda i, j: lookup[(i, j)],
                           n_universe=n_universe, matching=None,
                           info={} if soft is None else {"soft": soft})


def test_metrics_of_a_hand_made_answer():
    """Three graphs over a universe of 3 (sizes 3, 2, 2). The answer gets pair (0, 1) right,
    matches an unshared node in (0, 2) and swaps (1, 2): 3 of 6 predicted matches are right,
    3 of 5 true correspondences found; the three maps contradict each other."""
    truth = MultiMatching([np.array([0, 1, 2]), np.array([1, 0]), np.array([2, 0])], 3)
    pairs = [(0, 1), (0, 2), (1, 2)]
    maps = [np.array([1, 0, -1]), np.array([1, 0, -1]), np.array([1, 0])]
    m = subgraph_metrics(_fake(pairs, maps, n_universe=4), truth, 0.5)
    assert m["precision"] == pytest.approx(0.5) and m["recall"] == pytest.approx(0.6)
    assert m["f1"] == pytest.approx(2 * 0.5 * 0.6 / 1.1)
    assert (m["n_universe"], m["n_universe_true"], m["universe_ok"], m["universe_error"]) == \
        (4.0, 3.0, 0.0, 1.0)
    assert m["transitivity_cvr"] > 0 and m["capacity_cvr"] == 0.0
    assert m["seconds"] == 0.5 and (m["size_min"], m["size_max"]) == (2.0, 3.0)
    assert not any(k.startswith("soft_") for k in m)


def test_soft_output_violations_are_measured_when_stored():
    """A soft block whose rows sum to 1.5 violates capacity; the discrete maps do not."""
    truth = MultiMatching([np.array([0, 1]), np.array([0, 1])], 2)
    soft = np.array([[[0.75, 0.75], [0.0, 0.5]]])
    m = subgraph_metrics(_fake([(0, 1)], [np.array([0, 1])], n_universe=2, soft=soft), truth,
                         0.1)
    assert m["capacity_cvr"] == 0.0 and m["f1"] == 1.0 and m["universe_ok"] == 1.0
    # row sums 1.5, 0.5; column sums 0.75, 1.25: two of four constraints violated, by 0.5 + 0.25
    assert m["soft_capacity_cvr"] == pytest.approx(0.5)
    assert m["soft_capacity_acvv"] == pytest.approx(0.375)
    assert m["soft_capacity_cvvr"] == pytest.approx(0.75 / 4.0)


def test_unsynchronized_rrwm_under_noise_is_inconsistent():
    """Heavy deformation: plain pairwise RRWM loses F1 and breaks transitivity; the numbers
    agree with transync.metrics."""
    from transync.metrics import constraint_violations, multimatching_precision_recall

    prob = make_subgraph_collection(5, 10, p_keep=(0.6, 1.0), deformation=0.3, rng=1)
    aff = functools.partial(gaussian_edge_affinity, sigma2=0.05)
    res, sec = run_method("RRWM", prob.graphs, aff, np.random.default_rng(0))
    m = subgraph_metrics(res, prob.ground_truth, sec)
    maps = {(i, j): res.pairwise(i, j) for i, j in res.pairs.tolist()}
    assert m["f1"] < 1.0 and m["transitivity_cvr"] > 0
    assert m["f1"] == pytest.approx(multimatching_precision_recall(maps, prob.ground_truth)["f1"])
    assert m["transitivity_cvr"] == pytest.approx(
        constraint_violations(maps, sizes=prob.sizes).transitivity.cvr)


def test_cmu_keep_range_and_sweep_on_a_written_sequence(tmp_path, write_sequence):
    assert cmu_keep_range(30) == (20, 25) and cmu_keep_range(1) == (1, 1)
    seq = write_sequence(tmp_path / "seq", n_landmarks=12)
    exp = build(quick=True, data=seq)
    cmu = {s.name: s for s in exp.sweeps}["cmu"]
    assert cmu.values == [4] and (cmu.base["keep_low"], cmu.base["keep_high"]) == (8, 10)
    assert "data" not in cmu.base and exp.trial.keywords["data"] == str(seq.resolve())
    assert tuple(cmu.methods) == GRAPH_METHODS + VERIFIED
    for method in ("S-RRWM", "S-RRWM verified"):
        out = exp.trial(dict(cmu.base, n_frames=4, method=method), np.random.default_rng(0))
        assert 8 <= out["size_min"] <= out["size_max"] <= 10
        assert out["transitivity_cvr"] == 0.0 and out["f1"] > 0.8
    # translated, jittered copies: the affine verification keeps exactly the shared landmarks
    assert out["f1"] == 1.0 and out["universe_ok"] == 1.0
    assert build(data=seq).sweeps[-1].values == [8]        # 20 frames asked, 8 in the sequence


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
def test_the_default_line_is_match_collection_with_its_defaults(tmp_path, write_sequence):
    """The targets table calls DEFAULT_METHOD the library's defaults: on the cmu sweep's
    graphs (different sizes, 2-d points) it gives exactly what match_collection gives when
    nothing but the affinity is passed."""
    from transync import match_collection
    from transync.datasets import LANDMARK_AFFINITY
    from transync.experiments.subgraph import _cmu_problem

    seq = write_sequence(tmp_path / "seq", n_landmarks=12)
    cmu = {s.name: s for s in build(quick=True, data=seq).sweeps}["cmu"]
    prob = _cmu_problem(dict(cmu.base, n_frames=5), np.random.default_rng(2), str(seq))
    assert len({g.n_nodes for g in prob.graphs}) > 1
    aff = functools.partial(gaussian_edge_affinity, **LANDMARK_AFFINITY)
    res, _ = run_method(DEFAULT_METHOD, prob.graphs, aff, np.random.default_rng(3))
    seed = int(np.random.default_rng(3).integers(2**31))        # run_method's draw
    plain = match_collection(prob.graphs, affinity=aff, rng=seed, progress=False)
    np.testing.assert_array_equal(res.assignments, plain.assignments)
    assert plain.info["verify"]["auto"] and plain.info["verify"]["used"]


def test_missing_data_folder_given_is_an_error(tmp_path, capsys):
    from transync.cli import main

    with pytest.raises(FileNotFoundError, match="nope"):
        build(quick=True, data=tmp_path / "nope")
    assert main(["experiment", "subgraph", "--quick", "--data", str(tmp_path / "nope"),
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nope" in err and not (tmp_path / "out").exists()
    assert main(["experiment", "--list"]) == 0
    assert "subgraph" in capsys.readouterr().out


@pytest.mark.dataset("cmu-house")
def test_cmu_house_partial_trial():
    """Real data, a short draw (6 frames spread over the sequence): consistent output, 20-25
    landmarks per frame, a good F1."""
    exp = build(quick=True)
    cmu = {s.name: s for s in exp.sweeps}["cmu"]
    assert (cmu.base["keep_low"], cmu.base["keep_high"]) == (20, 25)
    out = exp.trial(dict(cmu.base, n_frames=6, method="RRWM+spectral"),
                    np.random.default_rng(0))
    assert 20 <= out["size_min"] <= out["size_max"] <= 25
    assert out["transitivity_cvr"] == 0.0 and out["f1"] > 0.5
    # the protocol's 20 frames with the geometric verification: the universe is found and F1
    # is high (0.98-1.0 per draw, docs/experiments/subgraph; 0.75-0.80 without it)
    out = exp.trial(dict(cmu.base, n_frames=20, method="RRWM+spectral verified"),
                    np.random.default_rng(0))
    assert out["transitivity_cvr"] == 0.0 and out["f1"] > 0.95 and out["universe_ok"] == 1.0


def _record(sweep, value, method, trial_, **metrics):
    var = {"deformation": "deformation", "range": "p_low"}[sweep]
    return dict(sweep=sweep, config={var: value, "method": method}, trial=trial_,
                metrics=metrics, error=None, seconds=1.0)


def test_tables_from_planted_records(tmp_path, monkeypatch, write_sequence):
    """Targets: universe vs dummies per point with ties; the paired F1 loss is computed on the
    problems where S-RRWM's universe estimate is wrong (figures are the runner's, not drawn)."""
    import transync.experiments._plot as plot_module

    monkeypatch.setattr(plot_module, "plot_experiment", lambda sub, rows, path: path)
    zero = {k: 0.0 for k in ("capacity_cvr", "transitivity_cvr", "capacity_cvvr",
                             "capacity_acvv", "transitivity_cvvr", "transitivity_acvv")}
    recs = []
    for t, (ok, f1) in enumerate([(1.0, 0.9), (0.0, 0.6)]):
        recs.append(_record("deformation", 0.2, "S-RRWM", t, f1=f1, universe_ok=ok,
                            universe_error=1.0 - ok, **zero))
        recs.append(_record("deformation", 0.2, "S-RRWM known d", t, f1=0.9, universe_ok=1.0,
                            universe_error=0.0, **zero))
        recs.append(_record("deformation", 0.2, "S-RRWM dummies", t, f1=0.5, universe_ok=0.0,
                            universe_error=-1.0, **zero))
        recs.append(_record("range", 1.0, "S-RRWM", t, f1=1.0, universe_ok=1.0,
                            universe_error=0.0, **zero))
        recs.append(_record("range", 1.0, "S-RRWM dummies", t, f1=1.0, universe_ok=1.0,
                            universe_error=0.0, **zero))
    exp = build(quick=True, data=write_sequence(tmp_path / "seq", n_landmarks=12))
    paths = exp.finish(recs, [], tmp_path)
    names = {p.name for p in paths}
    assert {"table_7_2.md", "table_universe.md", "table_targets.md"} <= names
    assert "table_cmu.md" not in names                     # no cmu trial stored
    targets = (tmp_path / "table_targets.md").read_text()
    assert "0.7500 vs 0.5000 ✓" in targets and "1.0000 vs 1.0000 =" in targets
    assert "better (✓) at 1, equal (=) at 1, worse (✗) at 0" in " ".join(targets.split())
    assert "largest transitivity cvr 0 over" in targets.lower()
    assert "75.0 % of 4 trials" in targets              # 3 of 4 S-RRWM estimates right
    universe = (tmp_path / "table_universe.md").read_text()
    row = next(line for line in universe.splitlines()
               if line.startswith("| deformation | S-RRWM |"))
    assert "| 50.0 % |" in row and row.rstrip(" |").endswith("0.3000")   # 0.9 - 0.6
    assert "| 0.9000 | 0.6000 |" in row


def _small(exp):
    """The quick experiment cut to two sweeps, three methods (a CI-sized end-to-end run)."""
    keep = {"deformation": [0.0], "range": [0.5]}
    methods = ("S-RRWM", "RRWM", "S-RRWM dummies")
    sweeps = [dataclasses.replace(sw, values=keep[sw.name], methods=methods)
              for sw in exp.sweeps if sw.name in keep]
    return dataclasses.replace(exp, sweeps=sweeps)


def _end_to_end(run_twice, exp, folder, trials, plot):
    first, again = run_twice(exp, folder, trials, plot)
    f1 = {(r["sweep"], r["value"], r["method"]): r["mean"] for r in again.summary
          if r["metric"] == "f1"}
    assert f1[("deformation", 0.0, "S-RRWM")] > 0.9
    return first


def test_small_run_end_to_end_and_resumes(tmp_path, no_data, run_twice):
    _end_to_end(run_twice, _small(build(quick=True)), tmp_path, trials=1, plot=False)


@pytest.mark.slow
def test_quick_mode_end_to_end(tmp_path, write_sequence, run_twice):
    exp = build(quick=True, data=write_sequence(tmp_path / "seq", n_landmarks=12))
    rep = _end_to_end(run_twice, exp, tmp_path / "out", trials=None, plot=True)
    assert (tmp_path / "out" / "subgraph.png").stat().st_size > 0
    names = {p.name for p in rep.extra_files}
    assert {f[0] for f in FIGURES.values()} <= names
    assert {"table_7_2.md", "table_universe.md", "table_cmu.md", "table_targets.md"} <= names
    assert all(p.stat().st_size > 0 for p in rep.extra_files)
