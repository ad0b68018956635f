"""What every ROS 2 transport offers the node: typed publishers and subscriptions on topics.

A transport (DDS through cyclonedds, Zenoh through eclipse-zenoh with rmw_zenoh's key
expressions, or :class:`MemoryTransport` for tests) is made for one node. It takes and gives
message objects of the typestore (:mod:`companion.ros.messages`) and serialises them itself, so
the bytes on every wire come from one place. Topic names are absolute ROS names (``/cmd_vel``);
each transport maps them to its own wire names (``rt/cmd_vel`` in DDS).
"""

from __future__ import annotations

import os
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from companion.errors import ConfigError


@dataclass(frozen=True)
class Qos:
    """A ROS 2 QoS profile, the parts companion uses: reliability, durability, history depth."""

    reliable: bool = True
    transient_local: bool = False
    depth: int = 10


#: rclpy's ``qos_profile_sensor_data``: best effort, volatile, depth 5 (drivers publish scans so).
SENSOR_DATA = Qos(reliable=False, depth=5)
#: rclpy's default profile: reliable, volatile, depth 10.
DEFAULT = Qos()
#: rmw's ``rmw_qos_profile_services_default``: reliable, volatile, depth 10.
SERVICES = Qos()
#: rcl's /rosout profile: reliable, transient local (a late listener gets the recent log),
#: depth 1000.
ROSOUT = Qos(reliable=True, transient_local=True, depth=1000)
#: rclpy's ``qos_profile_parameter_events``: reliable, volatile, depth 1000.
PARAMETER_EVENTS = Qos(depth=1000)


#: Highest DDS domain id whose ports fit the RTPS port formula (ROS 2 documents 0..232).
MAX_DOMAIN_ID = 232


def ros_domain_id(value: int | str | None = None) -> int:
    """The ROS domain: ``value``, else ``$ROS_DOMAIN_ID``, else 0, as every ROS 2 node takes
    it; an integer 0..232, else a ConfigError naming where it came from."""
    source = "domain_id"
    if value is None:
        source, value = "ROS_DOMAIN_ID", os.environ.get("ROS_DOMAIN_ID", "0") or "0"
    try:
        domain = int(value)
    except (TypeError, ValueError):
        domain = -1
    if not 0 <= domain <= MAX_DOMAIN_ID or isinstance(value, float):
        raise ConfigError(f"{source}: {value!r} is not a ROS domain id; allowed: an integer "
                          f"0..{MAX_DOMAIN_ID}")
    return domain


@dataclass(frozen=True)
class Endpoint:
    """A publisher another node has on the graph, as discovery reports it: its topic, message
    type (``'geometry_msgs/msg/PoseArray'``) and offered reliability and durability (a
    discovered endpoint's depth is not known: 0)."""

    topic: str
    msgtype: str
    qos: Qos


class Transport(Protocol):
    """One node's connection to a ROS 2 graph."""

    def publisher(self, topic: str, msgtype: str, qos: Qos = DEFAULT
                  ) -> Callable[[Any], None]:
        """A function that publishes a ``msgtype`` message (``'geometry_msgs/msg/Twist'``)."""
        ...

    def subscribe(self, topic: str, msgtype: str, callback: Callable[[Any], None],
                  qos: Qos = DEFAULT) -> None:
        """Call ``callback(message)`` for every ``msgtype`` message received on ``topic``; the
        callback may run on another thread."""
        ...

    def serve(self, service: str, srvtype: str, handler: Callable[[Any], Any]) -> None:
        """Answer every request to ``service`` (``'/companion/get_parameters'``) of ``srvtype``
        (``'rcl_interfaces/srv/GetParameters'``) with ``handler(request)``, a response
        message; the handler may run on another thread."""
        ...

    def publishers(self, topic: str) -> list[Endpoint]:
        """The publishers other nodes have on ``topic``, as discovery knows them now."""
        ...

    def close(self) -> None:
        """Stop receiving and release the transport's sockets and threads."""
        ...


class MemoryTransport:
    """An in-process graph for tests: every publisher reaches every subscription of the same
    :class:`MemoryBus`, synchronously, with the message serialised and read back (so a message
    that would not survive CDR fails here too); :meth:`call` is a service client."""

    def __init__(self, bus: MemoryBus, typestore: Any):
        self.bus, self.typestore = bus, typestore

    def publisher(self, topic: str, msgtype: str, qos: Qos = DEFAULT) -> Callable[[Any], None]:
        self.bus.endpoints.append((self, Endpoint(topic, msgtype, qos)))

        def publish(msg: Any) -> None:
            data = self.typestore.serialize_cdr(msg, msgtype)
            self.bus.sent.append((topic, msgtype, bytes(data)))
            for want, callback in list(self.bus.subscribers[topic]):
                if want == msgtype:
                    callback(self.typestore.deserialize_cdr(data, msgtype))
        return publish

    def subscribe(self, topic: str, msgtype: str, callback: Callable[[Any], None],
                  qos: Qos = DEFAULT) -> None:
        self.bus.subscribers[topic].append((msgtype, callback))

    def serve(self, service: str, srvtype: str, handler: Callable[[Any], Any]) -> None:
        self.bus.services[service] = (srvtype, handler)

    def call(self, service: str, srvtype: str, request: Any) -> Any:
        """The response of ``service`` to ``request`` (both through CDR); KeyError if no node
        serves it, TypeError if it serves another type."""
        have, handler = self.bus.services[service]
        if have != srvtype:
            raise TypeError(f"{service} is a {have}, not a {srvtype}")
        ts = self.typestore
        sent = ts.deserialize_cdr(ts.serialize_cdr(request, f"{srvtype}_Request"),
                                  f"{srvtype}_Request")
        response = handler(sent)
        return ts.deserialize_cdr(ts.serialize_cdr(response, f"{srvtype}_Response"),
                                  f"{srvtype}_Response")

    def publishers(self, topic: str) -> list[Endpoint]:
        return [e for owner, e in self.bus.endpoints if owner is not self and e.topic == topic]

    def close(self) -> None:
        pass


class MemoryBus:
    """The shared state of :class:`MemoryTransport` s: subscriptions, publishers, services and
    every message sent."""

    def __init__(self) -> None:
        self.subscribers: defaultdict[str, list] = defaultdict(list)
        self.endpoints: list[tuple[MemoryTransport, Endpoint]] = []
        self.services: dict[str, tuple[str, Callable[[Any], Any]]] = {}
        self.sent: list[tuple[str, str, bytes]] = []
