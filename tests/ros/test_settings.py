"""The node's parameters YAML: ROS 2's layout, every companion parameter, one-line errors."""

from __future__ import annotations

import math

import pytest

from companion.errors import ConfigError
from companion.ros.settings import load_node_config


def write(tmp_path, text: str):
    path = tmp_path / "companion.yaml"
    path.write_text(text)
    return path


def test_ros_parameters_with_nested_and_dotted_keys(tmp_path):
    path = write(tmp_path, """
companion:
  ros__parameters:
    controller: pid
    dt: 0.04
    formation.distance: 1.2
    formation:
      bearing: right
    lqr.q: [1.0, 2.0, 3.0, 4.0, 5.0]
    ros:
      transport: zenoh
      topics: {odom: /robot/odom, scan: ""}
      lidar_mount: [0.2, 0.0, 3.14159]
""")
    c = load_node_config(path)
    assert c.controller == "pid" and c.params.dt == 0.04
    assert c.params.formation.distance == 1.2
    assert c.params.formation.bearing == pytest.approx(1.5 * math.pi)   # right
    assert c.params.lqr.q == (1.0, 2.0, 3.0, 4.0, 5.0)
    assert c.ros.transport == "zenoh" and c.ros.topics.odom == "/robot/odom"
    assert c.ros.topics.scan == "" and c.ros.lidar_mount == (0.2, 0.0, 3.14159)


def test_the_wildcard_node_name_is_read(tmp_path):
    c = load_node_config(write(tmp_path, "/**:\n  ros__parameters:\n    dt: 0.1\n"))
    assert c.params.dt == 0.1


@pytest.mark.parametrize(("text", "expected"), [
    ("companion:\n  ros__parameters:\n    lqr.qq: 1\n", "lqr.qq: unknown key; did you mean 'q'"),
    ("companion:\n  ros__parameters:\n    ros: {transprt: dds}\n",
     "ros.transprt: unknown key; did you mean 'transport'"),
    ("companion:\n  ros__parameters:\n    ros: {transport: ddss}\n",
     "ros.transport: expected one of 'dds', 'zenoh', 'rclpy', got 'ddss'"),
    ("companion:\n  ros__parameters:\n    ros: {domain_id: 500}\n",
     "ros.domain_id: expected an integer in [0, 232], got 500"),
    ("companion:\n  ros__parameters:\n    ros: {topics: {odom: odom}}\n",
     "ros.topics.odom: expected an absolute ROS topic name"),
    ("companion:\n  ros__parameters:\n    dt: .nan\n", "dt: expected a number, got nan"),
    ("companion:\n  ros__parameters:\n    controller: lqrr\n",
     "unknown controller 'lqrr'; did you mean 'lqr'"),
    ("companion:\n  ros__parameters:\n    lqr: {q: [0, 0, 0, 0, 0]}\n", "lqr.q"),
    ("companion:\n  ros__parametrs:\n    dt: 0.1\n", "expected a 'ros__parameters' table"),
    ("companion: [1, 2\n", "line 2: invalid YAML"),
    ("other:\n  ros__parameters: {}\n", "other: unknown key"),
])
def test_bad_parameters_are_one_line_naming_the_file_and_key(tmp_path, text, expected):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_node_config(path)
    message = str(err.value)
    assert message.startswith(str(path)) and expected in message and "\n" not in message


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_node_config(tmp_path / "nope.yaml")


def test_docs_list_every_node_parameter():
    from pathlib import Path

    from companion.config import field_docs
    from companion.ros.settings import RosParams

    text = (Path(__file__).parents[2] / "docs" / "ros2.md").read_text()
    missing = [k for k, *_ in field_docs(RosParams) if f"`ros.{k}`" not in text]
    assert not missing
