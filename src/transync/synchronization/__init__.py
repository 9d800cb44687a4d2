"""Synchronization of pairwise transformations.

* Permutations and partial permutations (multi-matching through a universe of nodes):
  :func:`synchronize_permutations` (``method="spectral" | "orthogonal" | "matcheig"``).
* Soft (doubly-stochastic) pairwise matches, projected onto the convex hull of consistent
  permutation configurations: :func:`synchronize_doubly_stochastic`; and the
  Birkhoff-von Neumann decomposition :func:`birkhoff_von_neumann`. The universe size of
  objects of different sizes from soft matches alone: :func:`estimate_universe`.
* Invertible linear maps and homographies: :func:`synchronize_linear_maps`,
  :func:`synchronize_homographies`.

Every permutation and Birkhoff result carries its consistent multi-matching as a
:class:`transync.permutations.MultiMatching` (``result.matching``). Every function reads its
pairwise input through one parser, with one meaning of ``mask``: it selects the pairs to use
(pair ``{i, j}`` when ``mask[i, j] or mask[j, i]``), for a dict, triples or a dense array alike,
and ignores the diagonal. Results are frozen dataclasses and pickle.
"""

from ._birkhoff import (
    BirkhoffSyncResult,
    UniverseEstimate,
    birkhoff_von_neumann,
    estimate_universe,
    synchronize_doubly_stochastic,
)
from ._linear_maps import LinearMapSyncResult, synchronize_homographies, synchronize_linear_maps
from ._permutations import synchronize_permutations
from ._result import PermutationSyncResult

__all__ = [
    "BirkhoffSyncResult",
    "LinearMapSyncResult",
    "PermutationSyncResult",
    "UniverseEstimate",
    "birkhoff_von_neumann",
    "estimate_universe",
    "synchronize_doubly_stochastic",
    "synchronize_homographies",
    "synchronize_linear_maps",
    "synchronize_permutations",
]
