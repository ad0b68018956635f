"""Safety supervisor: the last layer between any controller and the motors.

:class:`SafetySupervisor` wraps a :class:`~companion.control.base.Controller` (in the standard
stack, the avoidance layer around it). It is the only layer that accepts raw sensor data, and
it guarantees that its output is finite, within ``robot.v_max`` / ``robot.omega_max`` and within
the acceleration limits of ``supervisor`` (one sample period ``dt`` per call), whatever the
input. Each command carries a status, ``ok``, ``degraded`` (the robot moves, with a fault
handled) or ``stopped`` (it brakes to a stop and holds), and a reason. docs/safety.md lists
every fault, its behaviour, its parameters and its test.

Per call, in this order:

1. **Clock.** The step from the last observation's time must be in ``(0, max_step_ratio * dt]``.
   A zero, negative or non-finite step is a clock fault: the observation is discarded, the
   last command is held and one period is counted. A longer step is accepted (the data are
   real) but the wrapped controller's filters are reset. Nothing integrates over the measured
   step: the controllers integrate over ``dt`` and the rate limits act per call.
2. **Robot pose.** Not finite: stop (``robot_pose_invalid``).
3. **Person.** An estimate that is missing or not finite is skipped; one farther from the
   last accepted estimate than ``max_person_speed`` times the time since then (plus
   ``jump_tolerance``) is an outlier (identity switch) and is skipped. While the last accepted
   estimate is younger than ``person_timeout`` the controller gets it predicted forward at
   constant speed and turn rate (``degraded``); after that the person is lost: stop and hold
   (``person_lost``), never driving on towards the last known point. To follow again, the
   estimates must agree with each other (same gate) for ``reacquire_time`` (``reacquiring``).
4. **Obstacles and scan.** Obstacles with non-finite fields are dropped (``obstacle_invalid``).
   An obstacle inside the footprint, a LiDAR return closer than the footprint radius, or a
   scan with fewer than ``min_valid_returns`` valid (non-NaN) beams: stop. Invalid returns
   are never taken as free space.
5. **Controller.** The wrapped controller gets a checked observation. A non-finite output
   stops the robot (``controller_fault``) and resets the controller.
6. **Keep-out.** Inside ``protective_distance`` of the person the robot may only rotate or
   move away (``protective_zone``). Outside it, and towards obstacles, the speed of approach is
   limited to what braking at the deceleration limit can still stop before the protective
   distance (the person) or :data:`CONTACT_MARGIN` short of contact (obstacles), counting one
   period of delay; an evasive check replaces commands predicted to come too close.
7. **Rate limits** towards the target (the controller's command, or zero when stopped), then
   the velocity limits. A stopped robot therefore brakes at ``decel_max`` and
   ``angular_accel_max``, and a resuming one ramps up: no jump beyond the limits.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numba import njit

from companion.control.base import Command, Controller, Observation, PersonState, Pose
from companion.control.safety import clip_to, obstacle_normals, person_normal, speed_bound
from companion.obstacles import Circle, Obstacle
from companion.params import Params
from companion.perception import Scan

OK, DEGRADED, STOPPED = "ok", "degraded", "stopped"

#: Clearance (m) short of contact at which the braking bound towards obstacles stops the robot.
CONTACT_MARGIN = 0.02


def _finite(*values: float) -> bool:
    return all(math.isfinite(x) for x in values)


def pose_is_finite(pose: Pose) -> bool:
    return _finite(pose.x, pose.y, pose.theta)


def person_is_finite(person: PersonState) -> bool:
    return _finite(person.x, person.y, person.theta, person.v, person.omega)


def obstacle_is_finite(ob: Obstacle) -> bool:
    """All fields finite (an unset ``influence`` is fine), a circle's radius >= 0."""
    influence = () if ob.influence is None else (ob.influence,)
    if isinstance(ob, Circle):
        return _finite(ob.x, ob.y, ob.radius, *influence) and ob.radius >= 0.0
    return _finite(ob.x0, ob.y0, ob.x1, ob.y1, *influence)


