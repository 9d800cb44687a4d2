"""Synthetic generators and real-data loaders.

The rendered scenes and the image loaders need OpenCV (and scikit-image); they are imported on
first use, so that ``import transync.datasets`` stays light.
"""
from .._lazy import lazy_attributes
from ._graphs import (  # noqa: F401
    GraphCollectionProblem,
    PairwiseProblem,
    make_graph_collection,
    make_pairwise_problem,
    make_point_matching_problem,
)
from ._home import data_home  # noqa: F401
from ._permutations import PermutationCollection, make_permutation_collection  # noqa: F401
from ._transforms import (  # noqa: F401
    TransformProblem,
    make_noisy_homographies,
    make_noisy_linear_maps,
)

#: public name -> private module that defines it, imported on first access
_LAZY = {
    "PlanarScene": "._scenes",
    "make_planar_scene": "._scenes",
    "AdelaideRMFPair": "._image_loaders",
    "HomographySequence": "._image_loaders",
    "list_adelaidermf": "._image_loaders",
    "load_adelaidermf": "._image_loaders",
    "load_graf": "._image_loaders",
    "load_hpatches_sequence": "._image_loaders",
    "load_oxford_sequence": "._image_loaders",
    "read_image": "._image_loaders",
    "LANDMARK_AFFINITY": "._cmu",
    "LandmarkSequence": "._cmu",
    "load_cmu_sequence": "._cmu",
    "load_willow_class": "._willow",
    "TUDataset": "._tu",
    "list_tu": "._tu",
    "load_tu": "._tu",
    "SubgraphCollectionProblem": "._subgraphs",
    "make_subgraph_collection": "._subgraphs",
}

__all__ = [
    "GraphCollectionProblem",
    "PairwiseProblem",
    "PermutationCollection",
    "TransformProblem",
    "data_home",
    "make_graph_collection",
    "make_noisy_homographies",
    "make_noisy_linear_maps",
    "make_pairwise_problem",
    "make_permutation_collection",
    "make_point_matching_problem",
    *_LAZY,
]


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())
