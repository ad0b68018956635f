"""``companion node``: the standard stack (tracker, controller, avoidance, supervisor) as a
ROS 2 node on any :class:`~companion.ros.transport.Transport`.

Messages are stored as they arrive (any thread); :meth:`CompanionNode.tick`, called every
period ``dt`` on the node's clock (the system clock, or /clock with ``use_sim_time``), turns
what arrived into one :class:`~companion.types.Observation` and publishes the command, the
status and the markers. Header stamps, not arrival times, place every input in time: a
detection or scan is placed with the odometry pose at its stamp (interpolated), and odometry
older than ``ros.odom_timeout_s`` or no scan for ``ros.scan_timeout_s`` stops the robot
(reasons ``odometry_stale``, ``scan_stale``) until fresh data return. docs/ros2.md.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from companion.control import make_controller
from companion.control.avoidance import influence_range
from companion.control.slot import slot_point
from companion.geometry import unicycle_step, wrap_pi
from companion.model import relative_state
from companion.perception import extract_obstacles
from companion.ros import convert
from companion.ros.convert import OdometrySample, Stamped
from companion.ros.settings import NodeConfig
from companion.ros.transport import DEFAULT, SENSOR_DATA, Qos, Transport
from companion.types import (
    Circle,
    Command,
    Observation,
    PersonDetection,
    PersonEstimate,
    Pose,
)

_NOWHERE = Pose(math.nan, math.nan, math.nan)


class View(NamedTuple):
    """What the node shows of one tick (markers, the recorded scene): the time (s), the
    robot pose it used, the person estimate, the desired slot and the obstacles it knows with
    their influence ranges (m)."""

    t: float
    robot: Pose
    estimate: PersonEstimate | None
    slot: tuple[float, float] | None
    obstacles: tuple[tuple[Circle, float], ...]


def with_reasons(cmd: Command, reasons: list[str]) -> Command:
    """``cmd`` with the node's own ``reasons`` added (degraded if it was ok)."""
    return dataclasses.replace(cmd, status="degraded" if cmd.status == "ok" else cmd.status,
                               reason="+".join([cmd.reason] * bool(cmd.reason) + reasons))


def pose_at(samples: deque[OdometrySample], t: float) -> Pose | None:
    """The odometry pose at time ``t``: interpolated between the samples around it, or
    moved on from the nearest end with its velocity (at most 0.5 s); None without samples."""
    if not samples:
        return None
    if t <= samples[0].t or t >= samples[-1].t:
        s = samples[0] if t <= samples[0].t else samples[-1]
        x, y, th = unicycle_step(s.pose.x, s.pose.y, s.pose.theta, *s.velocity,
                                 max(-0.5, min(t - s.t, 0.5)))
        return Pose(x, y, wrap_pi(th))
    lo, hi = 0, len(samples) - 1
    while hi - lo > 1:              # the samples are in time order
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if samples[mid].t <= t else (lo, mid)
    a, b = samples[lo], samples[hi]
    w = (t - a.t) / (b.t - a.t) if b.t > a.t else 0.0
    dth = wrap_pi(b.pose.theta - a.pose.theta)
    return Pose(a.pose.x + w * (b.pose.x - a.pose.x), a.pose.y + w * (b.pose.y - a.pose.y),
                wrap_pi(a.pose.theta + w * dth))