def limit_rate(target: float, prev: float, grow: float, shrink: float, dt: float) -> float:
    """The value closest to ``target`` reachable from ``prev`` in ``dt`` when ``|x|`` may grow
    at most at rate ``grow`` and shrink at most at rate ``shrink`` (crossing zero: shrink to
    0 first, then grow for the rest of the period)."""
    if prev < 0.0:
        return -limit_rate(-target, -prev, grow, shrink, dt)
    hi = prev + grow * dt
    to_zero = prev / shrink
    lo = prev - shrink * dt if to_zero >= dt else -grow * (dt - to_zero)
    return min(max(target, lo), hi)


def braking_speed(gap: float, decel: float, dt: float) -> float:
    """Largest closing speed from which a robot that reacts one period ``dt`` late and then
    decelerates at ``decel`` stops within ``gap``: the root of ``v dt + v^2 / (2 decel) = gap``
    (0 for ``gap <= 0``)."""
    if gap <= 0.0:
        return 0.0
    ad = decel * dt
    return math.sqrt(ad * ad + 2.0 * decel * gap) - ad


def predict_pose(x: float, y: float, theta: float, v: float, omega: float, tau: float
                 ) -> tuple[float, float, float]:
    """Pose ``tau`` seconds on at constant speed ``v`` and turn rate ``omega`` (exact unicycle
    arc); the heading is not wrapped. Plain math: also compiled, as :data:`_predict_pose_nb`."""
    th = theta + omega * tau
    if abs(omega * tau) < 1e-9:
        s = v * tau
        return x + s * math.cos(theta), y + s * math.sin(theta), th
    r = v / omega
    return x + r * (math.sin(th) - math.sin(theta)), y - r * (math.cos(th) - math.cos(theta)), th


def predict(person: PersonState, tau: float) -> PersonState:
    """The person ``tau`` seconds on at constant speed and turn rate (exact unicycle arc)."""
    x, y, th = predict_pose(person.x, person.y, person.theta, person.v, person.omega, tau)
    return PersonState(x, y, math.remainder(th, 2.0 * math.pi), person.v, person.omega)


def valid_fraction(scan: Scan) -> float:
    """Share of the scan's beams that are not NaN (0 for an empty scan). ``inf`` (nothing
    within range) and ``-inf`` (closer than the sensor's minimum) are valid, as in ROS REP 117."""
    n = scan.ranges.size
    return 0.0 if n == 0 else float(n - np.count_nonzero(np.isnan(scan.ranges))) / n


def too_close(scan: Scan, radius: float) -> bool:
    """A valid return (``-inf`` included) closer than ``radius`` to the sensor."""
    r = scan.ranges
    return bool(np.any(r[~np.isnan(r)] < radius))


#: Candidate targets of the evasive check: fractions of v_max and omega_max.
_V_GRID = np.linspace(-1.0, 1.0, 7)
_W_GRID = np.linspace(-1.0, 1.0, 5)


def obstacle_clearances(x: np.ndarray, y: np.ndarray, obstacles: Sequence[Obstacle],
                        radius: float) -> np.ndarray:
    """Smallest clearance from footprints of ``radius`` at the points ``(x, y)`` to the
    obstacles (``inf`` without obstacles), elementwise."""
    out = np.full(np.shape(x), np.inf)
    for ob in obstacles:
        if isinstance(ob, Circle):
            gap = np.hypot(x - ob.x, y - ob.y) - ob.radius
        else:
            ex, ey = ob.x1 - ob.x0, ob.y1 - ob.y0
            length2 = ex * ex + ey * ey
            u = 0.0 if length2 == 0.0 else np.clip(((x - ob.x0) * ex + (y - ob.y0) * ey)
                                                   / length2, 0.0, 1.0)
            gap = np.hypot(x - ob.x0 - u * ex, y - ob.y0 - u * ey)
        out = np.minimum(out, gap - radius)
    return out


#: Speed (m/s) up to which a person is assumed to be able to speed up (brisk walking).
BRISK_WALK = 1.5


