"""Static obstacles of the world: circles (pillars, bins) and wall segments.

Pure geometry, no dependencies on the rest of the package. Distances are in metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Circle:
    """A circular obstacle; ``influence`` (m) overrides the avoidance range r / K_ob if set."""

    x: float
    y: float
    radius: float
    influence: float | None = None


@dataclass(frozen=True)
class Wall:
    """A wall segment from (x0, y0) to (x1, y1); ``influence`` (m) overrides the default."""

    x0: float
    y0: float
    x1: float
    y1: float
    influence: float | None = None


Obstacle = Circle | Wall


def nearest_point(obstacle: Obstacle, px: float, py: float) -> tuple[float, float]:
    """Point of the obstacle's surface nearest to (px, py) (its centre-line for a wall)."""
    if isinstance(obstacle, Circle):
        dx, dy = px - obstacle.x, py - obstacle.y
        dist = math.hypot(dx, dy)
        if dist < 1e-12:
            return obstacle.x + obstacle.radius, obstacle.y
        return obstacle.x + obstacle.radius * dx / dist, obstacle.y + obstacle.radius * dy / dist
    ex, ey = obstacle.x1 - obstacle.x0, obstacle.y1 - obstacle.y0
    length2 = ex * ex + ey * ey
    s = 0.0 if length2 == 0.0 else ((px - obstacle.x0) * ex + (py - obstacle.y0) * ey) / length2
    s = min(max(s, 0.0), 1.0)
    return obstacle.x0 + s * ex, obstacle.y0 + s * ey


def surface_distance(obstacle: Obstacle, px: float, py: float) -> float:
    """Signed distance from (px, py) to the obstacle's surface (negative inside a circle)."""
    if isinstance(obstacle, Circle):
        return math.hypot(px - obstacle.x, py - obstacle.y) - obstacle.radius
    nx, ny = nearest_point(obstacle, px, py)
    return math.hypot(px - nx, py - ny)
