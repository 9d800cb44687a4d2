"""transync vs pygmtools and pylibmgm on identical multi-graph matching problems.

Problems: :func:`transync.datasets.make_graph_collection` with Yan et al.'s preset (``n``
inliers, no outliers, deformation 0.05, edge density 1, node orders shuffled), one collection of
``N`` graphs per setting and trial, regenerated bit-identically from the seed for every method.
Affinity: Cho et al.'s Gaussian edge affinity ``exp(-(e_ij - e'_ab)^2 / sigma2)`` on the edge
attributes, ``sigma2 = 0.05`` (Yan), the same ``K`` for every tool that takes a ``K``.

Methods (``--methods``; the reference for every ratio is ``ts-s-rrwm``):

* ``ts-s-rrwm``: transync S-RRWM, ``match_collection(solver="rrwm", sync="birkhoff",
  mode="online")`` (all pairs in lock-step, Birkhoff synchronization steering the iterates).
* ``ts-rrwm``: transync pairwise RRWM of every pair, no synchronization (the baseline).
* ``ts-rrwm+birkhoff`` / ``ts-rrwm+spectral``: the same pairwise RRWM, then one offline
  synchronization.
* ``ts-cao-pc``: transync's CAO-PC (Yan et al. TPAMI 2016) from pairwise RRWM.
* ``pg-cao`` / ``pg-mgm-floyd``: pygmtools 0.6 ``cao`` / ``mgm_floyd`` (numpy backend, defaults:
  its own pairwise RRWM start) on the dense ``(N, N, n^2, n^2)`` K built with
  ``pygmtools.utils.build_aff_mat`` + ``gaussian_aff_fn(sigma=sigma2)`` (checked equal to
  transync's affinity, ``meta.k_check_max_abs_diff``). Mode (``--pg-mode auto``): ``cao`` in
  ``"memory"`` mode (at N=8, n=20 its ``"time"`` mode was 3x slower with an 8x higher peak),
  ``mgm_floyd`` in ``"time"`` mode (faster, same peak).
* ``pg-gamgm`` / ``pg-gamgm-doc``: pygmtools ``gamgm``. It takes no K: it maximizes the
  Koopmans-Beckmann objective ``sum_ij tr(X_ij^T A_i X_ij A_j)`` on adjacency matrices. It gets
  the same edge attributes, centred on the edges (``A_i = E_i - 0.5`` off the diagonal; on
  complete graphs the centring changes the objective on permutations by a constant only), and
  zero node similarities. So gamgm solves a *different model* on the same data: the squared
  edge-attribute discrepancy instead of the Gaussian affinity. ``pg-gamgm`` uses gamgm's
  defaults; ``pg-gamgm-doc`` the Sinkhorn temperatures of pygmtools' own gamgm docstring example
  (``sk_init_tau=0.1, sk_min_tau=0.01``).
* ``mgm-solve``: pylibmgm's GREEDA multi-graph solver ``solver.solve_mgm_parallel`` (library
  default optimization level EXHAUSTIVE) on the same QAP: libmgm *minimizes* cost, so every
  pair's model gets the negated affinity, unary ``-K[a, a]`` and one edge per unordered pair of
  assignments with cost ``-2 K[a, b]`` (libmgm stores an edge once; ``x^T K x`` counts it
  twice). Then ``-evaluate()`` equals transync's total score. Build = one Python call per
  assignment and per edge (pylibmgm has no batched setter); its time is reported as a stage.
* ``mgm-sync``: pylibmgm ``solver.synchronize_solution`` (GREEDA on the synchronization problem,
  library defaults: 3 restarts, EXHAUSTIVE) applied to transync's pairwise RRWM maps (the
  ``ts-rrwm`` input), ``feasible=False`` (every assignment allowed, like the other
  synchronizers; with complete K this is the same search space as ``feasible=True``).

Every (setting, trial, method) runs in its own subprocess: the same problem, a time cap
(``--cap``, the whole subprocess; a method that hits it is recorded as ``timeout`` and skipped at
every setting with no smaller ``N`` and ``n``), memory caps predicted from the problem size
(``--max-mem-gb``; recorded as ``skipped`` with the reason) and a clean peak-memory reading: **peak RSS** of the child (Linux
``VmHWM``, reset through ``/proc/self/clear_refs`` after the imports and the problem generation)
minus its RSS at that moment, so native allocations (pylibmgm's C++ cost maps) count too.
Times are wall-clock seconds from the graphs to the final pairwise maps, **affinity construction
included** (stages in ``stages``). Accuracy: fraction of the true correspondences recovered over
the pairs ``i < j`` (:func:`transync.metrics.multimatching_accuracy`); consistency:
``1 - cycle_error`` of the output maps over all triangles (sampled beyond 200k,
:func:`transync.permutations.cycle_inconsistency_arrays`), 1.0 = cycle-consistent; score: total
``x^T K x`` over the pairs.

Results are saved after every method (``--out``, atomically) and a re-run skips what is stored,
so an interrupted run resumes.

Usage::

    python benchmarks/multigraph.py --quick
    python benchmarks/multigraph.py --out benchmarks/results/multigraph.json
    python benchmarks/multigraph.py --sizes 32x20 --methods ts-s-rrwm pg-cao mgm-solve
    python benchmarks/multigraph.py --scale --out benchmarks/results/multigraph_scale.json
    python benchmarks/multigraph.py --fit benchmarks/results/multigraph.json
    python benchmarks/multigraph.py --markdown benchmarks/results/multigraph.json [--wide time]
    python benchmarks/multigraph.py --sizes 8x10 32x20 --deformation 0.15 \\
        --out benchmarks/results/multigraph_hard.json      # a harder problem family

The README's runs used ``--threads 1`` (transync limits BLAS to one thread itself).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REFERENCE = "ts-s-rrwm"
TS_METHODS = {
    "ts-s-rrwm": dict(solver="rrwm", sync="birkhoff", mode="online"),
    "ts-rrwm": dict(solver="rrwm", sync=None, mode="offline"),
    "ts-rrwm+birkhoff": dict(solver="rrwm", sync="birkhoff", mode="offline"),
    "ts-rrwm+spectral": dict(solver="rrwm", sync="spectral", mode="offline"),
    "ts-cao-pc": dict(solver="cao-pc", sync=None, mode="offline"),
}
PG_METHODS = ("pg-cao", "pg-mgm-floyd", "pg-gamgm", "pg-gamgm-doc")
MGM_METHODS = ("mgm-solve", "mgm-sync")
METHODS = tuple(TS_METHODS) + PG_METHODS + MGM_METHODS
#: methods that need every pair: pygmtools' dense K; pylibmgm 1.1.3's GREEDA (solve_mgm and
#: the solve inside synchronize_solution) raises ``IndexError: unordered_map::at`` on a model
#: that lacks a pair (checked on N=8 with a 4-regular view graph)
ALL_PAIRS_ONLY = ("pg-cao", "pg-mgm-floyd", "pg-gamgm", "pg-gamgm-doc", "mgm-solve", "mgm-sync")

GRID_N = (8, 16, 32, 64, 128)
GRID_n = (10, 20, 30)
QUICK = ((4, 6), (8, 10))
#: the issue's scale targets: (label, N, n, methods, view-graph degree or None, limit seconds)
SCALE = (
    ("online N=64", 64, 20, ("ts-s-rrwm",), None, 60.0),
    ("offline N=256 sparse", 256, 20, ("ts-rrwm+birkhoff", "ts-rrwm+spectral", "ts-rrwm"), 16,
     300.0),
)

_GIB = 2.0 ** 30
#: predicted peak bytes, calibrated on the measured rows (N <= 16): pygmtools' cao and
#: mgm_floyd hold the dense K plus its batched RRWM copies; libmgm about 60 bytes per edge of
#: its hash maps plus the Python-side K of one pair
PG_K_FACTOR = 2.5
MGM_BYTES_PER_EDGE = 60.0


# =========================================================================== problems
def view_graph(N: int, degree: int | None) -> np.ndarray | None:
    """``None`` (all pairs) or a circulant view graph: graph ``i`` matched to ``i +- 1..degree/2``
    (mod ``N``), as ``(P, 2)`` rows ``i < j``."""
    if degree is None:
        return None
    half = degree // 2
    rows = set()
    for i in range(N):
        for d in range(1, half + 1):
            j = (i + d) % N
            rows.add((min(i, j), max(i, j)))
    return np.array(sorted(rows), dtype=np.int64)


#: the problem family (Yan preset by default); ``--deformation`` etc. change it for a whole run
PROBLEM = {"deformation": 0.05, "outliers": 0, "density": 1.0}


def make_problem(N: int, n: int, seed: int, trial: int, deformation: float = 0.05,
                 outliers: int = 0, density: float = 1.0):
    """``N`` graphs of ``n`` inliers (+ ``outliers``), the same for a given seed and trial."""
    from transync.datasets import make_graph_collection

    rng = np.random.default_rng([seed, N, n, trial])
    return make_graph_collection(N, n, outliers, deformation, density, shuffle=True, rng=rng)


def all_pairs(N: int) -> np.ndarray:
    i, j = np.triu_indices(N, 1)
    return np.column_stack([i, j]).astype(np.int64)


# =========================================================================== memory
def _status_kib(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return -1


def _reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


# =========================================================================== method runners
# Each returns (pairs (P, 2), assignments (P, n), stages {name: seconds}, extra dict).
def run_transync(method, graphs, sigma2, pairs, seed):
    import functools
    import warnings

    from transync import match_collection
    from transync.matching import gaussian_edge_affinity

    kw = TS_METHODS[method]
    aff = functools.partial(gaussian_edge_affinity, sigma2=sigma2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = match_collection(graphs, affinity=aff, pairs=pairs, rng=seed, progress=False, **kw)
    extra = {"ts_consistency": res.consistency, "ts_input_consistency": res.input_consistency,
             "ts_total_score": res.total_score, "n_iter": res.n_iter,
             "converged": res.converged, "consistent_by_construction": res.matching is not None,
             "_matching": res.matching}
    return res.pairs, res.assignments, dict(res.timings), extra


def pg_affinity(pygm, graphs, sigma2):
    """Dense ``(N, N, n^2, n^2)`` K through pygmtools' own pipeline (one batched call per row)."""
    import functools

    N, n = len(graphs), graphs[0].n_nodes
    sp = [pygm.utils.dense_to_sparse(np.asarray(g.edge_features)) for g in graphs]
    ne = {s[0].shape[0] for s in sp}
    fn = functools.partial(pygm.utils.gaussian_aff_fn, sigma=sigma2)
    K = np.empty((N, N, n * n, n * n))
    if len(ne) == 1:                                 # equal edge counts: batch a row of K
        conn = np.stack([s[0] for s in sp])
        ef = np.stack([s[1] for s in sp])
        ns = np.full(N, n)
        for i in range(N):
            K[i] = pygm.utils.build_aff_mat(None, np.repeat(ef[i:i + 1], N, 0),
                                            np.repeat(conn[i:i + 1], N, 0), None, ef, conn,
                                            ns, None, ns, None, edge_aff_fn=fn)
    else:
        for i in range(N):
            for j in range(N):
                K[i, j] = pygm.utils.build_aff_mat(None, sp[i][1], sp[i][0], None, sp[j][1],
                                                   sp[j][0], np.array([n]), None, np.array([n]),
                                                   None, edge_aff_fn=fn)
    return K


