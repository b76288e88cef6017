"""The experiment's series in a Rerun recording (``experiment.rrd``), beside the PNG figures.

Entities (each a scalar series with its 80% band as ``lo``/``hi`` siblings where it has one):

- ``fig7/<landmark>/{mean,lo,hi}`` on timeline ``movement`` (impartial prior, n_l);
- ``fig8/{mean,lo,hi}`` on timeline ``n_l`` (after ``n_l_movements`` movements);
- ``comparison/<method>`` on timeline ``movement`` (mean over runs and scored landmarks);
- ``calibration/<method>`` on timeline ``movement`` (share of 80% regions holding the truth);
- ``fig1/...``: the three priors of one bearing (:func:`replay.fig1.log_fig1`).

Values in centimetres (calibration: a fraction).
"""

from __future__ import annotations

import math
from pathlib import Path

import rerun as rr

from replay.experiments.results import CRB, Results
from replay.experiments.stats import Band, calibration, movement_curve, n_l_curve, select
from replay.fig1 import log_fig1

APPLICATION_ID = "bslam_experiment"


def _log_bands(rec: rr.RecordingStream, entity: str, timeline: str, bands: dict[int, Band]) -> None:
    for part, color in (("mean", (31, 119, 180)), ("lo", (150, 150, 150)), ("hi", (150, 150, 150))):
        rec.log(f"{entity}/{part}", rr.SeriesLines(colors=[color], names=[part]), static=True)
    for x, b in sorted(bands.items()):
        rec.set_time(timeline, sequence=x)
        rec.log(f"{entity}/mean", rr.Scalars(b.mean))
        rec.log(f"{entity}/lo", rr.Scalars(b.lo))
        rec.log(f"{entity}/hi", rr.Scalars(b.hi))


def write_rrd(results: Results, path: Path) -> Path:
    """Write the experiment's series to ``path`` (an ``.rrd`` file) and return it."""
    cfg = results.config
    proto = cfg["protocol"]
    scored = cfg["scored_landmarks"]
    rec = rr.RecordingStream(APPLICATION_ID)
    rec.save(path)
    log_fig1(rec, math.radians(float(cfg["scenario"]["vision_error_deg"])))
    for name in scored:
        bands = movement_curve(results.rows, method="impartial", n_l=proto["n_l"], landmarks=[name])
        _log_bands(rec, f"fig7/{name}", "movement", bands)
    if proto["n_l_values"]:
        bands = n_l_curve(
            results.rows, method="impartial", movement=proto["n_l_movements"], landmarks=scored
        )
        _log_bands(rec, "fig8", "n_l", bands)
    for method in cfg["methods"]:
        n_l = proto["n_l"] if method in proto["priors"] else 0
        curve = movement_curve(results.rows, method=method, n_l=n_l, landmarks=scored)
        for m, b in sorted(curve.items()):
            rec.set_time("movement", sequence=m)
            rec.log(f"comparison/{method}", rr.Scalars(b.mean))
            if method == CRB:
                continue
            share, n = calibration(
                select(results.rows, method=method, n_l=n_l, movement=m, landmarks=scored)
            )
            if n:
                rec.log(f"calibration/{method}", rr.Scalars(share))
    rec.flush()
    rec.disconnect()
    return path
