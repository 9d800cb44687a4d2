"""The `kernels` experiment (thesis Tables 4.2, 4.3, §4.5): data-set resolution and keys, the
Gram cache, the tables and plots from planted records, and a quick run on a TU fixture the tests
write (24 small graphs, 2 classes)."""

import json
import shutil

import numpy as np
import pytest

from transync.experiments import REGISTRY, run_experiment
from transync.experiments import kernels as kx


def write_tu(folder, name="TOY", n_per_class=12, seed=0, labels=True):
    """Class 0: cycles, class 1: stars, 5-8 nodes; node labels = degree (capped at 3)."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True)
    edges, indicator, glabels, nlabels = [], [], [], []
    offset = 0
    for g in range(2 * n_per_class):
        cls = g % 2
        n = int(rng.integers(5, 9))
        if cls == 0:
            e = [(k, (k + 1) % n) for k in range(n)]
        else:
            e = [(0, k) for k in range(1, n)]
        deg = np.zeros(n, int)
        for u, v in e:
            edges += [(u + offset + 1, v + offset + 1), (v + offset + 1, u + offset + 1)]
            deg[u] += 1
            deg[v] += 1
        indicator += [g + 1] * n
        nlabels += np.minimum(deg, 3).tolist()
        glabels.append(1 if cls else -1)
        offset += n
    (folder / f"{name}_A.txt").write_text("".join(f"{u}, {v}\n" for u, v in edges))
    (folder / f"{name}_graph_indicator.txt").write_text("".join(f"{i}\n" for i in indicator))
    (folder / f"{name}_graph_labels.txt").write_text("".join(f"{c}\n" for c in glabels))
    if labels:
        (folder / f"{name}_node_labels.txt").write_text("".join(f"{c}\n" for c in nlabels))
    return folder


@pytest.fixture
def toy(tmp_path):
    return write_tu(tmp_path / "data" / "TOY")


# --------------------------------------------------------------------------- data sets, keys

def test_registered():
    assert REGISTRY["kernels"] == "transync.experiments.kernels"


def test_resolve_sets_folder_parent_and_names(tmp_path, monkeypatch):
    a = write_tu(tmp_path / "tu" / "AAA", name="AAA")
    write_tu(tmp_path / "tu" / "MUTAG", name="MUTAG", seed=1)
    (tmp_path / "tu" / "notes").mkdir()
    assert kx.resolve_sets(a) == {"AAA": a}
    both = kx.resolve_sets(tmp_path / "tu")
    assert list(both) == ["MUTAG", "AAA"]                # DATASETS order first
    assert list(kx.resolve_sets(tmp_path / "tu", sets="AAA")) == ["AAA"]
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path))
    assert list(kx.resolve_sets("AAA,MUTAG")) == ["MUTAG", "AAA"]
    with pytest.raises(FileNotFoundError,
                       match="'NOPE': not a folder, and no such TU set.*found: AAA, MUTAG"):
        kx.resolve_sets("NOPE")
    with pytest.raises(ValueError, match="`sets`: 'BBB' not found; available: AAA, MUTAG"):
        kx.resolve_sets(tmp_path / "tu", sets=["BBB"])
    for empty in (",", [], [" "]):        # --sets , named an internal Sweep.values
        with pytest.raises(ValueError, match="`sets` .* must name at least one data set"):
            kx.resolve_sets(tmp_path / "tu", sets=empty)
    with pytest.raises(ValueError, match="holds no TU data set"):
        kx.resolve_sets(tmp_path / "tu" / "notes")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        kx.resolve_sets(tmp_path / "nowhere" / "x")


def test_keys_follow_content_not_path(tmp_path, toy):
    """Issue: the cmu experiment keyed trials by absolute path. Here a moved copy keeps its
    key (stored trials stay valid) and an edited file changes it."""
    moved = tmp_path / "elsewhere" / "TOY"
    shutil.copytree(toy, moved)
    assert kx.fingerprint(moved) == kx.fingerprint(toy)
    e1, e2 = kx.build(data=toy, out=tmp_path / "o"), kx.build(data=moved, out=tmp_path / "o")
    v1, v2 = e1.sweeps[0].values, e2.sweeps[0].values
    assert v1 == v2 == [f"TOY@{kx.fingerprint(toy)}"]
    assert str(tmp_path) not in json.dumps([dict(sw.base) for sw in e1.sweeps])
    (moved / "TOY_graph_labels.txt").write_text(
        (toy / "TOY_graph_labels.txt").read_text().replace("-1", "2", 1))
    assert kx.fingerprint(moved) != kx.fingerprint(toy)


def test_build_reports_a_broken_set_at_once(toy, tmp_path):
    (toy / "TOY_graph_labels.txt").write_text("1\n")
    with pytest.raises(ValueError, match="TOY_graph_labels.txt"):
        kx.build(data=toy, out=tmp_path)


def test_build_quick_and_full(toy, tmp_path):
    quick = kx.build(quick=True, data=toy, out=tmp_path)
    assert quick.trials == 2 and [sw.name for sw in quick.sweeps] == ["table"]
    assert tuple(quick.sweeps[0].methods) == kx.QUICK_KERNELS
    full = kx.build(data=toy, out=tmp_path)
    assert full.trials == 10 and tuple(full.sweeps[0].methods) == kx.FULL_KERNELS
    assert full.trial.keywords["cache_dir"] == str(tmp_path / "cache")


def test_dimensionality_sweeps_on_mutag_named_sets(tmp_path):
    d = write_tu(tmp_path / "MUTAG", name="MUTAG")
    exp = kx.build(data=d, out=tmp_path)
    names = {sw.name: sw for sw in exp.sweeps}
    assert names["universe"].methods == tuple(f"TAK-lin n+{k}" for k in kx.EXTRA_SLOTS)
    assert names["scales"].methods == tuple(f"TAK-lin T={t}" for t in kx.SCALES)


def test_kernel_params():
    assert kx.kernel_params("TAK-lin") == dict(family="tak", matcher="rrwm",
                                               sync="orthogonal", kernel="linear", scales=10,
                                               extra=0)
    assert kx.kernel_params("TAK-node T=4")["scales"] == 4
    assert kx.kernel_params("TAK-node n+20")["extra"] == 20
    with pytest.raises(ValueError, match="unknown kernel 'XYZ'"):
        kx.kernel_params("XYZ")
    with pytest.raises(ValueError, match="TAK kernels only"):
        kx.kernel_params("WL n+5")


def test_pruning_rule_caps_outliers_and_keeps_small_sets():
    sizes = np.r_[np.full(95, 20), np.full(5, 200)]
    keep, rule = kx.prune(sizes, np.r_[np.zeros(50, int), np.ones(50, int)])
    assert keep.size == 95 and "cap = max(floor(q0.95 of sizes), 30) = 30 nodes" in rule
    keep, rule = kx.prune(np.full(20, 10), np.r_[np.zeros(9, int), np.ones(11, int)])
    assert keep.tolist() == list(range(9, 20))              # a class of 9 < 10 graphs dropped
    keep, _ = kx.prune(np.full(40, 28), np.arange(40) % 2)
    assert keep.size == 40                                  # MUTAG-like: nothing pruned


# --------------------------------------------------------------------------- the cache

def test_save_npz_is_atomic(tmp_path, monkeypatch):
    path = kx.save_npz(tmp_path / "a.npz", K=np.eye(2))
    assert np.load(path)["K"].tolist() == [[1, 0], [0, 1]]

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez", boom)
    with pytest.raises(OSError, match="disk full"):
        kx.save_npz(path, K=np.zeros(3))
    assert np.load(path)["K"].shape == (2, 2)               # the old file is intact
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npz"]


def test_gram_is_computed_once_and_cached(toy, tmp_path, monkeypatch):
    prepared = kx.prepare(str(toy))
    g1 = kx.compute_gram(prepared, "graphlet-3", tmp_path / "cache")
    assert g1.path.exists() and g1.K.shape == (24, 24) and g1.seconds > 0
    import transync.kernels as tk

    monkeypatch.setattr(tk, "graphlet3_kernel", lambda graphs: 1 / 0)
    g2 = kx.compute_gram(prepared, "graphlet-3", tmp_path / "cache")   # read, not computed
    np.testing.assert_array_equal(g1.K, g2.K)
    assert g2.seconds == g1.seconds and g1.min_eig_ratio >= -1e-9


# --------------------------------------------------------------------------- outputs

def _records(sets, methods, reps=4, seed=0):
    """Planted trials: TAK-a beats every baseline by 5 points at every repetition."""
    rng = np.random.default_rng(seed)
    out = []
    for s in sets:
        for t in range(reps):
            base = 0.7 + 0.02 * rng.random()
            folds_id = float(1000 + t)
            for m in methods:
                acc = base + {"TAK-a": 0.05, "TAK-b": 0.0, "B1": 0.0, "B2": -0.01}[m] \
                    + {"TAK-a": 0.002, "TAK-b": 0.02}.get(m, 0.0) * (rng.random() - 0.5)
                metrics = {"accuracy": acc, "gram_seconds": 1.5, "folds_id": folds_id}
                metrics.update({f"fold_{k}": acc for k in range(10)})
                metrics.update({f"C_{k}": 1.0 for k in range(10)})
                out.append(dict(sweep="table", config={"dataset": s, "method": m}, trial=t,
                                metrics=metrics, error=None, seconds=1.0))
    return out


def test_tables_from_planted_records(tmp_path):
    sets = ["A@00000000", "B@11111111"]
    recs = _records(sets, ["TAK-a", "TAK-b", "B1", "B2"])
    table = kx._by(recs, "table")
    t42 = kx._table_4_2(table, sets, ["TAK-a", "TAK-b", "B1", "B2"], {}, tmp_path).read_text()
    row = next(line for line in t42.splitlines() if line.startswith("| TAK-a |"))
    assert row.count("**") == 4                              # best on both sets
    assert "| B1 | 7" in t42 and "**" not in next(
        line for line in t42.splitlines() if line.startswith("| B1 |"))
    t43 = kx._table_4_3(table, sets, ["TAK-a", "TAK-b", "B1", "B2"], tmp_path).read_text()
    a_row = next(line for line in t43.splitlines() if line.startswith("| TAK-a |"))
    assert a_row.count("**p=") == 2 and "(+5.0)" in a_row    # +5 points at every repetition
    b_row = next(line for line in t43.splitlines() if line.startswith("| TAK-b |"))
    assert "**" not in b_row.split("|")[2]                   # TAK-b vs B1: small noise only


def test_t_test_refuses_unpaired_folds(tmp_path):
    sets = ["A@0"]
    recs = _records(sets, ["TAK-a", "B1"])
    for r in recs:
        if r["config"]["method"] == "B1":
            r["metrics"]["folds_id"] += 7
    text = kx._table_4_3(kx._by(recs, "table"), sets, ["TAK-a", "B1"], tmp_path).read_text()
    assert "folds differ" in text


def test_psd_table_and_spectra_plot(tmp_path):
    cache = tmp_path / "cache"
    rng = np.random.default_rng(0)
    X = rng.normal(size=(12, 3))
    psd = X @ X.T
    indefinite = psd - 0.5 * np.eye(12) * np.abs(np.linalg.eigvalsh(psd)).max()
    for m, K in (("TAK-lin", psd), ("HKS-OA", indefinite)):
        kx.save_npz(kx.gram_path(cache, "S@1", m), K=K, spectrum=np.linalg.eigvalsh(K), seconds=1.0,
                    params=np.str_("{}"))
    spectra = kx._spectra(["S@1"], ["TAK-lin", "HKS-OA"], cache)
    text = kx._psd(spectra, ["S@1"], ["TAK-lin", "HKS-OA"], tmp_path).read_text()
    assert "| TAK-lin | ✓" in text and "| HKS-OA | ✗ -" in text
    png = kx._plot_spectra(spectra, ["S@1"], ["TAK-lin", "HKS-OA"], tmp_path)
    assert png.stat().st_size > 1000


def test_spectra_survive_a_finish_without_the_gram_cache(tmp_path):
    """The spectra a finish saw are kept beside the tables; a later finish whose cache lacks
    them (cleared, another machine) reuses them, and a recomputed Gram matrix wins."""
    import shutil

    cache, out = tmp_path / "cache", tmp_path / "out"
    rng = np.random.default_rng(1)
    X = rng.normal(size=(8, 3))
    K = X @ X.T
    kx.save_npz(kx.gram_path(cache, "S@1", "TAK-lin"), K=K, spectrum=np.linalg.eigvalsh(K),
                seconds=1.0, params=np.str_("{}"))
    first = kx._spectra(["S@1"], ["TAK-lin", "WL"], cache, out)
    assert list(first) == [("S@1", "TAK-lin")] and (out / kx.SPECTRA_FILE).exists()
    shutil.rmtree(cache)
    again = kx._spectra(["S@1"], ["TAK-lin", "WL"], cache, out)
    np.testing.assert_array_equal(again[("S@1", "TAK-lin")], first[("S@1", "TAK-lin")])
    assert "| TAK-lin | ✓" in kx._psd(again, ["S@1"], ["TAK-lin"], out).read_text()
    new = np.arange(8.0)
    kx.save_npz(kx.gram_path(cache, "S@1", "TAK-lin"), K=K, spectrum=new, seconds=1.0,
                params=np.str_("{}"))
    np.testing.assert_array_equal(kx._spectra(["S@1"], ["TAK-lin"], cache, out)
                                  [("S@1", "TAK-lin")], new)
    other = kx._spectra(["T@2"], ["WL"], tmp_path / "none", out)     # other sets: kept
    assert other == {}
    assert set(kx._load_npz(out / kx.SPECTRA_FILE)) == {"S@1::TAK-lin"}


def test_dimensionality_plot(tmp_path):
    recs = []
    for s in ("MUTAG@1", "PTC_MR@2"):
        for t in range(3):
            for k in kx.EXTRA_SLOTS:
                recs.append(dict(sweep="universe", config={"dataset": s,
                                                           "method": f"TAK-lin n+{k}"},
                                 trial=t, metrics={"accuracy": 0.8 - 0.001 * k}, error=None))
            for T in kx.SCALES:
                recs.append(dict(sweep="scales", config={"dataset": s, "method": f"TAK-lin T={T}"},
                                 trial=t, metrics={"accuracy": 0.7 + 0.01 * T}, error=None))
    assert kx._plot_dimensionality(recs, tmp_path).stat().st_size > 1000
    assert kx._plot_dimensionality([], tmp_path) is None


# --------------------------------------------------------------------------- end to end

def test_run_on_fixture_resumes_without_recomputing(toy, tmp_path, monkeypatch):
    exp = kx.build(quick=True, data=toy, out=tmp_path / "out", kernels=["graphlet-3"], folds=3)
    rep = run_experiment(exp, tmp_path / "out", progress=False, plot=False)
    assert rep.n_failed == 0 and rep.n_new == 2
    assert [r["metrics"]["accuracy"] for r in rep.records] == [1.0, 1.0]   # cycles vs stars
    assert len({r["metrics"]["folds_id"] for r in rep.records}) == 2       # one per repetition
    assert len(list((tmp_path / "out" / "cache").rglob("gram-*.npz"))) == 1
    import transync.kernels as tk

    monkeypatch.setattr(tk, "graphlet3_kernel", lambda graphs: 1 / 0)
    again = run_experiment(exp, tmp_path / "out", progress=False, trials=3, plot=False)
    assert again.n_new == 1 and again.n_failed == 0   # third repetition: cached Gram matrix


@pytest.mark.parametrize("method, kernel", [("TAK-node", "linear"),
                                            ("TAK-node-gauss", "gaussian")])
def test_tak_gram_equals_the_estimators(toy, tmp_path, method, kernel):
    """The experiment computes the TAK variants from one cached alignment: each must equal
    the estimator's own Gram matrix for that kernel."""
    from transync.kernels import TransitiveAssignmentKernel

    prepared = kx.prepare(str(toy))
    ours = kx.compute_gram(prepared, method, tmp_path / "cache").K
    est = TransitiveAssignmentKernel(matcher="node", kernel=kernel, times=kx._times(10),
                                     random_state=0)
    np.testing.assert_allclose(ours, est.fit_transform(list(prepared.graphs)), atol=1e-10)
    assert len(list((tmp_path / "cache").rglob("alignment-*.npz"))) == 1


