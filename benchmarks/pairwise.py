"""transync vs pygmtools on identical pairwise matching problems.

For every configuration (n nodes per graph, deformation, with/without outliers) and every trial,
one problem is generated with :func:`transync.datasets.make_point_matching_problem`: ``n_in``
inlier points in the unit square, the second graph a rotated, permuted and Gaussian-deformed copy;
with outliers, a third of the ``n`` nodes of *each* graph are extra uniform points
(``n_in = n - n // 3``), so both libraries see ``n x n`` problems of the same size with and
without outliers. Graphs are fully connected (``--edges delaunay``: Delaunay triangulations, the
same edges for both libraries); the affinity is Cho et al.'s Gaussian edge-length affinity
``exp(-(d1 - d2)^2 / sigma2)`` with the same ``sigma2`` for both libraries.

Pipelines, timed from the point sets to the assignment:

* transync: ``Graph.from_points(edges="full")`` x2, ``gaussian_edge_affinity`` (auto backend),
  solver (``sm``, ``rrwm`` or ``ipfp``; each rounds with Hungarian internally). ``rrwm`` is the
  original authors' algorithm with its Sinkhorn warm-started (transync's default);
  ``rrwm-authors`` is ``rrwm(warm_start=False)``, the authors' loop exactly;
  ``rrwm-pygmtools`` is ``rrwm(variant="pygmtools")``, which runs pygmtools' own RRWM loop --
  all three are compared with ``pygm.rrwm``.
* pygmtools (numpy backend): distance matrices (masked to the Delaunay edges, which transync's
  ``Graph.from_points`` computes for both), ``dense_to_sparse``, ``build_aff_mat`` with
  ``gaussian_aff_fn(sigma=sigma2)``, ``pygm.sm/rrwm/ipfp`` (pygmtools defaults), ``pygm.hungarian``.

The affinity of a problem is built once per library and its build time is added to each solver's
time (the solvers do not modify it). Peak memory is measured with ``tracemalloc`` (numpy
allocations are traced) on the first trial of each configuration, in a separate run of the full
pipeline (build + solve) so that tracing does not distort the timings.

Usage::

    python benchmarks/pairwise.py --quick
    python benchmarks/pairwise.py --trials 20 --out benchmarks/results/pairwise.json
    python benchmarks/pairwise.py --markdown benchmarks/results/pairwise.json   # README rows
"""

from __future__ import annotations

import argparse
import functools
import gc
import json
import platform
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np

from transync.datasets import make_point_matching_problem
from transync.graphs import Graph
from transync.matching import gaussian_edge_affinity, ipfp, rrwm, sm
from transync.metrics import matching_accuracy

METHODS = ("sm", "rrwm", "rrwm-authors", "rrwm-pygmtools", "ipfp")
_TS = {"sm": sm, "rrwm": rrwm, "rrwm-authors": functools.partial(rrwm, warm_start=False),
       "rrwm-pygmtools": functools.partial(rrwm, variant="pygmtools"), "ipfp": ipfp}
_PG = {"sm": "sm", "rrwm": "rrwm", "rrwm-authors": "rrwm", "rrwm-pygmtools": "rrwm",
       "ipfp": "ipfp"}


def make_problem(n: int, deformation: float, outliers: bool, rng: np.random.Generator):
    """Point sets ``P1``, ``P2`` (n x 2 each) and ``truth[i]`` for the inliers (the first nodes)."""
    n_out = n // 3 if outliers else 0
    prob = make_point_matching_problem(n - n_out, n_out, deformation, edges="full", rng=rng)
    return prob.g1.points, prob.g2.points, prob.truth[: n - n_out]


def accuracy(assignment, truth) -> float:
    """Accuracy over the inliers, which are the first ``truth.size`` nodes of g1."""
    return matching_accuracy(assignment[: truth.size], truth)


# --------------------------------------------------------------------------- transync
def ts_build(P1, P2, sigma2, edges="full"):
    g1 = Graph.from_points(P1, edges=edges)
    g2 = Graph.from_points(P2, edges=edges)
    return gaussian_edge_affinity(g1, g2, sigma2=sigma2)


def ts_solve(aff, method):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _TS[method](aff).assignment


