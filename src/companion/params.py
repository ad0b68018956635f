"""All parameters of companion, with the paper's Table 1 values as defaults.

One frozen, typed tree (:class:`Params`) validated in one place (:mod:`companion.config`).
docs/parameters.md documents every field; a test keeps the two in step.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Mapping

from companion.config import (Validated, all_non_negative, all_positive, all_positive_or_inf,
                              build, load_toml, non_negative, param, positive, validate)
from companion.errors import ConfigError
from companion.model import SIDES
from companion.perception import ExtractorParams
from companion.sim.lidar import LidarParams


def _sample_period(x: float) -> str | None:
    return None if 1e-3 <= x <= 1.0 else "a sample period in [0.001, 1] s"


def _bearing(x: float) -> str | None:
    return None if 0.0 <= x < 2.0 * math.pi else "an angle in [0, 2*pi) rad"


@dataclasses.dataclass(frozen=True)
class RobotParams(Validated):
    """Differential-drive robot: geometry and input limits."""

    d: float = param(0.25, "m", "offset of the reference point R ahead of the wheel axle (Eq. 2); "
                     "must be > 0 for the offset-point model to be controllable", positive)
    v_max: float = param(1.5, "m/s", "limit on |v|, the linear velocity", positive)
    omega_max: float = param(0.5 * math.pi, "rad/s", "limit on |omega|, the angular velocity",
                             positive)
    radius: float = param(0.25, "m", "radius of the robot's footprint, a circle around the "
                          "wheel axle (for obstacle clearance and collisions)", positive)


@dataclasses.dataclass(frozen=True)
class Formation(Validated):
    """Where the robot walks relative to the person."""

    distance: float = param(1.0, "m", "desired distance rho_d from the person to R", positive)
    bearing: float = param(0.5 * math.pi, "rad",
                           "desired bearing alpha_d of R from the person's heading, in [0, 2*pi): "
                           "left pi/2, behind pi, right 3*pi/2, front 0. TOML also accepts "
                           "\"left\", \"right\", \"behind\", \"front\"", _bearing)


@dataclasses.dataclass(frozen=True)
class LqrParams(Validated):
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
    solver: str = param("compiled", "-",
                        "Riccati solver of the per-step gain: 'compiled' (numba doubling + "
                        "Newton, ~10 us; companion.fastlqr) or 'scipy' (solve_discrete_are, "
                        "~0.6 ms; the reference). The gains agree to 1e-8 relative",
                        choices=("compiled", "scipy"))
    error_clip: tuple[float, float, float] = param(
        (1.0, 0.5 * math.pi, 0.5 * math.pi), "m, rad, rad",
        "limits on |rho_e|, |alpha_e|, |beta_e| as seen by the LQR (ours; inf = paper-literal, "
        "no clipping)", all_positive_or_inf)
    rho_min: float = param(0.2, "m", "floor on rho in the Jacobians (the model is singular at "
                           "rho = 0)", positive)


@dataclasses.dataclass(frozen=True)
class SafetyParams(Validated):
    """Keep-out barriers around the person and obstacles (ours; :mod:`companion.control.safety`)."""

    person_clearance: float = param(0.6, "m", "distance from robot centre to person that the "
                                    "barrier keeps; 0 switches the barrier off", non_negative)
    obstacle_clearance: float = param(0.1, "m", "clearance from the robot's footprint to an "
                                      "obstacle surface that the barrier keeps; 0 switches "
                                      "it off", non_negative)
    barrier_rate: float = param(2.0, "1/s", "rate of the barriers: the robot may approach at "
                                "most at barrier_rate * (clearance - its minimum)", positive)


def _fraction(x: float) -> str | None:
    return None if 0.0 <= x <= 1.0 else "a fraction in [0, 1]"


def _step_ratio(x: float) -> str | None:
    return None if 1.0 < x < math.inf else "a finite ratio > 1"


@dataclasses.dataclass(frozen=True)
class SupervisorParams(Validated):
    """Safety supervisor, the last layer before the motors (:mod:`companion.control.supervisor`,
    docs/safety.md). Acceleration defaults are those of Nav2's velocity smoother."""

    accel_max: float = param(2.5, "m/s^2", "limit on the rate at which |v| grows", positive)
    decel_max: float = param(2.5, "m/s^2", "limit on the rate at which |v| shrinks; faults "
                             "brake at this rate", positive)
    angular_accel_max: float = param(3.2, "rad/s^2", "limit on the rate of change of omega",
                                     positive)
    person_timeout: float = param(0.5, "s", "a person estimate older than this is lost: brake "
                                  "to a stop and hold (before it, the last estimate is "
                                  "predicted forward at constant speed and turn rate)", positive)
    max_person_speed: float = param(3.0, "m/s", "a person observation farther from the last "
                                    "accepted one than this speed allows (plus jump_tolerance) "
                                    "is an outlier (identity switch) and is rejected; a "
                                    "reported person speed above it is clipped to it", positive)
    max_person_turn_rate: float = param(2.0 * math.pi, "rad/s", "a reported person turn rate "
                                        "above this is clipped to it before the person is "
                                        "predicted forward", positive)
    jump_tolerance: float = param(0.2, "m", "position noise allowed on top of max_person_speed "
                                  "in the outlier gate", non_negative)
    reacquire_time: float = param(0.3, "s", "after the person was lost, observations must be "
                                  "consistent with each other for this long before the robot "
                                  "follows again", non_negative)
    protective_distance: float = param(0.5, "m", "robot centre to person distance inside which "
                                       "the robot may only rotate or move away; outside it the "
                                       "speed towards the person is limited so that braking at "
                                       "decel_max stops it here", positive)
    person_accel: float = param(1.0, "m/s^2", "acceleration towards the robot a person may "
                                "add; the braking-distance bound towards the person plans with "
                                "the robot's rate limit minus this", non_negative)
    max_step_ratio: float = param(3.0, "-", "a time step longer than max_step_ratio * dt (or "
                                  "zero, negative or not finite) is a clock fault: the "
                                  "controller's filters are reset", _step_ratio)
    min_valid_returns: float = param(0.5, "-", "fraction of a LiDAR scan's beams that must be "
                                     "valid (not NaN); below it the robot stops", _fraction)


