"""Faults across processes on loopback (docs/ros2.md): the node killed, the robot killed, and a
second person in the detections. ``companion node`` and ``companion sim-robot`` run as
subprocesses bounded in time; the test process listens (or drives the robot) with companion's
own transports."""

from __future__ import annotations

import csv
import math
import time
from collections import Counter

import numpy as np
import pytest
from wire_driver import Driver, Process, free_port, loopback_env, status_of, write_params

from companion.geometry import unicycle_step, wrap_pi
from companion.params import Params
from companion.ros import convert
from companion.ros.settings import RosParams
from companion.sim.episode import start_in_slot, timed_out
from companion.types import PersonState, Pose

P = Params()
DT = P.dt


def transport_flags(transport: str, domain: int) -> tuple[list[str], dict]:
    """CLI flags and ``ros`` parameters of one transport on loopback (Zenoh: a fresh port)."""
    ros = {"transport": transport, "domain_id": domain}
    flags = ["--transport", transport, "--domain-id", str(domain)]
    if transport == "zenoh":
        ros["zenoh_connect"] = f"tcp/127.0.0.1:{free_port()}"
        flags += ["--zenoh-connect", ros["zenoh_connect"]]
    return flags, ros


# -- two people: the tracker keeps the companion --------------------------------------------

SPEED = 1.0          # m/s, the companion walks along +x from the origin
NOISE = 0.05         # m, standard deviation of every detected position
CLOSEST = 0.5        # m, the crossing bystander's closest approach to the companion
CROSS_AT = 3.0       # s, when the crossing bystander crosses the companion's line


def companion_at(t: float) -> tuple[float, float]:
    return SPEED * t, 0.0


def bystander_at(kind: str, t: float) -> tuple[float, float]:
    """``parallel``: 1.5 m to the companion's right at its speed (the robot walks on its
    left). ``crossing``: walks across the companion's line from its right at the same speed,
    behind it by ``CLOSEST * sqrt(2)`` where it crosses, so at its closest it is ``CLOSEST``
    m away (at ``CROSS_AT - CLOSEST / sqrt(2)`` s)."""
    if kind == "parallel":
        return SPEED * t, -1.5
    return SPEED * CROSS_AT - CLOSEST * math.sqrt(2.0), SPEED * (t - CROSS_AT)


@pytest.mark.parametrize("transport,kind", [("dds", "parallel"), ("dds", "crossing"),
                                            ("zenoh", "crossing")])
def test_a_second_person_does_not_take_the_track(tmp_path, ros_domain, transport, kind):
    """The robot (the test process, in lock step with the node) walks beside a person with a
    bystander in every PoseArray, in shuffled order after the first (the first detection of
    the first message starts the track: the companion); every status the node sends has its
    estimate on the companion, never lost, and the robot stays beside it."""
    _, ros = transport_flags(transport, ros_domain)
    ros.update(use_sim_time=True, person_type="pose_array", topics={"scan": ""})
    params = write_params(tmp_path / "node.yaml", ros)
    rng = np.random.default_rng(7)
    steps = int(round(7.0 / DT))
    h0 = PersonState(0.0, 0.0, 0.0, SPEED, 0.0)
    robot, velocity = start_in_slot(h0, P), (SPEED, 0.0)
    with Driver(RosParams(**{k: v for k, v in ros.items() if k != "topics"})) as driver, \
            Process(["node", "--params", str(params)], loopback_env(tmp_path, ros_domain),
                    tmp_path / "node.log") as node:
        assert driver.wait_for_node(60.0), node.output()
        closest = math.inf
        for k in range(steps):
            t = (k + 1) * DT
            people = [companion_at(t), bystander_at(kind, t)]
            closest = min(closest, math.dist(*people))
            if k > 0:
                rng.shuffle(people)
            seen = [(x + NOISE * rng.standard_normal(), y + NOISE * rng.standard_normal())
                    for x, y in people]
            got = driver.lockstep(t, robot, velocity, seen)
            assert got is not None, f"no /cmd_vel within 2 s at t = {t:.2f}\n{node.output()}"
            velocity = got[1:]
            x, y, th = unicycle_step(robot.x, robot.y, robot.theta, *velocity, DT)
            robot = Pose(x, y, wrap_pi(th))
        time.sleep(0.2)               # the last statuses
        statuses = list(driver.statuses)
    assert closest == pytest.approx(CLOSEST if kind == "crossing" else 1.5, abs=0.02)
    ticks = [s for s in statuses if s.t > DT / 2]          # after the wait at /clock = 0
    assert len(ticks) >= steps - 2
    for s in ticks:
        est = (s.values["person_x"], s.values["person_y"])
        true, other = companion_at(s.t), bystander_at(kind, s.t)
        assert math.dist(est, true) < 0.3, (s.t, est, true)
        assert math.dist(est, true) < math.dist(est, other), (s.t, est, other)
        assert s.values["person_track"] == "seen", s
        assert not {"person_lost", "reacquiring"} & set(s.reason.split("+")), s
    # the robot walked beside the companion: its reference point ends near the slot (left, 1 m)
    rx = robot.x + P.robot.d * math.cos(robot.theta)
    ry = robot.y + P.robot.d * math.sin(robot.theta)
    cx, cy = companion_at(steps * DT)
    assert math.hypot(rx - cx, ry - (cy + P.formation.distance)) < 0.3


