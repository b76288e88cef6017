"""Display colours shared by the viewers' sinks (Rerun, the derived log's Foxglove channels)."""

from __future__ import annotations

from data_schemas.colors import NOMINAL_BGR
from data_schemas.session import Session, shared_classes
from pipeline.association.result import slot_name

ELLIPSE_RGB = (190, 150, 255)  # 80% regions: a hue no landmark class uses
TRUTH_RGB = (240, 240, 240)
TRAJECTORY_RGB = (255, 160, 0)
REJECTED_RGB = (128, 128, 128)  # blobs rejected as landmarks: grey


def landmark_rgb(session: Session) -> dict[str, tuple[int, int, int]]:
    """Display colour (RGB) of each catalog landmark: its nominal colour (top band if coded)."""
    out = {}
    for spec in session.landmarks:
        b, g, r = NOMINAL_BGR.get(spec.bands[0] if spec.bands else str(spec.color), (200, 200, 200))
        out[spec.name] = (r, g, b)
    for label, names in shared_classes(session.landmarks).items():  # red#1 ... as their class
        out.update({slot_name(label, k): out[names[0]] for k in range(1, len(names) + 1)})
    return out