# --------------------------------------------------------------------------- pygmtools
def pg_build(pygm, P1, P2, sigma2, edges="full"):
    n1, n2 = len(P1), len(P2)
    D1 = np.linalg.norm(P1[:, None] - P1[None], axis=-1)
    D2 = np.linalg.norm(P2[:, None] - P2[None], axis=-1)
    if edges != "full":     # the same edges as transync's graphs (zero entries are non-edges)
        D1 = D1 * (Graph.from_points(P1, edges=edges).adjacency > 0)
        D2 = D2 * (Graph.from_points(P2, edges=edges).adjacency > 0)
    conn1, e1 = pygm.utils.dense_to_sparse(D1)
    conn2, e2 = pygm.utils.dense_to_sparse(D2)
    aff_fn = functools.partial(pygm.utils.gaussian_aff_fn, sigma=sigma2)
    # non-batched inputs: n1, n2 must be given as length-1 arrays (pygmtools adds the batch axis)
    return pygm.utils.build_aff_mat(None, e1, conn1, None, e2, conn2, np.array([n1]), None,
                                    np.array([n2]), None,
                                    edge_aff_fn=aff_fn)


def pg_solve(pygm, K, n1, n2, method):
    with np.errstate(divide="ignore", invalid="ignore"):   # pygmtools' ipfp divides 0 / 0
        X = getattr(pygm, _PG[method])(K, n1, n2)
    X = pygm.hungarian(X)
    a = np.full(n1, -1)
    r, c = np.nonzero(X)
    a[r] = c
    return a


def _timed(fn, *args):
    t = time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - t


def _peak(fn, *args) -> float:
    gc.collect()
    tracemalloc.start()
    tracemalloc.reset_peak()
    fn(*args)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 2**20


def run(sizes, deformations, trials, sigma2, methods, seed, memory=True, edges="full"):
    import pygmtools as pygm

    pygm.set_backend("numpy")
    # warm-up both pipelines (imports, first-call overheads)
    P1, P2, _ = make_problem(8, 0.0, False, np.random.default_rng(0))
    for m in methods:
        ts_solve(ts_build(P1, P2, sigma2), m)
        pg_solve(pygm, pg_build(pygm, P1, P2, sigma2), 8, 8, m)
    rows = []
    for n in sizes:
        for outliers in (False, True):
            for deformation in deformations:
                rec = {m: {"ts_acc": [], "pg_acc": [], "ts_time": [], "pg_time": []}
                       for m in methods}
                mem = {}
                for t in range(trials):
                    rng = np.random.default_rng([seed, n, int(outliers), int(1000 * deformation), t])
                    P1, P2, truth = make_problem(n, deformation, outliers, rng)
                    aff, tb_ts = _timed(ts_build, P1, P2, sigma2, edges)
                    K, tb_pg = _timed(pg_build, pygm, P1, P2, sigma2, edges)
                    pg_done = {}     # pygmtools' rrwm is deterministic: solve it once per trial
                    for m in methods:
                        a_ts, t_ts = _timed(ts_solve, aff, m)
                        if _PG[m] not in pg_done:
                            pg_done[_PG[m]] = _timed(pg_solve, pygm, K, n, n, m)
                        a_pg, t_pg = pg_done[_PG[m]]
                        r = rec[m]
                        r["ts_acc"].append(accuracy(a_ts, truth))
                        r["pg_acc"].append(accuracy(a_pg, truth))
                        r["ts_time"].append(tb_ts + t_ts)
                        r["pg_time"].append(tb_pg + t_pg)
                    del K, aff
                    if memory and t == 0:
                        for m in methods:
                            mem[m] = (
                                _peak(lambda: ts_solve(ts_build(P1, P2, sigma2, edges), m)),
                                _peak(lambda: pg_solve(pygm, pg_build(pygm, P1, P2, sigma2,
                                                                      edges), n, n, m)),
                            )
                for m in methods:
                    r = rec[m]
                    row = {
                        "n": n, "outliers": outliers, "deformation": deformation, "method": m,
                        "trials": trials, "sigma2": sigma2, "edges": edges,
                        "acc_transync": float(np.mean(r["ts_acc"])),
                        "acc_pygmtools": float(np.mean(r["pg_acc"])),
                        "time_transync_s": float(np.median(r["ts_time"])),
                        "time_pygmtools_s": float(np.median(r["pg_time"])),
                    }
                    row["time_ratio"] = row["time_pygmtools_s"] / row["time_transync_s"]
                    if m in mem:
                        row["peak_mib_transync"], row["peak_mib_pygmtools"] = mem[m]
                        row["memory_ratio"] = mem[m][1] / max(mem[m][0], 1e-9)
                    rows.append(row)
                    _print_row(row)
    return rows


