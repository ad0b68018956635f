"""The adaptive formation policy (``formation.policy = "adaptive"``, docs/crowds.md
"Formations"): beside the person, take the side the robot is on instead of crossing over to
the configured one, and fall in behind where side by side does not fit.

- **Side.** Chosen when the person is first seen and again whenever the person's walking
  heading has turned by more than :data:`REVERSAL` from the one at the last choice (a
  turnaround; a person first seen standing who sets off keeps the side, as does one who
  stands and turns on the spot until they walk off): a
  robot that was on the person's left is on their right once they walk back, and switching
  the formation's side keeps it where it is instead of running round the person. A gradual
  turn (a circle) keeps the robot on its side, so it never switches there. A side set while
  running (``ros2 param set``, a retune) is the first choice instead, until the next turnaround.
- **Narrow passage.** Where the room on that side of the person's way (the nearest obstacle
  the robot knows within :data:`AHEAD` m ahead of the person that it cannot pass on its far
  side while the person walks, any obstacle while they stand, measured sideways from the
  line of the person's heading) is less than the formation
  distance plus the robot's radius plus :data:`MARGIN`, the robot falls in behind; it
  returns to the side once the room is :data:`HYSTERESIS` more than that and it can move
  straight to its side slot past every wall (a robot still before a door that the person
  is through stays behind them until it is through too).
- The bearing in force moves towards the chosen one at most :data:`BEARING_RATE`, so the slot
  never jumps. Only formations beside the person adapt; behind and front stay.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from companion.control.slot import slot_point
from companion.geometry import sweep_clear, wrap_2pi, wrap_pi
from companion.params import BEHIND, LEFT, RIGHT, Params
from companion.types import Circle, Obstacle, PersonState, Pose, Wall

#: Heading change (rad) that counts as the person turning round.
REVERSAL = 2.5
#: Below this speed (m/s) the person's heading does not count.
MOVING = 0.3
#: How far ahead of the person (m) obstacles count for the room beside the way.
AHEAD = 3.0
#: Room (m) beyond the formation distance and the robot's radius that side by side needs, and
#: the extra room before the robot returns to the side.
MARGIN, HYSTERESIS = 0.3, 0.3
#: Fastest change of the bearing in force (rad/s).
BEARING_RATE = 1.0


def side_of(robot: Pose, person: PersonState) -> float:
    """+1 where the robot is left of the person's heading, -1 right of it."""
    cross = math.cos(person.theta) * (robot.y - person.y) \
        - math.sin(person.theta) * (robot.x - person.x)
    return 1.0 if cross >= 0.0 else -1.0


def side_room(person: PersonState, side: float, obstacles: Sequence[Obstacle],
              ahead: float = AHEAD, lane: float | None = None) -> float:
    """Room (m) on ``side`` (+1 left, -1 right) of the person's way: the sideways distance
    from the line of the person's heading to the nearest standing obstacle within ``ahead`` m
    ahead of the person that the robot cannot pass on its far side (0 where one crosses the
    line there); inf if none. A wall, or a piece of one (a LiDAR circle marked ``piece``),
    bounds the way; with a ``lane`` (m) another circle does only where less than that is
    free beyond it before the next obstacle (a pillar in a wide corridor does not), without
    one every circle does. Moving circles (walkers) do not
    narrow the way: they pass, and avoidance and the keep-out see them."""
    c, s = math.cos(person.theta), math.sin(person.theta)

    def frame(x: float, y: float) -> tuple[float, float]:    # (along, sideways on ``side``)
        dx, dy = x - person.x, y - person.y
        return dx * c + dy * s, side * (-dx * s + dy * c)

    spans: list[tuple[float, float, bool]] = []      # (from, to, bounds the way) sideways
    for ob in obstacles:
        if isinstance(ob, Circle):
            if ob.moving:
                continue
            along, lat = frame(ob.x, ob.y)
            if -ob.radius <= along <= ahead + ob.radius and lat > -ob.radius:
                spans.append((max(lat - ob.radius, 0.0), lat + ob.radius, ob.piece))
        elif isinstance(ob, Wall):
            (a0, l0), (a1, l1) = frame(ob.x0, ob.y0), frame(ob.x1, ob.y1)
            lo, hi = max(min(a0, a1), 0.0), min(max(a0, a1), ahead)
            if lo > hi:
                continue
            if abs(a1 - a0) < 1e-12:
                lats = (l0, l1)
            else:
                lats = tuple(l0 + (l1 - l0) * (a - a0) / (a1 - a0) for a in (lo, hi))
            if min(lats) <= 0.0 <= max(lats):
                spans.append((0.0, math.inf, True))          # it crosses the way
            elif min(lats) > 0.0:
                spans.append((min(lats), math.inf, True))
    merged: list[list] = []                          # overlapping spans as one
    for start, end, bounds in sorted(spans):
        if merged and start <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], end)
            merged[-1][2] = merged[-1][2] or bounds
        else:
            merged.append([start, end, bounds])
    for i, (start, end, bounds) in enumerate(merged):
        beyond = merged[i + 1][0] if i + 1 < len(merged) else math.inf
        if bounds or lane is None or beyond - end < lane:
            return start
    return math.inf