def _pg_assignments(X, pairs):
    # ndarray (N, N, n, n) from cao / mgm_floyd; gamgm's result object indexes the same way
    return np.stack([np.asarray(X[i, j]).argmax(1) for i, j in pairs.tolist()])


def run_pygmtools(method, graphs, sigma2, pairs, seed, pg_mode):
    import pygmtools as pygm

    pygm.set_backend("numpy")
    N, n = len(graphs), graphs[0].n_nodes
    stages = {}
    t0 = time.perf_counter()
    if method in ("pg-cao", "pg-mgm-floyd"):
        K = pg_affinity(pygm, graphs, sigma2)
        stages["affinity"] = time.perf_counter() - t0
        t = time.perf_counter()
        fn = pygm.cao if method == "pg-cao" else pygm.mgm_floyd
        if pg_mode == "auto":      # the faster and leaner mode of each, measured at N=8, n=20
            pg_mode = "memory" if method == "pg-cao" else "time"
        with np.errstate(divide="ignore", invalid="ignore"):
            X = fn(K, mode=pg_mode)
        stages["solve"] = time.perf_counter() - t
    else:
        E = np.stack([np.asarray(g.edge_features, dtype=float) for g in graphs])
        mask = np.stack([np.asarray(g.adjacency) != 0 for g in graphs])
        A = np.where(mask, E - 0.5, 0.0)
        W = np.zeros((N, N, n, n))
        stages["affinity"] = time.perf_counter() - t0
        kw = {} if method == "pg-gamgm" else dict(sk_init_tau=0.1, sk_min_tau=0.01)
        np.random.seed(seed % 2**32)              # gamgm draws its start from numpy's global RNG
        t = time.perf_counter()
        with np.errstate(divide="ignore", invalid="ignore"):
            X = pygm.gamgm(A, W, **kw)
        stages["solve"] = time.perf_counter() - t
    stages["total"] = time.perf_counter() - t0
    return pairs, _pg_assignments(X, pairs), stages, {"pg_mode": pg_mode}


