"""Plane geometry: angles, the unicycle (paper Eq. 1-3) and obstacle clearance.

One angle convention: wrapped angles are in (-pi, pi] (:func:`wrap_pi`), bearings from the
person in [0, 2*pi) (:func:`wrap_2pi`). One clearance rule: the distance from a point to an
obstacle's surface (a circle's rim, a wall's centre-line), minus the footprint radius
(:func:`clearance`). The scalar functions are :func:`~companion._jit.jitable`, so compiled
kernels use these very functions.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from companion._jit import jitable, kernel
from companion.types import Circle, Obstacle, Wall

TWO_PI = 2.0 * math.pi


@jitable
def wrap_pi(angle: float) -> float:
    """Wrap an angle to (-pi, pi]; an angle already in that range is returned unchanged."""
    if -math.pi < angle <= math.pi:
        return angle
    a = (angle + math.pi) % TWO_PI   # [0, 2*pi]: Python's modulo, also in compiled code
    if a == 0.0:
        a = TWO_PI
    return a - math.pi


def wrap_pi_array(angle: np.ndarray) -> np.ndarray:
    """:func:`wrap_pi` elementwise, for arrays (the same operations)."""
    angle = np.asarray(angle, dtype=float)
    a = (angle + math.pi) % TWO_PI
    a = np.where(a == 0.0, TWO_PI, a) - math.pi
    return np.where((angle > -math.pi) & (angle <= math.pi), angle, a)


@jitable
def wrap_2pi(angle: float) -> float:
    """Wrap an angle to [0, 2*pi); an angle already in that range is returned unchanged."""
    if 0.0 <= angle < TWO_PI:
        return angle
    a = angle % TWO_PI
    # the modulo of a tiny negative number can round to exactly 2*pi
    return 0.0 if a >= TWO_PI else a


@jitable
def lagged(actual: float, command: float, tau: float, dt: float) -> tuple[float, float]:
    """``(next, mean)``: a first-order lag of time constant ``tau`` from ``actual`` towards
    ``command`` held over ``dt``: the value after ``dt`` and the mean over it (a robot base's
    response to a velocity command; ``tau`` 0: instant)."""
    if tau <= 0.0:
        return command, command
    a = math.exp(-dt / tau)
    return command + (actual - command) * a, command + (actual - command) * tau / dt * (1 - a)


@jitable
def unicycle_step(x: float, y: float, theta: float, v: float, omega: float, dt: float
                  ) -> tuple[float, float, float]:
    """Pose after ``dt`` s at constant ``v`` and ``omega``: the exact circular arc (a straight
    segment when ``omega`` is 0), smooth as ``omega -> 0``. Theta is not wrapped."""
    half = 0.5 * omega * dt
    if abs(half) < 1e-6:
        sinc = 1.0 - half * half / 6.0   # sin(h)/h to fourth order: exact in doubles here
    else:
        sinc = math.sin(half) / half
    dist = v * dt * sinc
    mid = theta + half
    return x + dist * math.cos(mid), y + dist * math.sin(mid), theta + omega * dt


@jitable
def base_step(x: float, y: float, theta: float, va: float, wa: float, v: float, omega: float,
              tau: float, dt: float) -> tuple[float, float, float, float, float]:
    """``(x, y, theta, va, wa)`` one period ``dt`` on for a differential-drive base whose
    actual velocity ``(va, wa)`` follows the command ``(v, omega)`` through a first-order lag
    ``tau`` (:func:`lagged`), moving along the arc of its mean velocity over the period (how
    the simulated base moves; theta is not wrapped)."""
    va, v_mean = lagged(va, v, tau, dt)
    wa, w_mean = lagged(wa, omega, tau, dt)
    x, y, theta = unicycle_step(x, y, theta, v_mean, w_mean, dt)
    return x, y, theta, va, wa


@jitable
def offset_point(x: float, y: float, theta: float, d: float) -> tuple[float, float]:
    """Reference point R at distance ``d`` ahead of the wheel-axle centre (Eq. 2)."""
    return x + d * math.cos(theta), y + d * math.sin(theta)


@jitable
def segment_point(px: float, py: float, x0: float, y0: float, x1: float, y1: float
                  ) -> tuple[float, float]:
    """Point of the segment (x0, y0)-(x1, y1) nearest to (px, py)."""
    ex, ey = x1 - x0, y1 - y0
    length2 = ex * ex + ey * ey
    s = 0.0
    if length2 > 0.0:
        s = min(max(((px - x0) * ex + (py - y0) * ey) / length2, 0.0), 1.0)
    return x0 + s * ex, y0 + s * ey


def nearest_point(obstacle: Obstacle, px: float, py: float) -> tuple[float, float]:
    """Point of the obstacle's surface nearest to (px, py) (a wall: its centre-line)."""
    if isinstance(obstacle, Circle):
        dx, dy = px - obstacle.x, py - obstacle.y
        dist = math.hypot(dx, dy)
        if dist < 1e-12:
            return obstacle.x + obstacle.radius, obstacle.y
        return obstacle.x + obstacle.radius * dx / dist, obstacle.y + obstacle.radius * dy / dist
    return segment_point(px, py, obstacle.x0, obstacle.y0, obstacle.x1, obstacle.y1)


