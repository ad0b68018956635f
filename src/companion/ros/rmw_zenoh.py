"""What rmw_zenoh_cpp puts on the wire, as pure functions: data key expressions, liveliness
tokens (with their QoS string), entity GIDs, sample attachments and the session configuration.

Every format here is read from rmw_zenoh's source as released for Jazzy (rmw_zenoh_cpp 0.2.9,
github.com/ros2-gbp/rmw_zenoh-release, tag ``release/jazzy/rmw_zenoh_cpp/0.2.9-1``); Humble's
0.1.9 and Kilted's 0.6.7 build the same strings, except that Humble sends
``TypeHashNotSupported`` in place of the RIHS01 hash. The file each format comes from is named
beside it. :mod:`companion.ros.zenoh` uses these to be a node that rmw_zenoh nodes see and hear.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from typing import Any

import xxhash

from companion.errors import ConfigError
from companion.ros.messages import dds_type_name, ros_type_name, service_type_hash, type_hash
from companion.ros.transport import Qos

# src/detail/liveliness_utils.cpp: ADMIN_SPACE, the entity strings and SLASH_REPLACEMENT.
ADMIN_SPACE = "@ros2_lv"
NODE, PUBLISHER, SUBSCRIPTION, SERVICE = "NN", "MP", "MS", "SS"
#: rmw_zenoh's default depth (src/detail/qos.cpp, RMW_ZENOH_DEFAULT_HISTORY_DEPTH): a depth of 0
#: becomes 42, and a depth of 42 is left out of the QoS string.
DEFAULT_DEPTH = 42
#: What Humble's rmw_zenoh (0.1.9, src/detail/rmw_publisher_data.cpp) sends for the type hash.
NO_TYPE_HASH = "TypeHashNotSupported"
#: rmw_zenoh's router address (config/DEFAULT_RMW_ZENOH_SESSION_CONFIG.json5, connect/endpoints
#: ``tcp/localhost:7447``), written as the IPv4 loopback address so that no name is resolved.
DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
#: Where our session listens by default: the loopback interface, a port of the system's choice
#: (rmw_zenoh's default is ``tcp/localhost:0``).
DEFAULT_LISTEN = "tcp/127.0.0.1:0"
#: rmw_gid_t's storage in Jazzy (rmw/types.h RMW_GID_STORAGE_SIZE) and rmw_zenoh's GID everywhere.
GID_SIZE = 16

_NODE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_ROS_NAME = re.compile(r"(/[A-Za-z_][A-Za-z0-9_]*)+")


def check_names(node_name: str, namespace: str) -> None:
    """Raise :class:`ConfigError` unless ``node_name`` is a ROS base name and ``namespace`` is
    ``/`` or an absolute ROS name (the rules rcl applies before rmw_zenoh sees them)."""
    if not _NODE_NAME.fullmatch(node_name):
        raise ConfigError(f"node_name: {node_name!r} is not a ROS node name; allowed: letters, "
                          "digits and '_', not starting with a digit")
    if namespace != "/" and not _ROS_NAME.fullmatch(namespace):
        raise ConfigError(f"namespace: {namespace!r} is not a ROS namespace; allowed: '/' or "
                          "an absolute name such as '/robot1'")


def check_topic(topic: str) -> None:
    """Raise :class:`ConfigError` unless ``topic`` is an absolute ROS topic name."""
    if not _ROS_NAME.fullmatch(topic):
        raise ConfigError(f"topic: {topic!r} is not an absolute ROS topic name; allowed: "
                          "names such as '/cmd_vel' or '/robot1/scan'")


def wire_type_hash(msgtype: str, distro: str) -> str:
    """The type hash rmw_zenoh of ``distro`` puts in keys: RIHS01 from Jazzy on, and
    ``TypeHashNotSupported`` in Humble (which has no type hashes)."""
    return NO_TYPE_HASH if distro == "humble" else type_hash(msgtype, distro)


def wire_service_hash(srvtype: str, distro: str) -> str:
    """The type hash rmw_zenoh of ``distro`` puts in a service's keys (the service type's)."""
    return NO_TYPE_HASH if distro == "humble" else service_type_hash(srvtype, distro)


def topic_keyexpr(domain_id: int, topic: str, msgtype: str, hash_: str) -> str:
    """The key expression samples of ``topic`` travel on:
    ``<domain>/<topic without its leading and trailing '/'>/<DDS type name>/<type hash>``
    (src/detail/liveliness_utils.cpp, ``TopicInfo::TopicInfo``)."""
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(msgtype)}/{hash_}"


def mangle(name: str) -> str:
    """A name as one chunk of a liveliness token: every ``/`` becomes ``%``
    (src/detail/liveliness_utils.cpp, ``mangle_name``)."""
    return name.replace("/", "%")


def qos_keyexpr(qos: Qos) -> str:
    """The QoS chunk of a token (src/detail/liveliness_utils.cpp, ``qos_to_keyexpr``).

    ``reliability:durability:history,depth:deadline_s,ns:lifespan_s,ns:liveliness,s,ns`` with
    every field equal to rmw_zenoh's default (reliable, volatile, keep last 42, infinite
    durations, automatic liveliness) left empty; rmw's enum values: best effort 2, transient
    local 1. companion always keeps last ``depth`` and leaves the durations infinite.
    """
    reliability = "" if qos.reliable else "2"
    durability = "1" if qos.transient_local else ""
    depth = "" if qos.depth in (0, DEFAULT_DEPTH) else str(qos.depth)
    return f"{reliability}:{durability}:,{depth}:,:,:,,"


def parse_qos(text: str) -> Qos | None:
    """The reliability, durability and depth of a token's QoS chunk (:func:`qos_keyexpr`);
    None if it is not one (src/detail/liveliness_utils.cpp, ``keyexpr_to_qos``)."""
    parts = text.split(":")
    if len(parts) < 6 or "," not in parts[2]:
        return None
    depth = parts[2].split(",")[1]
    return Qos(reliable=parts[0] != "2", transient_local=parts[1] == "1",
               depth=int(depth) if depth.isdigit() else DEFAULT_DEPTH)


def parse_token(key: str) -> tuple[str, str, str, str, Qos] | None:
    """``(zid, kind, topic, ROS message type, QoS)`` of a publisher's, subscription's or
    service's liveliness token; None for a node's token or a key that is not a token."""
    parts = key.split("/")
    if len(parts) != 13 or parts[0] != ADMIN_SPACE or parts[5] == NODE:
        return None
    qos = parse_qos(parts[12])
    if qos is None:
        return None
    return (parts[2], parts[5], parts[9].replace("%", "/"), ros_type_name(parts[10]), qos)


@dataclass(frozen=True)
class Entity:
    """One node, publisher or subscription as rmw_zenoh's graph cache knows it."""

    domain_id: int
    zid: str
    node_id: int
    entity_id: int
    kind: str
    enclave: str
    namespace: str
    node_name: str
    topic: str | None = None
    dds_type: str | None = None
    type_hash: str | None = None
    qos: Qos | None = None

    def liveliness_keyexpr(self) -> str:
        """``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node>``
        and for publishers and subscriptions ``/<topic>/<DDS type>/<type hash>/<QoS>``, names
        mangled (src/detail/liveliness_utils.cpp, ``Entity::Entity``)."""
        parts = [ADMIN_SPACE, str(self.domain_id), self.zid, str(self.node_id),
                 str(self.entity_id), self.kind, mangle(self.enclave), mangle(self.namespace),
                 mangle(self.node_name)]
        if self.kind != NODE:
            parts += [mangle(self.topic or ""), mangle(self.dds_type or ""),
                      mangle(self.type_hash or ""), qos_keyexpr(self.qos or Qos())]
        return "/".join(parts)

    def gid(self) -> bytes:
        """The entity's GID: XXH3-128 of its liveliness key expression, low 64 bits then high
        64 bits, each little-endian (src/detail/liveliness_utils.cpp, ``Entity::Entity``)."""
        return xxhash.xxh3_128_intdigest(self.liveliness_keyexpr().encode()).to_bytes(
            GID_SIZE, "little")