def _quiet_libmgm():
    import logging

    logging.getLogger("libmgm").setLevel(logging.ERROR)
    logging.getLogger("libmgm.interface").setLevel(logging.ERROR)


def mgm_model(lm, graphs, sigma2, pairs):
    """pylibmgm ``MgmModel`` of the negated QAP of every pair (assignment id = pygmtools index
    ``u + n v``)."""
    from transync.matching import gaussian_edge_affinity

    n = graphs[0].n_nodes
    lg = [lm.Graph(k, n) for k in range(len(graphs))]
    model = lm.MgmModel()
    idx = np.arange(n * n)
    u_of, v_of = (idx % n).tolist(), (idx // n).tolist()
    t_aff = 0.0
    for i, j in pairs.tolist():
        t = time.perf_counter()
        K = gaussian_edge_affinity(graphs[i], graphs[j], sigma2=sigma2).to_dense()
        t_aff += time.perf_counter() - t
        diag = (-np.diag(K)).tolist()
        Ku = np.triu(K, 1)
        a, b = np.nonzero(Ku)
        cost = (-2.0 * Ku[a, b]).tolist()
        gm = lm.GmModel(lg[i], lg[j], n * n, len(cost))
        add_a, add_e = gm.add_assignment, gm.add_edge
        for k in range(n * n):
            add_a(u_of[k], v_of[k], diag[k])
        for ea, eb, c in zip(a.tolist(), b.tolist(), cost):
            add_e(ea, eb, c)
        model.add_model(gm)
    return model, t_aff


def _mgm_assignments(sol, pairs):
    lab = sol.labeling()
    return np.array([lab[(i, j)] for i, j in pairs.tolist()], dtype=np.int64)


def run_pylibmgm(method, graphs, sigma2, pairs, seed, threads):
    import pylibmgm as lm
    from pylibmgm import solver as ls

    _quiet_libmgm()
    N, n = len(graphs), graphs[0].n_nodes
    if method == "mgm-solve":
        t0 = time.perf_counter()
        model, t_aff = mgm_model(lm, graphs, sigma2, pairs)
        t_build = time.perf_counter() - t0
        t = time.perf_counter()
        sol = ls.solve_mgm_parallel(model, nr_threads=threads)
        t_solve = time.perf_counter() - t
        stages = {"affinity": t_aff, "build": t_build - t_aff, "solve": t_solve,
                  "total": time.perf_counter() - t0}
        return pairs, _mgm_assignments(sol, pairs), stages, {"mgm_objective": sol.evaluate()}
    # mgm-sync: transync's pairwise RRWM maps, then libmgm's synchronization
    p, A, ts_stages, _ = run_transync("ts-rrwm", graphs, sigma2, pairs, seed)
    t = time.perf_counter()
    lg = [lm.Graph(k, n) for k in range(N)]
    model = lm.MgmModel()
    for i, j in p.tolist():
        model.add_model(lm.GmModel(lg[i], lg[j], 0, 0))      # sync needs the graphs only
    sol = lm.MgmSolution(model)
    for (i, j), a in zip(p.tolist(), A.tolist()):
        sol.set_solution((i, j), a)
    out = ls.synchronize_solution(model, sol, feasible=False)
    t_sync = time.perf_counter() - t
    stages = {"affinity": ts_stages.get("affinity", 0.0),
              "pairwise": ts_stages["total"] - ts_stages.get("affinity", 0.0),
              "sync": t_sync, "total": ts_stages["total"] + t_sync}
    return p, _mgm_assignments(out, p), stages, {}


# =========================================================================== child process
def child(spec: dict) -> dict:
    """Run one method on one problem; called in a fresh subprocess."""
    import importlib

    from transync.permutations import cycle_inconsistency_arrays

    # import the method's libraries before the memory baseline
    importlib.import_module("transync.multigraph")
    if spec["method"] in PG_METHODS:
        importlib.import_module("pygmtools")
    if spec["method"] in MGM_METHODS:
        importlib.import_module("pylibmgm")
    N, n, method = spec["N"], spec["n"], spec["method"]
    prob = make_problem(N, n, spec["seed"], spec["trial"], **spec["problem"])
    n = n + spec["problem"]["outliers"]
    pairs = view_graph(N, spec.get("degree"))
    pairs_arg = pairs
    if pairs is None:
        pairs = all_pairs(N)
    reset_ok = _reset_peak()
    rss0 = _status_kib("VmRSS")
    t0 = time.perf_counter()
    if method in TS_METHODS:
        out = run_transync(method, prob.graphs, spec["sigma2"], pairs_arg, spec["seed"])
    elif method in PG_METHODS:
        out = run_pygmtools(method, prob.graphs, spec["sigma2"], pairs, spec["seed"],
                            spec["pg_mode"])
    else:
        out = run_pylibmgm(method, prob.graphs, spec["sigma2"], pairs, spec["seed"],
                           spec["threads"])
    wall = time.perf_counter() - t0
    hwm = _status_kib("VmHWM")
    p, A, stages, extra = out
    matching = extra.pop("_matching", None)
    p = np.asarray(p, dtype=np.int64)
    A = np.asarray(A, dtype=np.int64)
    pred = {(int(i), int(j)): a for (i, j), a in zip(p, A)}
    truth = prob.ground_truth
    from transync.metrics import multimatching_accuracy

    acc = multimatching_accuracy(pred, truth, pairs=p)
    rep = cycle_inconsistency_arrays(p, A, np.full(N, n), rng=0)
    cons = 1.0 - float(rep["cycle_error"]) if rep["n_triangles"] else 1.0
    row = {
        "status": "ok", "time_s": float(stages.get("total", wall)), "wall_s": wall,
        "stages": {k: float(v) for k, v in stages.items()},
        "peak_mib": (hwm - rss0) / 1024.0 if reset_ok else None,
        "peak_rss_mib": hwm / 1024.0, "base_rss_mib": rss0 / 1024.0,
        "accuracy": float(acc), "consistency": cons,
        "inconsistent_triangles": float(rep["inconsistent_triangles"]),
        "triangles_sampled": bool(rep["sampled"]),
        "unmatched": float(np.mean(A < 0)), "P": int(len(p)),
    }
    if spec.get("score", True):
        row["score"] = _total_score(prob.graphs, p, A, spec["sigma2"])
    row.update({k: (float(v) if isinstance(v, (np.floating, float)) else v)
                for k, v in extra.items()})
    if spec.get("degree") is not None:
        row["note"] = "accuracy over the view-graph pairs"
        if matching is not None:          # consistent output: every pair (i, j) is defined
            row["accuracy_all_pairs"] = float(multimatching_accuracy(matching, truth))
    return row


def _total_score(graphs, pairs, A, sigma2) -> float:
    import functools

    from transync.matching import gaussian_edge_affinity
    from transync.multigraph import PairAffinities

    aff = PairAffinities.from_graphs(graphs, pairs,
                                     functools.partial(gaussian_edge_affinity, sigma2=sigma2))
    return float(np.sum(aff.score_assignments(np.arange(len(pairs)), A)))


# =========================================================================== parent
def predict_skip(method: str, N: int, n: int, P: int, degree, max_mem_gb: float) -> str | None:
    """Reason not to run ``method`` on this setting (memory predicted over the cap), or None."""
    lib = {"pg": "pygmtools", "mgm": "pylibmgm"}.get(method.split("-")[0])
    if lib is not None and importlib.util.find_spec(lib) is None:
        return f"{lib} is not installed (pip install -e .[bench])"
    if degree is not None and method in ALL_PAIRS_ONLY:
        if method.startswith("mgm"):
            return ("pylibmgm 1.1.3's solver fails on a model without every pair "
                    "(IndexError: unordered_map::at); setting uses a sparse view graph")
        return "needs all pairs (dense K), setting uses a sparse view graph"
    if method in ("pg-cao", "pg-mgm-floyd"):
        k_bytes = 8.0 * N * N * n ** 4
        if PG_K_FACTOR * k_bytes > max_mem_gb * _GIB:
            return (f"dense K (N, N, n^2, n^2) alone is {k_bytes / _GIB:.1f} GiB, predicted peak "
                    f"{PG_K_FACTOR * k_bytes / _GIB:.1f} GiB > cap {max_mem_gb:g} GiB")
    if method == "mgm-solve":
        edges = P * (n * n) * (n - 1) ** 2 / 2.0
        need = edges * MGM_BYTES_PER_EDGE
        if need > max_mem_gb * _GIB:
            return (f"{edges / 1e6:.0f}M QAP edges in libmgm's cost maps, predicted "
                    f"{need / _GIB:.1f} GiB > cap {max_mem_gb:g} GiB")
    return None


def run_child(spec: dict, cap: float, env: dict) -> dict:
    with tempfile.NamedTemporaryFile("r", suffix=".json", delete=False) as f:
        out = f.name
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(spec),
           "--child-out", out]
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env,
                            start_new_session=True, text=True)
    try:
        _, err = proc.communicate(timeout=cap)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        os.unlink(out)
        return {"status": "timeout", "cap_s": cap, "wall_s": time.perf_counter() - t}
    try:
        if proc.returncode != 0:
            tail = (err or "").strip().splitlines()[-1:]
            return {"status": "error", "returncode": proc.returncode,
                    "error": " | ".join(tail)[:300]}
        return json.loads(Path(out).read_text())
    finally:
        if os.path.exists(out):
            os.unlink(out)


