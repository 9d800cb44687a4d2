"""Synchronization of pairwise transformations.

* Permutations and partial permutations (multi-matching through a universe of nodes):
  :func:`synchronize_permutations` (``method="spectral" | "orthogonal" | "matcheig"``).
* Soft (doubly-stochastic) pairwise matches, projected onto the convex hull of consistent
  permutation configurations: :func:`synchronize_doubly_stochastic`; and the
  Birkhoff-von Neumann decomposition :func:`birkhoff_von_neumann`.
* Invertible linear maps and homographies: :func:`synchronize_linear_maps`,
  :func:`synchronize_homographies`.
"""

from ._birkhoff import BirkhoffSyncResult, birkhoff_von_neumann, synchronize_doubly_stochastic
from ._linear_maps import LinearMapSyncResult, synchronize_homographies, synchronize_linear_maps
from ._permutations import synchronize_permutations
from ._result import PermutationSyncResult

__all__ = [
    "BirkhoffSyncResult",
    "LinearMapSyncResult",
    "PermutationSyncResult",
    "birkhoff_von_neumann",
    "synchronize_doubly_stochastic",
    "synchronize_homographies",
    "synchronize_linear_maps",
    "synchronize_permutations",
]
