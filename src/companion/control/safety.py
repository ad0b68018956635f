"""Keep-out barrier around the person, applied to any controller's linear velocity.

A control-barrier condition on the distance ``D`` from the robot centre (wheel axle) to the
person:

    dD/dt >= -barrier_rate * (D - person_clearance)

so the robot may approach at most at a speed that shrinks to zero at the clearance, and
must move away inside it. ``dD/dt = v e(theta_r).n - v_h e(theta_h).n`` with ``n`` the unit
vector from the person to the robot, which is linear in ``v``: the filter clips ``v`` to the
half-line that satisfies the condition (and to the input limit). ``omega`` is never changed,
so the robot can always turn. ``person_clearance = 0`` switches the filter off.
"""

from __future__ import annotations

import math

from companion.control.base import PersonState, Pose
from companion.params import RobotParams, SafetyParams


def person_barrier(v: float, robot: Pose, person: PersonState, safety: SafetyParams,
                   limits: RobotParams) -> float:
    """The linear velocity closest to ``v`` that satisfies the person keep-out barrier."""
    if safety.person_clearance <= 0.0:
        return v
    dx, dy = robot.x - person.x, robot.y - person.y
    dist = math.hypot(dx, dy)
    if dist < 1e-9:
        return 0.0  # no direction to move away along; stop translating
    nx, ny = dx / dist, dy / dist
    along = math.cos(robot.theta) * nx + math.sin(robot.theta) * ny   # dD/dt per unit v
    person_in = person.v * (math.cos(person.theta) * nx + math.sin(person.theta) * ny)
    need = person_in - safety.barrier_rate * (dist - safety.person_clearance)  # v*along >= need
    if abs(along) < 1e-9:
        return v
    bound = need / along
    if along > 0.0:
        v = max(v, bound)
    else:
        v = min(v, bound)
    return min(max(v, -limits.v_max), limits.v_max)
