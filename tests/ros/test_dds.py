"""The DDS transport on loopback: rosbags' bytes on the wire, rmw's discovery announcements,
and exchanges with cyclonedds peers in this process."""

from __future__ import annotations

import threading
import time

import pytest
from cyclonedds.core import InstanceState, Policy, Qos, SampleState, ViewState
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from ros_helpers import samples
from rosbags.typesys.store import Nodetype

from companion.errors import ConfigError
from companion.ros.dds import (
    DISCOVERY_TOPIC,
    DISCOVERY_TYPE,
    DdsTransport,
    dds_topic_name,
    loopback_config,
    padded,
)
from companion.ros.idl import idl_type
from companion.ros.messages import message
from companion.ros.transport import SENSOR_DATA, ros_domain_id

RELIABLE = Qos(Policy.Reliability.Reliable(max_blocking_time=10**8), Policy.History.KeepLast(10),
               Policy.DataRepresentation(use_cdrv0_representation=True))
LATCHED = Qos(Policy.Reliability.Reliable(max_blocking_time=10**8),
              Policy.Durability.TransientLocal, Policy.History.KeepLast(1),
              Policy.DataRepresentation(use_cdrv0_representation=True))


def wait_for(predicate, seconds=5.0, step=None):
    """Poll ``predicate`` (calling ``step`` first each time) until true or ``seconds`` pass."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if step:
            step()
        if predicate():
            return True
        time.sleep(0.05)
    return False


def to_idl(store, msgtype, msg):
    """The cyclonedds sample equal to rosbags message ``msg`` (to check the announced type)."""
    def value(desc, v):
        kind, detail = desc
        if kind == Nodetype.NAME:
            return to_idl(store, detail, v)
        if kind == Nodetype.BASE:
            return v.item() if hasattr(v, "item") else v
        return [value(detail[0], x) for x in v]
    return idl_type(store, msgtype)(**{name: value(desc, getattr(msg, name))
                                       for name, desc in store.fielddefs[msgtype][1]})


@pytest.fixture
def transport(ros_domain):
    with DdsTransport("companion", domain_id=ros_domain, config=loopback_config()) as t:
        yield t


@pytest.fixture
def raw(transport, ros_domain):
    """A second participant of the same domain in this process, reading bytes as they come."""
    participant = DomainParticipant(ros_domain)
    yield participant
    participant.__del__()


def test_bytes_sent_are_rosbags_cdr(store, transport, raw):
    """What the transport writes is ``serialize_cdr`` (zeros to a multiple of 4 bytes, as
    rmw_cyclonedds_cpp writes), for every type the node and the simulated robot send;
    cyclonedds' own serialiser of the announced type gives the same bytes."""
    for i, (msgtype, msg) in enumerate(samples(store).items()):
        expected = bytes(store.serialize_cdr(msg, msgtype))
        assert to_idl(store, msgtype, msg).serialize(use_version_2=False) == expected, msgtype
        reader = DataReader(raw, Topic(raw, f"rt/bytes{i}", idl_type(store, msgtype)),
                            qos=RELIABLE)
        reader.take()   # nothing yet; the raw bytes are read below
        publish = transport.publisher(f"/bytes{i}", msgtype)
        got: list[bytes] = []

        def take(reader=reader, got=got):
            from cyclonedds._clayer import ddspy_take
            from cyclonedds.core import InstanceState, SampleState, ViewState
            got.extend(data for data, info in ddspy_take(
                reader._ref, SampleState.Any | ViewState.Any | InstanceState.Any, 8)
                if info.valid_data)
        assert wait_for(lambda got=got: got, step=lambda p=publish, m=msg, t=take: (p(m), t())), \
            msgtype
        assert got[0] == padded(expected), msgtype


