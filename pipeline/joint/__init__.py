"""The joint estimator: every bearing in one GTSAM factor graph, initialized by the paper's filter.

Modules: ``state`` (settings, movements, and :class:`~pipeline.joint.state.MapState`, what a
rollback restores), ``placement`` (where a movement is placed), ``mapgraph`` (the iSAM2 graph's
bookkeeping), ``robustness`` (outliers, reseating, divergence, rollback), ``window`` (old
movements marginalized out of the graph), ``graph`` (GTSAM keys and factors), ``noise``
(bearing noise from residuals), ``table`` (the map's bearings as arrays, for its residuals),
``result`` (per-movement result), ``estimator`` (:class:`JointSlam`, which composes them for
one movement). The gtsam-free geometry it shares with association (resection, ray
intersection) is :mod:`pipeline.geometry`. ``JointSlam`` is loaded on first use: ``gtsam``
costs ~0.3 s to import, and reading a result needs none of it.
"""

from typing import Any

from pipeline.joint.noise import NoiseEstimate
from pipeline.joint.result import JointMovementResult


def __getattr__(name: str) -> Any:
    if name == "JointSlam":
        from pipeline.joint.estimator import JointSlam

        return JointSlam
    raise AttributeError(f"module 'pipeline.joint' has no attribute {name!r}")


__all__ = ["JointMovementResult", "JointSlam", "NoiseEstimate"]
