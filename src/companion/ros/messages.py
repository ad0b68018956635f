"""ROS 2 message types from one source: rosbags' typestore of a named distribution.

The typestore gives the message classes, their CDR serialisation and their type hashes
(RIHS01, sent by Jazzy and later); :func:`dds_type_name` gives the name DDS and rmw_zenoh use
on the wire. Conversions between messages and companion's own types live beside the node.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore

from companion.errors import ConfigError

#: ROS 2 distributions companion can speak, by their rosbags typestore.
DISTROS = {"humble": Stores.ROS2_HUMBLE, "jazzy": Stores.ROS2_JAZZY}
DEFAULT_DISTRO = "jazzy"


@cache
def typestore(distro: str = DEFAULT_DISTRO) -> Any:
    """The typestore of ``distro`` (one of :data:`DISTROS`)."""
    if distro not in DISTROS:
        raise ConfigError(f"distro: unknown ROS 2 distribution {distro!r}; "
                          f"allowed: {', '.join(DISTROS)}")
    return get_typestore(DISTROS[distro])


def dds_type_name(msgtype: str) -> str:
    """``'geometry_msgs/msg/Twist'`` -> ``'geometry_msgs::msg::dds_::Twist_'`` (the DDS and
    rmw_zenoh wire name)."""
    package, kind, name = msgtype.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def type_hash(msgtype: str, distro: str = DEFAULT_DISTRO) -> str:
    """The message's RIHS01 type hash (``'RIHS01_<64 hex>'``), as Jazzy and later send it."""
    return typestore(distro).hash_rihs01(msgtype)


_NUMPY = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "int8": np.int8,
          "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16, "int32": np.int32,
          "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64, "float32": np.float32,
          "float64": np.float64}


def _default(node: tuple, distro: str) -> Any:
    """The ROS 2 default of one field: 0, False, "", an empty or zeroed array, a message."""
    kind, spec = node
    if kind == Nodetype.BASE:
        name = spec[0]
        return "" if name == "string" else False if name == "bool" else \
            0.0 if name.startswith("float") else 0
    if kind == Nodetype.NAME:
        return make(spec, distro)
    (sub_kind, sub), size = spec
    if sub_kind == Nodetype.BASE and sub[0] in _NUMPY:
        return np.zeros(size if kind == Nodetype.ARRAY else 0, dtype=_NUMPY[sub[0]])
    return [_default((sub_kind, sub), distro) for _ in range(size)] \
        if kind == Nodetype.ARRAY else []


def make(msgtype: str, distro: str = DEFAULT_DISTRO, **fields: Any) -> Any:
    """A ``msgtype`` message with ``fields`` set and every other field at its ROS 2 default
    (what ``msg = Twist()`` gives in rclpy)."""
    store = typestore(distro)
    if msgtype == "geometry_msgs/msg/Quaternion":   # the one default companion meets that the
        fields.setdefault("w", 1.0)                 # .msg file sets (w = 1: no rotation)
    defs = store.fielddefs[msgtype][1]
    values = {name: fields.pop(name) if name in fields else _default(node, distro)
              for name, node in defs}
    if fields:   # a programming error: a field the message does not have
        raise TypeError(f"{msgtype} has no field(s) {', '.join(fields)}")
    return store.types[msgtype](**values)