def test_two_transports_exchange_every_type(store, ros_domain):
    """A message published by one node arrives equal at another (scans best effort)."""
    sent = samples(store)
    received: dict[str, object] = {}
    lock = threading.Lock()
    with DdsTransport("a", domain_id=ros_domain, config=loopback_config()) as a, \
            DdsTransport("b", domain_id=ros_domain, config=loopback_config()) as b:
        publishers = []
        for i, msgtype in enumerate(sent):
            qos = SENSOR_DATA if msgtype.endswith("LaserScan") else None

            def keep(msg, msgtype=msgtype):
                with lock:
                    received.setdefault(msgtype, msg)
            kw = {"qos": qos} if qos else {}
            b.subscribe(f"/t{i}", msgtype, keep, **kw)
            publishers.append((a.publisher(f"/t{i}", msgtype, **kw), sent[msgtype]))
        assert wait_for(lambda: len(received) == len(sent),
                        step=lambda: [p(m) for p, m in publishers])
    for msgtype, msg in sent.items():
        assert (bytes(store.serialize_cdr(received[msgtype], msgtype))
                == bytes(store.serialize_cdr(msg, msgtype))), msgtype


def test_discovery_announces_node_and_endpoints(store, transport, raw):
    """ros_discovery_info carries the participant's GID and the node's readers and writers by
    their DDS GUIDs (what rclpy matches against discovered endpoints), and endpoints carry the
    RIHS01 type hash in USER_DATA; when the node closes it announces no node.

    (The endpoints are seen through matched readers and writers: cyclonedds-python 11.0.1 crashes
    reading its built-in DCPSPublication topic.)"""
    infos = DataReader(raw, Topic(raw, DISCOVERY_TOPIC, idl_type(store, DISCOVERY_TYPE)),
                       qos=LATCHED)
    twist, scan = "geometry_msgs/msg/Twist", "sensor_msgs/msg/LaserScan"
    listener = DataReader(raw, Topic(raw, "rt/cmd_vel", idl_type(store, twist)), qos=RELIABLE)
    talker = DataWriter(raw, Topic(raw, "rt/scan", idl_type(store, scan)),
                        qos=Qos(Policy.Reliability.BestEffort,
                                Policy.DataRepresentation(use_cdrv0_representation=True)))
    transport.publisher("/cmd_vel", twist)
    transport.subscribe("/scan", scan, lambda m: None, SENSOR_DATA)
    seen: dict = {}

    def poll():
        for sample in infos.take(16):
            seen["info"] = sample
        seen["writers"] = [listener.get_matched_publication_data(h)
                           for h in listener.get_matched_publications()]
        seen["readers"] = [talker.get_matched_subscription_data(h)
                           for h in talker.get_matched_subscriptions()]

    def complete():
        info = seen.get("info")
        return (seen["writers"] and seen["readers"] and info and info.node_entities_info_seq
                and info.node_entities_info_seq[0].reader_gid_seq
                and info.node_entities_info_seq[0].writer_gid_seq)
    assert wait_for(complete, step=poll)
    info = seen["info"]
    assert bytes(info.gid.data) == transport.participant.guid.bytes
    (node,) = info.node_entities_info_seq
    assert (node.node_namespace, node.node_name) == ("/", "companion")
    (writer,), (reader,) = seen["writers"], seen["readers"]
    assert [bytes(g.data) for g in node.writer_gid_seq] == [writer.key.bytes]
    assert [bytes(g.data) for g in node.reader_gid_seq] == [reader.key.bytes]
    assert writer.topic_name == "rt/cmd_vel"
    assert writer.type_name == "geometry_msgs::msg::dds_::Twist_"
    assert writer.participant_key == transport.participant.guid
    for endpoint, msgtype in ((writer, twist), (reader, scan)):
        assert endpoint.qos[Policy.Userdata].data == (
            f"typehash={store.hash_rihs01(msgtype)};".encode())
    assert reader.qos[Policy.Reliability] == Policy.Reliability.BestEffort
    assert reader.qos[Policy.History] == Policy.History.KeepLast(5)
    assert isinstance(writer.qos[Policy.Reliability], Policy.Reliability.Reliable)
    assert writer.qos[Policy.Durability] == Policy.Durability.Volatile
    assert writer.qos[Policy.History] == Policy.History.KeepLast(10)
    transport.close()
    assert wait_for(lambda: not seen["info"].node_entities_info_seq, step=poll)


