"""Between ROS 2 messages and companion's own types (SI units; ROS REP 103 frames).

Pure functions without a transport: a message in, companion data out, and back. Stamps are
seconds (float) on companion's side and ``builtin_interfaces/Time`` on the wire.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from companion.geometry import wrap_pi
from companion.perception.front_end import OdometrySample
from companion.ros.messages import make
from companion.types import (
    Circle,
    Command,
    PersonDetection,
    PersonEstimate,
    PersonState,
    Pose,
    Scan,
    StepReport,
)


class TimeBase(NamedTuple):
    """Stamps on the wire (``builtin_interfaces/Time``, whole nanoseconds) and companion's
    seconds since ``origin_ns``. Seconds near zero keep nanosecond precision, where a float
    of 1.8e9 s (the system clock) or of the simulated epoch resolves only a few 1e-7 s; the
    node and the simulated robot each count from their own origin, in whole seconds."""

    origin_ns: int = 0

    def seconds(self, stamp: Any) -> float:
        """A ``builtin_interfaces/Time`` in seconds since the origin."""
        return self.since(stamp.sec * 1_000_000_000 + stamp.nanosec)

    def since(self, ns: int) -> float:
        """A stamp in nanoseconds as seconds since the origin (whole seconds and the
        fraction apart, so that a large count keeps its nanoseconds as far as a float can)."""
        sec, nsec = divmod(ns - self.origin_ns, 1_000_000_000)
        return sec + nsec * 1e-9

    def ns(self, t: float) -> int:
        """Seconds since the origin as a stamp in nanoseconds (rounded)."""
        return int(self.origin_ns) + int(round(t * 1e9))

    def stamp(self, t: float) -> Any:
        """``builtin_interfaces/Time`` of ``t`` seconds since the origin (never 1e9 ns)."""
        ns = self.ns(t)
        return make("builtin_interfaces/msg/Time", sec=ns // 1_000_000_000,
                    nanosec=ns % 1_000_000_000)

    @classmethod
    def at(cls, ns: int) -> TimeBase:
        """The origin of a clock that reads ``ns``: its whole second."""
        return cls(ns - ns % 1_000_000_000)


#: Stamps as they are: seconds since 1970 (the recorder's log times, companion run's bags).
ABSOLUTE = TimeBase(0)


def time_msg(t: float, tb: TimeBase = ABSOLUTE) -> Any:
    """``builtin_interfaces/Time`` of ``t`` seconds since ``tb``'s origin."""
    return tb.stamp(t)


def seconds(stamp: Any, tb: TimeBase = ABSOLUTE) -> float:
    """A ``builtin_interfaces/Time`` in seconds since ``tb``'s origin."""
    return tb.seconds(stamp)


def stamp_ns(stamp: Any) -> int:
    """A ``builtin_interfaces/Time`` in nanoseconds since 1970."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def header(t: float, frame: str, tb: TimeBase = ABSOLUTE) -> Any:
    return make("std_msgs/msg/Header", stamp=tb.stamp(t), frame_id=frame)


def yaw(q: Any) -> float:
    """Heading (rad) of a quaternion: the rotation about z (REP 103)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def quaternion(theta: float) -> Any:
    return make("geometry_msgs/msg/Quaternion", z=math.sin(0.5 * theta),
                w=math.cos(0.5 * theta))


def point(x: float, y: float, z: float = 0.0) -> Any:
    return make("geometry_msgs/msg/Point", x=x, y=y, z=z)


def pose_msg(x: float, y: float, theta: float, z: float = 0.0) -> Any:
    return make("geometry_msgs/msg/Pose", position=point(x, y, z), orientation=quaternion(theta))


# -- inputs ------------------------------------------------------------------------------

def odometry_sample(msg: Any, tb: TimeBase = ABSOLUTE) -> OdometrySample:
    """The pose (odometry frame) and body velocity of a nav_msgs/Odometry."""
    p, tw = msg.pose.pose, msg.twist.twist
    return OdometrySample(tb.seconds(msg.header.stamp),
                          Pose(p.position.x, p.position.y, yaw(p.orientation)),
                          (tw.linear.x, tw.angular.z))


def scan_from(msg: Any, sensor: Pose, t: float = math.nan) -> Scan:
    """A sensor_msgs/LaserScan stamped ``t`` (s) taken from the sensor pose ``sensor``
    (world frame), as a :class:`Scan`; it is read by :func:`companion.perception.checked_scan`
    later."""
    ranges = np.asarray(msg.ranges, dtype=float)
    angles = msg.angle_min + msg.angle_increment * np.arange(ranges.size)
    return Scan(angles, ranges, sensor.x, sensor.y, sensor.theta, float(msg.range_min),
                float(msg.range_max), t)


