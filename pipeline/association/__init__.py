"""Association of detections of landmarks that look alike (several catalog landmarks share a
colour or a band code) with the map, and new landmarks started from hypotheses.

:class:`Associator` is the entry point: per movement it places the two keyframes from the
landmarks whose class is their own (else, after a placed movement, by matching every detection
with the map), predicts the bearing of every mapped landmark of a shared
class with its uncertainty, gates and assigns detections one-to-one, starts hypotheses from
detections no landmark explains, and confirms or drops them as movements arrive; once the log is
processed it places the movements the map left out by matching and associates every keyframe
again with the final map. Maths:
docs/method.md (association).
"""

from pipeline.association.assign import Assignment, assign
from pipeline.association.predict import predict_bearings, ray_point_cov
from pipeline.association.result import MovementAssociation
from pipeline.association.tracker import Associator, pose_between

__all__ = [
    "Assignment",
    "Associator",
    "MovementAssociation",
    "assign",
    "pose_between",
    "predict_bearings",
    "ray_point_cov",
]
