"""The transform tree (/tf, /tf_static) and the node placing inputs through it: chains,
interpolation at a stamp, static transforms, what is not known yet (wait) or never (a named
reason), a camera's optical frame (tilted, depth along z), odometry of another child frame."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from companion.ros import convert
from companion.ros.messages import make, typestore
from companion.ros.node import CompanionNode
from companion.ros.settings import config_from_mapping
from companion.ros.tf import Lookup, Transform, TransformBuffer
from companion.ros.transport import MemoryBus, MemoryTransport
from companion.types import PersonDetection, Pose
from stepping import tick


def tf(x=0.0, y=0.0, z=0.0, yaw=0.0, rotation=None):
    return Transform(rotation or Rotation.from_euler("z", yaw), np.array([x, y, z]))


def test_a_chain_is_composed_and_inverted():
    buf = TransformBuffer()
    buf.add("odom", "base_link", 0.0, tf(1.0, 2.0, yaw=math.pi / 2), static=True)
    buf.add("base_link", "laser", 0.0, tf(0.2, 0.0, 0.3), static=True)
    p = buf.lookup("odom", "laser", 5.0).apply(np.array([1.0, 0.0, 0.0]))
    np.testing.assert_allclose(p, [1.0, 3.2, 0.3], atol=1e-12)
    back = buf.lookup("laser", "odom", 5.0).apply(p)
    np.testing.assert_allclose(back, [1.0, 0.0, 0.0], atol=1e-12)
    up = buf.lookup("base_link", "/laser", 5.0)           # a leading slash is ignored
    np.testing.assert_allclose(up.translation, [0.2, 0.0, 0.3])


def test_dynamic_transforms_interpolate_and_say_what_is_missing():
    buf = TransformBuffer(cache_s=1.0)
    buf.add("odom", "base_link", 10.0, tf(0.0, yaw=0.0))
    buf.add("odom", "base_link", 10.2, tf(2.0, yaw=1.0))
    mid = buf.lookup("odom", "base_link", 10.1)
    assert mid.translation[0] == pytest.approx(1.0) and mid.yaw == pytest.approx(0.5)
    with pytest.raises(Lookup) as later:
        buf.lookup("odom", "base_link", 10.3)
    assert later.value.reason == "future"
    buf.add("odom", "base_link", 11.5, tf(3.0))                # 10.0 and 10.2 age out
    with pytest.raises(Lookup) as early:
        buf.lookup("odom", "base_link", 10.1)
    assert early.value.reason == "past"
    with pytest.raises(Lookup) as alone:
        buf.lookup("odom", "camera", 11.5)
    assert alone.value.reason == "unconnected" and "camera" in str(alone.value)


def test_a_loop_in_the_tree_ends():
    buf = TransformBuffer()
    buf.add("a", "b", 0.0, tf(1.0), static=True)
    buf.add("b", "a", 0.0, tf(1.0), static=True)
    with pytest.raises(Lookup):
        buf.lookup("a", "c", 0.0)


def transform_msg(parent, child, t, x, y, z, q):
    return make("geometry_msgs/msg/TransformStamped", header=convert.header(t, parent),
                child_frame_id=child, transform=make(
                    "geometry_msgs/msg/Transform",
                    translation=make("geometry_msgs/msg/Vector3", x=x, y=y, z=z),
                    rotation=make("geometry_msgs/msg/Quaternion", x=q[0], y=q[1], z=q[2],
                                  w=q[3])))


#: A camera's optical frame (REP 103: z forward, x right, y down) 0.3 m ahead of the base and
#: 1.2 m up, looking along the base's x axis: as robot_state_publisher gives it.
OPTICAL = Rotation.from_euler("ZYX", [-math.pi / 2, 0.0, -math.pi / 2])


def camera_rig(static=True, **ros):
    bus, ts = MemoryBus(), typestore()
    node = CompanionNode(config_from_mapping({"ros": {"topics": {"scan": ""}, **ros}}),
                         MemoryTransport(bus, ts), time_base=convert.ABSOLUTE)
    other = MemoryTransport(bus, ts)
    tf_pub = other.publisher("/tf_static" if static else "/tf", "tf2_msgs/msg/TFMessage")
    odom = other.publisher("/odom", "nav_msgs/msg/Odometry")
    point = other.publisher("/person", "geometry_msgs/msg/PointStamped")
    return node, tf_pub, odom, point


def camera_tf(t=0.0):
    return make("tf2_msgs/msg/TFMessage", transforms=[
        transform_msg("base_link", "camera_link", t, 0.3, 0.0, 1.2, (0, 0, 0, 1)),
        transform_msg("camera_link", "camera_optical", t, 0.0, 0.0, 0.0, OPTICAL.as_quat())])


def test_a_detection_in_a_camera_optical_frame_is_placed_through_the_tree():
    """The robot at (2, 1) heading +y; the person 2 m in front of the camera (z = 2 in the
    optical frame) and 0.5 m to its right (x = 0.5), at the height of the camera's axis
    (y = 0): in the odometry frame at (2 + 0.5, 1 + 0.3 + 2)."""
    node, tf_pub, odom, point = camera_rig()
    tf_pub(camera_tf())
    for k in range(3):
        t = 20.0 + 0.05 * k
        odom(convert.odometry_msg(t, Pose(2.0, 1.0, math.pi / 2), (0, 0), "odom", "base_link"))
    s = PersonDetection(20.05, 0.5, 0.0, "camera_optical", z=2.0)
    d = node.placer.detection(s, node._odom, "world")
    assert (d.frame, d.x, d.y) == ("world", pytest.approx(2.5), pytest.approx(3.3))
    s = dataclasses.replace(s, covariance=(0.04, 0.0, 0.0, 0.01))
    cov = node.placer.detection(s, node._odom, "world").covariance
    # the optical x (0.04) is the base's -y, i.e. the world's x here; optical y points down
    assert cov == pytest.approx((0.04, 0.0, 0.0, 0.0), abs=1e-12)


def test_a_transform_that_comes_late_is_waited_for_within_the_bound():
    """/tf (odom -> camera, a camera fixed in the world) is published after the detection:
    the detection waits for it at most ros.tf_wait_s, then is placed; one that has no
    transform at all is the tracker's detection_frame and a warning naming the frame."""
    node, tf_pub, odom, point = camera_rig(static=False, tf_wait_s=0.2)
    reasons, placed = [], []
    for k in range(40):
        t = 30.0 + 0.05 * k
        odom(convert.odometry_msg(t, Pose(0.0, 0.0, 0.0), (0, 0), "odom", "base_link"))
        point(convert.person_msg([PersonDetection(t, 1.0, 0.0, "fixed_cam")], "point", t,
                                 "fixed_cam"))
        if k >= 2:                  # the camera's pose comes 0.1 s behind the detections
            tf_pub(make("tf2_msgs/msg/TFMessage", transforms=[transform_msg(
                "odom", "fixed_cam", t - 0.1, 5.0, 0.0, 0.0, (0, 0, 0, 1))]))
        cmd = tick(node, t)
        reasons.append(cmd.reason)
        placed.append(cmd.estimate)
    assert placed[-1] is not None and placed[-1].state.x == pytest.approx(6.0, abs=0.05)
    assert not any("detection_frame" in r for r in reasons[10:])
    node2, _, odom2, point2 = camera_rig()
    for k in range(30):
        t = 30.0 + 0.05 * k
        odom2(convert.odometry_msg(t, Pose(0.0, 0.0, 0.0), (0, 0), "odom", "base_link"))
        point2(convert.person_msg([PersonDetection(t, 1.0, 0.0, "nowhere")], "point", t,
                                  "nowhere"))
        cmd = tick(node2, t)
    assert "detection_frame" in cmd.reason
    assert any("detections in frame nowhere cannot be placed" in w for w in node2.warnings)


def test_odometry_of_another_child_frame_is_moved_to_the_base():
    """Odometry of base_footprint; base_link is 0.1 m ahead of it (static): the node's robot
    pose is base_link's."""
    node, tf_pub, odom, _ = camera_rig()
    tf_pub(make("tf2_msgs/msg/TFMessage", transforms=[
        transform_msg("base_footprint", "base_link", 0.0, 0.1, 0.0, 0.0, (0, 0, 0, 1))]))
    odom(convert.odometry_msg(40.0, Pose(1.0, 1.0, math.pi / 2), (0, 0), "odom",
                              "base_footprint"))
    sample = node._odom[-1]
    assert (sample.pose.x, sample.pose.y) == (pytest.approx(1.0), pytest.approx(1.1))
