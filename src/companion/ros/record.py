"""Runs recorded as ROS 2 bags (docs/recording.md): ``companion run --bag`` runs the node and
the simulated robot in lock-step over an in-memory graph that records every message; ``sim-robot
--bag`` and ``node --bag`` record through their transport. Each adds the Foxglove scene of what
it knows: the run everything, the simulator the truth, the node its estimates.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from companion.control.avoidance import influence_range
from companion.control.slot import slot_point
from companion.ros import convert
from companion.ros.bag import BagWriter, RecordingBus, RecordingTransport
from companion.ros.convert import TimeBase
from companion.ros.node import CompanionNode
from companion.ros.parameters import config_mapping
from companion.ros.scene import SCENE_TOPIC, SCENE_TYPE, Scene, scene_types
from companion.ros.settings import NodeConfig, RosParams
from companion.ros.sim_robot import Pacer, WireRobot, run_sim_robot
from companion.ros.transport import MemoryTransport, Transport
from companion.sim.runner import EpisodeSpec
from companion.types import Log

CUSTOM_KEY = "companion.parameters"
#: The person detections of a recorded run: nav_msgs/Odometry carries everything the
#: simulated sensor measures, so the node's loop equals the plain simulation (to 1e-6).
RUN_PERSON_TYPE = "odometry"


def open_bag(path: Path, config: NodeConfig) -> BagWriter:
    """A bag at ``path`` that stores ``config`` in its metadata (``companion.parameters``)."""
    bag = BagWriter(path, config.ros.distro)
    bag.set_custom_data(CUSTOM_KEY, json.dumps(config_mapping(config)))
    return bag


def run_config(spec: EpisodeSpec, controller: str, ros: RosParams | None = None) -> NodeConfig:
    """The node's configuration for a recorded run of ``spec``: its parameters and
    controller, simulated time, odometry-typed person detections."""
    ros = dataclasses.replace(ros or RosParams(), use_sim_time=True,
                              person_type=RUN_PERSON_TYPE)
    return NodeConfig(spec.params, ros, controller)


def on_clock(t: float) -> float:
    """``t`` as the node's clock reads it from /clock (nanoseconds): ticking at it makes the
    status stamps give the tick times back exactly, so a replay repeats the recording."""
    return convert.seconds(convert.time_msg(t))


def record_run(spec: EpisodeSpec, config: NodeConfig, bag_path: Path,
               reached: Callable[[float], None] | None = None) -> Log:
    """Run ``spec`` with the node of ``config`` and the simulated robot ticked in lock-step
    (the node right after each sample's messages) and record every message, plus the scene,
    in a bag at ``bag_path``; returns the log. ``reached(t)`` after each tick (progress)."""
    r, p = config.ros, spec.params
    bag = open_bag(bag_path, config)
    try:
        bus = RecordingBus(bag)
        node = CompanionNode(config, MemoryTransport(bus, bag.typestore))
        scene = Scene(r.odom_frame, p.robot.radius)

        def tick(t: float) -> None:
            node.tick(on_clock(t))
            v = node.view
            update = scene.update(v.t, v.robot, spec.person.state(t), v.estimate, v.slot,
                                  v.obstacles, node.time)
            if update is not None:
                bus.record(SCENE_TOPIC, SCENE_TYPE, update)
            if reached is not None:
                reached(t)

        log, _ = run_sim_robot(spec, MemoryTransport(bus, bag.typestore), r, Pacer(0.0),
                               after=tick)
    finally:
        bag.close()
    return log


def recording_sim_robot(spec: EpisodeSpec, transport: Transport, ros: RosParams,
                        pacer: Pacer, epoch_ns: int | None, bag_path: Path,
                        wait_s: float = 0.0,
                        lockstep_s: float = 0.0,
                        after: Callable[[float], None] | None = None
                        ) -> tuple[Log, WireRobot]:
    """:func:`~companion.ros.sim_robot.run_sim_robot` recording what the robot sends and
    receives, the node's status and markers, and the scene of the truth (robot, person, the
    slot on the true person, obstacles), in a bag at ``bag_path``; ``after`` as in
    run_sim_robot."""
    p = spec.params
    bag = BagWriter(bag_path, ros.distro)
    try:
        rec = RecordingTransport(transport, bag)
        t = ros.topics
        if t.markers:                   # (the robot itself listens to the status)
            rec.subscribe(t.markers, "visualization_msgs/msg/MarkerArray", lambda msg: None)
        scene = Scene(ros.odom_frame, p.robot.radius)
        reach = tuple((ob, influence_range(ob, p.avoidance)) for ob in spec.obstacles)

        def sample_done(k: float) -> None:
            if after is not None:
                after(k)                 # a lock-step node (tests)
            odom = rec.last.get(t.odom)
            if odom is None:
                return
            # simulated time k on the robot's stamps: the odometry of sample k is stamped k
            tb = TimeBase(convert.stamp_ns(odom.header.stamp) - int(round(k * 1e9)))
            person, sample = spec.person.state(k), convert.odometry_sample(odom, tb)
            update = scene.update(sample.t, sample.pose, person, None, slot_point(person, p),
                                  reach, tb)
            if update is not None:
                rec.record(SCENE_TOPIC, SCENE_TYPE, update)

        return run_sim_robot(spec, rec, ros, pacer, epoch_ns, after=sample_done,
                             wait_s=wait_s, lockstep_s=lockstep_s)
    finally:
        bag.close()


class RecordedNode(CompanionNode):
    """The node, recording what it receives and publishes and the scene of its estimates in
    ``bag`` (log times on the node's clock)."""

    def __init__(self, config: NodeConfig, transport: Transport, bag: BagWriter,
                 log_clock: Callable[[], int | None] | None = None, **kw: Any):
        """``log_clock()``: the log time (ns) to record at (default: the node's clock)."""
        self.bag = bag
        self.recorder = RecordingTransport(transport, bag, clock=log_clock or self._clock)
        self.scene = Scene(config.ros.odom_frame, config.params.robot.radius)
        super().__init__(config, self.recorder, **kw)

    def _clock(self) -> int | None:
        now = self.now()
        return None if now is None or self.time is None else self.time.ns(now)

    def tick(self, now: float):
        cmd = super().tick(now)
        v = self.view
        update = self.scene.update(now, v.robot, None, v.estimate, v.slot, v.obstacles,
                                   self.time)
        if update is not None:
            self.recorder.record(SCENE_TOPIC, SCENE_TYPE, update)
        return cmd


__all__ = ["BagWriter", "RecordedNode", "record_run", "recording_sim_robot", "run_config",
           "scene_types"]
