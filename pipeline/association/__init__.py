"""Association of detections of landmarks that look alike (several catalog landmarks share a
colour or a band code) with the map, and new landmarks started from hypotheses.

:class:`Associator` (``tracker.py``) is the entry point and composes the steps. Per movement:
placement for association (``match.py``), predictions of the named landmarks (``predict.py``),
the gated one-to-one assignment of the movement's detections (``assign.py``:
:func:`assign_movement` returns the :class:`MovementAssignment` record), then after the
estimator the hypotheses' lifecycle, where landmarks are named (``lifecycle.py``), and the
support of each name (``support.py``); what association did for the movement is a
:class:`MovementAssociation` (``result.py``). Once the log is processed every keyframe is
associated again with the final map and names are repaired (``final.py``). Maths:
docs/method.md (association).
"""

from pipeline.association.assign import Assignment, MovementAssignment, assign, assign_movement
from pipeline.association.predict import predict_bearings, ray_point_cov
from pipeline.association.result import MovementAssociation
from pipeline.association.tracker import Associator

__all__ = [
    "Assignment",
    "Associator",
    "MovementAssignment",
    "MovementAssociation",
    "assign",
    "assign_movement",
    "predict_bearings",
    "ray_point_cov",
]
