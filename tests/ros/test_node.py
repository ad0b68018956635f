"""The node and the simulated robot over an in-memory ROS 2 graph (no network): the closed loop
equals the simulation, stale inputs stop the robot, frames and stamps place the inputs."""

from __future__ import annotations

import dataclasses
import math
import threading

import numpy as np
import pytest

from companion import metrics
from companion.ros import convert
from companion.ros.messages import typestore
from companion.ros.node import CompanionNode
from companion.ros.placement import pose_at
from companion.ros.settings import config_from_mapping
from companion.ros.sim_robot import Pacer, run_sim_robot
from companion.ros.spin import spin
from companion.ros.transport import MemoryBus, MemoryTransport
from companion.sim.runner import run_one
from companion.sim.scenario import load_scenario
from companion.types import PersonDetection, Pose, Scan
from stepping import tick


def graph():
    bus = MemoryBus()
    return bus, (lambda: MemoryTransport(bus, typestore()))


def lockstep(sensing: str, person_type: str, duration: float, scenario: str = "figure8",
             silent_from: float = math.inf):
    """sim-robot and node on one bus, the node ticked right after each sample's messages
    (until ``silent_from`` s)."""
    sc = load_scenario(scenario, {"sensing": sensing})
    bus, transport = graph()
    cfg = config_from_mapping({"ros": {"use_sim_time": True, "person_type": person_type}})
    cfg = dataclasses.replace(cfg, params=sc.params, controller=sc.controller)
    node = CompanionNode(cfg, transport())
    spec = dataclasses.replace(sc.episode(), duration=duration)
    log, robot = run_sim_robot(spec, transport(), cfg.ros, Pacer(0.0),
                               after=lambda t: tick(node, t) if t < silent_from - 1e-9 else None)
    return spec, log, robot, bus


@pytest.mark.parametrize("sensing", ["ideal", "realistic"])
def test_the_loop_over_the_wire_equals_the_simulation(sensing):
    """With detections that carry everything the sensing model measures (nav_msgs/Odometry),
    node + sim-robot give the simulation's trajectory: the wire loses nothing but rounding."""
    spec, log, robot, _ = lockstep(sensing, "odometry", 20.0)
    direct = run_one(dataclasses.replace(spec, obstacle_source="lidar"))
    assert robot.commands == len(log) == 400
    for column in ("robot_x", "robot_y", "rho", "alpha"):
        np.testing.assert_allclose(log[column], direct[column], atol=1e-6)


def test_point_detections_follow_the_person():
    """PointStamped detections (positions only): the tracker estimates the motion itself."""
    _, log, _, _ = lockstep("realistic", "point", 30.0)
    m = metrics.compute(log)
    assert m["rmse_rho_m"] < 0.2
    assert m["min_person_distance_m"] > 0.6


def odom(t: float, x: float, y: float, theta: float, v: float = 0.0, w: float = 0.0):
    return convert.odometry_msg(t, Pose(x, y, theta), (v, w), "odom", "base_link")


def person(t: float, x: float, y: float, frame: str = "odom"):
    return convert.person_msg([PersonDetection(t, x, y, frame)], "point", t, frame)


def node_on_bus(**ros):
    bus, transport = graph()
    node = CompanionNode(config_from_mapping({"ros": {"topics": {"scan": ""}, **ros}}),
                         transport(), time_base=convert.ABSOLUTE)
    pub = transport()
    return bus, node, pub.publisher("/odom", "nav_msgs/msg/Odometry"), \
        pub.publisher("/person", "geometry_msgs/msg/PointStamped")


def statuses(bus):
    ts = typestore()
    return [ts.deserialize_cdr(data, kind).status[0] for topic, kind, data in bus.sent
            if topic == "/companion/status"]


def test_stale_odometry_stops_the_robot_and_fresh_odometry_resumes():
    bus, node, send_odom, send_person = node_on_bus()
    t = 0.0
    for k in range(40):                       # 2 s of a person walking ahead-left, odometry fresh
        t = 100.0 + 0.05 * k
        send_odom(odom(t, 0.05 * k, 0.0, 0.0, 1.0))
        send_person(person(t, 0.05 * k + 0.3, 1.0))
        cmd = tick(node, t)
    assert cmd.status != "stopped" and "odometry" not in cmd.reason, cmd.reason
    for k in range(40, 60):                   # odometry stops, detections go on
        t = 100.0 + 0.05 * k
        send_person(person(t, 0.05 * k + 0.3, 1.0))
        cmd = tick(node, t)
    assert cmd.status == "stopped" and cmd.reason.startswith("odometry_stale")
    assert cmd.v == pytest.approx(0.0, abs=1e-9)
    last = statuses(bus)[-1]
    assert last.level == 2 and last.message.startswith("odometry_stale")
    for k in range(60, 80):                   # odometry back
        t = 100.0 + 0.05 * k
        send_odom(odom(t, 2.0, 0.0, 0.0))
        send_person(person(t, 0.05 * k + 0.3, 1.0))
        cmd = tick(node, t)
    assert "odometry_stale" not in cmd.reason and cmd.status != "stopped"


