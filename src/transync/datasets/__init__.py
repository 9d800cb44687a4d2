"""Synthetic generators and real-data loaders."""
from ._graphs import (  # noqa: F401
    GraphCollectionProblem,
    PairwiseProblem,
    make_graph_collection,
    make_pairwise_problem,
    make_point_matching_problem,
)
from ._permutations import PermutationCollection, make_permutation_collection  # noqa: F401
from ._scenes import PlanarScene, make_planar_scene  # noqa: F401
from ._transforms import TransformProblem, make_noisy_homographies, make_noisy_linear_maps  # noqa: F401
from ._home import data_home  # noqa: F401
from ._image_loaders import (  # noqa: F401
    AdelaideRMFPair,
    HomographySequence,
    list_adelaidermf,
    load_adelaidermf,
    load_graf,
    load_hpatches_sequence,
    load_oxford_sequence,
)
