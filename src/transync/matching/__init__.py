"""Pairwise graph matching: affinities and solvers behind ``match_graphs``."""

from ._affinity import (
    DEFAULT_SIGMA2,
    MAX_SEPARABLE_ERROR,
    Affinity,
    DenseAffinity,
    FactorizedAffinity,
    GaussianEdgeFactors,
    SeparableAffinity,
    SparseAffinity,
    as_affinity,
    gaussian_edge_affinity,
    gaussian_edge_factors,
    gaussian_node_affinity,
    prefers_separable,
)
from ._front import METHODS, match_graphs, solver_options
from ._ga import GAStepper, annealing_levels, default_beta_max, ga
from ._ipfp import IPFPStepper, ipfp
from ._linear import hungarian, sinkhorn
from ._pf import PFStepper, pf
from ._result import MatchingResult
from ._rrwm import RRWMStepper, rrwm
from ._sinkhorn import SinkhornBatchOutput, sinkhorn_augmented_batch, sinkhorn_batch
from ._sm import SMStepper, sm
from ._stepwise import Stepper
from ._verify import VERIFY_MODELS, VerificationResult, verify_assignment

__all__ = [
    "DEFAULT_SIGMA2",
    "MAX_SEPARABLE_ERROR",
    "Affinity",
    "DenseAffinity",
    "FactorizedAffinity",
    "GaussianEdgeFactors",
    "SeparableAffinity",
    "SparseAffinity",
    "VERIFY_MODELS",
    "VerificationResult",
    "as_affinity",
    "gaussian_edge_affinity",
    "gaussian_edge_factors",
    "gaussian_node_affinity",
    "prefers_separable",
    "GAStepper",
    "IPFPStepper",
    "METHODS",
    "MatchingResult",
    "PFStepper",
    "RRWMStepper",
    "SMStepper",
    "SinkhornBatchOutput",
    "Stepper",
    "annealing_levels",
    "default_beta_max",
    "ga",
    "hungarian",
    "ipfp",
    "match_graphs",
    "pf",
    "rrwm",
    "sinkhorn",
    "sinkhorn_augmented_batch",
    "sinkhorn_batch",
    "sm",
    "solver_options",
    "verify_assignment",
]
