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
import math
import shlex
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from data_schemas.errors import BslamError, LogError
from pipeline.estimators import ESTIMATORS
from replay import defaults
from replay.defaults import ESTIMATOR as DEFAULT_ESTIMATOR
from replay.records import MethodConfig

#: Default tolerance on a landmark mean, FL units (|L1 L2| = 0.3 m makes it 0.3 mm).
MEAN_TOL = 1e-3
#: Default tolerance on a covariance entry, relative to the largest entry of that matrix.
COV_RTOL = 0.05

EXPECTED_SUFFIX = ".expected.json"


class NoCasesError(LogError):
    """A regression folder holds no ``NAME.mcap`` + ``NAME.expected.json`` pair."""


class ExpectedFileError(LogError):
    """An expected summary is not a summary ``bslam process`` writes (names the file and key)."""


class ToleranceError(BslamError):
    """A regression tolerance is negative or not a finite number."""


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
    """The settings an expected summary was produced with (raise BslamError if impossible)."""
    m = expected["method"]
    return MethodConfig(
        prior=m["prior"],
        n_r=m["n_r"],
        n_l=m["n_l"],
        seed=m["seed"],
        estimator=m.get("estimator", "paper"),
        turn_prior_deg=m.get("turn_prior_deg"),
        distance_prior=m.get("distance_prior"),
        window=m.get("window", defaults.JOINT_WINDOW),
    )


def load_expected(case: Case) -> dict[str, Any]:
    """Read a case's expected summary and check the parts the comparison uses.

    Raises
    ------
    ExpectedFileError
        One line naming the file and the first key that is missing or malformed.
    """
    try:
        doc = json.loads(case.expected.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ExpectedFileError(
            f"{case.expected}: cannot read the expected summary ({exc})"
        ) from None
    problem = _expected_problem(doc)
    if problem is not None:
        raise ExpectedFileError(
            f"{case.expected}: {problem}; it is not a summary written by bslam; restore it "
            f"(git checkout) or rewrite it with "
            f"{shlex.join(['bslam', 'regress', str(case.log.parent), '--update'])}"
        )
    result: dict[str, Any] = doc
    return result


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _landmarks_problem(where: str, landmarks: Any) -> str | None:
    if not isinstance(landmarks, dict):
        return f"key {where!r} is not an object"
    for name, est in landmarks.items():
        key = f"{where}.{name}"
        if not isinstance(est, dict):
            return f"key {key!r} is not an object"
        mean, cov = est.get("mean"), est.get("cov")
        if not (isinstance(mean, list) and len(mean) == 2 and all(map(_is_number, mean))):
            return f"key {key}.mean is not two finite numbers"
        if not (
            isinstance(cov, list)
            and len(cov) == 2
            and all(isinstance(r, list) and len(r) == 2 and all(map(_is_number, r)) for r in cov)
        ):
            return f"key {key}.cov is not a 2 x 2 matrix of finite numbers"
    return None


def _expected_problem(doc: Any) -> str | None:
    """What is wrong with an expected summary, or None."""
    if not isinstance(doc, dict):
        return "not a JSON object"
    method = doc.get("method")
    if not isinstance(method, dict):
        return "key 'method' is missing or not an object"
    for key in ("prior", "n_r", "n_l", "seed"):
        if key not in method:
            return f"key 'method.{key}' is missing"
    movements = doc.get("movements")
    if not isinstance(movements, list):
        return "key 'movements' is missing or not a list"
    for i, m in enumerate(movements):
        if not (isinstance(m, dict) and isinstance(m.get("index"), int)):
            return f"key 'movements[{i}].index' is missing or not an integer"
        if not isinstance(m.get("status"), str):
            return f"key 'movements[{i}].status' is missing or not text"
        problem = _landmarks_problem(f"movements[{i}].landmarks", m.get("landmarks"))
        if problem is not None:
            return problem
    return _landmarks_problem("landmarks", doc.get("landmarks"))


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
        if not moved <= mean_tol:  # NaN is a move too
            yield (
                f"{where} {name}: mean moved by {moved:.3g} (> {mean_tol:g}): "
                f"expected {_fmt(e['mean'])}, got {_fmt(a['mean'])}"
            )
        e_cov = [x for row in e["cov"] for x in row]
        a_cov = [x for row in a["cov"] for x in row]
        scale = max(abs(x) for x in e_cov) or 1.0
        changed = max(abs(x - y) for x, y in zip(e_cov, a_cov, strict=True)) / scale
        if not changed <= cov_rtol:
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


@dataclass(frozen=True)
class CaseResult:
    """What regression found for one case.

    Attributes
    ----------
    case : Case
    status : {"ok", "regression", "written"}
        ``written``: the expected file was (re)written by ``update``.
    diffs : list of str
        Readable differences (empty unless ``status == "regression"``).
    """

    case: Case
    status: Literal["ok", "regression", "written"]
    diffs: list[str]


def run_regression(
    folder: Path,
    *,
    update: bool = False,
    estimator: str | None = None,
    mean_tol: float = MEAN_TOL,
    cov_rtol: float = COV_RTOL,
    on_case: Callable[[CaseResult], None] | None = None,
) -> list[CaseResult]:
    """Reprocess every case in ``folder`` and compare it with (or, if ``update``, rewrite) its
    expected summary.

    Parameters
    ----------
    folder : Path
        Folder of ``NAME.mcap`` logs with their expected summaries (see :func:`find_cases`).
    update : bool
        Rewrite every expected file from the current code (each with its own settings) instead
        of comparing.
    estimator : str, optional
        Only the expected summaries this estimator made (see :func:`find_cases`).
    mean_tol, cov_rtol : float
        Tolerances of :func:`compare` (finite, >= 0).
    on_case : callable, optional
        Called with each result as soon as its case is done (progress output).

    Raises
    ------
    NoCasesError, ExpectedFileError, ToleranceError
        One line each. Every expected file is read and checked before any log is processed.
    """
    from replay.process import process_log, write_json

    for name, tol in (("mean tolerance", mean_tol), ("covariance tolerance", cov_rtol)):
        if not (math.isfinite(tol) and tol >= 0):
            raise ToleranceError(f"{name} must be a finite number >= 0, got {tol}")
    todo = find_cases(folder, update=update, estimator=estimator)
    expected = {
        case.expected: load_expected(case) if case.expected.is_file() else None for case in todo
    }
    results = []
    for case in todo:
        doc = expected[case.expected]
        method = MethodConfig(estimator=case.estimator) if doc is None else method_of(doc)
        actual = process_log(case.log, method).to_json()
        if update or doc is None:
            write_json(case.expected, actual)
            result = CaseResult(case, "written", [])
        else:
            diffs = compare(doc, actual, mean_tol=mean_tol, cov_rtol=cov_rtol)
            result = CaseResult(case, "regression" if diffs else "ok", diffs)
        if on_case is not None:
            on_case(result)
        results.append(result)
    return results
