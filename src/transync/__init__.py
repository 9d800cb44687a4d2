"""transync: transformation synchronization for graph matching and multi-view geometry.

Front doors (keyword-only options, ``method=`` strings, frozen dataclass results):

* :func:`match_graphs` — pairwise graph matching (hungarian, sinkhorn, sm, rrwm, ipfp, ga, pf);
* :func:`synchronize_permutations` — consistent multi-matchings from pairwise assignments;
* :func:`synchronize_doubly_stochastic` — Birkhoff-polytope synchronization of soft matchings;
* :func:`match_collection` — multi-graph matching: S-GA, S-RRWM, S-PF, offline sync, CAO;
* :func:`synchronize_linear_maps` / :func:`synchronize_homographies` — invertible maps, SL(3);
* :func:`estimate_plane_homographies` — consistent plane homographies and masks across views.

Subpackages are imported on first use, so ``import transync`` stays light (OpenCV and
scikit-image load only with :mod:`transync.homography`).

>>> import transync
>>> transync.match_graphs.__name__
'match_graphs'
"""

from __future__ import annotations

from ._lazy import lazy_attributes

__version__ = "0.1.0"

_LAZY = {
    # name: (module, attribute or None for the module itself)
    "match_graphs": ("transync.matching", "match_graphs"),
    "MatchingResult": ("transync.matching", "MatchingResult"),
    "Graph": ("transync.graphs", "Graph"),
    "MultiMatching": ("transync.permutations", "MultiMatching"),
    "synchronize_permutations": ("transync.synchronization", "synchronize_permutations"),
    "synchronize_doubly_stochastic": ("transync.synchronization",
                                      "synchronize_doubly_stochastic"),
    "synchronize_linear_maps": ("transync.synchronization", "synchronize_linear_maps"),
    "synchronize_homographies": ("transync.synchronization", "synchronize_homographies"),
    "match_collection": ("transync.multigraph", "match_collection"),
    "MultiMatchingResult": ("transync.multigraph", "MultiMatchingResult"),
    "estimate_plane_homographies": ("transync.homography", "estimate_plane_homographies"),
    "PlaneAlignmentResult": ("transync.homography", "PlaneAlignmentResult"),
    "DenseOptions": ("transync.homography", "DenseOptions"),
    "PermutationSyncResult": ("transync.synchronization", "PermutationSyncResult"),
    "BirkhoffSyncResult": ("transync.synchronization", "BirkhoffSyncResult"),
    "LinearMapSyncResult": ("transync.synchronization", "LinearMapSyncResult"),
    "birkhoff_von_neumann": ("transync.synchronization", "birkhoff_von_neumann"),
    "ConvergenceWarning": ("transync.exceptions", "ConvergenceWarning"),
    "DegenerateInputError": ("transync.exceptions", "DegenerateInputError"),
    "ExecutorError": ("transync.exceptions", "ExecutorError"),
    "datasets": ("transync.datasets", None),
    "experiments": ("transync.experiments", None),
    "geometry": ("transync.geometry", None),
    "graphs": ("transync.graphs", None),
    "homography": ("transync.homography", None),
    "matching": ("transync.matching", None),
    "metrics": ("transync.metrics", None),
    "multigraph": ("transync.multigraph", None),
    "parallel": ("transync.parallel", None),
    "permutations": ("transync.permutations", None),
    "synchronization": ("transync.synchronization", None),
}

__all__ = ["__version__", *_LAZY]


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())
