"""The parts of the DDS transport that are DDS and rmw conventions rather than a node: the
loopback configuration, ROS names as DDS names, ROS QoS as DDS QoS, the process's cyclonedds
domains, CDR padding, GIDs, and rmw_cyclonedds_cpp's service request header
(:mod:`companion.ros.dds` uses them; docs/ros-dds.md)."""

from __future__ import annotations

import re
import struct
import threading
from pathlib import Path
from typing import Any

from cyclonedds.core import InstanceState, Policy, Qos, SampleState, ViewState
from cyclonedds.domain import Domain

from companion.errors import ConfigError
from companion.ros.transport import Qos as RosQos

#: The topic and type of rmw_dds_common's graph announcements.
DISCOVERY_TOPIC = "ros_discovery_info"
DISCOVERY_TYPE = "rmw_dds_common/msg/ParticipantEntitiesInfo"
GID_TYPE = "rmw_dds_common/msg/Gid"
#: rmw_dds_common's QoS for it: reliable, transient local, keep last 1 (a late joiner gets the
#: current state).
DISCOVERY_QOS = RosQos(reliable=True, transient_local=True, depth=1)

NODE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
TOPIC_NAME = re.compile(r"/?([A-Za-z_][A-Za-z0-9_]*)(/[A-Za-z_][A-Za-z0-9_]*)*")
ANY_STATE = SampleState.Any | ViewState.Any | InstanceState.Any


#: The loopback configurations companion ships for Cyclone DDS and Fast DDS (docs/ros2.md).
LOOPBACK = Path(__file__).with_name("loopback")


def loopback_config() -> str:
    """cyclonedds configuration for one machine (``loopback/cyclonedds.xml``): the ``lo``
    interface only, multicast off, participants found by unicast to 127.0.0.1 (the ports of
    participant indices 0..32)."""
    return (LOOPBACK / "cyclonedds.xml").read_text(encoding="utf-8")


def dds_topic_name(topic: str, namespace: str = "/") -> str:
    """``'/cmd_vel'`` -> ``'rt/cmd_vel'``; a relative name is taken in ``namespace``."""
    if not TOPIC_NAME.fullmatch(topic):
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


DOMAINS = _Domains()


def padded(cdr: bytes) -> bytes:
    """CDR bytes with zeros up to a multiple of 4, as rmw_cyclonedds_cpp sends them (cyclonedds
    sends whole 4-byte words; unpadded, the last word's tail would be whatever memory held)."""
    return bytes(cdr) + b"\0" * (-len(cdr) % 4)


def gid(entity: Any) -> bytes:
    """The 16 bytes of an entity's DDS GUID, which rmw uses as its GID."""
    return entity.guid.bytes



#: rmw_cyclonedds_cpp's service header (serdata.hpp, ``cdds_request_header_t``): the client's
#: 64-bit id and the request's sequence number, before the request or response in the CDR
#: stream (after the 4-byte encapsulation header).
REQUEST_HEADER = struct.Struct("<Qq")


def service_topics(service: str, srvtype: str) -> tuple[str, str, str, str]:
    """``(request topic, request type, reply topic, reply type)`` of a ROS service as rmw
    names them: ``/companion/get_parameters`` -> ``rq/companion/get_parametersRequest`` and
    ``rr/companion/get_parametersReply``, of ``<srv>_Request`` and ``<srv>_Response``."""
    name = dds_topic_name(service)[2:]
    return f"rq{name}Request", f"{srvtype}_Request", f"rr{name}Reply", f"{srvtype}_Response"


def split_request(data: bytes) -> tuple[bytes, bytes]:
    """``(header, CDR of the request)`` of a request sample: the 16 header bytes and the
    request with its encapsulation header; ValueError if the sample is too short."""
    if len(data) < 4 + REQUEST_HEADER.size:
        raise ValueError(f"a service request of {len(data)} bytes has no request header")
    end = 4 + REQUEST_HEADER.size
    return bytes(data[4:end]), bytes(data[:4]) + bytes(data[end:])


def with_header(header: bytes, cdr: bytes) -> bytes:
    """A reply sample: ``cdr``'s encapsulation header, the request's ``header``, the body."""
    return padded(bytes(cdr[:4]) + header + bytes(cdr[4:]))