PERSON_TYPES = {"point": "geometry_msgs/msg/PointStamped",
                "pose": "geometry_msgs/msg/PoseStamped",
                "pose_array": "geometry_msgs/msg/PoseArray",
                "odometry": "nav_msgs/msg/Odometry"}


def _std(variance: float) -> float:
    return math.sqrt(variance) if variance > 0.0 else 0.0


def person_types(kind: str) -> tuple[str, ...]:
    """The message types the person topic takes with ``ros.person_type`` ``kind``."""
    return tuple(PERSON_TYPES.values()) if kind == "auto" else (PERSON_TYPES[kind],)


def person_kind(msgtype: str) -> str:
    """The :data:`PERSON_TYPES` key of a person message type."""
    return next(kind for kind, name in PERSON_TYPES.items() if name == msgtype)


def people_from(msg: Any, kind: str, tb: TimeBase = ABSOLUTE) -> list[PersonDetection]:
    """Every person in a PointStamped, PoseStamped, PoseArray or Odometry (``kind`` as in
    :data:`PERSON_TYPES`), with the message's stamp and its header's frame (a ROS frame, which
    the node places in the tracker's frame: ros/placement.py) and ``z``. An Odometry (an upstream
    tracker, a tag with an IMU) also gives the covariance, heading, speed and turn rate
    (diagonal variances; 0 means exact; as in sensor_msgs/Imu, a first variance of -1 means
    "not measured": c[0] for the position, c[35] for the heading, the twist's c[0] for speed
    and turn rate)."""
    t, frame = tb.seconds(msg.header.stamp), msg.header.frame_id
    if kind == "odometry":
        p, c = msg.pose.pose, msg.pose.covariance
        tw, tc = msg.twist.twist, msg.twist.covariance
        heading = (yaw(p.orientation), _std(c[35])) if c[35] >= 0.0 else (None, None)
        moving = (tw.linear.x, tw.angular.z, (_std(tc[0]), _std(tc[35]))) if tc[0] >= 0.0 \
            else (None, None, None)
        cov = (float(c[0]), float(c[1]), float(c[6]), float(c[7])) if c[0] >= 0.0 else None
        return [PersonDetection(t, p.position.x, p.position.y, frame, cov, *heading, *moving,
                                z=p.position.z)]
    if kind == "point":
        return [PersonDetection(t, msg.point.x, msg.point.y, frame, z=msg.point.z)]
    if kind == "pose":
        p = msg.pose.position
        return [PersonDetection(t, p.x, p.y, frame, z=p.z)]
    return [PersonDetection(t, q.position.x, q.position.y, frame, z=q.position.z)
            for q in msg.poses]


def twist_velocity(msg: Any) -> tuple[float, float]:
    """``(v, omega)`` of a Twist or TwistStamped."""
    tw = getattr(msg, "twist", msg)
    return tw.linear.x, tw.angular.z


# -- outputs -----------------------------------------------------------------------------

def twist_msg(v: float, omega: float, stamped: bool = False, t: float = 0.0,
              frame: str = "base_link", tb: TimeBase = ABSOLUTE) -> Any:
    """geometry_msgs/Twist, or TwistStamped with ``t`` and ``frame``."""
    tw = make("geometry_msgs/msg/Twist", linear=make("geometry_msgs/msg/Vector3", x=v),
              angular=make("geometry_msgs/msg/Vector3", z=omega))
    return make("geometry_msgs/msg/TwistStamped", header=header(t, frame, tb), twist=tw) \
        if stamped else tw


def odometry_msg(t: float, pose: Pose, velocity: tuple[float, float], frame: str,
                 child: str, tb: TimeBase = ABSOLUTE) -> Any:
    twist = make("geometry_msgs/msg/Twist",
                 linear=make("geometry_msgs/msg/Vector3", x=velocity[0]),
                 angular=make("geometry_msgs/msg/Vector3", z=velocity[1]))
    return make("nav_msgs/msg/Odometry", header=header(t, frame, tb), child_frame_id=child,
                pose=make("geometry_msgs/msg/PoseWithCovariance",
                          pose=pose_msg(pose.x, pose.y, pose.theta)),
                twist=make("geometry_msgs/msg/TwistWithCovariance", twist=twist))


def tf_msg(t: float, pose: Pose, frame: str, child: str, tb: TimeBase = ABSOLUTE) -> Any:
    """tf2_msgs/TFMessage with one transform ``frame -> child`` at ``pose``."""
    transform = make("geometry_msgs/msg/Transform",
                     translation=make("geometry_msgs/msg/Vector3", x=pose.x, y=pose.y),
                     rotation=quaternion(pose.theta))
    return make("tf2_msgs/msg/TFMessage", transforms=[make(
        "geometry_msgs/msg/TransformStamped", header=header(t, frame, tb), child_frame_id=child,
        transform=transform)])


