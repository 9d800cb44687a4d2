"""Pairwise graph matching: affinities and solvers behind ``match_graphs``."""

from ._affinity import (
    Affinity,
    DenseAffinity,
    FactorizedAffinity,
    SeparableAffinity,
    SparseAffinity,
    as_affinity,
    gaussian_edge_affinity,
    gaussian_node_affinity,
)

__all__ = [
    "Affinity",
    "DenseAffinity",
    "FactorizedAffinity",
    "SeparableAffinity",
    "SparseAffinity",
    "as_affinity",
    "gaussian_edge_affinity",
    "gaussian_node_affinity",
]
