"""Multi-view plane homographies: sparse initialization, synchronization, dense refinement,
plane segmentation and the accuracy measures used to evaluate them."""

from ._metrics import (
    brenner_focus,
    corner_accuracy,
    corner_error,
    pairwise_corner_error,
    segmentation_scores,
)

__all__ = [
    "brenner_focus",
    "corner_accuracy",
    "corner_error",
    "pairwise_corner_error",
    "segmentation_scores",
]
