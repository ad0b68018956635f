"""Recording ROS 2 bags as Jazzy's rosbag2 writes them: a folder with a metadata.yaml
(version 9) and one MCAP file (the ``ros2`` profile, ``ros2msg`` schemas, each channel with its
offered QoS and type hash), written with the ``mcap`` library; rosbags gives the message
definitions and reads bags back.

:class:`BagWriter` writes messages of the typestore at given log times; :class:`RecordingTransport`
wraps a :class:`~companion.ros.transport.Transport` so that every message its node publishes
or receives is also written; :class:`RecordingBus` records everything sent on an in-memory
graph once. Log times are the recorder's clock when a message went out or came in (as
``ros2 bag record`` does, ns since 1970); header stamps inside the messages stay the
measurement times. A message received after the recorder published something at log time T
is logged after T, so replaying a bag in log-time order feeds a node the inputs it had when it
ticked. docs/recording.md.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from companion import __version__
from companion.io import write_text
from companion.ros.convert import stamp_ns
from companion.ros.scene import scene_types
from companion.ros.transport import DEFAULT, MemoryBus, Qos, Transport

#: rosbag2 metadata version written (9, as Jazzy's rosbag2 writes it).
BAG_VERSION = 9
#: RMW_DURATION_INFINITE as rosbag2 stores it (deadline, lifespan, liveliness lease).
INFINITE = {"sec": 9223372036, "nsec": 854775807}


def ns(t: float) -> int:
    """Seconds to integer nanoseconds (the bag's log times)."""
    return int(round(t * 1e9))


def message_stamp(msg: Any) -> int | None:
    """The time a message carries (ns since 1970): its header stamp, a Clock's time, its own
    stamp (Log, ParameterEvent) or the first transform's or marker's stamp; None for messages
    without one (Twist)."""
    stamp = getattr(getattr(msg, "header", None), "stamp", None) or getattr(msg, "clock", None) \
        or getattr(msg, "stamp", None)
    if stamp is None:
        inner = getattr(msg, "transforms", None) or getattr(msg, "markers", None)
        if inner:
            stamp = inner[0].header.stamp
    return None if stamp is None else stamp_ns(stamp)


def qos_profile(qos: Qos) -> dict[str, Any]:
    """One offered QoS profile as rosbag2 (metadata version 9) writes it."""
    return {"history": "keep_last" if qos.depth else "unknown", "depth": qos.depth,
            "reliability": "reliable" if qos.reliable else "best_effort",
            "durability": "transient_local" if qos.transient_local else "volatile",
            "deadline": dict(INFINITE), "lifespan": dict(INFINITE), "liveliness": "automatic",
            "liveliness_lease_duration": dict(INFINITE),
            "avoid_ros_namespace_conventions": False}


def _dump(data: Any) -> str:
    """YAML as rosbag2 writes it (block style, keys in order, no anchors)."""
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=False)


class BagWriter:
    """A rosbag2 bag being written at ``path`` (which must not exist) in the message types
    and ``ros_distro`` of ``distro``; a topic is added at its first message, with the QoS
    given then. :meth:`close` writes the summary and metadata.yaml."""

    def __init__(self, path: str | Path, distro: str):
        self.path, self.distro = Path(path), distro
        self.typestore = scene_types(distro)
        self.path.mkdir(parents=True)             # FileExistsError: never over a bag
        self.file_name = f"{self.path.name}_0.mcap"
        self._file = (self.path / self.file_name).open("wb")
        self._mcap = McapWriter(self._file, compression=CompressionType.NONE)
        self._mcap.start(profile="ros2", library=f"companion {__version__}")
        self._schemas: dict[str, int] = {}
        self.topics: dict[tuple[str, str], dict[str, Any]] = {}
        self.custom: dict[str, str] = {}
        self.first_ns, self.last_ns = None, 0
        self._early: list[tuple[str, str, bytes, Qos]] = []
        self._lock = threading.Lock()       # transports call back on their own threads

    def set_custom_data(self, key: str, value: str) -> None:
        """A key of the metadata's ``custom_data``."""
        self.custom[key] = value

    def write(self, topic: str, msgtype: str, log_ns: int | None, msg: Any = None,
              data: bytes | None = None, qos: Qos = DEFAULT) -> None:
        """Write ``msg`` (or its CDR bytes ``data``) on ``topic`` at ``log_ns``; ``qos`` is the
        offered QoS recorded for the topic if this is its first message. A message whose time
        is not known yet (``log_ns`` None: sent before the recorder's clock started) is
        written at the first time that is."""
        if data is None:
            data = bytes(self.typestore.serialize_cdr(msg, msgtype))
        with self._lock:
            if log_ns is None:
                self._early.append((topic, msgtype, data, qos))
                return
            early, self._early = self._early, []
            for item in early:
                self._put(item[0], item[1], log_ns, item[2], item[3])
            self._put(topic, msgtype, log_ns, data, qos)

    def _put(self, topic: str, msgtype: str, log_ns: int, data: bytes, qos: Qos) -> None:
        entry = self.topics.get((topic, msgtype)) or self._add(topic, msgtype, qos)
        entry["count"] += 1
        self._mcap.add_message(entry["channel"], log_ns, data, log_ns, sequence=entry["count"])
        self.first_ns = log_ns if self.first_ns is None else min(self.first_ns, log_ns)
        self.last_ns = max(self.last_ns, log_ns)

    def _add(self, topic: str, msgtype: str, qos: Qos) -> dict[str, Any]:
        schema = self._schemas.get(msgtype)
        if schema is None:
            text, _ = self.typestore.generate_msgdef(msgtype, ros_version=2)
            schema = self._schemas[msgtype] = self._mcap.register_schema(
                msgtype, "ros2msg", text.encode())
        type_hash = self.typestore.hash_rihs01(msgtype)
        profiles = [qos_profile(qos)]
        channel = self._mcap.register_channel(topic, "cdr", schema, {
            "offered_qos_profiles": _dump(profiles).strip(), "topic_type_hash": type_hash})
        entry = self.topics[(topic, msgtype)] = {"channel": channel, "count": 0,
                                                  "qos": profiles, "hash": type_hash}
        return entry

    def metadata(self) -> dict[str, Any]:
        """The bag's rosbag2_bagfile_information (version 9)."""
        start = self.first_ns or 0
        duration = {"nanoseconds": self.last_ns - start if self.first_ns is not None else 0}
        count = sum(e["count"] for e in self.topics.values())
        return {
            "version": BAG_VERSION, "storage_identifier": "mcap",
            "duration": duration, "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": count,
            "topics_with_message_count": [
                {"topic_metadata": {"name": topic, "type": msgtype,
                                    "serialization_format": "cdr",
                                    "offered_qos_profiles": e["qos"],
                                    "type_description_hash": e["hash"]},
                 "message_count": e["count"]}
                for (topic, msgtype), e in self.topics.items()],
            "compression_format": "", "compression_mode": "",
            "relative_file_paths": [self.file_name],
            "files": [{"path": self.file_name,
                       "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": dict(duration), "message_count": count}],
            "custom_data": dict(self.custom), "ros_distro": self.distro}

    def close(self) -> None:
        """Finish the MCAP file (its own copy of the metadata, as rosbag2's MCAP storage
        keeps it) and write metadata.yaml."""
        with self._lock:
            early, self._early = self._early, []
            for topic, msgtype, data, qos in early:      # never followed by a known time
                self._put(topic, msgtype, self.last_ns, data, qos)
            info = self.metadata()
            self._mcap.add_metadata("rosbag2", {"serialized_metadata": _dump(info)})
            self._mcap.finish()
            self._file.close()
        write_text(self.path / "metadata.yaml",
                   _dump({"rosbag2_bagfile_information": info}))


