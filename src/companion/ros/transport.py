"""What every ROS 2 transport offers the node: typed publishers and subscriptions on topics.

A transport (DDS through cyclonedds, Zenoh through eclipse-zenoh with rmw_zenoh's key
expressions, or :class:`MemoryTransport` for tests) is made for one node. It takes and gives
message objects of the typestore (:mod:`companion.ros.messages`) and serialises them itself, so
the bytes on every wire come from one place. Topic names are absolute ROS names (``/cmd_vel``);
each transport maps them to its own wire names (``rt/cmd_vel`` in DDS).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol


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

    def close(self) -> None:
        """Stop receiving and release the transport's sockets and threads."""
        ...


class MemoryTransport:
    """An in-process graph for tests: every publisher reaches every subscription of the same
    :class:`MemoryBus`, synchronously, with the message serialised and read back (so a message
    that would not survive CDR fails here too)."""

    def __init__(self, bus: MemoryBus, typestore: Any):
        self.bus, self.typestore = bus, typestore

    def publisher(self, topic: str, msgtype: str, qos: Qos = DEFAULT) -> Callable[[Any], None]:
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

    def close(self) -> None:
        pass


class MemoryBus:
    """The shared state of :class:`MemoryTransport` s: subscriptions and every message sent."""

    def __init__(self) -> None:
        self.subscribers: defaultdict[str, list] = defaultdict(list)
        self.sent: list[tuple[str, str, bytes]] = []
