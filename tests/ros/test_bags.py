"""Recorded bags read back: rosbag2 metadata and MCAP storage, topics and types of the node,
log times in order, messages equal to what the run published, the Foxglove scene, and
all-or-nothing on SIGTERM."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from companion.io import leftovers
from companion.ros import convert
from companion.ros.bag import BagWriter, RecordingTransport
from companion.ros.record import RecordedNode, config_mapping, record_run, run_config
from companion.ros.scene import DEFINITIONS, SCENE_TYPE, scene_types
from companion.ros.settings import config_from_mapping
from companion.ros.sim_robot import SIM_EPOCH_NS
from companion.ros.transport import MemoryBus, MemoryTransport
from companion.sim.scenario import load_scenario
from companion.types import PersonDetection, Pose

DURATION = 4.0
SIM = convert.TimeBase(SIM_EPOCH_NS)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A 4 s run of the fig7 scenario (obstacles) with realistic sensing, recorded."""
    sc = load_scenario("fig7", {"sensing": "realistic"})
    spec = dataclasses.replace(sc.episode(), duration=DURATION)
    config = run_config(spec, sc.controller)
    path = tmp_path_factory.mktemp("bags") / "run"
    log = record_run(spec, config, path)
    return path, log, config


def read(path):
    ts = scene_types("jazzy")
    out: dict[str, list] = {}
    with Reader(path) as r:
        types = {c.topic: c.msgtype for c in r.connections}
        for c, t, data in r.messages():
            out.setdefault(c.topic, []).append((t, ts.deserialize_cdr(data, c.msgtype)))
    return types, out


def test_the_bag_has_the_nodes_topics_types_and_metadata(recorded):
    path, log, _ = recorded
    assert (path / "metadata.yaml").exists() and (path / f"{path.name}_0.mcap").exists()
    types, msgs = read(path)
    assert types == {"/clock": "rosgraph_msgs/msg/Clock", "/odom": "nav_msgs/msg/Odometry",
                     "/tf": "tf2_msgs/msg/TFMessage", "/scan": "sensor_msgs/msg/LaserScan",
                     "/person": "nav_msgs/msg/Odometry", "/cmd_vel": "geometry_msgs/msg/Twist",
                     "/companion/status": "diagnostic_msgs/msg/DiagnosticArray",
                     "/companion/markers": "visualization_msgs/msg/MarkerArray",
                     "/companion/scene": SCENE_TYPE, "/rosout": "rcl_interfaces/msg/Log",
                     "/parameter_events": "rcl_interfaces/msg/ParameterEvent"}
    n = len(log)
    assert n == 80
    for topic in ("/odom", "/tf", "/cmd_vel", "/companion/status", "/clock"):
        assert len(msgs[topic]) == n, topic
    assert len(msgs["/scan"]) == n // 2          # 10 Hz LiDAR, 20 Hz control
    assert len(msgs["/companion/scene"]) == n // 2     # the scene at 10 Hz
    for topic, items in msgs.items():
        times = [t for t, _ in items]
        assert times == sorted(times), topic
    meta = (path / "metadata.yaml").read_text()
    assert "storage_identifier: mcap" in meta and "companion.parameters" in meta


def test_recorded_messages_equal_what_the_run_did(recorded):
    path, log, _ = recorded
    _, msgs = read(path)
    t = (np.array([tt for tt, _ in msgs["/odom"]]) - SIM_EPOCH_NS) * 1e-9
    np.testing.assert_allclose(t, log["t"], atol=1e-9)
    pose = np.array([[m.pose.pose.position.x, m.pose.pose.position.y,
                      convert.yaw(m.pose.pose.orientation)] for _, m in msgs["/odom"]])
    np.testing.assert_allclose(pose[:, 0], log["robot_x"], atol=1e-12)
    np.testing.assert_allclose(pose[:, 1], log["robot_y"], atol=1e-12)
    np.testing.assert_allclose(np.cos(pose[:, 2] - log["robot_theta"]), 1.0, atol=1e-12)
    cmd = np.array([convert.twist_velocity(m) for _, m in msgs["/cmd_vel"]])
    assert np.array_equal(cmd[:, 0], log["v"]) and np.array_equal(cmd[:, 1], log["omega"])
    stamps = [SIM.seconds(m.header.stamp) for _, m in msgs["/companion/status"]]
    np.testing.assert_allclose(stamps, log["t"], atol=1e-9)
    # each sample's inputs are logged no later than the tick that used them
    assert all(ti <= tc for (ti, _), (tc, _) in zip(msgs["/odom"], msgs["/cmd_vel"]))


