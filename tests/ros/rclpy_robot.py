"""A differential-drive robot written in rclpy (Jazzy, rmw_fastrtps_cpp) for the closed-loop
tests, run as a bounded subprocess: ``python rclpy_robot.py PLAN.json``.

It is a third-party ROS 2 robot, so it imports nothing of companion: an ideal unicycle (the
exact arc of each period, no actuator lag) with ros2_control's 0.5 s command timeout, driven
in lock step with a node on ``use_sim_time`` (docs/ros2.md):

1. wait until the graph shows the node's endpoints, then publish /clock = 0 every 50 ms until
   a first /cmd_vel arrives;
2. for k = 0..steps-1, at the stamp s = (k + 1) * dt: /odom (pose and velocity at k), /scan
   (every ``scan_every`` periods; every beam +inf: no return), /person (the plan's person
   state at k as nav_msgs/Odometry, covariances 0: measured exactly), the plan's malformed
   messages for k, and last /clock = s; then wait up to ``step_wait`` s of wall time for a
   /cmd_vel sent after that /clock and apply it over the period; without one, keep the last
   command and brake at the deceleration limits once it is ``command_timeout`` s old.

The plan (JSON): dt, steps, start [x, y, theta], velocity [v, omega], person [[x, y, theta,
v, omega], ...] (one per step), cmd_vel_stamped, scan_every, scan_beams, range_min,
range_max, command_timeout, decel [m/s^2, rad/s^2], wait (s for the node), step_wait (s),
timeout (s, the whole run), inject {"k": [[topic, kind, value], ...]} (see ``malformed``),
set_at {"k": [[name, value], ...]} (parameters the robot sets on /companion before step k's
clock, as ``ros2 param set`` would), out (the log's file). The log: per step t, pose, applied
velocity, whether a command came and its stamp (TwistStamped); the parameters set (sets); the
/companion/status messages heard (stamp, level, message); the phase the run ended in.
"""

import json
import math
import sys
import time

import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan

RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
SENSOR = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
CLOCK = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)


