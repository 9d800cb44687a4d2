"""
Repair corrupted matchings with permutation synchronization
===========================================================

Thirty objects of 20 nodes each; every pairwise matching between them has 40% of its
correspondences replaced by random ones. Permutation synchronization finds one labelling of
every object's nodes by a common universe, so that all the pairwise maps it implies are
cycle-consistent, and recovers the truth from the redundancy of the pairs
(:func:`transync.synchronize_permutations`; the methods are described on the methods page
*Permutation synchronization*).

Run ``python examples/synchronize_noisy_matchings.py``; it prints and writes nothing else.
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

# %%
# ``matcheig`` (Maset et al.) returns pairwise maps that are each a permutation but are not
# forced to agree around cycles, hence ``cycle-consistent False``; ``spectral`` and
# ``orthogonal`` return a multi-matching, consistent by construction.