def speed_up_distance(v: float, accel: float, t: float) -> float:
    """Extra distance (m) a person walking at ``v`` covers in ``t`` s by speeding up at
    ``accel`` until :data:`BRISK_WALK` (none if already faster)."""
    if accel <= 0.0 or v >= BRISK_WALK:
        return 0.0
    t_up = min(t, (BRISK_WALK - v) / accel)
    return 0.5 * accel * t_up * t_up + accel * t_up * (t - t_up)


_predict_pose_nb = njit(cache=True, error_model="numpy")(predict_pose)
_speed_up_distance_nb = njit(cache=True, error_model="numpy")(speed_up_distance)


@njit(cache=True, error_model="numpy")
def _rollout_nb(x0, y0, th0, v0, w0, targets, px, py, pth, pv, pw, person_accel, protective,
                circles, walls, radius, v_rate, w_rate, step, n_steps, out):
    """Body of :func:`rollout_margins`; ``circles`` rows (x, y, r), ``walls`` rows
    (x0, y0, x1, y1); ``out`` receives the margins."""
    hx = np.empty(n_steps)
    hy = np.empty(n_steps)
    for k in range(n_steps):
        t = (k + 1) * step
        qx, qy, _ = _predict_pose_nb(px, py, pth, pv, pw, t)
        extra = _speed_up_distance_nb(pv, person_accel, t)
        hx[k] = qx + extra * math.cos(pth)
        hy[k] = qy + extra * math.sin(pth)
    for i in range(targets.shape[0]):
        x, y, th = x0, y0, th0
        margin = np.inf
        for k in range(n_steps):
            t = (k + 1) * step
            v = v0 + min(max(targets[i, 0] - v0, -v_rate * t), v_rate * t)
            w = w0 + min(max(targets[i, 1] - w0, -w_rate * t), w_rate * t)
            x = x + step * v * math.cos(th + 0.5 * step * w)
            y = y + step * v * math.sin(th + 0.5 * step * w)
            th = th + step * w
            margin = min(margin, math.hypot(x - hx[k], y - hy[k]) - protective)
            for c in range(circles.shape[0]):
                gap = math.hypot(x - circles[c, 0], y - circles[c, 1]) - circles[c, 2]
                margin = min(margin, gap - radius)
            for j in range(walls.shape[0]):
                ax, ay = walls[j, 0], walls[j, 1]
                ex, ey = walls[j, 2] - ax, walls[j, 3] - ay
                length2 = ex * ex + ey * ey
                u = 0.0
                if length2 > 0.0:
                    u = min(max(((x - ax) * ex + (y - ay) * ey) / length2, 0.0), 1.0)
                margin = min(margin, math.hypot(x - ax - u * ex, y - ay - u * ey) - radius)
        out[i] = margin


def obstacle_arrays(obstacles: Sequence[Obstacle]) -> tuple[np.ndarray, np.ndarray]:
    """Circles as rows (x, y, r) and walls as rows (x0, y0, x1, y1)."""
    circles = [(o.x, o.y, o.radius) for o in obstacles if isinstance(o, Circle)]
    walls = [(o.x0, o.y0, o.x1, o.y1) for o in obstacles if not isinstance(o, Circle)]
    return (np.array(circles, dtype=float).reshape(-1, 3),
            np.array(walls, dtype=float).reshape(-1, 4))