def scan_rig():
    """A node with a 0.3 s scan timeout, publishers of /odom, /scan and /person, the bus."""
    bus, transport = graph()
    node = CompanionNode(config_from_mapping({"ros": {"scan_timeout_s": 0.3}}), transport(),
                         time_base=convert.ABSOLUTE)
    pub = transport()
    return (node, pub.publisher("/odom", "nav_msgs/msg/Odometry"),
            pub.publisher("/scan", "sensor_msgs/msg/LaserScan"),
            pub.publisher("/person", "geometry_msgs/msg/PointStamped"), bus)


def test_no_scan_for_longer_than_its_timeout_stops_the_robot():
    node, send_odom, send_scan, send_person, bus = scan_rig()
    scan = convert.scan_msg

    empty = Scan(np.linspace(-1.5, 1.5, 61), np.full(61, np.inf), 0.0, 0.0, 0.0, 0.05, 10.0)
    reasons = []
    for k in range(30):
        t = 5.0 + 0.05 * k
        send_odom(odom(t, 0.0, 0.0, 0.0))
        send_person(person(t, 0.0, 1.0))
        if k < 10:
            send_scan(scan(t, empty, "laser", 0.1))
        reasons.append(tick(node, t).reason)
    assert "scan_stale" not in reasons[9]
    assert all("scan_stale" in r for r in reasons[17:])    # 0.3 s after the last scan at 5.45


def test_robot_frame_detections_are_placed_with_the_odometry_pose_at_their_stamp():
    """The robot drives along +y (heading pi/2) at 1 m/s; a person 1 m ahead in base_link,
    seen at a stamp between two odometry samples, is at the interpolated pose + 1 m."""
    bus, node, send_odom, send_person = node_on_bus()
    for k in range(11):
        t = 10.0 + 0.1 * k
        send_odom(odom(t, 0.0, 0.1 * k, math.pi / 2, 1.0))
    d = node.placer.detection(PersonDetection(10.55, 1.0, 0.0, "base_link"), node._odom,
                              "world")
    assert (d.x, d.y, d.frame) == (pytest.approx(0.0, abs=1e-9), pytest.approx(1.55),
                                   "world")
    unknown = node.placer.detection(PersonDetection(10.55, 1.0, 0.0, "camera"), node._odom,
                                    "world")
    assert unknown.frame == "camera"          # the tracker rejects it (detection_frame)


def test_pose_at_interpolates_between_samples_across_the_angle_seam():
    from collections import deque
    a = convert.OdometrySample(0.0, Pose(0.0, 0.0, math.pi - 0.1), (0.0, 0.0))
    b = convert.OdometrySample(1.0, Pose(1.0, 2.0, -math.pi + 0.1), (0.0, 0.0))
    mid = pose_at(deque([a, b]), 0.5)
    assert (mid.x, mid.y) == (pytest.approx(0.5), pytest.approx(1.0))
    assert abs(abs(mid.theta) - math.pi) < 1e-9
    ahead = pose_at(deque([convert.OdometrySample(0.0, Pose(0, 0, 0), (1.0, 0.0))]), 0.2)
    assert ahead.x == pytest.approx(0.2)
    assert pose_at(deque(), 0.0) is None


def test_spin_ends_with_a_zero_velocity():
    bus, node, send_odom, _ = node_on_bus()
    stop = threading.Event()
    threading.Timer(0.3, stop.set).start()
    ticks = spin(node, stop)
    assert ticks >= 3
    ts = typestore()
    cmds = [ts.deserialize_cdr(d, k) for topic, k, d in bus.sent if topic == "/cmd_vel"]
    assert len(cmds) == ticks + 1
    assert (cmds[-1].linear.x, cmds[-1].angular.z) == (0.0, 0.0)


def test_person_odometry_round_trip_keeps_what_was_measured():
    full = PersonDetection(3.5, 1.0, 2.0, "odom", (0.01, 0.002, 0.002, 0.04), 0.3, 0.1, 1.2,
                           0.2, (0.05, 0.06))
    part = PersonDetection(3.5, 1.0, 2.0, "odom")
    ts = typestore()
    for p in (full, part):
        msg = convert.person_msg([p], "odometry", p.t, p.frame)
        back = convert.people_from(ts.deserialize_cdr(ts.serialize_cdr(
            msg, "nav_msgs/msg/Odometry"), "nav_msgs/msg/Odometry"), "odometry")[0]
        for got, want in zip(dataclasses.astuple(back), dataclasses.astuple(p), strict=True):
            assert got == pytest.approx(want) if want is not None else got is None


