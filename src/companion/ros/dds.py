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
import re
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.core import (
    DDSException,
    InstanceState,
    Listener,
    Policy,
    Qos,
    SampleState,
    ViewState,
)
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from companion.errors import ConfigError
from companion.ros.idl import idl_type
from companion.ros.messages import DEFAULT_DISTRO, message
from companion.ros.messages import typestore as distro_typestore
from companion.ros.transport import DEFAULT
from companion.ros.transport import Qos as RosQos

log = logging.getLogger(__name__)

#: The topic and type of rmw_dds_common's graph announcements.
DISCOVERY_TOPIC = "ros_discovery_info"
DISCOVERY_TYPE = "rmw_dds_common/msg/ParticipantEntitiesInfo"
GID_TYPE = "rmw_dds_common/msg/Gid"
#: rmw_dds_common's QoS for it: reliable, transient local, keep last 1 (a late joiner gets the
#: current state).
DISCOVERY_QOS = RosQos(reliable=True, transient_local=True, depth=1)
#: Highest DDS domain id whose ports fit the RTPS port formula (ROS 2 documents 0..232).
MAX_DOMAIN_ID = 232

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_TOPIC = re.compile(r"/?([A-Za-z_][A-Za-z0-9_]*)(/[A-Za-z_][A-Za-z0-9_]*)*")
_ANY = SampleState.Any | ViewState.Any | InstanceState.Any


def loopback_config() -> str:
    """cyclonedds configuration for one machine: the ``lo`` interface only, multicast off,
    participants found by unicast to 127.0.0.1 (ports of participant indices 0..9)."""
    return ("<CycloneDDS><Domain Id=\"any\"><General><Interfaces>"
            "<NetworkInterface name=\"lo\"/></Interfaces>"
            "<AllowMulticast>false</AllowMulticast></General>"
            "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
            "<Peers><Peer address=\"127.0.0.1\"/></Peers></Discovery></Domain></CycloneDDS>")


def ros_domain_id(value: int | str | None = None) -> int:
    """The DDS domain: ``value``, else ``$ROS_DOMAIN_ID``, else 0; 0..232."""
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


def dds_topic_name(topic: str, namespace: str = "/") -> str:
    """``'/cmd_vel'`` -> ``'rt/cmd_vel'``; a relative name is taken in ``namespace``."""
    if not _TOPIC.fullmatch(topic):
        raise ConfigError(f"topic: {topic!r} is not a ROS topic name; allowed: names of letters, "
                          "digits and underscores separated by '/', not starting with a digit")
    absolute = topic if topic.startswith("/") else f"{namespace.rstrip('/')}/{topic}"
    return "rt" + absolute


def dds_qos(qos: RosQos, user_data: bytes) -> Qos:
    """cyclonedds QoS of a ROS 2 profile as rmw_cyclonedds_cpp sets it: reliability, durability
    (transient local keeps ``depth`` samples for late joiners), keep-last history, XCDR1, no
    auto-dispose, and ``user_data``."""
    policies = [
        Policy.Reliability.Reliable(max_blocking_time=10**8) if qos.reliable
        else Policy.Reliability.BestEffort,
        Policy.History.KeepLast(qos.depth),
        Policy.DataRepresentation(use_cdrv0_representation=True),
        Policy.WriterDataLifecycle(autodispose=False),
        Policy.Userdata(data=user_data),
    ]
    if qos.transient_local:
        policies += [Policy.Durability.TransientLocal,
                     Policy.DurabilityService(cleanup_delay=0, history=Policy.History.KeepLast(
                         qos.depth), max_samples=-1, max_instances=-1,
                         max_samples_per_instance=-1)]
    else:
        policies.append(Policy.Durability.Volatile)
    return Qos(*policies)


