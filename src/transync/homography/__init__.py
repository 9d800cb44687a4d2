"""Multi-view plane homographies: sparse initialization, synchronization, dense refinement,
plane segmentation and the accuracy measures used to evaluate them."""

from ._dense import mean_warped_image, refine_homography_ecc
from ._metrics import (
    brenner_focus,
    corner_accuracy,
    corner_error,
    pairwise_corner_error,
    segmentation_scores,
)
from ._pipeline import PlaneAlignmentResult, estimate_plane_homographies
from ._segmentation import segment_plane
from ._sparse import PairwiseHomographies, estimate_pairwise_homographies

__all__ = [
    "PairwiseHomographies",
    "PlaneAlignmentResult",
    "brenner_focus",
    "corner_accuracy",
    "corner_error",
    "estimate_pairwise_homographies",
    "estimate_plane_homographies",
    "mean_warped_image",
    "pairwise_corner_error",
    "refine_homography_ecc",
    "segment_plane",
    "segmentation_scores",
]
