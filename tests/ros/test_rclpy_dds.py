"""companion's DDS transport against a real ROS 2 node: Jazzy's rclpy over rmw_fastrtps_cpp, in
a subprocess, both on 127.0.0.1 only."""

from __future__ import annotations

import threading
import time

import pytest
from ros_helpers import Peer, needs_rclpy, samples

from companion.ros.dds import DdsTransport, loopback_config, padded
from companion.ros.transport import DEFAULT, SENSOR_DATA

pytestmark = needs_rclpy

#: rclpy -> companion: what the node and the simulated robot subscribe to.
INBOUND = {"/teleop/cmd_vel": ("geometry_msgs/msg/Twist", DEFAULT),
           "/odom": ("nav_msgs/msg/Odometry", DEFAULT),
           "/scan": ("sensor_msgs/msg/LaserScan", SENSOR_DATA),
           "/person": ("geometry_msgs/msg/PointStamped", DEFAULT)}
#: companion -> rclpy: what the node publishes, and the other types whose bytes are checked
#: (tf2_msgs has no pip package, so TFMessage is checked in test_dds only).
OUTBOUND = {"/cmd_vel": ("geometry_msgs/msg/Twist", DEFAULT),
            "/cmd_vel_stamped": ("geometry_msgs/msg/TwistStamped", DEFAULT),
            "/companion/status": ("diagnostic_msgs/msg/DiagnosticArray", DEFAULT),
            "/companion/markers": ("visualization_msgs/msg/MarkerArray", DEFAULT),
            "/echo/odom": ("nav_msgs/msg/Odometry", DEFAULT),
            "/echo/scan": ("sensor_msgs/msg/LaserScan", SENSOR_DATA),
            "/echo/poses": ("geometry_msgs/msg/PoseArray", DEFAULT),
            "/clock": ("rosgraph_msgs/msg/Clock", DEFAULT)}


@pytest.fixture(scope="module")
def exchange(store, ros_domain, rclpy_env, tmp_path_factory):
    """One rclpy node and one companion transport publishing to each other until each has heard
    every topic and rclpy's graph shows the node; returns what both sides saw."""
    sent = samples(store)
    heard: dict[str, object] = {}
    lock = threading.Lock()
    plan = {"publish": [[topic, msgtype, qos.reliable, bytes(store.serialize_cdr(
                sent[msgtype], msgtype)).hex()] for topic, (msgtype, qos) in INBOUND.items()],
            "listen": [[topic, msgtype, qos.reliable] for topic, (msgtype, qos) in
                       OUTBOUND.items()],
            "node": ["companion", "/"],
            "expect": {"publishers": len(OUTBOUND), "subscribers": len(INBOUND)},
            "timeout": 25.0}
    started = time.monotonic()
    with DdsTransport("companion", domain_id=ros_domain, config=loopback_config()) as node:
        for topic, (msgtype, qos) in INBOUND.items():
            def keep(msg, topic=topic):
                with lock:
                    heard.setdefault(topic, msg)
            node.subscribe(topic, msgtype, keep, qos)
        publishers = [(node.publisher(topic, msgtype, qos), sent[msgtype])
                      for topic, (msgtype, qos) in OUTBOUND.items()]
        peer = Peer(rclpy_env, plan, tmp_path_factory.mktemp("peer"))
        try:
            while peer.running() and len(heard) < len(INBOUND):
                for publish, msg in publishers:
                    publish(msg)
                time.sleep(0.1)
            stop = threading.Event()

            def keep_publishing():
                while not stop.wait(0.1):
                    for publish, msg in publishers:
                        publish(msg)
            thread = threading.Thread(target=keep_publishing, daemon=True)
            thread.start()
            try:
                report = peer.finish()
            finally:
                stop.set()
                thread.join(timeout=2)
        finally:
            peer.kill()
    return {"sent": sent, "heard": heard, "report": report,
            "seconds": time.monotonic() - started}


def test_rclpy_messages_arrive_equal(store, exchange):
    """Twist, Odometry, LaserScan (best effort) and PointStamped published by rclpy arrive as
    the same messages (equal rosbags serialisations)."""
    for topic, (msgtype, _) in INBOUND.items():
        assert topic in exchange["heard"], f"nothing from rclpy on {topic}"
        assert (bytes(store.serialize_cdr(exchange["heard"][topic], msgtype))
                == bytes(store.serialize_cdr(exchange["sent"][msgtype], msgtype))), topic


def test_rclpy_receives_rosbags_bytes(store, exchange):
    """What rclpy receives from companion is rosbags' serialisation byte for byte (with zeros to
    a multiple of 4, as rmw_cyclonedds_cpp sends), and rclpy decodes it to a message that it
    serialises to exactly rosbags' bytes."""
    heard = exchange["report"]["heard"]
    for topic, (msgtype, _) in OUTBOUND.items():
        assert topic in heard, f"rclpy heard nothing on {topic}"
        expected = bytes(store.serialize_cdr(exchange["sent"][msgtype], msgtype)).hex()
        assert heard[topic]["raw"] == padded(bytes.fromhex(expected)).hex(), topic
        assert heard[topic]["rclpy"] == expected, topic


def test_rclpy_sees_the_node(store, exchange):
    """rclpy's graph shows /companion with its publishers and subscriptions and their types,
    Jazzy's type hashes, and the QoS of each endpoint."""
    graph = exchange["report"]["graph"]
    assert ["companion", "/"] in graph["nodes"]
    assert sorted(graph["publishers"]) == sorted(
        [topic, [msgtype]] for topic, (msgtype, _) in OUTBOUND.items())
    assert sorted(graph["subscribers"]) == sorted(
        [topic, [msgtype]] for topic, (msgtype, _) in INBOUND.items())
    for side, topics in (("writers", OUTBOUND), ("readers", INBOUND)):
        for topic, (msgtype, qos) in topics.items():
            (ours,) = [e for e in graph[side][topic] if e["node"] == "companion"]
            assert ours["type"] == msgtype
            assert ours["hash"] == store.hash_rihs01(msgtype)
            assert ours["reliability"] == ("RELIABLE" if qos.reliable else "BEST_EFFORT")
            assert ours["durability"] == "VOLATILE"
