"""The Zenoh transport against rmw_zenoh_cpp's wire format, on loopback only.

Expected strings and bytes are written out here from rmw_zenoh's Jazzy source (rmw_zenoh_cpp
0.2.9: src/detail/liveliness_utils.cpp for keys and tokens, src/detail/qos.cpp for the QoS
defaults, src/detail/attachment_helpers.cpp with zenoh-cpp's ext::Serializer for attachments),
not from companion's code. Every session listens on 127.0.0.1, connects only to 127.0.0.1 and
has multicast scouting off; every wait is bounded.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest
import xxhash
import zenoh
import zenoh.ext

from companion.errors import ConfigError
from companion.ros import rmw_zenoh as wire
from companion.ros.messages import message, typestore
from companion.ros.transport import DEFAULT, SENSOR_DATA, Qos
from companion.ros.zenoh import ZenohTransport

TS = typestore("jazzy")
T = TS.types
TWIST = "geometry_msgs/msg/Twist"
TWIST_TYPE = "geometry_msgs::msg::dds_::Twist_"
# std_msgs/msg/String's hash as rmw_zenoh's design document and ros2 topic info show it.
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
WAIT = 5.0                                   # s, the longest any test waits for the wire


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def raw_session(connect_port: int) -> zenoh.Session:
    """A plain Zenoh peer (no companion code) connected to a transport on loopback."""
    config = zenoh.Config()
    for key, value in {"mode": "peer", "scouting/multicast/enabled": False,
                       "listen/endpoints": ["tcp/127.0.0.1:0"],
                       "connect/endpoints": [f"tcp/127.0.0.1:{connect_port}"]}.items():
        config.insert_json5(key, json.dumps(value))
    return zenoh.open(config)


def until(condition, action=None, timeout=WAIT, period=0.05) -> bool:
    """Repeat ``action`` until ``condition()`` holds or ``timeout`` s pass."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if action is not None:
            action()
        if condition():
            return True
        time.sleep(period)
    return condition()


@pytest.fixture
def port():
    return free_port()


@pytest.fixture
def listener(port):
    """A transport that listens on a known loopback port (and connects to nothing)."""
    with ZenohTransport("listener", connect=[], listen=[f"tcp/127.0.0.1:{port}"]) as t:
        yield t


@pytest.fixture
def talker(port, listener):
    with ZenohTransport("talker", connect=[f"tcp/127.0.0.1:{port}"]) as t:
        yield t


# -- the strings rmw_zenoh builds --------------------------------------------------------------

def test_data_key_expressions_are_rmw_zenohs():
    twist_hash = wire.wire_type_hash(TWIST, "jazzy")
    assert wire.topic_keyexpr(0, "/cmd_vel", TWIST, twist_hash) == \
        f"0/cmd_vel/{TWIST_TYPE}/{twist_hash}"
    assert wire.topic_keyexpr(7, "/robot1/scan", "sensor_msgs/msg/LaserScan", "H") == \
        "7/robot1/scan/sensor_msgs::msg::dds_::LaserScan_/H"
    assert wire.wire_type_hash("std_msgs/msg/String", "jazzy") == STRING_HASH
    assert wire.wire_type_hash("std_msgs/msg/String", "humble") == "TypeHashNotSupported"


@pytest.mark.parametrize("qos, expected", [
    (DEFAULT, "::,10:,:,:,,"),                   # rclpy default: reliable, volatile, depth 10
    (SENSOR_DATA, "2::,5:,:,:,,"),               # best effort (2), depth 5
    (Qos(transient_local=True, depth=1), ":1:,1:,:,:,,"),   # transient local (1)
    (Qos(depth=42), "::,:,:,:,,"),               # rmw_zenoh's own default depth is left out
    (Qos(depth=0), "::,:,:,:,,"),                # depth 0 means rmw_zenoh's default, 42
])
def test_qos_strings_are_rmw_zenohs(qos, expected):
    assert wire.qos_keyexpr(qos) == expected