@dataclasses.dataclass(frozen=True)
class AvoidanceParams(Validated):
    """Behavioural-dynamics obstacle avoidance (Sec. 3.3, Eq. 17-20)."""

    eta: float = param(28.0, "rad/s^2", "gain of the avoidance angular acceleration (Table 1); "
                       "0 switches avoidance off", non_negative)
    c1: float = param(1.5, "1/rad", "decay of the acceleration with |phi| (Table 1)",
                      non_negative)
    c2: float = param(0.9, "1/m", "decay of the acceleration with rho_ob (Table 1)",
                      non_negative)
    k_ob: float = param(0.375, "-", "K_ob = r_o / rho_o, obstacle radius over influence range; "
                        "Table 1 prints 0.6 but both experiments imply 0.375 (NOTES.md 9)",
                        positive)
    wall_influence: float = param(0.5, "m", "influence range rho_o of wall segments", positive)
    decay_time: float = param(0.5, "s", "time constant with which u_ob leaks back to 0 "
                              "(ours; the paper integrates without leak)", positive)
    field_of_view: float = param(0.5 * math.pi, "rad", "only obstacles with |phi| below this "
                                 "count (ahead of the robot)", positive)
    cone_margin: float = param(0.1, "m", "clearance margin of the collision cone: when the "
                               "heading would pass closer than this, Eq. 17 is evaluated at the "
                               "cone's edge (ours; a negative value uses the paper's phi)")
    tie_band: float = param(0.15, "rad", "inside the collision cone, obstacles with |phi| below "
                            "this are passed on the side away from the person", non_negative)


