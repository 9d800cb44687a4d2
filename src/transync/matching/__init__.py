"""Pairwise graph matching (being written)."""
