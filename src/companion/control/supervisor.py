"""Safety supervisor: the last layer between any controller and the motors (docs/safety.md).

It is the only layer that accepts raw sensor data and the outermost one of the standard stack.
Its output is finite, within the velocity limits and within the acceleration limits (one
period ``dt`` per call), whatever the input, and carries a status (``ok``, ``degraded``: a
fault is handled and the robot moves, ``stopped``: it brakes to a stop and holds) and a
reason. Per call:

1. clock (:class:`~companion.control.checks.Clock`);
2. person estimate (:class:`~companion.control.person_gate.PersonGate`);
3. robot pose, obstacles and scan (:mod:`companion.control.checks`);
4. the wrapped controller, on a checked observation;
5. keep-out rules (:func:`companion.control.keepout.keep_out`);
6. rate and velocity limits (:func:`companion.control.limits.limit`); a stopped robot's target
   is zero, so it brakes at the limits.
"""

from __future__ import annotations

from companion.control import checks
from companion.control.base import Controller
from companion.control.keepout import keep_out
from companion.control.limits import limit
from companion.control.person_gate import PersonGate
from companion.params import Params
from companion.types import Command, Observation

OK, DEGRADED, STOPPED = "ok", "degraded", "stopped"


class SafetySupervisor:
    """Wraps any controller; see the module docstring."""

    def __init__(self, inner: Controller, params: Params):
        self.inner = inner
        self.params = params
        self._clock = checks.Clock(params.dt, params.supervisor.max_step_ratio)
        self._person = PersonGate(params.supervisor)
        self.reset()

    def reset(self) -> None:
        self.inner.reset()
        self._inner_fresh = False     # inner must be reset before its next step
        self._prev = (0.0, 0.0)       # last output (v, omega)
        self._clock.reset()
        self._person.reset()

    def step(self, obs: Observation) -> Command:
        p = self.params
        reasons: list[str] = []
        stop = ""
        elapsed, clock = self._clock.tick(obs.t)
        if clock != "ok":
            reasons.append(clock)
            self._inner_fresh = True
        fresh = clock != "clock"   # a zero, negative or non-finite step discards the data
        self._person.advance(elapsed)
        if fresh:
            self._person.update(obs.person, reasons)
            self._inner_fresh |= self._person.reacquired
        person = self._person.now(reasons)
        if not checks.pose_is_finite(obs.robot):
            stop = "robot_pose_invalid"
        elif person is None:
            stop = "reacquiring" if self._person.reacquiring else "person_lost"
        obstacles = tuple(ob for ob in obs.obstacles if checks.obstacle_is_finite(ob))
        if len(obstacles) < len(obs.obstacles):
            reasons.append("obstacle_invalid")
        if not stop and checks.obstacle_inside(obs.robot, obstacles, p.robot.radius):
            stop = "obstacle_in_footprint"
        if not stop and obs.scan is not None:
            stop = checks.scan_fault(obs.scan, p, reasons)

        stepped = False
        target = (*self._prev, 0.0)
        if not stop and fresh:
            if self._inner_fresh:
                self.inner.reset()
                self._inner_fresh = False
            cmd = self.inner.step(Observation(self._clock.now, obs.robot, person, obstacles,
                                              obs.scan))
            if checks.finite(cmd.v, cmd.omega, cmd.u_ob):
                stepped, target = True, (cmd.v, cmd.omega, cmd.u_ob)
            else:
                stop = "controller_fault"
        if stop:
            target = (0.0, 0.0, 0.0)
            self._inner_fresh = True
        else:
            target = keep_out(target, obs.robot, person, obstacles, self._prev, p, reasons)
        self._prev = limit(target[:2], self._prev, p)
        final = Command(*self._prev, target[2])
        if stepped:
            self.inner.applied(final)
        status = STOPPED if stop else DEGRADED if reasons else OK
        reason = "+".join(dict.fromkeys([stop] * bool(stop) + reasons))
        return Command(final.v, final.omega, final.u_ob, status, reason)

    def applied(self, cmd: Command) -> None:
        """Told the command the robot executes outside a step (its velocity at the start of an
        episode): the rate limits start from it."""
        if checks.finite(cmd.v, cmd.omega):
            r = self.params.robot
            self._prev = (min(max(cmd.v, -r.v_max), r.v_max),
                          min(max(cmd.omega, -r.omega_max), r.omega_max))
            self.inner.applied(cmd)