def test_liveliness_tokens_are_rmw_zenohs():
    zid, h = "1f2e3d", wire.wire_type_hash(TWIST, "jazzy")
    node = wire.Entity(0, zid, 0, 0, wire.NODE, "/", "/", "companion")
    assert node.liveliness_keyexpr() == "@ros2_lv/0/1f2e3d/0/0/NN/%/%/companion"
    pub = wire.Entity(0, zid, 0, 3, wire.PUBLISHER, "/", "/", "companion", "/cmd_vel",
                      TWIST_TYPE, h, DEFAULT)
    assert pub.liveliness_keyexpr() == \
        f"@ros2_lv/0/1f2e3d/0/3/MP/%/%/companion/%cmd_vel/{TWIST_TYPE}/{h}/::,10:,:,:,,"
    sub = wire.Entity(5, zid, 2, 4, wire.SUBSCRIPTION, "/", "/robot1", "companion",
                      "/robot1/scan", "sensor_msgs::msg::dds_::LaserScan_", "H", SENSOR_DATA)
    assert sub.liveliness_keyexpr() == ("@ros2_lv/5/1f2e3d/2/4/MS/%/%robot1/companion/"
                                        "%robot1%scan/sensor_msgs::msg::dds_::LaserScan_/H/"
                                        "2::,5:,:,:,,")


def test_gid_is_xxh3_128_of_the_token_low_half_first():
    entity = wire.Entity(0, "ab", 0, 1, wire.PUBLISHER, "/", "/", "n", "/t", "T", "H", DEFAULT)
    digest = xxhash.xxh3_128(entity.liveliness_keyexpr().encode()).digest()  # big-endian
    high, low = digest[:8], digest[8:]
    assert entity.gid() == low[::-1] + high[::-1]         # memcpy of low64, high64 on x86
    assert len(entity.gid()) == 16


def test_attachment_is_zenoh_serializers_int64_int64_array16():
    gid = bytes(range(100, 116))
    data = wire.attachment(7, 1_700_000_000_123_456_789, gid)
    expected = ((7).to_bytes(8, "little") + (1_700_000_000_123_456_789).to_bytes(8, "little")
                + bytes([16]) + gid)
    assert data == expected
    # zenoh's own serializer writes std::array<uint8_t, 16> as a sequence the same way
    ze = zenoh.ext
    assert data == ze.z_serialize((ze.Int64(7), ze.Int64(1_700_000_000_123_456_789),
                                   [ze.UInt8(b) for b in gid])).to_bytes()
    assert wire.parse_attachment(data) == (7, 1_700_000_000_123_456_789, gid)
    with pytest.raises(ValueError):
        wire.parse_attachment(data[:-1])
    with pytest.raises(ValueError):
        wire.attachment(1, 2, gid[:8])


def test_session_config_is_loopback_peer_without_multicast():
    config = wire.session_config([wire.DEFAULT_ROUTER], [wire.DEFAULT_LISTEN])
    assert config["mode"] == "peer"
    assert config["scouting/multicast/enabled"] is False
    assert config["connect/endpoints"] == ["tcp/127.0.0.1:7447"]
    assert config["listen/endpoints"] == ["tcp/127.0.0.1:0"]


@pytest.mark.parametrize("kwargs, word", [({"node_name": "9lives"}, "node_name"),
                                          ({"namespace": "robot1"}, "namespace"),
                                          ({"distro": "rolling"}, "distro")])
def test_bad_names_are_one_line_config_errors(kwargs, word):
    with pytest.raises(ConfigError, match=word) as err:
        ZenohTransport(connect=[], listen=["tcp/127.0.0.1:0"], **kwargs)
    assert "\n" not in str(err.value)


def test_relative_topic_is_a_config_error(listener):
    with pytest.raises(ConfigError, match="cmd_vel"):
        listener.publisher("cmd_vel", TWIST)


# -- on the wire -------------------------------------------------------------------------------

def header(sec=12, frame="odom"):
    return T["std_msgs/msg/Header"](T["builtin_interfaces/msg/Time"](sec, 345), frame)


def vec(x, y, z):
    return T["geometry_msgs/msg/Vector3"](x, y, z)


def pose(x, y, yaw):
    return T["geometry_msgs/msg/Pose"](T["geometry_msgs/msg/Point"](x, y, 0.0),
                                       T["geometry_msgs/msg/Quaternion"](
                                           0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)))


MESSAGES = {
    TWIST: T[TWIST](vec(0.4, 0.0, 0.0), vec(0.0, 0.0, -0.25)),
    "nav_msgs/msg/Odometry": T["nav_msgs/msg/Odometry"](
        header(), "base_link",
        T["geometry_msgs/msg/PoseWithCovariance"](pose(1.5, -2.0, 0.3),
                                                  np.arange(36, dtype=np.float64)),
        T["geometry_msgs/msg/TwistWithCovariance"](T[TWIST](vec(0.5, 0, 0), vec(0, 0, 0.1)),
                                                   np.eye(6).ravel())),
    "sensor_msgs/msg/LaserScan": T["sensor_msgs/msg/LaserScan"](
        header(frame="laser"), -np.pi, np.pi, 2 * np.pi / 360, 0.0, 0.1, 0.05, 12.0,
        np.linspace(0.5, 11.0, 360, dtype=np.float32), np.zeros(0, dtype=np.float32)),
    "geometry_msgs/msg/PoseArray": T["geometry_msgs/msg/PoseArray"](
        header(), [pose(2.0, 1.0, 0.0), pose(-1.0, 3.5, 1.2)]),
}