def _problem_key(problem: dict) -> tuple:
    return tuple(float(problem.get(k, v)) for k, v in PROBLEM.items())


def _key(r) -> tuple:
    return (r["N"], r["n"], r["trial"], r["method"], r.get("degree"),
            _problem_key(r.get("problem", PROBLEM)))


class Store:
    """Result rows in one JSON file, rewritten atomically after every row."""

    def __init__(self, path: Path | None, meta: dict):
        self.path, self.rows = path, []
        self.meta = meta
        if path is not None and path.exists():
            data = json.loads(path.read_text())
            self.rows = data.get("rows", [])
            self.meta = {**data.get("meta", {}), **meta}
        # errors are retried on the next run; ok, timeout and skipped rows are kept
        self.rows = [r for r in self.rows if r["status"] != "error"]
        self.done = {_key(r) for r in self.rows}

    def add(self, row: dict) -> None:
        self.rows = [r for r in self.rows if _key(r) != _key(row)]
        self.rows.append(row)
        self.done.add(_key(row))
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.path.with_suffix(".tmp")
            tmp.write_text(json.dumps({"meta": self.meta, "rows": self.rows}, indent=1))
            os.replace(tmp, self.path)


def _timed_out_below(timed_out, method, N, n, degree) -> tuple | None:
    """A setting no larger in N and n where ``method`` already hit the cap, or None."""
    for (m, N0, n0, d0) in timed_out:
        if m == method and d0 == degree and N0 <= N and n0 <= n:
            return N0, n0
    return None


