"""Pure computation: bearings in, particle sets and estimates out (no I/O)."""

from pipeline.cones import ConeIntersection, Degenerate, intersect_cones, vision_cone_polygon
from pipeline.crb import cramer_rao_bound, fisher_information, truncated_gaussian_std
from pipeline.estimate import LandmarkEstimate
from pipeline.frame_change import change_frame
from pipeline.fusion import LikelihoodUpdate, fuse, fuse_likelihood
from pipeline.init_fr import initialize_fr, sample_fr_posterior
from pipeline.likelihood import FrameLikelihood
from pipeline.priors import (
    R_MAX_FR,
    R_MIN_FR,
    GaussianPrior,
    ImpartialPrior,
    MixturePrior,
    make_prior,
    prior_density_grid,
    range_marginal,
)
from pipeline.slam import BearingSlam, MovementObservation, MovementResult


def __getattr__(name: str) -> object:
    # batch_least_squares needs scipy.optimize (~0.25 s to import): load it on first use only,
    # so that `bslam process` and `bslam replay` do not pay for it.
    if name == "batch_least_squares":
        from pipeline.batch_ls import batch_least_squares

        return batch_least_squares
    raise AttributeError(f"module 'pipeline' has no attribute {name!r}")


__all__ = [
    "R_MAX_FR",
    "R_MIN_FR",
    "BearingSlam",
    "ConeIntersection",
    "Degenerate",
    "FrameLikelihood",
    "GaussianPrior",
    "ImpartialPrior",
    "LandmarkEstimate",
    "LikelihoodUpdate",
    "MixturePrior",
    "MovementObservation",
    "MovementResult",
    "batch_least_squares",
    "change_frame",
    "cramer_rao_bound",
    "fisher_information",
    "fuse",
    "fuse_likelihood",
    "initialize_fr",
    "intersect_cones",
    "make_prior",
    "prior_density_grid",
    "range_marginal",
    "sample_fr_posterior",
    "truncated_gaussian_std",
    "vision_cone_polygon",
]