class CompanionNode:
    """The node's state and its one step; see the module docstring."""

    def __init__(self, config: NodeConfig, transport: Transport,
                 clock: Callable[[], float] = time.time):
        self.config, self.transport = config, transport
        p, r = config.params, config.ros
        self.stack = make_controller(config.controller, p)
        self._system_clock = clock
        self._lock = threading.Condition()
        self._odom: deque[OdometrySample] = deque()
        self._scan: tuple[float, Any] | None = None        # (stamp, LaserScan) not yet used
        self._scan_t = -math.inf                             # stamp of the last scan used
        self._obstacles: tuple[Circle, ...] = ()
        self._scan_seen: Any = None
        self._people: list[Stamped] = []
        self._sim_time: float | None = None
        self._seen: tuple[float, float] | None = None
        self.last: Command | None = None
        self.view: View | None = None
        t = r.topics
        reliable = Qos(depth=r.history_depth)
        transport.subscribe(t.odom, "nav_msgs/msg/Odometry", self.on_odom, reliable)
        if t.scan:
            transport.subscribe(t.scan, "sensor_msgs/msg/LaserScan", self.on_scan,
                                reliable if r.scan_reliable else SENSOR_DATA)
        transport.subscribe(t.person, convert.PERSON_TYPES[r.person_type], self.on_person,
                            reliable)
        if r.use_sim_time:
            transport.subscribe(t.clock, "rosgraph_msgs/msg/Clock", self.on_clock,
                                Qos(reliable=False, depth=1))
        cmd_type = "geometry_msgs/msg/TwistStamped" if r.cmd_vel_stamped \
            else "geometry_msgs/msg/Twist"
        self._cmd = transport.publisher(t.cmd_vel, cmd_type, DEFAULT)
        self._status = transport.publisher(t.status, "diagnostic_msgs/msg/DiagnosticArray",
                                           DEFAULT)
        self._markers = transport.publisher(t.markers, "visualization_msgs/msg/MarkerArray",
                                            DEFAULT) if t.markers else None

    # -- inputs (any thread) -------------------------------------------------------------

    def on_odom(self, msg: Any) -> None:
        sample = convert.odometry_sample(msg)
        with self._lock:
            if self._odom and sample.t <= self._odom[-1].t:
                self._odom.clear()        # time went back (a restarted bag or robot): restart
            self._odom.append(sample)
            while self._odom[0].t < sample.t - self.config.ros.odometry_buffer_s:
                self._odom.popleft()

    def on_scan(self, msg: Any) -> None:
        with self._lock:
            self._scan = (convert.seconds(msg.header.stamp), msg)

    def on_person(self, msg: Any) -> None:
        people = convert.people_from(msg, self.config.ros.person_type)
        with self._lock:
            self._people.extend(people)

    def on_clock(self, msg: Any) -> None:
        with self._lock:
            self._sim_time = convert.seconds(msg.clock)
            self._lock.notify_all()

    # -- the step ------------------------------------------------------------------------

    def now(self) -> float | None:
        """The node's time (s): /clock with ``use_sim_time`` (None before the first), else
        the system clock."""
        if self.config.ros.use_sim_time:
            return self._sim_time
        return self._system_clock()

    def wait_clock(self, until: float, timeout: float) -> float | None:
        """With ``use_sim_time``: wait up to ``timeout`` s of system time for /clock to reach
        ``until``; the node's time then (None if /clock never came)."""
        with self._lock:
            self._lock.wait_for(lambda: self._sim_time is not None and self._sim_time >= until,
                                timeout)
            return self._sim_time

    def tick(self, now: float) -> Command:
        """One period at time ``now``: the observation, the stack's command, the outputs."""
        r = self.config.ros
        with self._lock:
            future = self._drop_future(now)
            odom = self._odom[-1] if self._odom else None
            people, self._people = self._people, []
            scan, self._scan = self._scan, None
            samples = deque(self._odom)
        stale = []
        if odom is None or now - odom.t > r.odom_timeout_s:
            stale.append("odometry")
        if odom is None:
            robot, velocity = _NOWHERE, None
        else:
            lead = max(0.0, min(now - odom.t, r.odom_timeout_s))
            x, y, th = unicycle_step(odom.pose.x, odom.pose.y, odom.pose.theta,
                                     *odom.velocity, lead)
            robot, velocity = Pose(x, y, wrap_pi(th)), odom.velocity
        detections = tuple(self._detection(s, samples) for s in people)
        placed = [d for d in detections if d.frame == self.config.params.tracker.world_frame]
        if placed:                # the newest detection, until the estimate, hides the person
            self._seen = (placed[-1].x, placed[-1].y)      # from the LiDAR's obstacles
        if scan is not None:
            self._use_scan(*scan, samples)
        if r.topics.scan and now - self._scan_t > r.scan_timeout_s:
            stale.append("scan")
        obs = Observation(now, robot, None, self._obstacles, self._scan_seen, velocity,
                          detections, tuple(stale))
        cmd = self.stack.step(obs)
        if future:
            cmd = with_reasons(cmd, future)
        self.last = cmd
        if cmd.estimate is not None:
            self._seen = (cmd.estimate.state.x, cmd.estimate.state.y)
        self._publish(now, robot, cmd)
        return cmd

    def stop(self, now: float) -> None:
        """Publish a zero velocity (the node's last word)."""
        r = self.config.ros
        self._cmd(convert.twist_msg(0.0, 0.0, r.cmd_vel_stamped, now, r.base_frame))

    # -- the pieces ----------------------------------------------------------------------

    def _drop_future(self, now: float) -> list[str]:
        """Drop odometry and the scan stamped later than ``now`` plus the tracker's
        ``future_tolerance_s`` (a clock ahead, a corrupt stamp); the reasons. Under the lock."""
        ahead, reasons = now + self.config.params.tracker.future_tolerance_s, []
        if self._odom and self._odom[-1].t > ahead:
            reasons.append("odometry_future")
            while self._odom and self._odom[-1].t > ahead:
                self._odom.pop()
        if self._scan is not None and self._scan[0] > ahead:
            reasons.append("scan_future")
            self._scan = None
        return reasons

    def _use_scan(self, t: float, msg: Any, samples: deque[OdometrySample]) -> None:
        """A new scan: placed with the odometry pose at its stamp and the LiDAR's mounting
        pose; its obstacles replace the previous scan's."""
        r = self.config.ros
        robot = pose_at(samples, t)
        if robot is None:
            return                      # no odometry yet: the scan cannot be placed
        sensor = convert.compose(robot, Pose(*r.lidar_mount))
        self._scan_t = t
        self._scan_seen = convert.scan_from(msg, sensor)
        self._obstacles = tuple(extract_obstacles(self._scan_seen, self._seen,
                                                  self.config.params.extractor))

    def _detection(self, s: Stamped, samples: deque[OdometrySample]) -> PersonDetection:
        """A person position as the tracker takes it: odometry-frame positions as they are,
        positions in the robot's or the LiDAR's frame moved with the odometry pose at their
        stamp; any other frame is passed on by name (the tracker rejects it)."""
        r, tr = self.config.ros, self.config.params.tracker
        extra = (s.covariance, s.heading, s.heading_std, s.speed, s.turn_rate, s.velocity_std)
        if s.frame == r.odom_frame:
            return PersonDetection(s.t, s.x, s.y, tr.world_frame, *extra)
        mounts = {r.base_frame: Pose(0.0, 0.0, 0.0), r.lidar_frame: Pose(*r.lidar_mount)}
        robot = pose_at(samples, s.t)
        if s.frame not in mounts or robot is None:
            return PersonDetection(s.t, s.x, s.y, s.frame or "(no frame)", *extra)
        f = convert.compose(robot, mounts[s.frame])
        c, si = math.cos(f.theta), math.sin(f.theta)
        cov = s.covariance
        if cov is not None:       # R C R^T
            rot = np.array(((c, -si), (si, c)))
            cov = tuple((rot @ np.reshape(cov, (2, 2)) @ rot.T).ravel().tolist())
        heading = None if s.heading is None else wrap_pi(s.heading + f.theta)
        return PersonDetection(s.t, f.x + c * s.x - si * s.y, f.y + si * s.x + c * s.y,
                               tr.world_frame, cov, heading, s.heading_std, s.speed,
                               s.turn_rate, s.velocity_std)

    def _publish(self, now: float, robot: Pose, cmd: Command) -> None:
        p, r = self.config.params, self.config.ros
        self._cmd(convert.twist_msg(cmd.v, cmd.omega, r.cmd_vel_stamped, now, r.base_frame))
        errors = slot = None
        e = cmd.estimate
        if e is not None and math.isfinite(robot.x):
            w = e.walker
            errors = relative_state(robot.x, robot.y, robot.theta, w.x, w.y, w.theta,
                                    p.robot.d)
            slot = slot_point(w, p)
        self._status(convert.status_msg(now, cmd, errors, r.node_name))
        reach = tuple((ob, influence_range(ob, p.avoidance)) for ob in self._obstacles)
        self.view = View(now, robot, e, slot, reach)
        if self._markers is not None:
            self._markers(convert.markers_msg(now, r.odom_frame, e, slot, reach))

#: A period is due this much before its time: /clock carries nanoseconds and the schedule
#: sums ``dt``, so a clock of exactly ``k * dt`` can read a hair before the summed time.
_CLOCK_SLACK_S = 1e-6


def spin(node: CompanionNode, stop: threading.Event, limit_s: float | None = None) -> int:
    """Tick ``node`` every period until ``stop`` is set (or ``limit_s`` s of the node's time
    have passed), then publish a zero velocity; returns the number of ticks."""
    dt, sim = node.config.params.dt, node.config.ros.use_sim_time
    ticks, start, next_t = 0, None, None
    while not stop.is_set():
        due = -math.inf if next_t is None else next_t - _CLOCK_SLACK_S
        now = node.wait_clock(due, 0.1) if sim else node.now()
        if now is None or now < due:
            if not sim:
                stop.wait(min(due - now, dt))
            continue
        start = now if start is None else start
        if limit_s is not None and now - start >= limit_s:
            break
        node.tick(now)
        ticks += 1
        next_t = (next_t if next_t is not None else now) + dt
        if next_t < now - dt:           # fell behind by more than a period: do not burst
            next_t = now + dt
    node.stop(node.now() or 0.0)
    return ticks
