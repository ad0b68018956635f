"""How the controller learns about obstacles in simulation: ground truth or a simulated LiDAR.

A perception model is asked once per control step for the obstacles the controller knows
about (world frame). ``GroundTruth`` passes the world's obstacles through; ``LidarPerception``
casts a scan at the LiDAR's rate, extracts circles from it (the tracked person excluded) and
holds them until the next scan.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from companion.errors import ConfigError
from companion.params import Params
from companion.perception import extract_obstacles
from companion.sim.lidar import cast
from companion.types import Circle, Obstacle, Pose, Scan, Wall


class Perception(Protocol):
    def reset(self) -> None:
        """Forget everything before a new episode."""

    def obstacles(self, step: int, robot: Pose, world: Sequence[Obstacle],
                  person_true: tuple[float, float], person_seen: tuple[float, float],
                  rng: np.random.Generator) -> tuple[Obstacle, ...]:
        """Obstacles known at control step ``step``."""

    def scan(self) -> Scan | None:
        """The latest LiDAR scan (None without a LiDAR)."""


class GroundTruth:
    """The controller knows the world's obstacles exactly."""

    def reset(self) -> None:
        pass

    def obstacles(self, step: int, robot: Pose, world: Sequence[Obstacle],
                  person_true: tuple[float, float], person_seen: tuple[float, float],
                  rng: np.random.Generator) -> tuple[Obstacle, ...]:
        return tuple(world)

    def scan(self) -> Scan | None:
        return None


class LidarPerception:
    """The controller sees what a simulated LiDAR detects: a scan every
    ``round(1 / (lidar.rate * dt))`` steps, cast against the true obstacles and the person's
    body, turned into circles by :func:`companion.perception.extract_obstacles` (the tracked
    person, at its observed position, is excluded) and held until the next scan."""

    def __init__(self, params: Params):
        self.params = params
        self.every = max(1, round(1.0 / (params.lidar.rate * params.dt)))
        self.reset()

    def reset(self) -> None:
        self.held: tuple[Obstacle, ...] = ()
        self.last_scan: Scan | None = None

    def obstacles(self, step: int, robot: Pose, world: Sequence[Obstacle],
                  person_true: tuple[float, float], person_seen: tuple[float, float],
                  rng: np.random.Generator) -> tuple[Obstacle, ...]:
        if step % self.every == 0:
            circles = [ob for ob in world if isinstance(ob, Circle)]
            walls = [ob for ob in world if isinstance(ob, Wall)]
            scan = cast(robot, circles, walls, person_true, self.params.lidar, rng)
            self.last_scan = scan
            self.held = tuple(extract_obstacles(scan, person_seen, self.params.extractor))
        return self.held

    def scan(self) -> Scan | None:
        return self.last_scan


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
