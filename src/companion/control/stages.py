"""The stages of the safety supervisor's step (docs/safety.md, "The pipeline").

Each stage is a small object made from the parameters it needs, called with the step's
typed context (:class:`Step`) and returning the reasons it raises; the pipeline
(:class:`~companion.control.supervisor.SafetySupervisor`) collects them. In order:

1. :class:`Clocking`: the observation's time, and whether its data are fresh;
2. :class:`Tracking`: the person from the detections (the tracker), the obstacles from the
   perception front end (:class:`~companion.perception.front_end.FrontEnd`);
3. :class:`InputChecks`: stale sources, the robot pose, a lost person, the footprint, the
   scan and the odometry; the first that fails stops the robot;
4. :class:`~companion.control.choice.Choosing`: what to do: follow (the formation's
   bearing), search for a lost person, rejoin round walls, or stop;
5. :class:`Driving`: the wrapped controller on a checked observation predicted to the moment
   its command takes effect;
6. :class:`Guarding`: the slot error report and the keep-out rules
   (:func:`~companion.control.keepout.keep_out`);
7. :class:`Limiting`: the rate and velocity limits.
"""

from __future__ import annotations

import dataclasses
import math

from companion.control import checks
from companion.control.base import Controller, saturate
from companion.control.delays import DelayMeter
from companion.control.keepout import keep_out
from companion.control.limits import limit
from companion.control.slot import reference_point, slot_point
from companion.geometry import speed_turn_std, unicycle_step, wrap_pi
from companion.params import Params
from companion.perception import checked_scan
from companion.perception.front_end import FrontEnd
from companion.tracking import PersonTracker, exact_detection, predict
from companion.types import (
    Command,
    Observation,
    Obstacle,
    PersonDetection,
    PersonEstimate,
    Pose,
    Scan,
)


@dataclasses.dataclass(slots=True)
class Step:
    """The context of one step, filled in by the stages in order."""

    obs: Observation
    params: Params                         # in force (the formation's bearing)
    prev: tuple[float, float]              # the last command sent
    t: float = 0.0                         # the clock's time
    now: float = 0.0                       # the sensor clock: the last valid time
    fresh: bool = True                     # the observation's data are used
    restart: bool = False                  # the controller's filters start fresh
    stop: str = ""                         # why the robot brakes to a stop ("" if not)
    estimate: PersonEstimate | None = None
    lost: bool = False                     # lost, and a search may look for the person
    obstacles: tuple[Obstacle, ...] = ()
    scan: Scan | None = None               # checked
    velocity: tuple[float, float] = (0.0, 0.0)
    measured: bool = False                 # velocity from odometry, not the last command
    odometry: str = ""                     # the odometry sample's fault
    manoeuvre: tuple[float, float, str] | None = None   # a search's or rejoin's command
    run: Params | None = None              # params with the measured delays
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    stepped: bool = False                  # the controller made the target
    requested: tuple[float, float] | None = None


class Clocking:
    """The time between calls (:class:`~companion.control.checks.Clock`): a step that is not
    forward discards the data; a gap restarts the controller."""

    def __init__(self, params: Params):
        self.dt = params.dt
        self.clock = checks.Clock(params.dt, params.supervisor.max_step_ratio)
        self.reset()

    def reset(self) -> None:
        self.clock.reset()
        self.sensor_t = 0.0

    def __call__(self, s: Step) -> list[str]:
        _, state = self.clock.tick(s.obs.t)
        s.fresh = state != "clock"
        self.sensor_t = s.obs.t if s.fresh else self.sensor_t + self.dt
        s.t, s.now, s.restart = self.clock.now, self.sensor_t, state != "ok"
        return [] if state == "ok" else [state]