def run(settings, methods, args, store: Store, env: dict):
    """``settings``: list of (N, n, degree, label); rows already stored are skipped."""
    pk = _problem_key(args.problem)
    timed_out = {(r["method"], r["N"], r["n"], r.get("degree")) for r in store.rows
                 if r["status"] == "timeout" and _problem_key(r.get("problem", PROBLEM)) == pk
                 and not args.redo}
    for N, n, degree, label in settings:
        P = len(view_graph(N, degree)) if degree is not None else N * (N - 1) // 2
        for trial in range(args.trials):
            for method in methods:
                row = {"N": N, "n": n, "trial": trial, "method": method, "degree": degree,
                       "label": label, "P": P, "problem": args.problem}
                if _key(row) in store.done and not args.redo:
                    continue
                reason = predict_skip(method, N, n + args.outliers, P, degree, args.max_mem_gb)
                below = _timed_out_below(timed_out, method, N, n, degree)
                if reason is None and below is not None:
                    reason = f"timed out (cap {args.cap:g} s) at N={below[0]}, n={below[1]}"
                if reason is not None:
                    row.update(status="skipped", reason=reason)
                else:
                    spec = {"N": N, "n": n, "trial": trial, "method": method,
                            "degree": degree, "seed": args.seed, "sigma2": args.sigma2,
                            "pg_mode": args.pg_mode, "threads": args.threads,
                            "score": not args.no_score, "problem": args.problem}
                    try:
                        row["load_avg"] = os.getloadavg()[0]
                    except OSError:
                        pass
                    row.update(run_child(spec, args.cap, env))
                    if row["status"] == "timeout":
                        timed_out.add((method, N, n, degree))
                store.add(row)
                _print_row(row, store.rows)


