"""Thesis experiments (being written)."""
