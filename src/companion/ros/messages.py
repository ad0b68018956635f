"""ROS 2 message types from one source: rosbags' typestore of a named distribution.

The typestore gives the message classes, their CDR serialisation and their type hashes
(RIHS01, sent by Jazzy and later); :func:`dds_type_name` gives the name DDS and rmw_zenoh use
on the wire. Conversions between messages and companion's own types live beside the node.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Nodetype

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
