"""The experiment store's promises (issue 13): seed in the key, self-contained results.sqlite,
workers that die with their parent, clean Ctrl-C, corrupted/read-only/locked folders."""

import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time

import pytest

from transync.exceptions import ExperimentStoreError
from transync.experiments import Experiment, Sweep, run_experiment

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="process checks read /proc")


def draw_trial(config, rng):
    return {"v": float(config["x"]), "draw": float(rng.random())}


def _exp(trials=3):
    return Experiment(name="st", trial=draw_trial, trials=trials, sweeps=[
        Sweep(name="s", variable="x", values=[0, 1], methods=["m"], metrics=("v",))])


def _count(db):
    con = sqlite3.connect(db)
    try:
        return con.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
    finally:
        con.close()


def test_seed_is_part_of_the_configuration_key(tmp_path):
    first = run_experiment(_exp(), tmp_path, progress=False, plot=False)
    other = run_experiment(_exp(), tmp_path, seed=1, progress=False, plot=False)
    again = run_experiment(_exp(), tmp_path, seed=1, progress=False, plot=False)
    assert (first.n_new, other.n_new, again.n_new) == (6, 6, 0)
    # each run reports its own seed's trials only, and they differ
    assert len(other.records) == len(again.records) == 6
    draws = lambda rep: {r["metrics"]["draw"] for r in rep.records}  # noqa: E731
    assert draws(first).isdisjoint(draws(other)) and draws(other) == draws(again)
    assert _count(tmp_path / "results.sqlite") == 12


def test_results_file_alone_holds_every_trial(tmp_path):
    run_experiment(_exp(), tmp_path / "run", progress=False, plot=False)
    names = sorted(p.name for p in (tmp_path / "run").iterdir())
    assert not any(n.endswith(("-wal", "-shm", "-journal", ".lock")) for n in names), names
    (tmp_path / "copy").mkdir()
    shutil.copy(tmp_path / "run" / "results.sqlite", tmp_path / "copy" / "results.sqlite")
    assert _count(tmp_path / "copy" / "results.sqlite") == 6


def test_corrupted_store_is_reported_and_left_untouched(tmp_path):
    db = tmp_path / "results.sqlite"
    db.write_bytes(b"not a database at all" * 100)
    before = db.read_bytes()
    with pytest.raises(ExperimentStoreError, match=r"results\.sqlite is not a readable "
                                                   r"experiment store .*\.recover") as exc:
        run_experiment(_exp(), tmp_path, progress=False, plot=False)
    assert str(db) in str(exc.value)
    assert db.read_bytes() == before
    # a real store with damaged pages
    run_experiment(_exp(trials=8), tmp_path / "b", progress=False, plot=False)
    db = tmp_path / "b" / "results.sqlite"
    data = bytearray(db.read_bytes())
    data[4096:8192] = b"\xff" * 4096
    db.write_bytes(bytes(data))
    with pytest.raises(ExperimentStoreError, match="salvage"):
        run_experiment(_exp(trials=8), tmp_path / "b", progress=False, plot=False)
    assert db.read_bytes() == bytes(data)


def test_unwritable_folder_is_named_and_no_folder_left(monkeypatch, tmp_path):
    out = tmp_path / "new"
    real = os.access
    monkeypatch.setattr(os, "access",
                        lambda p, mode, **kw: False if str(p) == str(out) else real(p, mode, **kw))
    with pytest.raises(ExperimentStoreError, match=f"output folder {out} is not writable"):
        run_experiment(_exp(), out, progress=False, plot=False)
    assert not out.exists()
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(ExperimentStoreError, match="exists and is not a folder"):
        run_experiment(_exp(), afile, progress=False, plot=False)


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0,
                    reason="needs a non-root POSIX user (root ignores permissions)")
def test_read_only_folder_real_permissions(tmp_path):  # pragma: no cover - CI runs as root
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(ExperimentStoreError, match="not writable"):
            run_experiment(_exp(), ro, progress=False, plot=False)
    finally:
        ro.chmod(0o755)