_HEADER = (f"{'n':>4} {'out':>3} {'def':>5} {'method':>14} | {'acc ts':>6} {'acc pg':>6} | "
           f"{'t ts [s]':>9} {'t pg [s]':>9} {'pg/ts':>6} | {'mem ts':>8} {'mem pg':>8} {'pg/ts':>6}")


def _print_row(row):
    mem = ""
    if "peak_mib_transync" in row:
        mem = (f"{row['peak_mib_transync']:7.1f}M {row['peak_mib_pygmtools']:7.1f}M "
               f"{row['memory_ratio']:6.1f}")
    print(f"{row['n']:>4} {('yes' if row['outliers'] else 'no'):>3} {row['deformation']:>5.2f} "
          f"{row['method']:>14} | {row['acc_transync']:6.3f} {row['acc_pygmtools']:6.3f} | "
          f"{row['time_transync_s']:9.4f} {row['time_pygmtools_s']:9.4f} "
          f"{row['time_ratio']:6.1f} | {mem}", flush=True)


def markdown(rows) -> str:
    """The README's table rows for stored result rows (one line per row); files with rows that
    record ``edges`` and ``sigma2`` get those two columns first."""
    lines = []
    for r in rows:
        lead = ""
        if "edges" in r:
            lead = f"| {r['edges']} | {r['sigma2']} "
        mem = "—"
        if "peak_mib_transync" in r:
            mem = f"{r['peak_mib_transync']:.1f} / {r['peak_mib_pygmtools']:.0f} MiB"
        lines.append(
            f"{lead}| {r['n']} | {'yes' if r['outliers'] else 'no'} | {r['deformation']} | "
            f"{r['method']} | {r['acc_transync']:.3f} / {r['acc_pygmtools']:.3f} | "
            f"{1e3 * r['time_transync_s']:.1f} ms / {1e3 * r['time_pygmtools_s']:.0f} ms | "
            f"{r['time_ratio']:.1f}x | {mem} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes, 3 trials")
    ap.add_argument("--trials", type=int, default=None, help="problems per configuration (20)")
    ap.add_argument("--sizes", type=int, nargs="+", default=None, help="n (10 20 50 100)")
    ap.add_argument("--deformations", type=float, nargs="+", default=[0.0, 0.02, 0.04])
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--sigma2", type=float, default=0.15)
    ap.add_argument("--edges", default="full", choices=("full", "delaunay"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-memory", action="store_true", help="skip the tracemalloc runs")
    ap.add_argument("--out", type=Path, default=None, help="write JSON results here")
    ap.add_argument("--markdown", type=Path, nargs="+", default=None, metavar="JSON",
                    help="print the Markdown table rows of stored results and exit")
    args = ap.parse_args(argv)
    if args.markdown:
        for path in args.markdown:
            print(markdown(json.loads(path.read_text())["rows"]))
        return
    sizes = args.sizes or ([10, 20] if args.quick else [10, 20, 50, 100])
    trials = args.trials or (3 if args.quick else 20)
    print("times: median seconds from point sets to assignment; accuracy: mean over trials; "
          "memory: tracemalloc peak (MiB), first trial")
    print(_HEADER)
    t0 = time.time()
    rows = run(sizes, args.deformations, trials, args.sigma2, args.methods, args.seed,
               memory=not args.no_memory, edges=args.edges)
    print(f"total {time.time() - t0:.0f} s")
    if args.out is not None:
        import pygmtools

        args.out.parent.mkdir(parents=True, exist_ok=True)
        meta = {"python": platform.python_version(), "numpy": np.__version__,
                "pygmtools": getattr(pygmtools, "__version__", "?"), "machine": platform.machine(),
                "sizes": sizes, "trials": trials, "sigma2": args.sigma2, "seed": args.seed,
                "edges": args.edges}
        args.out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
