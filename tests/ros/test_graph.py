"""What the node names on the graph: a publisher on an input with a type it does not take, or
with a QoS its subscription cannot match, is one warning line (the topic, the type or QoS, the
setting that would accept it) on /companion/status and in the log, /rosout included; a person
topic on ``auto`` takes any of the four person types."""

from __future__ import annotations

import pytest

from companion.ros import convert, graph
from companion.ros.messages import message, typestore
from companion.ros.node import CompanionNode
from companion.ros.settings import RosParams, config_from_mapping
from companion.ros.transport import DEFAULT, SENSOR_DATA, Endpoint, MemoryBus, MemoryTransport
from companion.types import PersonDetection, Pose
from stepping import tick

POSES = "geometry_msgs/msg/PoseArray"


def endpoint(topic, msgtype, qos=DEFAULT):
    return Endpoint(topic, msgtype, qos)


@pytest.mark.parametrize("ros, pub, words", [
    ({"person_type": "point"}, endpoint("/person", POSES),
     "/person: a publisher sends geometry_msgs/msg/PoseArray, which ros.person_type 'point' "
     "does not take; set ros.person_type: pose_array (or auto)"),
    ({}, endpoint("/person", "people_msgs/msg/People"),
     "/person: a publisher sends people_msgs/msg/People, which companion does not read as "
     "ros.topics.person"),
    ({}, endpoint("/odom", "geometry_msgs/msg/PoseStamped"),
     "it takes nav_msgs/msg/Odometry (set ros.topics.odom to a topic of that type)"),
    ({"qos": {"odom": {"reliability": "reliable"}}},
     endpoint("/odom", "nav_msgs/msg/Odometry", SENSOR_DATA),
     "/odom: a publisher offers best-effort delivery and ros.qos.odom.reliability is "
     "'reliable' (incompatible QoS: nothing arrives); set ros.qos.odom.reliability: "
     "best_effort"),
    ({"qos": {"person": {"durability": "transient_local"}}},
     endpoint("/person", "geometry_msgs/msg/PointStamped"),
     "set ros.qos.person.durability: volatile"),
])
def test_a_problem_is_one_line_naming_topic_type_and_setting(ros, pub, words):
    settings = config_from_mapping({"ros": ros}).ros
    lines = graph.input_problems(settings, lambda topic: [pub] if topic == pub.topic else [])
    assert len(lines) == 1 and words in lines[0], lines


def test_what_the_node_takes_raises_no_problem():
    ros = RosParams()
    pubs = {"/odom": [endpoint("/odom", "nav_msgs/msg/Odometry", SENSOR_DATA)],
            "/person": [endpoint("/person", t) for t in convert.PERSON_TYPES.values()],
            "/scan": [endpoint("/scan", "sensor_msgs/msg/LaserScan", SENSOR_DATA)]}
    assert graph.input_problems(ros, lambda topic: pubs.get(topic, [])) == []


def rig(**ros):
    bus, ts = MemoryBus(), typestore()
    node = CompanionNode(config_from_mapping({"ros": {"topics": {"scan": ""}, **ros}}),
                         MemoryTransport(bus, ts), time_base=convert.ABSOLUTE)
    return bus, ts, node, MemoryTransport(bus, ts)


def sent(bus, ts, topic):
    return [ts.deserialize_cdr(d, k) for t, k, d in bus.sent if t == topic]


def test_a_detector_of_another_type_is_named_on_status_and_rosout():
    """ros.person_type point and a detector publishing PoseArray: nothing reaches the tracker,
    and within a second the status and /rosout name the type and the setting."""
    bus, ts, node, other = rig(person_type="point")
    poses = other.publisher("/person", POSES)
    odom = other.publisher("/odom", "nav_msgs/msg/Odometry")
    for k in range(30):
        t = 50.0 + 0.05 * k
        odom(convert.odometry_msg(t, Pose(0, 0, 0), (0, 0), "odom", "base_link"))
        poses(convert.person_msg([PersonDetection(t, 1.0, 1.0, "odom")], "pose_array", t,
                                 "odom"))
        cmd = tick(node, t)
    assert cmd.estimate is None
    status = sent(bus, ts, "/companion/status")[-1].status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert "set ros.person_type: pose_array" in values["warning"]
    assert "set ros.person_type: pose_array" in status.message
    logs = [m for m in sent(bus, ts, "/rosout") if "ros.person_type" in m.msg]
    assert len(logs) == 1 and logs[0].level == 30 and logs[0].name == "companion"


def test_auto_takes_any_person_type():
    bus, ts, node, other = rig()
    poses = other.publisher("/person", POSES)
    odom = other.publisher("/odom", "nav_msgs/msg/Odometry")
    for k in range(30):
        t = 50.0 + 0.05 * k
        odom(convert.odometry_msg(t, Pose(0, 0, 0), (0, 0), "odom", "base_link"))
        poses(convert.person_msg([PersonDetection(t, 1.0 + 0.05 * k, 1.0, "odom")],
                                 "pose_array", t, "odom"))
        cmd = tick(node, t)
    assert cmd.estimate is not None and node.warnings == []


def test_the_node_logs_start_warnings_and_status_changes_to_rosout():
    bus, ts, node, other = rig()
    node.log.info("hello")
    for k in range(25):
        tick(node, 50.0 + 0.05 * k)                      # no odometry: stopped
    logs = sent(bus, ts, "/rosout")
    assert [m.msg for m in logs][:2] == ["hello", "status stopped: odometry_stale"]
    assert logs[1].level == 30 and logs[0].stamp.sec > 0
    assert logs[1].function == "status" and logs[1].file.endswith("watch.py")
    rosout = next(e for o, e in bus.endpoints if e.topic == "/rosout")
    assert rosout.qos.transient_local and rosout.qos.depth == 1000
    assert message(ts, "rcl_interfaces/msg/Log").__msgtype__ == logs[0].__msgtype__
