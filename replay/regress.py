"""Regression on stored logs: rerun each log and compare its summary with the expected one.

A case is a log ``NAME.mcap`` with an expected summary beside it (written by ``bslam process``):
``NAME.expected.json`` and/or ``NAME.<estimator>.expected.json`` (``NAME.paper.expected.json``
keeps the paper filter's map beside the default estimator's). The log is reprocessed with the
method settings (estimator, prior, particle counts, seed) of the expected summary (one without
an ``estimator`` predates the joint estimator: the paper filter made it); any movement whose
status or placement changed, any landmark that appeared or disappeared, and any mean or
covariance that moved beyond the tolerance is a regression, reported as one readable line.
``bslam regress --update`` rewrites the expected files on purpose (each with its own settings;
a log without any gets ``NAME.expected.json`` from the default estimator).
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from data_schemas.errors import LogError
from pipeline.estimators import DEFAULT_ESTIMATOR, ESTIMATORS
from replay.records import MethodConfig

#: Default tolerance on a landmark mean, FL units (|L1 L2| = 0.3 m makes it 0.3 mm).
MEAN_TOL = 1e-3
#: Default tolerance on a covariance entry, relative to the largest entry of that matrix.
COV_RTOL = 0.05

EXPECTED_SUFFIX = ".expected.json"


class NoCasesError(LogError):
    """A regression folder holds no ``NAME.mcap`` + ``NAME.expected.json`` pair."""


@dataclass(frozen=True)
class Case:
    """One stored log and one expected summary of it."""

    log: Path
    expected: Path
    estimator: str = DEFAULT_ESTIMATOR

    def method(self) -> MethodConfig:
        """The settings of the expected summary (a new case: defaults, its estimator)."""
        if self.expected.is_file():
            return method_of(load_expected(self))
        return MethodConfig(estimator=self.estimator)

    @property
    def name(self) -> str:
        """``NAME.mcap``, or ``NAME.mcap (paper)`` for ``NAME.paper.expected.json``."""
        tag = self.expected.name[len(self.log.stem) : -len(EXPECTED_SUFFIX)]
        return self.log.name + (f" ({tag[1:]})" if tag else "")


def find_cases(folder: Path, *, update: bool = False, estimator: str | None = None) -> list[Case]:
    """The cases in ``folder``: every ``*.mcap`` with each of its expected summaries.

    ``estimator`` keeps only the summaries that estimator made. With ``update``, a log without
    one gets a new case: ``NAME.expected.json`` for the default estimator, else
    ``NAME.<estimator>.expected.json``.
    """
    if not folder.is_dir():
        raise NoCasesError(f"{folder}: not a folder; give the folder of the stored logs")
    cases = []
    for log in sorted(folder.glob("*.mcap")):
        default = log.with_name(log.stem + EXPECTED_SUFFIX)
        tagged = [log.with_name(f"{log.stem}.{e}{EXPECTED_SUFFIX}") for e in ESTIMATORS]
        found = [Case(log, p) for p in (default, *tagged) if p.is_file()]
        if estimator is not None:
            found = [c for c in found if c.method().estimator == estimator]
        if not found and update:
            want = estimator or DEFAULT_ESTIMATOR
            path = (
                default
                if want == DEFAULT_ESTIMATOR
                else default.with_name(f"{log.stem}.{want}{EXPECTED_SUFFIX}")
            )
            found = [Case(log, path, want)]
        cases += found
    if not cases:
        raise NoCasesError(
            f"{folder}: no NAME.mcap with NAME{EXPECTED_SUFFIX}; "
            "run 'bslam regress --update' to create the expected files"
        )
    return cases


def method_of(expected: Mapping[str, Any]) -> MethodConfig:
    """The settings an expected summary was produced with."""
    m = expected["method"]
    return MethodConfig(
        prior=m["prior"],
        n_r=m["n_r"],
        n_l=m["n_l"],
        seed=m["seed"],
        estimator=m.get("estimator", "paper"),
        turn_prior_deg=m.get("turn_prior_deg"),
    )


def load_expected(case: Case) -> dict[str, Any]:
    """Read a case's expected summary."""
    try:
        doc: dict[str, Any] = json.loads(case.expected.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise LogError(f"{case.expected}: cannot read the expected summary ({exc})") from None
    return doc


def _fmt(v: Any) -> str:
    return json.dumps(v)


def _compare_landmarks(
    where: str,
    expected: Mapping[str, Any],
    actual: Mapping[str, Any],
    mean_tol: float,
    cov_rtol: float,
) -> Iterator[str]:
    for name in sorted(set(expected) | set(actual)):
        if name not in actual:
            yield f"{where} {name}: disappeared (expected mean {_fmt(expected[name]['mean'])})"
            continue
        if name not in expected:
            yield f"{where} {name}: new landmark (mean {_fmt(actual[name]['mean'])})"
            continue
        e, a = expected[name], actual[name]
        moved = max(abs(x - y) for x, y in zip(e["mean"], a["mean"], strict=True))
        if moved > mean_tol:
            yield (
                f"{where} {name}: mean moved by {moved:.3g} (> {mean_tol:g}): "
                f"expected {_fmt(e['mean'])}, got {_fmt(a['mean'])}"
            )
        e_cov = [x for row in e["cov"] for x in row]
        a_cov = [x for row in a["cov"] for x in row]
        scale = max(abs(x) for x in e_cov) or 1.0
        changed = max(abs(x - y) for x, y in zip(e_cov, a_cov, strict=True)) / scale
        if changed > cov_rtol:
            yield (
                f"{where} {name}: covariance changed by {changed:.1%} (> {cov_rtol:.0%}): "
                f"expected {_fmt(e['cov'])}, got {_fmt(a['cov'])}"
            )


def compare(
    expected: Mapping[str, Any],
    actual: Mapping[str, Any],
    *,
    mean_tol: float = MEAN_TOL,
    cov_rtol: float = COV_RTOL,
) -> list[str]:
    """Readable differences between two summaries (empty list: no regression)."""
    diffs: list[str] = []
    e_moves = {m["index"]: m for m in expected["movements"]}
    a_moves = {m["index"]: m for m in actual["movements"]}
    for index in sorted(set(e_moves) | set(a_moves)):
        where = f"movement {index}"
        if index not in a_moves:
            diffs.append(f"{where}: missing from the new run")
            continue
        if index not in e_moves:
            diffs.append(f"{where}: not expected (status {a_moves[index]['status']!r})")
            continue
        e, a = e_moves[index], a_moves[index]
        if e["status"] != a["status"]:
            diffs.append(f"{where}: status was {e['status']!r}, now {a['status']!r}")
        if e.get("placement") != a.get("placement"):
            diffs.append(
                f"{where}: placement was {e.get('placement')!r}, now {a.get('placement')!r}"
            )
        diffs.extend(_compare_landmarks(where, e["landmarks"], a["landmarks"], mean_tol, cov_rtol))
    diffs.extend(
        _compare_landmarks("final", expected["landmarks"], actual["landmarks"], mean_tol, cov_rtol)
    )
    return diffs