class Tracking:
    """The person (the tracker, the one place that decides whether the person is seen,
    predicted or lost) and the obstacles (the front end)."""

    def __init__(self, params: Params, delays: DelayMeter):
        self.params, self.delays = params, delays
        self.tracker = PersonTracker(params.tracker, params.sensing)
        self.front = FrontEnd(params)

    def reset(self) -> None:
        self.tracker.reset()
        self.front.reset()

    def __call__(self, s: Step) -> list[str]:
        obs, reasons = s.obs, []
        if s.fresh:
            self.front.odometry.add(obs.t, obs.robot, obs.robot_velocity)
            self.tracker.add(self._detections(obs), obs.t, self.front.odometry.pose_at, reasons)
            self.front.people.update(self.tracker.others)
            self.delays.detections(obs.detections, obs.t)
            s.restart |= self.tracker.reacquired
        s.estimate = self.tracker.estimate(s.now, reasons)
        known = obs.obstacles
        if known:
            known = tuple(ob for ob in known if checks.obstacle_is_finite(ob))
            if len(known) < len(obs.obstacles):
                reasons.append("obstacle_invalid")
        s.obstacles = self.front.obstacles(known, obs.scan, s.estimate, s.now)
        return reasons

    def _detections(self, obs: Observation) -> tuple[PersonDetection, ...]:
        """The observation's detections; a ``person`` given is an exact detection now."""
        if obs.person is None:
            return obs.detections
        return (*obs.detections,
                exact_detection(obs.t, obs.person, self.params.tracker.world_frame))


class InputChecks:
    """The inputs that stop the robot, first one wins: stale sources, an invalid robot pose,
    a lost person (unless a search may look), an obstacle in the footprint, an invalid scan,
    odometry invalid for longer than ``supervisor.odometry_timeout_s``; and the velocity the
    robot moves at (odometry if plausible, else the last command)."""

    def __init__(self, params: Params, tracker: PersonTracker, delays: DelayMeter):
        self.params, self.tracker, self.delays = params, tracker, delays
        self.odometry = checks.Odometry(params.robot)
        self.reset()

    def reset(self) -> None:
        self.odometry.reset()
        self.bad_since: float | None = None      # odometry invalid since

    def __call__(self, s: Step) -> list[str]:
        obs, p, reasons = s.obs, s.params, []
        if obs.stale:
            s.stop = "+".join(f"{source}_stale" for source in obs.stale)
        elif not checks.pose_is_finite(obs.robot):
            s.stop = "robot_pose_invalid"
        if not s.stop and s.estimate is None:
            if self.tracker.reacquiring:
                s.stop = "reacquiring"
            elif p.search.max_time_s > 0.0:
                s.lost = True
            else:
                s.stop = "person_lost"
        if not s.stop and checks.obstacle_inside(obs.robot, s.obstacles, p.robot.radius):
            s.stop = "obstacle_in_footprint"
        s.scan = None if obs.scan is None else checked_scan(obs.scan, p.lidar.range_max)
        if not s.stop and obs.scan is not None:
            s.stop = "scan_invalid" if s.scan is None else checks.scan_fault(s.scan, p, reasons)
        s.odometry = self.odometry.check(obs.t, obs.robot)
        reasons += self._velocity(s)
        if not s.stop and self.bad_since is not None \
                and s.now - self.bad_since > p.supervisor.odometry_timeout_s:
            s.stop = "odometry_lost"
        if s.fresh:
            self.delays.motion(obs.t if obs.robot_stamp is None else obs.robot_stamp,
                               s.velocity if s.measured else None)
        s.restart |= bool(s.odometry)
        return reasons

    def _velocity(self, s: Step) -> list[str]:
        """Odometry's velocity if the sample is plausible (its time advances, its pose does
        not jump) and finite and at most twice the velocity limits, else the last command;
        an invalid sample is reported and counts as missing (the timeout stops the robot)."""
        v, r = s.obs.robot_velocity, self.params.robot
        s.velocity, s.measured = s.prev, False
        if not s.odometry and v is None:
            self.bad_since = None
            return []
        if not s.odometry and checks.finite(*v) and abs(v[0]) <= 2.0 * r.v_max \
                and abs(v[1]) <= 2.0 * r.omega_max:
            self.bad_since = None
            s.velocity, s.measured = v, True
            return []
        if self.bad_since is None:
            self.bad_since = s.now
        return [s.odometry or "odometry_invalid"]