class RecordingTransport:
    """A :class:`Transport` that writes every message published or received to ``bag``.

    ``clock()`` gives the log time (ns; None: not yet known); without a clock, the log time
    is the latest stamp the recorder has published (a simulator's own clock)."""

    def __init__(self, inner: Transport, bag: BagWriter,
                 clock: Callable[[], int | None] | None = None):
        self.inner, self.bag, self.clock = inner, bag, clock
        self.typestore = inner.typestore
        self._now = 0           # ns: the recorder's time
        self._published = -1   # ns: log time of the last message published
        self.last: dict[str, Any] = {}   # the last message published on each topic

    def _time(self, msg: Any, outgoing: bool) -> int | None:
        now = self.clock() if self.clock is not None else None
        if now is not None:
            t = now
        else:
            stamp = message_stamp(msg) if outgoing and self.clock is None else None
            t = max(self._now, stamp) if stamp is not None else self._now
            if not t:
                return None                  # before the first time known
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
            self.bag.write(topic, msgtype, self._time(msg, True), msg, qos=qos)
        return recorded

    def subscribe(self, topic: str, msgtype: str, callback: Callable[[Any], None],
                  qos: Qos = DEFAULT) -> None:
        def recorded(msg: Any) -> None:
            self.bag.write(topic, msgtype, self._time(msg, False), msg,
                           qos=self._offered(topic, msgtype, qos))
            callback(msg)
        self.inner.subscribe(topic, msgtype, recorded, qos)

    def _offered(self, topic: str, msgtype: str, ours: Qos) -> Qos:
        """The QoS a publisher of the topic offers, as discovery shows it (as rosbag2 records
        it); our subscription's when discovery does not say."""
        if (topic, msgtype) in self.bag.topics:
            return ours
        try:
            found = [e.qos for e in self.inner.publishers(topic) if e.msgtype == msgtype]
        except Exception:
            found = []
        return found[0] if found else ours

    def serve(self, service: str, srvtype: str, handler: Callable[[Any], Any]) -> None:
        self.inner.serve(service, srvtype, handler)

    def publishers(self, topic: str) -> list:
        return self.inner.publishers(topic)

    def record(self, topic: str, msgtype: str, msg: Any) -> None:
        """Write ``msg`` to the bag only, as if published now (the scene)."""
        self.bag.write(topic, msgtype, self._time(msg, True), msg)

    def close(self) -> None:
        self.inner.close()


class _Sent:
    """``MemoryBus.sent`` that writes to a bag instead of keeping the messages."""

    def __init__(self, bag: BagWriter, bus: MemoryBus):
        self.bag, self.bus = bag, bus

    def append(self, item: tuple[str, str, bytes]) -> None:
        topic, msgtype, data = item
        stamp = message_stamp(self.bag.typestore.deserialize_cdr(data, msgtype))
        t = max(self.bag.last_ns, stamp) if stamp is not None else self.bag.last_ns or None
        qos = next((e.qos for _, e in self.bus.endpoints
                    if e.topic == topic and e.msgtype == msgtype), DEFAULT)
        self.bag.write(topic, msgtype, t, data=data, qos=qos)


class RecordingBus(MemoryBus):
    """An in-memory graph whose every message goes to ``bag`` once, at the latest stamp seen
    (the simulator publishes each sample's messages stamped with its time first)."""

    def __init__(self, bag: BagWriter):
        super().__init__()
        self.sent = _Sent(bag, self)   # type: ignore[assignment]

    def record(self, topic: str, msgtype: str, msg: Any) -> None:
        """Write ``msg`` to the bag only (no subscriber gets it), like a message sent now."""
        self.sent.append((topic, msgtype, bytes(self.sent.bag.typestore.serialize_cdr(
            msg, msgtype))))
