"""Plain data types shared by every layer; this module imports nothing from the package.

Units are SI: metres, radians, seconds. Poses and positions are in the world frame unless a
field says otherwise.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


@dataclass(frozen=True)
class Pose:
    """Planar pose of the robot's wheel-axle centre: x, y (m) and heading theta (rad)."""

    x: float
    y: float
    theta: float


@dataclass(frozen=True)
class PersonState:
    """The person's pose and velocity (paper Eq. 3): x, y (m), theta (rad), v (m/s),
    omega (rad/s)."""

    x: float
    y: float
    theta: float
    v: float
    omega: float


@dataclass(frozen=True)
class PersonDetection:
    """One detection of a person by a sensor (LiDAR legs, camera, UWB, a magnetic tag).

    ``t`` is the time the person was seen (s, not when the detection arrived), ``x``, ``y``
    the position (m) in the named ``frame`` ("world", the frame of the robot pose, or "robot",
    the robot's own frame at time ``t``). Optional: the position ``covariance`` (2x2, row-major,
    m^2), the ``heading`` (rad, world frame) with ``heading_std``, the ``speed`` (m/s) and
    ``turn_rate`` (rad/s) with ``velocity_std`` (an upstream tracker, a tag with an IMU), and
    the detector's own ``track_id``. A missing std means the tracker's default; a std of 0
    means exact. ``z`` (m) is the third coordinate in ``frame`` for a detector that measures
    it (a camera's optical frame measures depth along z): placing the detection through tf
    uses it; the tracker uses ``x``, ``y`` only.
    """

    t: float
    x: float
    y: float
    frame: str = "world"
    covariance: tuple[float, float, float, float] | None = None
    heading: float | None = None
    heading_std: float | None = None
    speed: float | None = None
    turn_rate: float | None = None
    velocity_std: tuple[float, float] | None = None
    track_id: int | None = None
    z: float = 0.0


@dataclass(frozen=True)
class PersonEstimate:
    """The tracker's estimate of the person at one instant.

    ``state`` is the kinematic estimate (moving forwards, speed >= 0), what safety reasons
    about; ``walker`` the state the formation is defined on: the same, but a standing person
    (too slow for positions to tell a heading) faces the way it last walked, without speed or
    turning. Also: the standard deviation of the position (m, the larger axis of its 2x2
    covariance), the 5x5 covariance of the tracker's state (x, y, vx, vy, omega; its position
    part widened while the detections show a manoeuvre the filter did not expect), the time
    since the last accepted detection (s) and the track's status, "seen" or "predicted"
    (coasting over missing detections).
    """

    state: PersonState
    position_std: float
    covariance: np.ndarray
    age: float
    status: str
    walker: PersonState


@dataclass(frozen=True)
class Circle:
    """A circular obstacle; ``influence`` (m) overrides the avoidance range r / K_ob if set.
    ``vx``, ``vy`` (m/s, world frame): its velocity, for a walker or a moving LiDAR cluster
    (0: standing or unknown); the keep-out and avoidance predict it at constant velocity.
    ``piece``: one of the circles the LiDAR split a larger thing (a wall) into, which bounds
    the way (nothing is known beyond it)."""

    x: float
    y: float
    radius: float
    influence: float | None = None
    vx: float = 0.0
    vy: float = 0.0
    piece: bool = False

    @property
    def moving(self) -> bool:
        return self.vx != 0.0 or self.vy != 0.0

    def at(self, dt: float) -> Circle:
        """Where it is ``dt`` s on at its velocity."""
        return dataclasses.replace(self, x=self.x + self.vx * dt, y=self.y + self.vy * dt)


@dataclass(frozen=True)
class Wall:
    """A wall segment from (x0, y0) to (x1, y1) of zero thickness; ``influence`` (m) overrides
    the default avoidance range."""

    x0: float
    y0: float
    x1: float
    y1: float
    influence: float | None = None


Obstacle = Circle | Wall


@dataclass(frozen=True, eq=False)
class Scan:
    """One planar LiDAR scan and the sensor pose it was taken from.

    ``angles`` (rad, robot frame, increasing) and ``ranges`` (m) have one entry per beam;
    a range is ``inf`` where nothing was hit and NaN where the return is invalid
    (as in ROS REP 117). ``range_min`` and ``range_max`` (m) are the sensor's limits, as in
    sensor_msgs/LaserScan (``companion.perception.checked_scan`` reads a scan by them). ``t``
    (s) is the time it was taken (its stamp; NaN: unknown).
    """

    angles: np.ndarray
    ranges: np.ndarray
    x: float
    y: float
    theta: float
    range_min: float = 0.0
    range_max: float = math.inf
    t: float = math.nan


@dataclass(frozen=True)
class Observation:
    """What the robot knows at one sample: time (s), robot pose, the person, the obstacles
    known at that time (world frame), the LiDAR scan they came from (None without a LiDAR),
    the robot's measured velocity ``(v, omega)`` from odometry (None: unknown), the person
    detections that arrived since the last sample, the sources that are stale, the time
    of the odometry sample the velocity comes from (None: ``t``), the formation in force
    ``(distance, bearing)`` (m, rad; None: the controller's configured one), which a
    formation policy changes while walking, and the standard deviations of the person's
    estimated speed and turn rate ``(m/s, rad/s)`` (None: ``person`` is exact).

    The standard stack's input is the detections: its safety supervisor tracks the person
    from them and hands the layers inside it ``person``, the estimate. A ``person`` given to
    the stack is taken as an exact detection at ``t`` (an ideal sensor). Raw data may be
    missing or corrupt (NaN, Inf, time going backwards); only the supervisor accepts such
    observations and hands the layers inside it a checked one.
    """

    t: float
    robot: Pose
    person: PersonState | None = None
    obstacles: tuple[Obstacle, ...] = ()
    scan: Scan | None = None
    robot_velocity: tuple[float, float] | None = None
    detections: tuple[PersonDetection, ...] = ()
    stale: tuple[str, ...] = ()
    robot_stamp: float | None = None
    formation: tuple[float, float] | None = None
    person_std: tuple[float, float] | None = None