class _Domains:
    """The process's cyclonedds domains with the configuration companion gave them: cyclonedds
    has one configuration per domain id and process, so transports on the same id share it."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.open: dict[int, tuple[Domain | None, str | None, int]] = {}

    def acquire(self, domain_id: int, config: str | None) -> None:
        with self.lock:
            if domain_id in self.open:
                domain, have, users = self.open[domain_id]
                if have != config:
                    raise ConfigError(f"dds_config: domain {domain_id} is already open in this "
                                      "process with another configuration; allowed: the same one")
                self.open[domain_id] = (domain, have, users + 1)
                return
            domain = None
            if config is not None:
                try:
                    domain = Domain(domain_id, config)
                except Exception as exc:   # cyclonedds raises its DDSException with the code
                    raise ConfigError(f"dds_config: cyclonedds refused the configuration of "
                                      f"domain {domain_id} ({exc})") from exc
            self.open[domain_id] = (domain, config, 1)

    def release(self, domain_id: int) -> None:
        """One user fewer; the domain (its sockets and threads) goes with the last one, unless
        participants made outside companion still use it (deleting it would delete them)."""
        with self.lock:
            domain, config, users = self.open[domain_id]
            if users > 1 or (domain is not None and domain.get_participants()):
                self.open[domain_id] = (domain, config, max(users - 1, 0))
                return
            del self.open[domain_id]
            if domain is not None:
                domain.__del__()


_DOMAINS = _Domains()


def padded(cdr: bytes) -> bytes:
    """CDR bytes with zeros up to a multiple of 4, as rmw_cyclonedds_cpp sends them (cyclonedds
    sends whole 4-byte words; unpadded, the last word's tail would be whatever memory held)."""
    return bytes(cdr) + b"\0" * (-len(cdr) % 4)


def gid(entity: Any) -> bytes:
    """The 16 bytes of an entity's DDS GUID, which rmw uses as its GID."""
    return entity.guid.bytes


class DdsTransport:
    """One ROS 2 node ``namespace/node_name`` on its own DDS participant in ``domain_id``
    (None: ``$ROS_DOMAIN_ID`` or 0), speaking the messages of ``typestore`` (default: that of
    ``distro``). ``config`` is a cyclonedds XML configuration (or a file URI); None means
    ``$CYCLONEDDS_URI`` if it is set, else :func:`loopback_config`. Callbacks of subscriptions
    run on cyclonedds' receive threads."""

    def __init__(self, node_name: str = "companion", namespace: str = "/",
                 domain_id: int | str | None = None, distro: str = DEFAULT_DISTRO,
                 typestore: Any = None, config: str | None = None):
        if not _NAME.fullmatch(node_name):
            raise ConfigError(f"node_name: {node_name!r} is not a ROS node name; allowed: "
                              "letters, digits and underscores, not starting with a digit")
        if namespace != "/" and not (namespace.startswith("/")
                                     and _TOPIC.fullmatch(namespace.rstrip("/"))):
            raise ConfigError(f"namespace: {namespace!r} is not a ROS namespace; allowed: '/' "
                              "or an absolute name such as '/robot1'")
        self.node_name, self.namespace = node_name, namespace.rstrip("/") or "/"
        self.typestore = typestore if typestore is not None else distro_typestore(distro)
        self.domain_id = ros_domain_id(domain_id)
        source = "dds_config"
        if config is None:
            source = "CYCLONEDDS_URI" if os.environ.get("CYCLONEDDS_URI") else "loopback"
            config = None if source == "CYCLONEDDS_URI" else loopback_config()
        _DOMAINS.acquire(self.domain_id, config)
        self._lock = threading.RLock()
        self._topics: dict[str, tuple[str, Topic]] = {}
        self._readers: list[DataReader] = []
        self._writers: list[DataWriter] = []
        self._closed = False
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
            self._announce()
        except BaseException:
            if hasattr(self, "participant"):
                self.participant.__del__()
            _DOMAINS.release(self.domain_id)
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
            while samples := ddspy_take(reader._ref, _ANY, 64):
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
                for entity in [*self._readers, *self._writers, self._discovery,
                               *(topic for _, topic in self._topics.values()), self.participant]:
                    entity.__del__()
                _DOMAINS.release(self.domain_id)

    def __enter__(self) -> DdsTransport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _endpoint(self, kind: type, topic: str, msgtype: str, qos: RosQos,
                  listener: Listener | None = None) -> Any:
        """A new DataWriter or DataReader of ``msgtype`` on ROS ``topic``, announced."""
        with self._lock:
            endpoint = kind(self.participant, self._topic(dds_topic_name(topic, self.namespace),
                            msgtype), qos=dds_qos(qos, self._user_data(msgtype)),
                            listener=listener)
            (self._writers if kind is DataWriter else self._readers).append(endpoint)
            self._announce()
        return endpoint

    def _topic(self, name: str, msgtype: str) -> Topic:
        """The participant's DDS topic ``name`` of ``msgtype``; one type per topic."""
        if name in self._topics:
            have, topic = self._topics[name]
            if have != msgtype:
                raise ConfigError(f"topic: {name[2:] if name.startswith('rt/') else name} is "
                                  f"already {have} in this node; allowed: one type per topic")
            return topic
        if self._closed:
            raise RuntimeError("the DDS transport is closed")
        topic = Topic(self.participant, name, idl_type(self.typestore, msgtype))
        self._topics[name] = (msgtype, topic)
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
