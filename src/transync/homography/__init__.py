"""Multi-view plane homographies: sparse initialization, synchronization, dense refinement,
plane segmentation and the accuracy measures used to evaluate them."""

from ._dense import mean_warped_image, refine_homography_ecc, warp_to_reference
from ._evaluate import chained_homographies, evaluate_alignment, to_reference_homographies
from ..metrics import (
    brenner_focus,
    corner_accuracy,
    corner_error,
    misclassification_error,
    pairwise_corner_error,
    segmentation_scores,
)
from ._multiplane import MultiPlaneResult, extract_planes
from ._pipeline import (
    DenseOptions,
    PlaneAlignmentResult,
    estimate_plane_homographies,
    view_graph_pairs,
)
from ._segmentation import PlaneSegmentation, segment_plane, segment_plane_evidence
from ._sparse import (
    PairwiseHomographies,
    estimate_pairwise_homographies,
    estimate_rectified_pairwise,
    load_images,
    sift_features,
    to_gray,
)

__all__ = [
    "DenseOptions",
    "MultiPlaneResult",
    "PairwiseHomographies",
    "PlaneAlignmentResult",
    "PlaneSegmentation",
    "brenner_focus",
    "chained_homographies",
    "corner_accuracy",
    "corner_error",
    "estimate_pairwise_homographies",
    "estimate_rectified_pairwise",
    "load_images",
    "sift_features",
    "to_gray",
    "evaluate_alignment",
    "extract_planes",
    "estimate_plane_homographies",
    "mean_warped_image",
    "misclassification_error",
    "pairwise_corner_error",
    "refine_homography_ecc",
    "segment_plane",
    "segment_plane_evidence",
    "segmentation_scores",
    "to_reference_homographies",
    "view_graph_pairs",
    "warp_to_reference",
]
