"""Every keep-out rule: how close the robot may come to the person and to obstacles.

The safety supervisor applies them to the controller's target in this order (docs/safety.md):

1. **Comfort barriers** (:func:`barrier_speed`): for a clearance ``D`` to keep at ``D_min``,
   ``dD/dt >= -barrier_rate (D - D_min)``; the approach speed shrinks to 0 at
   ``keepout.person_clearance`` (robot centre to person) and ``keepout.obstacle_clearance``
   (footprint to surface). 0 switches a barrier off.
2. **Evasive check** (:func:`evasive_target`): when the robot and the person close in and the
   controller's command has a collision risk (:func:`risk_of`, :mod:`.risk`) of at least
   ``keepout.collision_risk``, the next ``keepout.evasive_horizon_s`` are predicted (the
   robot through its actuator lag, the person along its estimated heading and
   ``keepout.heading_sigmas`` standard deviations to either side) and a command that would
   come within 5 cm of the protective distance or of an obstacle is replaced by the closest
   safe one of a grid (:mod:`.evasive`). The same check gives way to walkers
   (:func:`~companion.control.evasive.give_way_target`): a command on whose path a moving
   obstacle, at its velocity, comes within ``keepout.give_way_margin`` is replaced too.
3. **Braking bound** (:func:`braking_bound`): inside ``protective_distance`` the robot may only
   turn or move away (at least as fast as the person comes); where only the person's
   uncertainty reaches the zone, the robot may not approach but need not flee; outside, and
   towards obstacles, the robot's own approach speed is
   what braking at the rate limit can still stop in time, counting one period of delay and
   the distance the actuator lag carries the robot on at its measured speed. A person's own
   approach outside the zone is rule 2's to answer: backing off along the line to the person
   drove the robot into the path of people passing by (docs/safety.md).
4. **Stop path** (:func:`companion.control.stopping.stop_path_target`): last, on the command
   the others leave, so it checks what is sent. The robot must still be able to brake to a
   stop along the path it turns along without coming within ``keepout.contact_margin`` of
   an obstacle; else the closest command (steering too) that can, preferring those within
   the person's braking interval. Rules 1-3 look along the current heading only, so a turn
   can outrun them; this one makes the obstacle side hold by construction.

Without a person estimate (lost, while the robot searches) only giving way and rule 4 apply.
Rules 1 and 3 change only ``v``, so the robot can always turn. The
protective distance grows by ``keepout.uncertainty_sigmas`` standard deviations of where the
person may be by the time the robot reacts (:func:`reaction_std`), and braking counts the
actuator lag and the detections' latency as reaction time.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence

import numpy as np

from companion.control.evasive import ROLLOUT_STEP, evasive_target, give_way_target
from companion.control.risk import compiled_command_risk
from companion.control.stopping import stop_path_target
from companion.geometry import (
    clearance,
    major_std,
    segment_point,
)
from companion.params import Params
from companion.types import Circle, Obstacle, PersonEstimate, PersonState, Pose

#: Distance band (m) beyond the protective distance within which the evasive check always runs.
EVASIVE_BAND = 0.3
#: A speed (m/s) a rule changes by more than this is changed: its reason is reported.
CHANGED = 1e-6


def speed_bound(theta: float, nx: float, ny: float, approach: float, allowed: float
                ) -> tuple[float, float]:
    """Interval of ``v`` with ``v e(theta).n - approach >= -allowed``: ``n`` is the unit vector
    from the thing to the robot, ``approach`` the thing's speed towards the robot along ``n``,
    ``allowed`` the acceptable closing speed (negative: the distance must grow)."""
    along = math.cos(theta) * nx + math.sin(theta) * ny
    if abs(along) < 1e-9:
        return -math.inf, math.inf   # v cannot change the distance
    bound = (approach - allowed) / along
    return (bound, math.inf) if along > 0.0 else (-math.inf, bound)


def person_normal(robot: Pose, person: PersonState) -> tuple[float, float, float, float] | None:
    """``(nx, ny, dist, approach)``: unit vector from the person to the robot centre, their
    distance and the person's speed towards the robot (None if they coincide)."""
    dx, dy = robot.x - person.x, robot.y - person.y
    dist = math.hypot(dx, dy)
    if dist < 1e-9:
        return None
    nx, ny = dx / dist, dy / dist
    return nx, ny, dist, person.v * (math.cos(person.theta) * nx + math.sin(person.theta) * ny)


