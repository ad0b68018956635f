"""Every parameter of companion, the paper's Table 1 values as defaults.

One frozen, typed tree (:class:`Params`) validated in one place (:mod:`companion.config`).
docs/parameters.md documents every field; a test keeps the two in step.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from companion.config import (
    Validated,
    all_non_negative,
    all_positive,
    all_positive_or_inf,
    build,
    load_toml,
    non_negative,
    param,
    positive,
    validate,
)
from companion.errors import ConfigError
from companion.geometry import TWO_PI

LEFT = 0.5 * math.pi
BEHIND = math.pi
RIGHT = 1.5 * math.pi
FRONT = 0.0
#: Side names accepted for ``formation.bearing``.
SIDES = {"left": LEFT, "right": RIGHT, "behind": BEHIND, "front": FRONT}


def _sample_period(x: float) -> str | None:
    return None if 1e-3 <= x <= 1.0 else "a sample period in [0.001, 1] s"


def _bearing(x: float) -> str | None:
    return None if 0.0 <= x < TWO_PI else "an angle in [0, 2*pi) rad"


def _fraction(x: float) -> str | None:
    return None if 0.0 <= x <= 1.0 else "a fraction in [0, 1]"


def _step_ratio(x: float) -> str | None:
    return None if 1.0 < x < math.inf else "a finite ratio > 1"


def _fov(x: float) -> str | None:
    return None if 0.0 < x <= TWO_PI + 1e-9 else "an angle in (0, 2*pi] rad"


def _resolution(x: float) -> str | None:
    return None if 1e-4 <= x <= math.pi else "an angle in [0.0001, pi] rad"


def _at_least_one(n: int) -> str | None:
    return None if n >= 1 else "an integer >= 1"


def _breakpoint_angle(x: float) -> str | None:
    return None if 0.0 <= x < 0.5 * math.pi else "an angle in [0, pi/2) rad"


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
    bearing: float = param(LEFT, "rad",
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
                        "Riccati solver of the per-step gain: 'compiled' (doubling + Newton, "
                        "numba; companion.riccati) or 'scipy' (solve_discrete_are, the "
                        "reference); the gains agree to 1e-8 relative",
                        choices=("compiled", "scipy"))
    error_clip: tuple[float, float, float] = param(
        (1.0, 0.5 * math.pi, 0.5 * math.pi), "m, rad, rad",
        "limits on |rho_e|, |alpha_e|, |beta_e| as seen by the LQR (ours; inf = paper-literal, "
        "no clipping)", all_positive_or_inf)
    rho_min: float = param(0.2, "m", "floor on rho in the Jacobians (the model is singular at "
                           "rho = 0)", positive)


@dataclasses.dataclass(frozen=True)
class KeepOutParams(Validated):
    """Every rule that keeps the robot away from the person and the obstacles, applied by the
    safety supervisor (:mod:`companion.control.keepout`, docs/safety.md)."""

    person_clearance: float = param(0.6, "m", "comfort barrier: robot centre to person "
                                    "distance that the speed barrier keeps; 0 switches the "
                                    "barrier off", non_negative)
    obstacle_clearance: float = param(0.1, "m", "comfort barrier: footprint to obstacle "
                                      "surface clearance that the speed barrier keeps; 0 "
                                      "switches it off", non_negative)
    barrier_rate: float = param(2.0, "1/s", "rate of the comfort barriers: the robot may "
                                "approach at most at barrier_rate * (clearance - its minimum)",
                                positive)
    protective_distance: float = param(0.5, "m", "robot centre to person distance inside which "
                                       "the robot may only rotate or move away; outside it the "
                                       "speed towards the person is limited so that braking at "
                                       "the deceleration limit stops it here", positive)
    person_accel: float = param(1.0, "m/s^2", "acceleration towards the robot a person may "
                                "add; the braking bound towards the person plans with the "
                                "robot's rate limit minus this", non_negative)
    contact_margin: float = param(0.02, "m", "clearance short of contact at which the braking "
                                  "bound towards obstacles stops the robot", non_negative)


@dataclasses.dataclass(frozen=True)
class SupervisorParams(Validated):
    """Safety supervisor: rate limits and fault handling (:mod:`companion.control.supervisor`,
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
    max_person_turn_rate: float = param(TWO_PI, "rad/s", "a reported person turn rate above "
                                        "this is clipped to it before the person is predicted "
                                        "forward", positive)
    jump_tolerance: float = param(0.2, "m", "position noise allowed on top of max_person_speed "
                                  "in the outlier gate", non_negative)
    reacquire_time: float = param(0.3, "s", "after the person was lost, observations must be "
                                  "consistent with each other for this long before the robot "
                                  "follows again", non_negative)
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
                        "Table 1 prints 0.6 but both experiments imply 0.375 (docs/model.md "
                        "R9)", positive)
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
class LidarParams(Validated):
    """A simulated 2D LiDAR at the robot's pose (:mod:`companion.sim.lidar`)."""

    fov: float = param(TWO_PI, "rad", "field of view, centred on the robot's heading, in "
                       "(0, 2*pi]; 2*pi is a full 360 degree scan", _fov)
    range_max: float = param(10.0, "m", "maximum range; beams hitting nothing closer return "
                             "inf", positive)
    resolution: float = param(math.radians(0.5), "rad",
                              "angular step between beams (0.5 deg: 720 beams per revolution); "
                              "for a full circle it is rounded so that it divides 2*pi",
                              _resolution)
    rate: float = param(10.0, "Hz", "scans per second; the simulator scans every "
                        "round(1 / (rate * dt)) control steps and holds the result in between",
                        positive)
    noise_std: float = param(0.01, "m", "standard deviation of the Gaussian noise added to "
                             "every finite range (clipped at 0); 0 = exact", non_negative)
    person_radius: float = param(0.2, "m", "radius of the circle that stands for the person's "
                                 "body in the scan", positive)