@dataclasses.dataclass(frozen=True)
class PidParams(Validated):
    """PID baseline (:mod:`companion.control.pid`, docs/baselines.md). Errors are those of the
    reference point R against the slot S in the robot frame (e_x ahead, e_y left) and of the
    heading against the slot-holding heading (e_theta)."""

    kp_x: float = param(3.412, "1/s", "proportional gain of v on e_x", non_negative)
    ki_x: float = param(0.1497, "1/s^2", "integral gain of v on e_x", non_negative)
    kd_x: float = param(0.04882, "-", "derivative gain of v on the filtered rate of e_x",
                        non_negative)
    kp_y: float = param(7.851, "rad/(s m)", "proportional gain of omega on e_y", non_negative)
    ki_y: float = param(0.05333, "rad/(s^2 m)", "integral gain of omega on e_y", non_negative)
    kd_y: float = param(0.0232, "rad/m", "derivative gain of omega on the filtered rate of e_y",
                        non_negative)
    kp_theta: float = param(3.991, "1/s", "proportional gain of omega on e_theta", non_negative)
    derivative_tau: float = param(0.2, "s", "time constant of the first-order filter on the "
                                  "derivative terms", positive)
    i_limit_v: float = param(0.5, "m/s", "clamp on the integral term of v (anti-windup)",
                             non_negative)
    i_limit_omega: float = param(0.5, "rad/s", "clamp on the integral term of omega "
                                 "(anti-windup)", non_negative)


@dataclasses.dataclass(frozen=True)
class VsmParams(Validated):
    """Virtual spring model baseline (:mod:`companion.control.vsm`, docs/baselines.md): a
    spring-damper between R and the slot S acting on a virtual mass at R."""

    stiffness: float = param(8.326, "N/m", "spring constant k", positive)
    damping: float = param(1.948, "N s/m", "damper constant c", non_negative)
    mass: float = param(0.309, "kg", "virtual mass m", positive)


@dataclasses.dataclass(frozen=True)
class ImpedanceParams(Validated):
    """Impedance control baseline (:mod:`companion.control.impedance`, docs/baselines.md):
    ``M e_ddot + D e_dot + K e = 0`` on the slot error in the person frame, per axis
    (longitudinal along the person's heading, lateral to its left)."""

    mass: tuple[float, float] = param((0.1437, 0.9623), "kg", "virtual mass M (longitudinal, lateral)",
                                      all_positive)
    damping: tuple[float, float] = param((0.2843, 7.237), "N s/m",
                                         "damping D (longitudinal, lateral)", all_non_negative)
    stiffness: tuple[float, float] = param((1.9, 18.99), "N/m",
                                           "stiffness K (longitudinal, lateral)", all_positive)


@dataclasses.dataclass(frozen=True)
class Params(Validated):
    """Everything that tunes a run; defaults are the paper's Table 1."""

    dt: float = param(0.05, "s", "sample period T of controller and simulator, in [0.001, 1]",
                      _sample_period)
    robot: RobotParams = param(RobotParams(), "", "")
    formation: Formation = param(Formation(), "", "")
    lqr: LqrParams = param(LqrParams(), "", "")
    safety: SafetyParams = param(SafetyParams(), "", "")
    supervisor: SupervisorParams = param(SupervisorParams(), "", "")
    avoidance: AvoidanceParams = param(AvoidanceParams(), "", "")
    lidar: LidarParams = param(LidarParams(), "", "")
    extractor: ExtractorParams = param(ExtractorParams(), "", "")
    pid: PidParams = param(PidParams(), "", "")
    vsm: VsmParams = param(VsmParams(), "", "")
    impedance: ImpedanceParams = param(ImpedanceParams(), "", "")

    def __post_init__(self) -> None:
        super().__post_init__()
        f = self.formation
        # robot centre (axle) in the slot, heading with the person: R - d e(theta_h)
        cx = f.distance * math.cos(f.bearing) - self.robot.d
        cy = f.distance * math.sin(f.bearing)
        for name, keep in (("safety.person_clearance", self.safety.person_clearance),
                           ("supervisor.protective_distance",
                            self.supervisor.protective_distance)):
            if math.hypot(cx, cy) < keep:
                raise ConfigError(
                    f"formation.distance: the slot at {f.distance:g} m, bearing "
                    f"{f.bearing:.3f} rad puts the robot centre {math.hypot(cx, cy):.2f} m from "
                    f"the person, inside {name} ({keep:g} m); expected a larger distance or a "
                    f"smaller {name.split('.')[1]}")

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
