"""``companion node``: the standard stack (tracker, controller, avoidance, supervisor) as a
ROS 2 node on any :class:`~companion.ros.transport.Transport`.

Messages are stored as they arrive (any thread); :meth:`CompanionNode.tick`, called every
period ``dt`` on the node's clock (the system clock, or /clock with ``use_sim_time``), turns
what arrived into one :class:`~companion.types.Observation` and publishes the command, the
status and the markers. Header stamps, not arrival times, place every input in time, and the
transform tree places it in space (:mod:`companion.ros.placement`); odometry older than
``ros.odom_timeout_s`` or no scan for ``ros.scan_timeout_s`` stops the robot (reasons
``odometry_stale``, ``scan_stale``) until fresh data return. Like every ROS 2 node it serves
its parameters (:mod:`companion.ros.parameters`), logs to /rosout, and names what it sees
wrong on the graph: a publisher on an input of a type or QoS it cannot take
(:mod:`companion.ros.graph`). Times inside the node are seconds since its
:class:`~companion.ros.convert.TimeBase`'s origin. docs/ros2.md.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, NamedTuple

from companion.control import make_controller, retune
from companion.control.avoidance import influence_range
from companion.control.slot import slot_point
from companion.geometry import unicycle_step, wrap_pi
from companion.model import relative_state
from companion.ros import convert, graph
from companion.ros.convert import OdometrySample, TimeBase, person_types
from companion.ros.parameters import ParameterServer
from companion.ros.placement import WAIT, Placer, flat
from companion.ros.rosout import RosoutHandler, logger_name
from companion.ros.settings import NodeConfig
from companion.ros.tf import TransformBuffer, from_message
from companion.ros.transport import DEFAULT, PARAMETER_EVENTS, ROSOUT, Qos, Transport
from companion.ros.watch import Watch
from companion.types import (
    Circle,
    Command,
    Observation,
    PersonDetection,
    PersonEstimate,
    Pose,
    Scan,
    StepReport,
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


def with_reasons(report: StepReport, reasons: list[str]) -> StepReport:
    """``report`` with the node's own ``reasons`` added (degraded if it was ok)."""
    return report._replace(
        status="degraded" if report.status == "ok" else report.status,
        reason="+".join([report.reason] * bool(report.reason) + reasons),
        stages=(*report.stages, *(("node", r) for r in reasons)))