@dataclasses.dataclass(frozen=True)
class ExtractorParams(Validated):
    """Turning a LiDAR scan into circular obstacles (:mod:`companion.perception`)."""

    cluster_gap: float = param(0.15, "m", "consecutive returns farther apart than this (and "
                               "than the adaptive breakpoint distance) start a new cluster; so "
                               "does a beam without return", positive)
    breakpoint_angle: float = param(math.radians(10.0), "rad",
                                    "adaptive breakpoint (Borges & Aldon 2004): returns on a "
                                    "surface seen at least this angle away from grazing stay in "
                                    "one cluster, i.e. the gap threshold grows to r * sin(step) "
                                    "/ sin(breakpoint_angle - step) at range r; 0 = fixed "
                                    "cluster_gap only", _breakpoint_angle)
    min_points: int = param(3, "-", "clusters with fewer returns are dropped as noise",
                            _at_least_one)
    max_segment: float = param(0.6, "m", "a cluster that is not one circle (a wall, a corner) "
                               "and is longer than this is split into pieces of at most this "
                               "length, each reported as its own circle", positive)
    person_exclusion: float = param(0.5, "m", "circles whose centre is within person_radius + "
                                    "this of the tracked person are the person and are not "
                                    "reported (absorbs tracking error)", non_negative)
    person_radius: float = param(0.2, "m", "radius of the person's body; should match "
                                 "lidar.person_radius", positive)
    piece_influence: float = param(0.5, "m", "avoidance influence range given to circles that "
                                   "stand for pieces of a wall or a large object (like "
                                   "avoidance.wall_influence for known walls)", positive)
    min_radius: float = param(0.05, "m", "smallest reported radius", positive)
    max_radius: float = param(1.0, "m", "largest fitted radius; a circle is only enlarged "
                              "beyond it to cover its cluster's returns", positive)
    fit_tolerance: float = param(0.04, "m", "largest RMS radial residual of an accepted "
                                 "circle fit; the returns must also bulge towards the sensor by "
                                 "twice this from their chord (about 2-4 x the range noise)",
                                 positive)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.min_radius > self.max_radius:
            raise ConfigError(f"extractor.min_radius: expected at most max_radius "
                              f"({self.max_radius:g} m), got {self.min_radius:g}")


@dataclasses.dataclass(frozen=True)
class PidParams(Validated):
    """PID baseline (:mod:`companion.control.pid`, docs/baselines.md): errors of R against the
    slot S in the robot frame (e_x ahead, e_y left) and of the heading (e_theta)."""

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
    """Virtual spring model baseline (:mod:`companion.control.vsm`): a spring-damper between R
    and the slot S acting on a virtual mass at R."""

    stiffness: float = param(8.326, "N/m", "spring constant k", positive)
    damping: float = param(1.948, "N s/m", "damper constant c", non_negative)
    mass: float = param(0.309, "kg", "virtual mass m", positive)


@dataclasses.dataclass(frozen=True)
class ImpedanceParams(Validated):
    """Impedance control baseline (:mod:`companion.control.impedance`): ``M e_ddot + D e_dot +
    K e = 0`` per axis of the slot error in the person frame (longitudinal, lateral)."""

    mass: tuple[float, float] = param((0.1437, 0.9623), "kg",
                                      "virtual mass M (longitudinal, lateral)", all_positive)
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
    keepout: KeepOutParams = param(KeepOutParams(), "", "")
    supervisor: SupervisorParams = param(SupervisorParams(), "", "")
    avoidance: AvoidanceParams = param(AvoidanceParams(), "", "")
    lidar: LidarParams = param(LidarParams(), "", "")
    extractor: ExtractorParams = param(ExtractorParams(), "", "")
    pid: PidParams = param(PidParams(), "", "")
    vsm: VsmParams = param(VsmParams(), "", "")
    impedance: ImpedanceParams = param(ImpedanceParams(), "", "")

    def __post_init__(self) -> None:
        super().__post_init__()
        f, k = self.formation, self.keepout
        # robot centre (axle) in the slot, heading with the person: R - d e(theta_h)
        centre = math.hypot(f.distance * math.cos(f.bearing) - self.robot.d,
                            f.distance * math.sin(f.bearing))
        for name, keep in (("keepout.person_clearance", k.person_clearance),
                           ("keepout.protective_distance", k.protective_distance)):
            if centre < keep:
                raise ConfigError(
                    f"formation.distance: the slot at {f.distance:g} m, bearing "
                    f"{f.bearing:.3f} rad puts the robot centre {centre:.2f} m from the person, "
                    f"inside {name} ({keep:g} m); expected a larger distance or a smaller "
                    f"{name.split('.')[1]}")

    def replace(self, **changes: Any) -> Params:
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


#: Keys that moved to another section: old name -> new name (named in the error).
MOVED = {"safety": "keepout", "supervisor.protective_distance": "keepout.protective_distance",
         "supervisor.person_accel": "keepout.person_accel"}


def _reject_moved(mapping: Mapping[str, Any], prefix: str) -> None:
    for old, new in MOVED.items():
        section, _, key = old.partition(".")
        table = mapping.get(section)
        if table is not None and (not key or (isinstance(table, Mapping) and key in table)):
            raise ConfigError(f"{prefix}{old}: moved to {new} (docs/parameters.md)")


def params_from_mapping(mapping: Mapping[str, Any], prefix: str = "") -> Params:
    """Build validated :class:`Params` from a parsed TOML mapping."""
    _reject_moved(mapping, prefix)
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