SLOW = """
import os, sys, time
from transync.experiments import Experiment, Sweep, REGISTRY, run_experiment

def trial(config, rng):
    time.sleep(float(os.environ.get("SLOW_SLEEP", "0.2")))
    return {"v": float(config["x"])}

EXP = Experiment(name="slow", trial=trial, trials=8, description="slow toy", sweeps=[
    Sweep(name="s", variable="x", values=[0, 1], methods=["m"], metrics=("v",))])

def build(*, quick=False):
    return EXP

if __name__ == "__main__":
    sys.modules.setdefault("slowexp", sys.modules["__main__"])
    if sys.argv[1] == "cli":
        REGISTRY["slow"] = "slowexp"
        from transync.cli import main
        sys.exit(main(["experiment", "slow", "--no-progress", *sys.argv[2:]]))
    run_experiment(EXP, sys.argv[2], workers=int(sys.argv[3]), progress=False, plot=False)
"""


@pytest.fixture
def slow_script(tmp_path, monkeypatch):
    monkeypatch.setenv("SLOW_SLEEP", "0.2")        # the subprocess runs are slow ...
    path = tmp_path / "slowexp.py"
    path.write_text(textwrap.dedent(SLOW))
    return path


def _wait_for_rows(db, n, proc, timeout=60):
    deadline = time.time() + timeout
    while time.time() < deadline:
        assert proc.poll() is None, "the run ended before it was interrupted"
        if db.exists():
            try:
                if _count(db) >= n:
                    return
            except sqlite3.Error:
                pass
        time.sleep(0.05)
    raise AssertionError(f"fewer than {n} trials stored after {timeout} s")


def _children(pid):
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    fields = fh.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                out.append(int(entry))
    return out


def _alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@linux_only
def test_kill_9_leaves_no_workers_and_a_self_contained_store(tmp_path, slow_script):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, str(slow_script), "lib", str(out), "2"],
                            cwd=tmp_path)
    try:
        _wait_for_rows(out / "results.sqlite", 4, proc)
        workers = _children(proc.pid)
        assert len(workers) >= 2
        committed = _count(out / "results.sqlite")
    finally:
        proc.kill()
        proc.wait()
    deadline = time.time() + 10
    while time.time() < deadline and any(_alive(w) for w in workers):
        time.sleep(0.05)
    orphans = [w for w in workers if _alive(w)]
    for w in orphans:                                   # do not leak them if the check fails
        os.kill(w, signal.SIGKILL)
    assert not orphans, "worker processes outlived their parent"
    (tmp_path / "copy").mkdir()
    shutil.copy(out / "results.sqlite", tmp_path / "copy" / "results.sqlite")   # file alone
    copied = _count(tmp_path / "copy" / "results.sqlite")
    assert committed <= copied == _count(out / "results.sqlite") < 16
    rep = run_experiment(_load(slow_script).EXP, out, progress=False, plot=False)
    assert rep.n_new == 16 - copied and len(rep.records) == 16


def _load(path):
    """The script's module, its trials made instant (... the in-process resumes are fast)."""
    import importlib.util

    os.environ["SLOW_SLEEP"] = "0"             # restored by the fixture's monkeypatch

    spec = importlib.util.spec_from_file_location("slowexp_test", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@linux_only
@pytest.mark.parametrize("workers", ["1", "2"])
def test_ctrl_c_stops_cleanly_and_says_how_to_resume(tmp_path, slow_script, workers):
    out = tmp_path / "out"
    # a terminal's process: SIGINT at its default, even when the test suite itself runs in the
    # background of a non-interactive shell (which starts its jobs with SIGINT ignored)
    proc = subprocess.Popen([sys.executable, str(slow_script), "cli", "--out", str(out),
                             "--workers", workers], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        _wait_for_rows(out / "results.sqlite", 3, proc)
        workers = _children(proc.pid)
        os.killpg(proc.pid, signal.SIGINT)           # as a terminal's Ctrl-C: the whole group
        _stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    assert "run the same command again to resume" in stderr and str(out) in stderr
    assert not any(_alive(w) for w in workers)
    stored = _count(out / "results.sqlite")
    assert 3 <= stored < 16
    rep = run_experiment(_load(slow_script).EXP, out, progress=False, plot=False)
    assert rep.n_new == 16 - stored


def test_second_run_on_the_same_folder_is_refused(tmp_path, slow_script):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, str(slow_script), "lib", str(out), "1"],
                            cwd=tmp_path)
    try:
        _wait_for_rows(out / "results.sqlite", 1, proc)
        with pytest.raises(ExperimentStoreError,
                           match=rf"another run \(pid {proc.pid}\) is using the output folder"):
            run_experiment(_load(slow_script).EXP, out, progress=False, plot=False)
    finally:
        proc.kill()
        proc.wait()
    # the killed run's lock died with it: the folder can be resumed
    rep = run_experiment(_load(slow_script).EXP, out, progress=False, plot=False)
    assert len(rep.records) == 16 and _count(out / "results.sqlite") == 16