def scan_msg(t: float, scan: Scan, frame: str, period: float, tb: TimeBase = ABSOLUTE) -> Any:
    """sensor_msgs/LaserScan of a simulated :class:`Scan` (evenly spaced beams, in the
    sensor's own frame); ``inf`` stays "no return" and NaN an invalid beam."""
    angles = np.asarray(scan.angles, float)
    step = float(angles[1] - angles[0]) if angles.size > 1 else 0.0
    return make("sensor_msgs/msg/LaserScan", header=header(t, frame, tb),
                angle_min=float(angles[0]) if angles.size else 0.0,
                angle_max=float(angles[-1]) if angles.size else 0.0, angle_increment=step,
                scan_time=period, range_min=float(scan.range_min),
                range_max=float(min(scan.range_max, np.finfo(np.float32).max)),
                ranges=np.asarray(scan.ranges, dtype=np.float32))


def person_msg(people: Sequence[PersonDetection], kind: str, t: float, frame: str,
               tb: TimeBase = ABSOLUTE) -> Any:
    """The people as a PointStamped, PoseStamped or Odometry (the first) or a PoseArray
    (all)."""
    if kind == "odometry":
        return _person_odometry(people[0], tb)
    if kind == "pose_array":
        return make("geometry_msgs/msg/PoseArray", header=header(t, frame, tb),
                    poses=[pose_msg(p.x, p.y, 0.0, getattr(p, "z", 0.0)) for p in people])
    p = people[0]
    if kind == "point":
        return make("geometry_msgs/msg/PointStamped", header=header(p.t, p.frame, tb),
                    point=point(p.x, p.y, getattr(p, "z", 0.0)))
    return make("geometry_msgs/msg/PoseStamped", header=header(p.t, p.frame, tb),
                pose=pose_msg(p.x, p.y, 0.0, getattr(p, "z", 0.0)))


def _person_odometry(p: PersonDetection, tb: TimeBase) -> Any:
    """nav_msgs/Odometry of one person; what was not measured has a first variance of -1
    (:func:`people_from`)."""
    pose = make("geometry_msgs/msg/PoseWithCovariance", pose=pose_msg(p.x, p.y, p.heading or 0.0))
    pose.covariance[[0, 1, 6, 7]] = (-1.0, 0.0, 0.0, 0.0) if p.covariance is None \
        else p.covariance
    pose.covariance[35] = -1.0 if p.heading is None else (p.heading_std or 0.0) ** 2
    twist = make("geometry_msgs/msg/TwistWithCovariance", twist=twist_msg(p.speed or 0.0,
                                                                          p.turn_rate or 0.0))
    twist.covariance[[0, 35]] = (-1.0, -1.0) if p.speed is None or p.turn_rate is None \
        else np.square(p.velocity_std or (0.0, 0.0))
    return make("nav_msgs/msg/Odometry", header=header(p.t, p.frame, tb), pose=pose,
                twist=twist)


def clock_msg(t: float, tb: TimeBase = ABSOLUTE) -> Any:
    return make("rosgraph_msgs/msg/Clock", clock=tb.stamp(t))


LEVELS = {"ok": 0, "degraded": 1, "stopped": 2}   # DiagnosticStatus OK, WARN, ERROR


def status_msg(t: float, cmd: Command, report: StepReport,
               errors: tuple[float, float, float] | None,
               name: str = "companion", tb: TimeBase = ABSOLUTE,
               warnings: Sequence[str] = (),
               delays: tuple[float | None, float | None] = (None, None)) -> Any:
    """diagnostic_msgs/DiagnosticArray: the step's status (OK, WARN for degraded, ERROR for
    stopped) and reason (its :class:`StepReport`), the command, the relative state ``(rho,
    alpha, beta)`` to the person estimate and the estimate itself, the measured detection
    latency and actuator lag (``delays``, s; absent until measured), as key-value pairs (SI
    units); the node's active ``warnings`` (a problem on its inputs) as ``warning`` and the
    message."""
    values = {"status": report.status, "reason": report.reason, "v": cmd.v,
              "omega": cmd.omega}
    for key, value in zip(("latency_measured_s", "actuator_tau_measured_s"), delays):
        if value is not None:
            values[key] = value
    if errors is not None:
        values.update(zip(("rho", "alpha", "beta"), errors))
    e = report.estimate
    if e is not None:
        values.update(person_x=e.state.x, person_y=e.state.y, person_theta=e.state.theta,
                      person_v=e.state.v, person_omega=e.state.omega,
                      person_std=e.position_std, person_track=e.status)
    if warnings:
        values["warning"] = " | ".join(warnings)
    pairs = [make("diagnostic_msgs/msg/KeyValue", key=k,
                  value=v if isinstance(v, str) else repr(float(v))) for k, v in values.items()]
    message = " | ".join([report.reason or report.status, *warnings])
    status = make("diagnostic_msgs/msg/DiagnosticStatus", level=LEVELS[report.status],
                  name=name,
                  message=message, values=pairs)
    return make("diagnostic_msgs/msg/DiagnosticArray", header=header(t, "", tb),
                status=[status])