def test_stamps_round_trip_to_the_nanosecond():
    for t in (0.0, 1.5, 1_764_000_000.123456789, 0.999_999_999_6):
        assert convert.seconds(convert.time_msg(t)) == pytest.approx(t, abs=1e-9)
        assert 0 <= convert.time_msg(t).nanosec < 1_000_000_000


def test_odometry_and_scans_from_the_future_are_dropped_with_a_reason():
    """Stamped later than the node's time plus tracker.future_tolerance_s (a clock ahead, a
    corrupt stamp): odometry_future, scan_future; a scan from the future does not hide that
    the scans stopped."""
    node, send_odom, send_scan, send_person, bus = scan_rig()
    empty = Scan(np.linspace(-1.5, 1.5, 61), np.full(61, np.inf), 0.0, 0.0, 0.0, 0.05, 10.0)
    cmds = []
    for k in range(30):
        t = 5.0 + 0.05 * k
        send_odom(odom(t, 0.0, 0.0, 0.0))
        if k == 12:
            send_odom(odom(t + 5.0, 0.0, 0.0, 0.0))
        send_person(person(t, 0.0, 1.0))
        if k < 10:
            send_scan(convert.scan_msg(t, empty, "laser", 0.1))
        if k == 10:
            send_scan(convert.scan_msg(t + 5.0, empty, "laser", 0.1))
        cmds.append(tick(node, t))
    assert "scan_future" in cmds[10].reason.split("+") and cmds[10].status != "ok"
    assert "odometry_future" in cmds[12].reason.split("+") and cmds[12].status != "ok"
    assert "odometry_future" not in cmds[13].reason
    assert "scan_stale" not in cmds[9].reason
    assert all("scan_stale" in c.reason for c in cmds[17:])   # 0.3 s after the scan at 5.45
    assert statuses(bus)[10].message == cmds[10].reason


def test_a_node_that_ticked_before_any_odometry_starts_from_the_robots_velocity():
    """A robot already moving when the node starts (the lock-step robot's wait at /clock 0):
    the rate limits start from the first odometry's velocity, not from the zero the node
    sent before it had any, so the commands equal those of a node that waited."""
    def run(tick_at_zero: bool) -> list[tuple[float, float]]:
        bus, node, send_odom, send_person = node_on_bus()
        if tick_at_zero:
            assert tick(node, 0.0).reason.startswith("odometry_stale")
        out = []
        for k in range(1, 21):
            t = 0.05 * k
            send_odom(odom(t, 1.0 * t, 0.0, 0.0, 1.0))
            send_person(person(t, 1.0 * t + 0.2, 1.0))
            cmd = tick(node, t)
            out.append((cmd.v, cmd.omega))
        return out

    waited, early = run(False), run(True)
    assert early[0][0] > 0.8                  # not a ramp from 0 at the acceleration limit
    assert early == waited


def test_spin_ticks_on_every_clock_of_k_dt():
    """With ``use_sim_time``, ``spin`` ticks at each /clock of exactly k * dt (in nanoseconds)
    although its schedule sums dt and reads a hair later from k = 15 at 20 Hz: lock step
    (sim-robot --lockstep) needs an answer to every period."""
    bus, store = MemoryBus(), typestore()
    node = CompanionNode(config_from_mapping({"ros": {"use_sim_time": True}}),
                         MemoryTransport(bus, store))
    clock = MemoryTransport(bus, store).publisher("/clock", "rosgraph_msgs/msg/Clock")
    ticks = threading.Semaphore(0)
    bus.subscribers["/cmd_vel"].append(("geometry_msgs/msg/Twist", lambda _: ticks.release()))
    stop = threading.Event()
    thread = threading.Thread(target=spin, args=(node, stop), daemon=True)
    thread.start()
    try:
        for k in range(40):
            clock(convert.clock_msg(k * node.config.params.dt))
            assert ticks.acquire(timeout=60.0 if k == 0 else 5.0), f"no tick at k = {k}"
    finally:
        stop.set()
        thread.join(timeout=5.0)


