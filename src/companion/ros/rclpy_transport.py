"""A transport on rclpy: the node as a node of the robot's own ROS 2, on whatever RMW that
runs (``--transport rclpy``; docs/ros2.md).

companion speaks DDS and Zenoh itself (:mod:`companion.ros.dds`, :mod:`companion.ros.zenoh`),
but one thing cannot cross from Cyclone DDS to Fast DDS: a service reply, which Fast DDS's
clients (rmw_fastrtps_cpp, Jazzy's default) match by a sample identity that Cyclone DDS does
not send (ros2/rmw_cyclonedds#184). On a Fast DDS graph, this transport is how ``ros2 param``
reaches the node. Messages still come from rosbags' typestore: they cross rclpy as CDR bytes
(``raw`` subscriptions, serialised publishing), and requests and responses are converted the
same way, so the node and its parameter server are the same code on every transport. It needs
rclpy and the Python packages of the message types it uses (a ROS 2 install, or the ``ros``
extra); a type whose package is missing is named once and its topic is left out.
"""

from __future__ import annotations

import importlib
import logging
import threading
from collections.abc import Callable
from typing import Any

from companion.errors import TransportError
from companion.ros.messages import DEFAULT_DISTRO, typestore
from companion.ros.transport import DEFAULT, Endpoint, Qos

log = logging.getLogger(__name__)


def decode(store: Any, data: bytes, msgtype: str) -> Any:
    """A message of rclpy's CDR bytes. rclpy's serialiser hands over its whole buffer, which
    may end past the message (seen: 4 to 8 bytes, not always zeros), more than the 3 bytes of
    padding rosbags' ``deserialize_cdr`` allows; the message is read from the start with
    rosbags' own deserialiser and the rest is ignored."""
    data = bytes(data)
    if len(data) < 4 or data[:2] not in (b"\0\0", b"\0\1"):
        raise ValueError(f"{msgtype}: not CDR (encapsulation {data[:4].hex()})")
    msgdef = store.get_msgdef(msgtype)
    read = msgdef.deserialize_cdr_le if data[1] else msgdef.deserialize_cdr_be
    message, _ = read(data[4:], 0, msgdef.cls, store)
    return message


def ros_class(name: str) -> Any:
    """The rclpy class of ``pkg/msg/Name`` or ``pkg/srv/Name``; ImportError naming the
    package if it is not installed."""
    package, kind, type_name = name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), type_name)


class RclpyTransport:
    """One rclpy node ``namespace/node_name`` on ``domain_id``, in its own rclpy context,
    spun by one executor thread (every callback runs there)."""

    #: A topic takes one type in a node (Fast DDS refuses a second type on a topic name).
    multi_type_topics = False

    def __init__(self, node_name: str = "companion", namespace: str = "/",
                 domain_id: int = 0, distro: str = DEFAULT_DISTRO):
        try:
            import rclpy
            from rclpy.executors import SingleThreadedExecutor
        except ImportError as exc:
            raise TransportError(f"rclpy: not installed ({exc}); source your ROS 2 set-up or "
                                 f"pip install -e '.[ros]'") from None
        self.typestore = typestore(distro)
        self._rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(node_name, namespace=namespace, context=self.context,
                                      start_parameter_services=False, enable_rosout=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name="rclpy-executor", daemon=True)
        self._thread.start()
        self._missing: set[str] = set()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:  # the context was shut down under it: the transport is closing
            log.debug("rclpy: the executor stopped", exc_info=True)

    def _class(self, name: str) -> Any | None:
        try:
            return ros_class(name)
        except (ImportError, AttributeError) as exc:
            if name not in self._missing:
                self._missing.add(name)
                log.warning("rclpy: %s has no Python package here (%s); its topic is left out",
                            name, exc)
            return None

    def _qos(self, qos: Qos) -> Any:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(qos.depth, 1),
                          reliability=ReliabilityPolicy.RELIABLE if qos.reliable
                          else ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL if qos.transient_local
                          else DurabilityPolicy.VOLATILE)

    def publisher(self, topic: str, msgtype: str, qos: Qos = DEFAULT) -> Callable[[Any], None]:
        cls = self._class(msgtype)
        if cls is None:
            return lambda msg: None
        pub = self.node.create_publisher(cls, topic, self._qos(qos))
        serialize = self.typestore.serialize_cdr

        def publish(msg: Any) -> None:
            pub.publish(bytes(serialize(msg, msgtype)))
        return publish

    def subscribe(self, topic: str, msgtype: str, callback: Callable[[Any], None],
                  qos: Qos = DEFAULT) -> None:
        cls = self._class(msgtype)
        if cls is None:
            return
        store = self.typestore

        def on_raw(data: bytes) -> None:
            try:
                msg = decode(store, data, msgtype)
            except Exception as exc:
                log.warning("rclpy: dropped a %s on %s that does not decode (%s)", msgtype,
                            topic, exc)
                return
            try:
                callback(msg)
            except Exception:
                log.exception("rclpy: the callback of %s raised", topic)

        self.node.create_subscription(cls, topic, on_raw, self._qos(qos), raw=True)

    def serve(self, service: str, srvtype: str, handler: Callable[[Any], Any]) -> None:
        from rclpy.serialization import deserialize_message, serialize_message

        cls = self._class(srvtype)
        if cls is None:
            return
        ts = self.typestore

        def on_request(request: Any, response: Any) -> Any:
            try:
                ours = decode(ts, serialize_message(request), f"{srvtype}_Request")
                answer = ts.serialize_cdr(handler(ours), f"{srvtype}_Response")
                return deserialize_message(bytes(answer), cls.Response)
            except Exception:
                log.exception("rclpy: %s could not answer", service)
                return response

        self.node.create_service(cls, service, on_request)

    def publishers(self, topic: str) -> list[Endpoint]:
        from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

        me = (self.node.get_name(), self.node.get_namespace())
        return [Endpoint(topic, info.topic_type, Qos(
                    info.qos_profile.reliability != ReliabilityPolicy.BEST_EFFORT,
                    info.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL, 0))
                for info in self.node.get_publishers_info_by_topic(topic)
                if (info.node_name, info.node_namespace) != me]

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        if self.context.ok():
            self._rclpy.shutdown(context=self.context)
        self._thread.join(timeout=2.0)
