"""The experiment protocol: what a run does (methods, particle counts) and what it varies.

:class:`Protocol` defaults are the paper's (docs/method.md, part 7): 40 runs of 10 straight
movements, n_r = 50, n_l = 300, eps = 3°, four landmarks with |L1 L2| = 30 cm in a 105 x 68 cm
arena (the geometry lives in the scenario). A sweep changes one :data:`SWEEP_PARAMS` entry.
"""

from __future__ import annotations

import copy
import math
from dataclasses import asdict, dataclass, replace
from typing import Any

from data_schemas.errors import BslamError
from replay import defaults
from replay.defaults import PRIORS

FRAME_CHANGES = ("sampled", "exact")
#: the paper's Fig. 8 particle counts
PAPER_N_L_VALUES = (50, 100, 200, 300, 500, 1000)


class ProtocolError(BslamError):
    """An experiment was asked for with impossible parameters."""


@dataclass(frozen=True)
class Protocol:
    """How every run of one experiment configuration is made and scored.

    Attributes
    ----------
    runs : int
        Number of simulated trajectories.
    movements : int
        Straight movements per trajectory.
    n_r, n_l : int
        Particles per landmark in FR and in FL.
    priors : tuple of str
        Single-view priors compared over all movements (each with ``n_l``).
    n_l_values : tuple of int
        Particle counts of the Fig. 8 sweep (impartial prior, first ``n_l_movements`` movements).
    n_l_movements : int
        Movements scored in the n_l sweep (the paper: 3).
    joint, batch_ls, crb : bool
        Also score the joint estimator, batch least squares and the Cramér–Rao bound on the same
        bearings.
    frame_change : str
        ``sampled`` (n_l random triples, O(n_l)) or ``exact`` (all n_r^3 triples, reduced).
    distance_prior : float or None
        The joint estimator's prior on each movement's length from its driven distance (relative
        std; None: lengths free), as ``bslam process --distance-prior``.
    seed : int
        Run ``i`` uses seed ``seed + i`` for the trajectory, the noise and the particles.
    """

    runs: int = 40
    movements: int = 10
    n_r: int = defaults.N_R
    n_l: int = defaults.N_L
    priors: tuple[str, ...] = PRIORS
    n_l_values: tuple[int, ...] = PAPER_N_L_VALUES
    n_l_movements: int = 3
    joint: bool = True
    batch_ls: bool = True
    crb: bool = True
    frame_change: str = "sampled"
    seed: int = 0
    distance_prior: float | None = defaults.DISTANCE_PRIOR_REL

    def __post_init__(self) -> None:
        if self.runs < 1 or self.movements < 1:
            raise ProtocolError(
                f"runs and movements must be at least 1, got {self.runs} and {self.movements}"
            )
        if self.n_r < 2 or self.n_l < 2 or any(n < 2 for n in self.n_l_values):
            raise ProtocolError("particle counts n_r and n_l must be at least 2")
        unknown = [p for p in self.priors if p not in PRIORS]
        if unknown or not self.priors:
            raise ProtocolError(f"unknown prior(s) {unknown}; choose from {', '.join(PRIORS)}")
        if self.frame_change not in FRAME_CHANGES:
            choices = ", ".join(FRAME_CHANGES)
            raise ProtocolError(f"unknown frame change {self.frame_change!r}; use one of {choices}")
        if self.distance_prior is not None and not self.distance_prior > 0.0:
            raise ProtocolError(f"distance prior std must be > 0, got {self.distance_prior}")

    def to_dict(self) -> dict[str, Any]:
        """The protocol as JSON-ready data (tuples become lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


def _set_bearing_noise(scenario: dict[str, Any], value: float) -> None:
    scenario["camera"]["bearing_noise_deg"] = value


def _set_vision_error(scenario: dict[str, Any], value: float) -> None:
    scenario["vision_error_deg"] = value


def _set_movement_length(scenario: dict[str, Any], value: float) -> None:
    scenario["trajectory"]["distance"] = [0.8 * value, 1.2 * value]


def _set_n_landmarks(scenario: dict[str, Any], value: float) -> None:
    from recorder.sim.coded import with_coded_landmarks

    if value != int(value):
        raise ProtocolError(f"n_landmarks must be a whole number, got {value:g}")
    n = int(value)
    scenario.update(with_coded_landmarks(scenario, n, seed=n))


#: scenario parameters a sweep can vary -> how to set them (value in the parameter's unit);
#: ``n_landmarks`` replaces the landmarks by that many coded ones in the scenario's arena
#: (layout drawn from seed n, reference pair L1, L2)
SWEEP_PARAMS = {
    "bearing_noise_deg": _set_bearing_noise,
    "vision_error_deg": _set_vision_error,
    "movement_length_m": _set_movement_length,
    "n_landmarks": _set_n_landmarks,
}
#: parameters that change the protocol rather than the scenario
PROTOCOL_PARAMS = ("frame_change", "camera_model", "n_l")


def apply_scenario_param(scenario: dict[str, Any], param: str, value: float) -> dict[str, Any]:
    """A copy of ``scenario`` with one sweep parameter set."""
    out = copy.deepcopy(scenario)
    SWEEP_PARAMS[param](out, value)
    return out


def apply_protocol_param(protocol: Protocol, param: str, value: str) -> Protocol:
    """A copy of ``protocol`` with ``frame_change`` or ``n_l`` set (string value from the CLI)."""
    if param == "frame_change":
        return replace(protocol, frame_change=value)
    if param == "n_l":
        return replace(protocol, n_l=int(value))
    raise ProtocolError(f"{param!r} is not a protocol parameter")


#: every parameter ``bslam experiment sweep --param`` accepts
ALL_SWEEP_PARAMS = (*SWEEP_PARAMS, *PROTOCOL_PARAMS)
CAMERA_MODELS = ("unwrapped", "omni")


def check_sweep_values(param: str, values: list[str]) -> None:
    """Raise ProtocolError (one line) unless every value can be used for ``param``.

    Scenario parameters take finite numbers, ``n_l`` integers of at least 2, ``frame_change``
    one of :data:`FRAME_CHANGES`, ``camera_model`` one of :data:`CAMERA_MODELS` or a scenario
    file. Whether a number makes a possible scenario is checked with the scenario itself.
    """
    if param not in ALL_SWEEP_PARAMS:
        raise ProtocolError(
            f"unknown sweep parameter {param!r}; use one of {', '.join(ALL_SWEEP_PARAMS)}"
        )
    if not values:
        raise ProtocolError("give at least one value, e.g. 0.5,1,2")
    for value in values:
        if param in SWEEP_PARAMS:
            try:
                ok = math.isfinite(float(value))
            except ValueError:
                ok = False
            if not ok:
                raise ProtocolError(f"{param} takes finite numbers, got {value!r}")
        elif param == "n_l" and not (value.isdigit() and int(value) >= 2):
            raise ProtocolError(f"n_l takes integers of at least 2, got {value!r}")
        elif param == "frame_change" and value not in FRAME_CHANGES:
            raise ProtocolError(f"frame_change takes {' or '.join(FRAME_CHANGES)}, got {value!r}")