def test_second_run_in_the_same_process_is_refused(tmp_path):
    def nested(config, rng):                      # tries to start a run on its own folder
        try:
            run_experiment(_exp(), tmp_path, progress=False, plot=False)
        except ExperimentStoreError as exc:
            return {"refused": float("another run (pid" in str(exc))}
        return {"refused": 0.0}

    exp = Experiment(name="nest", trial=nested, trials=1, sweeps=[
        Sweep(name="s", variable="x", values=[0], methods=["m"], metrics=("refused",))])
    rep = run_experiment(exp, tmp_path, progress=False, plot=False)
    assert [r["metrics"]["refused"] for r in rep.records] == [1.0]
    assert _count(tmp_path / "results.sqlite") == 1          # the nested run stored nothing
    assert run_experiment(_exp(), tmp_path, progress=False, plot=False).n_new == 6


def test_run_interrupted_before_any_trial_leaves_no_folder(tmp_path):
    def interrupted(config, rng):
        raise KeyboardInterrupt

    exp = Experiment(name="int", trial=interrupted, trials=2, sweeps=[
        Sweep(name="s", variable="x", values=[0], methods=["m"], metrics=("v",))])
    with pytest.raises(KeyboardInterrupt):
        run_experiment(exp, tmp_path / "new", progress=False, plot=False)
    assert not (tmp_path / "new").exists()
    (tmp_path / "old").mkdir()                        # a folder that existed stays
    with pytest.raises(KeyboardInterrupt):
        run_experiment(exp, tmp_path / "old", progress=False, plot=False)
    assert (tmp_path / "old").is_dir()


def test_refused_run_never_removes_the_running_runs_store(monkeypatch, tmp_path):
    """Two runs start together on a folder that does not exist yet: the one refused by the lock
    must not clean up (it would delete the store of the run that holds the folder)."""
    import transync.experiments._runner as runner   # white-box: interleave the two runs

    out = tmp_path / "race"
    real_prepare = runner._prepare_folder
    holder = {}

    def prepare_then_other_run_takes_the_folder(folder):
        real_prepare(folder)
        if holder:                             # the store prepares its folder too
            return
        holder["busy"] = True
        lock = runner._FolderLock(folder)      # the other run: holds the lock, empty store
        lock.__enter__()
        holder["lock"] = lock
        holder["store"] = runner.ExperimentStore(folder / "results.sqlite")

    monkeypatch.setattr(runner, "_prepare_folder", prepare_then_other_run_takes_the_folder)
    with pytest.raises(ExperimentStoreError, match="another run"):
        run_experiment(_exp(), out, progress=False, plot=False)
    assert (out / "results.sqlite").exists()
    holder["store"].close()
    holder["lock"].__exit__(None, None, None)
    monkeypatch.setattr(runner, "_prepare_folder", real_prepare)
    report = run_experiment(_exp(), out, progress=False, plot=False)
    assert report.n_new == len(report.records) > 0 and report.n_other == 0


def test_trials_of_other_seeds_are_counted_not_reported(tmp_path):
    first = run_experiment(_exp(), tmp_path / "s", progress=False, plot=False)
    second = run_experiment(_exp(), tmp_path / "s", seed=1, progress=False, plot=False)
    assert second.n_new == len(second.records) == len(first.records)
    assert second.n_other == len(first.records)