@dataclass(frozen=True)
class Command:
    """What the base receives: linear velocity v (m/s), angular velocity omega (rad/s) and
    the stack's ``status`` ("ok", "degraded" or "stopped").

    ``u_ob`` (rad/s) is the part of omega that obstacle avoidance added: a controller's
    output that the controller is told back (``applied``); everything else the stack knows
    about the step is in its :class:`StepReport`.
    """

    v: float
    omega: float
    u_ob: float = 0.0
    status: str = "ok"


class StepReport(NamedTuple):
    """What the standard stack did in one step, beside the :class:`Command` it sent: the
    ``status`` and ``reason`` (the reasons joined by "+", the stop first; empty when ok),
    each ``(stage, reason)`` in the order the pipeline's stages raised them, the person
    ``estimate`` the command was made for (None: lost), the controller's ``requested``
    ``(v, omega)`` within the rate limits before the keep-out changed it (None without a
    controller step), the formation's ``bearing`` in force (rad) and the ``obstacles`` the
    stack knew (world frame). Logs, bags, the node's status topic and the simulator's
    recorder read it. A named tuple: the stack makes one every step."""

    status: str = "ok"
    reason: str = ""
    stages: tuple[tuple[str, str], ...] = ()
    estimate: PersonEstimate | None = None
    requested: tuple[float, float] | None = None
    bearing: float | None = None
    obstacles: tuple[Obstacle, ...] = ()


LOG_COLUMNS = ("t", "robot_x", "robot_y", "robot_theta", "person_x", "person_y",
               "person_theta", "person_v", "person_omega", "rho", "alpha", "beta",
               "rho_d", "alpha_d", "beta_ref", "v", "omega", "u_ob", "rho_ob",
               "robot_v", "robot_omega", "person_est_x", "person_est_y", "person_est_theta",
               "person_est_v", "person_est_omega", "person_est_std", "slot_error_m",
               "estimate_error_m", "tracking_error_m", "safety_shift_m", "person_gap_m",
               "walker_gap_m", "walker_contact", "person_in_view", "odom_x", "odom_y",
               "odom_theta", "plant_contact")
"""Numeric columns of an episode log: the true state of robot and person, the relative state,
``beta_ref`` (heading offset that holding the slot needs), the command (``v``, ``omega``),
``u_ob`` (the avoidance part of omega, rad/s), ``rho_ob`` (clearance from the robot's
footprint to the nearest true obstacle surface, m; NaN without obstacles), the robot's actual
velocity (``robot_v``, ``robot_omega``; behind the command by the actuator lag), the
tracker's estimate of the person with its position std (NaN without one), and where the slot
error comes from (docs/sensing.md): ``slot_error_m`` from the robot's reference point R to the
true person's slot, ``estimate_error_m`` from the slot the estimate implies to the true one,
``tracking_error_m`` from R to the estimated slot (both NaN without an estimate), and
``safety_shift_m``, how far the keep-out moved R in this step (the executed command's motion
of R over one period against the controller's request; 0 without a request); the crowd
columns (docs/crowds.md): ``person_gap_m``, ``walker_gap_m``, ``walker_contact`` and
``person_in_view`` (1 where the person detector could see the person, 0 out of its range or
hidden); the pose the robot's odometry reports (``odom_x``, ``odom_y``, ``odom_theta``: the
true pose on the kinematic plant, dead reckoning from the wheels on the MuJoCo base) and
``plant_contact`` (1 where the plant's physics finds the robot's body touching the person or
an obstacle, 0 where not, NaN on a plant without bodies; docs/plants.md)."""

TEXT_COLUMNS = ("status", "reason")
"""The safety supervisor's status and reason per sample ("ok" and "" without one)."""


@dataclass(frozen=True, eq=False)
class Log:
    """Columns of one episode: :data:`LOG_COLUMNS` as float arrays and :data:`TEXT_COLUMNS`
    as string arrays, all of length N (row k: state at t_k and the command applied from t_k);
    a crowd episode also has ``walkers_xy``, N rows of the walkers' positions (x0, y0, x1,
    ...; in memory only, not in log.csv)."""

    columns: dict[str, np.ndarray]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __len__(self) -> int:
        return len(self.columns["t"])

    @staticmethod
    def concat(blocks: Iterable[Log]) -> Log:
        """The logs of consecutive blocks of one episode joined into one log."""
        parts = list(blocks)
        return Log({name: np.concatenate([p.columns[name] for p in parts])
                    for name in parts[0].columns})

    def equals(self, other: Log) -> bool:
        """True if both logs hold the same columns with bit-identical values."""
        if self.columns.keys() != other.columns.keys():
            return False
        return all(np.array_equal(a, other.columns[k], equal_nan=a.dtype.kind == "f")
                   for k, a in self.columns.items())