def obstacle_normals(robot: Pose, obstacles: Sequence[Obstacle], radius: float
                     ) -> Iterator[tuple[float, float, float]]:
    """``(nx, ny, clearance)`` per obstacle: unit vector from a circle's centre or a wall's
    nearest point to the robot centre, and the footprint's clearance (robot centre on it:
    skipped)."""
    for ob in obstacles:
        if isinstance(ob, Circle):
            cx, cy = ob.x, ob.y
        else:
            cx, cy = segment_point(robot.x, robot.y, ob.x0, ob.y0, ob.x1, ob.y1)
        dx, dy = robot.x - cx, robot.y - cy
        dist = math.hypot(dx, dy)
        if dist >= 1e-9:
            yield dx / dist, dy / dist, clearance(ob, robot.x, robot.y, radius)


def clip_to(v: float, bounds: Iterable[tuple[float, float]], v_max: float) -> float:
    """``v`` clipped to the intersection of ``bounds`` and ``[-v_max, v_max]``; where the
    bounds contradict each other, the middle of the tightest pair of ends."""
    lo, hi = -math.inf, math.inf
    for a, b in bounds:
        lo, hi = max(lo, a), min(hi, b)
    v = min(max(v, lo), hi) if lo <= hi else 0.5 * (lo + hi)
    return min(max(v, -v_max), v_max)


def reaction_std(estimate: PersonEstimate, delay: float) -> float:
    """Standard deviation (m, larger axis) of the person's position ``delay`` s on from the
    estimate: its position and velocity uncertainty over the time the robot needs to react."""
    c = estimate.covariance
    pos = c[:2, :2] + delay * (c[:2, 2:4] + c[2:4, :2]) + delay * delay * c[2:4, 2:4]
    return max(major_std(pos), estimate.position_std)


def heading_std(estimate: PersonEstimate) -> float:
    """Standard deviation (rad) of the person's heading: the velocity's uncertainty across
    its direction over the speed, at most pi/4 (a standing person has no heading)."""
    if estimate.state.v <= 0.0:
        return 0.0
    th = estimate.state.theta
    across = np.array((-math.sin(th), math.cos(th)))
    var = float(across @ estimate.covariance[2:4, 2:4] @ across)
    return min(math.sqrt(max(var, 0.0)) / estimate.state.v, 0.25 * math.pi)


def barrier_speed(v: float, robot: Pose, person: PersonState, obstacles: Sequence[Obstacle],
                  params: Params) -> float:
    """Rule 1: the speed closest to ``v`` that meets the comfort barriers (not grown by the
    person's uncertainty: that would push the robot out of its slot on every noisy step)."""
    k = params.keepout
    bounds = []
    if k.person_clearance > 0.0:
        normal = person_normal(robot, person)
        if normal is None:
            return 0.0  # no direction to move away along
        nx, ny, dist, approach = normal
        bounds.append(speed_bound(robot.theta, nx, ny, approach,
                                  k.barrier_rate * (dist - k.person_clearance)))
    if k.obstacle_clearance > 0.0:
        for nx, ny, gap in obstacle_normals(robot, obstacles, params.robot.radius):
            bounds.append(speed_bound(robot.theta, nx, ny, 0.0,
                                      k.barrier_rate * (gap - k.obstacle_clearance)))
    return clip_to(v, bounds, params.robot.v_max)


def braking_speed(gap: float, decel: float, dt: float) -> float:
    """Largest closing speed from which a robot that reacts one period ``dt`` late and then
    decelerates at ``decel`` stops within ``gap``: the root of ``v dt + v^2 / (2 decel) = gap``
    (0 for ``gap <= 0``)."""
    if gap <= 0.0:
        return 0.0
    ad = decel * dt
    return math.sqrt(ad * ad + 2.0 * decel * gap) - ad


def reaction_delay(params: Params) -> float:
    """Time (s) from the data a command is based on to the robot braking: one period, the
    actuator lag and the person detections' latency."""
    return params.dt + params.sensing.actuator_tau_s + params.sensing.person_latency_s