def test_the_scene_shows_robot_person_slot_obstacles_and_paths(recorded):
    path, log, _ = recorded
    _, msgs = read(path)
    last_t, last = msgs["/companion/scene"][-1]
    entities = {e.id: e for e in last.entities}
    assert set(entities) == {"robot", "person", "person_estimate", "slot", "obstacles",
                             "paths"}
    k = int(np.argmin(np.abs(log["t"] - SIM.since(last_t))))
    body = entities["robot"].cylinders[0]
    assert (body.pose.position.x, body.pose.position.y) == (
        pytest.approx(log["robot_x"][k], abs=1e-9), pytest.approx(log["robot_y"][k], abs=1e-9))
    assert body.size.x == pytest.approx(0.5)            # footprint diameter, robot.radius 0.25
    person = entities["person"].cylinders[0].pose.position
    assert (person.x, person.y) == (pytest.approx(log["person_x"][k], abs=1e-9),
                                    pytest.approx(log["person_y"][k], abs=1e-9))
    assert len(entities["obstacles"].cylinders) >= 2   # obstacle and influence, seen by LiDAR
    robot_path = entities["paths"].lines[0].points
    assert len(robot_path) == pytest.approx(DURATION / 0.2, abs=1)
    assert all(e.frame_id == "odom" for e in last.entities)


def test_scene_definitions_match_foxglove_sdk():
    """Every field companion writes exists, by name, in foxglove-sdk's schema of the type."""
    fm = pytest.importorskip("foxglove.messages")
    ts = scene_types("jazzy")
    for name in DEFINITIONS:
        fields = [f for f, _ in ts.fielddefs[f"foxglove_msgs/msg/{name}"][1]]
        try:
            getattr(fm, name)(**dict.fromkeys(fields))
        except TypeError as exc:
            assert "unexpected keyword" not in str(exc), (name, exc)


def test_a_node_records_inputs_before_the_tick_that_used_them(tmp_path):
    bus = MemoryBus()
    ts = scene_types("jazzy")
    cfg = config_from_mapping({"ros": {"topics": {"scan": ""}}})
    clock = [100.0]
    bag = BagWriter(tmp_path / "node", "jazzy")
    node = RecordedNode(cfg, MemoryTransport(bus, ts), bag, clock=lambda: clock[0],
                        time_base=convert.ABSOLUTE)
    pub = MemoryTransport(bus, ts)
    odom = pub.publisher("/odom", "nav_msgs/msg/Odometry")
    person = pub.publisher("/person", "geometry_msgs/msg/PointStamped")
    for k in range(10):
        clock[0] = 100.0 + 0.05 * k
        odom(convert.odometry_msg(clock[0], Pose(0.05 * k, 0, 0), (1.0, 0.0), "odom",
                                  "base_link"))
        person(convert.person_msg([PersonDetection(clock[0], 0.05 * k, 1.0, "odom")],
                                  "point", clock[0], "odom"))
        node.tick(clock[0])
        person(convert.person_msg([PersonDetection(clock[0], 0.05 * k, 1.0, "odom")],
                                  "point", clock[0], "odom"))   # after the tick
    bag.close()
    _, msgs = read(tmp_path / "node")
    ticks = [tt for tt, _ in msgs["/companion/status"]]
    assert ticks == [round((100.0 + 0.05 * k) * 1e9) for k in range(10)]
    late = [tt for tt, _ in msgs["/person"]][1::2]
    assert all(a > b for a, b in zip(late, ticks))   # came after its tick: logged after it
    assert len(msgs["/cmd_vel"]) == 10 and "/companion/scene" in msgs


def test_recording_transport_without_a_clock_logs_at_the_latest_stamp(tmp_path):
    bag = BagWriter(tmp_path / "b", "jazzy")
    rec = RecordingTransport(MemoryTransport(MemoryBus(), bag.typestore), bag)
    send = rec.publisher("/odom", "nav_msgs/msg/Odometry")
    tw = rec.publisher("/cmd_vel", "geometry_msgs/msg/Twist")
    send(convert.odometry_msg(5.0, Pose(0, 0, 0), (0, 0), "odom", "base_link"))
    tw(convert.twist_msg(0.1, 0.0))
    send(convert.odometry_msg(4.0, Pose(0, 0, 0), (0, 0), "odom", "base_link"))  # older
    bag.close()
    with Reader(tmp_path / "b") as r:
        assert [t for _, t, _ in r.messages()] == [5_000_000_000] * 3