@jitable
def circle_clearance(px: float, py: float, cx: float, cy: float, r: float) -> float:
    """Distance from (px, py) to the rim of the circle (cx, cy, r) (negative: inside)."""
    return math.hypot(px - cx, py - cy) - r


@jitable
def wall_clearance(px: float, py: float, x0: float, y0: float, x1: float, y1: float) -> float:
    """Distance from (px, py) to the segment (x0, y0)-(x1, y1)."""
    qx, qy = segment_point(px, py, x0, y0, x1, y1)
    return math.hypot(px - qx, py - qy)


def clearance(obstacle: Obstacle, px: float, py: float, footprint: float = 0.0) -> float:
    """Distance from a footprint circle of radius ``footprint`` at (px, py) to the obstacle's
    surface (negative: overlap)."""
    if isinstance(obstacle, Circle):
        return circle_clearance(px, py, obstacle.x, obstacle.y, obstacle.radius) - footprint
    o = obstacle
    return wall_clearance(px, py, o.x0, o.y0, o.x1, o.y1) - footprint


def line_of_sight(ax: float, ay: float, bx: float, by: float,
                  obstacles: Sequence[Obstacle]) -> bool:
    """True if the segment from ``(ax, ay)`` to ``(bx, by)`` passes through no circle and
    crosses no wall (touching counts as clear)."""
    for o in obstacles:
        if isinstance(o, Circle):
            px, py = segment_point(o.x, o.y, ax, ay, bx, by)
            if math.hypot(px - o.x, py - o.y) < o.radius:
                return False
        elif _crosses(ax, ay, bx, by, o.x0, o.y0, o.x1, o.y1):
            return False
    return True


def sweep_clear(ax: float, ay: float, bx: float, by: float, obstacles: Sequence[Obstacle],
                footprint: float) -> bool:
    """True if a footprint of radius ``footprint`` moved straight from ``(ax, ay)`` to
    ``(bx, by)`` overlaps no obstacle on the way, or, for an obstacle it already overlaps at
    ``(ax, ay)``, gets no closer to it than there."""
    for o in obstacles:
        if isinstance(o, Circle):
            px, py = segment_point(o.x, o.y, ax, ay, bx, by)
            need = min(o.radius + footprint, math.hypot(ax - o.x, ay - o.y))
            if math.hypot(px - o.x, py - o.y) < need - 1e-9:
                return False
            continue
        if _crosses(ax, ay, bx, by, o.x0, o.y0, o.x1, o.y1):
            return False
        need = min(footprint, wall_clearance(ax, ay, o.x0, o.y0, o.x1, o.y1))
        if min(wall_clearance(bx, by, o.x0, o.y0, o.x1, o.y1),
               wall_clearance(o.x0, o.y0, ax, ay, bx, by),
               wall_clearance(o.x1, o.y1, ax, ay, bx, by)) < need - 1e-9:
            return False
    return True


def _crosses(ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float,
             dy: float) -> bool:
    """Whether segments ab and cd cross properly (each one's ends on both sides of the
    other's line)."""
    def side(px, py, qx, qy, rx, ry):
        return (qx - px) * (ry - py) - (qy - py) * (rx - px)
    return (side(ax, ay, bx, by, cx, cy) * side(ax, ay, bx, by, dx, dy) < 0.0
            and side(cx, cy, dx, dy, ax, ay) * side(cx, cy, dx, dy, bx, by) < 0.0)


def closest_approach_time(dx: float, dy: float, dvx: float, dvy: float, horizon: float
                          ) -> float:
    """The time in ``[0, horizon]`` (s) at which two points moving at constant velocities are
    closest: ``(dx, dy)`` is the one's position relative to the other, ``(dvx, dvy)`` its
    relative velocity."""
    speed2 = dvx * dvx + dvy * dvy
    if speed2 <= 1e-12:
        return 0.0
    return min(max(-(dx * dvx + dy * dvy) / speed2, 0.0), horizon)