def stamp(t):
    """builtin_interfaces/Time of t seconds, nanoseconds rounded."""
    ns = int(round(t * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def arc(x, y, theta, v, omega, dt):
    """The pose after dt s at constant v and omega: the exact circular arc (the formula of
    companion.geometry.unicycle_step), the heading wrapped."""
    half = 0.5 * omega * dt
    sinc = 1.0 - half * half / 6.0 if abs(half) < 1e-6 else math.sin(half) / half
    dist = v * dt * sinc
    heading = theta + omega * dt
    if not -math.pi < heading <= math.pi:       # to (-pi, pi], as companion.geometry.wrap_pi
        heading = (heading + math.pi) % (2.0 * math.pi) - math.pi
    return x + dist * math.cos(theta + half), y + dist * math.sin(theta + half), heading


def braked(command, decel, dt):
    """One period of a base whose commands stopped: each velocity towards 0 at its limit."""
    return tuple(math.copysign(max(abs(c) - a * dt, 0.0), c) for c, a in zip(command, decel))


def odometry(t, x, y, theta, v, omega, child="base_link"):
    msg = Odometry()
    msg.header.stamp, msg.header.frame_id, msg.child_frame_id = stamp(t), "odom", child
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.z = math.sin(0.5 * theta)
    msg.pose.pose.orientation.w = math.cos(0.5 * theta)
    msg.twist.twist.linear.x, msg.twist.twist.angular.z = v, omega
    return msg


def scan(t, plan, ranges=None):
    n = plan["scan_beams"]
    msg = LaserScan()
    msg.header.stamp, msg.header.frame_id = stamp(t), "laser"
    msg.angle_increment = 2.0 * math.pi / n
    msg.angle_min, msg.angle_max = -math.pi, math.pi - msg.angle_increment
    msg.scan_time = plan["dt"] * plan["scan_every"]
    msg.range_min, msg.range_max = plan["range_min"], plan["range_max"]
    msg.ranges = [math.inf] * n if ranges is None else ranges
    return msg


def malformed(topic, kind, value, s, pose, velocity, person, plan):
    """One bad message on ``topic`` at stamp s: ``nan`` (its position NaN), ``shift`` (stamped
    ``value`` s from s: the past or the future), ``empty`` (a scan without beams)."""
    t = s + value if kind == "shift" else s
    if topic == "/scan":
        return scan(t, plan, ranges=[] if kind == "empty" else None)
    msg = odometry(t, *pose, *velocity) if topic == "/odom" else odometry(t, *person, "")
    if kind == "nan":
        msg.pose.pose.position.x = math.nan
    return msg


class Robot:
    def __init__(self, node, plan):
        self.node, self.plan = node, plan
        self.odom = node.create_publisher(Odometry, "/odom", RELIABLE)
        self.scan = node.create_publisher(LaserScan, "/scan", SENSOR)
        self.person = node.create_publisher(Odometry, "/person", RELIABLE)
        self.clock = node.create_publisher(Clock, "/clock", CLOCK)
        kind = TwistStamped if plan["cmd_vel_stamped"] else Twist
        node.create_subscription(kind, "/cmd_vel", self.on_cmd, RELIABLE)
        node.create_subscription(DiagnosticArray, "/companion/status", self.on_status, RELIABLE)
        self.commands, self.last, self.statuses = 0, None, []
        self.params = None

    def on_cmd(self, msg):
        tw = getattr(msg, "twist", msg)
        ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec \
            if hasattr(msg, "header") else None
        self.commands, self.last = self.commands + 1, (tw.linear.x, tw.angular.z, ns)

    def on_status(self, msg):
        for st in msg.status:
            self.statuses.append([msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
                                  int.from_bytes(st.level, "little") if isinstance(
                                      st.level, bytes) else int(st.level), st.message])

    def spin_until(self, done, seconds):
        end = time.monotonic() + seconds
        while not done() and time.monotonic() < end:
            rclpy.spin_once(self.node, timeout_sec=0.01)
        return done()

    def set_parameter(self, name, value):
        """``ros2 param set /companion NAME VALUE`` from the robot: (successful, reason), or
        None if no answer came in 5 s."""
        if self.params is None:
            self.params = AsyncParameterClient(self.node, "/companion")
            self.params.wait_for_services(timeout_sec=5.0)
        future = self.params.set_parameters([Parameter(name, value=value)])
        self.spin_until(future.done, 5.0)
        if not future.done():
            return None
        result = future.result().results[0]
        return [result.successful, result.reason]

    def node_ready(self):
        """The node's endpoints are in our graph: it subscribes to what we publish and
        publishes /cmd_vel."""
        n = self.node
        return (n.count_subscribers("/clock") and n.count_subscribers("/odom")
                and n.count_subscribers("/person") and n.count_subscribers("/scan")
                and n.count_publishers("/cmd_vel"))

    def run(self):
        plan, dt = self.plan, self.plan["dt"]
        log = {"steps": [], "statuses": self.statuses, "phase": "discovery"}
        deadline = time.monotonic() + plan["timeout"]
        if not self.spin_until(self.node_ready, plan["wait"]):
            return log
        self.spin_until(lambda: False, 0.5)      # the node's side of the discovery
        log["phase"] = "waiting"

        def waited():
            self.clock.publish(Clock(clock=stamp(0.0)))
            return self.spin_until(lambda: self.commands > 0, 0.05)
        if not self.spin_until(waited, plan["wait"]):
            return log
        log["phase"] = "running"
        (x, y, theta), velocity = plan["start"], tuple(plan["velocity"])
        base, last_cmd_t = velocity, 0.0
        for k in range(plan["steps"]):
            if time.monotonic() > deadline:
                return log
            t, s = k * dt, (k + 1) * dt
            self.odom.publish(odometry(s, x, y, theta, *velocity))
            if k % plan["scan_every"] == 0:
                self.scan.publish(scan(s, plan))
            person = plan["person"][k]
            self.person.publish(odometry(s, *person, ""))
            for topic, kind, value in plan["inject"].get(str(k), []):
                pub = {"/odom": self.odom, "/person": self.person, "/scan": self.scan}[topic]
                pub.publish(malformed(topic, kind, value, s, (x, y, theta), velocity, person,
                                      plan))
            for name, value in plan.get("set_at", {}).get(str(k), []):
                log.setdefault("sets", []).append([k, name, self.set_parameter(name, value)])
            before = self.commands
            self.clock.publish(Clock(clock=stamp(s)))
            came = self.spin_until(lambda n=before: self.commands > n, plan["step_wait"])
            if came:
                base, last_cmd_t = self.last[:2], t
            elif t - last_cmd_t >= plan["command_timeout"] - 1e-9:
                base = braked(base, plan["decel"], dt)
            log["steps"].append([t, x, y, theta, *base, came, self.last[2] if came else None])
            x, y, theta = arc(x, y, theta, *base, dt)
            velocity = base
        self.spin_until(lambda: False, 0.3)      # the last statuses
        log["phase"] = "done"
        return log


def main():
    with open(sys.argv[1]) as f:
        plan = json.load(f)
    rclpy.init()
    node = rclpy.create_node("rclpy_robot")
    try:
        log = Robot(node, plan).run()
    finally:
        node.destroy_node()
        rclpy.shutdown()
    with open(plan["out"], "w") as f:
        json.dump(log, f)


if __name__ == "__main__":
    main()
