"""Helpers of the ROS 2 tests: sample messages of every type companion sends or receives, and a
real rclpy node (Jazzy, rmw_fastrtps_cpp) confined to 127.0.0.1 and run as a bounded subprocess.

The pip-installed ROS packages need one thing from the environment: LD_LIBRARY_PATH naming their
libraries, which their ``ros_wheels_bootstrapper`` .pth sets by re-executing Python once at
start-up; no ROS set-up script, AMENT_PREFIX_PATH or RMW_IMPLEMENTATION is needed (Fast DDS is the
only RMW installed; the tests name it anyway).
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from companion.ros.dds_base import LOOPBACK
from companion.ros.messages import message

PEER = Path(__file__).with_name("rclpy_peer.py")
RCLPY_PACKAGES = ("rclpy", "geometry_msgs", "nav_msgs", "sensor_msgs", "visualization_msgs",
                  "diagnostic_msgs", "rosgraph_msgs")
MISSING = [name for name in RCLPY_PACKAGES if importlib.util.find_spec(name) is None]
needs_rclpy = pytest.mark.skipif(
    bool(MISSING), reason=f"ROS 2 Jazzy's Python packages are not installed (missing: "
    f"{', '.join(MISSING)}); pip install -e '.[test]' installs them")

#: Fast DDS on the loopback interface only, as companion ships it for users (one UDPv4 transport
#: limited to 127.0.0.1, the built-in transports off, 127.0.0.1 as initial peer).
FASTDDS_LOOPBACK = (LOOPBACK / "fastdds.xml").read_text()


def stamp(store, sec=1_700_000_000, nanosec=123_456_789, frame="odom"):
    return message(store, "std_msgs/msg/Header", frame_id=frame,
                   stamp=message(store, "builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec))


def vector(store, x, y, z, msgtype="geometry_msgs/msg/Vector3"):
    return message(store, msgtype, x=x, y=y, z=z)


def samples(store) -> dict:
    """One message of each type the node and the simulated robot use, with odd-length strings
    and sequences so that alignment and padding are exercised."""
    m = lambda msgtype, **kw: message(store, msgtype, **kw)  # noqa: E731
    twist = m("geometry_msgs/msg/Twist", linear=vector(store, 0.75, -0.0, 0.0),
              angular=vector(store, 0.0, 0.0, -1.25))
    pose = m("geometry_msgs/msg/Pose", position=vector(store, 1.5, -2.25, 0.0,
                                                       "geometry_msgs/msg/Point"),
             orientation=m("geometry_msgs/msg/Quaternion", z=0.6, w=0.8))
    marker = lambda i, text: m(  # noqa: E731
        "visualization_msgs/msg/Marker", header=stamp(store), ns="companion", id=i, type=2,
        pose=pose, scale=vector(store, 0.3, 0.3, 0.3), text=text, frame_locked=bool(i % 2),
        color=m("std_msgs/msg/ColorRGBA", r=1.0, g=0.5, b=0.0, a=1.0),
        points=[vector(store, 0.1 * k, 0.0, 0.0, "geometry_msgs/msg/Point") for k in range(i)],
        lifetime=m("builtin_interfaces/msg/Duration", sec=0, nanosec=500_000_000))
    return {
        "geometry_msgs/msg/Twist": twist,
        "geometry_msgs/msg/TwistStamped": m("geometry_msgs/msg/TwistStamped",
                                            header=stamp(store, frame="base_link"), twist=twist),
        "nav_msgs/msg/Odometry": m(
            "nav_msgs/msg/Odometry", header=stamp(store), child_frame_id="base_link",
            pose=m("geometry_msgs/msg/PoseWithCovariance", pose=pose,
                   covariance=np.arange(36, dtype=np.float64) / 7.0),
            twist=m("geometry_msgs/msg/TwistWithCovariance", twist=twist,
                    covariance=np.eye(6).ravel() * 0.01)),
        "sensor_msgs/msg/LaserScan": m(
            "sensor_msgs/msg/LaserScan", header=stamp(store, frame="laser"),
            angle_min=-1.5, angle_max=1.5, angle_increment=0.5, time_increment=0.0,
            scan_time=0.1, range_min=0.05, range_max=12.0,
            ranges=np.array([1.0, 2.5, np.inf, 0.75, 3.0, 4.0, 12.5], dtype=np.float32),
            intensities=np.array([], dtype=np.float32)),
        "geometry_msgs/msg/PointStamped": m(
            "geometry_msgs/msg/PointStamped", header=stamp(store, frame="base_link"),
            point=vector(store, 1.25, 0.5, 0.0, "geometry_msgs/msg/Point")),
        "geometry_msgs/msg/PoseArray": m("geometry_msgs/msg/PoseArray", header=stamp(store),
                                         poses=[pose, pose]),
        "diagnostic_msgs/msg/DiagnosticArray": m(
            "diagnostic_msgs/msg/DiagnosticArray", header=stamp(store),
            status=[m("diagnostic_msgs/msg/DiagnosticStatus", level=1, name="companion",
                      message="odometry_lost", hardware_id="sim",
                      values=[m("diagnostic_msgs/msg/KeyValue", key="rho", value="0.412"),
                              m("diagnostic_msgs/msg/KeyValue", key="alpha", value="-1.0")])]),
        "visualization_msgs/msg/MarkerArray": m(
            "visualization_msgs/msg/MarkerArray", markers=[marker(0, "person"),
                                                           marker(3, "slot")]),
        "rosgraph_msgs/msg/Clock": m("rosgraph_msgs/msg/Clock", clock=m(
            "builtin_interfaces/msg/Time", sec=12, nanosec=500_000_000)),
        "tf2_msgs/msg/TFMessage": m("tf2_msgs/msg/TFMessage", transforms=[m(
            "geometry_msgs/msg/TransformStamped", header=stamp(store), child_frame_id="base_link",
            transform=m("geometry_msgs/msg/Transform", translation=vector(store, 1.0, 2.0, 0.0),
                        rotation=m("geometry_msgs/msg/Quaternion", w=1.0)))]),
    }


class Peer:
    """A running ``rclpy_peer.py``; :meth:`finish` tells it to stop and returns its report.
    The process is killed if it outlives its time limit."""

    def __init__(self, env: dict, plan: dict, folder: Path):
        self.plan_file = folder / "plan.json"
        self.plan_file.write_text(json.dumps(plan))
        self.timeout = plan["timeout"] + 10.0   # its start-up on top of its own deadline
        self.proc = subprocess.Popen([sys.executable, str(PEER), str(self.plan_file)], env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        self.started = time.monotonic()

    def running(self) -> bool:
        return self.proc.poll() is None and time.monotonic() - self.started < self.timeout

    def finish(self) -> dict:
        try:
            out, err = self.proc.communicate("done\n", timeout=max(
                1.0, self.timeout - (time.monotonic() - self.started)))
        except subprocess.TimeoutExpired:
            self.kill()
            pytest.fail("the rclpy peer did not finish in time")
        lines = [line for line in out.splitlines() if line.startswith("{")]
        assert self.proc.returncode == 0 and lines, f"rclpy peer failed: {err[-2000:]}"
        return json.loads(lines[-1])

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=5)
