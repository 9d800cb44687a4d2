"""Transitive assignment kernels for graph classification (thesis ch. 4; methods page
*Transitive assignment kernels*).

Optimal-assignment graph kernels compare graphs by their best node alignment; pairwise-optimal
alignments contradict each other, so the similarity matrix is not positive semidefinite.
Synchronizing the alignments onto one universe of node slots makes the kernel an inner product
in a fixed feature space, hence PSD by construction.

Front door: the scikit-learn transformer :class:`TransitiveAssignmentKernel` (``fit(graphs)``,
``transform(graphs)`` -> Gram matrix against the fitted graphs). Its stages are public:

* node features -- :func:`heat_kernel_signature`, :func:`hks_features` (grid :data:`HKS_TIMES`);
* pairwise matching of padded graphs -- :func:`match_pairs` (:data:`PAIRWISE_MATCHERS`,
  width :func:`default_sigma2`);
* which pairs to match -- :func:`view_graph` (all pairs, or each graph's nearest graphs under
  :func:`graph_descriptors` plus a spanning tree), :func:`nearest_graphs`;
* synchronization onto the transitive space -- :func:`synchronize_alignments` -> :class:`Alignment`;
  inductive placement of new graphs -- :func:`place_graphs`;
* aligned features and kernels -- :func:`aligned_features`, :func:`relaxed_features`,
  :func:`assignment_kernel` (:data:`KERNELS`, width :func:`median_gamma`); size pruning --
  :func:`prune_by_size`;
* baselines -- :func:`graphlet3_kernel` (:func:`graphlet3_counts`), :func:`hks_oa_kernel`,
  :func:`pairwise_assignment_kernel` (the kernel on the unsynchronized pairwise maps),
  :func:`hks_mean_kernel`, :func:`random_walk_kernel`, :func:`grakel_kernel`
  (:data:`GRAKEL_KERNELS`);
* evaluation -- :func:`cosine_normalize`, :func:`spectrum`, :func:`min_eigenvalue_ratio`,
  :func:`repeated_cv` (-> :class:`CVResult`), :func:`paired_ttest`.

Names load on first use.
"""

from __future__ import annotations

from .._lazy import lazy_attributes

_LAZY = {
    # heat kernel signature and the batched pairwise matcher
    "HKS_TIMES": "._hks",
    "heat_kernel_signature": "._hks",
    "hks_features": "._hks",
    "DUMMY_AFFINITY": "._pairwise",
    "LABEL_MISMATCH": "._pairwise",
    "PAIRWISE_MATCHERS": "._pairwise",
    "default_sigma2": "._pairwise",
    "match_pairs": "._pairwise",
    # transitive synchronization and kernels
    "Alignment": "._transitive",
    "KERNELS": "._transitive",
    "SYNC_METHODS": "._transitive",
    "aligned_features": "._transitive",
    "assignment_kernel": "._transitive",
    "graph_descriptors": "._transitive",
    "nearest_graphs": "._transitive",
    "median_gamma": "._transitive",
    "pairwise_assignment_kernel": "._transitive",
    "place_graphs": "._transitive",
    "prune_by_size": "._transitive",
    "relaxed_features": "._transitive",
    "synchronize_alignments": "._transitive",
    "view_graph": "._transitive",
    "TransitiveAssignmentKernel": "._estimator",
    # baselines and evaluation
    "GRAKEL_KERNELS": "._baselines",
    "graphlet3_counts": "._baselines",
    "graphlet3_kernel": "._baselines",
    "grakel_kernel": "._baselines",
    "hks_mean_kernel": "._baselines",
    "hks_oa_kernel": "._baselines",
    "random_walk_kernel": "._baselines",
    "CVResult": "._evaluate",
    "DEFAULT_C_GRID": "._evaluate",
    "MAX_KERNEL_TIMES_C": "._evaluate",
    "cosine_normalize": "._evaluate",
    "min_eigenvalue_ratio": "._evaluate",
    "paired_ttest": "._evaluate",
    "repeated_cv": "._evaluate",
    "spectrum": "._evaluate",
}

__all__ = sorted(_LAZY)


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())