def predicted(obstacles: Sequence[Obstacle], x: float, y: float, vx: float, vy: float,
              horizon: float, reach: float = math.inf) -> tuple[Obstacle, ...]:
    """The obstacles with every moving circle on a collision course where it will be when
    closest to a point at ``(x, y)`` moving at ``(vx, vy)`` (the robot), within ``horizon`` s:
    what avoidance steers around. On a collision course: at the closest its body comes within
    ``reach`` of the point. Other circles, standing obstacles and walls are as they are."""
    if horizon <= 0.0:
        return tuple(obstacles)
    out = []
    for o in obstacles:
        if isinstance(o, Circle) and o.moving:
            dx, dy, dvx, dvy = o.x - x, o.y - y, o.vx - vx, o.vy - vy
            t = closest_approach_time(dx, dy, dvx, dvy, horizon)
            if math.hypot(dx + dvx * t, dy + dvy * t) < o.radius + reach:
                o = o.at(t)
        out.append(o)
    return tuple(out)


class ObstacleArrays(NamedTuple):
    """Obstacles as arrays for compiled kernels: circles as rows (x, y, r, vx, vy), walls as
    rows (x0, y0, x1, y1)."""

    circles: np.ndarray
    walls: np.ndarray


def obstacle_arrays(obstacles: Sequence[Obstacle]) -> ObstacleArrays:
    """The obstacles as :class:`ObstacleArrays`."""
    circles = [(o.x, o.y, o.radius, o.vx, o.vy) for o in obstacles if isinstance(o, Circle)]
    walls = [(o.x0, o.y0, o.x1, o.y1) for o in obstacles if not isinstance(o, Circle)]
    return ObstacleArrays(np.array(circles, dtype=float).reshape(-1, 5),
                          np.array(walls, dtype=float).reshape(-1, 4))


def sample_obstacles() -> ObstacleArrays:
    """A moving circle and a wall: the obstacles of the kernels' example calls
    (:func:`companion._jit.register`)."""
    return obstacle_arrays([Circle(1.0, 0.5, 0.2, vx=0.1), Wall(0.0, 1.0, 2.0, 1.0)])


@jitable
def min_clearance(px: float, py: float, obstacles: ObstacleArrays, footprint: float,
                  t: float = 0.0) -> float:
    """Smallest :func:`clearance` from a footprint at (px, py) to the obstacles (inf if none),
    the circles where their velocities take them in ``t`` s."""
    out = math.inf
    c, w = obstacles.circles, obstacles.walls
    for i in range(c.shape[0]):
        out = min(out, circle_clearance(px, py, c[i, 0] + t * c[i, 3], c[i, 1] + t * c[i, 4],
                                        c[i, 2]))
    for j in range(w.shape[0]):
        out = min(out, wall_clearance(px, py, w[j, 0], w[j, 1], w[j, 2], w[j, 3]))
    return out - footprint


@jitable
def _path_clearance(xs: np.ndarray, ys: np.ndarray, obstacles: ObstacleArrays,
                    footprint: float) -> float:
    out = math.inf
    for i in range(xs.shape[0]):
        out = min(out, min_clearance(xs[i], ys[i], obstacles, footprint))
    return out


#: Smallest :func:`min_clearance` along the points ``(xs[i], ys[i])`` (compiled).
path_clearance = kernel(_path_clearance,
                        lambda: (np.zeros(2), np.ones(2), sample_obstacles(), 0.0))


@jitable
def _point_clearances(xs: np.ndarray, ys: np.ndarray, obstacles: ObstacleArrays,
                      footprint: float) -> np.ndarray:
    out = np.empty(xs.shape[0])
    for i in range(xs.shape[0]):
        out[i] = min_clearance(xs[i], ys[i], obstacles, footprint)
    return out


#: :func:`min_clearance` at each of the points ``(xs[i], ys[i])`` (compiled).
point_clearances = kernel(_point_clearances,
                          lambda: (np.zeros(2), np.ones(2), sample_obstacles(), 0.0))


def speed_turn_std(cov: np.ndarray, theta: float) -> tuple[float, float]:
    """Standard deviations of a walker's speed along its heading ``theta`` (m/s) and of its
    turn rate (rad/s) from the covariance ``cov`` of a state (x, y, vx, vy, omega)."""
    c, s = math.cos(theta), math.sin(theta)
    var = c * c * cov[2, 2] + c * s * (cov[2, 3] + cov[3, 2]) + s * s * cov[3, 3]
    return math.sqrt(max(float(var), 0.0)), math.sqrt(max(float(cov[4, 4]), 0.0))


def major_std(cov: np.ndarray) -> float:
    """The square root of the largest eigenvalue of the 2x2 position block of ``cov``: the
    standard deviation (m) along the least certain direction (closed form, symmetrised)."""
    a, c, b = cov[0, 0], cov[1, 1], 0.5 * (cov[0, 1] + cov[1, 0])
    top = 0.5 * (a + c) + math.hypot(0.5 * (a - c), b)
    return math.sqrt(max(float(top), 0.0))