def rollout_margins(robot: Pose, current: tuple[float, float], targets: np.ndarray,
                    person: PersonState, obstacles: Sequence[Obstacle], params: Params,
                    horizon: float = 1.2, step: float = 0.1) -> np.ndarray:
    """Predicted safety margin of each candidate target ``(v, omega)`` (rows of ``targets``).

    The robot's velocity ramps from ``current`` to the target at the acceleration limits and
    the unicycle is integrated over ``horizon`` s; the person moves at constant speed and
    turn rate (:func:`predict`) plus the distance it could gain by speeding up at
    ``person_accel`` along its heading (:func:`speed_up_distance`). The margin is the
    smallest, over the horizon, of the distance to the person minus ``protective_distance``
    and the clearance to the obstacles (:func:`obstacle_clearances`). Compiled: about 2 us
    for the 36 candidates of :func:`evasive_target` without obstacles.
    """
    s = params.supervisor
    circles, walls = obstacle_arrays(obstacles)
    out = np.empty(len(targets))
    _rollout_nb(robot.x, robot.y, robot.theta, float(current[0]), float(current[1]),
                np.ascontiguousarray(targets, dtype=float), person.x, person.y, person.theta,
                person.v, person.omega, s.person_accel, s.protective_distance, circles, walls,
                params.robot.radius, min(s.accel_max, s.decel_max), s.angular_accel_max, step,
                int(round(horizon / step)), out)
    return out


def evasive_target(robot: Pose, current: tuple[float, float], nominal: tuple[float, float],
                   person: PersonState, obstacles: Sequence[Obstacle], params: Params,
                   needed: float = 0.05, comfort: float = 0.2) -> tuple[float, float] | None:
    """A replacement for the ``nominal`` target if its predicted margin
    (:func:`rollout_margins`) is below ``needed`` m, else None.

    The replacement is the grid target with the best score ``min(margin, comfort) - 0.02 *
    change``: margins count up to ``comfort`` m, and among equally safe targets the one
    closest to the nominal (``change``: distance in units of v_max and omega_max) wins.
    """
    r = params.robot
    grid = np.column_stack([np.repeat(_V_GRID, _W_GRID.size) * r.v_max,
                            np.tile(_W_GRID, _V_GRID.size) * r.omega_max])
    targets = np.vstack([np.array(nominal), grid])
    margin = rollout_margins(robot, current, targets, person, obstacles, params)
    if margin[0] >= needed:
        return None
    change = np.hypot((targets[:, 0] - nominal[0]) / r.v_max,
                      (targets[:, 1] - nominal[1]) / r.omega_max)
    best = int(np.argmax(np.minimum(margin, comfort) - 0.02 * change))
    return float(targets[best, 0]), float(targets[best, 1])


