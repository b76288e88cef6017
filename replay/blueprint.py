"""The Rerun blueprint: a layout for reading the method from left to right.

Tab "Method": the panorama with masks and detections over the bearings as time series (what
the camera measured); one movement in FR with its cones and particles over the log (estimator,
skipped movements, placements) and the joint map's residuals (what one movement tells); the map
in FL with particles, estimates, 80% ellipses, trajectory and truth, over the error time series
(what the method concluded).
Tab "Fig. 1": the three priors for one bearing (impartial PDF, single Gaussian, mixture) and
their range marginals, as in the paper's Fig. 1.
"""

from __future__ import annotations

import rerun.blueprint as rrb

from replay.sinks.rerun_columns import MOVEMENT


def method_blueprint(*, fig1_priors: tuple[str, ...] = (), live: bool = False) -> rrb.Blueprint:
    """The default blueprint of ``bslam replay`` and ``bslam demo``.

    Parameters
    ----------
    fig1_priors : tuple of str
        Names under ``fig1/density/`` to show side by side on the "Fig. 1" tab (none: no tab).
    live : bool
        Follow the latest movement as it arrives (``bslam replay --follow``): the time panel
        is set to "following" on the movement timeline.
    """
    method = rrb.Horizontal(
        rrb.Vertical(
            rrb.Spatial2DView(origin="/camera", name="Panorama: masks and bearings"),
            rrb.TimeSeriesView(origin="/bearings", name="Bearings (deg)"),
            row_shares=[2, 3],
        ),
        rrb.Vertical(
            rrb.Spatial2DView(origin="/", contents="/fr/**", name="One movement in FR"),
            rrb.TextLogView(origin="/log", name="Log: estimator, skips, placements"),
            rrb.TimeSeriesView(origin="/residuals", name="Joint map: residual RMS, noise (deg)"),
            row_shares=[4, 1, 1],
        ),
        rrb.Vertical(
            rrb.Spatial2DView(origin="/", contents="/map/**", name="Map in FL (unit |L1 L2|)"),
            rrb.TimeSeriesView(origin="/error", name="Error vs truth (m)"),
            row_shares=[3, 1],
        ),
        column_shares=[2, 2, 3],
        name="Method",
    )
    parts: list[rrb.Container] = [method]
    if fig1_priors:
        densities = [
            rrb.Spatial2DView(origin=f"/fig1/density/{p}", name=f"{p} density") for p in fig1_priors
        ]
        parts.append(
            rrb.Vertical(
                rrb.Horizontal(*densities),
                rrb.BarChartView(origin="/fig1/range", name="Range marginal p(r)"),
                name="Fig. 1",
            )
        )
    return rrb.Blueprint(
        rrb.Tabs(*parts),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(
            timeline=MOVEMENT, state="collapsed", play_state="following" if live else None
        ),
    )
