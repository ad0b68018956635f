"""Safety supervisor: the last layer between any controller and the motors (docs/safety.md).

It is the only layer that accepts raw sensor data and the outermost one of the standard stack.
Its output is finite, within the velocity limits and within the acceleration limits (one
period ``dt`` per call), whatever the input, and carries a status (``ok``, ``degraded``: a
fault is handled and the robot moves, ``stopped``: it brakes to a stop and holds). What else
it did (the reasons, the person estimate, the controller's request, the bearing in force, the
obstacles it knew) is the step's :class:`~companion.types.StepReport`, :attr:`report`.

The step is a pipeline of separate stages over one typed context
(:mod:`companion.control.stages`): clock -> tracking (the person tracker and the perception
front end) -> input checks -> choosing what to do (:mod:`companion.control.choice`: follow,
search, rejoin, stop) -> the controller -> the keep-out -> the limits. Each stage returns
the reasons it raises; the pipeline collects them. The keep-out and the controller use the
detection latency and actuator lag measured by :class:`~companion.control.delays.DelayMeter`
(``supervisor.delays``), not the declared ones.
"""

from __future__ import annotations

from companion.control import checks
from companion.control.base import Controller
from companion.control.choice import Choosing
from companion.control.delays import DelayMeter
from companion.control.stages import (
    Clocking,
    Driving,
    Guarding,
    InputChecks,
    Limiting,
    Step,
    Tracking,
)
from companion.params import Params
from companion.tracking import Reidentify
from companion.types import Command, Observation, StepReport

OK, DEGRADED, STOPPED = "ok", "degraded", "stopped"


class SafetySupervisor:
    """Wraps any controller; see the module docstring."""

    def __init__(self, inner: Controller, params: Params):
        self.params = params
        self.delays = DelayMeter(params)
        self._clock = Clocking(params)
        self._tracking = Tracking(params, self.delays)
        self._checks = InputChecks(params, self._tracking.tracker, self.delays)
        self._choice = Choosing(params, self.delays)
        self._driving = Driving(inner)
        self._guard = Guarding(params)
        self._limits = Limiting(params)
        self._stages()
        self.reset()

    def _stages(self) -> None:
        """The pipeline's stages in order, with their names in the report: those that read
        the inputs, then (the rate limits started from a measured velocity) those that act."""
        self._inputs = (("clock", self._clock), ("tracking", self._tracking),
                        ("inputs", self._checks))
        self._actions = (("choice", self._choice), ("controller", self._driving),
                         ("keepout", self._guard))

    @property
    def inner(self) -> Controller:
        """The wrapped controller."""
        return self._driving.inner

    def reset(self) -> None:
        self.delays.reset()
        for stage in (self._clock, self._tracking, self._checks, self._choice, self._driving,
                      self._guard, self._limits):
            stage.reset()
        self.report = StepReport()

    def step(self, obs: Observation) -> Command:
        s = Step(obs, self._choice.in_force, self._limits.prev)
        raised: list[tuple[str, str]] = []
        for name, stage in self._inputs:
            reasons = stage(s)
            if reasons:
                raised += [(name, r) for r in reasons]
        if s.measured and not self._limits.started:   # limits start from the measured velocity
            self._limits.start(*s.velocity)
            s.prev = self._limits.prev
        for name, stage in self._actions:
            reasons = stage(s)
            if reasons:
                raised += [(name, r) for r in reasons]
        final = self._limits(s)
        if s.fresh:
            self.delays.sent(obs.t, self._limits.prev)
        self._driving.applied(s, final)
        reasons = [r for _, r in raised]
        status = STOPPED if s.stop else DEGRADED if reasons else OK
        self.report = StepReport(status, "+".join(dict.fromkeys([s.stop] * bool(s.stop)
                                                                + reasons)),
                                 tuple(raised), s.estimate, s.requested,
                                 s.params.formation.bearing, s.obstacles)
        return Command(final.v, final.omega, final.u_ob, status)

    def applied(self, cmd: Command) -> None:
        """Told the command the robot executes outside a step (its velocity at the start of an
        episode): the rate limits start from it."""
        if checks.finite(cmd.v, cmd.omega):
            self._limits.start(cmd.v, cmd.omega)
            self.inner.applied(cmd)

    def retune(self, inner: Controller, params: Params) -> None:
        """Run on with new parameters (a formation, limits or gains changed while running) and
        ``inner`` made with them: the tracker, the clock and the last command stay, so the rate
        limits carry the robot from its last command towards the new slot; ``inner`` starts
        fresh at the next step. Parameters of the clock and tracker must not change."""
        moved = params.formation.bearing != self.params.formation.bearing
        last = self._choice.last
        self.params = params
        self._checks = InputChecks(params, self._tracking.tracker, self.delays)
        self._choice = Choosing(params, self.delays, given=moved)
        self._choice.last = last
        self._driving = Driving(inner)
        self._driving.fresh = True
        self._guard = Guarding(params)
        prev, started = self._limits.prev, self._limits.started
        self._limits = Limiting(params)
        self._limits.prev, self._limits.started = prev, started
        self._stages()

    @property
    def reidentify(self) -> Reidentify | None:
        """The re-identification hook of the person tracker (:data:`Reidentify`): after a
        loss, a detection is the person where it returns True, is not where False, and the
        tracker's prediction decides where None (or no hook)."""
        return self._tracking.tracker.reidentify

    @reidentify.setter
    def reidentify(self, hook: Reidentify | None) -> None:
        self._tracking.tracker.reidentify = hook