def test_sigterm_mid_run_leaves_no_bag(tmp_path):
    """A run killed while recording leaves neither the bag nor its staging folder."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "companion.apps.cli", "run", "figure8",
                             "--duration", "3000", "--out", str(tmp_path / "o"), "--bag",
                             str(tmp_path / "bag")], cwd=tmp_path, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        end = time.monotonic() + 120
        staged = ".bag.companion-*.tmp/bag/*.mcap"          # in the hidden folder beside
        while time.monotonic() < end and not list(tmp_path.glob(staged)):
            time.sleep(0.1)
        assert list(tmp_path.glob(staged)), "the run never started"
        time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(60) == 143
    finally:
        proc.kill()
        proc.wait()
    assert not (tmp_path / "bag").exists()
    assert leftovers(tmp_path) == [] and leftovers(tmp_path / "bag") == []
    assert not (tmp_path / "o" / "log.csv").exists()


def test_a_second_recording_replaces_the_bag_whole(tmp_path, recorded):
    from companion.apps.bags import bag_outputs

    path = tmp_path / "bag"
    for seconds in (1.0, 2.0):
        sc = load_scenario("figure8")
        spec = dataclasses.replace(sc.episode(), duration=seconds)
        with bag_outputs(path) as staged:
            record_run(spec, run_config(spec, sc.controller), staged)
        with Reader(path) as r:
            assert r.topics["/odom"].msgcount == round(seconds / 0.05)
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".")) == ["bag"]
    assert leftovers(tmp_path) == [] and leftovers(path) == []
    assert not path.is_symlink() and not any(p.is_symlink() for p in path.iterdir())


def test_run_with_a_bag_names_the_bag_where_it_is(tmp_path, capsys, monkeypatch):
    """The bag is a plain folder, and the last line gives it by its path from here."""
    from companion.apps.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["run", "line", "--duration", "1", "--out", "o", "--bag", "bags/b1"]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == \
        "wrote o/log.csv, o/metrics.json, bags/b1/"
    bag = tmp_path / "bags" / "b1"
    assert (bag / "metadata.yaml").is_file() and not bag.is_symlink()
    assert leftovers(bag) == [] and leftovers(tmp_path / "o") == []


def test_config_mapping_round_trips(recorded):
    _, _, config = recorded
    assert config_from_mapping(config_mapping(config)) == config


def test_the_bag_is_written_as_jazzys_rosbag2_writes_it(recorded):
    """metadata.yaml version 9 with the offered QoS, type hash and counts of every topic, a
    real ros_distro and a start on the documented simulated epoch (2000-01-01), never 0; the
    MCAP file's ros2 profile, its channels' offered_qos_profiles and topic_type_hash, and its
    own copy of the metadata (rosbag2_storage_mcap's layout)."""
    import yaml
    from mcap.reader import make_reader

    path, log, _ = recorded
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    ts = scene_types("jazzy")
    assert info["version"] == 9 and info["ros_distro"] == "jazzy"
    assert info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == [f"{path.name}_0.mcap"]
    start = info["starting_time"]["nanoseconds_since_epoch"]
    assert start == SIM_EPOCH_NS and info["duration"]["nanoseconds"] >= round(
        (len(log) - 1) * 0.05 * 1e9)
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    odom = topics["/odom"]["topic_metadata"]
    assert odom["type_description_hash"] == ts.hash_rihs01("nav_msgs/msg/Odometry")
    (qos,) = odom["offered_qos_profiles"]
    assert qos["reliability"] == "reliable" and qos["durability"] == "volatile"
    assert qos["history"] == "keep_last" and qos["depth"] == 10
    assert qos["deadline"] == {"sec": 9223372036, "nsec": 854775807}
    assert topics["/scan"]["topic_metadata"]["offered_qos_profiles"][0]["reliability"] \
        == "best_effort"
    assert topics["/rosout"]["topic_metadata"]["offered_qos_profiles"][0]["durability"] \
        == "transient_local"
    assert sum(t["message_count"] for t in topics.values()) == info["message_count"]
    with (path / f"{path.name}_0.mcap").open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert reader.get_header().profile == "ros2"
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            assert channel.metadata["topic_type_hash"] == ts.hash_rihs01(schema.name)
            assert yaml.safe_load(channel.metadata["offered_qos_profiles"])[0]["reliability"] \
                in ("reliable", "best_effort")
        (meta,) = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
        assert yaml.safe_load(meta.metadata["serialized_metadata"])["ros_distro"] == "jazzy"


def test_the_metadata_has_no_yaml_anchors(recorded):
    """Every value written out in full (a YAML reader without anchors reads it too)."""
    text = (recorded[0] / "metadata.yaml").read_text()
    assert "&id" not in text and "*id" not in text
