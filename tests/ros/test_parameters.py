"""The node's parameters over its services (rcl_interfaces), on an in-memory graph: list, get,
describe, types, set and set atomically with rclpy's rules; a bad or read-only value is refused
with the reason and changes nothing; a side switch while walking moves the robot to the other
side within the rate limits; /parameter_events reports every change."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion.geometry import wrap_pi
from companion.params import RIGHT
from companion.ros import convert
from companion.ros.messages import message, typestore
from companion.ros.node import CompanionNode
from companion.ros.parameters import (
    DOUBLE,
    DOUBLE_ARRAY,
    NOT_SET,
    RUNTIME,
    STRING,
    from_msg,
    to_msg,
)
from companion.ros.settings import config_from_mapping
from companion.ros.sim_robot import Pacer, run_sim_robot
from companion.ros.transport import MemoryBus, MemoryTransport
from companion.sim.scenario import load_scenario

SRV = "rcl_interfaces/srv/"


@pytest.fixture()
def rig():
    """A node with default parameters on a bus, and a client transport."""
    bus = MemoryBus()
    ts = typestore()
    node = CompanionNode(config_from_mapping({"ros": {"topics": {"scan": ""}}}),
                         MemoryTransport(bus, ts), time_base=convert.ABSOLUTE)
    return node, MemoryTransport(bus, ts), bus, ts


def call(client, name, srv, **fields):
    return client.call(f"/companion/{name}", SRV + srv,
                       message(client.typestore, f"{SRV}{srv}_Request", **fields))


def param(ts, name, value, kind=None):
    return message(ts, "rcl_interfaces/msg/Parameter", name=name, value=to_msg(ts, value, kind))


def get(client, *names):
    return [from_msg(v)[1] for v in call(client, "get_parameters", "GetParameters",
                                         names=list(names)).values]


def test_every_parameter_of_the_file_is_listed_and_read(rig):
    node, client, _, _ = rig
    result = call(client, "list_parameters", "ListParameters", prefixes=[], depth=0).result
    names = list(result.names)
    assert {"formation.distance", "formation.bearing", "lqr.q", "controller", "dt",
            "ros.topics.odom", "ros.qos.odom.reliability"} <= set(names)
    assert "formation" in result.prefixes and "ros.qos.odom" in result.prefixes
    assert get(client, "formation.distance", "lqr.q", "ros.topics.odom", "controller") == [
        1.0, [25.0, 10.0, 25.0, 30.0, 30.0], "/odom", "lqr"]
    unknown = call(client, "get_parameters", "GetParameters", names=["nope"]).values[0]
    assert unknown.type == NOT_SET


def test_list_follows_rclpys_prefix_and_depth_rules(rig):
    _, client, _, _ = rig
    top = call(client, "list_parameters", "ListParameters", prefixes=[], depth=1).result
    assert list(top.names) == ["use_sim_time", "dt", "controller"]
    formation = call(client, "list_parameters", "ListParameters", prefixes=["formation"],
                     depth=0).result
    assert list(formation.names) == ["formation.distance", "formation.bearing",
                                     "formation.policy"]
    shallow = call(client, "list_parameters", "ListParameters", prefixes=["ros"],
                   depth=1).result
    assert "ros.node_name" in shallow.names and "ros.topics.odom" not in shallow.names


def test_descriptors_and_types_say_what_can_change(rig):
    _, client, _, _ = rig
    names = ["formation.bearing", "dt", "lqr.q", "ros.transport"]
    d = call(client, "describe_parameters", "DescribeParameters", names=names).descriptors
    assert [x.read_only for x in d] == [False, True, False, True]
    assert d[0].dynamic_typing and "rad" in d[0].description
    assert "allowed" in d[1].additional_constraints
    types = call(client, "get_parameter_types", "GetParameterTypes", names=names).types
    assert list(types) == [DOUBLE, DOUBLE, DOUBLE_ARRAY, STRING]
    assert {"formation.distance", "formation.bearing", "robot.v_max", "lqr.q"} <= RUNTIME


@pytest.mark.parametrize("name, value, words", [
    ("formation.distance", -1.0, "formation.distance: expected a finite positive number"),
    ("formation.distance", 0.3, "inside keepout.person_clearance"),
    ("formation.bearing", "sideways", "expected a bearing in rad or one of"),
    ("lqr.q", [1.0, 1.0], "lqr.q: expected 5 values"),
    ("lqr.r", [0.0, 1.0], "lqr.r"),
    ("dt", 0.1, "dt: read-only while the node runs"),
    ("ros.topics.odom", "/x", "read-only"),
    ("nope", 1.0, "nope: no such parameter of /companion"),
    ("formation.distance", True, "formation.distance: expected a double, got a bool"),
    ("formation.distance", math.nan, "expected a finite number"),
])
def test_a_bad_value_is_refused_with_the_reason_and_nothing_changes(rig, name, value, words):
    node, client, bus, ts = rig
    before = node.config
    events = len([1 for topic, *_ in bus.sent if topic == "/parameter_events"])
    (result,) = call(client, "set_parameters", "SetParameters",
                     parameters=[param(ts, name, value)]).results
    assert not result.successful and words in result.reason, result.reason
    assert node.config == before and node.stack.params == before.params
    assert len([1 for topic, *_ in bus.sent if topic == "/parameter_events"]) == events


def test_set_applies_each_parameter_and_atomically_all_or_none(rig):
    node, client, bus, ts = rig
    node.tick(50.0)                           # the first tick announces every parameter
    results = call(client, "set_parameters", "SetParameters", parameters=[
        param(ts, "formation.distance", 1.5), param(ts, "robot.v_max", -1.0),
        param(ts, "formation.bearing", "right")]).results
    assert [r.successful for r in results] == [True, False, True]
    assert get(client, "formation.distance", "robot.v_max", "formation.bearing") == [
        1.5, 1.5, pytest.approx(RIGHT)]
    assert node.stack.params.formation.distance == 1.5
    result = call(client, "set_parameters_atomically", "SetParametersAtomically", parameters=[
        param(ts, "formation.distance", 2.0), param(ts, "dt", 0.1)]).result
    assert not result.successful and "dt" in result.reason
    assert get(client, "formation.distance") == [1.5]
    result = call(client, "set_parameters_atomically", "SetParametersAtomically", parameters=[
        param(ts, "formation.distance", 2, kind=2), param(ts, "lqr.q", [1, 1, 1, 1, 1])]).result
    assert result.successful and get(client, "formation.distance", "lqr.q") == [
        2.0, [1.0] * 5]
    events = [ts.deserialize_cdr(d, k) for topic, k, d in bus.sent
              if topic == "/parameter_events"]
    assert len(events[0].new_parameters) > 100 and events[0].node == "/companion"
    assert [[p.name for p in e.changed_parameters] for e in events[1:]] == [
        ["formation.distance"], ["formation.bearing"], ["formation.distance", "lqr.q"]]


def bearing_of_robot(log, d):
    """The bearing (rad) of the reference point from the person's heading, every sample."""
    rx = log["robot_x"] + d * np.cos(log["robot_theta"])
    ry = log["robot_y"] + d * np.sin(log["robot_theta"])
    return np.array([wrap_pi(math.atan2(y - py, x - px) - pth) for x, y, px, py, pth in zip(
        rx, ry, log["person_x"], log["person_y"], log["person_theta"])])