# -- the node killed: the robot stops by its command timeout ---------------------------------

def read_log(path) -> dict[str, np.ndarray]:
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) for r in rows])
            for k in ("t", "v", "omega", "robot_v", "robot_omega", "robot_x", "robot_y")}


def same(a: tuple[float, float], b: tuple[float, float], tol: float = 1e-8) -> bool:
    """Equal to the 10 significant digits of log.csv."""
    return abs(a[0] - b[0]) <= tol and abs(a[1] - b[1]) <= tol


def last_hold_and_brake(cmd: list[tuple[float, float]]) -> tuple[int, int]:
    """``(c, b)``: from row ``b`` to the end every command is the previous one brought towards
    zero at the deceleration limits (:func:`timed_out`), and rows ``c .. b-1`` repeat one
    command (row ``c`` differs from row ``c-1``): the last command the robot received, applied
    from row ``c`` and held until the braking began."""
    j = len(cmd) - 1
    while j >= 1 and same(cmd[j], timed_out(cmd[j - 1], P)):
        j -= 1
    c = j
    while c >= 1 and same(cmd[c - 1], cmd[j]):
        c -= 1
    return c, j + 1


@pytest.mark.parametrize("transport", ["dds", pytest.param("zenoh", marks=pytest.mark.slow)])
def test_robot_stops_by_its_command_timeout_when_the_node_is_killed(tmp_path, ros_domain,
                                                                   transport):
    """The node is killed (SIGKILL: no zero velocity) once the test has heard 2.5 s of
    odometry in a figure-8 run of sim-robot (6 s; 10 s over Zenoh, where the listener
    joins the robot's router a few seconds late; over Zenoh both run on sim-robot's /clock).
    In sim-robot's log.csv, the command the
    robot executes (``v``, ``omega``) is the last command it received, one of the last the
    node sent (a listener in the test heard them), held for exactly
    ``robot.command_timeout_s`` (0.5 s) from the period the robot applied it (at most one
    period, 0.05 s, after it arrived: so braking starts within 0.55 s of the arrival), then
    brought to zero at ``supervisor.decel_max`` and ``angular_accel_max`` every period, and
    zero to the end; the base (``robot_v``, ``robot_omega``, no actuator lag with ideal
    sensing) with it."""
    from companion.ros.wire import open_transport

    flags, ros = transport_flags(transport, ros_domain)
    env = loopback_env(tmp_path, ros_domain)
    duration = 6 if transport == "dds" else 10    # a Zenoh listener joins up to 4 s late
    node_flags = robot_flags = flags
    if transport == "zenoh":
        # sim time (/clock from sim-robot): the node reaches the robot's router only after
        # Zenoh's connection retry (1 to 4 s), and sim-robot's wall-clock stamps count from
        # before its wait for the node, so its odometry could reach the node already stale
        params = write_params(tmp_path / "sim_time.yaml", {**ros, "use_sim_time": True})
        node_flags = [*flags, "--params", str(params)]
        robot_flags = [*flags, "--ros-params", str(params)]
    heard, odom = [], []
    listener = open_transport(RosParams(**ros), "fault_listener")
    try:
        listener.subscribe("/cmd_vel", "geometry_msgs/msg/Twist",
                           lambda m: heard.append((m.linear.x, m.angular.z)))
        listener.subscribe("/odom", "nav_msgs/msg/Odometry", lambda m: odom.append(1))
        with Process(["node", *node_flags], env, tmp_path / "node.log") as node, \
                Process(["sim-robot", "figure8", "--duration", str(duration), "--wait", "60",
                         "--out", str(tmp_path / "run"), *robot_flags], env,
                        tmp_path / "robot.log") as robot:
            end = time.monotonic() + 90
            while len(odom) < 50 and time.monotonic() < end and robot.proc.poll() is None:
                time.sleep(0.02)
            assert len(odom) >= 50, node.output() + robot.output()
            node.kill()
            killed_after = len(heard)
            assert robot.wait(60) == 0, robot.output()
    finally:
        listener.close()
    assert len(heard) == killed_after > 20
    log = read_log(tmp_path / "run" / "log.csv")
    cmd = list(zip(log["v"], log["omega"]))
    c, b = last_hold_and_brake(cmd)
    t = log["t"]
    assert len(t) == round(duration / DT) and 1.0 < t[c] < duration - 1.5, (len(t), t[c])
    assert any(same(cmd[c], h) for h in heard[-3:]), (cmd[c], heard[-3:])
    assert abs(cmd[c][0]) > 0.1                      # it was walking when the node died
    assert t[b] - t[c] == pytest.approx(P.robot.command_timeout_s, abs=1e-6)
    assert cmd[-1] == (0.0, 0.0)
    stopped = next(k for k in range(b, len(t)) if cmd[k] == (0.0, 0.0))
    brake_rows = max(math.ceil(abs(cmd[c][0]) / (P.supervisor.decel_max * DT) - 1e-9),
                     math.ceil(abs(cmd[c][1]) / (P.supervisor.angular_accel_max * DT) - 1e-9))
    assert stopped - b + 1 == brake_rows
    # row k holds the base's velocity at t_k, the command of row k - 1 (no lag)
    assert np.array_equal(log["robot_v"][b + 1:], log["v"][b:-1])
    assert log["robot_v"][-1] == 0.0 and log["robot_omega"][-1] == 0.0


