"""All parameters of companion, with the paper's Table 1 values as defaults.

One frozen, typed tree (:class:`Params`) validated in one place (:mod:`companion.config`).
docs/parameters.md documents every field; a test keeps the two in step.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Mapping

from companion.config import (all_non_negative, all_positive, all_positive_or_inf, build,
                              load_toml, non_negative, param, positive, validate)
from companion.errors import ConfigError
from companion.model import SIDES


def _bearing(x: float) -> str | None:
    return None if 0.0 <= x < 2.0 * math.pi else "an angle in [0, 2*pi) rad"


@dataclasses.dataclass(frozen=True)
class RobotParams:
    """Differential-drive robot: geometry and input limits."""

    d: float = param(0.25, "m", "offset of the reference point R ahead of the wheel axle (Eq. 2); "
                     "must be > 0 for the offset-point model to be controllable", positive)
    v_max: float = param(1.5, "m/s", "limit on |v|, the linear velocity", positive)
    omega_max: float = param(0.5 * math.pi, "rad/s", "limit on |omega|, the angular velocity",
                             positive)


@dataclasses.dataclass(frozen=True)
class Formation:
    """Where the robot walks relative to the person."""

    distance: float = param(1.0, "m", "desired distance rho_d from the person to R", positive)
    bearing: float = param(0.5 * math.pi, "rad",
                           "desired bearing alpha_d of R from the person's heading, in [0, 2*pi): "
                           "left pi/2, behind pi, right 3*pi/2, front 0. TOML also accepts "
                           "\"left\", \"right\", \"behind\", \"front\"", _bearing)


@dataclasses.dataclass(frozen=True)
class LqrParams:
    """Augmented-state LQR companion controller (Sec. 3.2)."""

    q: tuple[float, float, float, float, float] = param(
        (25.0, 10.0, 25.0, 30.0, 30.0), "-",
        "diagonal of Q, weights on [rho_e, alpha_e, beta_e, v_e, omega_e] of xi (Eq. 13)",
        all_non_negative)
    r: tuple[float, float] = param((20.0, 20.0), "-",
                                   "diagonal of R, weights on the input increment [dv, domega]",
                                   all_positive)
    linearize_at: str = param("measured", "-",
                              "operating point of the Jacobians: 'measured' (current state and "
                              "last applied input; ours) or 'desired' (paper-literal Eq. 8)",
                              choices=("measured", "desired"))
    feedforward: str = param("geometric", "-",
                             "u_d and beta target: 'geometric' (the input and heading that hold "
                             "the slot, ours) or 'person' (u_d = u_h, beta_d = 0; paper-literal)",
                             choices=("geometric", "person"))
    discretization: str = param("euler", "-",
                                "discretisation of the linearised model: 'euler' (paper) or "
                                "'zoh' (exact zero-order hold)", choices=("euler", "zoh"))
    error_clip: tuple[float, float, float] = param(
        (1.0, 0.5 * math.pi, 0.5 * math.pi), "m, rad, rad",
        "limits on |rho_e|, |alpha_e|, |beta_e| as seen by the LQR (ours; inf = paper-literal, "
        "no clipping)", all_positive_or_inf)
    rho_min: float = param(0.2, "m", "floor on rho in the Jacobians (the model is singular at "
                           "rho = 0)", positive)


@dataclasses.dataclass(frozen=True)
class SafetyParams:
    """Keep-out barrier around the person (ours; :mod:`companion.control.safety`)."""

    person_clearance: float = param(0.6, "m", "distance from robot centre to person that the "
                                    "barrier keeps; 0 switches the barrier off", non_negative)
    barrier_rate: float = param(2.0, "1/s", "rate of the barrier: the robot may approach at "
                                "most at barrier_rate * (distance - person_clearance)", positive)


@dataclasses.dataclass(frozen=True)
class Params:
    """Everything that tunes a run; defaults are the paper's Table 1."""

    dt: float = param(0.05, "s", "sample period T of controller and simulator", positive)
    robot: RobotParams = param(RobotParams(), "", "")
    formation: Formation = param(Formation(), "", "")
    lqr: LqrParams = param(LqrParams(), "", "")
    safety: SafetyParams = param(SafetyParams(), "", "")

    def replace(self, **changes: Any) -> "Params":
        """A copy with top-level fields replaced, validated."""
        out = dataclasses.replace(self, **changes)
        validate(out)
        return out


def side_to_bearing(value: Any, name: str) -> Any:
    """Map a side name to its bearing; other values pass through unchanged for validation."""
    if isinstance(value, str):
        if value not in SIDES:
            raise ConfigError(f"{name}: expected a bearing in rad or one of "
                              f"{', '.join(map(repr, SIDES))}, got {value!r}")
        return SIDES[value]
    return value


def params_from_mapping(mapping: Mapping[str, Any], prefix: str = "") -> Params:
    """Build validated :class:`Params` from a parsed TOML mapping."""
    mapping = dict(mapping)
    formation = mapping.get("formation")
    if isinstance(formation, Mapping) and "bearing" in formation:
        formation = dict(formation)
        formation["bearing"] = side_to_bearing(formation["bearing"],
                                               f"{prefix}formation.bearing")
        mapping["formation"] = formation
    return build(Params, mapping, prefix=prefix)


def load_params(path: str | Path) -> Params:
    """Load :class:`Params` from a TOML file; errors name the file and key."""
    return params_from_mapping(load_toml(path), prefix=f"{path}: ")