# =========================================================================== output
def _ref(row, rows):
    key = _key({**row, "method": REFERENCE})
    for r in rows:
        if r["status"] == "ok" and _key(r) == key:
            return r
    return None


_HEADER = (f"{'N':>4} {'n':>3} {'t':>2} {'method':>17} | {'acc':>6} {'cons':>6} | "
           f"{'time [s]':>9} {'x ref':>7} | {'peak MiB':>9} {'x ref':>7} | stages")


def _print_row(row, rows):
    head = f"{row['N']:>4} {row['n']:>3} {row['trial']:>2} {row['method']:>17} | "
    if row["status"] != "ok":
        why = row.get("reason") or row.get("error") or f"cap {row.get('cap_s', 0):g} s"
        print(head + f"{row['status']}: {why}", flush=True)
        return
    ref = _ref(row, rows)
    tr = f"{row['time_s'] / ref['time_s']:6.1f}x" if ref else f"{'':>7}"
    pk = row.get("peak_mib")
    pr = (f"{pk / max(ref['peak_mib'], 1e-3):6.1f}x"
          if ref and pk is not None and ref.get("peak_mib") else f"{'':>7}")
    st = " ".join(f"{k}={v:.2f}" for k, v in row["stages"].items() if k != "total")
    pks = f"{pk:9.1f}" if pk is not None else f"{'?':>9}"
    print(head + f"{row['accuracy']:6.3f} {row['consistency']:6.3f} | {row['time_s']:9.2f} "
          f"{tr} | {pks} {pr} | {st}", flush=True)


def summary(rows) -> list[dict]:
    """Mean over trials per (N, n, degree, method)."""
    groups: dict[tuple, list] = {}
    for r in rows:
        groups.setdefault((_problem_key(r.get("problem", PROBLEM)), r["N"], r["n"],
                           r.get("degree"), r["method"]), []).append(r)
    out = []
    for (prob, N, n, degree, method), rs in sorted(groups.items(), key=lambda kv: (
            kv[0][0], kv[0][3] is not None, kv[0][1], kv[0][2], METHODS.index(kv[0][4])
            if kv[0][4] in METHODS else 99)):
        ok = [r for r in rs if r["status"] == "ok"]
        s = {"N": N, "n": n, "degree": degree, "method": method, "trials": len(ok),
             "problem": prob}
        if not ok:
            s["status"] = rs[0]["status"]
            s["reason"] = rs[0].get("reason") or rs[0].get("error") or \
                f"cap {rs[0].get('cap_s', 0):g} s"
        else:
            s["status"] = "ok"
            for k in ("accuracy", "consistency", "time_s", "peak_mib", "score", "unmatched"):
                vals = [r[k] for r in ok if r.get(k) is not None]
                if vals:
                    s[k] = float(np.mean(vals))
            s["stages"] = {k: float(np.mean([r["stages"].get(k, 0.0) for r in ok]))
                           for k in ok[0]["stages"]}
        out.append(s)
    for s in out:
        ref = next((r for r in out if r["method"] == REFERENCE and r["N"] == s["N"]
                    and r["n"] == s["n"] and r["degree"] == s["degree"]
                    and r["problem"] == s["problem"] and r["status"] == "ok"), None)
        if ref is not None and s["status"] == "ok":
            s["time_ratio"] = s["time_s"] / ref["time_s"]
            if s.get("peak_mib") is not None and ref.get("peak_mib"):
                s["memory_ratio"] = s["peak_mib"] / max(ref["peak_mib"], 1e-3)
    return out


def _fmt_t(t):
    return f"{t:.2f} s" if t < 100 else f"{t:.0f} s"


def markdown(rows) -> str:
    lines = ["| N | n | method | accuracy | consistency | time (x S-RRWM) | peak MiB "
             "(x S-RRWM) |", "|---|---|---|---|---|---|---|"]
    default = _problem_key(PROBLEM)
    for s in summary(rows):
        if s["degree"] is not None:
            continue
        if s["problem"] != default:        # another problem family: say which on the row
            d, o, r = s["problem"]
            s = {**s, "method": f"{s['method']} (def {d:g}, out {o:g}, dens {r:g})"}
        if s["status"] != "ok":
            lines.append(f"| {s['N']} | {s['n']} | {s['method']} | {s['status']}: "
                         f"{s['reason']} | | | |")
            continue
        tr = f" ({s['time_ratio']:.1f}x)" if "time_ratio" in s else ""
        mr = f" ({s['memory_ratio']:.1f}x)" if "memory_ratio" in s else ""
        pk = f"{s['peak_mib']:.0f}" if s.get("peak_mib") is not None else "?"
        lines.append(f"| {s['N']} | {s['n']} | {s['method']} | {s['accuracy']:.3f} | "
                     f"{s['consistency']:.3f} | {_fmt_t(s['time_s'])}{tr} | {pk}{mr} |")
    return "\n".join(lines)


