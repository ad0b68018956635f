"""Plain data types shared by every layer; this module imports nothing from the package.

Units are SI: metres, radians, seconds. Poses and positions are in the world frame unless a
field says otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

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

    ``t`` is the time the person was seen (s), ``x``, ``y`` the position (m) in the named
    ``frame``; ``heading`` (rad) and the 2x2 position ``covariance`` (m^2) are optional, and
    ``track_id`` is the detector's own label, if it has one.
    """

    t: float
    x: float
    y: float
    frame: str = "world"
    heading: float | None = None
    covariance: tuple[float, float, float, float] | None = None
    track_id: int | None = None


@dataclass(frozen=True)
class Circle:
    """A circular obstacle; ``influence`` (m) overrides the avoidance range r / K_ob if set."""

    x: float
    y: float
    radius: float
    influence: float | None = None


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
    (as in ROS REP 117).
    """

    angles: np.ndarray
    ranges: np.ndarray
    x: float
    y: float
    theta: float


@dataclass(frozen=True)
class Observation:
    """What a controller sees at one sample: time (s), robot pose, person state, the
    obstacles known at that time (world frame) and the LiDAR scan they came from (None without
    a LiDAR).

    Raw data may be missing (``person`` None) or corrupt (NaN, Inf, time going backwards);
    only the safety supervisor accepts such observations and hands the layers inside it a
    checked one.
    """

    t: float
    robot: Pose
    person: PersonState | None
    obstacles: tuple[Obstacle, ...] = ()
    scan: Scan | None = None


@dataclass(frozen=True)
class Command:
    """Robot input: linear velocity v (m/s) and angular velocity omega (rad/s).

    ``u_ob`` (rad/s) is the part of omega that obstacle avoidance added. ``status`` ("ok",
    "degraded" or "stopped") and ``reason`` (empty when ok) are set by the safety supervisor.
    """

    v: float
    omega: float
    u_ob: float = 0.0
    status: str = "ok"
    reason: str = ""


LOG_COLUMNS = ("t", "robot_x", "robot_y", "robot_theta", "person_x", "person_y",
               "person_theta", "person_v", "person_omega", "rho", "alpha", "beta",
               "rho_d", "alpha_d", "beta_ref", "v", "omega", "u_ob", "rho_ob")
"""Numeric columns of an episode log. ``beta_ref``: heading offset that holding the slot
needs; ``u_ob``: the avoidance part of omega (rad/s); ``rho_ob``: clearance (m) from the
robot's footprint to the nearest true obstacle surface (NaN without obstacles)."""

TEXT_COLUMNS = ("status", "reason")
"""The safety supervisor's status and reason per sample ("ok" and "" without one)."""


@dataclass(frozen=True, eq=False)
class Log:
    """Columns of one episode: :data:`LOG_COLUMNS` as float arrays and :data:`TEXT_COLUMNS`
    as string arrays, all of length N (row k: state at t_k and the command applied from t_k)."""

    columns: dict[str, np.ndarray]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __len__(self) -> int:
        return len(self.columns["t"])

    def equals(self, other: Log) -> bool:
        """True if both logs hold the same columns with bit-identical values."""
        if self.columns.keys() != other.columns.keys():
            return False
        return all(np.array_equal(a, other.columns[k], equal_nan=a.dtype.kind == "f")
                   for k, a in self.columns.items())
