"""Multi-view plane homographies (being written)."""
