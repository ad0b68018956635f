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


@dataclasses.dataclass(frozen=True)
class RosParams(Validated):
    """How the node meets the ROS 2 graph (docs/ros2.md)."""

    node_name: str = param("companion", "", "the node's name", _node_name)
    namespace: str = param("/", "", "the node's namespace", _namespace)
    transport: str = param("dds", "", "wire protocol", choices=("dds", "zenoh"))
    distro: str = param("jazzy", "", "ROS 2 distribution of the message types and type "
                        "hashes", choices=tuple(DISTROS))
    domain_id: int = param(0, "", "ROS_DOMAIN_ID", _domain)
    zenoh_connect: str = param("tcp/127.0.0.1:7447", "", "Zenoh endpoint to connect to (the "
                               "zenohd router of rmw_zenoh)", endpoint_problem)
    use_sim_time: bool = param(False, "", "take time from /clock instead of the system clock")
    person_type: str = param("point", "", "type of the person topic: PointStamped, PoseStamped, "
                             "PoseArray or Odometry (docs/ros2.md)", choices=tuple(PERSON_TYPES))
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
    scan_reliable: bool = param(False, "", "subscribe to the scan reliably (default: best "
                                "effort, as drivers publish it)")
    history_depth: int = param(10, "", "QoS history depth of reliable topics", _depth)
    odometry_buffer_s: float = param(2.0, "s", "how much odometry is kept to place late "
                                     "detections and scans",
                                     between(0.1, 60.0, "s"))
    topics: Topics = param(Topics(), "", "")


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
    controller = tree.pop("controller", "lqr")
    try:
        lookup(str(controller))
    except ConfigError as exc:
        raise ConfigError(f"{where}{exc}") from None
    ros = build(RosParams, tree.pop("ros", {}) or {}, prefix=f"{where}ros.")
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