def test_names_and_settings_are_checked(ros_domain, monkeypatch):
    assert dds_topic_name("/cmd_vel") == "rt/cmd_vel"
    assert dds_topic_name("status", "/companion") == "rt/companion/status"
    for bad in ("", "/", "cmd vel", "/9lives", "/a//b"):
        with pytest.raises(ConfigError, match="topic"):
            dds_topic_name(bad)
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    assert ros_domain_id() == 42 and ros_domain_id(7) == 7
    for bad in (-1, 233, "x", 1.5):
        with pytest.raises(ConfigError, match="domain_id"):
            ros_domain_id(bad)
    monkeypatch.setenv("ROS_DOMAIN_ID", "300")
    with pytest.raises(ConfigError, match="ROS_DOMAIN_ID: '300'"):
        ros_domain_id()
    with pytest.raises(ConfigError, match="node_name"):
        DdsTransport("1robot", domain_id=ros_domain)
    with DdsTransport("a", domain_id=ros_domain, config=loopback_config()) as t:
        t.publisher("/x", "geometry_msgs/msg/Twist")
        with pytest.raises(ConfigError, match="another configuration"):
            DdsTransport("b", domain_id=ros_domain, config=loopback_config().replace(
                "auto", "none"))


def test_cyclonedds_uri_replaces_the_loopback_default(ros_domain, monkeypatch, capfd):
    """A user's CYCLONEDDS_URI is what the transport runs on (here one naming an interface this
    machine lacks), and a configuration cyclonedds refuses is a ConfigError naming its source."""
    monkeypatch.setenv("CYCLONEDDS_URI", loopback_config().replace('name="lo"', 'name="nosuch0"'))
    with pytest.raises(ConfigError, match=f"CYCLONEDDS_URI: .* domain {ros_domain + 1}"):
        DdsTransport("companion", domain_id=ros_domain + 1)
    assert "nosuch0" in capfd.readouterr().err
    with pytest.raises(ConfigError, match="dds_config: "):
        DdsTransport("companion", domain_id=ros_domain + 2,
                     config=loopback_config().replace('name="lo"', 'name="nosuch0"'))


def test_humble_gids_are_24_bytes(ros_domain):
    """Humble's rmw_dds_common has 24-byte GIDs: the 16-byte GUID and zeros, as its rmw fill it."""
    from companion.ros.messages import typestore
    humble = typestore("humble")
    with DdsTransport("companion", domain_id=ros_domain, distro="humble",
                      config=loopback_config()) as transport:
        raw = DomainParticipant(ros_domain)
        infos = DataReader(raw, Topic(raw, DISCOVERY_TOPIC, idl_type(humble, DISCOVERY_TYPE)),
                           qos=LATCHED)
        got = []
        assert wait_for(lambda: got, step=lambda: got.extend(infos.take(4)))
        assert bytes(got[-1].gid.data) == transport.participant.guid.bytes + b"\0" * 8
        raw.__del__()


