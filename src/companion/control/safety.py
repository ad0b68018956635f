"""Keep-out barriers around the person and the obstacles, applied to the linear velocity.

For each thing to keep away from, a control-barrier condition on the clearance ``D``:

    dD/dt >= -barrier_rate * (D - D_min)

so the robot may approach at most at a speed that shrinks to zero at ``D_min``, and must
move away inside it. ``dD/dt = v e(theta_r).n - (velocity of the thing).n`` with ``n`` the
unit vector from the thing's nearest point to the robot centre, which is linear in ``v``: each
condition keeps ``v`` on one side of a bound, and the filter returns the speed closest to the
requested one that meets all of them (and the input limit). ``omega`` is never changed, so
the robot can always turn.

* Person: ``D`` is the distance from the robot centre to the person, ``D_min`` is
  ``safety.person_clearance`` (0 switches it off).
* Obstacles: ``D`` is the clearance from the robot's footprint to the surface,
  ``D_min`` is ``safety.obstacle_clearance`` (0 switches it off).
"""

from __future__ import annotations

import math
from typing import Iterable, Iterator, Sequence

from companion.control.base import PersonState, Pose
from companion.obstacles import Circle, Obstacle, nearest_point
from companion.params import Params


def speed_bound(theta: float, nx: float, ny: float, approach: float, allowed: float
                ) -> tuple[float, float]:
    """Interval of v meeting ``v e(theta).n - approach >= -allowed``.

    ``n`` is the unit vector from the thing to the robot, ``approach`` the thing's speed
    towards the robot along ``n`` and ``allowed`` the closing speed that is still acceptable
    (negative: the distance must grow). Where the heading is perpendicular to ``n``, ``v``
    cannot change the distance and the interval is unbounded.
    """
    along = math.cos(theta) * nx + math.sin(theta) * ny
    need = approach - allowed
    if abs(along) < 1e-9:
        return -math.inf, math.inf
    bound = need / along
    return (bound, math.inf) if along > 0.0 else (-math.inf, bound)


def person_normal(robot: Pose, person: PersonState) -> tuple[float, float, float, float] | None:
    """``(nx, ny, dist, approach)``: unit vector from the person to the robot centre, their
    distance and the person's speed towards the robot along it (None if they coincide)."""
    dx, dy = robot.x - person.x, robot.y - person.y
    dist = math.hypot(dx, dy)
    if dist < 1e-9:
        return None
    nx, ny = dx / dist, dy / dist
    approach = person.v * (math.cos(person.theta) * nx + math.sin(person.theta) * ny)
    return nx, ny, dist, approach


def obstacle_normals(robot: Pose, obstacles: Sequence[Obstacle], radius: float
                     ) -> Iterator[tuple[float, float, float]]:
    """``(nx, ny, clearance)`` per obstacle: unit vector from the obstacle towards the robot
    centre (from a circle's centre, from a wall's nearest point) and the clearance from a
    footprint of ``radius`` to its surface. Obstacles at the robot centre are skipped."""
    for ob in obstacles:
        if isinstance(ob, Circle):
            cx, cy, inner = ob.x, ob.y, ob.radius
        else:
            (cx, cy), inner = nearest_point(ob, robot.x, robot.y), 0.0
        dx, dy = robot.x - cx, robot.y - cy
        dist = math.hypot(dx, dy)
        if dist >= 1e-9:
            yield dx / dist, dy / dist, dist - inner - radius


def clip_to(v: float, bounds: Iterable[tuple[float, float]], v_max: float) -> float:
    """``v`` clipped to the intersection of the intervals ``bounds`` and ``[-v_max, v_max]``;
    if the intervals contradict each other, the middle of the tightest pair of ends."""
    lo, hi = -math.inf, math.inf
    for a, b in bounds:
        lo, hi = max(lo, a), min(hi, b)
    v = min(max(v, lo), hi) if lo <= hi else 0.5 * (lo + hi)
    return min(max(v, -v_max), v_max)


def safe_speed(v: float, robot: Pose, person: PersonState | None,
               obstacles: Sequence[Obstacle], params: Params) -> float:
    """The linear velocity closest to ``v`` that meets every keep-out barrier.

    If the barriers contradict each other (squeezed between two things) the middle of the
    two bounds is taken. The result is within ``robot.v_max``.
    """
    s = params.safety
    bounds = []
    if person is not None and s.person_clearance > 0.0:
        normal = person_normal(robot, person)
        if normal is None:
            return 0.0  # no direction to move away along
        nx, ny, dist, approach = normal
        bounds.append(speed_bound(robot.theta, nx, ny, approach,
                                  s.barrier_rate * (dist - s.person_clearance)))
    if s.obstacle_clearance > 0.0:
        for nx, ny, gap in obstacle_normals(robot, obstacles, params.robot.radius):
            bounds.append(speed_bound(robot.theta, nx, ny, 0.0,
                                      s.barrier_rate * (gap - s.obstacle_clearance)))
    return clip_to(v, bounds, params.robot.v_max)
