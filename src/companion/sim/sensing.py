"""What the robot senses in simulation: person detections and obstacles (docs/sensing.md).

:class:`PersonSensor` samples detections of the person from the true motion as the sensing
profile says (rate, noise, latency, dropouts, holes in a recording). For obstacles a
perception model is asked once per control step for what the robot's obstacle sensors give
(world frame): ``GroundTruth`` passes the world's obstacles through; ``LidarPerception`` casts
a scan at the LiDAR's rate, which the robot's own front end turns into obstacles. Each noise
source draws from its own random stream (:func:`streams`), so two controllers run on one
seed see the same person detections and the same LiDAR noise.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from companion.errors import ConfigError
from companion.geometry import line_of_sight
from companion.params import Params, SensingParams
from companion.sim.lidar import cast
from companion.sim.person import PersonMotion
from companion.types import Circle, Obstacle, PersonDetection, PersonState, Pose, Scan, Wall

#: The noise sources of an episode, in the order their streams are spawned (a new source goes
#: at the end, so that the others keep their streams).
SOURCES = ("person_sensor", "person_dropout", "lidar", "walkers")


def streams(seed: int) -> dict[str, np.random.Generator]:
    """One random generator per source of :data:`SOURCES`, spawned from ``seed`` (numpy
    ``SeedSequence``): what one source draws does not depend on what the others drew, so a
    controller that moves differently (and so draws LiDAR noise at other moments, or gets
    other scans) cannot change the person detections."""
    children = np.random.SeedSequence(seed).spawn(len(SOURCES))
    return {name: np.random.default_rng(c) for name, c in zip(SOURCES, children)}


class PersonSensor:
    """Detections of the person as ``params.sensing`` describes them.

    A detection shows the true person at its time ``t_s`` (one every ``1 / person_rate_hz``
    s from a random phase, or one per control step at an infinite rate) with Gaussian noise
    on the position (and on heading, speed and turn rate where those are measured), and
    arrives ``person_latency_s`` later. It is lost with probability ``person_dropout`` (drawn
    from ``dropout``, default ``rng``), and never made while the motion says the person is
    not observed (a hole in a recording).
    """

    def __init__(self, params: Params, person: PersonMotion, rng: np.random.Generator,
                 dropout: np.random.Generator | None = None):
        self.sensing, self.dt, self.person, self.rng = params.sensing, params.dt, person, rng
        self.dropout = rng if dropout is None else dropout
        self.frame = params.tracker.world_frame
        rate = self.sensing.person_rate_hz
        self.period = 0.0 if rate == np.inf else 1.0 / rate   # 0: one per control step
        self.next = rng.uniform(0.0, self.period) if self.period else 0.0

    def handover(self, t: float) -> PersonDetection:
        """A detection of the whole state with modest stds: the track a robot that was
        already walking with the person brings into an episode."""
        s, h = self.sensing, self.person.state(t)
        pos = s.person_position_noise_m
        stds = (0.1 if s.person_heading_noise_rad is None else s.person_heading_noise_rad,
                0.1 if s.person_velocity_noise is None else s.person_velocity_noise)
        e, var = self.rng.normal(size=5), s.declared_noise_m ** 2
        return PersonDetection(t, h.x + pos * e[0], h.y + pos * e[1], self.frame,
                               (var, 0.0, 0.0, var), h.theta + stds[0] * e[2],
                               stds[0], h.v + stds[1] * e[3], h.omega + stds[1] * e[4],
                               (stds[1], stds[1]))

    def detections(self, t: float, in_view: bool = True) -> tuple[PersonDetection, ...]:
        """The detections that arrive by control time ``t`` since the last call; none while
        the person is not ``in_view`` (out of range or hidden, :func:`in_view`, judged at
        ``t``: the latency is a tenth of a second). The noise is drawn either way, so what a
        controller's motion hides does not change the later detections of the seed."""
        last = t - self.sensing.person_latency_s
        if not self.period:
            times = [last] if last >= 0.0 else []
        else:
            times = []
            while self.next <= last + 1e-9:
                times.append(self.next)
                self.next += self.period
        made = [d for d in map(self._detect, times) if d is not None]   # draws as if seen
        return tuple(made) if in_view else ()


    def _detect(self, ts: float) -> PersonDetection | None:
        s = self.sensing
        observed = getattr(self.person, "observed", None)
        if (observed is not None and not observed(ts)) \
                or (s.person_dropout > 0.0 and self.dropout.random() < s.person_dropout):
            return None
        h: PersonState = self.person.state(ts)
        pos = s.person_position_noise_m
        e = self.rng.normal(size=2) if pos > 0.0 else (0.0, 0.0)
        heading = speed = turn = heading_std = velocity_std = None
        if s.person_heading_noise_rad is not None:
            heading_std = s.person_heading_noise_rad
            heading = h.theta + (heading_std * self.rng.normal() if heading_std else 0.0)
        if s.person_velocity_noise is not None:
            w = s.person_velocity_noise
            ev = self.rng.normal(size=2) if w else (0.0, 0.0)
            speed, turn, velocity_std = h.v + w * ev[0], h.omega + w * ev[1], (w, w)
        var = s.declared_noise_m ** 2
        return PersonDetection(ts, h.x + pos * e[0], h.y + pos * e[1], self.frame,
                               (var, 0.0, 0.0, var), heading, heading_std, speed,
                               turn, velocity_std)