def markdown_wide(rows, key: str = "time_s") -> str:
    """One row per setting, one column per method: ``key`` (time or peak memory) with the ratio
    to S-RRWM, or why the method did not run; accuracy and consistency are appended to a cell
    when below 1."""
    summ = [s for s in summary(rows) if s["degree"] is None]
    methods = [m for m in METHODS if any(s["method"] == m for s in summ)]
    settings = sorted({(s["problem"], s["N"], s["n"]) for s in summ})
    lines = ["| N | n | " + " | ".join(methods) + " |",
             "|---|---|" + "---|" * len(methods)]
    for prob, N, n in settings:
        cells = []
        for m in methods:
            s = next((x for x in summ if (x["problem"], x["N"], x["n"], x["method"])
                      == (prob, N, n, m)), None)
            if s is None:
                cells.append("")
            elif s["status"] != "ok":
                cells.append("timeout" if s["status"] == "timeout" else
                             "no memory" if "GiB" in s.get("reason", "") else s["status"])
            else:
                v = s.get(key)
                ratio = s.get("time_ratio" if key == "time_s" else "memory_ratio")
                txt = (_fmt_t(v) if key == "time_s" else f"{v:.0f} MiB") if v is not None else "?"
                if ratio is not None and m != REFERENCE:
                    txt += f" ({ratio:.1f}x)"
                if s["accuracy"] < 0.9995 or s["consistency"] < 0.9995:
                    txt += f"; acc {s['accuracy']:.3f}, cons {s['consistency']:.2f}"
                cells.append(txt)
        lines.append(f"| {N} | {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def fit_exponents(rows, min_N: int = 16) -> dict:
    """Least-squares ``log y = c + a log N + b log n`` for time and peak memory per method."""
    out = {}
    for method in METHODS:
        pts = [s for s in summary(rows) if s["method"] == method and s["status"] == "ok"
               and s["degree"] is None and s["N"] >= min_N
               and s["problem"] == _problem_key(PROBLEM)]
        if len({p["N"] for p in pts}) < 2 or len(pts) < 3:
            continue
        logN = np.log([p["N"] for p in pts])
        logn = np.log([p["n"] for p in pts])
        res = {"points": len(pts)}
        for key in ("time_s", "peak_mib"):
            y = np.array([p.get(key) or np.nan for p in pts], dtype=float)
            ok = np.isfinite(y) & (y > 0)
            if ok.sum() < 3:
                continue
            M = np.column_stack([np.ones(ok.sum()), logN[ok], logn[ok]])
            if len(set(logn[ok])) < 2:         # one n only: fit N alone
                M = M[:, :2]
            coef, *_ = np.linalg.lstsq(M, np.log(y[ok]), rcond=None)
            res[key] = {"N": float(coef[1]), "n": float(coef[2]) if len(coef) > 2 else None}
        out[method] = res
    return out


def print_fit(rows) -> None:
    fits = fit_exponents(rows)
    print("growth exponents (fit log y = c + a log N + b log n over N >= 16):")
    for m, f in fits.items():
        parts = []
        for key, name in (("time_s", "time"), ("peak_mib", "memory")):
            if key in f:
                b = f[key]["n"]
                parts.append(f"{name} ~ N^{f[key]['N']:.2f}" + (f" n^{b:.2f}" if b else ""))
        print(f"  {m:>17}: {', '.join(parts)}  ({f['points']} settings)")


def print_scale(rows) -> None:
    for label, N, n, methods, degree, limit in SCALE:
        for m in methods:
            rs = [r for r in rows if r["N"] == N and r["n"] == n and r["method"] == m
                  and r.get("degree") == degree]
            for r in rs:
                if r["status"] != "ok":
                    print(f"  {label}: {m} {r['status']} {r.get('reason', '')}")
                    continue
                verdict = "meets" if r["time_s"] < limit else "MISSES"
                print(f"  {label}: {m} {r['time_s']:.1f} s ({verdict} < {limit:g} s), "
                      f"accuracy {r['accuracy']:.3f}, consistency {r['consistency']:.3f}, "
                      f"peak {r.get('peak_mib') or 0:.0f} MiB, P={r['P']}")


# =========================================================================== main
def _parse_size(tok: str) -> tuple[int, int]:
    try:
        a, b = tok.lower().replace(":", "x").split("x")
        return int(a), int(b)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a size is NxN (graphs x nodes), e.g. 32x20, got "
                                         f"{tok!r}") from None


def _meta(args) -> dict:
    from importlib.metadata import PackageNotFoundError, version

    meta = {"python": platform.python_version(), "numpy": np.__version__,
            "machine": platform.machine(),
            "cpus": os.cpu_count(), "sigma2": args.sigma2, "seed": args.seed,
            "cap_s": args.cap, "max_mem_gb": args.max_mem_gb, "threads": args.threads,
            "pg_mode": args.pg_mode, "trials": args.trials,
            "time": "wall seconds from graphs to final maps, affinity construction included",
            "memory": "peak RSS (VmHWM reset after setup) minus RSS at reset, per subprocess",
            "generator": "make_graph_collection(N, n, n_outliers=0, deformation=0.05, "
                         "density=1.0, shuffle=True)"}
    for lib in ("transync", "pygmtools", "pylibmgm"):
        try:
            meta[lib] = version(lib)
        except PackageNotFoundError:
            meta[lib] = None
    try:
        meta["load_avg_start"] = os.getloadavg()
    except OSError:
        pass
    return meta


