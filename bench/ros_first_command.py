"""How soon a robot written in rclpy (Jazzy, rmw_fastrtps_cpp) hears `companion node`'s first
command once both are up, on loopback (docs/ros2.md, "Discovery").

    python bench/ros_first_command.py [--runs 10] [--transport dds] [--json FILE]

Each run starts the node (its start line marks it up) and an rclpy node listening to /cmd_vel
(up once its node exists), in both orders: node first, and robot first (the node 2 s later).
The figure is the time from the later of the two being up to the robot's first /cmd_vel.
Fast DDS runs on companion's shipped loopback profile (src/companion/ros/loopback/fastdds.xml),
companion on its Cyclone loopback configuration; every run on a fresh domain id. Prints the
distribution (min, median, p90, max) per order and writes the samples as JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "ros"))
from test_rclpy_node import first_command  # noqa: E402  (one timed start, shared with the test)

from companion.ros.dds_base import LOOPBACK  # noqa: E402


def envs(home: Path, domain: int) -> tuple[dict, dict]:
    """The node's and the rclpy robot's environments: loopback only, this run's domain."""
    clean = {k: v for k, v in os.environ.items() if not k.startswith(
        ("ROS_", "RMW_", "FASTRTPS_", "FASTDDS_", "CYCLONEDDS_", "_ROS_WHEELS_", "AMENT_"))}
    node = dict(clean, HOME=str(home))
    profile = str(LOOPBACK / "fastdds.xml")       # Jazzy's Fast DDS 2.14 reads FASTRTPS_...
    robot = dict(clean, HOME=str(home), ROS_LOG_DIR=str(home / "log"),
                 ROS_DOMAIN_ID=str(domain), RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
                 FASTRTPS_DEFAULT_PROFILES_FILE=profile, FASTDDS_DEFAULT_PROFILES_FILE=profile)
    return node, robot


def one_run(home: Path, domain: int, order: str, transport: str) -> float:
    node_env, robot_env = envs(home, domain)
    return first_command(home, node_env, robot_env, order,
                         "--domain-id", str(domain), "--transport", transport)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--transport", default="dds", choices=("dds", "rclpy"))
    ap.add_argument("--json", metavar="FILE", help="write the samples here")
    args = ap.parse_args()
    samples: dict[str, list[float]] = {"node first": [], "robot first": []}
    base = 100 + os.getpid() % 100
    with tempfile.TemporaryDirectory() as tmp:
        for run in range(args.runs):
            for k, order in enumerate(samples):
                home = Path(tmp) / f"{run}-{k}"
                home.mkdir()
                samples[order].append(one_run(home, base + 2 * run + k, order, args.transport))
                print(f"{order}, run {run + 1}: {samples[order][-1]:.3f} s", flush=True)
    for order, xs in samples.items():
        xs = sorted(xs)
        p90 = xs[min(len(xs) - 1, round(0.9 * (len(xs) - 1)))]
        print(f"{order}: min {xs[0]:.3f} s, median {statistics.median(xs):.3f} s, p90 "
              f"{p90:.3f} s, max {xs[-1]:.3f} s over {len(xs)} starts")
    if args.json:
        Path(args.json).write_text(json.dumps(samples, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
