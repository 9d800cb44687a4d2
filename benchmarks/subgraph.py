"""transync vs pygmtools ``gamgm`` and pylibmgm on identical multi-subgraph matching problems.

Issue #11, item 6 (thesis ch. 7): graphs of *different sizes* drawn from one universe.

Problems: :func:`transync.datasets.make_subgraph_collection` with ``N`` graphs over a universe of
``d`` nodes, every graph keeping each universe node with its own probability ``p ~ U(0.6, 1)``,
complete graphs (density 1), shuffled node orders, and a problem *family* (``--families``):

* ``def0.05``: deformation 0.05, no outliers (Yan et al.'s preset);
* ``def0.10``: deformation 0.10, no outliers;
* ``def0.05-out2``: deformation 0.05 and 2 outliers per graph (nodes of no universe id).

Every method gets the same problem, regenerated bit-identically from ``[seed, N, d, trial]``.
The *given universe* is ``d`` without outliers and ``d + n_outliers`` with them (the largest
possible graph; ``n_universe`` must be at least the largest graph, and outliers, which the model
maps into slots of their own, cannot fit into ``d`` slots).

Affinity: Cho et al.'s Gaussian edge affinity ``exp(-(e_uv - e'_ab)^2 / sigma2)`` on the edge
attributes, ``sigma2 = 0.05``, no node term:

* transync gets it as ``affinity=functools.partial(gaussian_edge_affinity, sigma2=sigma2)``
  (``--ts-affinity callable``, default: the library's own path, a separable expansion of the
  kernel with entrywise error below 1e-8, never forming a K) or as the dense pygmtools-layout K
  blocks pylibmgm gets (``--ts-affinity blocks``: built before the clock starts and handed over
  by a callable that looks them up, since ``match_collection`` takes precomputed blocks only for
  graphs of one size);
* pylibmgm gets the exact dense K blocks (``gaussian_edge_affinity(g_i, g_j,
  backend="dense").to_dense()``, checked against pygmtools' ``build_aff_mat`` +
  ``gaussian_aff_fn`` on one unequal-size pair: ``meta.k_check_max_abs_diff``), negated
  because libmgm minimizes cost: unary ``-K[a, a]`` and one edge ``-2 K[a, b]`` per pair of
  candidates ``a < b`` (``x^T K x`` counts it twice);
* pygmtools ``gamgm`` takes no K: it maximizes the Koopmans-Beckmann objective
  ``sum_ij lambda tr(X_ij^T A_i X_ij A_j) + tr(X_ij^T W_ij)``. It gets ``A`` of shape
  ``(N, n_max, n_max)``, ``A_i[u, v] = e_uv - 0.5`` on the edges of graph ``i`` (attributes
  centred, 0 elsewhere and in the padding), ``W = 0`` (``(N, N, n_max, n_max)``; the graphs have
  no node attributes), ``ns`` = the graph sizes and ``n_univ`` = the given universe. So gamgm
  solves a *different model* on the same data (products of centred attributes instead of the
  Gaussian affinity), as in ``benchmarks/multigraph.py``. This is the closest input it accepts.

Methods (``--methods``; ``@d`` = the given universe is passed, otherwise it is estimated):

* ``ts-s-rrwm`` / ``ts-s-rrwm@d``: ``match_collection(solver="rrwm", sync="birkhoff",
  mode="online", partial="universe")`` (S-RRWM on the multi-simplex). Every ratio is
  ``ts-s-rrwm`` (universe estimated) over the other method: time, memory, and F1 difference.
* ``ts-rrwm+spectral`` / ``ts-rrwm+spectral@d``: pairwise RRWM with slack, then the
  partial-permutation spectral synchronization (``mode="offline", sync="spectral"``).
* ``ts-rrwm``: pairwise RRWM of every pair, no synchronization (the input of the next three).
* ``ts-matcheig`` / ``ts-matcheig@d``: ``synchronize_permutations(maps, method="matcheig")`` on
  the ``ts-rrwm`` maps (offline baseline of Maset et al.; pairwise rounding, need not be
  consistent). Time = pairwise stage + synchronization.
* ``pg-gamgm@d``: pygmtools 0.6 ``gamgm`` (numpy backend) with its defaults;
  ``pg-gamgm-doc@d``: with the parameters of pygmtools' own partial-matching docstring example
  (``sk_init_tau=0.1, sk_min_tau=0.01, param_lambda=0.3``); ``pg-gamgm-tuned@d``: with
  ``param_lambda=3`` (the best of 18 settings of ``param_lambda`` and the Sinkhorn temperatures
  on separate seeds, see ``GAMGM_KW``; its F1 there 0.39, the defaults' 0.15). With ``W = 0``,
  ``param_lambda`` only rescales the objective, i.e. the temperatures. ``outlier_thresh`` (gamgm's
  own way to leave nodes unmatched) did not help (F1 <= 0.16 or nothing matched for thresholds
  0.5-8). gamgm draws its start from numpy's global RNG, seeded per trial.
* ``mgm-solve``: pylibmgm's GREEDA ``solver.solve_mgm_parallel`` (EXHAUSTIVE, 1 thread) on the
  negated QAP. libmgm leaves nodes unmatched natively (labeling ``-1``), so it accepts graphs of
  different sizes; its universe is its number of cliques. Build = one Python call per candidate
  and per edge (no batched setter), included in the time. Skipped above ``--mgm-max-edges`` QAP
  edges (its memory is about 60 bytes per edge and its time grows faster).
* ``mgm-sync``: pylibmgm ``synchronize_solution(feasible=False)`` of the ``ts-rrwm`` maps.

Measured per trial: precision, recall, F1 and accuracy (MA, equal to recall) of the pairwise
maps over all pairs ``i < j`` (:func:`transync.metrics.multimatching_precision_recall`,
real-to-real correspondences; a match involving an outlier counts as a wrong prediction),
transitivity CVR of the pairwise maps (:func:`transync.metrics.constraint_violations`; 0 for
every synchronized output), the universe size (estimated, given, or pylibmgm's cliques) and
whether it equals the true ``d`` (families without outliers), wall time from the graphs to the
final pairwise maps (affinity construction included; each subprocess first runs its method
once on a tiny problem, untimed, so that lazy imports and caches are warm), and the **peak
RSS** above the process's base (Linux ``VmHWM``, reset through ``/proc/self/clear_refs`` before
each trial, after the problem is generated and after ``malloc_trim`` hands freed heap back, so
that earlier trials do not hide this one's peak), so native allocations count too.

Every (family, method) runs in one subprocess (imports paid once) over its settings, smallest
first, and appends one JSON line per trial. A trial past ``--cap`` seconds is stopped by
SIGALRM, or flagged when a native call (pylibmgm's solver) returns after the cap. The method is
then skipped at every larger setting. A subprocess still running after ``cap`` x trials + 120 s
is killed. Results go to ``--out`` (JSON, rewritten after every subprocess; a re-run skips
what is stored, ``meta.runs`` lists every run) and a Markdown report (``--markdown-out``,
default: the JSON path with ``.md``).

Usage::

    python benchmarks/subgraph.py --quick                       # smoke test, < 1 min
    python benchmarks/subgraph.py --out benchmarks/results/subgraph.json
    python benchmarks/subgraph.py --graphs 8 --universes 20 --trials 10 --families def0.05
    python benchmarks/subgraph.py --markdown benchmarks/results/subgraph.json
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from multigraph import _quiet_libmgm, _reset_peak, _status_kib  # noqa: E402  (one home)

REFERENCE = "ts-s-rrwm"
#: transync methods: match_collection keywords
TS_METHODS = {
    "ts-s-rrwm": dict(solver="rrwm", sync="birkhoff", mode="online"),
    "ts-s-rrwm@d": dict(solver="rrwm", sync="birkhoff", mode="online"),
    "ts-rrwm+spectral": dict(solver="rrwm", sync="spectral", mode="offline"),
    "ts-rrwm+spectral@d": dict(solver="rrwm", sync="spectral", mode="offline"),
    "ts-rrwm": dict(solver="rrwm", sync=None, mode="offline"),
}
SYNC_METHODS = ("ts-matcheig", "ts-matcheig@d", "mgm-sync")      # on the ts-rrwm maps
PG_METHODS = ("pg-gamgm@d", "pg-gamgm-doc@d", "pg-gamgm-tuned@d")
METHODS = tuple(TS_METHODS) + ("ts-matcheig", "ts-matcheig@d") + PG_METHODS + (
    "mgm-solve", "mgm-sync")
#: the peers of the issue's target "F1 at least gamgm's in at most a fifth of its time"
TARGET_PEERS = PG_METHODS
GAMGM_KW = {
    "pg-gamgm@d": {},
    "pg-gamgm-doc@d": dict(sk_init_tau=0.1, sk_min_tau=0.01, param_lambda=0.3),
    # tuned here on separate seeds (100-102, N = 8, d = 20, def0.05), best mean F1 of
    # param_lambda in {0.3, 1, 3, 10, 30, 100} x (init, min) tau in {(0.5, 0.1), (0.1, 0.01),
    # (0.05, 0.001)}: 0.39 against 0.15 with the defaults
    "pg-gamgm-tuned@d": dict(param_lambda=3.0),
}

FAMILIES = {
    "def0.05": dict(deformation=0.05, n_outliers=0),
    "def0.10": dict(deformation=0.10, n_outliers=0),
    "def0.05-out2": dict(deformation=0.05, n_outliers=2),
}
P_KEEP = (0.6, 1.0)
GRID_N = (8, 16, 32)
GRID_D = (10, 20, 30)
QUICK = dict(graphs=(5,), universes=(8,), trials=2, families=("def0.05-out2",))


# =========================================================================== problems
def make_problem(family: str, N: int, d: int, seed: int, trial: int):
    """The collection of a (family, N, d, trial): the same for every method."""
    from transync.datasets import make_subgraph_collection

    fam = FAMILIES[family]
    rng = np.random.default_rng([seed, N, d, trial])
    return make_subgraph_collection(N, d, p_keep=P_KEEP, n_outliers=fam["n_outliers"],
                                    deformation=fam["deformation"], density=1.0,
                                    shuffle=True, rng=rng)


def given_universe(family: str, d: int) -> int:
    """The universe size handed to the ``@d`` methods: ``d`` (+ outliers per graph)."""
    return d + FAMILIES[family]["n_outliers"]


def all_pairs(N: int) -> np.ndarray:
    i, j = np.triu_indices(N, 1)
    return np.column_stack([i, j]).astype(np.int64)


def k_blocks(graphs, pairs, sigma2: float) -> dict:
    """Dense pygmtools-layout K of every pair (candidate ``(u, a)`` at index ``u + n_i a``)."""
    from transync.matching import gaussian_edge_affinity

    return {(i, j): gaussian_edge_affinity(graphs[i], graphs[j], sigma2=sigma2,
                                           backend="dense").to_dense()
            for i, j in pairs.tolist()}


class BlockLookup:
    """``affinity(g_i, g_j)``: the precomputed dense K block of that pair, for transync.

    ``match_collection`` takes precomputed K blocks only for graphs of one size; for different
    sizes it takes a callable, so ``--ts-affinity blocks`` hands it the very blocks pylibmgm
    gets through this lookup (by graph identity)."""

    def __init__(self, graphs, blocks: dict):
        self.index = {id(g): k for k, g in enumerate(graphs)}
        self.blocks = blocks

    def __call__(self, g1, g2):
        from transync.matching import as_affinity

        i, j = self.index[id(g1)], self.index[id(g2)]
        return as_affinity(self.blocks[(i, j)], n1=g1.n_nodes, n2=g2.n_nodes)


def mgm_edges(sizes, pairs) -> float:
    """QAP edges of the complete-graph model pylibmgm would hold (``a < b``, ``u != v``,
    ``a != b``)."""
    s = np.asarray(sizes, dtype=float)
    ni, nj = s[pairs[:, 0]], s[pairs[:, 1]]
    return float(np.sum(ni * nj * (ni - 1) * (nj - 1) / 2.0))


# =========================================================================== method runners
# Each returns (maps {(i, j): (n_i,) int, -1 unmatched}, stages {name: seconds}, extra dict).
def _ts_call(graphs, affinity, n_universe, seed, **kw):
    from transync import match_collection

    if n_universe is not None:
        kw["n_universe"] = n_universe
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return match_collection(graphs, affinity=affinity, rng=seed, progress=False, **kw)


def _ts_maps(res, pairs) -> dict:
    return {(i, j): np.asarray(res.pairwise(i, j), dtype=np.int64) for i, j in pairs.tolist()}


def run_transync(method, graphs, affinity, n_universe, pairs, seed):
    kw = TS_METHODS[method]
    d = n_universe if method.endswith("@d") else None
    res = _ts_call(graphs, affinity, d, seed, **kw)
    extra = {"n_universe": getattr(res, "n_universe", None),
             "n_universe_rule": res.info.get("n_universe_rule"),
             "universe_given": d is not None, "converged": bool(res.converged)}
    if extra["n_universe"] is None and res.matching is not None:
        extra["n_universe"] = int(res.matching.n_universe)
    return _ts_maps(res, pairs), dict(res.timings), extra


def run_sync(method, graphs, affinity, n_universe, pairs, seed):
    """matcheig (transync) or pylibmgm's synchronization of transync's pairwise RRWM maps."""
    t0 = time.perf_counter()
    res = _ts_call(graphs, affinity, None, seed, **TS_METHODS["ts-rrwm"])
    maps = _ts_maps(res, pairs)
    t_pair = time.perf_counter() - t0
    sizes = np.array([g.n_nodes for g in graphs])
    t = time.perf_counter()
    if method.startswith("ts-matcheig"):
        from transync.synchronization import synchronize_permutations

        d = n_universe if method.endswith("@d") else None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = synchronize_permutations(maps, method="matcheig", n_universe=d, sizes=sizes,
                                         rng=seed)
        out = {(i, j): np.asarray(s.pairwise(i, j), dtype=np.int64) for i, j in maps}
        extra = {"n_universe": int(s.n_universe), "universe_given": d is not None,
                 "n_universe_rule": s.info.get("n_universe_rule")}
    else:                                                       # mgm-sync
        import pylibmgm as lm
        from pylibmgm import solver as ls

        _quiet_libmgm()
        lg = [lm.Graph(k, int(n)) for k, n in enumerate(sizes)]
        model = lm.MgmModel()
        for i, j in maps:
            model.add_model(lm.GmModel(lg[i], lg[j], 0, 0))     # sync needs the graphs only
        sol = lm.MgmSolution(model)
        for (i, j), a in maps.items():
            sol.set_solution((i, j), a.tolist())
        synced = ls.synchronize_solution(model, sol, feasible=False)
        lab = synced.labeling()
        out = {(i, j): np.asarray(lab[(i, j)], dtype=np.int64) for i, j in maps}
        extra = {"n_universe": len(synced.cliques()), "universe_given": False,
                 "n_universe_rule": "pylibmgm: number of cliques"}
    t_sync = time.perf_counter() - t
    stages = {"affinity": res.timings.get("affinity", 0.0),
              "pairwise": t_pair - res.timings.get("affinity", 0.0), "sync": t_sync,
              "total": time.perf_counter() - t0}
    return out, stages, extra


def gamgm_inputs(graphs):
    """gamgm's ``A`` (centred edge attributes, padded), ``W = 0`` and ``ns``."""
    N = len(graphs)
    ns = np.array([g.n_nodes for g in graphs], dtype=np.int64)
    m = int(ns.max())
    A = np.zeros((N, m, m))
    for k, g in enumerate(graphs):
        E = np.asarray(g.edge_features, dtype=float)
        mask = np.asarray(g.adjacency) != 0
        A[k, :ns[k], :ns[k]] = np.where(mask, E - 0.5, 0.0)
    return A, np.zeros((N, N, m, m)), ns


