"""ROS 2 message types from one source: rosbags' typestore of a named distribution.

The typestore gives the message classes, their CDR serialisation and their type hashes
(RIHS01, sent by Jazzy and later); :func:`dds_type_name` gives the name DDS and rmw_zenoh use
on the wire. Conversions between messages and companion's own types live beside the node.
"""

from __future__ import annotations

from functools import cache
from typing import Any

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
