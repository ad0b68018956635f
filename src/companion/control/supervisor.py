"""Safety supervisor: the last layer between any controller and the motors (docs/safety.md).

It is the only layer that accepts raw sensor data and the outermost one of the standard stack.
Its output is finite, within the velocity limits and within the acceleration limits (one
period ``dt`` per call), whatever the input, and carries a status (``ok``, ``degraded``: a
fault is handled and the robot moves, ``stopped``: it brakes to a stop and holds), a reason
and the person estimate. Per call:

1. clock (:class:`~companion.control.checks.Clock`);
2. the person: detections to the tracker (:class:`~companion.tracking.PersonTracker`), the
   one place that decides whether the person is seen, predicted or lost (the detections it
   takes for other people are tracked as moving obstacles); a lost person
   means a controlled stop, then (``search.max_time_s`` > 0) a search
   (:class:`~companion.control.search.Search`);
3. robot pose, obstacles and scan (:mod:`companion.control.checks`);
4. the wrapped controller, on a checked observation predicted to the moment its command takes
   effect (the actuator lag on), the same for every controller;
5. keep-out rules, with the protective distance grown by the person's uncertainty, the last
   of them checking the command as the rate limits will send it against the last command
   (:func:`companion.control.keepout.keep_out`); while searching for a lost person, giving
   way to walkers and the stop path only;
6. rate and velocity limits (:func:`companion.control.limits.limit`); a stopped robot's target
   is zero, so it brakes at the limits.

Steps 4 and 5 use the detection latency and actuator lag measured by
:class:`~companion.control.delays.DelayMeter` (``supervisor.delays``), not the declared ones.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Callable

from companion.control import checks
from companion.control.base import Controller, saturate
from companion.control.delays import DelayMeter
from companion.control.formation import FormationPolicy
from companion.control.keepout import keep_out
from companion.control.limits import limit
from companion.control.rejoin import Rejoin
from companion.control.search import Search
from companion.control.slot import reference_point, slot_point
from companion.geometry import unicycle_step, wrap_pi
from companion.params import Params
from companion.perception import MovingTracker, checked_scan
from companion.tracking import PersonTracker, Reidentify, exact_detection, predict
from companion.types import (
    Circle,
    Command,
    Observation,
    PersonDetection,
    PersonEstimate,
    Pose,
    Scan,
)

OK, DEGRADED, STOPPED = "ok", "degraded", "stopped"


class SafetySupervisor:
    """Wraps any controller; see the module docstring."""

    #: The simulator hands this layer the raw person detections (it tracks the person).
    takes_detections = True

    def __init__(self, inner: Controller, params: Params,
                 rebuild: Callable[[Params], Controller] | None = None):
        self.inner = inner
        self.params = params
        self._configured = params     # the parameters as given; ``params``: those in force
        self._rebuild = rebuild       # the inner controller for other parameters
        self._formation = FormationPolicy(params)
        self._clock = checks.Clock(params.dt, params.supervisor.max_step_ratio)
        self._odometry = checks.Odometry(params.robot)
        self._tracker = PersonTracker(params.tracker, params.sensing)
        self._others = MovingTracker(params.movers)   # the other people detected
        self.delays = DelayMeter(params)
        self._search = Search(params)
        self._rejoin = Rejoin(params)
        self.reset()

    def reset(self) -> None:
        if self.params is not self._configured and self._rebuild is not None:
            self.inner, self.params = self._rebuild(self._configured), self._configured
            self._search.params = self._rejoin.params = self.params
        self._formation.reset()
        self._rejoin.reset()
        self.inner.reset()
        self._inner_fresh = False     # inner must be reset before its next step
        self._prev = (0.0, 0.0)       # last output (v, omega)
        self._started = False         # _prev is known (a measured velocity, or applied())
        self._odometry_bad_since: float | None = None       # odometry invalid since
        self._clock.reset()
        self._odometry.reset()
        self._tracker.reset()
        self._others.reset()
        self.delays.reset()
        self._sensor_t = 0.0          # the sensor clock: the last valid time, periods counted on
        self._poses: deque[tuple[float, Pose]] = deque()   # for robot-frame detections
        self._far_since: float | None = None               # the slot error is large since
        self._last: PersonEstimate | None = None           # the last estimate of the person
        self._search.reset()

    def step(self, obs: Observation) -> Command:
        p = self.params
        reasons: list[str] = []
        stop = ""
        _, clock = self._clock.tick(obs.t)
        if clock != "ok":
            reasons.append(clock)
            self._inner_fresh = True
        fresh = clock != "clock"   # a zero, negative or non-finite step discards the data
        if fresh:
            self._sensor_t = obs.t
            self._remember(obs.t, obs.robot)
            self._tracker.add(self._detections(obs), obs.t, self._pose_at, reasons)
            self._track_others(self._tracker.others)
            self.delays.detections(obs.detections, obs.t)
            self._inner_fresh |= self._tracker.reacquired
        else:
            self._sensor_t += p.dt
        estimate = self._tracker.estimate(self._sensor_t, reasons)
        if obs.stale:
            stop = "+".join(f"{source}_stale" for source in obs.stale)
        elif not checks.pose_is_finite(obs.robot):
            stop = "robot_pose_invalid"
        lost = False
        if not stop and estimate is None:
            if self._tracker.reacquiring:
                stop = "reacquiring"
            elif p.search.max_time_s > 0.0:
                lost = True           # the other checks first; then stop or search below
            else:
                stop = "person_lost"
        obstacles = tuple(ob for ob in obs.obstacles if checks.obstacle_is_finite(ob))
        if len(obstacles) < len(obs.obstacles):
            reasons.append("obstacle_invalid")
        obstacles += self._others.circles(self._sensor_t)
        if estimate is not None:
            self._last = estimate
            self._search.reset()
            self._rejoin.record(estimate.walker)
            if not stop and p.formation.policy == "adaptive" and self._rebuild is not None:
                bearing = self._formation.update(obs.robot, estimate.walker, obstacles)
                if bearing != p.formation.bearing:
                    p = self._switch(bearing)
        if not stop and checks.obstacle_inside(obs.robot, obstacles, p.robot.radius):
            stop = "obstacle_in_footprint"
        scan = None if obs.scan is None else checked_scan(obs.scan, p.lidar.range_max)
        if not stop and obs.scan is not None:
            stop = "scan_invalid" if scan is None else checks.scan_fault(scan, p, reasons)
        odometry = self._odometry.check(obs.t, obs.robot)   # a fault: missing odometry
        velocity, measured = self._velocity(obs, reasons, odometry)
        if not stop and self._odometry_bad_since is not None \
                and self._sensor_t - self._odometry_bad_since > p.supervisor.odometry_timeout_s:
            stop = "odometry_lost"
        if fresh:
            self.delays.motion(obs.t if obs.robot_stamp is None else obs.robot_stamp,
                               velocity if measured else None)
        if measured and not self._started:   # rate limits start from the measured velocity
            self._prev, self._started = saturate(*velocity, self.params.robot), True
        manoeuvre = None      # (v, omega, reason) of a search or a rejoin: not the controller
        if lost and not stop:
            manoeuvre = self._searching(obs, obstacles, velocity) if fresh else None
            stop = "" if manoeuvre is not None else "person_lost"
        elif not stop and fresh and estimate is not None and p.formation.policy == "adaptive":
            way = self._rejoin.target(obs.robot, estimate.walker, slot_point(estimate.walker, p),
                                      obstacles, velocity[0])
            manoeuvre = None if way is None else (*way, "rejoin")
        run = self.delays.params(p) if p.supervisor.delays == "measured" else p

        stepped = False
        target = (*self._prev, 0.0)
        if odometry:
            self._inner_fresh = True  # the controller's filters knew the pose before it
        if manoeuvre is not None:
            target = (manoeuvre[0], manoeuvre[1], 0.0)
            reasons += ["person_lost", manoeuvre[2]] if lost else [manoeuvre[2]]
            self._inner_fresh = True      # the controller's filters knew the person before
        elif not stop and fresh and not odometry:
            if self._inner_fresh:
                self.inner.reset()
                self._inner_fresh = False
            cmd = self.inner.step(self._ahead(obs, estimate, obstacles, scan, velocity,
                                              run.sensing.actuator_tau_s))
            if checks.finite(cmd.v, cmd.omega, cmd.u_ob):
                stepped, target = True, (cmd.v, cmd.omega, cmd.u_ob)
            else:
                stop = "controller_fault"
        requested = None
        if stop:
            target = (0.0, 0.0, 0.0)
            self._inner_fresh = True
            self._far_since = None    # a stop restarts the slot-error clock
        else:          # the keep-out: the controller's, a rejoin's or (lost) a search's
            if not lost:
                self._check_slot(obs.robot, estimate, reasons)
            if stepped:
                requested = limit(target[:2], self._prev, p)
            target = keep_out(target, obs.robot, estimate, obstacles, velocity, run, reasons,
                              self._prev)
        self._prev = limit(target[:2], self._prev, p)
        if fresh:
            self.delays.sent(obs.t, self._prev)
        final = Command(*self._prev, target[2])
        if stepped:
            self.inner.applied(final)
        status = STOPPED if stop else DEGRADED if reasons else OK
        reason = "+".join(dict.fromkeys([stop] * bool(stop) + reasons))
        return Command(final.v, final.omega, final.u_ob, status, reason, estimate, requested,
                       p.formation.bearing)

    def applied(self, cmd: Command) -> None:
        """Told the command the robot executes outside a step (its velocity at the start of an
        episode): the rate limits start from it."""
        if checks.finite(cmd.v, cmd.omega):
            self._prev, self._started = saturate(cmd.v, cmd.omega, self.params.robot), True
            self.inner.applied(cmd)

    def retune(self, inner: Controller, params: Params) -> None:
        """Run on with new parameters (a formation, limits or gains changed while running) and
        ``inner`` made with them: the tracker, the clock and the last command stay, so the rate
        limits carry the robot from its last command towards the new slot; ``inner`` starts
        fresh at the next step. Parameters of the clock and tracker must not change."""
        moved = params.formation.bearing != self._configured.formation.bearing
        self.inner, self.params, self._configured = inner, params, params
        self._formation = FormationPolicy(params, given=moved)
        self._search.params = self._rejoin.params = params
        self._odometry.robot = params.robot
        self._inner_fresh = True
        self._far_since = None

    @property
    def reidentify(self) -> Reidentify | None:
        """The re-identification hook of the person tracker (:data:`Reidentify`): after a
        loss, a detection is the person where it returns True, is not where False, and the
        tracker's prediction decides where None (or no hook)."""
        return self._tracker.reidentify

    @reidentify.setter
    def reidentify(self, hook: Reidentify | None) -> None:
        self._tracker.reidentify = hook

    # -- the pieces -----------------------------------------------------------------------

    def _track_others(self, others: list[PersonDetection]) -> None:
        """The other people on the person topic (detections the tracker's gate kept out), as
        moving obstacles (:class:`~companion.perception.MovingTracker`)."""
        r = self.params.movers.person_radius
        for t in sorted({d.t for d in others}):
            self._others.update([Circle(d.x, d.y, r) for d in others if d.t == t], t)

    def _switch(self, bearing: float) -> Params:
        """Put the formation's ``bearing`` in force (the adaptive policy chose the other
        side): the inner controller is made anew for it and starts fresh; the rate limits
        carry the robot on from its last command."""
        f = self._configured.formation
        self.params = self._configured.replace(formation=dataclasses.replace(f, bearing=bearing))
        self.inner = self._rebuild(self.params)
        self._search.params = self._rejoin.params = self.params
        self._inner_fresh = True
        return self.params

    def _searching(self, obs: Observation, obstacles: tuple, velocity: tuple[float, float]
                   ) -> tuple[float, float, str] | None:
        """The search's command for a lost person (None: stop and hold): it begins once the
        controlled stop has brought the robot to rest."""
        s = self.params.search
        if s.max_time_s <= 0.0 or self._last is None or self._search.over:
            return None
        if not self._search.active:
            if abs(self._prev[0]) > 0.05 or abs(self._prev[1]) > 0.1:
                return None                   # the controlled stop first
            self._search.begin(obs.t, obs.robot, self._last)
        return self._search.target(obs.t, obs.robot, obstacles, velocity[0])

    def _detections(self, obs: Observation) -> tuple[PersonDetection, ...]:
        """The observation's detections; a ``person`` given is an exact detection now."""
        if obs.person is None:
            return obs.detections
        return (*obs.detections,
                exact_detection(obs.t, obs.person, self.params.tracker.world_frame))

    def _remember(self, t: float, robot: Pose) -> None:
        if checks.pose_is_finite(robot):
            self._poses.append((t, robot))
        while self._poses and self._poses[0][0] < t - self.params.tracker.max_delay_s - 1.0:
            self._poses.popleft()

    def _pose_at(self, t: float) -> Pose:
        """The robot pose at time ``t``: the last one known at or before it."""
        at = self._poses[0][1] if self._poses else Pose(math.nan, math.nan, math.nan)
        for time, pose in self._poses:
            if time > t:
                break
            at = pose
        return at

    def _velocity(self, obs: Observation, reasons: list[str], fault: str
                  ) -> tuple[tuple[float, float], bool]:
        """The robot's velocity and whether it was measured: odometry if the sample is
        plausible (``fault`` empty: its time advances and its pose does not jump) and its
        velocity is finite and at most twice the velocity limits, else the last command; an
        invalid sample is reported and counts as missing (the timeout stops the robot)."""
        v, r = obs.robot_velocity, self.params.robot
        if not fault and v is None:
            self._odometry_bad_since = None
            return self._prev, False
        if not fault and checks.finite(*v) and abs(v[0]) <= 2.0 * r.v_max \
                and abs(v[1]) <= 2.0 * r.omega_max:
            self._odometry_bad_since = None
            return v, True
        reasons.append(fault or "odometry_invalid")
        if self._odometry_bad_since is None:
            self._odometry_bad_since = self._sensor_t
        return self._prev, False

    def _ahead(self, obs: Observation, estimate: PersonEstimate, obstacles: tuple,
               scan: Scan | None, velocity: tuple[float, float], tau: float) -> Observation:
        """What the controller gets: robot and person predicted ``tau`` s on (the actuator
        lag), the moment a command sent now mostly takes effect."""
        robot, person = obs.robot, estimate.walker
        if tau > 0.0:
            x, y, th = unicycle_step(robot.x, robot.y, robot.theta, *velocity, tau)
            robot, person = Pose(x, y, wrap_pi(th)), predict(person, tau)
        return Observation(self._clock.now, robot, person, obstacles, scan, velocity)

    def _check_slot(self, robot: Pose, estimate: PersonEstimate, reasons: list[str]) -> None:
        """Report a slot error above ``slot_error_m`` that lasts ``slot_error_time_s``."""
        s = self.params.supervisor
        rx, ry = reference_point(robot, self.params.robot.d)
        sx, sy = slot_point(estimate.walker, self.params)
        if math.hypot(rx - sx, ry - sy) <= s.slot_error_m:
            self._far_since = None
            return
        if self._far_since is None:
            self._far_since = self._sensor_t
        if self._sensor_t - self._far_since >= s.slot_error_time_s:
            reasons.append("slot_error")
