"""Back to the slot round the walls (``formation.policy = "adaptive"``, docs/crowds.md
"Formations").

A robot held up before a door or a corridor's mouth (walkers coming through, a corner) while
the person walked on can find a wall between itself and its slot; tracking the slot
straight would press it against the wall, where avoidance and the slot's pull hold it in
place. While the robot's footprint (its radius and ``keepout.obstacle_clearance``) cannot
move straight to its slot past the walls (walls and LiDAR wall pieces,
:func:`companion.geometry.sweep_clear`; once on its way round, until that way has
:data:`RELEASE` m more room, so that the controller's curve to the slot does not clip the
corner it just rounded), :class:`Rejoin` plans the shortest way round them
(:func:`companion.control.planner.plan_way`) and the circles that stand near it
(:func:`standing_near`: a walker and the robot stopped face to face in an opening would
each wait for the other), keeping to the person's own way (kept every
:data:`SPACING` m, the last :data:`LENGTH` m) where it can, to the slot, or where the slot
itself is walled in, to the latest point of the person's way at least the formation
distance behind the person, and drives along it (:func:`companion.control.planner.next_point`,
:func:`companion.control.search.drive_to`); the keep-out and the rate limits still apply.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

from companion.control.formation import walls_of
from companion.control.planner import next_point
from companion.control.search import drive_to
from companion.geometry import sweep_clear
from companion.params import Params
from companion.types import Circle, Obstacle, PersonState, Pose

#: Distance (m) between the points kept of the person's way, and how much of it is kept.
SPACING, LENGTH = 0.25, 15.0
#: Speed per metre to the point (1/s), the least speed (m/s) and the heading error (rad)
#: above which the robot turns on the spot (at up to ``robot.omega_max``).
SPEED_GAIN, MIN_SPEED, FACING = 1.5, 0.3, 0.8
#: Room (m) beyond the footprint the straight way to the slot needs before a rejoin ends,
#: and the way round keeps (so that it does not run along the keep-out's obstacle barrier).
RELEASE, MARGIN = 0.3, 0.05
#: Circles slower than this (m/s) within this (m) of the robot are planned round.
STANDING, NEAR = 0.3, 2.0


def standing_near(robot: Pose, obstacles: Sequence[Obstacle]) -> list[Obstacle]:
    """The circles (not wall pieces) within :data:`NEAR` m of the robot that stand (slower
    than :data:`STANDING` m/s): a walker stopped in the way is planned round like a pillar;
    one who walks is the keep-out's to give way to."""
    return [o for o in obstacles if isinstance(o, Circle) and not o.piece
            and math.hypot(o.vx, o.vy) < STANDING
            and math.hypot(o.x - robot.x, o.y - robot.y) - o.radius < NEAR]


class Rejoin:
    """The person's way, and the way back to the slot round the walls (module docstring)."""

    def __init__(self, params: Params):
        self.params = params
        self._trail: deque[tuple[float, float]] = deque(maxlen=int(LENGTH / SPACING))
        self.active = False           # on the way round the walls

    def reset(self) -> None:
        self._trail.clear()
        self.active = False

    def record(self, person: PersonState) -> None:
        """Keep the person's position if it is :data:`SPACING` from the last one kept."""
        if not (math.isfinite(person.x) and math.isfinite(person.y)):
            return
        if not self._trail or math.hypot(person.x - self._trail[-1][0],
                                         person.y - self._trail[-1][1]) >= SPACING:
            self._trail.append((person.x, person.y))

    def target(self, robot: Pose, person: PersonState, slot: tuple[float, float],
               obstacles: Sequence[Obstacle], v_now: float) -> tuple[float, float] | None:
        """``(v, omega)`` along the way round the walls, or None where the robot can move
        straight to ``slot`` (or no way is found): the controller tracks the slot."""
        p = self.params
        walls, r = walls_of(obstacles), p.robot.radius + p.keepout.obstacle_clearance
        room = r + RELEASE if self.active else r
        self.active = bool(walls) and not sweep_clear(robot.x, robot.y, *slot, walls, room)
        if not self.active:
            return None
        goals = [slot] + [(x, y) for x, y in reversed(self._trail)
                          if math.hypot(x - person.x, y - person.y) >= p.formation.distance]
        around = walls + standing_near(robot, obstacles)
        for goal in goals[:3]:
            point = next_point((robot.x, robot.y), goal, around, r + MARGIN, self._trail)
            if point is not None:
                break
        else:
            self.active = False
            return None
        x, y = point
        speed = min(p.robot.v_max,
                    max(MIN_SPEED, SPEED_GAIN * math.hypot(x - robot.x, y - robot.y)))
        v, omega, _ = drive_to((x, y), robot, obstacles, v_now, p, speed, p.robot.omega_max,
                               FACING)
        return v, omega
