"""A scripted robot on the wire for the fault tests and the latency bench, and ``companion
node`` / ``companion sim-robot`` as bounded subprocesses on loopback.

:class:`Driver` stands where a robot stands: it publishes /odom and the people on /person
(a geometry_msgs/PoseArray in the odometry frame) and, in lock step (the node with
``ros.use_sim_time``), /clock last; it records every /cmd_vel and /companion/status it gets
back with the arrival time on its own monotonic clock. :meth:`Driver.lockstep` follows the
lock-step contract of docs/ros2.md: /clock = 0 every 50 ms until a first /cmd_vel, then per
period the inputs, /clock, and a bounded wait for the command.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import yaml

from companion.ros import convert
from companion.ros.settings import RosParams
from companion.ros.transport import Qos
from companion.ros.wire import open_transport
from companion.types import PersonDetection, Pose

CLI = [sys.executable, "-m", "companion.apps.cli"]
TWIST = "geometry_msgs/msg/Twist"
STATUS = "diagnostic_msgs/msg/DiagnosticArray"


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (for a Zenoh router)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def loopback_env(home: Path, domain: int) -> dict:
    """The environment of a companion subprocess: nothing inherited from a ROS, DDS or Zenoh
    set-up (so cyclonedds keeps to loopback), HOME in a temp folder, this run's domain."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("ROS_", "CYCLONEDDS_", "ZENOH_"))}
    env.update(HOME=str(home), ROS_DOMAIN_ID=str(domain))
    return env


def write_params(path: Path, ros: dict, **sections: Any) -> Path:
    """A node parameters YAML: ``companion: ros__parameters: {ros: ros, **sections}``."""
    path.write_text(yaml.safe_dump({"companion": {"ros__parameters": {"ros": ros,
                                                                      **sections}}}))
    return path


class Process:
    """A companion subprocess (``args`` after ``companion``), its output in a file; on leaving
    the ``with`` block it is stopped: SIGINT, then SIGKILL if it has not ended within
    ``grace`` s."""

    def __init__(self, args: Sequence[str], env: dict, log: Path, grace: float = 20.0):
        self.log, self.grace = log, grace
        self._out = open(log, "w")
        self.proc = subprocess.Popen([*CLI, *args], env=env, stdout=self._out,
                                     stderr=subprocess.STDOUT, text=True)

    def __enter__(self) -> Process:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def kill(self) -> None:
        """SIGKILL: the process ends without a word (no zero velocity)."""
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(timeout=10)

    def wait(self, timeout: float) -> int:
        """Its exit code, killing it if it runs ``timeout`` s longer."""
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            raise

    def stop(self) -> int:
        """SIGINT (the node then publishes a zero velocity and exits 0); SIGKILL after
        ``grace`` s. Returns the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=self.grace)
            except subprocess.TimeoutExpired:
                self.kill()
        self._out.close()
        return self.proc.returncode

    def output(self) -> str:
        if not self._out.closed:
            self._out.flush()
        return self.log.read_text()


class Status(NamedTuple):
    """One /companion/status as received: arrival (monotonic s), the node's time (its
    stamp), level, message and the key-value pairs (numbers as floats)."""

    arrived: float
    t: float
    level: int
    reason: str
    values: dict


def status_of(msg: Any, arrived: float) -> Status:
    s = msg.status[0]
    values = {}
    for kv in s.values:
        try:
            values[kv.key] = float(kv.value)
        except ValueError:
            values[kv.key] = kv.value
    return Status(arrived, convert.seconds(msg.header.stamp), int(s.level), s.message, values)


class Driver:
    """See the module docstring. ``ros`` names the transport (``dds``; ``zenoh``: the driver
    is the router at ``ros.zenoh_connect``, as a robot runs rmw_zenohd), the domain and the
    topics; ``clock`` publishes /clock (the node with ``use_sim_time``)."""

    def __init__(self, ros: RosParams, clock: bool = True, odom_frame: str = "odom"):
        self.ros, self.frame = ros, odom_frame
        self.transport = open_transport(ros, "companion_driver", robot=True)
        t = ros.topics
        self._odom = self.transport.publisher(t.odom, "nav_msgs/msg/Odometry")
        self._person = self.transport.publisher(t.person, "geometry_msgs/msg/PoseArray")
        self._clock = self.transport.publisher(t.clock, "rosgraph_msgs/msg/Clock",
                                               Qos(reliable=False, depth=1)) if clock else None
        self._cond = threading.Condition()
        self.commands: list[tuple[float, float, float]] = []   # (arrived, v, omega)
        self.statuses: list[Status] = []
        self.transport.subscribe(t.cmd_vel, TWIST, self._on_cmd)
        self.transport.subscribe(t.status, STATUS, self._on_status)

    def close(self) -> None:
        self.transport.close()

    def __enter__(self) -> Driver:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _on_cmd(self, msg: Any) -> None:
        now = time.perf_counter()
        v, w = convert.twist_velocity(msg)
        with self._cond:
            self.commands.append((now, v, w))
            self._cond.notify_all()

    def _on_status(self, msg: Any) -> None:
        status = status_of(msg, time.perf_counter())
        with self._cond:
            self.statuses.append(status)

    def received(self) -> int:
        with self._cond:
            return len(self.commands)

    def wait_commands(self, count: int, timeout: float) -> bool:
        """Wait up to ``timeout`` s until ``count`` commands have arrived in all."""
        with self._cond:
            return self._cond.wait_for(lambda: len(self.commands) >= count, timeout)

    def wait_for_node(self, timeout: float) -> bool:
        """/clock = 0 every 50 ms (none without ``clock``) until a first /cmd_vel arrives."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self._clock is not None:
                self._clock(convert.clock_msg(0.0))
            if self.wait_commands(1, 0.05):
                return True
        return False

    def publish(self, t: float, robot: Pose, velocity: tuple[float, float],
                people: Sequence[tuple[float, float]]) -> float:
        """/odom and the people (odometry frame) stamped ``t``; returns the monotonic time
        just before the people were published."""
        r = self.ros
        self._odom(convert.odometry_msg(t, robot, velocity, self.frame, r.base_frame))
        group = [PersonDetection(t, x, y, self.frame) for x, y in people]
        sent = time.perf_counter()
        self._person(convert.person_msg(group, "pose_array", t, self.frame))
        return sent

    def lockstep(self, t: float, robot: Pose, velocity: tuple[float, float],
                 people: Sequence[tuple[float, float]], timeout: float = 2.0
                 ) -> tuple[float, float, float] | None:
        """One lock-step period at stamp ``t``: /odom, /person, then /clock; waits up to
        ``timeout`` s for the /cmd_vel it produces. Returns ``(latency, v, omega)``, the
        latency from publishing the people to the command's arrival (s), or None."""
        before = self.received()
        sent = self.publish(t, robot, velocity, people)
        self._clock(convert.clock_msg(t))
        got = self.command_after(before, timeout)
        return None if got is None else (got[0] - sent, got[1], got[2])

    def command_after(self, count: int, timeout: float) -> tuple[float, float, float] | None:
        """The command that arrives after the first ``count`` (``(arrived, v, omega)``),
        waiting up to ``timeout`` s for it; None if it did not come."""
        if not self.wait_commands(count + 1, timeout):
            return None
        with self._cond:
            return self.commands[count]

