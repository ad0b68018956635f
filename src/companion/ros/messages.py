"""ROS 2 message types from one source: rosbags' typestore of a named distribution.

The typestore gives the message classes, their CDR serialisation and their type hashes
(RIHS01, sent by Jazzy and later); :func:`dds_type_name` gives the name DDS and rmw_zenoh use
on the wire. Conversions between messages and companion's own types live beside the node.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Nodetype

from companion.errors import ConfigError

#: ROS 2 distributions companion can speak, by their rosbags typestore.
DISTROS = {"humble": Stores.ROS2_HUMBLE, "jazzy": Stores.ROS2_JAZZY}
DEFAULT_DISTRO = "jazzy"


@cache
def typestore(distro: str = DEFAULT_DISTRO) -> Any:
    """The typestore of ``distro`` (one of :data:`DISTROS`), with the parameter services'
    request, response and event types added (:data:`SERVICES`; rosbags has messages only)."""
    if distro not in DISTROS:
        raise ConfigError(f"distro: unknown ROS 2 distribution {distro!r}; "
                          f"allowed: {', '.join(DISTROS)}")
    store = get_typestore(DISTROS[distro])
    store.register(service_types())
    return store


#: The services a ROS 2 node serves for its parameters (rcl_interfaces/srv, as in Jazzy's
#: .srv files): name -> (request fields, response fields).
SERVICES = {
    "rcl_interfaces/srv/ListParameters": ("string[] prefixes\nuint64 depth",
                                          "rcl_interfaces/ListParametersResult result"),
    "rcl_interfaces/srv/GetParameters": ("string[] names",
                                         "rcl_interfaces/ParameterValue[] values"),
    "rcl_interfaces/srv/SetParameters": ("rcl_interfaces/Parameter[] parameters",
                                         "rcl_interfaces/SetParametersResult[] results"),
    "rcl_interfaces/srv/SetParametersAtomically": ("rcl_interfaces/Parameter[] parameters",
                                                   "rcl_interfaces/SetParametersResult result"),
    "rcl_interfaces/srv/DescribeParameters": ("string[] names",
                                              "rcl_interfaces/ParameterDescriptor[] descriptors"),
    "rcl_interfaces/srv/GetParameterTypes": ("string[] names", "uint8[] types"),
}
_EVENT_INFO = "service_msgs/msg/ServiceEventInfo"


def service_types() -> dict[str, Any]:
    """rosbags field definitions of every service of :data:`SERVICES`: ``<srv>_Request``,
    ``<srv>_Response``, ``<srv>_Event`` and the service itself (its three messages), as rosidl
    generates them."""
    texts = {}
    for srv, (request, response) in SERVICES.items():
        texts.update({f"{srv}_Request": request, f"{srv}_Response": response,
                      f"{srv}_Event": (f"service_msgs/ServiceEventInfo info\n"
                                       f"{srv}_Request[<=1] request\n"
                                       f"{srv}_Response[<=1] response"),
                      srv: (f"{srv}_Request request_message\n{srv}_Response response_message\n"
                            f"{srv}_Event event_message")})
    types: dict[str, Any] = {}
    for name, text in texts.items():
        (parsed,) = get_types_from_msg(text, "companion/msg/Parsed").values()
        types[name] = _srv_names(parsed)
    return types


@cache
def service_type_hash(srv: str, distro: str = DEFAULT_DISTRO) -> str:
    """The RIHS01 hash of a service of :data:`SERVICES` as rosidl computes it (rmw_zenoh puts it
    in a service's key expression). rosidl reads ``char`` in a .msg as uint8 while rosbags
    hashes it as a char, so the hash is taken in a private typestore whose
    service_msgs/msg/ServiceEventInfo has its ``char[16] client_gid`` as ``uint8[16]``."""
    store = get_typestore(DISTROS[distro])
    consts, fields = store.fielddefs[_EVENT_INFO]
    store.fielddefs[_EVENT_INFO] = (consts, [
        (name, (Nodetype.ARRAY, ((Nodetype.BASE, ("uint8", 0)), desc[1][1]))) if name ==
        "client_gid" else (name, desc) for name, desc in fields])
    store.register(service_types())
    return store.hash_rihs01(srv)


def _srv_names(value: Any) -> Any:
    """rosbags reads ``pkg/srv/Name`` in a .msg as ``pkg/srv/msg/Name``: put it back."""
    if isinstance(value, str):
        return value.replace("/srv/msg/", "/srv/")
    if isinstance(value, (tuple, list)):
        return type(value)(_srv_names(v) for v in value)
    return value


def dds_type_name(msgtype: str) -> str:
    """``'geometry_msgs/msg/Twist'`` -> ``'geometry_msgs::msg::dds_::Twist_'`` (the DDS and
    rmw_zenoh wire name)."""
    package, kind, name = msgtype.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def ros_type_name(dds_type: str) -> str:
    """``'geometry_msgs::msg::dds_::Twist_'`` -> ``'geometry_msgs/msg/Twist'``; a name of
    another form (a plain DDS type) is returned as it is."""
    parts = dds_type.split("::")
    if len(parts) == 4 and parts[2] == "dds_" and parts[3].endswith("_"):
        return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"
    return dds_type


def type_hash(msgtype: str, distro: str = DEFAULT_DISTRO) -> str:
    """The message's RIHS01 type hash (``'RIHS01_<64 hex>'``), as Jazzy and later send it."""
    return typestore(distro).hash_rihs01(msgtype)


def message(store: Any, msgtype: str, **fields: Any) -> Any:
    """A ``msgtype`` message of typestore ``store`` with ``fields`` set and every other field at
    its ROS default (zeros, empty strings and sequences, nested messages likewise), as rclpy
    builds a message without arguments."""
    if msgtype == "geometry_msgs/msg/Quaternion":   # the one default companion meets that a
        fields.setdefault("w", 1.0)                 # .msg file sets itself (no rotation)
    defs = store.fielddefs[msgtype][1]
    unknown = set(fields) - {name for name, _ in defs}
    if unknown:
        raise TypeError(f"{msgtype} has no field {', '.join(sorted(unknown))}")
    return store.types[msgtype](**{name: fields[name] if name in fields else
                                   _default(store, desc) for name, desc in defs})


def _default(store: Any, desc: tuple) -> Any:
    """The ROS default of one rosbags field description: numbers and booleans as numpy arrays
    when in arrays or sequences, as rosbags' deserialiser gives them."""
    kind, detail = desc
    if kind == Nodetype.BASE:
        return {"string": "", "wstring": "", "bool": False, "float32": 0.0,
                "float64": 0.0}.get(detail[0], 0)
    if kind == Nodetype.NAME:
        return message(store, detail)
    (subkind, subdetail), size = detail
    if subkind == Nodetype.BASE and subdetail[0] not in ("string", "wstring"):
        dtype = np.dtype({"bool": "bool", "byte": "uint8", "char": "uint8"}.get(
            subdetail[0], subdetail[0]))
        return np.zeros(size if kind == Nodetype.ARRAY else 0, dtype=dtype)
    if kind == Nodetype.ARRAY:
        return [_default(store, (subkind, subdetail)) for _ in range(size)]
    return []


def make(msgtype: str, distro: str = DEFAULT_DISTRO, **fields: Any) -> Any:
    """:func:`message` of the typestore of ``distro`` (what companion's conversions use)."""
    return message(typestore(distro), msgtype, **fields)