@pytest.mark.parametrize("method, neighbors", [("TAK-node-gauss-bag5", None),
                                               ("TAK-node-gauss-k10-bag5", 10)])
def test_ensemble_gram_equals_the_estimators(toy, tmp_path, method, neighbors):
    """The ensemble kernels reuse the cached pairwise maps of their single-alignment kernel
    (one pairwise file for both) and equal the estimator's n_alignments=5 Gram matrix."""
    from transync.kernels import TransitiveAssignmentKernel

    prepared = kx.prepare(str(toy))
    single = method.replace("-bag5", "")
    kx.compute_gram(prepared, single, tmp_path / "cache")
    ours = kx.compute_gram(prepared, method, tmp_path / "cache")
    assert len(list((tmp_path / "cache").rglob("pairwise-*.npz"))) == 1
    est = TransitiveAssignmentKernel(matcher="node", kernel="gaussian", times=kx._times(10),
                                     n_neighbors=neighbors, n_alignments=5, random_state=0)
    np.testing.assert_allclose(ours.K, est.fit_transform(list(prepared.graphs)), atol=1e-10)
    assert ours.seconds > 0 and np.isfinite(ours.cpu_seconds) and ours.min_eig_ratio >= -1e-9


@pytest.mark.parametrize("kernel", ["linear", "gaussian"])
def test_non_transitive_gram_uses_the_tak_maps(toy, tmp_path, kernel):
    """NT-lin / NT-gauss: the pairwise kernel on the very RRWM maps TAK-lin synchronizes (one
    pairwise file for both), equal to pairwise_assignment_kernel on the estimator's maps."""
    from transync.kernels import TransitiveAssignmentKernel, pairwise_assignment_kernel

    prepared = kx.prepare(str(toy))
    method = "NT-lin" if kernel == "linear" else "NT-gauss"
    ours = kx.compute_gram(prepared, method, tmp_path / "cache")
    kx.compute_gram(prepared, "TAK-lin", tmp_path / "cache")
    pw_files = list((tmp_path / "cache").rglob("pairwise-*.npz"))
    assert len(pw_files) == 1
    with np.load(pw_files[0]) as z:          # the synchronization's share of the fit's time
        assert 0 < z["sync_seconds"] < z["seconds"]
    est = TransitiveAssignmentKernel(matcher="rrwm", times=kx._times(10), random_state=0)
    est.fit(list(prepared.graphs))
    want = pairwise_assignment_kernel(est.kernel_features_, est.assignments_, est.pairs_,
                                      kernel=kernel)
    np.testing.assert_allclose(ours.K, want, atol=1e-12)
    assert ours.seconds > 0 and np.isfinite(ours.cpu_seconds)
    with pytest.raises(ValueError, match="TAK kernels only"):
        kx.kernel_params(f"{method} n+5")


