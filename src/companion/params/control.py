"""Parameters of the controllers and the safety layers (sections of :class:`Params`)."""

from __future__ import annotations

import dataclasses
import math

from companion.config import (
    Validated,
    all_non_negative,
    all_positive,
    all_positive_or_inf,
    fraction,
    non_negative,
    param,
    positive,
    positive_or_inf,
    ranged,
)
from companion.geometry import TWO_PI

LEFT = 0.5 * math.pi
BEHIND = math.pi
RIGHT = 1.5 * math.pi
FRONT = 0.0
#: Side names accepted for ``formation.bearing``.
SIDES = {"left": LEFT, "right": RIGHT, "behind": BEHIND, "front": FRONT}


@ranged("[0, 2*pi)")
def _bearing(x: float) -> str | None:
    return None if 0.0 <= x < TWO_PI else "an angle in [0, 2*pi) rad"


@ranged("(1, 1e6]")
def _step_ratio(x: float) -> str | None:
    return None if 1.0 < x < math.inf else "a finite ratio > 1"


@ranged("[0, 1)")
def _risk(x: float) -> str | None:
    return None if 0.0 <= x < 1.0 else "a probability in [0, 1)"


@ranged("[0.1, 10]")
def _horizon(x: float) -> str | None:
    return None if 0.1 <= x <= 10.0 else "a time in [0.1, 10] s"


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
    command_timeout_s: float = param(0.5, "s", "the (simulated) base brakes to a stop at the "
                                     "supervisor's deceleration limits when no command has "
                                     "arrived for this long, as ros2_control's diff drive "
                                     "controller does; inf: never", positive_or_inf)


@dataclasses.dataclass(frozen=True)
class Formation(Validated):
    """Where the robot walks relative to the person."""

    distance: float = param(1.0, "m", "desired distance rho_d from the person to R", positive)
    bearing: float = param(LEFT, "rad",
                           "desired bearing alpha_d of R from the person's heading, in [0, 2*pi): "
                           "left pi/2, behind pi, right 3*pi/2, front 0. TOML also accepts "
                           "\"left\", \"right\", \"behind\", \"front\"", _bearing)
    policy: str = param("adaptive", "-", "'adaptive': beside the person (left or right), the "
                        "robot takes the side it is on when it first sees the person and when "
                        "the person turns round, instead of crossing over, and falls in behind "
                        "where side by side does not fit (companion.control.formation); "
                        "'fixed': the bearing as given (the paper's, which its scenarios pin)",
                        choices=("fixed", "adaptive"))


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
    feedforward_std: tuple[float, float] = param(
        (0.1, 0.1), "m/s, rad/s",
        "the person's estimated speed and turn rate are trusted as exact up to these standard "
        "deviations; beyond, the weights on v_e and omega_e shrink by 1 + (std / this)^2, so "
        "the LQR leans on feedback, not on a feedforward the estimate does not support (ours; "
        "inf = paper-literal, always trusted)", all_positive_or_inf)


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
    uncertainty_sigmas: float = param(2.0, "-", "the protective distance grows by this many "
                                      "standard deviations of where the person may be by the "
                                      "time the robot reacts (the estimate's position and "
                                      "velocity uncertainty over one period, the actuator lag "
                                      "and the detection latency)", non_negative)
    evasive_horizon_s: float = param(1.2, "s", "how far ahead the evasive check predicts "
                                     "robot and person; longer sees a person who walks at "
                                     "the robot earlier, and acts more often", _horizon)
    heading_sigmas: float = param(1.5, "-", "the evasive check also predicts the person "
                                  "walking this many standard deviations of its estimated "
                                  "heading to either side (at most pi/4); 0: only along it",
                                  non_negative)
    collision_risk: float = param(0.0, "-", "how cautious the robot is: the evasive check "
                                  "acts only where the chance that the person and the "
                                  "footprint meet within evasive_horizon_s, under the "
                                  "tracker's distribution of the person, reaches this "
                                  "(lower: more cautious, the robot gives up its slot more "
                                  "often; 0: whenever the worst case comes near)", _risk)
    person_radius: float = param(0.2, "m", "radius of the person's body in the collision risk "
                                 "(contact: the footprint's radius plus this)", non_negative)
    give_way_margin: float = param(0.05, "m", "give way: when a moving obstacle (a walker, at "
                                   "constant velocity) would come within this of the footprint "
                                   "over evasive_horizon_s on the command's path, the evasive "
                                   "check chooses the nearest command that keeps clear; 0 "
                                   "switches giving way off", non_negative)


