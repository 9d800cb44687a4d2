"""Benchmark: permutation synchronization time and peak memory vs the number of objects N.

Every run happens in a fresh subprocess so that ``ru_maxrss`` is the peak of that run alone
(peak RSS of the child minus its RSS before the call is reported as ``peak MB``; tracemalloc
would miss SciPy's C++ allocations). The dense path (``eigh`` on the full block matrix) and the
matrix-free path (sparse block operator + block Krylov) run side by side; the dense one only up
to ``--dense-max`` total nodes. Prints a table and the fitted growth exponent of time vs N per
path. Issue #3 target: N=1000, n=30, 20 % corrupted pairs: < 60 s, < 4 GB, accuracy >= 0.99.

    python benchmarks/synchronization.py            # N = 64 ... 2000 (minutes)
    python benchmarks/synchronization.py --quick    # N = 32 ... 256
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import numpy as np

CHILD = r"""
import json, resource, sys, time
from transync.datasets import make_permutation_collection
from transync.synchronization import synchronize_permutations
N, n, corruption, solver = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
data = make_permutation_collection(N, n, corruption=corruption, rng=0)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
res = synchronize_permutations(data.pairwise, solver=solver, rng=0)
sec = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"N": N, "path": res.info["solver"], "seconds": sec,
                  "peak_mb": peak / 1024, "extra_mb": (peak - before) / 1024,
                  "accuracy": data.accuracy(res.labels),
                  "eigen_s": res.info.get("seconds_eigen", float("nan")),
                  "n_products": res.n_iter}))
"""


def run_one(N, n, corruption, solver):
    out = subprocess.run([sys.executable, "-c", CHILD, str(N), str(n), str(corruption), solver],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes only")
    ap.add_argument("--n-nodes", type=int, default=30)
    ap.add_argument("--corruption", type=float, default=0.2)
    ap.add_argument("--sizes", type=int, nargs="*", default=None)
    ap.add_argument("--dense-max", type=int, default=6000,
                    help="largest N * n for the dense path")
    ap.add_argument("--json", default=None, help="write the rows to this JSON file")
    args = ap.parse_args(argv)
    sizes = args.sizes or ([32, 64, 128, 256] if args.quick else [64, 128, 256, 512, 1000, 2000])
    rows = []
    print(f"{'N':>6} {'path':>12} {'seconds':>9} {'eigen s':>8} {'peak MB':>9} {'+MB':>8} "
          f"{'accuracy':>9}")
    for N in sizes:
        for solver in ("dense", "matrix_free"):
            if solver == "dense" and N * args.n_nodes > args.dense_max:
                continue
            r = run_one(N, args.n_nodes, args.corruption, solver)
            rows.append(r)
            print(f"{r['N']:>6} {r['path']:>12} {r['seconds']:>9.2f} {r['eigen_s']:>8.2f} "
                  f"{r['peak_mb']:>9.0f} {r['extra_mb']:>8.0f} {r['accuracy']:>9.4f}", flush=True)
    for path in ("dense", "matrix_free"):
        pts = [(r["N"], r["seconds"]) for r in rows if r["path"] == path and r["seconds"] > 0]
        if len(pts) >= 2:
            x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
            slope = np.polyfit(x, y, 1)[0]
            print(f"{path}: time ~ N^{slope:.2f} over N = {pts[0][0]} .. {pts[-1][0]}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()
