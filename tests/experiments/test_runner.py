import sqlite3
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from transync.experiments import Experiment, Sweep, run_experiment


def noisy_trial(config, rng):
    if config["method"] == "broken" and config["x"] == 2:
        raise RuntimeError("planted failure")
    return {"value": config["x"] + rng.normal(0, 0.01), "draw": rng.random()}


def _experiment(trials=4, methods=("a", "b")):
    return Experiment(name="t", trial=noisy_trial, trials=trials, sweeps=[
        Sweep(name="s", variable="x", values=[1, 2, 3], methods=list(methods),
              metrics=("value",))])


def test_all_trials_stored_and_summarized(tmp_path):
    rep = run_experiment(_experiment(), tmp_path, progress=False)
    assert rep.n_new == 3 * 2 * 4 and rep.n_failed == 0
    assert (tmp_path / "t.png").stat().st_size > 0
    assert (tmp_path / "summary.md").read_text().count("|") > 10
    rows = {(r["value"], r["method"]): r for r in rep.summary if r["metric"] == "value"}
    for x in (1, 2, 3):
        assert rows[(x, "a")]["mean"] == pytest.approx(x, abs=0.05)
        assert rows[(x, "a")]["n"] == 4


def test_methods_share_the_random_problem(tmp_path):
    rep = run_experiment(_experiment(), tmp_path, progress=False, plot=False)
    draws = {}
    for r in rep.records:
        draws.setdefault((r["config"]["x"], r["trial"]), set()).add(r["metrics"]["draw"])
    assert all(len(v) == 1 for v in draws.values())
    other = run_experiment(_experiment(), tmp_path / "seed1", seed=1, progress=False, plot=False)
    assert {r["metrics"]["draw"] for r in other.records}.isdisjoint(
        {r["metrics"]["draw"] for r in rep.records})


def test_resume_skips_finished_and_extends(tmp_path):
    first = run_experiment(_experiment(trials=2), tmp_path, progress=False, plot=False)
    again = run_experiment(_experiment(trials=2), tmp_path, progress=False, plot=False)
    more = run_experiment(_experiment(trials=3), tmp_path, progress=False, plot=False)
    assert (first.n_new, again.n_new, more.n_new) == (12, 0, 6)
    assert len(more.records) == 18


def test_failures_are_recorded_not_fatal(tmp_path):
    rep = run_experiment(_experiment(methods=("a", "broken")), tmp_path, progress=False,
                         plot=False)
    assert rep.n_failed == 4
    failed = [r for r in rep.records if r["error"]]
    assert all("planted failure" in r["error"] for r in failed)
    row = [r for r in rep.summary if r["method"] == "broken" and r["value"] == 2
           and r["metric"] == "value"][0]
    assert row["n"] == 0 and row["failed"] == 4


_FLAKY = {"fail": True}


def flaky_trial(config, rng):
    if _FLAKY["fail"] and config["x"] == 2:
        raise RuntimeError("transient failure")
    return {"value": float(config["x"])}


def test_a_rerun_retries_the_failed_trials(tmp_path):
    # failed trials were stored like finished ones and never run again, although the CLI says
    # "rerun to retry"; a rerun reported 0 new trials and exit status 0
    exp = Experiment(name="f", trial=flaky_trial, trials=3, sweeps=[
        Sweep(name="s", variable="x", values=[1, 2], methods=["a"], metrics=("value",))])
    _FLAKY["fail"] = True
    try:
        first = run_experiment(exp, tmp_path, progress=False, plot=False)
        assert (first.n_new, first.n_failed) == (6, 3)
        _FLAKY["fail"] = False
        second = run_experiment(exp, tmp_path, progress=False, plot=False)
        assert (second.n_new, second.n_failed) == (3, 0)
        assert not any(r["error"] for r in second.records) and len(second.records) == 6
        row = [r for r in second.summary if r["value"] == 2 and r["metric"] == "value"][0]
        assert row["n"] == 3 and row["failed"] == 0
        assert run_experiment(exp, tmp_path, progress=False, plot=False).n_new == 0
    finally:
        _FLAKY["fail"] = True