# ---------------------------------------------------------------------------------------------
# view-graph kernels on the larger sets, per-set kernel lists, Gram memory, repetitions per set
# ---------------------------------------------------------------------------------------------

def test_view_kernel_params_keep_the_all_pairs_keys():
    assert "neighbors" not in kx.kernel_params("TAK-lin")      # cached entries stay valid
    p = kx.kernel_params("TAK-node-k10")
    assert p["neighbors"] == 10 and p["matcher"] == "node"
    assert kx.kernel_params("TAK-lin-k10 n+5")["extra"] == 5


def test_per_set_kernel_lists(tmp_path):
    for name in ("MUTAG", "NCI1"):
        write_tu(tmp_path / name, name=name, n_per_class=10)
    exp = kx.build(data=tmp_path, out=tmp_path / "out", dimensionality=False)
    table = exp.sweeps[0]
    per_set = {}
    for value, method, _config in table.configs():
        per_set.setdefault(value.split("@")[0], []).append(method)
    assert per_set["MUTAG"] == list(kx.FULL_KERNELS)
    nci1 = per_set["NCI1"]
    assert not set(nci1) & set(kx.SKIP["NCI1"])
    assert "TAK-node-k10" in nci1 and "HKS-OA" in nci1 and "WL-OA" not in nci1
    assert not any(m in nci1 for m in ("TAK-lin", "TAK-node", "RW"))
    # an explicit kernel list is run as given (minus the skips), without the extra kernels
    only = kx.build(data=tmp_path, out=tmp_path / "o2", kernels=["WL", "RW"],
                    dimensionality=False)
    assert [(v.split("@")[0], m) for v, m, _ in only.sweeps[0].configs()] == [
        ("MUTAG", "WL"), ("MUTAG", "RW"), ("NCI1", "WL")]