def test_two_transports_exchange_messages_equal_after_the_trip(listener, talker):
    for i, (msgtype, msg) in enumerate(MESSAGES.items()):
        topic = f"/t{i}"
        got, event = [], threading.Event()
        qos = SENSOR_DATA if msgtype.startswith("sensor_msgs") else DEFAULT
        listener.subscribe(topic, msgtype, lambda m, g=got, e=event: (g.append(m), e.set()), qos)
        publish = talker.publisher(topic, msgtype, qos)
        assert until(event.is_set, lambda p=publish, m=msg: p(m)), msgtype
        assert bytes(TS.serialize_cdr(got[0], msgtype)) == bytes(TS.serialize_cdr(msg, msgtype))
    scan = MESSAGES["sensor_msgs/msg/LaserScan"]
    assert scan.ranges.dtype == np.float32 and len(scan.ranges) == 360


def test_plain_zenoh_subscriber_sees_rmw_zenohs_key_attachment_and_cdr(port, listener):
    raw = raw_session(port)
    try:
        samples = []
        sub = raw.declare_subscriber("0/cmd_vel/**", samples.append)
        msg = MESSAGES[TWIST]
        publish = listener.publisher("/cmd_vel", TWIST)
        t0 = time.time_ns()
        assert until(lambda: len(samples) >= 2, lambda: publish(msg))
        t1 = time.time_ns()
        tokens = [str(r.ok.key_expr) for r in raw.liveliness().get(
            f"@ros2_lv/0/{listener.zid}/0/*/MP/**", timeout=WAIT)]
        sub.undeclare()
    finally:
        raw.close()
    first, second = samples[0], samples[1]
    assert str(first.key_expr) == f"0/cmd_vel/{TWIST_TYPE}/{wire.wire_type_hash(TWIST, 'jazzy')}"
    payload = first.payload.to_bytes()
    assert payload == bytes(TS.serialize_cdr(msg, TWIST))
    assert payload[:4] == b"\x00\x01\x00\x00"             # CDR little-endian encapsulation
    att = first.attachment.to_bytes()
    assert len(att) == 33 and att[16] == 16
    seq = int.from_bytes(att[:8], "little")
    stamp = int.from_bytes(att[8:16], "little")
    assert seq >= 1 and t0 <= stamp <= t1
    assert int.from_bytes(second.attachment.to_bytes()[:8], "little") == seq + 1
    assert len(tokens) == 1                                # the publisher's own token
    digest = xxhash.xxh3_128(tokens[0].encode()).digest()
    assert att[17:] == digest[8:][::-1] + digest[:8][::-1]


def test_liveliness_query_sees_the_node_and_its_entities_until_close(port):
    node = ZenohTransport("companion", connect=[], listen=[f"tcp/127.0.0.1:{port}"])
    raw = raw_session(port)
    try:
        h = wire.wire_type_hash(TWIST, "jazzy")
        scan_hash = wire.wire_type_hash("sensor_msgs/msg/LaserScan", "jazzy")
        node.publisher("/cmd_vel", TWIST)
        node.subscribe("/scan", "sensor_msgs/msg/LaserScan", lambda m: None, SENSOR_DATA)
        z = node.zid
        expected = {
            f"@ros2_lv/0/{z}/0/0/NN/%/%/companion",
            f"@ros2_lv/0/{z}/0/1/MP/%/%/companion/%cmd_vel/{TWIST_TYPE}/{h}/::,10:,:,:,,",
            f"@ros2_lv/0/{z}/0/2/MS/%/%/companion/%scan/sensor_msgs::msg::dds_::LaserScan_/"
            f"{scan_hash}/2::,5:,:,:,,",
        }

        def seen():
            return {str(r.ok.key_expr) for r in raw.liveliness().get("@ros2_lv/0/**",
                                                                     timeout=1.0)}
        assert until(lambda: seen() == expected, timeout=WAIT), seen()
        node.close()
        assert until(lambda: not seen(), timeout=WAIT)
    finally:
        node.close()
        raw.close()