def test_process_pool_gives_the_same_numbers(tmp_path):
    serial = run_experiment(_experiment(trials=2), tmp_path / "a", progress=False, plot=False)
    pooled = run_experiment(_experiment(trials=2), tmp_path / "b", workers=2, progress=False,
                            plot=False)
    key = lambda r: (r["config"]["x"], r["config"]["method"], r["trial"])  # noqa: E731
    s = {key(r): r["metrics"]["value"] for r in serial.records}
    p = {key(r): r["metrics"]["value"] for r in pooled.records}
    assert s == p


def test_killed_run_loses_at_most_the_trial_in_flight(tmp_path):
    mod = tmp_path / "slowexp.py"
    mod.write_text(textwrap.dedent("""
        import time
        from transync.experiments import Experiment, Sweep, run_experiment
        def trial(config, rng):
            time.sleep(0.15)
            return {"v": float(config["x"])}
        EXP = Experiment(name="slow", trial=trial, trials=10, sweeps=[
            Sweep(name="s", variable="x", values=[0, 1], methods=["m"], metrics=("v",))])
        if __name__ == "__main__":
            import sys
            run_experiment(EXP, sys.argv[1], progress=False, plot=False)
    """))
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, str(mod), str(out)], cwd=tmp_path)
    db = out / "results.sqlite"
    deadline = time.time() + 60
    stored = 0
    while time.time() < deadline:
        time.sleep(0.1)
        if db.exists():
            try:
                with sqlite3.connect(db) as con:
                    stored = con.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
            except sqlite3.OperationalError:
                continue
            if stored >= 3:
                break
    proc.kill()
    proc.wait()
    with sqlite3.connect(db) as con:
        after_kill = con.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
    assert 3 <= after_kill < 20
    sys.path.insert(0, str(tmp_path))
    try:
        import slowexp
        rep = run_experiment(slowexp.EXP, out, progress=False, plot=False)
    finally:
        sys.path.remove(str(tmp_path))
    assert rep.n_new == 20 - after_kill
    assert len(rep.records) == 20
    assert np.allclose(sorted(r["metrics"]["v"] for r in rep.records), [0] * 10 + [1] * 10)


def test_finish_hook_files_listed_and_skipped_without_plot(tmp_path):
    seen = []

    def finish(records, summary, out_dir):
        seen.append((len(records), len(summary)))
        path = out_dir / "extra.md"
        path.write_text(f"{len(records)} records\n")
        return [path]

    exp = _experiment(trials=2)
    exp = Experiment(name=exp.name, trial=exp.trial, trials=2, sweeps=exp.sweeps, finish=finish)
    rep = run_experiment(exp, tmp_path / "a", progress=False, plot=False)
    assert rep.extra_files == () and seen == []
    rep = run_experiment(exp, tmp_path / "b", progress=False)
    assert rep.extra_files == (tmp_path / "b" / "extra.md",)
    assert (tmp_path / "b" / "extra.md").read_text() == "12 records\n"
    assert seen == [(12, len(rep.summary))]


def _returns(value):
    def trial(config, rng):
        return value
    return trial


@pytest.mark.parametrize("out, what", [
    ({"value": "x"}, "real numbers by metric name, got 'value': 'x'"),
    ({"value": 1 + 2j}, "real numbers by metric name"),
    ({3: 1.0}, "real numbers by metric name, got 3: 1.0"),
    ([("value", 1.0)], "must return a mapping"),
])
def test_a_trial_returning_junk_fails_that_trial_only(tmp_path, out, what):
    """A non-number metric was a float() error that stopped the whole run (unnamed)."""
    exp = Experiment(name="t", trial=_returns(out), trials=2, sweeps=[
        Sweep(name="s", variable="x", values=[1], methods=["a"], metrics=("value",))])
    rep = run_experiment(exp, tmp_path, progress=False, plot=False)
    assert rep.n_new == 2 and rep.n_failed == 2
    assert all(what in r["error"] for r in rep.records)


def test_sweep_values_of_any_shape_are_accepted():
    """Ragged and mixed values (lists of different lengths, None beside a tuple) are valid
    sweep values; the 0-d check must not turn them into an array."""
    for values in ([[1], [1, 2]], [None, (320, 240)], ["auto", (1, 2)], [{"a": 1, 2: "b"}]):
        assert list(Sweep(name="s", variable="x", values=values, methods=["a"]).values) == values