@dataclasses.dataclass(frozen=True)
class SupervisorParams(Validated):
    """Safety supervisor: rate limits and fault handling (:mod:`companion.control.supervisor`,
    docs/safety.md). Acceleration defaults are those of Nav2's velocity smoother."""

    accel_max: float = param(2.5, "m/s^2", "limit on the rate at which |v| grows", positive)
    decel_max: float = param(2.5, "m/s^2", "limit on the rate at which |v| shrinks; faults "
                             "brake at this rate", positive)
    angular_accel_max: float = param(3.2, "rad/s^2", "limit on the rate of change of omega",
                                     positive)
    max_step_ratio: float = param(3.0, "-", "a time step longer than max_step_ratio * dt (or "
                                  "zero, negative or not finite) is a clock fault: the "
                                  "controller's filters are reset", _step_ratio)
    min_valid_returns: float = param(0.5, "-", "fraction of a LiDAR scan's beams that must be "
                                     "valid (not NaN); below it the robot stops", fraction)
    slot_error_m: float = param(1.0, "m", "a distance from the robot's reference point to its "
                                "slot above this for longer than slot_error_time_s is reported "
                                "(degraded: slot_error)", positive)
    slot_error_time_s: float = param(2.0, "s", "see slot_error_m", positive)
    odometry_timeout_s: float = param(0.5, "s", "odometry that is given but invalid (not "
                                      "finite, or faster than twice the velocity limits) is "
                                      "reported (degraded: odometry_invalid) and replaced by "
                                      "the last command; for longer than this the robot stops "
                                      "(stopped: odometry_lost)", positive)
    delays: str = param("measured", "-", "which detection latency and actuator lag the "
                        "stack compensates: 'measured' (the detections' age at arrival and the "
                        "lag that odometry shows, within bounds; the declared ones until enough "
                        "is seen) or 'declared' (sensing.person_latency_s and "
                        "sensing.actuator_tau_s as given)", choices=("measured", "declared"))


@dataclasses.dataclass(frozen=True)
class SearchParams(Validated):
    """Looking for a lost person after the controlled stop (:mod:`companion.control.search`,
    docs/safety.md "Losing and finding the person")."""

    max_time_s: float = param(10.0, "s", "how long the robot searches once it has stopped for "
                              "a lost person; 0: it holds where it stopped (no search)",
                              non_negative)
    max_distance_m: float = param(15.0, "m", "how far from where it stopped it may go while "
                                  "searching", non_negative)
    speed: float = param(1.5, "m/s", "top speed towards where the person was going (at most "
                         "robot.v_max), within the braking bounds of what it sees and of the "
                         "person standing where they would be by now: faster than a walk, to "
                         "catch up with a person who walks on", positive)
    turn_rate: float = param(1.0, "rad/s", "turn rate while facing that place and while "
                             "scanning", positive)
    horizon_s: float = param(2.0, "s", "the person's last estimate, walked on at its "
                             "velocity for this long (or for the time searched so far, once "
                             "longer), is where the search goes", non_negative)
    arrive_m: float = param(1.0, "m", "the approach ends this close to that place; then the "
                            "robot turns on the spot", positive)


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
    prediction_horizon_s: float = param(2.0, "s", "moving obstacles (walkers) are steered "
                                        "around where they will be when closest to the robot "
                                        "within this; 0: where they are", non_negative)


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