def test_malformed_sample_is_dropped_and_counted(port, listener):
    raw = raw_session(port)
    try:
        got = []
        listener.subscribe("/cmd_vel", TWIST, got.append)
        key = wire.topic_keyexpr(0, "/cmd_vel", TWIST, wire.wire_type_hash(TWIST, "jazzy"))
        assert until(lambda: listener.dropped > 0, lambda: raw.put(key, b"\x00\x01\x00\x00x"))
        assert got == []
        good = bytes(TS.serialize_cdr(MESSAGES[TWIST], TWIST))
        assert until(lambda: got, lambda: raw.put(key, good))
        assert got[0].linear.x == pytest.approx(0.4)
    finally:
        raw.close()


def test_transient_local_reaches_a_late_subscriber(listener, talker):
    publish = listener.publisher("/latched", TWIST, Qos(transient_local=True, depth=1))
    publish(MESSAGES[TWIST])
    got, event = [], threading.Event()
    talker.subscribe("/latched", TWIST, lambda m: (got.append(m), event.set()),
                     Qos(transient_local=True, depth=1))
    assert event.wait(WAIT)
    assert got[0].angular.z == pytest.approx(-0.25)


def test_close_ends_every_thread_it_started(port):
    before = set(threading.enumerate())
    a = ZenohTransport("a", connect=[], listen=[f"tcp/127.0.0.1:{port}"])
    b = ZenohTransport("b", connect=[f"tcp/127.0.0.1:{port}"])
    got = []
    b.subscribe("/cmd_vel", TWIST, got.append)
    a.subscribe("/odom", "nav_msgs/msg/Odometry", got.append)
    publish = a.publisher("/cmd_vel", TWIST)
    assert until(lambda: got, lambda: publish(MESSAGES[TWIST]))
    assert set(threading.enumerate()) - before          # subscribers run callback threads
    a.close()
    b.close()
    b.close()                                            # twice is harmless
    assert until(lambda: set(threading.enumerate()) <= before, timeout=2.0), \
        set(threading.enumerate()) - before
    with pytest.raises(RuntimeError):
        a.publisher("/cmd_vel", TWIST)


CHILD = textwrap.dedent("""
    import sys, time
    from companion.ros.messages import typestore
    from companion.ros.zenoh import ZenohTransport
    T = typestore("jazzy").types
    V = T["geometry_msgs/msg/Vector3"]
    with ZenohTransport("child", connect=[sys.argv[1]]) as node:
        publish = node.publisher("/cmd_vel", "geometry_msgs/msg/Twist")
        end = time.monotonic() + float(sys.argv[2])
        while time.monotonic() < end:
            publish(T["geometry_msgs/msg/Twist"](V(0.7, 0, 0), V(0, 0, 0.2)))
            time.sleep(0.02)
""")


def test_two_processes_exchange_twist(port, listener):
    got, event = [], threading.Event()
    listener.subscribe("/cmd_vel", TWIST, lambda m: (got.append(m), event.set()))
    child = subprocess.Popen([sys.executable, "-c", CHILD, f"tcp/127.0.0.1:{port}", "8"])
    try:
        assert event.wait(8.0)
    finally:
        child.terminate()
        try:
            child.wait(timeout=5)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait(timeout=5)
    assert got[0].linear.x == pytest.approx(0.7) and got[0].angular.z == pytest.approx(0.2)


@pytest.fixture
def router(port):
    """A Zenoh router on loopback (a session in router mode, as rmw_zenohd is)."""
    config = zenoh.Config()
    for key, value in {"mode": "router", "listen/endpoints": [f"tcp/127.0.0.1:{port}"],
                       "scouting/multicast/enabled": False}.items():
        config.insert_json5(key, json.dumps(value))
    session = zenoh.open(config)
    yield session
    session.close()


def exchanges(src: ZenohTransport, dst: ZenohTransport, topic: str) -> bool:
    got, event = [], threading.Event()
    dst.subscribe(topic, TWIST, lambda m: (got.append(m), event.set()))
    publish = src.publisher(topic, TWIST)
    return until(event.is_set, lambda: publish(MESSAGES[TWIST])) and \
        got[0].linear.x == pytest.approx(0.4)


def test_through_a_router_as_rmw_zenoh_deploys(port, router):
    """rmw_zenoh's topology: both nodes connect to the router, gossip then connects them to
    each other directly."""
    with ZenohTransport("a", connect=[f"tcp/127.0.0.1:{port}"]) as a, \
            ZenohTransport("b", connect=[f"tcp/127.0.0.1:{port}"]) as b:
        assert exchanges(a, b, "/cmd_vel")
        assert [str(z) for z in b.session.info.routers_zid()] == [str(router.zid())]
        assert until(lambda: a.zid in [str(z) for z in b.session.info.peers_zid()])


