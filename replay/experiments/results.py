"""The results file of an experiment: every run's error per method, landmark and movement.

``results.json`` is the authoritative file (configuration, geometry, per-run status, rows);
``errors.csv`` holds the same rows flat for spreadsheets. Errors are Euclidean distances in FL
(unit |L1 L2|) and in centimetres (times the true |L1 L2| of the run's scenario).
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from data_schemas.errors import BslamError
from replay.defaults import PRIORS

RESULTS_NAME = "results.json"
CSV_NAME = "errors.csv"

#: methods whose rows are estimates (the rest are bounds)
ESTIMATORS = (*PRIORS, "joint", "batch_ls")
#: the Cramér–Rao bound rows: error_fl = sqrt(trace(CRB)), a Gaussian-equivalent line
CRB = "crb"

#: the paper's Fig. 7 reading: about 2 cm after 3 movements
PAPER_ERROR_CM = 2.0
#: How reports and figures name each method.
METHOD_LABELS = {
    "impartial": "impartial PDF",
    "gaussian": "single Gaussian",
    "mixture": "Gaussian mixture",
    "joint": "joint estimator (GTSAM)",
    "batch_ls": "batch least squares",
    CRB: "Cramér–Rao bound",
}


class ResultsError(BslamError):
    """A results file is missing or malformed."""


@dataclass(frozen=True)
class ErrorRow:
    """The error of one estimate of one landmark after some movements of one run.

    Attributes
    ----------
    group : str
        Which configuration the run belongs to (``"paper"`` or ``"<param>=<value>"`` in a sweep).
    run : int
        Run index within the group.
    method : str
        ``impartial``, ``gaussian``, ``mixture`` (the paper's filter with each prior), ``joint``
        (the joint estimator), ``batch_ls`` or ``crb``.
    n_l : int
        Particles per landmark in FL (0 for ``batch_ls`` and ``crb``).
    movement : int
        Number of straight movements processed (1-based).
    landmark : str
        Landmark name (not a reference landmark).
    error_fl : float
        Distance from the estimate to the truth, FL units (NaN: no estimate yet).
    error_cm : float
        The same in centimetres.
    inside_80 : bool or None
        Whether the 80% credible region holds the truth (None when the method gives no region).
    """

    group: str
    run: int
    method: str
    n_l: int
    movement: int
    landmark: str
    error_fl: float
    error_cm: float
    inside_80: bool | None


@dataclass(frozen=True)
class RunRecord:
    """What happened to one run: its seed, its log, its status and how long it took."""

    group: str
    run: int
    seed: int
    log: str
    status: str
    seconds: float


@dataclass
class Results:
    """A whole experiment: configuration, per-run records and error rows."""

    experiment: str
    config: dict[str, Any]
    runs: list[RunRecord] = field(default_factory=list)
    rows: list[ErrorRow] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)

    def failed(self) -> list[RunRecord]:
        """Runs whose status is not ``ok``."""
        return [r for r in self.runs if r.status != "ok"]


def json_float(x: float) -> float | None:
    """``x``, or None when it is not finite (JSON has no NaN or infinity)."""
    return x if math.isfinite(x) else None


def write_results(results: Results, out_dir: Path) -> Path:
    """Write ``results.json`` and ``errors.csv`` into ``out_dir``; return the JSON path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for r in results.rows:
        d = asdict(r)
        d["error_fl"] = json_float(r.error_fl)
        d["error_cm"] = json_float(r.error_cm)
        rows.append(d)
    doc = {
        "experiment": results.experiment,
        "config": results.config,
        "info": results.info,
        "runs": [asdict(r) for r in results.runs],
        "rows": rows,
    }
    path = out_dir / RESULTS_NAME
    path.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    names = [f.name for f in fields(ErrorRow)]
    with (out_dir / CSV_NAME).open("w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=names)
        writer.writeheader()
        writer.writerows(asdict(r) for r in results.rows)
    return path


def read_results(path: Path) -> Results:
    """Read a ``results.json`` (or the directory holding one).

    Raises
    ------
    ResultsError
        The file is missing, not JSON or lacks a field.
    """
    if path.is_dir():
        path = path / RESULTS_NAME
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ResultsError(f"{path}: no results file; run `bslam experiment paper` first") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ResultsError(f"{path}: not a readable results file ({exc})") from None
    try:
        rows = [
            ErrorRow(
                **{
                    **d,
                    "error_fl": math.nan if d["error_fl"] is None else float(d["error_fl"]),
                    "error_cm": math.nan if d["error_cm"] is None else float(d["error_cm"]),
                }
            )
            for d in doc["rows"]
        ]
        return Results(
            experiment=str(doc["experiment"]),
            config=dict(doc["config"]),
            runs=[RunRecord(**d) for d in doc["runs"]],
            rows=rows,
            info=dict(doc.get("info", {})),
        )
    except (KeyError, TypeError) as exc:
        raise ResultsError(f"{path}: malformed results file (missing or bad field {exc})") from None