def test_a_bad_row_leaves_the_store_open_and_intact(tmp_path):
    """add(None, ...) was reported as "not a readable experiment store ... salvage" and closed
    the connection: every later call raised AttributeError. Rows are checked before the
    transaction now; a closed store says so."""
    from transync.experiments import ExperimentStore

    store = ExperimentStore(tmp_path / "r.sqlite")
    store.add("e", "k", 0, "s", {"x": 1}, {"a": 1.0}, None, 0.1)
    bad = [((None, "k", 0, "s", {}, {}, None, 0.1), TypeError, "`experiment` must be a non-empty"),
           (("e", "k", 2**70, "s", {}, {}, None, 0.1), ValueError, r"`trial` must lie in"),
           (("e", "k", "zero", "s", {}, {}, None, 0.1), TypeError, "`trial` must be an int"),
           (("e", "k", 1, "s", {}, {"a": "x"}, None, 0.1), TypeError,
            "`metrics` must map str names to real numbers"),
           (("e", "k", 1, "s", {1: 2}, {}, None, 0.1), TypeError, "`config` must be a dict"),
           (("e", "k", 1, "s", {}, {}, 3, 0.1), TypeError, "`error` must be None or a str"),
           (("e", "k", 1, "s", {}, {}, None, float("nan")), ValueError, "`seconds` must be"),
           (("e", "k", 1, "s", {}, {}, None, 10**400), ValueError, "`seconds` must be a finite"),
           (("e", "k", 1, "s", {}, {}, None, "1"), TypeError, "`seconds` must be a number"),
           (("e", "k", 1, "s", {}, {"a": 10**400}, None, 0.1), ValueError,
            r"`metrics\['a'\]` must fit in float64")]
    for args, exc, match in bad:
        with pytest.raises(exc, match=match):
            store.add(*args)
    # a wrong `experiment` in a query blamed the file ("not a readable experiment store ...
    # salvage") and closed the store
    for query in (store.records, store.done):
        with pytest.raises(TypeError, match=r"`experiment` must be a non-empty string, got \['e'\]"):
            query(["e"])
    rows = store.records("e")
    assert len(rows) == 1 and rows[0]["metrics"] == {"a": 1.0}
    store.add("e", "k", 1, "s", {}, {"ok": True}, None, 0.1)   # bools count 0/1, as in trials
    assert store.records("e")[1]["metrics"] == {"ok": 1.0}
    store.add("e", "k", 1, "s", {}, {"a": 1.0}, None, 0.1)     # replaces trial 1
    assert store.done("e") == {("k", 0), ("k", 1)}
    store.close()
    with pytest.raises(ExperimentStoreError, match="is closed"):
        store.records("e")
    with pytest.raises(TypeError, match=r"`path` must be a path \(str or os.PathLike\)"):
        ExperimentStore(None)
    with pytest.raises(ValueError, match="`path` must be a path, got ''"):
        ExperimentStore("")


def test_rows_damaged_outside_transync_are_named(tmp_path):
    """A row whose metrics were not JSON said only "Expecting value: line 1 column 1"; a string
    metric or a config that is not an object failed later in mean_se / summarize without naming
    the store. A store path that is a folder was blamed on permissions."""
    from transync.experiments import ExperimentStore

    path = tmp_path / "r.sqlite"
    store = ExperimentStore(path)
    store.add("e", "k", 0, "s", {"x": 1}, {"a": 1.0}, None, 0.1)
    store.close()
    for column, text in (("metrics", "{oops"), ("metrics", '{"a": "x"}'), ("config", "[1, 2]")):
        con = sqlite3.connect(path)
        con.execute(f"UPDATE trials SET {column} = ?", (text,))
        con.commit()
        con.close()
        store = ExperimentStore(path)
        with pytest.raises(ExperimentStoreError, match=r"r.sqlite, row \(experiment='e', "
                                                       r"sweep='s', config hash k, trial=0\)"):
            store.records("e")
        store.close()
        con = sqlite3.connect(path)
        con.execute("UPDATE trials SET config = ?, metrics = ?", ('{"x": 1}', '{"a": 1.0}'))
        con.commit()
        con.close()
    (tmp_path / "dir.sqlite").mkdir()
    with pytest.raises(ExperimentStoreError, match="it is a folder, not a file"):
        ExperimentStore(tmp_path / "dir.sqlite")