class CompanionNode:
    """The node's state and its one step; see the module docstring. ``clock()`` is the
    system clock (s since 1970); ``time_base`` the origin of the node's seconds (default: the
    clock's whole second at start, or with ``use_sim_time`` the first stamp received)."""

    def __init__(self, config: NodeConfig, transport: Transport,
                 clock: Callable[[], float] = time.time, time_base: TimeBase | None = None):
        self.config, self.transport = config, transport
        r = config.ros
        self.stack = make_controller(config.controller, config.params)
        self._system_clock = clock
        if time_base is None and not r.use_sim_time:
            time_base = TimeBase(int(clock()) * 1_000_000_000)
        self.time = time_base
        self._lock = threading.Condition()
        self._step_lock = threading.Lock()                   # the stack: a tick or a retune
        self._odom: deque[OdometrySample] = deque()
        self._scans: list[tuple[float, float, Any]] = []     # (stamp, arrival, LaserScan)
        self._scan_t = -math.inf                             # stamp of the last scan placed
        self._scan_seen: Scan | None = None                  # the last scan placed
        self._people: list[tuple[PersonDetection, float]] = []       # (detection, arrival)
        self._sim_time: float | None = None
        self.last: Command | None = None
        self.report = StepReport()                           # the last tick's step report
        self.view: View | None = None
        self.tf = TransformBuffer() if r.use_tf else None
        self.placer = Placer(r, self.tf)
        self._announced = False                              # the parameters, at the 1st tick
        self.name = "/".join([r.namespace.rstrip("/"), r.node_name])
        self.log = logging.getLogger(f"companion.node.{logger_name(r.node_name, r.namespace)}")
        self.log.setLevel(logging.INFO)                      # as a ROS 2 node logs by default
        self.watch = Watch(self.log)                         # what the node logs of itself
        self._subscribe()
        self._advertise()

    # -- wiring --------------------------------------------------------------------------

    def _subscribe(self) -> None:
        r, t, tr = self.config.ros, self.config.ros.topics, self.transport
        tr.subscribe(t.odom, "nav_msgs/msg/Odometry", self.on_odom, r.qos.odom.qos())
        if t.scan:
            tr.subscribe(t.scan, "sensor_msgs/msg/LaserScan", self.on_scan, r.qos.scan.qos())
        self._person_types: list[str] = []
        if r.person_type != "auto" or getattr(tr, "multi_type_topics", True):
            for msgtype in person_types(r.person_type):
                self._take_people(msgtype)
        if t.clock:                    # without use_sim_time: to say that it is ignored
            tr.subscribe(t.clock, "rosgraph_msgs/msg/Clock", self.on_clock,
                         Qos(reliable=False, depth=1))
        if self.tf is not None and t.tf:
            tr.subscribe(t.tf, "tf2_msgs/msg/TFMessage", lambda m: self.on_tf(m, False),
                         Qos(reliable=False, depth=100))
        if self.tf is not None and t.tf_static:
            tr.subscribe(t.tf_static, "tf2_msgs/msg/TFMessage", lambda m: self.on_tf(m, True),
                         Qos(reliable=True, transient_local=True, depth=100))

    def _take_people(self, msgtype: str) -> None:
        """Subscribe to the person topic's ``msgtype``."""
        r, kind = self.config.ros, convert.person_kind(msgtype)
        self.transport.subscribe(r.topics.person, msgtype,
                                 lambda msg: self.on_person(msg, kind), r.qos.person.qos())
        self._person_types.append(msgtype)

    def _find_people(self) -> None:
        """``ros.person_type: auto`` on a transport whose topic takes one type (rclpy over
        Fast DDS): the type of the first publisher of a person type the graph shows."""
        topic = self.config.ros.topics.person
        found = [e.msgtype for e in self.transport.publishers(topic)
                 if e.msgtype in convert.PERSON_TYPES.values()]
        if found:
            self._take_people(found[0])
            self.log.info("%s: taking %s, the type its publisher sends (ros.person_type "
                          "auto)", topic, found[0])

    def _advertise(self) -> None:
        r, t, tr = self.config.ros, self.config.ros.topics, self.transport
        cmd_type = "geometry_msgs/msg/TwistStamped" if r.cmd_vel_stamped \
            else "geometry_msgs/msg/Twist"
        self._cmd = tr.publisher(t.cmd_vel, cmd_type, DEFAULT)
        self._status = tr.publisher(t.status, "diagnostic_msgs/msg/DiagnosticArray", DEFAULT)
        self._markers = tr.publisher(t.markers, "visualization_msgs/msg/MarkerArray",
                                     DEFAULT) if t.markers else None
        self._rosout = RosoutHandler(tr.typestore, tr.publisher(
            "/rosout", "rcl_interfaces/msg/Log", ROSOUT), logger_name(r.node_name, r.namespace),
            lambda: self.stamp(self.now() or 0.0))
        self.log.addHandler(self._rosout)
        events = tr.publisher("/parameter_events", "rcl_interfaces/msg/ParameterEvent",
                              PARAMETER_EVENTS)
        self.parameters = ParameterServer(self.name, self.config, tr.typestore, self._retune,
                                          events, lambda: self.stamp(self.now() or 0.0))
        for service, (srvtype, handler) in self.parameters.handlers().items():
            tr.serve(f"{self.name}/{service}", srvtype, handler)

    def close(self) -> None:
        """Stop logging to /rosout (the transport is closed by its owner)."""
        self.log.removeHandler(self._rosout)

    def _retune(self, config: NodeConfig) -> None:
        """A parameter changed while running: the stack runs on with the new parameters."""
        with self._step_lock:
            retune(self.stack, config.controller, config.params)
            self.config = dataclasses.replace(self.config, params=config.params)
        self.log.info("parameters changed: formation %.3f m at %.3f rad, v_max %.3g m/s",
                      config.params.formation.distance, config.params.formation.bearing,
                      config.params.robot.v_max)

    # -- inputs (any thread) -------------------------------------------------------------

    def _base(self, stamp: Any) -> TimeBase:
        """The node's time base, fixed by the first stamp it sees if not yet known."""
        if self.time is None:
            with self._lock:
                if self.time is None:
                    self.time = TimeBase.at(convert.stamp_ns(stamp))
        return self.time

    def on_odom(self, msg: Any) -> None:
        sample = self.placer.odometry(convert.odometry_sample(msg, self._base(msg.header.stamp)),
                                      msg.header.frame_id, msg.child_frame_id)
        if isinstance(sample, str):
            self._cannot_place("odom", sample)
            return
        with self._lock:
            if self._odom and sample.t <= self._odom[-1].t:
                self._odom.clear()        # time went back (a restarted bag or robot): restart
            self._odom.append(sample)
            while self._odom[0].t < sample.t - self.config.ros.odometry_buffer_s:
                self._odom.popleft()

    def on_scan(self, msg: Any) -> None:
        t = self._base(msg.header.stamp).seconds(msg.header.stamp)
        with self._lock:
            self._scans = [(t, self._arrival(), msg)]

    def on_person(self, msg: Any, kind: str) -> None:
        people = convert.people_from(msg, kind, self._base(msg.header.stamp))
        with self._lock:
            self._people.extend((p, self._arrival()) for p in people)

    def on_clock(self, msg: Any) -> None:
        if not self.config.ros.use_sim_time:      # a simulator's stamps will all look stale
            self.watch.placing["clock"] = (f"{self.config.ros.topics.clock}: a clock is "
                                           "published, but the node keeps the system clock "
                                           "(ros.use_sim_time is false: --use-sim-time)")
            return
        t = self._base(msg.clock).seconds(msg.clock)
        with self._lock:
            self._sim_time = t
            self._lock.notify_all()

    def on_tf(self, msg: Any, static: bool) -> None:
        for ts in msg.transforms:
            t = 0.0 if static else self._base(ts.header.stamp).seconds(ts.header.stamp)
            self.tf.add(ts.header.frame_id, ts.child_frame_id, t,
                        from_message(ts.transform), static)

    def _arrival(self) -> float:
        now = self.now()
        return math.inf if now is None else now

    # -- the step ------------------------------------------------------------------------

    def now(self) -> float | None:
        """The node's time (s since its origin): /clock with ``use_sim_time`` (None before
        the first), else the system clock."""
        if self.config.ros.use_sim_time:
            return self._sim_time
        return self._system_clock() - self.time.origin_ns * 1e-9

    def stamp(self, t: float) -> Any:
        """``builtin_interfaces/Time`` of the node's time ``t``."""
        return (self.time or convert.ABSOLUTE).stamp(t)

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
            scans, self._scans = self._scans, []
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
        detections = self._place_people(people, samples, now)
        for scan in scans:
            self._place_scan(*scan, samples, now)
        if r.topics.scan and now - self._scan_t > r.scan_timeout_s:
            stale.append("scan")
        obs = Observation(now, robot, None, (), self._scan_seen, velocity,
                          tuple(detections), tuple(stale), None if odom is None else odom.t)
        with self._step_lock:
            cmd = self.stack.step(obs)
            report = self.stack.report
        if future:
            report = with_reasons(report, future)
            cmd = dataclasses.replace(cmd, status=report.status)
        self.last, self.report = cmd, report
        self._publish(now, robot, cmd, report)
        if self.view is not None and self.last is cmd and not self._announced:
            self._announced = True
            self.parameters.announce()
        self.watch.status(now, report)
        self.watch.problems(now, self._graph_problems)
        return cmd

    def stop(self, now: float) -> None:
        """Publish a zero velocity (the node's last word)."""
        r = self.config.ros
        self._cmd(convert.twist_msg(0.0, 0.0, r.cmd_vel_stamped, now, r.base_frame,
                                    self.time or convert.ABSOLUTE))

    # -- the pieces ----------------------------------------------------------------------

    def _drop_future(self, now: float) -> list[str]:
        """Drop odometry and the scan stamped later than ``now`` plus the tracker's
        ``future_tolerance_s`` (a clock ahead, a corrupt stamp); the reasons. Under the lock."""
        ahead, reasons = now + self.config.params.tracker.future_tolerance_s, []
        if self._odom and self._odom[-1].t > ahead:
            reasons.append("odometry_future")
            while self._odom and self._odom[-1].t > ahead:
                self._odom.pop()
        if any(t > ahead for t, _, _ in self._scans):
            reasons.append("scan_future")
            self._scans = [s for s in self._scans if s[0] <= ahead]
        return reasons

    def _place_people(self, people: list[tuple[PersonDetection, float]],
                      samples: deque[OdometrySample], now: float) -> list:
        """The detections placed in the odometry frame; those waiting for their transform
        go back for the next period, at most ``ros.tf_wait_s`` after they arrived."""
        world, wait = self.config.params.tracker.world_frame, self.config.ros.tf_wait_s
        out, waiting = [], []
        for s, arrived in people:
            d = self.placer.detection(s, samples, world)
            if d == WAIT:
                if now - min(arrived, now) < wait:
                    waiting.append((s, arrived))
                    continue
                d = PersonDetection(s.t, s.x, s.y, s.frame or "(no frame)")
            if d.frame != world and samples:      # the tracker rejects it: detection_frame
                self._cannot_place("person", f"detections in frame {s.frame or '(none)'}")
            out.append(d)
        if waiting:
            with self._lock:
                self._people[:0] = waiting
        return out

    def _place_scan(self, t: float, arrived: float, msg: Any,
                    samples: deque[OdometrySample], now: float) -> None:
        """A new scan placed at its stamp, for the stack's perception front end."""
        where = self.placer.frame(msg.header.frame_id, t, samples)
        if where == WAIT and now - min(arrived, now) < self.config.ros.tf_wait_s:
            with self._lock:
                self._scans = self._scans or [(t, arrived, msg)]
            return
        if where is None or where == WAIT:
            if samples:
                self._cannot_place("scan", f"scans in frame {msg.header.frame_id or '(none)'}")
            return
        self._scan_t = t
        self._scan_seen = convert.scan_from(msg, flat(where), t)

    def _cannot_place(self, key: str, frame: str) -> None:
        """Remember (until the next look at the graph) that inputs of ``key`` in ``frame``
        could not be placed; a line naming the topic, the frame and what would place them."""
        r = self.config.ros
        line = (f"{frame} cannot be placed: no transform from it to {r.base_frame} or "
                f"{r.odom_frame} on {r.topics.tf} or {r.topics.tf_static}") \
            if key != "odom" else frame
        if key == "scan":
            line += " (or set ros.lidar_frame and ros.lidar_mount)"
        self.watch.placing[key] = f"{getattr(r.topics, key)}: {line}"

    def _publish(self, now: float, robot: Pose, cmd: Command, report: StepReport) -> None:
        p, r = self.config.params, self.config.ros
        tb = self.time or convert.ABSOLUTE
        self._cmd(convert.twist_msg(cmd.v, cmd.omega, r.cmd_vel_stamped, now, r.base_frame, tb))
        errors = slot = None
        e = report.estimate
        if e is not None and math.isfinite(robot.x):
            w = e.walker
            errors = relative_state(robot.x, robot.y, robot.theta, w.x, w.y, w.theta,
                                    p.robot.d)
            slot = slot_point(w, p)
        meter = self.stack.delays
        self._status(convert.status_msg(now, cmd, report, errors, r.node_name, tb,
                                        self.watch.warnings, (meter.latency, meter.tau)))
        reach = tuple((ob, influence_range(ob, p.avoidance)) for ob in report.obstacles
                      if isinstance(ob, Circle))
        self.view = View(now, robot, e, slot, reach)
        if self._markers is not None:
            self._markers(convert.markers_msg(now, r.odom_frame, e, slot, reach, tb))

    def _graph_problems(self) -> list[str]:
        try:
            if not self._person_types:
                self._find_people()
            return graph.input_problems(self.config.ros, self.transport.publishers)
        except Exception as exc:    # discovery must not stop the node
            self.log.debug("the graph could not be read: %s", exc)
            return []

    @property
    def warnings(self) -> list[str]:
        """The active problems with the node's inputs, one line each."""
        return self.watch.warnings