def lag_travel(robot: Pose, actual: float | None, nx: float, ny: float, tau: float) -> float:
    """Distance (m) the robot's actual speed ``actual`` still carries it against the unit
    vector ``(nx, ny)`` once its command is zero: ``tau`` times its closing speed (a
    first-order lag of time constant ``tau`` travels exactly that far beyond its command)."""
    if actual is None:
        return 0.0
    return tau * max(-actual * (math.cos(robot.theta) * nx + math.sin(robot.theta) * ny), 0.0)


def person_interval(robot: Pose, person: PersonState, params: Params, reasons: list[str],
                    grow: float = 0.0, actual: float | None = None) -> tuple[float, float]:
    """Rule 3 towards the person: the interval of ``v`` the protective zone (grown by ``grow``
    m) allows (see :func:`braking_bound`)."""
    k, s = params.keepout, params.supervisor
    normal = person_normal(robot, person)
    if normal is None:
        reasons.append("protective_zone")
        return 0.0, 0.0
    nx, ny, dist, approach = normal
    gap = dist - k.protective_distance - grow
    if dist <= k.protective_distance:     # inside the zone itself: away, as fast as it comes
        reasons.append("protective_zone")
        return speed_bound(robot.theta, nx, ny, max(approach, 0.0), 0.0)
    if gap <= 0.0:            # only the person's uncertainty reaches: no approach of its own
        reasons.append("protective_zone")
        return speed_bound(robot.theta, nx, ny, 0.0, 0.0)
    rate = min(s.accel_max, s.decel_max)
    net = max(rate - k.person_accel, 0.1 * rate)   # the person may speed up
    tau = params.sensing.actuator_tau_s
    delay = reaction_delay(params) - (0.0 if actual is None else tau)
    allowed = braking_speed(gap - lag_travel(robot, actual, nx, ny, tau), net, delay)
    return speed_bound(robot.theta, nx, ny, 0.0, allowed)   # the robot's own approach


def obstacle_bounds(robot: Pose, obstacles: Sequence[Obstacle], params: Params,
                    actual: float | None = None) -> list[tuple[float, float]]:
    """Rule 3 towards the obstacles: per obstacle, the interval of ``v`` from which braking
    stops ``keepout.contact_margin`` short of it (see :func:`braking_bound`)."""
    s, tau = params.supervisor, params.sensing.actuator_tau_s
    rate = min(s.accel_max, s.decel_max)
    delay = reaction_delay(params) - (0.0 if actual is None else tau)
    bounds = []
    for nx, ny, gap in obstacle_normals(robot, obstacles, params.robot.radius):
        gap -= params.keepout.contact_margin + lag_travel(robot, actual, nx, ny, tau)
        bounds.append(speed_bound(robot.theta, nx, ny, 0.0, braking_speed(gap, rate, delay)))
    return bounds


def braking_bound(v: float, robot: Pose, person: PersonState, obstacles: Sequence[Obstacle],
                  params: Params, reasons: list[str], grow: float = 0.0,
                  actual: float | None = None) -> float:
    """Rule 3: ``v`` limited by the protective zone (grown by ``grow`` m,
    :func:`person_interval`) and the braking-distance bounds (:func:`obstacle_bounds`),
    reacting :func:`reaction_delay` late.

    With the robot's ``actual`` speed (odometry) the actuator lag counts as the distance the
    lag carries the robot on at that speed (:func:`lag_travel`), not as time at ``v``: a
    robot that is braking moves faster than its command."""
    bounds = [person_interval(robot, person, params, reasons, grow, actual),
              *obstacle_bounds(robot, obstacles, params, actual)]
    return clip_to(v, bounds, params.robot.v_max)


def closing(robot: Pose, person: PersonState, v_now: float, params: Params,
            grow: float = 0.0) -> bool:
    """True if robot and person get closer at the current velocities, or are within
    :data:`EVASIVE_BAND` of the protective distance (grown by ``grow``): then the evasive
    check runs."""
    normal = person_normal(robot, person)
    if normal is None:
        return True
    nx, ny, dist, approach = normal
    if dist < params.keepout.protective_distance + grow + EVASIVE_BAND:
        return True
    away = v_now * (math.cos(robot.theta) * nx + math.sin(robot.theta) * ny)
    return approach - away > 0.0