class SafetySupervisor:
    """Wraps any controller; see the module docstring. Its commands carry ``status`` and
    ``reason``."""

    def __init__(self, inner: Controller, params: Params):
        self.inner = inner
        self.params = params
        self.reset()

    def reset(self) -> None:
        self.inner.reset()
        self._inner_fresh = False     # inner must be reset before its next step
        self._prev = (0.0, 0.0)       # last output (v, omega)
        self._t_last: float | None = None
        self._now = 0.0               # monotonic time handed to the inner controller
        self._track: PersonState | None = None
        self._age = math.inf          # s since the track was last confirmed
        self._lost = False            # the person was lost: reacquisition needed
        self._candidate: PersonState | None = None
        self._candidate_age = 0.0     # s since the last candidate estimate
        self._candidate_span = 0.0    # s over which the candidates agreed

    # -- one call -------------------------------------------------------------------------

    def step(self, obs: Observation) -> Command:
        p = self.params
        reasons: list[str] = []
        stop = ""
        elapsed, clock = self._clock(obs.t)
        if clock != "ok":
            reasons.append(clock)
            self._inner_fresh = True
        self._age += elapsed
        self._candidate_age += elapsed
        fresh = clock != "clock"   # a zero, negative or non-finite step discards the data
        if not pose_is_finite(obs.robot):
            stop = "robot_pose_invalid"
        if fresh:
            self._update_person(obs.person, elapsed, reasons)
        person = self._person_now(reasons)
        if person is None and not stop:
            stop = "reacquiring" if self._candidate is not None and self._lost else "person_lost"
        obstacles = tuple(ob for ob in obs.obstacles if obstacle_is_finite(ob))
        if len(obstacles) < len(obs.obstacles):
            reasons.append("obstacle_invalid")
        if not stop and self._obstacle_inside(obs.robot, obstacles):
            stop = "obstacle_in_footprint"
        if not stop and obs.scan is not None:
            stop = self._scan_fault(obs.scan, reasons)

        cmd = Command(*self._prev)
        stepped = False
        if not stop and fresh and person is not None:
            if self._inner_fresh:
                self.inner.reset()
                self._inner_fresh = False
            clean = Observation(self._now, obs.robot, person, obstacles, obs.scan)
            cmd = self.inner.step(clean)
            stepped = True
            if not _finite(cmd.v, cmd.omega, cmd.u_ob):
                stop, stepped = "controller_fault", False
                self._inner_fresh = True
        if stop:
            target_v, target_w, u_ob = 0.0, 0.0, 0.0
            self._inner_fresh = True
        else:
            target_v, target_w, u_ob = cmd.v, cmd.omega, cmd.u_ob
            evade = None
            if self._closing(obs.robot, person):
                evade = evasive_target(obs.robot, self._prev, (target_v, target_w), person,
                                       obstacles, p)
            if evade is not None:
                (target_v, target_w), u_ob = evade, 0.0
                reasons.append("evasive")
            target_v = self._keep_out(target_v, obs.robot, person, obstacles, reasons)
        final = self._limit(target_v, target_w, u_ob)
        if stepped:
            self.inner.applied(final)
        status = STOPPED if stop else DEGRADED if reasons else OK
        reason = "+".join(dict.fromkeys([stop] * bool(stop) + reasons))
        return Command(final.v, final.omega, final.u_ob, status, reason)

    def applied(self, cmd: Command) -> None:
        """Told the command the robot is executing outside a step (its velocity at the start
        of an episode): the rate limits start from it."""
        if _finite(cmd.v, cmd.omega):
            r = self.params.robot
            self._prev = (min(max(cmd.v, -r.v_max), r.v_max),
                          min(max(cmd.omega, -r.omega_max), r.omega_max))
            self.inner.applied(cmd)

    # -- the pieces -----------------------------------------------------------------------

    def _clock(self, t: float) -> tuple[float, str]:
        """Time elapsed since the last call and ``"ok"``, ``"clock"`` (zero, negative or
        non-finite step: data discarded, one period counted) or ``"clock_gap"`` (a step longer
        than ``max_step_ratio * dt``: data kept, filters reset)."""
        dt = self.params.dt
        if not math.isfinite(t):
            self._now += dt
            return dt, "clock"
        if self._t_last is None:
            self._t_last, self._now = t, t
            return 0.0, "ok"
        step = t - self._t_last
        self._t_last = t
        if step <= 0.0:
            self._now += dt
            return dt, "clock"
        self._now += step
        if step > self.params.supervisor.max_step_ratio * dt:
            return step, "clock_gap"
        return step, "ok"

    def _gate(self, ref: PersonState, new: PersonState, elapsed: float) -> bool:
        """True if ``new`` is a plausible successor of ``ref`` after ``elapsed`` s."""
        s = self.params.supervisor
        jump = math.hypot(new.x - ref.x, new.y - ref.y)
        return jump <= s.max_person_speed * elapsed + s.jump_tolerance

    def _update_person(self, h: PersonState | None, elapsed: float, reasons: list[str]
                       ) -> None:
        s = self.params.supervisor
        if h is None:
            reasons.append("person_missing")
            return
        if not person_is_finite(h):
            reasons.append("person_invalid")
            return
        v = min(max(h.v, -s.max_person_speed), s.max_person_speed)
        w = min(max(h.omega, -s.max_person_turn_rate), s.max_person_turn_rate)
        if (v, w) != (h.v, h.omega):
            reasons.append("person_rate_clipped")
            h = PersonState(h.x, h.y, h.theta, v, w)
        if self._track is None and not self._lost:   # first estimate of the episode
            self._accept(h)
            return
        if self._lost:
            if self._candidate is not None and self._candidate_age <= s.person_timeout \
                    and self._gate(self._candidate, h, self._candidate_age):
                self._candidate_span += self._candidate_age
            else:
                self._candidate_span = 0.0
            self._candidate, self._candidate_age = h, 0.0
            if self._candidate_span >= s.reacquire_time:
                self._accept(h)
            return
        if not self._gate(self._track, h, self._age):
            reasons.append("person_outlier")
            return
        self._accept(h)

    def _accept(self, h: PersonState) -> None:
        if self._lost:
            self._inner_fresh = True
        self._track, self._age, self._lost = h, 0.0, False
        self._candidate, self._candidate_span = None, 0.0

    def _person_now(self, reasons: list[str]) -> PersonState | None:
        """The person the controller gets now: the track, predicted if older than 0; None if
        there is none or it is older than the timeout (then the person is lost)."""
        if self._track is None or self._lost:
            return None
        if self._age > self.params.supervisor.person_timeout:
            self._lost = True
            return None
        if self._age > 0.0:
            if not any(r.startswith("person_") for r in reasons):
                reasons.append("person_predicted")
            return predict(self._track, self._age)
        return self._track

    def _obstacle_inside(self, robot: Pose, obstacles: tuple[Obstacle, ...]) -> bool:
        if not pose_is_finite(robot):
            return False
        radius = self.params.robot.radius
        return any(gap < 0.0 for _, _, gap in obstacle_normals(robot, obstacles, radius))

    def _scan_fault(self, scan: Scan, reasons: list[str]) -> str:
        fraction = valid_fraction(scan)
        if fraction < self.params.supervisor.min_valid_returns or fraction == 0.0:
            return "scan_invalid"
        if fraction < 1.0:
            reasons.append("scan_partial")
        if too_close(scan, self.params.robot.radius):
            return "obstacle_in_footprint"
        return ""

    def _closing(self, robot: Pose, person: PersonState, band: float = 0.3) -> bool:
        """True if the robot and the person are getting closer at the current velocities, or
        are within ``band`` m of the protective distance: then the evasive check runs."""
        normal = person_normal(robot, person)
        if normal is None:
            return True
        nx, ny, dist, approach = normal
        if dist < self.params.supervisor.protective_distance + band:
            return True
        away = self._prev[0] * (math.cos(robot.theta) * nx + math.sin(robot.theta) * ny)
        return approach - away > 0.0

    def _keep_out(self, v: float, robot: Pose, person: PersonState,
                  obstacles: tuple[Obstacle, ...], reasons: list[str]) -> float:
        """``v`` limited by the protective zone and the braking-distance bounds."""
        p, s = self.params, self.params.supervisor
        rate = min(s.accel_max, s.decel_max)
        bounds = []
        normal = person_normal(robot, person)
        if normal is None:
            reasons.append("protective_zone")
            bounds.append((0.0, 0.0))
        else:
            nx, ny, dist, approach = normal
            gap = dist - s.protective_distance
            if gap <= 0.0:
                reasons.append("protective_zone")
                bounds.append(speed_bound(robot.theta, nx, ny, max(approach, 0.0), 0.0))
            else:
                net = max(rate - s.person_accel, 0.1 * rate)   # the person may speed up
                bounds.append(speed_bound(robot.theta, nx, ny, max(approach, 0.0),
                                          braking_speed(gap, net, p.dt)))
        for nx, ny, gap in obstacle_normals(robot, obstacles, p.robot.radius):
            bounds.append(speed_bound(robot.theta, nx, ny, 0.0,
                                      braking_speed(gap - CONTACT_MARGIN, rate, p.dt)))
        return clip_to(v, bounds, p.robot.v_max)

    def _limit(self, v: float, omega: float, u_ob: float) -> Command:
        """Rate limits from the last output, then velocity limits; store the result."""
        p, s = self.params, self.params.supervisor
        pv, pw = self._prev
        v = limit_rate(v, pv, s.accel_max, s.decel_max, p.dt)
        w = limit_rate(omega, pw, s.angular_accel_max, s.angular_accel_max, p.dt)
        v = min(max(v, -p.robot.v_max), p.robot.v_max)
        w = min(max(w, -p.robot.omega_max), p.robot.omega_max)
        self._prev = (v, w)
        return Command(v, w, u_ob)
