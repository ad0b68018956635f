"""``companion sim-robot``: the simulator as a ROS 2 robot.

The episode is the one ``companion run`` steps (:class:`companion.sim.episode.Simulator`:
person, sensing model, LiDAR, actuator lag, the log), but the controller is on the wire:
:class:`WireRobot` publishes what the robot senses at each sample (/odom, /tf odom ->
base_link, /scan, /person detections, /clock) and hands the simulator the /cmd_vel received
in the period; the node's last /companion/status and estimate are the log's step report.
Without a command the simulator's base, like ros2_control's diff_drive_controller, keeps
the last command for ``robot.command_timeout_s`` and then brakes to a stop at the
deceleration limits (logged as ``stopped: command_timeout``).

In lock step (``lockstep_s`` > 0, with /clock) each period waits for the node's answer to
that period's /clock before the plant moves, as an in-process run does; docs/ros2.md.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from companion.params import Params
from companion.ros import convert
from companion.ros.convert import TimeBase
from companion.ros.settings import RosParams
from companion.ros.transport import DEFAULT, SENSOR_DATA, Qos, Transport
from companion.sim.episode import Simulator, drive
from companion.sim.runner import EpisodeSpec
from companion.sim.sensing import LidarPerception
from companion.types import Command, Log, Observation, PersonEstimate, StepReport

#: Where simulated time starts on the wire: 2000-01-01T00:00:00Z, in ns since 1970. Stamps,
#: /clock and a bag's log times of a simulated run count from it (a bag of a simulated run
#: starts on that day, not at 0, which tools show as 1970).
SIM_EPOCH_NS = 946_684_800 * 1_000_000_000
#: Wall time (s) a robot that waited for the node waits on after its first command.
SETTLE_S = 0.5


class Interrupted(Exception):
    """The run was stopped (SIGINT, SIGTERM) before its end."""


class Pacer:
    """Holds a simulation to the system clock: sample time ``t`` happens ``t / rate`` s after
    the start (``rate`` 0: as fast as possible); raises :class:`Interrupted` once ``stop`` is
    set."""

    def __init__(self, rate: float, stop: threading.Event | None = None):
        self.rate, self.stop = rate, stop or threading.Event()
        self.start: float | None = None

    def wait(self, t: float) -> None:
        if self.start is None:
            self.start = time.monotonic()
        if self.rate > 0.0:
            self.stop.wait(max(0.0, self.start + t / self.rate - time.monotonic()))
        if self.stop.is_set():
            raise Interrupted


class WireRobot:
    """A ROS 2 robot's interface to a node: :meth:`step` publishes a sample and returns the
    node's command of the period, if one came."""

    def __init__(self, transport: Transport, ros: RosParams, params: Params, pacer: Pacer,
                 epoch_ns: int | None = SIM_EPOCH_NS,
                 after: Callable[[float], None] | None = None, lockstep_s: float = 0.0):
        """``epoch_ns`` is the stamp of simulated time 0 (None: the system clock at the first
        sample, after the wait for a node; with ``use_sim_time`` one period after
        :data:`SIM_EPOCH_NS`, so that the node's tick on the waiting phase's /clock at the
        epoch is followed by one at every sample);
        ``after(t)`` runs once the sample's messages are out (a lock-step test ticks the node
        there); ``lockstep_s`` > 0 waits up to that long (wall time) each period for the
        node's answer to the period's /clock."""
        self.ros, self.params, self.pacer, self.after = ros, params, pacer, after
        self.time = None if epoch_ns is None else TimeBase(epoch_ns)
        self.lockstep_s = lockstep_s if ros.use_sim_time else 0.0
        t = ros.topics
        self._odom = transport.publisher(t.odom, "nav_msgs/msg/Odometry", DEFAULT)
        self._tf = transport.publisher("/tf", "tf2_msgs/msg/TFMessage", Qos(depth=100))
        self._scan = transport.publisher(t.scan, "sensor_msgs/msg/LaserScan", SENSOR_DATA) \
            if t.scan else None
        kind = measured_type(params) if ros.person_type == "auto" else ros.person_type
        self.person_type = kind
        self._person = transport.publisher(t.person, convert.PERSON_TYPES[kind], DEFAULT)
        # /clock reliable (readers may be best effort): on Zenoh the reliable and the
        # best-effort samples travel apart, and a clock must not overtake its sample's data
        self._clock = transport.publisher(t.clock, "rosgraph_msgs/msg/Clock",
                                          Qos(reliable=True, depth=1)) \
            if ros.use_sim_time else None
        cmd_type = "geometry_msgs/msg/TwistStamped" if ros.cmd_vel_stamped \
            else "geometry_msgs/msg/Twist"
        self._lock = threading.Condition()
        self._received: tuple[float, float] | None = None
        self._status = ("ok", "")        # the node's last word on /companion/status
        self._estimate: PersonEstimate | None = None   # and its person estimate
        self.commands = 0
        #: Whether the node ever said it was not stopped (None: it has no status topic).
        self.started: bool | None = False if t.status else None
        transport.subscribe(t.cmd_vel, cmd_type, self._on_cmd, DEFAULT)
        if t.status:
            transport.subscribe(t.status, "diagnostic_msgs/msg/DiagnosticArray",
                                self._on_status, DEFAULT)
        self.reset()

    def _on_cmd(self, msg: Any) -> None:
        v, w = convert.twist_velocity(msg)
        if math.isfinite(v) and math.isfinite(w):
            with self._lock:
                self._received = (v, w)
                self.commands += 1
                self._lock.notify_all()

    def _on_status(self, msg: Any) -> None:
        status, estimate = convert.status_of(msg), convert.estimate_of(msg)
        with self._lock:
            self._status, self._estimate = status, estimate
            self.started = self.started or status[0] != "stopped"

    def wait_for_node(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for a first /cmd_vel (with ``use_sim_time``, /clock stays
        at the start meanwhile, so the node can tick), then :data:`SETTLE_S` more: a first
        command shows the routes of /clock and /cmd_vel, not yet those of the node's other
        subscriptions (on Zenoh they were measured to come up later, and the first sample's
        odometry and detection were lost). True if a command came."""
        end, settled = time.monotonic() + timeout, None
        while time.monotonic() < end or settled is not None:
            if self._clock is not None and self.time is not None:
                self._clock(convert.clock_msg(-self.params.dt, self.time))
            with self._lock:
                if self.commands and settled is None:
                    settled = time.monotonic() + SETTLE_S
                if settled is not None and time.monotonic() >= settled:
                    self._received, self.commands = None, 0
                    return True
            if self.pacer.stop.wait(0.05):
                raise Interrupted
        return False

    def reset(self) -> None:
        self._last_scan = None
        #: What the node said of its last command (its status topic): the log's report.
        self.report = StepReport()

    def step(self, obs: Observation) -> Command | None:
        self.pacer.wait(obs.t)
        if self.time is None:
            self.time = TimeBase(time.time_ns() - int(round(obs.t * 1e9)))
        tb, t = self.time, obs.t
        r = self.ros
        velocity = obs.robot_velocity or (0.0, 0.0)
        self._odom(convert.odometry_msg(t, obs.robot, velocity, r.odom_frame, r.base_frame, tb))
        self._tf(convert.tf_msg(t, obs.robot, r.odom_frame, r.base_frame, tb))
        if self._scan is not None and obs.scan is not None and obs.scan is not self._last_scan:
            self._last_scan = obs.scan
            period = 1.0 / self.params.sensing.lidar_rate_hz
            self._scan(convert.scan_msg(t, obs.scan, r.lidar_frame, period, tb))
        if obs.detections:
            frames = {self.params.tracker.world_frame: r.odom_frame,
                      self.params.tracker.robot_frame: r.base_frame}
            people = [replace(d, frame=frames.get(d.frame, d.frame)) for d in obs.detections]
            if self.person_type == "pose_array":
                for frame in dict.fromkeys(p.frame for p in people):
                    group = [p for p in people if p.frame == frame]
                    self._person(convert.person_msg(group, "pose_array", group[-1].t, frame,
                                                    tb))
            else:
                for p in people:
                    self._person(convert.person_msg([p], self.person_type, p.t, p.frame, tb))
        if self._clock is not None:        # last: a node on /clock ticks with the sample in
            self._clock(convert.clock_msg(t, tb))
        if self.after is not None:
            self.after(obs.t)
        with self._lock:
            if self.lockstep_s > 0.0:      # period k's answer is command k + 1 (so a late
                due = round(obs.t / self.params.dt) + 1     # answer is not the next one's)
                self._lock.wait_for(lambda: self.commands >= due or self.pacer.stop.is_set(),
                                    self.lockstep_s)
            received, self._received = self._received, None
            (status, reason), estimate = self._status, self._estimate
        self.report = StepReport(status, reason, estimate=estimate)
        return None if received is None else Command(*received, 0.0, status)


def measured_type(params: Params) -> str:
    """The person message that carries what the sensing profile measures (``ros.person_type``
    auto): Odometry with a speed and turn rate, PoseStamped with a heading, else
    PointStamped; a message that carries less drops what the sensor knows."""
    s = params.sensing
    if s.person_velocity_noise is not None:
        return "odometry"
    return "pose" if s.person_heading_noise_rad is not None else "point"


def run_sim_robot(spec: EpisodeSpec, transport: Transport, ros: RosParams, pacer: Pacer,
                  epoch_ns: int | None = SIM_EPOCH_NS,
                  after: Callable[[float], None] | None = None,
                  wait_s: float = 0.0, lockstep_s: float = 0.0) -> tuple[Log, WireRobot]:
    """Run ``spec`` with its controller on the wire, after waiting up to ``wait_s`` s for a
    node's first command; the robot senses with a LiDAR (a ROS robot publishes /scan) and
    starts as ``companion run`` starts it (in the slot at the walking speed unless the
    scenario says otherwise). Returns the log and the robot (its count of commands received
    during the run)."""
    robot = WireRobot(transport, ros, spec.params, pacer, epoch_ns, after, lockstep_s)
    if wait_s > 0.0:
        robot.wait_for_node(wait_s)
    sim = Simulator(spec.person, spec.params, spec.duration, spec.start, spec.obstacles,
                    LidarPerception(spec.params), spec.faults, spec.start_velocity)
    return Log.concat(drive(sim, robot.step, spec.seed, report=lambda: robot.report)), robot
