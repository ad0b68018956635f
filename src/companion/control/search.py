"""Looking for a lost person (docs/safety.md, "Losing and finding the person").

Once the supervisor has brought the robot to a stop for a person the tracker lost, a
:class:`Search` (when ``search.max_time_s`` > 0) takes it through three phases, each named in
the status reason:

1. ``search_turn``: turn on the spot to face where the person was going: the last estimate
   walked on at its velocity for ``search.horizon_s``, or for the time searched so far once
   longer (a person who walks on out of sight is looked for where they would be by now, not
   where they vanished);
2. ``search_approach``: move there at up to ``search.speed``, never faster than the braking
   bound of every obstacle it sees (it can always stop short of them) and of the person
   standing where they would be by now (so it never runs into the person it looks for),
   until within ``search.arrive_m``; where walls stand in the straight way, round them
   (:func:`companion.control.planner.next_point`);
3. ``search_scan``: turn on the spot.

The search ends after ``search.max_time_s`` or once the robot is ``search.max_distance_m``
from where it stopped; then it holds. Detections that the tracker accepts end it at once.
The supervisor gives way to walkers on the search's commands
(:func:`companion.control.evasive.give_way_target`, without a person) and keeps the stop
path clear (:func:`companion.control.stopping.stop_path_target`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from companion.control.formation import walls_of
from companion.control.keepout import clip_to, obstacle_bounds, person_interval
from companion.control.planner import next_point
from companion.geometry import wrap_pi
from companion.params import Params
from companion.types import Obstacle, PersonEstimate, PersonState, Pose

#: Heading error (rad) below which the robot faces the goal; the turn's gain (1/s).
FACING, TURN_GAIN = 0.2, 2.0


def search_goal(last: PersonEstimate, horizon: float) -> tuple[float, float]:
    """Where the person was going: the last estimate walked on for ``horizon`` seconds."""
    s = last.state
    return s.x + s.v * math.cos(s.theta) * horizon, s.y + s.v * math.sin(s.theta) * horizon


class Search:
    """The search of one loss (module docstring): :meth:`begin`, then :meth:`target` each
    period until it returns None."""

    def __init__(self, params: Params):
        self.params = params
        self.reset()

    def reset(self) -> None:
        self._last: PersonEstimate | None = None
        self._t0 = 0.0
        self._from = (0.0, 0.0)
        self._scan = 1.0
        self.over = False

    @property
    def active(self) -> bool:
        return self._last is not None and not self.over

    def begin(self, t: float, robot: Pose, last: PersonEstimate) -> None:
        goal = search_goal(last, self.params.search.horizon_s)
        self._last, self._t0, self._from, self.over = last, t, (robot.x, robot.y), False
        bearing = wrap_pi(math.atan2(goal[1] - robot.y, goal[0] - robot.x) - robot.theta)
        self._scan = 1.0 if bearing >= 0.0 else -1.0

    def target(self, t: float, robot: Pose, obstacles: Sequence[Obstacle], v_now: float
               ) -> tuple[float, float, str] | None:
        """``(v, omega, phase)`` for this period, or None once the search is over."""
        s, p = self.params.search, self.params
        if self._last is None or self.over:
            return None
        searched = t - self._t0
        if searched > s.max_time_s or math.hypot(robot.x - self._from[0],
                                                 robot.y - self._from[1]) > s.max_distance_m:
            self.over = True
            return None
        goal = search_goal(self._last, max(s.horizon_s, searched))
        if math.hypot(goal[0] - robot.x, goal[1] - robot.y) <= s.arrive_m:
            return 0.0, self._scan * s.turn_rate, "search_scan"
        walls = walls_of(obstacles)
        point = next_point((robot.x, robot.y), goal, walls,
                           p.robot.radius + p.keepout.obstacle_clearance) if walls else None
        v, omega, facing = drive_to(point or goal, robot, obstacles, v_now, p, s.speed)
        # never faster than it can stop short of where the person would be by now
        there = PersonState(*search_goal(self._last, searched), self._last.state.theta, 0.0, 0.0)
        v = clip_to(v, [person_interval(robot, there, p, [], actual=v_now)], p.robot.v_max)
        return v, omega, "search_approach" if facing else "search_turn"


def drive_to(goal: tuple[float, float], robot: Pose, obstacles: Sequence[Obstacle],
             v_now: float, params: Params, speed: float, turn_rate: float | None = None,
             facing: float = FACING) -> tuple[float, float, bool]:
    """``(v, omega, facing)`` towards ``goal``: turn on the spot (at up to ``turn_rate``,
    default ``search.turn_rate``) until facing it within ``facing`` rad, then drive (turning
    on) at up to ``speed`` times the cosine of the heading error, never faster than the
    braking bound of every obstacle seen."""
    rate = params.search.turn_rate if turn_rate is None else turn_rate
    gx, gy = goal
    error = wrap_pi(math.atan2(gy - robot.y, gx - robot.x) - robot.theta)
    turn = max(-rate, min(rate, TURN_GAIN * error))
    if abs(error) > facing:
        return 0.0, turn, False
    v = clip_to(min(speed, params.robot.v_max) * math.cos(error),
                obstacle_bounds(robot, obstacles, params, v_now), params.robot.v_max)
    return v, turn, True
