"""Recording ROS 2 bags: rosbag2 folders with MCAP storage and a metadata.yaml (rosbags).

:class:`BagWriter` writes messages of the typestore at given log times; :class:`RecordingTransport`
wraps a :class:`~companion.ros.transport.Transport` so that every message its node publishes
or receives is also written; :class:`RecordingBus` records everything sent on an in-memory
graph once. Log times are the recorder's clock when a message went out or came in (as
``ros2 bag record`` does); header stamps inside the messages stay the measurement times.
A message received after the recorder published something at log time T is logged after T,
so replaying a bag in log-time order feeds a node the inputs it had when it ticked.
docs/recording.md.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rosbags.rosbag2 import StoragePlugin, Writer

from companion.ros.scene import scene_types
from companion.ros.transport import DEFAULT, MemoryBus, Qos, Transport

#: rosbag2 metadata version written (8: Humble reads it, and Jazzy).
BAG_VERSION = 8


def ns(t: float) -> int:
    """Seconds to integer nanoseconds (the bag's log times)."""
    return int(round(t * 1e9))


def message_stamp(msg: Any) -> float | None:
    """The time a message carries (s): its header stamp, a Clock's time or the first
    transform's stamp; None for messages without one (Twist)."""
    stamp = getattr(getattr(msg, "header", None), "stamp", None) or getattr(msg, "clock", None)
    if stamp is None:
        inner = getattr(msg, "transforms", None) or getattr(msg, "markers", None)
        if inner:
            stamp = inner[0].header.stamp
    return None if stamp is None else stamp.sec + stamp.nanosec * 1e-9


class BagWriter:
    """A rosbag2 bag (MCAP storage) being written at ``path`` (which must not exist); a
    connection is added for each topic at its first message."""

    def __init__(self, path: str | Path, distro: str):
        self.typestore = scene_types(distro)
        self.writer = Writer(Path(path), version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.connections: dict[str, tuple[str, Any]] = {}
        self.last_ns = 0
        self._lock = threading.Lock()       # transports call back on their own threads

    def write(self, topic: str, msgtype: str, log_ns: int, msg: Any = None,
              data: bytes | None = None) -> None:
        """Write ``msg`` (or its CDR bytes ``data``) on ``topic`` at ``log_ns``."""
        if data is None:
            data = bytes(self.typestore.serialize_cdr(msg, msgtype))
        with self._lock:
            self._write(topic, msgtype, log_ns, data)

    def _write(self, topic: str, msgtype: str, log_ns: int, data: bytes) -> None:
        known = self.connections.get(topic)
        if known is None:
            known = (msgtype, self.writer.add_connection(topic, msgtype,
                                                         typestore=self.typestore))
            self.connections[topic] = known
        elif known[0] != msgtype:
            raise ValueError(f"{topic}: recorded as {known[0]}, now {msgtype}")
        self.writer.write(known[1], log_ns, data)
        self.last_ns = max(self.last_ns, log_ns)

    def close(self) -> None:
        self.writer.close()


class RecordingTransport:
    """A :class:`Transport` that writes every message published or received to ``bag``.

    ``clock()`` gives the log time (s; None: not yet known); without a clock, the log time
    is the latest stamp the recorder has published (a simulator's own clock)."""

    def __init__(self, inner: Transport, bag: BagWriter,
                 clock: Callable[[], float | None] | None = None):
        self.inner, self.bag, self.clock = inner, bag, clock
        self._now = 0           # ns: the recorder's time
        self._published = -1   # ns: log time of the last message published
        self.last: dict[str, Any] = {}   # the last message published on each topic

    def _time(self, msg: Any, outgoing: bool) -> int:
        now = self.clock() if self.clock is not None else None
        if now is not None:
            t = ns(now)
        else:
            stamp = message_stamp(msg) if outgoing and self.clock is None else None
            t = max(self._now, ns(stamp)) if stamp is not None else self._now
        if not outgoing and t <= self._published:
            t = self._published + 1
        self._now = max(self._now, t)
        if outgoing:
            self._published = max(self._published, t)
        return t

    def publisher(self, topic: str, msgtype: str, qos: Qos = DEFAULT) -> Callable[[Any], None]:
        publish = self.inner.publisher(topic, msgtype, qos)

        def recorded(msg: Any) -> None:
            publish(msg)
            self.last[topic] = msg
            self.bag.write(topic, msgtype, self._time(msg, True), msg)
        return recorded

    def subscribe(self, topic: str, msgtype: str, callback: Callable[[Any], None],
                  qos: Qos = DEFAULT) -> None:
        def recorded(msg: Any) -> None:
            self.bag.write(topic, msgtype, self._time(msg, False), msg)
            callback(msg)
        self.inner.subscribe(topic, msgtype, recorded, qos)

    def record(self, topic: str, msgtype: str, msg: Any) -> None:
        """Write ``msg`` to the bag only, as if published now (the scene)."""
        self.bag.write(topic, msgtype, self._time(msg, True), msg)

    def close(self) -> None:
        self.inner.close()


class _Sent:
    """``MemoryBus.sent`` that writes to a bag instead of keeping the messages."""

    def __init__(self, bag: BagWriter):
        self.bag = bag

    def append(self, item: tuple[str, str, bytes]) -> None:
        topic, msgtype, data = item
        stamp = message_stamp(self.bag.typestore.deserialize_cdr(data, msgtype))
        t = max(self.bag.last_ns, ns(stamp)) if stamp is not None else self.bag.last_ns
        self.bag.write(topic, msgtype, t, data=data)


class RecordingBus(MemoryBus):
    """An in-memory graph whose every message goes to ``bag`` once, at the latest stamp seen
    (the simulator publishes each sample's messages stamped with its time first)."""

    def __init__(self, bag: BagWriter):
        super().__init__()
        self.sent = _Sent(bag)   # type: ignore[assignment]

    def record(self, topic: str, msgtype: str, msg: Any) -> None:
        """Write ``msg`` to the bag only (no subscriber gets it), like a message sent now."""
        self.sent.append((topic, msgtype, bytes(self.sent.bag.typestore.serialize_cdr(
            msg, msgtype))))
