"""Choosing what the robot does in one step (stage 4 of :mod:`companion.control.stages`):
follow the person at the formation's bearing in force (the adaptive policy may move it,
:class:`~companion.control.formation.FormationPolicy`), search for a lost person
(:class:`~companion.control.search.Search`), go back to the slot round walls
(:class:`~companion.control.rejoin.Rejoin`), or stop.

The bearing in force is an input of the controller's step (``Observation.formation``): a
change of side does not make the controller anew.
"""

from __future__ import annotations

import dataclasses

from companion.control.delays import DelayMeter
from companion.control.formation import FormationPolicy
from companion.control.rejoin import Rejoin
from companion.control.search import Search
from companion.control.slot import slot_point
from companion.control.stages import Step
from companion.params import Params
from companion.types import PersonEstimate

#: The controlled stop before a search has brought the robot to rest: both commands at most
#: this (m/s, rad/s; the rate limits end a stop at exactly zero).
AT_REST = (1e-9, 1e-9)


class Choosing:
    """See the module docstring. ``given``: the configured side is the formation policy's
    first choice (a side the user just set), not the side the robot is on."""

    def __init__(self, params: Params, delays: DelayMeter, given: bool = False):
        self.configured, self.delays = params, delays
        self.formation = FormationPolicy(params, given=given)
        self.search = Search(params)
        self.rejoin = Rejoin(params)
        self.reset()

    def reset(self) -> None:
        self.in_force = self.configured       # the params with the bearing in force
        self.formation.reset()
        self.search.reset()
        self.rejoin.reset()
        self.last: PersonEstimate | None = None   # the last estimate of the person

    def __call__(self, s: Step) -> list[str]:
        obs, e = s.obs, s.estimate
        adaptive = self.configured.formation.policy == "adaptive"
        if e is not None:
            self.last = e
            self.search.reset()
            self.rejoin.record(e.walker)
            if not s.stop and adaptive:
                self._bearing(self.formation.update(obs.robot, e.walker, s.obstacles), s)
        s.params = self.in_force
        if s.lost and not s.stop:
            s.manoeuvre = self._searching(s) if s.fresh else None
            s.stop = "" if s.manoeuvre is not None else "person_lost"
        elif not s.stop and s.fresh and e is not None and adaptive:
            way = self.rejoin.target(obs.robot, e.walker, slot_point(e.walker, s.params),
                                     s.obstacles, s.velocity[0])
            s.manoeuvre = None if way is None else (*way, "rejoin")
        p = s.params
        s.run = self.delays.params(p) if p.supervisor.delays == "measured" else p
        return []

    def _bearing(self, bearing: float, s: Step) -> None:
        """Put ``bearing`` in force; the controller's filters start fresh, the rate limits
        carry the robot on from its last command."""
        if bearing != self.in_force.formation.bearing:
            f = self.configured.formation
            self.in_force = self.configured.replace(
                formation=dataclasses.replace(f, bearing=bearing))
            s.restart = True

    def _searching(self, s: Step) -> tuple[float, float, str] | None:
        """The search's command for a lost person (None: stop and hold): it begins once the
        controlled stop has brought the robot to rest."""
        if self.configured.search.max_time_s <= 0.0 or self.last is None or self.search.over:
            return None
        if not self.search.active:
            if abs(s.prev[0]) > AT_REST[0] or abs(s.prev[1]) > AT_REST[1]:
                return None                   # the controlled stop first
            self.search.begin(s.obs.t, s.obs.robot, self.last)
        return self.search.target(s.obs.t, s.obs.robot, s.obstacles, s.velocity[0])