class Driving:
    """The wrapped controller: reset before its first step after anything that makes its
    filters' memory wrong (a clock fault, odometry fault, re-acquired person, stop or
    manoeuvre), then stepped on the observation predicted ``tau`` s on (the actuator lag)."""

    def __init__(self, inner: Controller):
        self.inner = inner
        self.reset()

    def reset(self) -> None:
        self.inner.reset()
        self.fresh = False

    def __call__(self, s: Step) -> list[str]:
        self.fresh |= s.restart or s.manoeuvre is not None or bool(s.stop)
        s.target = (*s.prev, 0.0)
        if s.manoeuvre is not None:
            s.target = (s.manoeuvre[0], s.manoeuvre[1], 0.0)
            return ["person_lost", s.manoeuvre[2]] if s.lost else [s.manoeuvre[2]]
        if s.stop or not s.fresh or s.odometry:
            return []
        if self.fresh:
            self.inner.reset()
            self.fresh = False
        cmd = self.inner.step(self._ahead(s))
        if checks.finite(cmd.v, cmd.omega, cmd.u_ob):
            s.stepped, s.target = True, (cmd.v, cmd.omega, cmd.u_ob)
        else:
            s.stop, self.fresh = "controller_fault", True
        return []

    def applied(self, s: Step, final: Command) -> None:
        """Tell the controller the command sent, if it made this step's target."""
        if s.stepped:
            self.inner.applied(final)

    def _ahead(self, s: Step) -> Observation:
        obs, person = s.obs, s.estimate.walker
        robot, tau = obs.robot, s.run.sensing.actuator_tau_s
        if tau > 0.0:
            x, y, th = unicycle_step(robot.x, robot.y, robot.theta, *s.velocity, tau)
            robot, person = Pose(x, y, wrap_pi(th)), predict(person, tau)
        f = s.params.formation
        return Observation(s.t, robot, person, s.obstacles, s.scan, s.velocity,
                           formation=(f.distance, f.bearing),
                           person_std=speed_turn_std(s.estimate.covariance, person.theta))


class Guarding:
    """The slot error report (above ``supervisor.slot_error_m`` for
    ``slot_error_time_s``) and the keep-out rules on whatever command is to be sent."""

    def __init__(self, params: Params):
        self.params = params
        self.reset()

    def reset(self) -> None:
        self.far_since: float | None = None     # the slot error is large since

    def __call__(self, s: Step) -> list[str]:
        if s.stop:
            s.target, self.far_since = (0.0, 0.0, 0.0), None
            return []
        reasons = [] if s.lost else self._slot(s)
        if s.stepped:
            s.requested = limit(s.target[:2], s.prev, s.params)
        s.target = keep_out(s.target, s.obs.robot, s.estimate, s.obstacles, s.velocity,
                            s.run, reasons, s.prev)
        return reasons

    def _slot(self, s: Step) -> list[str]:
        lim = self.params.supervisor
        rx, ry = reference_point(s.obs.robot, self.params.robot.d)
        sx, sy = slot_point(s.estimate.walker, s.params)
        if math.hypot(rx - sx, ry - sy) <= lim.slot_error_m:
            self.far_since = None
            return []
        if self.far_since is None:
            self.far_since = s.now
        return ["slot_error"] if s.now - self.far_since >= lim.slot_error_time_s else []


class Limiting:
    """The rate and velocity limits (:func:`~companion.control.limits.limit`) from the last
    command sent; before the first, from the measured velocity (or :meth:`start`)."""

    def __init__(self, params: Params):
        self.params = params
        self.reset()

    def reset(self) -> None:
        self.prev = (0.0, 0.0)
        self.started = False

    def start(self, v: float, omega: float) -> None:
        self.prev, self.started = saturate(v, omega, self.params.robot), True

    def __call__(self, s: Step) -> Command:
        self.prev = limit(s.target[:2], self.prev, s.params)
        return Command(*self.prev, s.target[2])