def in_view(robot: Pose, person: PersonState, blockers: Sequence[Obstacle],
            sensing: SensingParams) -> bool:
    """Whether the simulated person detector on ``robot`` can see ``person``: within
    ``person_range_m`` and, with ``person_occlusion``, no walker or obstacle of ``blockers``
    on the line between them."""
    if math.hypot(person.x - robot.x, person.y - robot.y) > sensing.person_range_m:
        return False
    return not sensing.person_occlusion or line_of_sight(robot.x, robot.y, person.x,
                                                         person.y, blockers)


class Perception(Protocol):
    """What the robot's obstacle sensors give at each control step: the obstacles known
    exactly (a map) and the LiDAR's latest scan. The robot's own front end
    (:class:`~companion.perception.front_end.FrontEnd`) turns scans into obstacles: the
    simulated world never reads what the robot believes."""

    def reset(self) -> None:
        """Forget everything before a new episode."""

    def sense(self, step: int, robot: Pose, world: Sequence[Obstacle],
              person: tuple[float, float], rng: np.random.Generator
              ) -> tuple[tuple[Obstacle, ...], Scan | None]:
        """The known obstacles and the latest scan at control step ``step``."""


class GroundTruth:
    """The controller knows the world's obstacles exactly."""

    def reset(self) -> None:
        pass

    def sense(self, step: int, robot: Pose, world: Sequence[Obstacle],
              person: tuple[float, float], rng: np.random.Generator
              ) -> tuple[tuple[Obstacle, ...], Scan | None]:
        return tuple(world), None


class LidarPerception:
    """A simulated LiDAR: a scan every ``round(1 / (sensing.lidar_rate_hz * dt))`` steps, cast
    against the true obstacles and the person's body, stamped with its time and held (the
    latest scan) until the next; nothing is known exactly."""

    def __init__(self, params: Params):
        self.params = params
        self.every = max(1, round(1.0 / (params.sensing.lidar_rate_hz * params.dt)))
        self.reset()

    def reset(self) -> None:
        self.last_scan: Scan | None = None

    def sense(self, step: int, robot: Pose, world: Sequence[Obstacle],
              person: tuple[float, float], rng: np.random.Generator
              ) -> tuple[tuple[Obstacle, ...], Scan | None]:
        if step % self.every == 0:
            circles = [ob for ob in world if isinstance(ob, Circle)]
            walls = [ob for ob in world if isinstance(ob, Wall)]
            scan = cast(robot, circles, walls, person, self.params.lidar, rng)
            self.last_scan = dataclasses.replace(scan, t=step * self.params.dt)
        return (), self.last_scan


#: Where the controller's obstacles come from (see the module docstring).
OBSTACLE_SOURCES = ("truth", "lidar")


def check_source(source: str, where: str = "") -> str:
    """``source`` if it is one of :data:`OBSTACLE_SOURCES`, else a ConfigError naming it."""
    if source not in OBSTACLE_SOURCES:
        raise ConfigError(f"{where}obstacle_source: expected one of "
                          f"{', '.join(OBSTACLE_SOURCES)}, got {source!r}")
    return source


def make_perception(source: str, params: Params) -> Perception:
    """The perception of ``source``, one of :data:`OBSTACLE_SOURCES`."""
    if check_source(source) == "truth":
        return GroundTruth()
    return LidarPerception(params)