def test_view_graph_gram_records_time_and_memory(tmp_path):
    d = write_tu(tmp_path / "TOY", n_per_class=10)
    prepared = kx.prepare(str(d))
    entry = kx.compute_gram(prepared, "TAK-node-k10", tmp_path / "cache")
    assert entry.seconds > 0 and entry.peak_mb > 10
    assert kx.compute_gram(prepared, "TAK-node-k10", tmp_path / "cache").peak_mb == entry.peak_mb
    assert entry.min_eig_ratio >= -1e-9
    assert len(list((tmp_path / "cache").rglob("alignment-node-*.npz"))) == 1


def test_table_states_repetitions_per_set(tmp_path):
    def rec(ds, t, acc):
        m = {"accuracy": acc, "gram_seconds": 1.0, "gram_peak_mb": 100.0, "folds_id": 1.0,
             "fold_0": acc, "fold_1": acc}
        return dict(sweep="table", config={"dataset": ds, "method": "WL"}, trial=t,
                    metrics=m, error=None, seconds=0.1)

    records = [rec("A@1", t, 0.8) for t in range(3)] + [rec("B@2", 0, 0.7)]
    path = kx._table_4_2(kx._by(records, "table"), ["A@1", "B@2"], ["WL"], {}, tmp_path)
    text = path.read_text()
    assert "| *repetitions* | 3 | 1 |" in text
    assert "| WL | **80.0 ± 0.0** | **70.0 ± 0.0** |" in text
    assert "Peak memory" in text and "| WL | 100 | 100 |" in text
    assert "| WL | 1 | 1 |" in text                      # no CPU time recorded: wall only


@pytest.mark.parametrize("bad", [0, "x"])
def test_bad_neighbors_in_estimator_message(bad):
    from transync.kernels import TransitiveAssignmentKernel

    with pytest.raises((ValueError, TypeError), match="n_neighbors"):
        TransitiveAssignmentKernel(n_neighbors=bad)._check_params()
