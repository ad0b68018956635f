"""`companion node` and `companion sim-robot` as two processes closing the loop over the real
wire protocols (DDS through cyclonedds, Zenoh with sim-robot as the router), on loopback."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest

CLI = [sys.executable, "-m", "companion.apps.cli"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def env_for(tmp_path, ros_domain: int) -> dict:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("ROS_", "CYCLONEDDS_", "ZENOH_"))}
    env.update(HOME=str(tmp_path), ROS_DOMAIN_ID=str(ros_domain))
    return env


@pytest.mark.parametrize("transport", ["dds", "zenoh"])
def test_node_and_sim_robot_close_the_loop(tmp_path, ros_domain, transport):
    flags = ["--transport", transport, "--domain-id", str(ros_domain)]
    if transport == "zenoh":
        flags += ["--zenoh-connect", f"tcp/127.0.0.1:{free_port()}"]
    env = env_for(tmp_path, ros_domain)
    node = subprocess.Popen([*CLI, "node", *flags], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        robot = subprocess.run([*CLI, "sim-robot", "figure8", "--duration", "6", "--wait", "60",
                                "--out", str(tmp_path / "run"), *flags], env=env,
                               capture_output=True, text=True, timeout=150)
        assert robot.returncode == 0, robot.stdout + robot.stderr
        m = json.loads((tmp_path / "run" / "metrics.json").read_text())
        assert m["commands_received"] >= 0.8 * m["steps"], m["commands_received"]
        assert m["min_person_distance_m"] > 0.5
        assert m["rmse_rho_m"] < 1.0     # started at rest beside the person, catching up
    finally:
        node.send_signal(signal.SIGINT)
        out, _ = node.communicate(timeout=30)
    assert node.returncode == 0, out
    assert "sent a zero velocity" in out


def test_node_sigterm_ends_with_a_zero_velocity(tmp_path, ros_domain):
    from companion.ros.dds import DdsTransport

    env = env_for(tmp_path, ros_domain)
    heard = []
    with DdsTransport(node_name="listener", domain_id=ros_domain) as listener:
        listener.subscribe("/cmd_vel", "geometry_msgs/msg/Twist",
                           lambda m: heard.append((m.linear.x, m.angular.z)))
        node = subprocess.Popen([*CLI, "node", "--domain-id", str(ros_domain)], env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            end = time.monotonic() + 60
            while len(heard) < 5 and time.monotonic() < end:
                time.sleep(0.05)
        finally:
            node.send_signal(signal.SIGTERM)
            out, _ = node.communicate(timeout=30)
        time.sleep(0.3)
    assert node.returncode == 0, out
    assert len(heard) >= 5 and heard[-1] == (0.0, 0.0)
