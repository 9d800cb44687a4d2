"""How often ``match_collection`` estimates the universe size right (issue #11's target).

Collections of :func:`transync.datasets.make_subgraph_collection` (``N`` graphs over a universe of
``d`` nodes, each graph keeping every node with its own probability ``p ~ U(p_low, 1)``), matched
exactly as ``transync experiment subgraph`` does for a method (its ``run_method`` and Gaussian edge
affinity) with ``n_universe=None``. The truth is the number of universe nodes kept by at least one
graph. Prints, per method, the share of collections whose estimate equals the truth (with a 95 %
Wilson interval), the mean signed error, the mean F1 and the median time.

Usage::

    python benchmarks/universe_estimate.py                       # default point, 100 collections
    python benchmarks/universe_estimate.py --collections 400 --deformation 0.05
    python benchmarks/universe_estimate.py --p-low 0.3 --methods S-RRWM
    python benchmarks/universe_estimate.py --graphs 16 --degree 6   # circulant view graph

With ``--degree k`` every graph is matched to its ``k`` nearest graphs in a circle (a view
graph, ``match_collection(pairs=...)``) and F1 is pooled over those pairs only.
"""

from __future__ import annotations

import argparse
import functools
import math
import time

import numpy as np


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion ``k / n``."""
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    den = 1 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, mid - half), min(1.0, mid + half)


def main(argv=None) -> None:
    from transync.datasets import make_subgraph_collection
    from transync.experiments.subgraph import SIGMA2, run_method, subgraph_metrics
    from transync.matching import gaussian_edge_affinity
    from transync.metrics import multimatching_precision_recall

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--collections", type=int, default=100, help="collections (default: 100)")
    ap.add_argument("--graphs", type=int, default=8, help="graphs per collection (default: 8)")
    ap.add_argument("--universe", type=int, default=20, help="universe size d (default: 20)")
    ap.add_argument("--p-low", type=float, default=0.6, help="p ~ U(p_low, 1) (default: 0.6)")
    ap.add_argument("--deformation", type=float, default=0.05, help="(default: 0.05)")
    ap.add_argument("--methods", nargs="+", default=["S-RRWM", "RRWM+spectral"],
                    help="methods of the subgraph experiment (default: S-RRWM RRWM+spectral)")
    ap.add_argument("--seed", type=int, default=5000,
                    help="first collection's seed (default: 5000)")
    ap.add_argument("--degree", type=int, default=None,
                    help="match every graph to its DEGREE neighbours on a circle (even; "
                         "default: all pairs)")
    args = ap.parse_args(argv)
    pairs = None
    if args.degree is not None:
        G = args.graphs
        pairs = sorted({tuple(sorted((i, (i + k) % G))) for i in range(G)
                        for k in range(1, args.degree // 2 + 1)})
    aff = functools.partial(gaussian_edge_affinity, sigma2=SIGMA2)
    rows = {m: [] for m in args.methods}
    for seed in range(args.seed, args.seed + args.collections):
        p = make_subgraph_collection(n_graphs=args.graphs, n_universe=args.universe,
                                     p_keep=(args.p_low, 1.0), deformation=args.deformation,
                                     rng=seed)
        truth = p.ground_truth
        for m in args.methods:
            t = time.perf_counter()
            res, sec = run_method(m, p.graphs, aff, np.random.default_rng(seed), pairs=pairs)
            met = subgraph_metrics(res, truth, sec)
            if pairs is not None:           # pooled over the matched pairs only
                met["f1"] = multimatching_precision_recall(res, truth,
                                                           pairs=np.asarray(pairs))["f1"]
            rows[m].append((met["universe_ok"], met["universe_error"], met["f1"],
                            time.perf_counter() - t))
    view = "all pairs" if pairs is None else f"circulant view graph of degree {args.degree}"
    print(f"N={args.graphs}, d={args.universe}, p ~ U({args.p_low}, 1), deformation "
          f"{args.deformation}, {view}, {args.collections} collections (seeds {args.seed}..)")
    for m, r in rows.items():
        a = np.array(r, dtype=float)
        k = int(a[:, 0].sum())
        lo, hi = wilson(k, len(a))
        print(f"{m:15s} estimate = truth {100 * k / len(a):5.1f} % (95 % CI {100 * lo:.1f}-"
              f"{100 * hi:.1f}), mean error {a[:, 1].mean():+.2f}, F1 {a[:, 2].mean():.4f}, "
              f"median {np.median(a[:, 3]):.3f} s")


if __name__ == "__main__":
    main()