def test_one_topic_carries_several_types_each_reader_gets_its_own(ros_domain):
    """A person topic with a PoseArray publisher and a PointStamped one: each subscription
    takes the messages of its type only (DDS matches by type name), and discovery names
    both publishers with their type and QoS."""
    got: dict[str, list] = {"point": [], "poses": []}
    with DdsTransport("a", domain_id=ros_domain, config=loopback_config()) as a, \
            DdsTransport("b", domain_id=ros_domain, config=loopback_config()) as b:
        b.subscribe("/person", "geometry_msgs/msg/PointStamped",
                    lambda m: got["point"].append(m), SENSOR_DATA)
        b.subscribe("/person", "geometry_msgs/msg/PoseArray", lambda m: got["poses"].append(m),
                    SENSOR_DATA)
        points = a.publisher("/person", "geometry_msgs/msg/PointStamped")
        poses = a.publisher("/person", "geometry_msgs/msg/PoseArray", SENSOR_DATA)
        end = time.monotonic() + 10
        while time.monotonic() < end and not (got["point"] and got["poses"]):
            points(message(a.typestore, "geometry_msgs/msg/PointStamped"))
            poses(message(a.typestore, "geometry_msgs/msg/PoseArray"))
            time.sleep(0.05)
        found = {(e.msgtype, e.qos.reliable) for e in b.publishers("/person")}
    assert all(m.__msgtype__ == "geometry_msgs/msg/PointStamped" for m in got["point"])
    assert all(m.__msgtype__ == "geometry_msgs/msg/PoseArray" for m in got["poses"])
    assert got["point"] and got["poses"]
    assert found == {("geometry_msgs/msg/PointStamped", True),
                     ("geometry_msgs/msg/PoseArray", False)}


def test_a_service_answers_in_rmw_cyclonedds_cpps_format(store, ros_domain):
    """A client written to rmw_cyclonedds_cpp's format (serdata.hpp: a request is the CDR
    encapsulation, a 16-byte header of client id and sequence number, then the request)
    writes on rq/companion/get_parametersRequest and reads rr/companion/get_parametersReply:
    the reply carries the header back and the response; both service endpoints announce a
    serviceid in their USER_DATA (what rmw_cyclonedds_cpp's clients wait for); a request
    too short to hold a header is dropped (cyclonedds checks the sample against the type with
    the header), not answered."""
    import struct

    from cyclonedds._clayer import ddspy_take, ddspy_write

    srv = "rcl_interfaces/srv/GetParameters"
    asked = []

    def handler(request):
        asked.append(list(request.names))
        return message(store, f"{srv}_Response", values=[message(
            store, "rcl_interfaces/msg/ParameterValue", type=4, string_value="lqr")])

    with DdsTransport("companion", domain_id=ros_domain, config=loopback_config()) as node, \
            DdsTransport("client", domain_id=ros_domain, config=loopback_config()) as client:
        node.serve("/companion/get_parameters", srv, handler)
        p = client.participant
        request_topic = Topic(p, "rq/companion/get_parametersRequest",
                              idl_type(store, f"{srv}_Request", request_header=True))
        reply_topic = Topic(p, "rr/companion/get_parametersReply",
                            idl_type(store, f"{srv}_Response", request_header=True))
        writer = DataWriter(p, request_topic, qos=RELIABLE)
        reader = DataReader(p, reply_topic, qos=RELIABLE)
        assert wait_for(lambda: writer.get_publication_matched_status().current_count
                        and reader.get_subscription_matched_status().current_count)
        matched = writer.get_matched_subscription_data(writer.get_matched_subscriptions()[0])
        user_data = next(q for q in matched.qos if isinstance(q, Policy.Userdata)).data
        assert user_data.startswith(b"serviceid=") and b";typehash=RIHS01_" in user_data
        body = bytes(store.serialize_cdr(message(store, f"{srv}_Request", names=["controller"]),
                                         f"{srv}_Request"))
        header = struct.pack("<Qq", 0xC0FFEE, 42)
        ddspy_write(writer._ref, padded(body[:4] + b"\0" * 2))       # too short: dropped
        ddspy_write(writer._ref, padded(body[:4] + header + body[4:]))
        replies = []

        def take():
            got = ddspy_take(reader._ref, SampleState.Any | ViewState.Any | InstanceState.Any, 8)
            replies.extend(d for d, info in got or [] if info.valid_data)
        assert wait_for(lambda: replies, step=take)
    reply = replies[0]
    assert reply[4:20] == header and asked == [["controller"]] and len(replies) == 1
    response = store.deserialize_cdr(reply[:4] + reply[20:], f"{srv}_Response")
    assert response.values[0].string_value == "lqr"
