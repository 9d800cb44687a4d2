"""Match two point sets with every pairwise solver and draw the RRWM correspondences.

Run: ``python examples/plot_pairwise_matching.py`` (writes ``pairwise_matching.png``).
"""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import transync  # noqa: E402
from transync.datasets import make_point_matching_problem  # noqa: E402
from transync.matching import gaussian_edge_affinity  # noqa: E402
from transync.metrics import matching_accuracy  # noqa: E402

p = make_point_matching_problem(n_inliers=30, n_outliers=5, deformation=0.02, rng=0)
aff = gaussian_edge_affinity(p.g1, p.g2, sigma2=0.05)   # never forms the 1225 x 1225 K
unary = aff.matvec(np.ones(aff.shape))                   # first-order term for the linear ones
unary /= unary.max()
for method in ["hungarian", "sinkhorn", "sm", "rrwm", "ipfp", "ga", "pf"]:
    res = transync.match_graphs(p.g1, p.g2, method=method, affinity=aff,
                                node_affinity=unary if method in ("hungarian", "sinkhorn")
                                else None)
    print(f"{method:10s} accuracy {matching_accuracy(res.assignment, p.truth):.3f}  "
          f"objective {res.objective:9.2f}  iterations {res.n_iter}")

res = transync.match_graphs(p.g1, p.g2, method="rrwm", affinity=aff)
fig, ax = plt.subplots(figsize=(7, 4))
P, Q = p.g1.points, p.g2.points + np.array([1.3, 0.0])
ax.scatter(*P.T, s=12)
ax.scatter(*Q.T, s=12)
for u, v in enumerate(res.assignment):
    if v >= 0:
        ok = p.truth[u] == v
        ax.plot([P[u, 0], Q[v, 0]], [P[u, 1], Q[v, 1]], lw=0.8,
                color="tab:green" if ok else "tab:red", alpha=0.7)
ax.set_axis_off()
ax.set_title("RRWM: green = correct, red = wrong (outliers have no true partner)")
fig.savefig("pairwise_matching.png", dpi=120, bbox_inches="tight")