def attachment(sequence_number: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    """A sample's attachment as zenoh-cpp's ``ext::Serializer`` writes rmw_zenoh's
    ``AttachmentData`` (src/detail/attachment_helpers.cpp): int64 sequence number and int64
    source timestamp (ns since the epoch), little-endian, then the 16-byte GID as a sequence
    (its length as a LEB128 varint, 16 = one byte 0x10, then the bytes)."""
    if len(gid) != GID_SIZE:
        raise ValueError(f"a GID has {GID_SIZE} bytes, not {len(gid)}")
    return struct.pack("<qqB", sequence_number, source_timestamp_ns, GID_SIZE) + gid


def parse_attachment(data: bytes) -> tuple[int, int, bytes]:
    """``(sequence_number, source_timestamp_ns, gid)`` from an attachment; ``ValueError`` if it
    is not rmw_zenoh's layout."""
    if len(data) != 17 + GID_SIZE or data[16] != GID_SIZE:
        raise ValueError(f"not an rmw_zenoh attachment ({len(data)} bytes)")
    seq, stamp = struct.unpack_from("<qq", data)
    return seq, stamp, bytes(data[17:])


#: Zenoh modes companion's session can take: ``peer`` (rmw_zenoh's: talks to the router and,
#: once gossip has introduced them, straight to the other nodes) or ``client`` (everything
#: through the router; opens no listening socket) or ``router`` (what rmw_zenohd is: listens
#: on ``listen`` and routes between the nodes; ``companion sim-robot`` plays the robot so).
MODES = ("peer", "client", "router")
#: How long a client waits for its router before giving up, ms.
CLIENT_CONNECT_TIMEOUT_MS = 5000


def session_config(connect: list[str], listen: list[str], mode: str = "peer") -> dict[str, Any]:
    """Zenoh session settings (key path -> JSON value) as rmw_zenoh's
    config/DEFAULT_RMW_ZENOH_SESSION_CONFIG.json5 sets them, with our endpoints.

    A peer connects to ``connect`` (retrying every 1-4 s in the background while a router is
    not up, as rmw_zenoh does) and listens on ``listen``; a client listens nowhere and fails
    after :data:`CLIENT_CONNECT_TIMEOUT_MS` without a router. Both: multicast scouting off,
    gossip scouting through the router on, no shared memory, samples timestamped.
    """
    if mode not in MODES:
        raise ConfigError(f"zenoh mode: {mode!r} is not allowed; allowed: {', '.join(MODES)}")
    peer = mode != "client"
    return {
        "mode": mode,
        "connect/endpoints": connect,
        "connect/timeout_ms": -1 if peer else CLIENT_CONNECT_TIMEOUT_MS,
        "connect/exit_on_failure": not peer,
        "connect/retry": {"period_init_ms": 1000, "period_max_ms": 4000,
                          "period_increase_factor": 2},
        "listen/endpoints": listen if peer else [],
        "listen/exit_on_failure": True,
        "scouting/multicast/enabled": False,
        "scouting/gossip/enabled": True,
        "scouting/gossip/multihop": False,
        "timestamping/enabled": True,
        "transport/shared_memory/enabled": False,
    }
