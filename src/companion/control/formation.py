"""The adaptive formation policy (``formation.policy = "adaptive"``, docs/safety.md): beside
the person, take the side the robot is on instead of crossing over to the configured one.

The side is chosen when the person is first seen and again whenever the person's heading has
turned by more than :data:`REVERSAL` from the heading at the last choice (a turnaround): a
robot that was on the person's left is on their right once they walk back, and switching the
formation's side keeps it where it is instead of running round the person. A gradual turn
(a circle) keeps the robot on its side, so it never switches there. Only the side bearings
(left, right) switch; behind and front stay.
"""

from __future__ import annotations

import math

from companion.geometry import wrap_pi
from companion.params import LEFT, RIGHT
from companion.types import PersonState, Pose

#: Heading change (rad) that counts as the person turning round.
REVERSAL = 2.5
#: Below this speed (m/s) the person's heading does not count.
MOVING = 0.3


def side_of(robot: Pose, person: PersonState) -> float:
    """+1 where the robot is left of the person's heading, -1 right of it."""
    cross = math.cos(person.theta) * (robot.y - person.y) \
        - math.sin(person.theta) * (robot.x - person.x)
    return 1.0 if cross >= 0.0 else -1.0


class FormationPolicy:
    """Chooses the bearing in force from the configured one (module docstring)."""

    def __init__(self, bearing: float):
        self.configured = bearing
        self.reset()

    def reset(self) -> None:
        self.bearing = self.configured
        self._heading: float | None = None       # the person's heading at the last choice

    def update(self, robot: Pose, person: PersonState) -> float:
        """The bearing in force after this estimate of the person."""
        if not _beside(self.configured):
            return self.bearing
        if self._heading is None:
            self._heading = person.theta
            self.bearing = LEFT if side_of(robot, person) > 0 else RIGHT
        elif person.v > MOVING and abs(wrap_pi(person.theta - self._heading)) > REVERSAL:
            self._heading = person.theta
            self.bearing = LEFT if side_of(robot, person) > 0 else RIGHT
        return self.bearing


def _beside(bearing: float) -> bool:
    return min(abs(wrap_pi(bearing - LEFT)), abs(wrap_pi(bearing - RIGHT))) < 1e-9
