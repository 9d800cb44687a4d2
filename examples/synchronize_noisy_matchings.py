"""Repair corrupted pairwise matchings with permutation synchronization.

Run: ``python examples/synchronize_noisy_matchings.py``.
"""

import numpy as np

import transync
from transync.datasets import make_permutation_collection

c = make_permutation_collection(n_objects=30, n_nodes=20, corruption=0.4, rng=0)
right = np.mean([np.mean(a == c.true_pairwise(i, j)) for (i, j), a in c.pairwise.items()])
print(f"input: {right:.3f} of the pairwise correspondences are right")
for method in ["spectral", "orthogonal", "matcheig"]:
    res = transync.synchronize_permutations(c.pairwise, method=method)
    rep = res.info["input_consistency"]
    print(f"{method:10s} accuracy {c.accuracy(res.labels):.3f}  "
          f"cycle-consistent {res.cycle_consistent}  "
          f"(input: {rep['inconsistent_triangles']:.0%} of triangles inconsistent)")