def test_a_side_switch_while_walking_moves_the_robot_to_the_other_side_within_the_limits():
    """The figure-8 walker with the robot on the right; at 10 s a client sets the bearing to
    left: the robot crosses behind or in front of the person to the left, never nearer than
    the protective distance, its commands within the velocity and acceleration limits, and
    holds the new side to the end."""
    sc = load_scenario("figure8", {"sensing": "ideal"})
    spec = dataclasses.replace(sc.episode(), duration=30.0)
    bus, ts = MemoryBus(), typestore()
    cfg = config_from_mapping({"ros": {"use_sim_time": True, "person_type": "odometry"}})
    cfg = dataclasses.replace(cfg, params=sc.params, controller=sc.controller)
    node = CompanionNode(cfg, MemoryTransport(bus, ts))
    client = MemoryTransport(bus, ts)
    results = []

    def tick(t: float) -> None:
        node.tick(t)
        if abs(t - 10.0) < 1e-9:
            results.append(call(client, "set_parameters", "SetParameters", parameters=[
                param(ts, "formation.bearing", "left", kind=STRING)]).results[0])

    log, _ = run_sim_robot(spec, MemoryTransport(bus, ts), cfg.ros, Pacer(0.0), after=tick)
    assert results and results[0].successful
    p = sc.params
    d, dt, s = p.robot.d, p.dt, p.supervisor
    alpha = bearing_of_robot(log, d)
    t = log["t"]
    assert np.all(alpha[(t > 2.0) & (t < 10.0)] < 0.0)          # right before
    assert np.all(np.abs(alpha[t > 25.0] - math.pi / 2) < 0.15)  # left at the end
    assert np.min(np.hypot(log["robot_x"] - log["person_x"],
                           log["robot_y"] - log["person_y"])) > p.keepout.protective_distance
    v, w = log["v"], log["omega"]
    assert np.all(np.abs(v) <= p.robot.v_max + 1e-9)
    assert np.all(np.abs(w) <= p.robot.omega_max + 1e-9)
    dv, dw = np.diff(v) / dt, np.diff(w) / dt
    assert np.all(dv <= s.accel_max + 1e-6) and np.all(dv >= -s.decel_max - 1e-6)
    assert np.all(np.abs(dw) <= s.angular_accel_max + 1e-6)


