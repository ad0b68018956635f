"""The node's parameters: a standard ROS 2 parameters YAML, checked in one place.

A file holds ``<node name>: ros__parameters:`` (or ``/**:``) with the node's own settings
under ``ros`` (:class:`RosParams`: topics, frames, QoS, transport), the controller's name
under ``controller`` and every companion parameter under its section, as in a parameters TOML
(docs/parameters.md). Keys may be nested or dotted (``lqr.q: [...]``), as ROS 2 allows. Unknown
keys, wrong types and out-of-range values are one-line errors naming the file and the key.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from companion.config import (
    Validated,
    between,
    build,
    param,
    ranged,
    reading,
    reject_unknown,
)
from companion.control import lookup, make_controller
from companion.errors import CompanionError, ConfigError
from companion.params import Params, params_from_mapping
from companion.ros.convert import PERSON_TYPES
from companion.ros.messages import DISTROS
from companion.ros.transport import Qos


@ranged("a ROS node name")
def _node_name(name: str) -> str | None:
    ok = re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name) is not None
    return None if ok else "a ROS node name: letters, digits and _, not starting with a digit"


@ranged("an absolute ROS namespace")
def _namespace(name: str) -> str | None:
    ok = re.fullmatch(r"/([A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*)?", name) is not None
    return None if ok else "an absolute ROS namespace such as '/' or '/robot1'"


@ranged("a Zenoh endpoint")
def endpoint_problem(text: str) -> str | None:
    ok = re.fullmatch(r"(tcp|udp|tls|quic|ws|unixsock-stream)/\S+", text) is not None
    return None if ok else "a Zenoh endpoint such as 'tcp/127.0.0.1:7447'"


@ranged("an absolute ROS topic name or ''")
def _topic(name: str) -> str | None:
    ok = name == "" or (name.startswith("/") and " " not in name and not name.endswith("/"))
    return None if ok else "an absolute ROS topic name such as '/odom' (or '' for none)"


@ranged("[0, 232]")
def _domain(n: int) -> str | None:
    return None if 0 <= n <= 232 else "an integer in [0, 232]"


@ranged("[1, 1000]")
def _depth(n: int) -> str | None:
    return None if 1 <= n <= 1000 else "an integer in [1, 1000]"


@ranged("|x|, |y| <= 10 m, |yaw| <= 7 rad")
def _mount(m: tuple[float, float, float]) -> str | None:
    ok = abs(m[0]) <= 10 and abs(m[1]) <= 10 and abs(m[2]) <= 7
    return None if ok else "|x|, |y| <= 10 m and |yaw| <= 7 rad"


@dataclasses.dataclass(frozen=True)
class Topics(Validated):
    """Topic names; remap them here."""

    odom: str = param("/odom", "", "nav_msgs/Odometry in", _topic)
    scan: str = param("/scan", "", "sensor_msgs/LaserScan in ('' : no LiDAR)", _topic)
    person: str = param("/person", "", "person detections in (type: ros.person_type)", _topic)
    cmd_vel: str = param("/cmd_vel", "", "velocity command out", _topic)
    status: str = param("/companion/status", "", "diagnostic_msgs/DiagnosticArray out",
                        _topic)
    markers: str = param("/companion/markers", "", "visualization_msgs/MarkerArray out "
                         "('' : none)", _topic)
    clock: str = param("/clock", "", "rosgraph_msgs/Clock in, with use_sim_time", _topic)
    tf: str = param("/tf", "", "tf2_msgs/TFMessage in (with use_tf; '' : none)", _topic)
    tf_static: str = param("/tf_static", "", "tf2_msgs/TFMessage in, transient local (with "
                           "use_tf; '' : none)", _topic)


@dataclasses.dataclass(frozen=True)
class TopicQos(Validated):
    """The QoS of one input topic's subscription (ROS 2's names and meanings)."""

    reliability: str = param("best_effort", "", "'best_effort' takes reliable and best-effort "
                             "publishers; 'reliable' takes reliable ones only",
                             choices=("best_effort", "reliable"))
    durability: str = param("volatile", "", "'transient_local' takes transient-local "
                            "publishers only and gets their stored messages",
                            choices=("volatile", "transient_local"))
    depth: int = param(10, "", "history depth (keep last)", _depth)

    def qos(self) -> Qos:
        return Qos(self.reliability == "reliable", self.durability == "transient_local",
                   self.depth)


@dataclasses.dataclass(frozen=True)
class InputQos(Validated):
    """The QoS of each input's subscription; the defaults are ROS 2's conventions (sensor data
    for scans, and best effort for odometry and people, which accepts both kinds of
    publisher)."""

    odom: TopicQos = param(TopicQos(), "", "")
    scan: TopicQos = param(TopicQos(depth=5), "", "")
    person: TopicQos = param(TopicQos(), "", "")


@dataclasses.dataclass(frozen=True)
class RosParams(Validated):
    """How the node meets the ROS 2 graph (docs/ros2.md)."""

    node_name: str = param("companion", "", "the node's name", _node_name)
    namespace: str = param("/", "", "the node's namespace", _namespace)
    transport: str = param("dds", "", "wire protocol: DDS or Zenoh spoken by companion, or "
                           "rclpy (the robot's own ROS 2; docs/ros2.md)",
                           choices=("dds", "zenoh", "rclpy"))
    distro: str = param("jazzy", "", "ROS 2 distribution of the message types and type "
                        "hashes", choices=tuple(DISTROS))
    domain_id: int | None = param(None, "", "DDS domain; None: $ROS_DOMAIN_ID (0 if unset), "
                                 "as every ROS 2 node", _domain)
    zenoh_connect: str = param("tcp/127.0.0.1:7447", "", "Zenoh endpoint to connect to (the "
                               "zenohd router of rmw_zenoh)", endpoint_problem)
    use_sim_time: bool = param(False, "", "take time from /clock instead of the system clock")
    person_type: str = param("auto", "", "type of the person topic: PointStamped, PoseStamped, "
                             "PoseArray or Odometry; 'auto': any of them (docs/ros2.md)",
                             choices=("auto", *PERSON_TYPES))
    cmd_vel_stamped: bool = param(False, "", "publish TwistStamped instead of Twist")
    odom_frame: str = param("odom", "", "frame of the odometry pose and of world-frame "
                            "detections")
    base_frame: str = param("base_link", "", "the robot's frame")
    lidar_frame: str = param("laser", "", "the LiDAR's frame")
    lidar_mount: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), "m, m, rad", "LiDAR pose (x, y, yaw) in the robot's frame", _mount)
    odom_timeout_s: float = param(0.5, "s", "odometry older than this stops the robot",
                                  between(1e-3, 10.0, "s"))
    scan_timeout_s: float = param(0.5, "s", "no scan for longer than this stops the robot",
                                  between(1e-3, 10.0, "s"))
    qos: InputQos = param(InputQos(), "", "")
    use_tf: bool = param(True, "", "place detections, scans and odometry through /tf and "
                         "/tf_static (ros.lidar_mount stays the fallback)")
    tf_wait_s: float = param(0.1, "s", "how long an input waits for the transform at its stamp",
                             between(0.0, 2.0, "s"))
    odometry_buffer_s: float = param(2.0, "s", "how much odometry is kept to place late "
                                     "detections and scans",
                                     between(0.1, 60.0, "s"))
    topics: Topics = param(Topics(), "", "")


#: Keys of earlier versions of the ``ros`` section and what replaced them.
MOVED = {"scan_reliable": "ros.qos.scan.reliability",
         "history_depth": "ros.qos.<topic>.depth"}


@dataclasses.dataclass(frozen=True)
class NodeConfig:
    """Everything the node runs with."""

    params: Params
    ros: RosParams
    controller: str


def _nest(mapping: Mapping[str, Any], where: str) -> dict[str, Any]:
    """Dotted keys (``lqr.q``) become nested tables, as ROS 2 reads parameter files."""
    out: dict[str, Any] = {}
    for key, value in mapping.items():
        if not isinstance(key, str):
            raise ConfigError(f"{where}{key!r}: expected a parameter name")
        target = out
        parts = key.split(".")
        for part in parts[:-1]:
            target = target.setdefault(part, {})
            if not isinstance(target, dict):
                raise ConfigError(f"{where}{key}: conflicts with a value given for {part}")
        leaf = parts[-1]
        if isinstance(value, Mapping):
            value = _nest(value, f"{where}{key}.")
            if isinstance(target.get(leaf), dict):
                target[leaf].update(value)
                continue
        target[leaf] = value
    return out


def config_from_mapping(parameters: Mapping[str, Any], where: str = "") -> NodeConfig:
    """The node's configuration from a ``ros__parameters`` mapping; errors start with
    ``where``."""
    tree = _nest(parameters, where)
    if "use_sim_time" in tree:     # every ROS 2 node's own parameter: ros.use_sim_time here
        ros_tree = tree.setdefault("ros", {})
        if not isinstance(ros_tree, dict) or "use_sim_time" in ros_tree:
            raise ConfigError(f"{where}use_sim_time: given with ros.use_sim_time; give one")
        ros_tree["use_sim_time"] = tree.pop("use_sim_time")
    controller = tree.pop("controller", "lqr")
    try:
        lookup(str(controller))
    except ConfigError as exc:
        raise ConfigError(f"{where}{exc}") from None
    ros_tree = tree.pop("ros", {}) or {}
    for old, new in MOVED.items():
        if isinstance(ros_tree, Mapping) and old in ros_tree:
            raise ConfigError(f"{where}ros.{old}: replaced by {new} (docs/ros2.md)")
    ros = build(RosParams, ros_tree, prefix=f"{where}ros.")
    params = params_from_mapping(tree, prefix=where)
    try:                  # weights without a stabilising gain: an error now, naming the keys
        make_controller(controller, params)
    except CompanionError as exc:
        raise ConfigError(f"{where}{exc}") from None
    return NodeConfig(params, ros, controller)


def load_node_config(path: str | Path | None, node_name: str = "companion") -> NodeConfig:
    """Read a ROS 2 parameters YAML (None: every default). The parameters of ``node_name``
    (or of ``/**``) are used; errors name the file and key."""
    if path is None:
        return config_from_mapping({})
    import yaml

    with reading(path, "parameters YAML"):
        try:
            with open(path, encoding="utf-8") as fh:
                doc = yaml.safe_load(fh)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            line = f" line {mark.line + 1}:" if mark is not None else ""
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
            raise ConfigError(f"{path}:{line} invalid YAML: {problem}") from None
    if not isinstance(doc, Mapping):
        raise ConfigError(f"{path}: expected '{node_name}: ros__parameters: ...' at the top")
    names = [k for k in (node_name, f"/{node_name}", "/**") if k in doc]
    if not names:
        reject_unknown({next(iter(doc), ""): None}, [node_name, "/**"], f"{path}: ")
    section = doc[names[0]]
    if not isinstance(section, Mapping) or "ros__parameters" not in section:
        raise ConfigError(f"{path}: {names[0]}: expected a 'ros__parameters' table")
    reject_unknown(section, ["ros__parameters"], f"{path}: {names[0]}.")
    parameters = section["ros__parameters"] or {}
    if not isinstance(parameters, Mapping):
        raise ConfigError(f"{path}: {names[0]}.ros__parameters: expected a table")
    return config_from_mapping(parameters, f"{path}: ")
