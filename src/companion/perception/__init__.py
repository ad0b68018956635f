"""Perception: a LiDAR scan -> circular obstacles (:mod:`.extract`), and moving things
tracked with their velocities (:mod:`.movers`). :class:`LidarObstacles` is the one front end
the simulator and the ROS node share."""

from __future__ import annotations

from companion.params import ExtractorParams, MoverParams
from companion.perception.extract import checked_scan, extract_obstacles
from companion.perception.movers import MovingTracker
from companion.types import Circle, Scan

__all__ = ["LidarObstacles", "MovingTracker", "checked_scan", "extract_obstacles"]


class LidarObstacles:
    """Scans -> the circles that cover their returns (:func:`extract_obstacles`, the tracked
    person left out), those of body size that move with their velocities
    (:class:`MovingTracker`)."""

    def __init__(self, extractor: ExtractorParams, movers: MoverParams):
        self.extractor = extractor
        self.tracker = MovingTracker(movers)

    def reset(self) -> None:
        self.tracker.reset()

    def update(self, scan: Scan, t: float, person: tuple[float, float] | None
               ) -> tuple[Circle, ...]:
        """The obstacles of ``scan`` taken at time ``t`` (s)."""
        return self.tracker.update(extract_obstacles(scan, person, self.extractor), t)
