"""The paper's arena (Huang, Maire & Keeratipranon 2007), defined once.

World frame, m: a 1.05 x 0.68 m KheperaSot arena with four landmarks; the map is anchored on the
reference pair (L1, L2), 0.30 m apart. The built-in scenarios ``paper`` and ``paper_omni``
(``recorder/sim/scenarios``) place their landmarks here (a test holds them to it) and
:mod:`pipeline.synthetic` uses it as its default geometry.
"""

from __future__ import annotations

#: Arena width (x) and height (y), m.
PAPER_ARENA_M: tuple[float, float] = (1.05, 0.68)

#: Landmark name -> (x, y), m, world frame.
PAPER_LANDMARKS_M: dict[str, tuple[float, float]] = {
    "L1": (0.375, 0.55),
    "L2": (0.675, 0.55),
    "L3": (0.20, 0.20),
    "L4": (0.85, 0.18),
}

#: The two landmarks the map is anchored on (FL: first at (0, 0), second at (1, 0)).
PAPER_REFERENCE: tuple[str, str] = ("L1", "L2")
