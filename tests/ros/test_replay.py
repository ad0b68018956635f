"""companion replay: the recorded commands come back exactly with the recording's controller
(bags of a run and of sim-robot with the node), another controller runs, sqlite3 bags read,
and every bad bag is exit 2 with one line naming the bag and the topic or record."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import pytest
import yaml
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from companion.apps.cli import main
from companion.io import leftovers
from companion.ros.bag import BagWriter
from companion.ros.node import CompanionNode
from companion.ros.record import (
    config_mapping,
    on_clock,
    record_run,
    recording_sim_robot,
    run_config,
)
from companion.ros.scene import scene_types
from companion.ros.settings import config_from_mapping
from companion.ros.sim_robot import SIM_EPOCH_NS, Pacer
from companion.ros.transport import MemoryBus, MemoryTransport
from companion.sim.scenario import load_scenario


@pytest.fixture(scope="module")
def run_bag(tmp_path_factory):
    sc = load_scenario("fig7", {"sensing": "realistic"})
    spec = dataclasses.replace(sc.episode(), duration=4.0)
    path = tmp_path_factory.mktemp("replay") / "run"
    record_run(spec, run_config(spec, sc.controller), path)
    return path


def replay_metrics(tmp_path, *argv):
    out = tmp_path / "out"
    assert main(["replay", *map(str, argv), "--out", str(out)]) == 0
    return json.loads((out / "metrics.json").read_text()), out


def test_replay_with_the_recording_controller_gives_its_commands_back(tmp_path, run_bag):
    m, out = replay_metrics(tmp_path, run_bag)
    assert m["controller"] == "lqr" and m["ticks"] == m["paired_commands"] == 80
    assert m["cmd_diff_v_mps_max"] == 0.0 and m["cmd_diff_omega_radps_max"] == 0.0
    assert 0.0 < m["rmse_rho_m"] < 0.2
    with Reader(out / "bag") as r:
        counts = {c.topic: c.msgcount for c in r.connections}
    assert counts["/cmd_vel"] == counts["/cmd_vel_recorded"] == counts["/odom"] == 80
    assert counts["/scan"] == 40 and counts["/companion/scene"] == 40


def test_replay_with_another_controller_differs(tmp_path, run_bag):
    m, _ = replay_metrics(tmp_path, run_bag, "--controller", "pid")
    assert m["controller"] == "pid" and m["paired_commands"] == 80
    assert m["cmd_diff_omega_radps_rms"] > 0.01


def test_a_sim_robot_bag_replays_exactly_with_the_nodes_parameters(tmp_path):
    """sim-robot records over the graph (the node elsewhere, here ticked in lock-step); the
    replay with the node's parameters YAML gives the node's commands back exactly."""
    sc = load_scenario("figure8", {"sensing": "realistic"})
    spec = dataclasses.replace(sc.episode(), duration=3.0)
    cfg = config_from_mapping({"ros": {"use_sim_time": True, "person_type": "point"}})
    cfg = dataclasses.replace(cfg, params=sc.params, controller="vsm")
    bus = MemoryBus()
    ts = scene_types("jazzy")
    node = CompanionNode(cfg, MemoryTransport(bus, ts))
    recording_sim_robot(spec, MemoryTransport(bus, ts), cfg.ros, Pacer(0.0), SIM_EPOCH_NS,
                        tmp_path / "sim", after=lambda t: node.tick(on_clock(t)))
    params = tmp_path / "node.yaml"
    params.write_text(yaml.safe_dump({"companion": {"ros__parameters": config_mapping(cfg)}}))
    m, _ = replay_metrics(tmp_path, tmp_path / "sim", "--params", params)
    assert m["controller"] == "vsm" and m["paired_commands"] == m["ticks"] == 60
    assert m["cmd_diff_v_mps_max"] == 0.0 and m["cmd_diff_omega_radps_max"] == 0.0


def test_an_sqlite3_bag_without_ticks_replays_on_a_grid(tmp_path, run_bag):
    """A robot's bag in sqlite3 storage with odometry and person only: ticks every period."""
    dst = tmp_path / "robot"
    with Reader(run_bag) as r, Writer(dst, version=8,
                                       storage_plugin=StoragePlugin.SQLITE3) as w:
        ts = scene_types("jazzy")
        conns = {c.topic: (c, w.add_connection(c.topic, c.msgtype, typestore=ts))
                 for c in r.connections if c.topic in ("/odom", "/person")}
        for c, t, data in r.messages([v[0] for v in conns.values()]):
            w.write(conns[c.topic][1], t, data)
    m, _ = replay_metrics(tmp_path, dst, "--params", _yaml(tmp_path, person_type="odometry"),
                          "--topics", "scan=")
    assert m["ticks"] == 80 and m["recorded_commands"] == 0 and m["paired_commands"] == 0
    assert m["ticks_with_estimate"] >= 79