class FormationPolicy:
    """Chooses the bearing in force from the configured one (module docstring)."""

    def __init__(self, params: Params, given: bool = False):
        """``given``: the configured side is the first choice (a side the user just set),
        not the side the robot is on."""
        self.params = params
        self.configured = params.formation.bearing
        self.need = params.formation.distance + params.robot.radius + MARGIN
        self.lane = 2.0 * (params.robot.radius + MARGIN)   # to pass an obstacle's far side
        # (while the person walks: beside a standing person the slot itself must be free)
        self.step = BEARING_RATE * params.dt
        self.given = given
        self.reset()

    def reset(self) -> None:
        self.bearing = self.configured
        self._side = self.configured
        self._behind = False
        self._heading: float | None = None       # the walking heading at the last choice
        self._seen = False

    def update(self, robot: Pose, person: PersonState,
               obstacles: Sequence[Obstacle] = ()) -> float:
        """The bearing in force after this estimate of the person."""
        if not _beside(self.configured):
            return self.bearing
        walking = person.v > MOVING
        if self._heading is None:                # not yet seen walking
            if not self._seen and not self.given:
                self._side = LEFT if side_of(robot, person) > 0 else RIGHT
            self._seen = True
            if walking:                          # setting off keeps the side
                self._heading = person.theta
        elif walking and abs(wrap_pi(person.theta - self._heading)) > REVERSAL:
            self._heading = person.theta
            self._side = LEFT if side_of(robot, person) > 0 else RIGHT
        room = side_room(person, 1.0 if self._side == LEFT else -1.0, obstacles,
                         lane=self.lane if walking else None)
        if room < self.need:
            self._behind = True
        elif room > self.need + HYSTERESIS and (not self._behind
                                                or self._reachable(robot, person, obstacles)):
            self._behind = False
        target = BEHIND if self._behind else self._side
        change = wrap_pi(target - self.bearing)
        if abs(change) > math.pi / 2 + 1e-9:     # side to side: the slot stays where it is
            self.bearing = target
        else:
            self.bearing = wrap_2pi(self.bearing + max(-self.step, min(self.step, change)))
        return self.bearing

    def _reachable(self, robot: Pose, person: PersonState,
                   obstacles: Sequence[Obstacle]) -> bool:
        """The robot's footprint can move straight to its slot on the chosen side without
        meeting a wall or a LiDAR wall piece."""
        sx, sy = slot_point(person, self.params, self._side)
        return sweep_clear(robot.x, robot.y, sx, sy, walls_of(obstacles),
                           self.params.robot.radius)


def walls_of(obstacles: Sequence[Obstacle]) -> list[Obstacle]:
    """The obstacles that bound the way: walls and LiDAR wall pieces."""
    return [o for o in obstacles if isinstance(o, Wall) or o.piece]


def _beside(bearing: float) -> bool:
    return min(abs(wrap_pi(bearing - LEFT)), abs(wrap_pi(bearing - RIGHT))) < 1e-9
