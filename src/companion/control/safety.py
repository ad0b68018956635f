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
from typing import Sequence

from companion.control.base import PersonState, Pose
from companion.obstacles import Circle, Obstacle, nearest_point
from companion.params import Params


def _bound(robot: Pose, nx: float, ny: float, approach: float, dist: float, d_min: float,
           rate: float) -> tuple[float, float]:
    """Interval of v meeting ``v e(theta).n - approach >= -rate (dist - d_min)``."""
    along = math.cos(robot.theta) * nx + math.sin(robot.theta) * ny
    need = approach - rate * (dist - d_min)
    if abs(along) < 1e-9:
        return -math.inf, math.inf
    bound = need / along
    return (bound, math.inf) if along > 0.0 else (-math.inf, bound)


def safe_speed(v: float, robot: Pose, person: PersonState | None,
               obstacles: Sequence[Obstacle], params: Params) -> float:
    """The linear velocity closest to ``v`` that meets every keep-out barrier.

    If the barriers contradict each other (squeezed between two things) the middle of the
    two bounds is taken. The result is within ``robot.v_max``.
    """
    s = params.safety
    lo, hi = -math.inf, math.inf
    if person is not None and s.person_clearance > 0.0:
        dx, dy = robot.x - person.x, robot.y - person.y
        dist = math.hypot(dx, dy)
        if dist < 1e-9:
            return 0.0  # no direction to move away along
        nx, ny = dx / dist, dy / dist
        approach = person.v * (math.cos(person.theta) * nx + math.sin(person.theta) * ny)
        a, b = _bound(robot, nx, ny, approach, dist, s.person_clearance, s.barrier_rate)
        lo, hi = max(lo, a), min(hi, b)
    if s.obstacle_clearance > 0.0:
        for ob in obstacles:
            if isinstance(ob, Circle):
                cx, cy = ob.x, ob.y  # normal from the centre; surface ob.radius out
                inner = ob.radius
            else:
                (cx, cy), inner = nearest_point(ob, robot.x, robot.y), 0.0
            dx, dy = robot.x - cx, robot.y - cy
            dist = math.hypot(dx, dy)
            if dist < 1e-9:
                continue
            clearance = dist - inner - params.robot.radius
            a, b = _bound(robot, dx / dist, dy / dist, 0.0, clearance, s.obstacle_clearance,
                          s.barrier_rate)
            lo, hi = max(lo, a), min(hi, b)
    v = min(max(v, lo), hi) if lo <= hi else 0.5 * (lo + hi)
    return min(max(v, -params.robot.v_max), params.robot.v_max)
