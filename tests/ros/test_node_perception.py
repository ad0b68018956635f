"""The node's perception is the stack's front end: it leaves the person out of the LiDAR's
obstacles only near the tracker's estimate, never at a detection the tracker refused."""

from __future__ import annotations

import math

from companion.params import ExtractorParams, LidarParams
from companion.perception import extract_obstacles
from companion.ros import convert
from companion.ros.messages import typestore
from companion.ros.node import CompanionNode
from companion.ros.settings import config_from_mapping
from companion.ros.transport import MemoryBus, MemoryTransport
from companion.sim.lidar import cast
from companion.types import Circle, PersonDetection, Pose

POST = Circle(1.2, 0.0, 0.1)


def post_scan():
    """A scan from the origin of a post 1.2 m ahead (no noise)."""
    return cast(Pose(0.0, 0.0, 0.0), [POST], [], None, LidarParams(noise_std=0.0))


def near_post(obstacles) -> bool:
    return any(math.hypot(o.x - POST.x, o.y - POST.y) < 0.2 for o in obstacles)


def test_a_nan_person_position_leaves_nothing_out():
    """``extract_obstacles`` with a person position that is not finite reports everything
    (it used to leave out every obstacle)."""
    assert near_post(extract_obstacles(post_scan(), (math.nan, math.nan), ExtractorParams()))
    assert not near_post(extract_obstacles(post_scan(), (1.2, 0.0), ExtractorParams()))


def test_nan_person_messages_hide_nothing_from_the_lidar():
    """A post 1.2 m ahead and /person messages that turn NaN: the tracker refuses them and
    loses the person, and the post stays an obstacle while the robot stops or searches (the
    node used to hand the LiDAR the newest detection, NaN, and saw no obstacles at all)."""
    bus = MemoryBus()
    node = CompanionNode(config_from_mapping({}), MemoryTransport(bus, typestore()),
                         time_base=convert.ABSOLUTE)
    pub = MemoryTransport(bus, typestore())
    send_odom = pub.publisher("/odom", "nav_msgs/msg/Odometry")
    send_scan = pub.publisher("/scan", "sensor_msgs/msg/LaserScan")
    send_person = pub.publisher("/person", "geometry_msgs/msg/PointStamped")
    scan = post_scan()
    reports = []
    for k in range(60):
        t = 10.0 + 0.05 * k
        send_odom(convert.odometry_msg(t, Pose(0.0, 0.0, 0.0), (0.0, 0.0), "odom", "base_link"))
        send_scan(convert.scan_msg(t, scan, "laser", 0.05))
        x = 1.0 if k < 10 else math.nan         # the person is seen, then NaN
        send_person(convert.person_msg([PersonDetection(t, x, 1.0, "odom")], "point", t,
                                       "odom"))
        node.tick(t)
        reports.append(node.report)
    lost = [r for r in reports[20:] if r.estimate is None]
    assert len(lost) > 20 and all("person_invalid" in r.reason for r in lost)
    assert all(near_post(r.obstacles) for r in lost)
