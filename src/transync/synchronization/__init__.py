"""Synchronization of pairwise transformations (being written)."""

from ._linear_maps import LinearMapSyncResult, synchronize_homographies, synchronize_linear_maps

__all__ = ["LinearMapSyncResult", "synchronize_homographies", "synchronize_linear_maps"]