@pytest.mark.parametrize("make, exc, match", [
    (lambda s: Experiment(name="", trial=noisy_trial, sweeps=[s]), TypeError, "Experiment.name"),
    (lambda s: Experiment(name="a/b", trial=noisy_trial, sweeps=[s]), ValueError, "figure file"),
    (lambda s: Experiment(name="t", trial=noisy_trial, sweeps=[]), TypeError, "non-empty list"),
    (lambda s: Experiment(name="t", trial=noisy_trial, sweeps=[s, s]), ValueError, "distinct"),
    (lambda s: Experiment(name="t", trial=3, sweeps=[s]), TypeError, "callable"),
    (lambda s: Experiment(name="t", trial=noisy_trial, sweeps=[s], trials=0), ValueError,
     "Experiment.trials"),
    (lambda s: Sweep(name="s", variable="x", values=[], methods=["a"]), ValueError,
     "Sweep.values` must not be empty"),
    (lambda s: Sweep(name="s", variable="x", values="12", methods=["a"]), TypeError,
     "Sweep.values` must be a list"),
    (lambda s: Sweep(name="s", variable="x", values=[1], methods=[""]), TypeError,
     "Sweep.methods"),
    (lambda s: Sweep(name="s", variable="x", values=[1], methods=["a"], base=3), TypeError,
     "Sweep.base"),
    # the method overwrote the swept value: every summary row n = 0, mean NaN
    (lambda s: Sweep(name="s", variable="method", values=["a"], methods=["a"]), ValueError,
     "`Sweep.variable` must not be 'method'"),
    # a repeated value ran twice and doubled its summary rows
    (lambda s: Sweep(name="s", variable="x", values=[0.0, 0.0], methods=["a"]), ValueError,
     r"`Sweep.values` must not repeat an entry .* got 0.0"),
    (lambda s: Sweep(name="s", variable="x", values=[1], methods=["a", "a"]), ValueError,
     r"`Sweep.methods` must not repeat"),
    # json's raw "'<' not supported between 'str' and 'int'" at the first run
    (lambda s: Sweep(name="s", variable="x", values=[1], methods=["a"], base={1: 2}), TypeError,
     r"`Sweep.base` keys must be str"),
    (lambda s: Sweep(name="s", variable="x", values=np.array(1.0), methods=["a"]), TypeError,
     r"`Sweep.values` must be a list"),
    (lambda s: Experiment(name="t", trial=noisy_trial, sweeps=[s], trials=10**30), ValueError,
     r"`Experiment.trials` must be <= 1000000"),
])
def test_malformed_experiments_are_refused_by_name(make, exc, match):
    sweep = Sweep(name="s", variable="x", values=np.arange(3), methods=("a",))   # arrays pass
    with pytest.raises(exc, match=match):
        make(sweep)


def test_mean_se_of_huge_values_and_junk():
    import warnings

    from transync.experiments import mean_se

    with warnings.catch_warnings():
        warnings.simplefilter("error")              # no overflow in the squares
        assert mean_se([1e308, 1e308, None]) == (1e308, 0.0, 2)
    for junk, exc in ((["a"], TypeError), (None, TypeError), ("12", TypeError),
                      (["1"], TypeError)):
        with pytest.raises(exc, match="`values`"):
            mean_se(junk)
    assert mean_se([10**400, 1.0]) == (1.0, 0.0, 1)    # beyond float64: infinite, skipped


def test_run_and_summarize_arguments_are_named(tmp_path):
    from transync.experiments import summarize

    exp = _experiment(trials=1)
    for call, exc, match in (
            (lambda: run_experiment(None, tmp_path), TypeError,
             "`experiment` must be an Experiment"),
            (lambda: run_experiment(exp, None), TypeError,
             r"`out_dir` must be a path \(str or os.PathLike\), got NoneType"),
            (lambda: run_experiment(exp, ""), ValueError, "`out_dir` must be a path, got ''"),
            (lambda: run_experiment(exp, tmp_path, workers=10**6), ValueError,
             r"`workers` must be <= 256"),
            (lambda: run_experiment(exp, tmp_path, trials=10**12), ValueError,
             r"`trials` must be <= 1000000"),
            (lambda: run_experiment(exp, tmp_path, progress="no"), TypeError,
             "`progress` must be a bool, got str 'no'"),
            (lambda: run_experiment(exp, tmp_path, plot=0), TypeError,
             "`plot` must be a bool, got int 0"),
            (lambda: summarize(None, []), TypeError, "`experiment` must be an Experiment"),
            (lambda: summarize(exp, [{"sweep": "s"}]), TypeError,
             r"`records\[0\]` must be a dict with keys"),
            (lambda: summarize(exp, "records"), TypeError, "`records` must be a list")):
        with pytest.raises(exc, match=match):
            call()
    assert not (tmp_path / "results.sqlite").exists()