def test_a_lower_speed_limit_is_reached_at_the_deceleration_limit(rig):
    """robot.v_max lowered below the current speed: the command comes down at the
    deceleration limit, not in one jump, and then stays within the new limit."""
    node, client, _, ts = rig
    stack, p = node.stack, node.config.params
    stack._prev, stack._started = (1.4, 0.0), True
    (ok,) = call(client, "set_parameters", "SetParameters",
                 parameters=[param(ts, "robot.v_max", 0.5)]).results
    assert ok.successful
    from companion.control.limits import limit
    prev, seen = (1.4, 0.0), []
    for _ in range(20):
        prev = limit((1.4, 0.0), prev, stack.params)
        seen.append(prev[0])
    steps = -np.diff([1.4, *seen]) / p.dt
    assert np.all(steps <= p.supervisor.decel_max + 1e-9) and seen[0] < 1.4
    assert seen[-1] == pytest.approx(0.5)


def test_use_sim_time_is_read_as_every_ros_2_node_has_it(tmp_path):
    """A parameter file for ROS 2 nodes often sets use_sim_time at the top: it is
    ros.use_sim_time; the node lists and reads it under both names."""
    from companion.errors import ConfigError
    from companion.ros.settings import load_node_config

    path = tmp_path / "p.yaml"
    path.write_text("/**:\n  ros__parameters:\n    use_sim_time: true\n")
    config = load_node_config(path)
    assert config.ros.use_sim_time
    bus, ts = MemoryBus(), typestore()
    CompanionNode(config, MemoryTransport(bus, ts))
    client = MemoryTransport(bus, ts)
    assert get(client, "use_sim_time", "ros.use_sim_time") == [True, True]
    path.write_text("/**:\n  ros__parameters:\n    use_sim_time: true\n"
                    "    ros: {use_sim_time: false}\n")
    with pytest.raises(ConfigError, match="p.yaml: use_sim_time: given with ros.use_sim_time"):
        load_node_config(path)
