"""What a replay needs from a bag that carries no companion parameters (recorded by another
tool, or converted by ``rosbags-convert``, which drops ``custom_data``).

The person topic's type comes from the topic itself (``ros.person_type: auto``); the side the
robot walked on comes from the data: the bearing of the robot's reference point from the
person's walking direction, over every detection while the person walks, rounded to the
nearest side. Without enough walking the side cannot be told, and the replay stops naming the
setting and the flag that gives it (docs/recording.md).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from companion.errors import ConfigError
from companion.geometry import wrap_2pi, wrap_pi
from companion.params import SIDES
from companion.ros import convert
from companion.ros.placement import Placer, pose_at
from companion.ros.settings import NodeConfig
from companion.types import PersonDetection

#: The person must walk at least this fast (m/s) ...
MIN_SPEED = 0.3
#: ... over this span of time (s) for a walking direction, ...
SPAN_S = 1.0
#: ... and the side needs this many such moments.
MIN_SAMPLES = 10


def walking_bearings(odometry: list[convert.OdometrySample],
                     people: list[tuple[float, float, float]], d: float) -> list[float]:
    """Bearings (rad, [0, 2 pi)) of the robot's reference point (``d`` m ahead of the axle)
    from the person's walking direction, at each person position ``(t, x, y)`` (odometry
    frame) from which the person walks on at least :data:`MIN_SPEED` over :data:`SPAN_S`."""
    samples = deque(odometry)
    out = []
    times = [p[0] for p in people]
    for t, x, y in people:
        j = int(np.searchsorted(times, t + SPAN_S))
        if j >= len(people):
            break
        tj, xj, yj = people[j]
        if math.hypot(xj - x, yj - y) < MIN_SPEED * (tj - t):
            continue
        robot = pose_at(samples, t)
        if robot is None or abs(t - min(samples, key=lambda s: abs(s.t - t)).t) > 0.5:
            continue
        heading = math.atan2(yj - y, xj - x)
        rx, ry = robot.x + d * math.cos(robot.theta), robot.y + d * math.sin(robot.theta)
        out.append(wrap_2pi(math.atan2(ry - y, rx - x) - heading))
    return out


def nearest_side(bearings: list[float]) -> tuple[str, float]:
    """The side nearest the bearings' circular mean, and that mean (rad)."""
    mean = wrap_2pi(math.atan2(float(np.mean(np.sin(bearings))),
                               float(np.mean(np.cos(bearings)))))
    side = min(SIDES, key=lambda s: abs(wrap_pi(SIDES[s] - mean)))
    return side, mean


def infer_side(reader: Any, config: NodeConfig) -> tuple[str, float]:
    """The side the robot walked on in the bag of ``reader`` (a replay's BagReader) and the
    mean bearing; a ConfigError naming the missing setting if the bag cannot tell."""
    r = config.ros
    odom = reader.topics.get(r.topics.odom)
    person = [c for c in reader.connections(r.topics.person)
              if c.msgtype in convert.PERSON_TYPES.values()]
    odometry: list[convert.OdometrySample] = []
    stamped: list[PersonDetection] = []
    if odom is not None and odom.msgtype == "nav_msgs/msg/Odometry" and person:
        for c, _, msg in reader.records([odom, *person]):
            if c.topic == r.topics.odom:
                odometry.append(convert.odometry_sample(msg))
            else:
                stamped.extend(convert.people_from(msg, convert.person_kind(c.msgtype)))
    odometry.sort(key=lambda s: s.t)
    placer, samples = Placer(r, None), deque(odometry)
    people = []
    for s in sorted(stamped, key=lambda s: s.t):
        d = placer.detection(s, samples, "world")
        robot = pose_at(samples, s.t)
        if not isinstance(d, str) and d.frame == "world" and robot is not None:
            people.append((d.t, d.x, d.y, math.hypot(d.x - robot.x, d.y - robot.y)))
    nearest: dict[float, tuple[float, float, float, float]] = {}
    for p in people:                          # several people at once: the nearest one
        if p[0] not in nearest or p[3] < nearest[p[0]][3]:
            nearest[p[0]] = p
    track = [p[:3] for _, p in sorted(nearest.items())]
    bearings = walking_bearings(odometry, track, config.params.robot.d)
    if len(bearings) < MIN_SAMPLES:
        raise ConfigError(
            f"{reader.path}: the bag holds no companion parameters (its custom_data was "
            f"dropped or never written) and the side cannot be told from it (the person "
            f"walks beside the robot at {len(bearings)} moments, {MIN_SAMPLES} needed); give "
            f"the node's parameters with --params FILE.yaml (formation.bearing)")
    return nearest_side(bearings)