def test_sim_robot_logs_the_node_status_and_its_command_timeout():
    """sim-robot's log carries the node's /companion/status; when the node falls silent (it
    stops ticking at 2 s) the robot keeps the last command for robot.command_timeout_s, then
    brakes at the deceleration limits to a stop, logged as stopped: command_timeout."""
    spec, log, _, _ = lockstep("ideal", "odometry", 4.0, silent_from=2.0)
    p, t = spec.params, log["t"]
    talking = t < 2.0 - 1e-9
    assert set(log["status"][talking]) == {"ok"}
    held = (t >= 2.0 - 1e-9) & (t < 2.0 + p.robot.command_timeout_s - p.dt - 1e-9)
    assert np.all(log["v"][held] == log["v"][talking][-1])
    braking = t >= 2.0 + p.robot.command_timeout_s - p.dt - 1e-9
    assert set(log["reason"][braking]) == {"command_timeout"}
    dv = -np.diff(log["v"][braking])
    assert np.all(dv <= p.supervisor.decel_max * p.dt + 1e-12) and log["v"][-1] == 0.0


def test_the_robot_logs_the_nodes_estimate_and_the_status_its_measured_delays():
    """sim-robot takes the node's person estimate from /companion/status, so a two-process run
    splits its slot error as an in-process one does; the status carries the detection
    latency and actuator lag the supervisor measured."""
    spec, log, robot, _ = lockstep("realistic", "odometry", 10.0)
    seen = np.isfinite(log["estimate_error_m"])
    assert seen.mean() > 0.9
    assert np.median(log["estimate_error_m"][seen]) < 0.2
    m = metrics.compute(log)
    assert m["rms_estimate_error_m"] is not None and m["rms_tracking_error_m"] is not None
    cmd = convert.status_msg(1.0, *robot_command(), None, delays=(0.125, 0.2))
    values = {kv.key: kv.value for kv in cmd.status[0].values}
    assert float(values["latency_measured_s"]) == 0.125
    assert float(values["actuator_tau_measured_s"]) == 0.2
    back = convert.estimate_of(cmd)
    assert back is not None and back.state.x == pytest.approx(1.5)
    assert convert.estimate_of(convert.status_msg(1.0, *robot_command(None), None)) is None


def robot_command(estimate=...):
    """A command and its step report with ``estimate`` (default: one)."""
    from companion.types import Command, PersonEstimate, PersonState, StepReport

    if estimate is ...:
        s = PersonState(1.5, 2.0, 0.3, 1.0, 0.1)
        estimate = PersonEstimate(s, 0.05, np.zeros((5, 5)), 0.0, "seen", s)
    return Command(0.5, 0.1), StepReport(estimate=estimate)


def test_a_node_on_the_system_clock_says_so_when_a_clock_is_published():
    """sim-robot in lock step publishes /clock; a node left on the system clock (no
    use_sim_time) takes every input as stale: within a second of its time it says that a clock
    is published and it ignores it, and the robot sees that the node never started."""
    sc = load_scenario("line")
    bus, transport = graph()
    node_cfg = dataclasses.replace(config_from_mapping({"ros": {"person_type": "point"}}),
                                   params=sc.params, controller=sc.controller)
    node = CompanionNode(node_cfg, transport())
    robot_ros = config_from_mapping({"ros": {"use_sim_time": True,
                                             "person_type": "point"}}).ros
    said = []

    def after(t):
        tick(node, node.now())
        said.append((t, list(node.warnings)))

    spec = dataclasses.replace(sc.episode(), duration=3.0)
    log, robot = run_sim_robot(spec, transport(), robot_ros, Pacer(0.0), after=after)
    first = next(t for t, w in said if any("a clock is published, but the node keeps the "
                                           "system clock" in line for line in w))
    assert first <= 1.0 + 1e-9
    assert robot.started is False and set(log["status"]) == {"stopped"}


def test_a_node_on_the_clock_starts_the_loop():
    _, log, robot, _ = lockstep("ideal", "point", 2.0, "line")
    assert robot.started is True and "ok" in set(log["status"])


def test_use_sim_time_is_a_flag_of_the_node_command():
    from companion.apps.cli import parser
    from companion.apps.rosapps import _ros_overrides
    from companion.ros.settings import RosParams

    args = parser().parse_args(["node", "--scenario", "line", "--use-sim-time"])
    assert _ros_overrides(RosParams(), args).use_sim_time
    args = parser().parse_args(["node", "--scenario", "line"])
    assert not _ros_overrides(RosParams(), args).use_sim_time


def test_sim_robot_says_how_far_it_is_every_five_seconds_of_wall_time(capsys, monkeypatch):
    from companion.apps import rosapps

    wall = iter([0.0, 1.0, 5.5, 5.6, 6.0, 10.7, 10.8])
    monkeypatch.setattr(rosapps.time, "monotonic", lambda: next(wall))
    sample = rosapps.progress_lines(60.0)
    for t in (0.05, 0.1, 0.15, 0.2):
        sample(t)
    assert capsys.readouterr().out.splitlines() == ["companion sim-robot: 0.1 of 60 s",
                                                    "companion sim-robot: 0.2 of 60 s"]
