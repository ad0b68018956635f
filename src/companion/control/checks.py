"""Checks of raw data for the safety supervisor: the clock, the robot pose, obstacles and LiDAR
scans (docs/safety.md, faults 2, 4 and 7)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from companion.geometry import clearance
from companion.params import Params, RobotParams
from companion.types import Circle, Obstacle, Pose, Scan


def finite(*values: float) -> bool:
    """Every value finite (a plain loop: called many times a step)."""
    for x in values:
        if not math.isfinite(x):
            return False
    return True


#: Largest plausible robot coordinate (m): beyond it a pose is corrupt, and the geometry of
#: a person 1 m away would lose every digit.
MAX_COORDINATE = 1e6


def pose_is_finite(pose: Pose) -> bool:
    """Finite, with coordinates a robot could have (at most :data:`MAX_COORDINATE`)."""
    return (finite(pose.x, pose.y, pose.theta) and abs(pose.x) <= MAX_COORDINATE
            and abs(pose.y) <= MAX_COORDINATE)


def obstacle_is_finite(ob: Obstacle) -> bool:
    """All fields finite (an unset ``influence`` is fine; a circle's velocity too), a circle's
    radius >= 0."""
    influence = () if ob.influence is None else (ob.influence,)
    if isinstance(ob, Circle):
        return finite(ob.x, ob.y, ob.radius, ob.vx, ob.vy, *influence) and ob.radius >= 0.0
    return finite(ob.x0, ob.y0, ob.x1, ob.y1, *influence)


def obstacle_inside(robot: Pose, obstacles: Sequence[Obstacle], radius: float) -> bool:
    """An obstacle overlaps the footprint of ``radius`` around a finite robot pose."""
    return pose_is_finite(robot) and any(clearance(ob, robot.x, robot.y, radius) < 0.0
                                         for ob in obstacles)


def valid_fraction(scan: Scan) -> float:
    """Share of the scan's beams that are not NaN (0 for an empty scan). ``inf`` (nothing
    within range) and ``-inf`` (closer than the sensor's minimum) are valid (ROS REP 117)."""
    n = scan.ranges.size
    return 0.0 if n == 0 else float(n - np.count_nonzero(np.isnan(scan.ranges))) / n


def too_close(scan: Scan, radius: float) -> bool:
    """A valid return (``-inf`` included) closer than ``radius`` to the sensor."""
    r = scan.ranges
    return bool(np.any(r[~np.isnan(r)] < radius))


def scan_fault(scan: Scan, params: Params, reasons: list[str]) -> str:
    """The stop reason a scan (read by :func:`companion.perception.checked_scan`) gives ("" if
    none); "scan_partial" goes to ``reasons``."""
    fraction = valid_fraction(scan)
    if fraction < params.supervisor.min_valid_returns or fraction == 0.0:
        return "scan_invalid"
    if fraction < 1.0:
        reasons.append("scan_partial")
    if too_close(scan, params.robot.radius):
        return "obstacle_in_footprint"
    return ""


class Clock:
    """The time between calls: ``tick(t)`` returns the seconds elapsed and ``"ok"``,
    ``"clock"`` (a zero, negative or non-finite step: the data are discarded and one period
    ``dt`` counts) or ``"clock_gap"`` (a step over ``max_step_ratio * dt``: the data are kept,
    the filters reset). :attr:`now` always advances."""

    def __init__(self, dt: float, max_step_ratio: float):
        self.dt, self.max_step = dt, max_step_ratio * dt
        self.reset()

    def reset(self) -> None:
        self._t_last: float | None = None
        self.now = 0.0

    def tick(self, t: float) -> tuple[float, str]:
        if not math.isfinite(t):
            self.now += self.dt
            return self.dt, "clock"
        if self._t_last is None:
            self._t_last, self.now = t, t
            return 0.0, "ok"
        step = t - self._t_last
        self._t_last = t
        if step <= 0.0:
            self.now += self.dt
            return self.dt, "clock"
        self.now += step
        return step, "clock_gap" if step > self.max_step else "ok"


#: A pose change between two odometry samples beyond this multiple of what the velocity limits
#: allow in the time between them (plus the floors below, for noise) is a jump no robot makes.
JUMP_MARGIN = 2.0
JUMP_FLOOR_M = 0.05
JUMP_FLOOR_RAD = 0.05


class Odometry:
    """The odometry samples of a stream (stamp, pose): ``check`` returns ``""`` for a
    plausible sample, ``"odometry_time"`` for a stamp that is not finite or earlier than the
    last one, ``"odometry_jump"`` for a pose change no robot can make in the time between.
    A jump becomes the reference for the next sample (a relocalised pose is followed again
    after one sample); a sample whose time went back does not. Non-finite poses are left to
    the robot pose check."""

    def __init__(self, robot: RobotParams):
        self.robot = robot
        self.reset()

    def reset(self) -> None:
        self._last: tuple[float, Pose] | None = None

    def check(self, stamp: float, pose: Pose) -> str:
        if not math.isfinite(stamp):
            return "odometry_time"
        if not pose_is_finite(pose):
            return ""
        if self._last is None:
            self._last = (stamp, pose)
            return ""
        t0, p0 = self._last
        if stamp < t0:
            return "odometry_time"
        self._last = (stamp, pose)
        elapsed = stamp - t0
        moved = math.hypot(pose.x - p0.x, pose.y - p0.y)
        turned = abs(math.remainder(pose.theta - p0.theta, 2.0 * math.pi))
        if moved > JUMP_MARGIN * self.robot.v_max * elapsed + JUMP_FLOOR_M \
                or turned > JUMP_MARGIN * self.robot.omega_max * elapsed + JUMP_FLOOR_RAD:
            return "odometry_jump"
        return ""
