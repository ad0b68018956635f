"""Fixtures of the ROS 2 tests: the Jazzy typestore, a DDS domain of this test run and the
environment of an rclpy subprocess (see ros_helpers)."""

from __future__ import annotations

import os

import pytest
from ros_helpers import FASTDDS_LOOPBACK

from companion.ros.messages import typestore


@pytest.fixture(scope="session")
def store():
    return typestore("jazzy")


@pytest.fixture(scope="session")
def ros_domain() -> int:
    """A DDS domain for this test run (1..200 from the process id), so that test runs of other
    work trees on the same machine do not meet."""
    return 1 + os.getpid() % 200


@pytest.fixture(scope="session")
def rclpy_env(tmp_path_factory, ros_domain) -> dict:
    """The environment of an rclpy subprocess: Fast DDS on 127.0.0.1 by a profiles file, this
    run's domain, HOME and the ROS log in a temp folder, nothing inherited from a ROS set-up."""
    home = tmp_path_factory.mktemp("rclpy_home")
    profile = home / "fastdds_loopback.xml"
    profile.write_text(FASTDDS_LOOPBACK)
    env = {k: v for k, v in os.environ.items() if not k.startswith(
        ("ROS_", "RMW_", "FASTRTPS_", "FASTDDS_", "CYCLONEDDS_", "_ROS_WHEELS_", "AMENT_"))}
    env.update(HOME=str(home), ROS_LOG_DIR=str(home / "log"), ROS_DOMAIN_ID=str(ros_domain),
               RMW_IMPLEMENTATION="rmw_fastrtps_cpp", FASTDDS_DEFAULT_PROFILES_FILE=str(profile),
               FASTRTPS_DEFAULT_PROFILES_FILE=str(profile))
    return env


@pytest.fixture(scope="session", autouse=True)
def kernels_cached():
    """Compile (or load) the stack's kernels under the cache's lock before any test starts a
    node or sim-robot process: on a cold cache this process would otherwise compile a kernel
    lazily, outside the lock, while a child loads it, and numba can then fail ("no compiled
    object yet")."""
    from companion.sim.runner import warm_up

    warm_up()