def test_out_dir_with_a_tilde_is_the_home_folder(tmp_path, monkeypatch):
    """``"~/runs"`` made a folder literally named ``~`` in the working directory."""
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.chdir(tmp_path)
    result = run_experiment(_experiment(trials=1), "~/runs", progress=False, plot=False)
    assert result.out_dir == tmp_path / "home" / "runs"
    assert (tmp_path / "home" / "runs" / "results.sqlite").is_file()
    assert not (tmp_path / "~").exists()


def test_workers_beyond_the_trials_start_no_idle_process(tmp_path, monkeypatch):
    """workers=40 for 2 trials started 40 processes."""
    import concurrent.futures
    import transync.experiments._runner as runner

    sizes = []

    class Recording(concurrent.futures.ProcessPoolExecutor):
        def __init__(self, max_workers=None, **kw):
            sizes.append(max_workers)
            super().__init__(max_workers=max_workers, **kw)

    monkeypatch.setattr(runner, "ProcessPoolExecutor", Recording)
    exp = Experiment(name="t", trial=noisy_trial, trials=1, sweeps=[
        Sweep(name="s", variable="x", values=[1], methods=["a", "b"], metrics=("value",))])
    report = run_experiment(exp, tmp_path, workers=40, progress=False, plot=False)
    assert report.n_new == 2 and sizes == [2]


def interrupting_trial(config, rng):
    if config["method"] == "b":
        raise KeyboardInterrupt
    return {"value": 1.0}


def dying_trial(config, rng):
    import os

    if config["method"] == "b":
        os._exit(3)                     # a worker killed mid-trial (signal, out of memory)
    time.sleep(0.05)
    return {"value": 1.0}


def test_a_pool_stores_every_finished_trial_before_it_reraises(tmp_path, monkeypatch):
    """Two trials finishing together, one interrupted: the loop re-raised on the first it met,
    and the finished one later in the same batch was never stored (0 rows in 7 of 8 runs)."""
    import concurrent.futures as cf

    import transync.experiments._runner as runner   # white-box: both trials done at once

    monkeypatch.setattr(runner, "wait", lambda fs, return_when=None: cf.wait(fs))
    exp = Experiment(name="t", trial=interrupting_trial, trials=1, sweeps=[
        Sweep(name="s", variable="x", values=[1], methods=["a", "b"], metrics=("value",))])
    with pytest.raises(KeyboardInterrupt):
        run_experiment(exp, tmp_path, workers=2, progress=False, plot=False)
    with sqlite3.connect(tmp_path / "results.sqlite") as db:
        rows = db.execute("SELECT config FROM trials").fetchall()
    assert len(rows) == 1 and '"method": "a"' in rows[0][0]


def test_a_dead_worker_is_named_and_the_finished_trials_kept(tmp_path):
    """A worker that died raised a raw BrokenProcessPool naming no trial."""
    from transync.exceptions import ExecutorError

    exp = Experiment(name="t", trial=dying_trial, trials=1, sweeps=[
        Sweep(name="s", variable="x", values=[1], methods=["a", "b"], metrics=("value",))])
    with pytest.raises(ExecutorError, match=r"a worker process died \(.*\) with [12] trial\(s\) "
                                            r"running or queued, the first sweep 's', trial 0, "
                                            r"config \{'x': 1, 'method': '[ab]'\}"):
        run_experiment(exp, tmp_path, workers=2, progress=False, plot=False)


def test_a_trial_that_cannot_reach_the_workers_is_refused_before_any_work(tmp_path):
    """A lambda or a closure failed inside the pool's feeder thread (PicklingError,
    AttributeError, tracebacks on stderr)."""
    exp = Experiment(name="t", trial=lambda c, r: {"value": 1.0}, trials=1, sweeps=[
        Sweep(name="s", variable="x", values=[1, 2], methods=["a"], metrics=("value",))])
    with pytest.raises(TypeError, match=r"`Experiment.trial` must be picklable .* or run it "
                                        r"with workers=1"):
        run_experiment(exp, tmp_path / "o", workers=2, progress=False, plot=False)
    assert not (tmp_path / "o").exists()
    assert run_experiment(exp, tmp_path / "o", progress=False, plot=False).n_new == 2


