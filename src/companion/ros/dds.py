"""DDS transport through cyclonedds: one ROS 2 node on one DDS participant, no ROS install.

Wire names are rmw's: the ROS topic ``/cmd_vel`` is the DDS topic ``rt/cmd_vel`` of type
``geometry_msgs::msg::dds_::Twist_``. Samples are rosbags' CDR (XCDR1, little endian), written
and read as bytes, so what goes on the wire is ``typestore.serialize_cdr`` (with zeros to a
multiple of 4 bytes, as rmw_cyclonedds_cpp sends it). Each reader
and writer carries ``typehash=RIHS01_...;`` in its USER_DATA (as rmw implementations of Jazzy and
later do), and the node announces itself on ``ros_discovery_info`` so ROS 2 tools list it.
By default the participant is confined to the loopback interface with multicast off
(:func:`loopback_config`); docs/ros-dds.md says how to open it to a robot's network.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import DDSException, Listener, Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from companion.errors import ConfigError
from companion.ros.dds_base import (
    ANY_STATE,
    DISCOVERY_QOS,
    DISCOVERY_TOPIC,
    DISCOVERY_TYPE,
    DOMAINS,
    GID_TYPE,
    NODE_NAME,
    TOPIC_NAME,
    dds_qos,
    dds_topic_name,
    gid,
    loopback_config,
    padded,
    service_topics,
    split_request,
    with_header,
)
from companion.ros.idl import idl_type
from companion.ros.messages import DEFAULT_DISTRO, message, ros_type_name
from companion.ros.messages import typestore as distro_typestore
from companion.ros.transport import DEFAULT, SERVICES, Endpoint, ros_domain_id
from companion.ros.transport import Qos as RosQos

log = logging.getLogger(__name__)
#: The vendor id that starts a Fast DDS (eProsima) GUID.
FAST_DDS_VENDOR = b"\x01\x0f"


class DdsTransport:
    """One ROS 2 node ``namespace/node_name`` on its own DDS participant in ``domain_id``
    (None: ``$ROS_DOMAIN_ID`` or 0), speaking the messages of ``typestore`` (default: that of
    ``distro``). ``config`` is a cyclonedds XML configuration (or a file URI); None means
    ``$CYCLONEDDS_URI`` if it is set, else :func:`loopback_config`. Callbacks of subscriptions
    run on cyclonedds' receive threads."""

    def __init__(self, node_name: str = "companion", namespace: str = "/",
                 domain_id: int | str | None = None, distro: str = DEFAULT_DISTRO,
                 typestore: Any = None, config: str | None = None):
        if not NODE_NAME.fullmatch(node_name):
            raise ConfigError(f"node_name: {node_name!r} is not a ROS node name; allowed: "
                              "letters, digits and underscores, not starting with a digit")
        if namespace != "/" and not (namespace.startswith("/")
                                     and TOPIC_NAME.fullmatch(namespace.rstrip("/"))):
            raise ConfigError(f"namespace: {namespace!r} is not a ROS namespace; allowed: '/' "
                              "or an absolute name such as '/robot1'")
        self.node_name, self.namespace = node_name, namespace.rstrip("/") or "/"
        self.typestore = typestore if typestore is not None else distro_typestore(distro)
        self.domain_id = ros_domain_id(domain_id)
        source = "dds_config"
        if config is None:
            source = "CYCLONEDDS_URI" if os.environ.get("CYCLONEDDS_URI") else "loopback"
            config = None if source == "CYCLONEDDS_URI" else loopback_config()
        DOMAINS.acquire(self.domain_id, config)
        self._lock = threading.RLock()
        self._topics: dict[tuple[str, str], Topic] = {}
        self._readers: list[DataReader] = []
        self._writers: list[DataWriter] = []
        self._closed = False
        self._services = 0
        self._fast_dds_named = False
        self._known: dict[Any, Any] = {}
        try:
            try:
                self.participant = DomainParticipant(
                    self.domain_id, qos=Qos(Policy.Userdata(data=b"enclave=/;")))
            except DDSException as exc:
                raise ConfigError(f"{source}: cyclonedds could not start a participant in domain "
                                  f"{self.domain_id} with this configuration ({exc}; cyclonedds "
                                  "names the setting on stderr)") from exc
            self._discovery = DataWriter(
                self.participant, self._topic(DISCOVERY_TOPIC, DISCOVERY_TYPE),
                qos=dds_qos(DISCOVERY_QOS, self._user_data(DISCOVERY_TYPE)))
            # other participants' writers (publishers()), read as they are discovered
            self._discovered = BuiltinDataReader(self.participant,
                                                 BuiltinTopicDcpsPublication)
            self._announce()
        except BaseException:
            if hasattr(self, "participant"):
                self.participant.__del__()
            DOMAINS.release(self.domain_id)
            raise

    def publisher(self, topic: str, msgtype: str, qos: RosQos = DEFAULT
                  ) -> Callable[[Any], None]:
        """A function that writes a ``msgtype`` message on ``topic`` as rosbags' CDR bytes."""
        writer = self._endpoint(DataWriter, topic, msgtype, qos)
        serialize = self.typestore.serialize_cdr

        def publish(msg: Any) -> None:
            code = ddspy_write(writer._ref, padded(serialize(msg, msgtype)))
            if code < 0:
                raise RuntimeError(f"DDS write of {msgtype} on {topic} failed (code {code})")
        return publish

    def subscribe(self, topic: str, msgtype: str, callback: Callable[[Any], None],
                  qos: RosQos = DEFAULT) -> None:
        """Call ``callback(message)`` for every ``msgtype`` sample on ``topic``; a sample that
        does not decode, or a callback that raises, is logged and skipped."""
        deserialize = self.typestore.deserialize_cdr

        def on_data(reader: DataReader) -> None:
            while samples := ddspy_take(reader._ref, ANY_STATE, 64):
                if isinstance(samples, int):   # an error code: the reader is being deleted
                    return
                for data, info in samples:
                    if not info.valid_data:
                        continue
                    try:
                        msg = deserialize(data, msgtype)
                    except Exception as exc:
                        log.warning("%s: dropped a %s sample that does not decode (%s)",
                                    topic, msgtype, exc)
                        continue
                    try:
                        callback(msg)
                    except Exception:
                        log.exception("%s: the callback raised", topic)

        self._endpoint(DataReader, topic, msgtype, qos, Listener(on_data_available=on_data))

    def serve(self, service: str, srvtype: str, handler: Callable[[Any], Any]) -> None:
        """Answer ``service`` as rmw_cyclonedds_cpp does: requests on ``rq/<name>Request``,
        each a 16-byte header (client id, sequence number) then the request; the reply on
        ``rr/<name>Reply`` with the same header, so that the client takes it as its own. Both
        endpoints carry ``serviceid=...;`` in their USER_DATA (a client waits for it before it
        asks). The samples' DDS type carries the header (:func:`idl_type`'s
        ``request_header``). A Fast DDS client (rmw_fastrtps_cpp) reads a reply only by a sample
        identity that Cyclone DDS cannot send (ros2/rmw_cyclonedds#184): such a client is named
        in one warning when it matches (its requests, without the header, are not answered). A
        request that does not decode is logged and skipped."""
        rq_topic, rq_type, rr_topic, rr_type = service_topics(service, srvtype)
        with self._lock:
            self._services += 1
            sid = ".".join(f"{b:x}" for b in gid(self.participant)[:12]
                           + self._services.to_bytes(4, "big"))
        extra = f"serviceid={sid};".encode()
        writer = self._endpoint(DataWriter, rr_topic, rr_type, SERVICES, raw=True,
                                extra=extra)
        ts = self.typestore

        def on_match(reader: DataReader, status: Any) -> None:
            """A client's request writer matched: name a Fast DDS one (once a transport)."""
            if not self._fast_dds_named and self._from_fast_dds(
                    reader, status.last_publication_handle):
                self._fast_dds_named = True
                log.warning("%s: a Fast DDS client (rmw_fastrtps_cpp) asked; it reads replies "
                            "by a sample identity Cyclone DDS cannot send "
                            "(ros2/rmw_cyclonedds#184), so it is not answered: run the node "
                            "with --transport rclpy on such a graph", service)

        def on_request(reader: DataReader) -> None:
            while samples := ddspy_take(reader._ref, ANY_STATE, 16):
                if isinstance(samples, int):
                    return
                for data, info in samples:
                    if not info.valid_data or self._from_fast_dds(reader,
                                                                  info.publication_handle):
                        continue
                    try:
                        header, cdr = split_request(data)
                        response = handler(ts.deserialize_cdr(cdr, rq_type))
                        reply = with_header(header, ts.serialize_cdr(response, rr_type))
                    except Exception as exc:  # a bad request must not stop it
                        log.warning("%s: dropped a request (%s)", service, exc)
                        continue
                    ddspy_write(writer._ref, reply)

        self._endpoint(DataReader, rq_topic, rq_type, SERVICES,
                       Listener(on_data_available=on_request, on_subscription_matched=on_match),
                       raw=True, extra=extra)

    def publishers(self, topic: str) -> list[Endpoint]:
        """Other participants' publishers on ``topic``, as DDS discovery reports them (the
        DCPSPublication built-in topic: type name and offered reliability and durability)."""
        name = dds_topic_name(topic, self.namespace)
        with self._lock:
            if self._closed:
                return []
            while found := self._discovered.take(N=256):
                for s in found:
                    alive = s.sample_info.valid_data and s.topic_name is not None
                    if not alive:
                        self._known.pop(s.key, None)
                    elif s.participant_key != self.participant.guid:
                        self._known[s.key] = s
            mine = [s for s in self._known.values() if s.topic_name == name]
        return [Endpoint(topic, ros_type_name(s.type_name), _offered(s.qos)) for s in mine]

    def _from_fast_dds(self, reader: DataReader, handle: int) -> bool:
        try:
            writer = reader.get_matched_publication_data(handle)
        except Exception:  # gone already: answer as usual
            return False
        return writer is not None and writer.participant_key.bytes[:2] == FAST_DDS_VENDOR

    def close(self) -> None:
        """Tell the graph the node is gone, then delete the participant (reliable writers linger
        up to 1 s for their last samples to be acknowledged, cyclonedds' default)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._announce(node=False)
            finally:
                for entity in [*self._readers, *self._writers, self._discovery, self._discovered,
                               *self._topics.values(), self.participant]:
                    entity.__del__()
                DOMAINS.release(self.domain_id)

    def __enter__(self) -> DdsTransport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _endpoint(self, kind: type, topic: str, msgtype: str, qos: RosQos,
                  listener: Listener | None = None, raw: bool = False,
                  extra: bytes = b"") -> Any:
        """A new DataWriter or DataReader of ``msgtype`` on ROS ``topic`` (``raw``: ``topic``
        is already a DDS topic name, of a service, whose samples carry rmw_cyclonedds_cpp's
        request header), announced; ``extra`` goes before the type hash in the USER_DATA."""
        with self._lock:
            name = topic if raw else dds_topic_name(topic, self.namespace)
            endpoint = kind(self.participant, self._topic(name, msgtype, raw),
                            qos=dds_qos(qos, extra + self._user_data(msgtype)),
                            listener=listener)
            (self._writers if kind is DataWriter else self._readers).append(endpoint)
            self._announce()
        return endpoint

    def _topic(self, name: str, msgtype: str, request_header: bool = False) -> Topic:
        """The participant's DDS topic ``name`` of ``msgtype`` (one topic may carry several
        types, each its own DDS topic of the same name: a reader matches writers of its type
        only)."""
        key = (name, msgtype)
        if key in self._topics:
            return self._topics[key]
        if self._closed:
            raise RuntimeError("the DDS transport is closed")
        topic = Topic(self.participant, name, idl_type(self.typestore, msgtype, request_header))
        self._topics[key] = topic
        return topic

    def _user_data(self, msgtype: str) -> bytes:
        """rmw's endpoint USER_DATA: ``typehash=RIHS01_<sha256 hex>;``."""
        return f"typehash={self.typestore.hash_rihs01(msgtype)};".encode()

    def _announce(self, node: bool = True) -> None:
        """Publish this participant's ParticipantEntitiesInfo: its GID and the node with the GIDs
        of its readers and writers (``node=False``: no node, as rmw does when a node goes)."""
        store = self.typestore
        size = len(message(store, GID_TYPE).data)   # 16 bytes from Jazzy on, 24 in Humble

        def as_gid(entity: Any) -> Any:
            return message(store, GID_TYPE, data=np.frombuffer(gid(entity).ljust(size, b"\0"),
                                                              dtype=np.uint8))

        nodes = [message(store, "rmw_dds_common/msg/NodeEntitiesInfo",
                         node_namespace=self.namespace, node_name=self.node_name,
                         reader_gid_seq=[as_gid(r) for r in self._readers],
                         writer_gid_seq=[as_gid(w) for w in self._writers])] if node else []
        info = message(store, DISCOVERY_TYPE, gid=as_gid(self.participant),
                       node_entities_info_seq=nodes)
        code = ddspy_write(self._discovery._ref,
                           padded(self.typestore.serialize_cdr(info, DISCOVERY_TYPE)))
        if code < 0:
            raise RuntimeError(f"DDS write on {DISCOVERY_TOPIC} failed (code {code})")


def _offered(qos: Any) -> RosQos:
    """The reliability and durability a discovered endpoint offers (depth: not announced)."""
    policies = list(qos) if qos is not None else []
    best_effort = any(p == Policy.Reliability.BestEffort for p in policies)
    transient = any(p in (Policy.Durability.TransientLocal, Policy.Durability.Transient,
                          Policy.Durability.Persistent) for p in policies)
    return RosQos(reliable=not best_effort, transient_local=transient, depth=0)
