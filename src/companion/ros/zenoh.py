"""A ROS 2 node on Zenoh, as rmw_zenoh_cpp makes one, through eclipse-zenoh (no ROS install).

One :class:`ZenohTransport` is one rmw_zenoh context with one node: a Zenoh peer session
configured as rmw_zenoh's default session (:func:`companion.ros.rmw_zenoh.session_config`),
a liveliness token for the node and one for each publisher and subscription, samples on
rmw_zenoh's key expressions with CDR payloads (encapsulation header first, as rosbags writes
it) and rmw_zenoh's attachment. Formats and their sources: :mod:`companion.ros.rmw_zenoh`.

rmw_zenoh nodes find each other through a Zenoh router (``ros2 run rmw_zenoh_cpp rmw_zenohd``,
or ``zenohd``), by default at ``tcp/localhost:7447``; so does this transport. Beside a robot,
pass the robot's router as ``connect=["tcp/<robot address>:7447"]``. The session listens on
the loopback interface only unless ``listen`` says otherwise, and never uses multicast.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh
import zenoh.ext

from companion.ros import rmw_zenoh as wire
from companion.ros.messages import DEFAULT_DISTRO, dds_type_name, typestore
from companion.ros.transport import DEFAULT, Endpoint, Qos

log = logging.getLogger(__name__)

# rmw_zenoh's heartbeat period for RELIABLE + TRANSIENT_LOCAL publishers, ms
# (src/detail/rmw_publisher_data.cpp, SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD).
_HEARTBEAT_MS = 500


def open_session(connect: list[str], listen: list[str], mode: str = "peer") -> zenoh.Session:
    """A Zenoh session with rmw_zenoh's default settings and these endpoints; a
    ``ConnectionError`` naming the endpoints if a client finds no router."""
    config = zenoh.Config()
    for key, value in wire.session_config(connect, listen, mode).items():
        config.insert_json5(key, json.dumps(value))
    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        raise ConnectionError(f"zenoh: cannot open a {mode} session connecting to "
                              f"{', '.join(connect) or 'nothing'} and listening on "
                              f"{', '.join(listen) or 'nothing'}: {exc}") from exc


class ZenohTransport:
    """One node on a ROS 2 graph of rmw_zenoh nodes (the :class:`Transport` contract).

    Parameters
    ----------
    node_name, namespace, domain_id, enclave
        The node as ``ros2 node list`` shows it (``/companion``), and its ROS domain.
    distro
        Which ROS 2 distribution's message definitions and type hashes to use.
    connect
        Zenoh endpoints to connect to; ``None``: rmw_zenoh's router on this computer
        (``tcp/127.0.0.1:7447``). An absent router is retried in the background.
    listen
        Endpoints this session accepts peers on; ``None``: the loopback interface, any port.
    mode
        ``"peer"`` (rmw_zenoh's) or ``"client"``: all traffic through the router of
        ``connect``, no listening socket; for a router on another computer whose nodes
        listen on their own loopback only (rmw_zenoh's default), which a peer cannot reach.
    """

    def __init__(self, node_name: str = "companion", namespace: str = "/", domain_id: int = 0,
                 distro: str = DEFAULT_DISTRO, connect: list[str] | None = None,
                 listen: list[str] | None = None, enclave: str = "/", mode: str = "peer"):
        wire.check_names(node_name, namespace)
        self.typestore = typestore(distro)
        self.distro, self.domain_id = distro, domain_id
        self.connect = [wire.DEFAULT_ROUTER] if connect is None else list(connect)
        self.listen = ([] if mode == "client" else [wire.DEFAULT_LISTEN] if listen is None
                       else list(listen))
        self.session = open_session(self.connect, self.listen, mode)
        self.zid = str(self.session.zid())
        self._lock = threading.Lock()
        self._closed = False
        self._next_id = 0
        self._declared: list[Any] = []      # publishers, subscribers, tokens: undeclared on close
        self.dropped = 0                    # samples received that did not decode
        self._graph: dict[str, tuple] = {}          # other nodes' tokens seen, by key
        # rmw_zenoh numbers the node and its entities from one counter per context, node first
        # (src/detail/rmw_context_impl_s.cpp, get_next_entity_id).
        node_id = self._new_id()
        self.node = wire.Entity(domain_id, self.zid, node_id, node_id, wire.NODE, enclave,
                                namespace, node_name)
        self._declare_token(self.node)
        # the graph (publishers()): other nodes' tokens, those already there first (this waits
        # for the router's answer, so it is done here, not when a node's period asks)
        self._keep(self.session.liveliness().declare_subscriber(
            f"{wire.ADMIN_SPACE}/{domain_id}/**", self._on_token, history=True))

    def publisher(self, topic: str, msgtype: str, qos: Qos = DEFAULT) -> Callable[[Any], None]:
        """A function publishing ``msgtype`` messages on ``topic`` as an rmw_zenoh publisher
        (src/detail/rmw_publisher_data.cpp): reliable or best effort as ``qos`` says, dropping
        rather than blocking when congested, a cache of ``depth`` samples for late subscribers
        when transient local; each sample carries sequence number (from 1), source time and
        the publisher's GID."""
        entity = self._entity(wire.PUBLISHER, topic, msgtype, qos)
        key = wire.topic_keyexpr(self.domain_id, topic, msgtype, entity.type_hash)
        options = {"reliability": zenoh.Reliability.RELIABLE if qos.reliable
                   else zenoh.Reliability.BEST_EFFORT,
                   "congestion_control": zenoh.CongestionControl.DROP}
        if qos.transient_local:
            miss = (zenoh.ext.MissDetectionConfig(sporadic_heartbeat=_HEARTBEAT_MS / 1000)
                    if qos.reliable else None)
            pub = zenoh.ext.declare_advanced_publisher(
                self.session, key, cache=zenoh.ext.CacheConfig(max_samples=_depth(qos)),
                sample_miss_detection=miss, publisher_detection=True, **options)
        else:
            pub = self.session.declare_publisher(key, **options)
        self._keep(pub)
        self._declare_token(entity)
        gid, serialize = entity.gid(), self.typestore.serialize_cdr
        counter = iter(range(1, 2**63))
        lock = threading.Lock()

        def publish(msg: Any) -> None:
            payload = bytes(serialize(msg, msgtype))
            with lock:
                attachment = wire.attachment(next(counter), time.time_ns(), gid)
                pub.put(payload, attachment=attachment)
        return publish

    def subscribe(self, topic: str, msgtype: str, callback: Callable[[Any], None],
                  qos: Qos = DEFAULT) -> None:
        """Call ``callback(message)`` (on a Zenoh thread) for every ``msgtype`` sample on
        ``topic``, as an rmw_zenoh subscription (src/detail/rmw_subscription_data.cpp): on the
        topic's key expression, which holds the type hash, so only publishers of the same type
        definition match; transient local subscriptions ask publishers for their cache. A sample
        that does not decode is counted in :attr:`dropped` and logged; an exception from
        ``callback`` is logged; neither is raised on the Zenoh thread."""
        entity = self._entity(wire.SUBSCRIPTION, topic, msgtype, qos)
        key = wire.topic_keyexpr(self.domain_id, topic, msgtype, entity.type_hash)
        deserialize = self.typestore.deserialize_cdr

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                msg = deserialize(sample.payload.to_bytes(), msgtype)
            except Exception as exc:  # a malformed sample must not kill the Zenoh thread
                with self._lock:
                    self.dropped += 1
                log.warning("zenoh: dropped a sample on %s that is not a %s: %s",
                            sample.key_expr, msgtype, exc)
                return
            try:
                callback(msg)
            except Exception:  # nobody up this thread to raise to: log it
                log.exception("zenoh: the callback of %s raised", topic)

        if qos.transient_local:
            history = zenoh.ext.HistoryConfig(detect_late_publishers=True,
                                              max_samples=_depth(qos))
            recovery = zenoh.ext.RecoveryConfig(heartbeat=True) if qos.reliable else None
            sub = zenoh.ext.declare_advanced_subscriber(
                self.session, key, in_order(on_sample), history=history, recovery=recovery,
                subscriber_detection=True)
        else:
            sub = self.session.declare_subscriber(key, in_order(on_sample))
        self._keep(sub)
        self._declare_token(entity)

    def serve(self, service: str, srvtype: str, handler: Callable[[Any], Any]) -> None:
        """Answer ``service`` as an rmw_zenoh service (src/detail/rmw_service_data.cpp): a
        complete queryable on the service's key expression (its type is the service type,
        ``pkg::srv::dds_::Name_``, with the service type's hash) and an ``SS`` token; each
        query carries the request's CDR and the client's attachment (sequence number, time,
        GID), and the reply carries the response with that sequence number and GID. A query
        that does not decode, or a handler that raises, is logged and not answered."""
        wire.check_topic(service)
        node = self.node
        entity = wire.Entity(self.domain_id, self.zid, node.node_id, self._new_id(),
                             wire.SERVICE, node.enclave, node.namespace, node.node_name,
                             service, dds_type_name(srvtype),
                             wire.wire_service_hash(srvtype, self.distro), Qos(depth=10))
        key = wire.topic_keyexpr(self.domain_id, service, srvtype, entity.type_hash)
        ts = self.typestore

        def on_query(query: zenoh.Query) -> None:
            try:
                seq, _, gid = wire.parse_attachment(query.attachment.to_bytes())
                request = ts.deserialize_cdr(query.payload.to_bytes(), f"{srvtype}_Request")
                response = bytes(ts.serialize_cdr(handler(request), f"{srvtype}_Response"))
            except Exception as exc:  # a bad query must not kill the Zenoh thread
                log.warning("zenoh: %s: a request was not answered (%s)", service, exc)
                return
            query.reply(key, response, attachment=wire.attachment(seq, time.time_ns(), gid))

        self._keep(self.session.declare_queryable(key, on_query, complete=True))
        self._declare_token(entity)

    def publishers(self, topic: str) -> list[Endpoint]:
        """Other nodes' publishers on ``topic``, as their liveliness tokens announce them
        (type and QoS)."""
        with self._lock:
            found = list(self._graph.values())
        return [Endpoint(t, msgtype, qos) for zid, kind, t, msgtype, qos in found
                if kind == wire.PUBLISHER and t == topic and zid != self.zid]

    def _on_token(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        token = wire.parse_token(key)
        with self._lock:
            if sample.kind == zenoh.SampleKind.DELETE:
                self._graph.pop(key, None)
            elif token is not None:
                self._graph[key] = token

    def close(self) -> None:
        """Undeclare every publisher, subscriber and token (ending the subscribers' callback
        threads), then close the session. Safe to call twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            declared, self._declared = self._declared[::-1], []
        for item in declared:
            try:
                item.undeclare()
            except zenoh.ZError as exc:  # already gone with a broken session: nothing to free
                log.debug("zenoh: undeclare failed: %s", exc)
        self.session.close()

    def __enter__(self) -> ZenohTransport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _new_id(self) -> int:
        with self._lock:
            self._next_id += 1
            return self._next_id - 1

    def _entity(self, kind: str, topic: str, msgtype: str, qos: Qos) -> wire.Entity:
        wire.check_topic(topic)
        if self._closed:
            raise RuntimeError("ZenohTransport is closed")
        node = self.node
        return wire.Entity(self.domain_id, self.zid, node.node_id, self._new_id(), kind,
                           node.enclave, node.namespace, node.node_name, topic,
                           dds_type_name(msgtype), wire.wire_type_hash(msgtype, self.distro),
                           Qos(qos.reliable, qos.transient_local, _depth(qos)))

    def _declare_token(self, entity: wire.Entity) -> None:
        self._keep(self.session.liveliness().declare_token(entity.liveliness_keyexpr()))

    def _keep(self, declared: Any) -> None:
        with self._lock:
            self._declared.append(declared)


def _depth(qos: Qos) -> int:
    """The depth rmw_zenoh uses: 0 (system default) becomes its default, 42."""
    return qos.depth or wire.DEFAULT_DEPTH


def in_order(on_sample: Callable[[zenoh.Sample], None]) -> zenoh.handlers.Callback:
    """``on_sample`` run on the Zenoh thread that receives the sample, not on a Python thread
    of its subscription (eclipse-zenoh's default): samples from one peer then reach their
    callbacks in the order they arrived, across topics, as a period's /odom and /person before
    its /clock (a node in lock step ticks on that /clock). Callbacks must be short."""
    return zenoh.handlers.Callback(on_sample, indirect=False)