def test_configurations_must_be_plain_data_and_names_fit_a_file():
    """An object in a configuration was keyed by its address: a rerun repeated every trial.
    A 300-character name failed with a raw OSError after every trial (its figure's file)."""

    class Opt:
        pass

    for kw, where in ((dict(base={"opts": Opt()}), r"Sweep\.base\['opts'\]"),
                      (dict(values=[1, Opt()]), r"Sweep\.values\[1\]"),
                      (dict(base={"opts": {"inner": [1, Opt()]}}),
                       r"Sweep\.base\['opts'\]\['inner'\]\[1\]")):
        with pytest.raises(TypeError, match=where + "` must be plain data"):
            Sweep(name="s", variable="x", **{"values": [1], "methods": ["a"], **kw})
    ok = Sweep(name="s", variable="x", values=[np.int64(1), (2, 3), np.arange(2)],
               methods=["a"], base={"k": {"a": None, "b": [1.5, "x"]}})
    assert len(list(ok.configs())) == 3
    with pytest.raises(ValueError, match="`Experiment.name` names its figure file: at most 200"):
        Experiment(name="x" * 300, trial=noisy_trial, trials=1, sweeps=[ok])


def test_a_finish_hook_that_returns_no_paths_is_named(tmp_path):
    """A finish() returning None failed with "'NoneType' object is not iterable"."""
    sw = Sweep(name="s", variable="x", values=[1], methods=["a"], metrics=("value",))
    exp = Experiment(name="t", trial=noisy_trial, trials=1, sweeps=[sw],
                     finish=lambda records, summary, out: None)
    with pytest.raises(TypeError, match=r"`Experiment.finish` must return the paths of the "
                                        r"files it wrote .* got None \(the trials are stored\)"):
        run_experiment(exp, tmp_path, progress=False)
    assert len(run_experiment(exp, tmp_path, progress=False, plot=False).records) == 1


def test_the_folder_stays_locked_while_the_outputs_are_written(tmp_path):
    """The lock was released before the summary, plot and finish files were written: a second
    run on the same folder was admitted meanwhile and the last writer's summary won."""
    from transync.exceptions import ExperimentStoreError

    refused = []

    def finish(records, summary, out_dir):
        with pytest.raises(ExperimentStoreError, match="another run .* is using the output"):
            run_experiment(_experiment(trials=1), out_dir, progress=False, seed=1)
        refused.append(True)
        return []

    base = _experiment(trials=1)
    exp = Experiment(name=base.name, trial=base.trial, trials=1, sweeps=base.sweeps,
                     finish=finish)
    rep = run_experiment(exp, tmp_path, progress=False)
    assert refused == [True] and rep.n_new == 6
    assert not (tmp_path / "results.sqlite.lock").exists()
    assert run_experiment(_experiment(trials=1), tmp_path, progress=False, seed=1).n_new == 6


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="no FIFOs here")
def test_a_fifo_in_the_output_folder_is_refused_before_any_trial(tmp_path):
    """A FIFO named summary.csv made the run block for ever after every trial was computed."""
    import os

    from transync.exceptions import ExperimentStoreError

    os.mkfifo(tmp_path / "summary.csv")
    with pytest.raises(ExperimentStoreError, match=r"holds summary\.csv, which is neither a "
                                                   r"file nor a folder"):
        run_experiment(_experiment(trials=1), tmp_path, progress=False)
    assert not (tmp_path / "results.sqlite").exists()


def test_more_trials_than_a_run_can_plan_are_refused_at_once(tmp_path):
    """10**6 trials per configuration were accepted for any number of configurations: planning
    176 configurations took minutes and more memory than the machine has, printing nothing."""
    with pytest.raises(ValueError, match=r"`trials`=200000 for the 6 configurations of "
                                         r"experiment 't' is 1200000 trials, more than 1000000 "
                                         r"in one run: ask for at most 166666 trials"):
        run_experiment(_experiment(), tmp_path / "out", trials=200_000, progress=False)
    assert not (tmp_path / "out").exists()
