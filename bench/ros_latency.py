"""Measure the time from a person detection to the /cmd_vel it produces, with ``companion
node`` as a separate process on loopback, over DDS and over Zenoh.

    python bench/ros_latency.py [--periods N] [--transports dds zenoh] [--modes ...]

This script acts as the robot (tests/ros/wire_driver.py): a person walks straight at 1 m/s,
the robot walks beside it with the commands it gets back. Per period it publishes /odom and
the person (geometry_msgs/PoseArray) and stamps, on its own monotonic clock, the moment just
before the detection is published and the moment the next /cmd_vel arrives: publish, two
wire hops, the node's period, receive. An upper bound on arrival -> /cmd_vel. Modes:

* ``lockstep``: the node with ``use_sim_time``; /clock is published right after the
  detection, so the node ticks as the data arrive (the lock-step contract, docs/ros2.md).
* ``timer``: the node on its own 20 Hz wall-clock timer; detections are published at a
  random phase of its period, so a detection waits for the next tick (half a period on
  average).
* ``compute``: :meth:`CompanionNode.tick` in this process over a MemoryTransport (messages
  still serialised), without and with a 720-beam LaserScan at 10 Hz: the node's own work.

The first 20 periods of each run are left out (discovery, start of the track). No LiDAR
in the wire modes (``ros.topics.scan: ''``). Each node process is stopped (SIGINT, then
SIGKILL) at the end; a run gives up after 10 periods without a command.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "ros"))
from wire_driver import Driver, Process, free_port, loopback_env, write_params

from companion.geometry import unicycle_step, wrap_pi
from companion.params import Params
from companion.ros import convert
from companion.ros.messages import typestore
from companion.ros.node import CompanionNode
from companion.ros.settings import RosParams, config_from_mapping
from companion.ros.transport import MemoryBus, MemoryTransport
from companion.sim.episode import start_in_slot
from companion.sim.lidar import cast
from companion.types import Circle, PersonDetection, PersonState, Pose

P = Params()
DT = P.dt
SKIP = 20
SPEED = 1.0


def person_at(t: float) -> tuple[float, float]:
    return SPEED * t, 0.0


def moved(robot: Pose, cmd: tuple[float, float], dt: float) -> Pose:
    x, y, th = unicycle_step(robot.x, robot.y, robot.theta, *cmd, dt)
    return Pose(x, y, wrap_pi(th))


def wire_run(transport: str, mode: str, periods: int, domain: int) -> list[float]:
    """Latencies (s) of one node process driven over ``transport`` in ``mode``."""
    ros = {"transport": transport, "domain_id": domain, "person_type": "pose_array",
           "use_sim_time": mode == "lockstep"}
    if transport == "zenoh":
        ros["zenoh_connect"] = f"tcp/127.0.0.1:{free_port()}"
    robot = start_in_slot(PersonState(0.0, 0.0, 0.0, SPEED, 0.0), P)
    cmd, latencies, misses = (SPEED, 0.0), [], 0
    with tempfile.TemporaryDirectory() as home:
        params = write_params(Path(home) / "node.yaml", {**ros, "topics": {"scan": ""}})
        with Driver(RosParams(**ros), clock=mode == "lockstep") as driver, \
                Process(["node", "--params", str(params)], loopback_env(Path(home), domain),
                        Path(home) / "node.log") as node:
            if not driver.wait_for_node(60.0):
                raise RuntimeError(f"{transport}: no /cmd_vel from the node\n{node.output()}")
            start = time.time()
            last = time.monotonic()
            for k in range(periods):
                if mode == "lockstep":
                    t = (k + 1) * DT
                    got = driver.lockstep(t, robot, cmd, [person_at(t)], timeout=2.0)
                    latency = None if got is None else got[0]
                else:
                    time.sleep(random.uniform(0.5 * DT, 1.5 * DT))
                    now = time.monotonic()
                    robot, last = moved(robot, cmd, now - last), now
                    t = time.time()
                    before = driver.received()
                    sent = driver.publish(t, robot, cmd, [person_at(t - start)])
                    got = driver.command_after(before, 1.0)
                    latency = None if got is None else got[0] - sent
                if latency is None:
                    misses += 1
                    if misses >= 10:
                        raise RuntimeError(f"{transport} {mode}: 10 periods without a command")
                    continue
                cmd = driver.commands[-1][1:]
                if mode == "lockstep":
                    robot = moved(robot, cmd, DT)
                if k >= SKIP:
                    latencies.append(latency)
    return latencies


def compute_run(periods: int, scan: bool) -> list[float]:
    """Times (s) of :meth:`CompanionNode.tick` over a MemoryTransport."""
    topics = {} if scan else {"scan": ""}
    config = config_from_mapping({"ros": {"person_type": "pose_array", "topics": topics}})
    bus = MemoryBus()
    node_side = MemoryTransport(bus, typestore())
    node = CompanionNode(config, node_side, time_base=convert.ABSOLUTE)   # stamps from 0
    robot_side = MemoryTransport(bus, node_side.typestore)
    r = config.ros
    odom = robot_side.publisher(r.topics.odom, "nav_msgs/msg/Odometry")
    people = robot_side.publisher(r.topics.person, "geometry_msgs/msg/PoseArray")
    lidar = robot_side.publisher("/scan", "sensor_msgs/msg/LaserScan")
    obstacles = [Circle(5.0 * i, 3.0, 0.3) for i in range(1, 2 + int(periods * DT * SPEED / 5))]
    rng = np.random.default_rng(1)
    robot = start_in_slot(PersonState(0.0, 0.0, 0.0, SPEED, 0.0), P)
    cmd, times = (SPEED, 0.0), []
    for k in range(periods):
        t = (k + 1) * DT
        odom(convert.odometry_msg(t, robot, cmd, r.odom_frame, r.base_frame))
        if scan and k % 2 == 0:
            seen = cast(robot, obstacles, (), person_at(t), P.lidar, rng)
            lidar(convert.scan_msg(t, seen, r.lidar_frame, 2 * DT))
        people(convert.person_msg([PersonDetection(t, *person_at(t), r.odom_frame)],
                                  "pose_array", t, r.odom_frame))
        start = time.perf_counter()
        out = node.tick(t)
        times.append(time.perf_counter() - start)
        bus.sent.clear()
        cmd = (out.v, out.omega)
        robot = moved(robot, cmd, DT)
    return times[SKIP:]


def row(name: str, seconds: list[float]) -> str:
    ms = 1e3 * np.asarray(seconds)
    return (f"{name:<38} {len(ms):>6} {np.median(ms):>9.3f} {np.percentile(ms, 99):>8.3f} "
            f"{ms.max():>8.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--periods", type=int, default=1000, help="periods per run (default 1000)")
    ap.add_argument("--transports", nargs="+", default=["dds", "zenoh"],
                    choices=["dds", "zenoh"])
    ap.add_argument("--modes", nargs="+", default=["lockstep", "timer", "compute"],
                    choices=["lockstep", "timer", "compute"])
    ap.add_argument("--domain-id", type=int, default=None,
                    help="DDS domain (default 1 + pid %% 200)")
    args = ap.parse_args()
    if args.periods <= SKIP:
        ap.error(f"--periods: expected more than {SKIP}, got {args.periods}")
    domain = args.domain_id if args.domain_id is not None else 1 + os.getpid() % 200
    lines = []
    for mode in args.modes:
        if mode == "compute":
            lines.append(row("in-process tick, no scan", compute_run(args.periods, False)))
            lines.append(row("in-process tick, 720-beam scan 10 Hz",
                             compute_run(args.periods, True)))
            continue
        for transport in args.transports:
            lines.append(row(f"{transport} {mode}", wire_run(transport, mode, args.periods,
                                                               domain)))
            print(lines[-1], flush=True)
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"\n{'detection -> /cmd_vel (ms)':<38} {'n':>6} {'median':>9} {'p99':>8} "
          f"{'max':>8}")
    print("\n".join(lines))
    print(f"({os.cpu_count()} cores; load average at the end {load})")


if __name__ == "__main__":
    main()
