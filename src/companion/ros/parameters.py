"""The node's parameters as ROS 2 parameters: rcl_interfaces' six services and
/parameter_events, so that ``ros2 param`` (rclpy's parameter client) lists, reads, describes
and sets them. docs/ros2.md, "Parameters while running".

Names are the parameter file's dotted keys (``formation.bearing``, ``lqr.q``,
``ros.topics.odom``), values as the file holds them (SI units; a bearing in rad, also settable
as ``left``, ``right``, ``behind`` or ``front``). The parameters of :data:`RUNTIME` can change
while the node runs; every other one is read-only and its descriptor says so. A change is
checked by reading the whole configuration again with it (:func:`config_from_mapping`, the
parameter file's own checks): a bad value is refused with that one-line reason and nothing
changes. Requests and responses are typestore messages; any transport serves them.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from companion.config import field_docs
from companion.errors import CompanionError
from companion.params import Params
from companion.ros.messages import message
from companion.ros.settings import NodeConfig, RosParams, config_from_mapping

#: Parameters that can change while the node runs: the formation, the speed limits and the
#: controllers' gains. The rest (sample period, tracker, topics, ...) need a restart.
RUNTIME = frozenset({
    "formation.distance", "formation.bearing", "robot.v_max", "robot.omega_max",
    "lqr.q", "lqr.r", "pid.kp_x", "pid.ki_x", "pid.kd_x", "pid.kp_y", "pid.ki_y", "pid.kd_y",
    "pid.kp_theta", "vsm.stiffness", "vsm.damping", "vsm.mass", "impedance.mass",
    "impedance.damping", "impedance.stiffness"})

# rcl_interfaces/msg/ParameterType
NOT_SET, BOOL, INTEGER, DOUBLE, STRING = 0, 1, 2, 3, 4
BOOL_ARRAY, INTEGER_ARRAY, DOUBLE_ARRAY, STRING_ARRAY = 6, 7, 8, 9
TYPE_NAMES = {NOT_SET: "not set", BOOL: "bool", INTEGER: "integer", DOUBLE: "double",
              STRING: "string", 5: "byte array", BOOL_ARRAY: "bool array",
              INTEGER_ARRAY: "integer array", DOUBLE_ARRAY: "double array",
              STRING_ARRAY: "string array"}
_FIELDS = {BOOL: "bool_value", INTEGER: "integer_value", DOUBLE: "double_value",
           STRING: "string_value", BOOL_ARRAY: "bool_array_value",
           INTEGER_ARRAY: "integer_array_value", DOUBLE_ARRAY: "double_array_value",
           STRING_ARRAY: "string_array_value"}
#: Types a value may be given as besides its own (an integer for a double, a side's name for a
#: bearing), as the parameter file accepts them.
_ALSO = {DOUBLE: (INTEGER,), DOUBLE_ARRAY: (INTEGER_ARRAY,)}


def config_mapping(config: NodeConfig) -> dict[str, Any]:
    """``config`` as a ``ros__parameters`` mapping (:func:`config_from_mapping` reads it
    back equal); stored in the bags companion records."""
    return {**dataclasses.asdict(config.params), "ros": dataclasses.asdict(config.ros),
            "controller": config.controller}


def flatten(mapping: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested tables as dotted names, in the mapping's order."""
    out: dict[str, Any] = {}
    for key, value in mapping.items():
        if isinstance(value, Mapping):
            out.update(flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = list(value) if isinstance(value, tuple) else value
    return out


def parameter_values(config: NodeConfig) -> dict[str, Any]:
    """The node's parameters by name: every key of the parameter file, and ``use_sim_time``,
    the parameter every ROS 2 node has (``ros.use_sim_time`` here)."""
    values = flatten(config_mapping(config))
    return {"use_sim_time": values["ros.use_sim_time"], **values}


def type_of(value: Any) -> int:
    """The ParameterType of a value of the configuration."""
    if value is None:
        return NOT_SET
    if isinstance(value, list):
        kinds = {type_of(v) for v in value} or {DOUBLE}
        kind = DOUBLE if kinds <= {DOUBLE, INTEGER} and DOUBLE in kinds else kinds.pop()
        return {BOOL: BOOL_ARRAY, INTEGER: INTEGER_ARRAY, DOUBLE: DOUBLE_ARRAY,
                STRING: STRING_ARRAY}[kind]
    return {bool: BOOL, int: INTEGER, float: DOUBLE, str: STRING}[type(value)]


def to_msg(store: Any, value: Any, kind: int | None = None) -> Any:
    """A rcl_interfaces/ParameterValue of ``value`` (of ParameterType ``kind``)."""
    kind = type_of(value) if kind is None else kind
    fields: dict[str, Any] = {"type": kind}
    if kind != NOT_SET:
        if kind == DOUBLE_ARRAY:
            value = [float(v) for v in value]
        elif kind == DOUBLE:
            value = float(value)
        fields[_FIELDS[kind]] = value
    msg = message(store, "rcl_interfaces/msg/ParameterValue")
    for name, v in fields.items():
        field = getattr(msg, name)
        setattr(msg, name, np.asarray(v, dtype=field.dtype) if hasattr(field, "dtype") else v)
    return msg


def from_msg(value: Any) -> tuple[int, Any]:
    """The ParameterType and Python value of a rcl_interfaces/ParameterValue."""
    kind = int(value.type)
    if kind not in _FIELDS:
        return kind, None
    raw = getattr(value, _FIELDS[kind])
    if kind in (BOOL, INTEGER, DOUBLE, STRING):
        return kind, {BOOL: bool, INTEGER: int, DOUBLE: float, STRING: str}[kind](raw)
    return kind, [v if isinstance(v, str) else v.item() for v in raw]


def _docs() -> dict[str, tuple[str, str, str]]:
    """(unit, meaning, range) of every documented key."""
    rows = field_docs(Params) + field_docs(RosParams, "ros.")
    docs = {key: (unit, meaning, allowed) for key, unit, _, meaning, allowed in rows}
    docs["use_sim_time"] = docs["ros.use_sim_time"]
    return docs


class ParameterServer:
    """The parameters of a running node: ``apply(config)`` installs a changed configuration
    (called under this server's lock), ``publish_event(msg)`` sends /parameter_events,
    ``stamp()`` gives the time of an event."""

    def __init__(self, node: str, config: NodeConfig, store: Any,
                 apply: Callable[[NodeConfig], None],
                 publish_event: Callable[[Any], None] | None = None,
                 stamp: Callable[[], Any] | None = None):
        self.node, self.config, self.store = node, config, store
        self.apply, self.publish_event, self.stamp = apply, publish_event, stamp
        self._lock = threading.Lock()
        self.values = parameter_values(config)
        self.types = {name: type_of(v) for name, v in self.values.items()}
        docs = _docs()
        self.descriptors = {name: self._descriptor(name, docs.get(name)) for name in self.values}

    def announce(self) -> None:
        """Publish every parameter as new on /parameter_events (as a node does when it
        declares them; the node calls this once its clock runs)."""
        self._event(new=list(self.values))

    def handlers(self) -> dict[str, tuple[str, Callable[[Any], Any]]]:
        """Service name (relative to the node) -> (service type, handler)."""
        srv = "rcl_interfaces/srv/"
        return {"list_parameters": (srv + "ListParameters", self.list_parameters),
                "get_parameters": (srv + "GetParameters", self.get_parameters),
                "set_parameters": (srv + "SetParameters", self.set_parameters),
                "set_parameters_atomically": (srv + "SetParametersAtomically",
                                              self.set_parameters_atomically),
                "describe_parameters": (srv + "DescribeParameters", self.describe_parameters),
                "get_parameter_types": (srv + "GetParameterTypes", self.get_parameter_types)}

    # -- the services ------------------------------------------------------------------

    def list_parameters(self, req: Any) -> Any:
        """rclpy's rules: every name under one of ``prefixes`` (all without prefixes) at most
        ``depth`` levels down (0: any depth), and the prefixes of the names returned."""
        depth, prefixes = int(req.depth), list(req.prefixes)

        def shallow(name: str) -> bool:
            return depth == 0 or name.count(".") < depth

        names = [n for n in self.values if (not prefixes and shallow(n)) or any(
            n == p or (n.startswith(p + ".") and shallow(n[len(p) + 1:])) for p in prefixes)]
        found = list(dict.fromkeys(n.rsplit(".", 1)[0] for n in names if "." in n))
        result = message(self.store, "rcl_interfaces/msg/ListParametersResult", names=names,
                         prefixes=found)
        return self._response("ListParameters", result=result)

    def get_parameters(self, req: Any) -> Any:
        with self._lock:
            values = [to_msg(self.store, self.values[n], self.types[n]) if n in self.values
                      else to_msg(self.store, None) for n in req.names]
        return self._response("GetParameters", values=values)

    def get_parameter_types(self, req: Any) -> Any:
        types = np.array([self.types.get(n, NOT_SET) for n in req.names], dtype=np.uint8)
        return self._response("GetParameterTypes", types=types)

    def describe_parameters(self, req: Any) -> Any:
        unknown = message(self.store, "rcl_interfaces/msg/ParameterDescriptor")
        return self._response("DescribeParameters", descriptors=[
            self.descriptors.get(n, unknown) for n in req.names])

    def set_parameters(self, req: Any) -> Any:
        """Each parameter on its own, in order: a refused one changes nothing, the others
        still apply."""
        results = [self._set([p]) for p in req.parameters]
        return self._response("SetParameters", results=results)

    def set_parameters_atomically(self, req: Any) -> Any:
        return self._response("SetParametersAtomically", result=self._set(list(req.parameters)))

    # -- the pieces --------------------------------------------------------------------

    def _set(self, parameters: list[Any]) -> Any:
        """Check ``parameters`` together and apply them all, or none with the reason."""
        with self._lock:
            changes: dict[str, Any] = {}
            for p in parameters:
                problem = self._check(p.name, p.value)
                if problem:
                    return self._result(False, problem)
                changes[p.name] = from_msg(p.value)[1]
            mapping = config_mapping(self.config)
            for name, value in changes.items():
                *path, leaf = name.split(".")
                table = mapping
                for part in path:
                    table = table[part]
                table[leaf] = value
            try:
                config = config_from_mapping(mapping)
            except CompanionError as exc:
                return self._result(False, str(exc))
            self.apply(config)
            self.config = config
            self.values = parameter_values(config)
            self._event(changed=list(changes))
        return self._result(True, "")

    def _check(self, name: str, value: Any) -> str | None:
        """Why ``name`` cannot take ``value`` (before the configuration's own checks)."""
        if name not in self.values:
            return f"{name}: no such parameter of {self.node}"
        if name not in RUNTIME:
            return (f"{name}: read-only while the node runs; set it in the parameter file "
                    f"and start the node again")
        kind, want = int(value.type), self.types[name]
        sides = name == "formation.bearing" and kind == STRING
        if kind != want and kind not in _ALSO.get(want, ()) and not sides:
            return (f"{name}: expected a {TYPE_NAMES[want]}"
                    f"{' or a side' if name == 'formation.bearing' else ''}, "
                    f"got a {TYPE_NAMES.get(kind, kind)}")
        _, python = from_msg(value)
        if kind in (DOUBLE, DOUBLE_ARRAY) and not all(
                math.isfinite(v) for v in (python if isinstance(python, list) else [python])):
            return f"{name}: expected a finite number, got {python!r}"
        return None

    def _descriptor(self, name: str, doc: tuple[str, str, str] | None) -> Any:
        unit, meaning, allowed = doc or ("", "", "")
        text = f"{meaning} ({unit})" if unit and unit != "-" else meaning
        return message(self.store, "rcl_interfaces/msg/ParameterDescriptor", name=name,
                       type=self.types[name], description=text,
                       additional_constraints=f"allowed: {allowed}" if allowed else "",
                       read_only=name not in RUNTIME,
                       dynamic_typing=name == "formation.bearing")

    def _result(self, ok: bool, reason: str) -> Any:
        return message(self.store, "rcl_interfaces/msg/SetParametersResult", successful=ok,
                       reason=reason)

    def _response(self, srv: str, **fields: Any) -> Any:
        return message(self.store, f"rcl_interfaces/srv/{srv}_Response", **fields)

    def _event(self, new: list[str] = (), changed: list[str] = ()) -> None:
        if self.publish_event is None:
            return

        def params(names: list[str]) -> list[Any]:
            return [message(self.store, "rcl_interfaces/msg/Parameter", name=n,
                            value=to_msg(self.store, self.values[n], self.types[n]))
                    for n in names]
        fields = {"node": self.node, "new_parameters": params(list(new)),
                  "changed_parameters": params(list(changed))}
        if self.stamp is not None:
            fields["stamp"] = self.stamp()
        self.publish_event(message(self.store, "rcl_interfaces/msg/ParameterEvent", **fields))