def risk_of(command: tuple[float, float], robot: Pose, v_now: tuple[float, float],
            estimate: PersonEstimate, params: Params) -> float:
    """The collision risk of ``command`` over the evasive horizon
    (:func:`companion.control.risk.collision_risk`): the robot from its velocity ``v_now``,
    the person as ``estimate`` says, contact at the footprint plus ``keepout.person_radius``."""
    r, s, k, h = params.robot, params.supervisor, params.keepout, estimate.state
    step = ROLLOUT_STEP
    return compiled_command_risk(
        robot.x, robot.y, robot.theta, float(v_now[0]), float(v_now[1]), float(command[0]),
        float(command[1]), min(s.accel_max, s.decel_max), s.angular_accel_max,
        params.sensing.actuator_tau_s, step, int(round(k.evasive_horizon_s / step)), h.x, h.y,
        h.theta, h.v, h.omega, np.ascontiguousarray(estimate.covariance, dtype=float),
        params.tracker.accel_std, r.radius + k.person_radius)


def keep_out(target: tuple[float, float, float], robot: Pose,
             estimate: PersonEstimate | None, obstacles: Sequence[Obstacle],
             v_now: tuple[float, float], params: Params, reasons: list[str],
             prev: tuple[float, float] | None = None) -> tuple[float, float, float]:
    """The target ``(v, omega, u_ob)`` after rules 1-4 (module docstring) for the person
    ``estimate``; ``v_now`` is the robot's velocity now, ``prev`` the last command (None:
    ``v_now``). Appends "comfort_barrier", "evasive", "give_way", "protective_zone",
    "braking" (rule 3 outside the zone) or "stop_path" to ``reasons`` when they act, so that
    no step whose command a rule changed reports ``ok``. Without an ``estimate`` (a lost
    person, while the robot searches) there is no one to keep out of: only giving way and
    the stop path apply."""
    v, w, u_ob = target
    last = v_now if prev is None else prev
    if estimate is None:
        evade = give_way_target(robot, v_now, (v, w), None, obstacles, params)
        if evade is not None:
            (v, w), u_ob = evade, 0.0
            reasons.append("give_way")
        stop = stop_path_target((v, w), robot, v_now, last, obstacles, params)
        if stop is not None:
            (v, w), u_ob = stop, 0.0
            reasons.append("stop_path")
        return v, w, u_ob
    person = estimate.state
    grow = params.keepout.uncertainty_sigmas * reaction_std(estimate, reaction_delay(params))
    v, asked = barrier_speed(v, robot, person, obstacles, params), v
    if abs(v - asked) > CHANGED:
        reasons.append("comfort_barrier")
    threshold = params.keepout.collision_risk
    spread = params.keepout.heading_sigmas * heading_std(estimate)
    evade = None
    if closing(robot, person, v_now[0], params, grow) and (
            threshold <= 0.0 or risk_of((v, w), robot, v_now, estimate, params) >= threshold):
        evade = evasive_target(robot, v_now, (v, w), person, obstacles, params, grow, spread,
                               horizon=params.keepout.evasive_horizon_s)
        if evade is not None:
            (v, w), u_ob = evade, 0.0
            reasons.append("evasive")
    if evade is None:          # the evasive check's rollout already moved the walkers
        evade = give_way_target(robot, v_now, (v, w), person, obstacles, params, grow, spread)
        if evade is not None:
            (v, w), u_ob = evade, 0.0
            reasons.append("give_way")
    allowed = person_interval(robot, person, params, reasons, grow, v_now[0])
    v, asked = clip_to(v, [allowed, *obstacle_bounds(robot, obstacles, params, v_now[0])],
                       params.robot.v_max), v
    if abs(v - asked) > CHANGED and "protective_zone" not in reasons:
        reasons.append("braking")
    stop = stop_path_target((v, w), robot, v_now, last, obstacles, params, allowed)
    if stop is not None:
        (v, w), u_ob = stop, 0.0
        reasons.append("stop_path")
    return v, w, u_ob