def _yaml(tmp_path, **ros):
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump({"companion": {"ros__parameters": {"ros": ros}}}))
    return path


def _bad(capsys, tmp_path, bag, *argv):
    assert main(["replay", str(bag), "--out", str(tmp_path / "bad"), *map(str, argv)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(bag) in err
    assert not (tmp_path / "bad" / "metrics.json").exists()
    assert leftovers(tmp_path / "bad") == []
    return err


def test_missing_topic(tmp_path, run_bag, capsys):
    err = _bad(capsys, tmp_path, run_bag, "--topics", "person=/people")
    assert "topic /people" in err and "not in the bag" in err


def test_wrong_message_type(tmp_path, run_bag, capsys):
    err = _bad(capsys, tmp_path, run_bag, "--params", _yaml(tmp_path, person_type="point"))
    assert "topic /person" in err and "nav_msgs/msg/Odometry" in err \
        and "geometry_msgs/msg/PointStamped" in err


@pytest.mark.parametrize("damage", ["truncated", "corrupt"])
def test_truncated_or_corrupt_bag(tmp_path, run_bag, capsys, damage):
    bag = tmp_path / damage
    shutil.copytree(run_bag, bag)
    data = bag / f"{run_bag.name}_0.mcap"
    raw = bytearray(data.read_bytes())
    if damage == "truncated":
        raw = raw[: len(raw) // 2]
    else:
        raw[len(raw) // 3: len(raw) // 3 + 4096] = bytes(4096)
    data.write_bytes(bytes(raw))
    err = _bad(capsys, tmp_path, bag)
    # zeros that land in the file's structure break a record; in a message, its decoding
    assert "record" in err or "not a readable" in err \
        or ("topic /" in err and "cannot be decoded" in err)


def test_empty_bag(tmp_path, capsys):
    bag = tmp_path / "empty"
    BagWriter(bag, "jazzy").close()
    assert "empty bag" in _bad(capsys, tmp_path, bag)


def test_no_such_bag(tmp_path, capsys):
    assert "no such bag" in _bad(capsys, tmp_path, tmp_path / "nothing")


def test_a_converted_bag_without_parameters_infers_the_side(tmp_path, capsys):
    """rosbags-convert keeps the messages and drops custom_data: replay takes the person
    topic's type from the topic and the side from the data (right, as recorded), and says
    so; a bag whose person does not walk stops with one line naming the flag."""
    import subprocess
    import sys

    sc = load_scenario("figure8", {"sensing": "realistic"})     # the right side
    spec = dataclasses.replace(sc.episode(), duration=6.0)
    record_run(spec, run_config(spec, sc.controller), tmp_path / "run")
    conv = tmp_path / "converted"
    done = subprocess.run([str(Path(sys.executable).parent / "rosbags-convert"), "--src",
                           str(tmp_path / "run"), "--dst", str(conv)], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "companion.parameters" not in (conv / "metadata.yaml").read_text()
    m, _ = replay_metrics(tmp_path, conv)
    out = capsys.readouterr().out
    assert "side read from the data (right" in out
    assert m["rmse_alpha_rad"] < 0.5 and m["ticks"] == 120
    still = tmp_path / "still"
    with Reader(tmp_path / "run") as r, Writer(still, version=9,
                                                storage_plugin=StoragePlugin.MCAP) as w:
        ts = scene_types("jazzy")
        conns = {c.topic: w.add_connection(c.topic, c.msgtype, typestore=ts)
                 for c in r.connections if c.topic in ("/odom", "/scan")}
        person = w.add_connection("/person", "geometry_msgs/msg/PointStamped", typestore=ts)
        for c, t, data in r.messages([c for c in r.connections if c.topic in conns]):
            w.write(conns[c.topic], t, data)
            if c.topic == "/odom":                 # a person standing still at (0, 1)
                msg = ts.deserialize_cdr(data, c.msgtype)
                p = ts.types["geometry_msgs/msg/PointStamped"](
                    header=msg.header, point=ts.types["geometry_msgs/msg/Point"](
                        x=0.0, y=1.0, z=0.0))
                w.write(person, t, ts.serialize_cdr(p, "geometry_msgs/msg/PointStamped"))
    err = _bad(capsys, tmp_path, still)
    assert "the side cannot be told" in err and "--params FILE.yaml (formation.bearing)" in err