def run_gamgm(method, graphs, n_universe, pairs, seed):
    import pygmtools as pygm

    pygm.set_backend("numpy")
    t0 = time.perf_counter()
    A, W, ns = gamgm_inputs(graphs)
    t_in = time.perf_counter() - t0
    kw = GAMGM_KW[method]
    np.random.seed(seed % 2 ** 32)               # gamgm draws its start from numpy's global RNG
    t = time.perf_counter()
    with np.errstate(divide="ignore", invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        X = pygm.gamgm(A, W, ns, n_univ=n_universe, **kw)
    t_solve = time.perf_counter() - t
    maps = {}
    for i, j in pairs.tolist():
        M = np.asarray(X[i, j])[:ns[i], :ns[j]]
        a = M.argmax(1)
        maps[(i, j)] = np.where(M.max(1) > 0.5, a, -1).astype(np.int64)
    used = set()
    for k in range(len(graphs)):                 # universe slots holding at least one node
        U = np.asarray(X.match_dict[k])
        used.update(np.flatnonzero(U.max(0) > 0.5).tolist())
    stages = {"affinity": t_in, "solve": t_solve, "total": time.perf_counter() - t0}
    return maps, stages, {"n_universe": int(n_universe), "universe_given": True,
                          "slots_used": len(used), "n_universe_rule": "given (n_univ)"}


def run_mgm_solve(graphs, sigma2, pairs, threads):
    import pylibmgm as lm
    from pylibmgm import solver as ls

    _quiet_libmgm()
    sizes = [g.n_nodes for g in graphs]
    t0 = time.perf_counter()
    K = k_blocks(graphs, pairs, sigma2)
    t_aff = time.perf_counter() - t0
    lg = [lm.Graph(k, n) for k, n in enumerate(sizes)]
    model = lm.MgmModel()
    for i, j in pairs.tolist():
        ni, nj = sizes[i], sizes[j]
        Kij = K.pop((i, j))
        idx = np.arange(ni * nj)
        diag = (-np.diag(Kij)).tolist()
        a, b = np.nonzero(np.triu(Kij, 1))
        cost = (-2.0 * Kij[a, b]).tolist()
        gm = lm.GmModel(lg[i], lg[j], ni * nj, len(cost))
        add_a, add_e = gm.add_assignment, gm.add_edge
        for u, v, c in zip((idx % ni).tolist(), (idx // ni).tolist(), diag):
            add_a(u, v, c)
        for ea, eb, c in zip(a.tolist(), b.tolist(), cost):
            add_e(ea, eb, c)
        model.add_model(gm)
        del Kij
    t_build = time.perf_counter() - t0 - t_aff
    t = time.perf_counter()
    sol = ls.solve_mgm_parallel(model, nr_threads=threads)
    t_solve = time.perf_counter() - t
    lab = sol.labeling()
    maps = {(i, j): np.asarray(lab[(i, j)], dtype=np.int64) for i, j in pairs.tolist()}
    stages = {"affinity": t_aff, "build": t_build, "solve": t_solve,
              "total": time.perf_counter() - t0}
    return maps, stages, {"n_universe": len(sol.cliques()), "universe_given": False,
                          "n_universe_rule": "pylibmgm: number of cliques",
                          "mgm_objective": -float(sol.evaluate())}


# =========================================================================== child process
def run_method(method, graphs, affinity, n_universe, pairs, seed, sigma2, threads):
    """Dispatch one method on one problem: ``(maps, stages, extra)``."""
    if method in TS_METHODS:
        return run_transync(method, graphs, affinity, n_universe, pairs, seed)
    if method in SYNC_METHODS:
        return run_sync(method, graphs, affinity, n_universe, pairs, seed)
    if method in PG_METHODS:
        return run_gamgm(method, graphs, n_universe, pairs, seed)
    if method == "mgm-solve":
        return run_mgm_solve(graphs, sigma2, pairs, threads)
    raise ValueError(f"unknown method {method!r}")


def evaluate(maps, prob, pairs) -> dict:
    """Precision / recall / F1 / accuracy against the ground truth, transitivity CVR."""
    from transync.metrics import constraint_violations, multimatching_precision_recall

    pr = multimatching_precision_recall(maps, prob.ground_truth, pairs=pairs)
    cv = constraint_violations(maps, sizes=prob.sizes.tolist(), rng=0)
    n_pred = sum(int(np.sum(a >= 0)) for a in maps.values())
    return {**{k: float(v) for k, v in pr.items()},
            "cvr_transitivity": float(cv.transitivity.cvr),
            "cvr_capacity": float(cv.capacity.cvr), "matches": n_pred}


class _Timeout(Exception):
    """A trial ran past ``--cap`` (raised by SIGALRM in the child)."""


def _on_alarm(signum, frame):
    raise _Timeout


def child(spec: dict, out_path: str) -> None:
    """One method on a list of ``(N, d, trial)`` items, smallest first; one JSON line per item
    appended to ``out_path``. A trial past ``spec["cap"]`` seconds is stopped (SIGALRM, so a
    long native call stops when it returns) and the method skipped at every larger setting."""
    import gc
    import importlib

    importlib.import_module("transync.multigraph")
    importlib.import_module("transync.metrics")
    method = spec["method"]
    if method in PG_METHODS:
        importlib.import_module("pygmtools")
    if method.startswith("mgm"):
        importlib.import_module("pylibmgm")
    from transync.matching import gaussian_edge_affinity

    family, sigma2 = spec["family"], spec["sigma2"]
    warm = make_problem(family, 3, 5, spec["seed"], 10 ** 6)     # untimed warm-up run
    run_method(method, warm.graphs, functools.partial(gaussian_edge_affinity, sigma2=sigma2),
               given_universe(family, 5), all_pairs(3), 0, sigma2, spec["threads"])
    signal.signal(signal.SIGALRM, _on_alarm)
    timed_out: list[tuple[int, int]] = []
    for N, d, trial in spec["items"]:
        base = {"family": family, "N": N, "d": d, "trial": trial, "method": method,
                "ts_affinity": spec["ts_affinity"], "load_avg": round(os.getloadavg()[0], 2)}
        below = next(((N0, d0) for N0, d0 in timed_out if N0 <= N and d0 <= d), None)
        if below is not None:
            _append(out_path, {**base, "status": "skipped",
                               "reason": f"timed out at N={below[0]}, d={below[1]}"})
            continue
        prob = make_problem(family, N, d, spec["seed"], trial)
        graphs = prob.graphs
        pairs = all_pairs(N)
        n_univ = given_universe(family, d)
        seed = int(np.random.default_rng([spec["seed"], N, d, trial, 1]).integers(2 ** 31))
        if spec["ts_affinity"] == "blocks" and (method in TS_METHODS or method in SYNC_METHODS):
            affinity = BlockLookup(graphs, k_blocks(graphs, pairs, sigma2))  # before the clock
        else:
            affinity = functools.partial(gaussian_edge_affinity, sigma2=sigma2)
        gc.collect()
        _malloc_trim()                 # hand freed heap back: earlier trials must not hide
        reset_ok = _reset_peak()       # this one's peak in memory the process already holds
        rss0 = _status_kib("VmRSS")
        signal.setitimer(signal.ITIMER_REAL, spec["cap"])
        t0 = time.perf_counter()
        try:
            maps, stages, extra = run_method(method, graphs, affinity, n_univ, pairs, seed,
                                             sigma2, spec["threads"])
            wall = time.perf_counter() - t0
        except _Timeout:
            timed_out.append((N, d))
            _append(out_path, {**base, "status": "timeout",
                               "reason": f"cap {spec['cap']:g} s per trial"})
            continue
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        if wall > spec["cap"]:         # a native call (pylibmgm's solver) ran past the alarm:
            timed_out.append((N, d))   # keep its result, skip the larger settings
        hwm = _status_kib("VmHWM")
        row = {**base, "status": "ok", "time_s": wall,
               "stages": {k: float(v) for k, v in stages.items()},
               "peak_mib": (hwm - rss0) / 1024.0 if reset_ok else None, "mem_trim": True,
               "sizes": prob.sizes.tolist(), "n_universe_given": n_univ}
        row.update(evaluate(maps, prob, pairs))
        row.update({k: (v.item() if isinstance(v, np.generic) else v) for k, v in extra.items()})
        if FAMILIES[family]["n_outliers"] == 0 and row.get("n_universe") is not None:
            row["universe_correct"] = bool(row["n_universe"] == d)
        _append(out_path, row)
        del maps, affinity, prob, graphs


def _malloc_trim() -> None:
    try:
        import ctypes

        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def _append(path: str, row: dict) -> None:
    with open(path, "a") as f:
        f.write(json.dumps(row) + "\n")


# =========================================================================== parent
def predict_skip(method, family, N, d, args) -> str | None:
    import importlib.util

    lib = {"pg": "pygmtools", "mgm": "pylibmgm"}.get(method.split("-")[0])
    if lib is not None and importlib.util.find_spec(lib) is None:
        return f"{lib} is not installed"
    if method == "mgm-solve":
        n = d + FAMILIES[family]["n_outliers"]
        sizes = np.full(N, 0.8 * d + FAMILIES[family]["n_outliers"])   # mean of p ~ U(0.6, 1)
        edges = mgm_edges(sizes, all_pairs(N))
        if edges > args.mgm_max_edges:
            return (f"about {edges / 1e6:.0f}M QAP edges (mean size {sizes[0]:.0f} of at most "
                    f"{n}) > --mgm-max-edges {args.mgm_max_edges / 1e6:g}M")
    return None


def run_child(spec: dict, limit: float, env: dict) -> tuple[list[dict], str | None]:
    """Run a child; returns its finished rows and ``None``, ``"timeout"`` or an error line."""
    fd, out = tempfile.mkstemp(suffix=".jsonl")
    os.close(fd)
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(spec),
           "--child-out", out]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env,
                            start_new_session=True, text=True)
    status = None
    try:
        _, err = proc.communicate(timeout=limit)
        if proc.returncode != 0:
            tail = (err or "").strip().splitlines()[-1:]
            status = "error: " + " | ".join(tail)[:300]
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        status = "timeout"
    rows = [json.loads(line) for line in Path(out).read_text().splitlines() if line.strip()]
    os.unlink(out)
    return rows, status


def dump(meta: dict, rows: list[dict]) -> str:
    """The results file: ``meta`` indented, one row per line (diffable, 3x smaller)."""
    body = ",\n".join(json.dumps(r, separators=(",", ":")) for r in rows)
    return f'{{"meta": {json.dumps(meta, indent=1)},\n"rows": [\n{body}\n]}}\n'


def _key(r) -> tuple:
    return (r["family"], r["N"], r["d"], r["trial"], r["method"], r.get("ts_affinity"))


class Store:
    """Result rows in one JSON file, rewritten atomically after every subprocess."""

    def __init__(self, path: Path | None, meta: dict):
        self.path, self.rows, self.meta = path, [], meta
        if path is not None and path.exists():
            data = json.loads(path.read_text())
            self.rows = [r for r in data.get("rows", []) if r["status"] != "error"]
            self.meta = {**data.get("meta", {}), **meta}

    @property
    def done(self) -> set:
        return {_key(r) for r in self.rows}

    def add(self, rows: list[dict]) -> None:
        new = {_key(r) for r in rows}
        self.rows = [r for r in self.rows if _key(r) not in new] + rows
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.path.with_suffix(".tmp")
            tmp.write_text(dump(self.meta, self.rows))
            os.replace(tmp, self.path)


def run(args, store: Store, env: dict) -> None:
    """One subprocess per (family, method), over the settings smallest first."""
    for family in args.families:
        for method in args.methods:
            items, skipped = [], []
            for N in sorted(args.graphs):
                for d in sorted(args.universes):
                    for t in range(args.trials):
                        row = {"family": family, "N": N, "d": d, "trial": t, "method": method,
                               "ts_affinity": args.ts_affinity}
                        if _key(row) in store.done and not args.redo:
                            continue
                        reason = predict_skip(method, family, N, d, args)
                        if reason is not None:
                            skipped.append({**row, "status": "skipped", "reason": reason})
                        else:
                            items.append((N, d, t))
            if skipped:
                store.add(skipped)
                _print(skipped[0], store.rows, len(skipped))
            if not items:
                continue
            spec = {"family": family, "method": method, "items": items, "seed": args.seed,
                    "sigma2": args.sigma2, "threads": args.threads, "cap": args.cap,
                    "ts_affinity": args.ts_affinity}
            rows, status = run_child(spec, args.cap * len(items) + 120.0, env)
            done = {(r["N"], r["d"], r["trial"]) for r in rows}
            if status is not None:
                rows += [{"family": family, "N": N, "d": d, "trial": t, "method": method,
                          "ts_affinity": args.ts_affinity,
                          "status": "timeout" if status == "timeout" else "error",
                          "reason": "subprocess killed" if status == "timeout" else status}
                         for N, d, t in items if (N, d, t) not in done]
            store.add(rows)
            for r in rows:
                _print(r, store.rows)


# =========================================================================== output
_HEADER = (f"{'family':>12} {'N':>3} {'d':>3} {'t':>2} {'method':>18} | {'F1':>5} {'prec':>5} "
           f"{'rec':>5} {'CVRt':>5} | {'univ':>4} | {'time s':>7} {'x ref':>6} | {'MiB':>6}")


def _print(row, rows, count=None):
    head = (f"{row['family']:>12} {row['N']:>3} {row['d']:>3} {row['trial']:>2} "
            f"{row['method']:>18} | ")
    if row["status"] != "ok":
        more = f" ({count} trials)" if count else ""
        print(head + f"{row['status']}: {row.get('reason', '')}{more}", flush=True)
        return
    ref = next((r for r in rows if r["status"] == "ok" and r["method"] == REFERENCE
                and _key(r)[:4] == _key(row)[:4]), None)
    tr = f"{row['time_s'] / ref['time_s']:5.1f}x" if ref else f"{'':>6}"
    u = row.get("n_universe")
    pk = row.get("peak_mib")
    print(head + f"{row['f1']:5.3f} {row['precision']:5.3f} {row['recall']:5.3f} "
          f"{row['cvr_transitivity']:5.3f} | {u if u is not None else '-':>4} | "
          f"{row['time_s']:7.2f} {tr} | {pk if pk is not None else float('nan'):6.1f}",
          flush=True)


def summary(rows) -> list[dict]:
    """Per (family, N, d, method): means over the trials that ran, plus ratios to transync."""
    groups: dict[tuple, list] = {}
    for r in rows:
        groups.setdefault((r["family"], r["N"], r["d"], r["method"]), []).append(r)
    fam_order = list(FAMILIES)
    out = []
    for (family, N, d, method), rs in sorted(groups.items(), key=lambda kv: (
            fam_order.index(kv[0][0]) if kv[0][0] in fam_order else 99, kv[0][1], kv[0][2],
            METHODS.index(kv[0][3]) if kv[0][3] in METHODS else 99)):
        ok = [r for r in rs if r["status"] == "ok"]
        s = {"family": family, "N": N, "d": d, "method": method, "trials": len(ok),
             "trials_asked": len(rs)}
        if not ok:
            s["status"] = rs[0]["status"]
            s["reason"] = rs[0].get("reason", "")
        else:
            s["status"] = "ok"
            for k in ("accuracy", "precision", "recall", "f1", "cvr_transitivity",
                      "cvr_capacity", "time_s", "peak_mib", "n_universe", "slots_used"):
                vals = [r[k] for r in ok if r.get(k) is not None]
                if k == "peak_mib" and not all(r.get("mem_trim") for r in ok):
                    vals = []          # measured without malloc_trim: peaks hidden, not shown
                if vals:
                    s[k] = float(np.mean(vals))
            s["time_median_s"] = float(np.median([r["time_s"] for r in ok]))
            s["f1_min"] = float(min(r["f1"] for r in ok))
            uc = [r["universe_correct"] for r in ok if "universe_correct" in r]
            if uc and not ok[0].get("universe_given"):
                s["universe_correct_frac"] = float(np.mean(uc))
            s["universe_given"] = bool(ok[0].get("universe_given"))
        out.append(s)
    for s in out:
        if s["status"] != "ok":
            continue
        for ref_name, tag in ((REFERENCE, "ref"), (REFERENCE + "@d", "ref_d")):
            ref = next((r for r in out if r["method"] == ref_name and r["status"] == "ok"
                        and (r["family"], r["N"], r["d"]) == (s["family"], s["N"], s["d"])),
                       None)
            if ref is None:
                continue
            # ratios transync / peer: time < 1 means transync is faster
            s[f"time_ratio_{tag}"] = ref["time_s"] / s["time_s"]
            if s.get("peak_mib") and ref.get("peak_mib"):
                s[f"memory_ratio_{tag}"] = ref["peak_mib"] / s["peak_mib"]
            s[f"f1_diff_{tag}"] = ref["f1"] - s["f1"]
    return out


def _fmt_t(t):
    return f"{t:.2f} s" if t < 100 else f"{t:.0f} s"


def markdown(rows, meta: dict | None = None) -> str:
    summ = summary(rows)
    lines = ["| family | N | d | method | trials | F1 | precision | recall | accuracy | "
             "CVR trans. | universe | time | ts/peer time | peak MiB | ts/peer memory |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in summ:
        head = f"| {s['family']} | {s['N']} | {s['d']} | {s['method']} | "
        if s["status"] != "ok":
            lines.append(head + f"0/{s['trials_asked']} | {s['status']}: {s['reason']} |"
                         + " |" * 10)
            continue
        u = s.get("n_universe")
        if u is None:
            ut = "-"
        elif s["universe_given"]:
            ut = f"{u:.0f} (given)"
            if s.get("slots_used") is not None:
                ut += f", {s['slots_used']:.1f} used"
        else:
            ut = f"{u:.1f}"
            if "universe_correct_frac" in s:
                ut += f" ({100 * s['universe_correct_frac']:.0f}% = d)"
        tr = f"{s['time_ratio_ref']:.2f}x" if "time_ratio_ref" in s else ""
        mr = f"{s['memory_ratio_ref']:.2f}x" if "memory_ratio_ref" in s else ""
        pk = f"{s['peak_mib']:.0f}" if s.get("peak_mib") is not None else "?"
        lines.append(head + f"{s['trials']} | {s['f1']:.3f} | {s['precision']:.3f} | "
                     f"{s['recall']:.3f} | {s['accuracy']:.3f} | {s['cvr_transitivity']:.3f} | "
                     f"{ut} | {_fmt_t(s['time_s'])} | {tr} | {pk} | {mr} |")
    return "\n".join(lines)


def target_table(rows) -> str:
    """The issue's target per setting and gamgm variant, for S-RRWM and offline RRWM +
    spectral (universe estimated): F1 at least the peer's, time at most a fifth of the peer's."""
    summ = summary(rows)
    ours = ("ts-s-rrwm", "ts-rrwm+spectral")
    lines = ["| family | N | d | peer | peer F1 | peer time | " + " | ".join(
        f"{m} F1 | {m} time (ts/peer) | target" for m in ours) + " |",
        "|---|---|---|---|---|---|" + "---|---|---|" * len(ours)]
    settings = sorted({(s["family"], s["N"], s["d"]) for s in summ},
                      key=lambda k: (list(FAMILIES).index(k[0]) if k[0] in FAMILIES else 99,
                                     k[1], k[2]))
    for key in settings:
        here = {s["method"]: s for s in summ if (s["family"], s["N"], s["d"]) == key
                and s["status"] == "ok"}
        for peer in TARGET_PEERS:
            if peer not in here:
                continue
            p = here[peer]
            cells = []
            for m in ours:
                if m not in here:
                    cells.append("- | - | -")
                    continue
                ts = here[m]
                ok_f1 = ts["f1"] >= p["f1"] - 1e-12
                ok_t = ts["time_s"] <= p["time_s"] / 5
                verdict = ("met" if ok_f1 and ok_t else "F1 only" if ok_f1
                           else "time only" if ok_t else "missed")
                cells.append(f"{ts['f1']:.3f} | {_fmt_t(ts['time_s'])} "
                             f"({ts['time_s'] / p['time_s']:.2f}x) | {verdict}")
            lines.append(f"| {key[0]} | {key[1]} | {key[2]} | {peer} | {p['f1']:.3f} | "
                         f"{_fmt_t(p['time_s'])} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _mean3(values) -> str:
    return f"{np.mean(values):.3f}" if values else "-"


def universe_table(rows) -> str:
    """Estimated universe vs the true d (families without outliers), and the F1 lost when wrong."""
    lines = ["| family | N | d | method | trials | estimate = d | estimates seen | "
             "F1 when right | F1 when wrong | F1 with d given (all trials) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    ok = [r for r in rows if r["status"] == "ok" and "universe_correct" in r
          and not r.get("universe_given")]
    keys = sorted({(r["family"], r["N"], r["d"], r["method"]) for r in ok},
                  key=lambda k: (k[0], k[1], k[2], METHODS.index(k[3]) if k[3] in METHODS
                                 else 99))
    for fam, N, d, m in keys:
        rs = [r for r in ok if (r["family"], r["N"], r["d"], r["method"]) == (fam, N, d, m)]
        right = [r["f1"] for r in rs if r["universe_correct"]]
        wrong = [r["f1"] for r in rs if not r["universe_correct"]]
        seen = sorted({r["n_universe"] for r in rs})
        given = [r["f1"] for r in rows if r["status"] == "ok" and r["method"] == m + "@d"
                 and (r["family"], r["N"], r["d"]) == (fam, N, d)]
        lines.append(f"| {fam} | {N} | {d} | {m} | {len(rs)} | "
                     f"{100 * len(right) / len(rs):.0f}% | {seen} | {_mean3(right)} | "
                     f"{_mean3(wrong)} | {_mean3(given)} |")
    return "\n".join(lines)


def report(rows, meta) -> str:
    runs = meta.get("runs") or [{k: meta.get(k, "?") for k in (
        "started", "grid", "cap_s_per_trial", "ts_affinity", "load_avg_start")}]
    run_lines = [f"* {r.get('started', '?')}: {r.get('grid', '?')}, cap {r.get('cap_s_per_trial')}"
                 f" s per trial, transync affinity `{r.get('ts_affinity')}`, load average at "
                 f"start {r.get('load_avg_start')}" + (f", methods {' '.join(r['methods'])}"
                                                       if r.get("methods") else "")
                 for r in runs]
    parts = ["## Multi-subgraph matching benchmark (`benchmarks/subgraph.py`)", "",
             f"K check vs pygmtools: {meta.get('k_check_max_abs_diff', float('nan')):.1e}. "
             "Runs stored in this file:", "", *run_lines, "",
             *[f"Note: {x}" for x in meta.get("notes", [])], "",
             "Ratios are transync / peer with transync = `ts-s-rrwm` (universe estimated): "
             "time ratio < 1 and memory ratio < 1 mean transync is faster / leaner. Peak "
             "memory is shown only where every trial was measured after `malloc_trim`.", "",
             "### Issue target: F1 at least gamgm's in at most a fifth of its time", "",
             target_table(rows), "", "### Estimated universe", "", universe_table(rows), "",
             "### All methods", "", markdown(rows)]
    return "\n".join(parts) + "\n"


def _meta(args) -> dict:
    from importlib.metadata import PackageNotFoundError, version

    meta = {"python": platform.python_version(), "numpy": np.__version__,
            "machine": platform.machine(), "cpus": os.cpu_count(), "sigma2": args.sigma2,
            "seed": args.seed, "cap_s_per_trial": args.cap, "threads": args.threads,
            "trials": args.trials, "ts_affinity": args.ts_affinity, "p_keep": P_KEEP,
            "families": {f: FAMILIES[f] for f in args.families},
            "grid": f"N {list(args.graphs)} x d {list(args.universes)} x "
                    f"{list(args.families)}, {args.trials} trial(s)",
            "time": "wall seconds from the graphs to the final pairwise maps, affinity "
                    "construction included",
            "memory": "peak RSS (VmHWM reset before each trial) minus RSS at reset",
            "started": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    for lib in ("transync", "pygmtools", "pylibmgm"):
        try:
            meta[lib] = version(lib)
        except PackageNotFoundError:
            meta[lib] = None
    meta["load_avg_start"] = round(os.getloadavg()[0], 2)
    # the library is developed alongside: fingerprint the code that ran
    import hashlib

    src = Path(__file__).resolve().parents[1] / "src" / "transync"
    h = hashlib.sha1()
    for f in sorted(src.rglob("*.py")):
        h.update(f.read_bytes())
    meta["transync_src_sha1"] = h.hexdigest()[:12]
    return meta


def check_k(sigma2: float) -> float:
    """Max |K_transync - K_pygmtools| on one pair of graphs of different sizes."""
    import pygmtools as pygm

    pygm.set_backend("numpy")
    prob = make_problem("def0.05", 4, 10, 0, 0)
    g1, g2 = sorted(prob.graphs, key=lambda g: g.n_nodes)[::3][:2]
    sp = [pygm.utils.dense_to_sparse(np.asarray(g.edge_features)) for g in (g1, g2)]
    fn = functools.partial(pygm.utils.gaussian_aff_fn, sigma=sigma2)
    Kp = pygm.utils.build_aff_mat(None, sp[0][1], sp[0][0], None, sp[1][1], sp[1][0],
                                  np.array([g1.n_nodes]), None, np.array([g2.n_nodes]), None,
                                  edge_aff_fn=fn)
    Kt = k_blocks([g1, g2], np.array([[0, 1]]), sigma2)[(0, 1)]
    return float(np.abs(Kp - Kt).max())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help="smoke test: N 5, d 8, 2 trials, family def0.05-out2, every method")
    ap.add_argument("--graphs", type=int, nargs="+", default=None, help="N values (8 16 32)")
    ap.add_argument("--universes", type=int, nargs="+", default=None,
                    help="universe sizes d (10 20 30)")
    ap.add_argument("--families", nargs="+", default=None, choices=tuple(FAMILIES),
                    help="problem families (all)")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--trials", type=int, default=None, help="problems per setting (2)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sigma2", type=float, default=0.05)
    ap.add_argument("--ts-affinity", choices=("callable", "blocks"), default="callable",
                    help="transync's affinity: its Gaussian edge affinity callable (default) or "
                         "the dense K blocks pylibmgm gets")
    ap.add_argument("--cap", type=float, default=120.0,
                    help="seconds per trial before a method's subprocess is killed (120)")
    ap.add_argument("--mgm-max-edges", type=float, default=3e7,
                    help="skip pylibmgm's solver above this many QAP edges (3e7)")
    ap.add_argument("--threads", type=int, default=1,
                    help="BLAS/OpenMP threads of every method and pylibmgm's nr_threads (1)")
    ap.add_argument("--redo", action="store_true", help="re-run rows already stored")
    ap.add_argument("--out", type=Path, default=None, help="JSON results (resumed if present)")
    ap.add_argument("--markdown-out", type=Path, default=None,
                    help="Markdown report (default: --out with .md)")
    ap.add_argument("--markdown", type=Path, nargs="+", default=None, metavar="JSON",
                    help="print the report of stored results and exit")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--child-out", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.child is not None:
        child(json.loads(args.child), args.child_out)
        return
    if args.markdown:
        data = [json.loads(p.read_text()) for p in args.markdown]
        print(report([r for x in data for r in x["rows"]], data[0].get("meta", {})))
        return
    q = args.quick
    args.graphs = args.graphs or (QUICK["graphs"] if q else GRID_N)
    args.universes = args.universes or (QUICK["universes"] if q else GRID_D)
    args.families = args.families or (QUICK["families"] if q else tuple(FAMILIES))
    args.trials = args.trials or (QUICK["trials"] if q else 2)
    if REFERENCE in args.methods:               # the reference first: ratios print live
        args.methods = [REFERENCE] + [m for m in args.methods if m != REFERENCE]
    env = dict(os.environ)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env[var] = str(args.threads)
    meta = _meta(args)
    if meta["pygmtools"] is not None:
        meta["k_check_max_abs_diff"] = check_k(args.sigma2)
        print(f"K check (transync vs pygmtools, one pair of sizes != ): max |diff| = "
              f"{meta['k_check_max_abs_diff']:.2e}")
    store = Store(args.out, meta)
    run_info = {k: meta[k] for k in ("started", "grid", "cap_s_per_trial", "ts_affinity",
                                     "load_avg_start", "transync_src_sha1")}
    run_info["methods"] = list(args.methods)
    store.meta["runs"] = [*store.meta.get("runs", []), run_info]    # every run that wrote here
    print("time: seconds, affinity included; x ref: time / ts-s-rrwm's; MiB: peak RSS above "
          "base; univ: universe size (estimated, given or pylibmgm's cliques)")
    print(_HEADER)
    t0 = time.time()
    run(args, store, env)
    store.meta["finished"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    store.meta["elapsed_s"] = round(time.time() - t0, 1)
    store.add([])                                 # rewrite with the final meta
    text = report(store.rows, store.meta)
    print(f"total {time.time() - t0:.0f} s\n")
    print(text)
    md = args.markdown_out or (args.out.with_suffix(".md") if args.out else None)
    if md is not None:
        md.parent.mkdir(parents=True, exist_ok=True)
        md.write_text(text)
        print(f"wrote {args.out} and {md}")


if __name__ == "__main__":
    main()