def status_of(msg: Any) -> tuple[str, str]:
    """``(status, reason)`` of a DiagnosticArray from :func:`status_msg` (a robot logging what
    the node said); another node's array gives its first status' level and message."""
    if not msg.status:
        return "ok", ""
    first = msg.status[0]
    values = {kv.key: kv.value for kv in first.values}
    names = {level: name for name, level in LEVELS.items()}
    status = values.get("status", names.get(int(first.level), "degraded"))
    reason = values.get("reason", "" if status == "ok" else first.message)
    return (status, reason) if status in LEVELS else ("degraded", reason)


def estimate_of(msg: Any) -> PersonEstimate | None:
    """The person estimate a :func:`status_msg` carries (its state; the covariance is not
    sent, so it is 0, and the formation's person is the state), or None without one."""
    if not msg.status:
        return None
    values = {kv.key: kv.value for kv in msg.status[0].values}
    keys = ("person_x", "person_y", "person_theta", "person_v", "person_omega", "person_std")
    try:
        x, y, theta, v, omega, std = (float(values[k]) for k in keys)
    except (KeyError, ValueError):
        return None
    state = PersonState(x, y, theta, v, omega)
    return PersonEstimate(state, std, np.zeros((5, 5)), 0.0,
                          values.get("person_track", "seen"), state)


_COLORS = {"person": (0.1, 0.4, 1.0, 0.9), "slot": (0.1, 0.8, 0.2, 0.8),
           "obstacle": (0.9, 0.2, 0.1, 0.9), "influence": (0.9, 0.6, 0.1, 0.25)}


def _marker(t: float, frame: str, ns: str, i: int, kind: int, x: float, y: float,
            theta: float, scale: tuple[float, float, float], color: str,
            tb: TimeBase = ABSOLUTE) -> Any:
    r, g, b, a = _COLORS[color]
    return make("visualization_msgs/msg/Marker", header=header(t, frame, tb), ns=ns, id=i,
                type=kind, action=0, pose=pose_msg(x, y, theta, 0.5 * scale[2]),
                scale=make("geometry_msgs/msg/Vector3", x=scale[0], y=scale[1], z=scale[2]),
                color=make("std_msgs/msg/ColorRGBA", r=r, g=g, b=b, a=a))


ARROW, CYLINDER, DELETEALL = 0, 3, 3   # Marker.type ARROW, CYLINDER; Marker.action DELETEALL


def markers_msg(t: float, frame: str, estimate: PersonEstimate | None,
                slot: tuple[float, float] | None,
                obstacles: Sequence[tuple[Circle, float]], tb: TimeBase = ABSOLUTE) -> Any:
    """visualization_msgs/MarkerArray for RViz: the person estimate (an arrow along its
    heading), the desired slot and the known round obstacles with their influence range
    (pairs of circle and range, m, measured from the surface as the avoidance does); a
    DELETEALL first, so obstacles that went away disappear."""
    clear = make("visualization_msgs/msg/Marker", header=header(t, frame, tb), action=DELETEALL)
    out = [clear]
    if estimate is not None:
        s = estimate.walker
        out.append(_marker(t, frame, "person", 0, ARROW, s.x, s.y, s.theta, (0.6, 0.15, 0.15),
                           "person", tb))
    if slot is not None:
        out.append(_marker(t, frame, "slot", 0, CYLINDER, *slot, 0.0, (0.3, 0.3, 0.05), "slot",
                           tb))
    for i, (ob, reach) in enumerate(obstacles):
        out.append(_marker(t, frame, "obstacles", i, CYLINDER, ob.x, ob.y, 0.0,
                           (2 * ob.radius, 2 * ob.radius, 0.5), "obstacle", tb))
        out.append(_marker(t, frame, "influence", i, CYLINDER, ob.x, ob.y, 0.0,
                           (2 * (ob.radius + reach),) * 2 + (0.02,), "influence", tb))
    return make("visualization_msgs/msg/MarkerArray", markers=out)


def compose(base: Pose, mount: Pose) -> Pose:
    """The pose of a frame mounted at ``mount`` (in ``base``'s frame) in the world."""
    c, s = math.cos(base.theta), math.sin(base.theta)
    return Pose(base.x + c * mount.x - s * mount.y, base.y + s * mount.x + c * mount.y,
                wrap_pi(base.theta + mount.theta))