def check_k(sigma2: float) -> float:
    """Max |K_transync - K_pygmtools| on one pair of a collection (same affinity check)."""
    import pygmtools as pygm

    from transync.matching import gaussian_edge_affinity

    pygm.set_backend("numpy")
    prob = make_problem(4, 10, 0, 0)
    K = pg_affinity(pygm, prob.graphs, sigma2)
    Kt = gaussian_edge_affinity(prob.graphs[1], prob.graphs[3], sigma2=sigma2).to_dense()
    return float(np.abs(K[1, 3] - Kt).max())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="tiny settings (4x6, 8x10)")
    ap.add_argument("--sizes", type=_parse_size, nargs="+", default=None, metavar="NxN",
                    help="settings as graphs x nodes, e.g. 8x10 32x20 (default: the grid "
                         "N in 8 16 32 64 128 x n in 10 20 30)")
    ap.add_argument("--graphs", type=int, nargs="+", default=None, help="grid N values")
    ap.add_argument("--nodes", type=int, nargs="+", default=None, help="grid n values")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--scale", action="store_true",
                    help="the scale targets (N=64 n=20 online; N=256 n=20 sparse offline)")
    ap.add_argument("--degree", type=int, default=None,
                    help="sparse circulant view graph: each graph matched to DEGREE others")
    ap.add_argument("--deformation", type=float, default=PROBLEM["deformation"],
                    help="edge-attribute noise (Yan preset 0.05)")
    ap.add_argument("--outliers", type=int, default=PROBLEM["outliers"],
                    help="outlier nodes added to every graph (0); n counts the inliers")
    ap.add_argument("--density", type=float, default=PROBLEM["density"], help="edge density (1)")
    ap.add_argument("--trials", type=int, default=1, help="problems per setting (1)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sigma2", type=float, default=0.05)
    ap.add_argument("--cap", type=float, default=600.0,
                    help="seconds per method and setting before it is killed (600)")
    ap.add_argument("--max-mem-gb", type=float, default=6.0,
                    help="skip a peer whose predicted peak memory exceeds this (6 GiB)")
    ap.add_argument("--threads", type=int, default=2,
                    help="BLAS/OpenMP threads of every method, pylibmgm's nr_threads (2)")
    ap.add_argument("--pg-mode", default="auto", choices=("auto", "time", "memory"),
                    help="pygmtools cao/mgm_floyd mode (auto: cao 'memory', mgm_floyd 'time')")
    ap.add_argument("--no-score", action="store_true", help="skip the total-score evaluation")
    ap.add_argument("--redo", action="store_true", help="re-run rows already stored")
    ap.add_argument("--out", type=Path, default=None, help="JSON results (resumed if present)")
    ap.add_argument("--markdown", type=Path, nargs="+", default=None, metavar="JSON",
                    help="print the README table of stored results and exit")
    ap.add_argument("--wide", choices=("time", "memory"), default=None,
                    help="with --markdown: one row per setting, one column per method")
    ap.add_argument("--fit", type=Path, nargs="+", default=None, metavar="JSON",
                    help="print growth exponents of stored results and exit")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--child-out", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    args.problem = {"deformation": args.deformation, "outliers": args.outliers,
                    "density": args.density}

    if args.child is not None:
        row = child(json.loads(args.child))
        Path(args.child_out).write_text(json.dumps(row))
        return
    if args.markdown or args.fit:
        rows = [r for p in (args.markdown or args.fit) for r in json.loads(p.read_text())["rows"]]
        if args.markdown:
            print(markdown_wide(rows, "time_s" if args.wide == "time" else "peak_mib")
                  if args.wide else markdown(rows))
        else:
            print_fit(rows)
            print_scale(rows)
        return

    if args.scale:
        settings = [(N, n, deg, label) for label, N, n, _, deg, _ in SCALE]
        methods = [m for m in METHODS if any(m in s[3] for s in SCALE)]
    else:
        if args.sizes:
            sizes = args.sizes
        elif args.quick:
            sizes = list(QUICK)
        else:
            sizes = [(N, n) for N in (args.graphs or GRID_N) for n in (args.nodes or GRID_n)]
        settings = [(N, n, args.degree, "grid") for N, n in sizes]
        methods = args.methods
    if REFERENCE in methods:                       # the reference first: ratios print live
        methods = [REFERENCE] + [m for m in methods if m != REFERENCE]
    env = dict(os.environ)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env[var] = str(args.threads)
    meta = _meta(args)
    if meta["pygmtools"] is not None:
        meta["k_check_max_abs_diff"] = check_k(args.sigma2)
        print(f"K check (transync vs pygmtools, one pair): max |diff| = "
              f"{meta['k_check_max_abs_diff']:.2e}")
    store = Store(args.out, meta)
    print("time: seconds, affinity included; peak: RSS MiB above the process's base; "
          f"x ref: ratio to {REFERENCE} (peer / transync)")
    print(_HEADER)
    t0 = time.time()
    if args.scale:
        for label, N, n, ms, deg, _ in SCALE:
            run([(N, n, deg, label)], list(ms), args, store, env)
    else:
        run(settings, methods, args, store, env)
    print(f"total {time.time() - t0:.0f} s")
    print(markdown(store.rows))
    print_fit(store.rows)
    if args.scale:
        print_scale(store.rows)
    if args.out is not None:
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