# -- the robot killed: the node reports stale odometry and stops ------------------------------

def test_node_reports_stale_odometry_and_stops_when_the_robot_is_killed(tmp_path, ros_domain):
    """sim-robot is killed (SIGKILL) once the node has sent 40 statuses with the robot
    moving. From its first tick more than ``ros.odom_timeout_s`` (0.5 s, node time) after the
    last odometry stamp, every status the node sends says ``stopped`` (level ERROR) with
    ``odometry_stale`` among its reasons; its commands shrink by at most the deceleration
    limits per period down to zero, and /cmd_vel ends with zeros. The node keeps running and
    exits 0 on SIGINT."""
    from companion.ros.dds import DdsTransport

    flags, _ = transport_flags("dds", ros_domain)
    env = loopback_env(tmp_path, ros_domain)
    statuses, heard, odom = [], [], []
    with DdsTransport(node_name="fault_listener", domain_id=ros_domain) as listener:
        listener.subscribe("/companion/status", "diagnostic_msgs/msg/DiagnosticArray",
                           lambda m: statuses.append(status_of(m, time.perf_counter())))
        listener.subscribe("/cmd_vel", "geometry_msgs/msg/Twist",
                           lambda m: heard.append((m.linear.x, m.angular.z)))
        listener.subscribe("/odom", "nav_msgs/msg/Odometry",
                           lambda m: odom.append(convert.seconds(m.header.stamp)))
        with Process(["node", *flags], env, tmp_path / "node.log") as node:
            with Process(["sim-robot", "figure8", "--duration", "60", "--wait", "60",
                          "--out", str(tmp_path / "run"), *flags], env,
                         tmp_path / "robot.log") as robot:
                end = time.monotonic() + 90
                while time.monotonic() < end and robot.proc.poll() is None and sum(
                        abs(s.values["v"]) > 0.1 for s in list(statuses)) < 40:
                    time.sleep(0.02)
                robot.kill()
            before = len(statuses)
            last_odom = odom[-1]
            end = time.monotonic() + 20
            while time.monotonic() < end and not (
                    any("odometry_stale" in s.reason for s in statuses[before:])
                    and len(heard) > 10 and heard[-10:] == [(0.0, 0.0)] * 10):
                time.sleep(0.05)
            time.sleep(0.5)
            assert node.proc.poll() is None, node.output()
            assert node.stop() == 0
            assert "sent a zero velocity" in node.output()
    moving = statuses[:before]
    assert sum(abs(s.values["v"]) > 0.1 for s in moving) >= 40, \
        Counter(s.reason for s in moving)          # the robot never moved: why
    assert "odometry_stale" not in moving[-1].reason.split("+"), moving[-1]
    after = statuses[before:]
    first = next(i for i, s in enumerate(after) if "odometry_stale" in s.reason.split("+"))
    # stale once the node's time passes the last odometry stamp by the timeout (the test's
    # last stamp may differ from the node's by a period at the kill; load may delay ticks)
    timeout = RosParams().odom_timeout_s
    assert timeout - DT < after[first].t - last_odom <= timeout + 5 * DT
    for s in after[first:]:
        assert "odometry_stale" in s.reason.split("+") and s.level == 2, s
        assert s.values["status"] == "stopped"
    braking = after[max(first - 1, 0):]       # from the last command before the stop
    v = [s.values["v"] for s in braking]
    w = [s.values["omega"] for s in braking]
    tol = 1e-9
    for a, b in zip(v, v[1:]):
        assert abs(b) <= abs(a) + tol and abs(a) - abs(b) <= P.supervisor.decel_max * DT + tol
    for a, b in zip(w, w[1:]):
        assert abs(b - a) <= P.supervisor.angular_accel_max * DT + tol
    assert (v[-1], w[-1]) == (0.0, 0.0)
    assert heard[-10:] == [(0.0, 0.0)] * 10