def test_client_reaches_peers_that_listen_nowhere_through_the_router(port, router):
    """A peer that cannot be reached directly (here: listening nowhere; on a robot: listening
    on its own loopback) still talks to a client, through the router, both ways."""
    with ZenohTransport("robot", connect=[f"tcp/127.0.0.1:{port}"], listen=[]) as robot, \
            ZenohTransport("companion", connect=[f"tcp/127.0.0.1:{port}"],
                           mode="client") as node:
        assert node.listen == []
        assert exchanges(node, robot, "/cmd_vel")
        assert exchanges(robot, node, "/odom_twist")
        assert list(node.session.info.peers_zid()) == []


def test_client_without_router_fails_in_bounded_time(monkeypatch, port):
    monkeypatch.setattr(wire, "CLIENT_CONNECT_TIMEOUT_MS", 300)
    start = time.monotonic()
    with pytest.raises(ConnectionError, match=f"tcp/127.0.0.1:{port}"):
        ZenohTransport(connect=[f"tcp/127.0.0.1:{port}"], mode="client")
    assert time.monotonic() - start < 3.0
    with pytest.raises(ConfigError, match="zenoh mode"):
        ZenohTransport(connect=[], mode="routr")


# -- services and the graph ----------------------------------------------------------------------

def test_a_service_answers_an_rmw_zenoh_query(port, listener):
    """A queryable on the service's key expression (the service type and its hash, as
    rmw_zenoh builds them) and an SS token; a plain Zenoh query carrying a request's CDR and a
    client's attachment gets the response with the request's sequence number and the client's
    GID back (src/detail/rmw_service_data.cpp); a query without an attachment is not answered."""
    srv = "rcl_interfaces/srv/GetParameters"
    asked = []

    def handler(request):
        asked.append(list(request.names))
        return message(TS, f"{srv}_Response", values=[message(
            TS, "rcl_interfaces/msg/ParameterValue", type=3, double_value=1.5)])

    listener.serve("/companion/get_parameters", srv, handler)
    h = wire.wire_service_hash(srv, "jazzy")
    key = f"0/companion/get_parameters/rcl_interfaces::srv::dds_::GetParameters_/{h}"
    request = bytes(TS.serialize_cdr(message(TS, f"{srv}_Request", names=["a", "bb"]),
                                     f"{srv}_Request"))
    gid = bytes(range(16))
    raw = raw_session(port)
    try:
        def ask():
            attachment = wire.attachment(7, time.time_ns(), gid)
            return [r.ok for r in raw.get(key, payload=request, attachment=attachment,
                                          timeout=2.0) if r.ok is not None]
        replies = []
        assert until(lambda: replies.append(ask()) or replies[-1], timeout=WAIT)
        tokens = [str(r.ok.key_expr) for r in raw.liveliness().get(
            f"@ros2_lv/0/{listener.zid}/**/SS/**", timeout=WAIT)]
        unanswered = [r.ok for r in raw.get(key, payload=request, timeout=1.0)
                      if r.ok is not None]
    finally:
        raw.close()
    reply = replies[-1][0]
    assert str(reply.key_expr) == key and asked[0] == ["a", "bb"]
    response = TS.deserialize_cdr(reply.payload.to_bytes(), f"{srv}_Response")
    assert response.values[0].double_value == 1.5
    seq, _, back = wire.parse_attachment(reply.attachment.to_bytes())
    assert (seq, back) == (7, gid)
    assert len(tokens) == 1 and "/SS/%/%/listener/%companion%get_parameters/" in tokens[0]
    assert h == "RIHS01_bf9803d5c74cf989a5de3e0c2e99444599a627c7ff75f97b8c05b01003675cbc"
    assert unanswered == []


def test_publishers_are_read_from_the_liveliness_tokens(listener, talker):
    talker.publisher("/person", "geometry_msgs/msg/PoseArray", SENSOR_DATA)
    talker.publisher("/odom", "nav_msgs/msg/Odometry")
    listener.publisher("/person", "geometry_msgs/msg/PointStamped")      # its own: not listed
    found = []
    assert until(lambda: found.append(listener.publishers("/person")) or found[-1])
    (pub,) = found[-1]
    assert pub.msgtype == "geometry_msgs/msg/PoseArray" and not pub.qos.reliable
    talker.close()
    assert until(lambda: listener.publishers("/person") == [])
