"""Rule 2 of the keep-out (:mod:`.keepout`): the evasive check and giving way.

Both predict the next seconds for a command and for candidates of a grid: the robot through
its rate limits and actuator lag (:func:`~companion.control.risk.robot_path`), the person
along its estimated heading (and ``spread`` to either side, possibly speeding up to a brisk
walk), moving obstacles (walkers) at their velocities, standing ones where they are. A
command whose predicted margin is too small is replaced by the grid's best. docs/safety.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from companion._jit import jitable, kernel
from companion.control.risk import robot_path
from companion.geometry import (
    ObstacleArrays,
    min_clearance,
    obstacle_arrays,
    sample_obstacles,
    unicycle_step,
)
from companion.params import Params
from companion.types import Circle, Obstacle, PersonState, Pose

#: Speed (m/s) up to which a person may speed up (brisk walking), in the evasive prediction.
BRISK_WALK = 1.5
#: Time step (s) of the evasive check's and the collision risk's predictions.
ROLLOUT_STEP = 0.1
#: Candidate targets of the evasive check: 7 x 5 fractions of (v_max, omega_max).
_GRID = np.array([(v, w) for v in np.linspace(-1.0, 1.0, 7) for w in np.linspace(-1.0, 1.0, 5)])


@jitable
def speed_up_distance(v: float, accel: float, t: float) -> float:
    """Extra distance (m) a person walking at ``v`` covers in ``t`` s by speeding up at
    ``accel`` until :data:`BRISK_WALK` (none if already faster)."""
    if accel <= 0.0 or v >= BRISK_WALK:
        return 0.0
    t_up = min(t, (BRISK_WALK - v) / accel)
    return 0.5 * accel * t_up * t_up + accel * t_up * (t - t_up)


class Rollout(NamedTuple):
    """What :func:`rollout_margins` predicts with: the person (pose, speed, turn rate, and the
    acceleration it may add), the protective distance, the footprint radius, the robot's rate
    limits (m/s^2, rad/s^2), the prediction grid (step s, number of steps), the actuator lag
    (s) and the spread (rad) of the person's heading hypotheses."""

    px: float
    py: float
    ptheta: float
    pv: float
    pomega: float
    person_accel: float
    protective: float
    radius: float
    v_rate: float
    w_rate: float
    step: float
    n_steps: int
    lag: float = 0.0
    spread: float = 0.0


@jitable
def rollout_margins(x0: float, y0: float, th0: float, v0: float, w0: float,
                    targets: np.ndarray, spec: Rollout, obstacles: ObstacleArrays) -> np.ndarray:
    """Predicted safety margin of each candidate ``(v, omega)`` (rows of ``targets``).

    The robot's command ramps from ``(v0, w0)`` to the target at the rate limits and its
    velocity follows through the first-order ``lag``; the person keeps its speed and turn rate
    from its heading and, with a ``spread``, from the headings ``spread`` to either side, and
    may also gain the :func:`speed_up_distance` along its heading; moving circles (walkers)
    keep their velocities. The margin is the smallest, over the horizon and the headings, of
    the distance to the person minus the protective distance and the obstacle clearance
    (:func:`min_clearance`).
    """
    n = spec.n_steps
    m = 3 if spec.spread > 0.0 else 1
    hx = np.empty((m, n))
    hy = np.empty((m, n))
    for j in range(m):
        heading = spec.ptheta + (j - (m - 1) // 2) * spec.spread
        for k in range(n):
            t = (k + 1) * spec.step
            qx, qy, _ = unicycle_step(spec.px, spec.py, heading, spec.pv, spec.pomega, t)
            extra = speed_up_distance(spec.pv, spec.person_accel, t)
            hx[j, k] = qx + extra * math.cos(heading)
            hy[j, k] = qy + extra * math.sin(heading)
    out = np.empty(targets.shape[0])
    for i in range(targets.shape[0]):
        xs, ys = robot_path(x0, y0, th0, v0, w0, targets[i, 0], targets[i, 1], spec.v_rate,
                            spec.w_rate, spec.lag, spec.step, n)
        margin = math.inf
        for k in range(n):
            margin = min(margin, min_clearance(xs[k], ys[k], obstacles, spec.radius,
                                               (k + 1) * spec.step))
            for j in range(m):
                margin = min(margin, math.hypot(xs[k] - hx[j, k], ys[k] - hy[j, k])
                             - spec.protective)
        out[i] = margin
    return out


_rollout_margins = kernel(rollout_margins, lambda: (
    0.0, 0.0, 0.0, 0.5, 0.0, np.array([(0.5, 0.0), (0.0, 0.0)]),
    Rollout(1.0, 1.0, 0.0, 1.0, 0.0, 0.5, 0.5, 0.25, 1.0, 2.0, 0.1, 3, 0.1, 0.1),
    sample_obstacles()))


def evasive_target(robot: Pose, current: tuple[float, float], nominal: tuple[float, float],
                   person: PersonState | None, obstacles: Sequence[Obstacle], params: Params,
                   grow: float = 0.0, spread: float = 0.0, needed: float = 0.05,
                   comfort: float = 0.2, horizon: float = 1.2, step: float = ROLLOUT_STEP
                   ) -> tuple[float, float] | None:
    """Rule 2: a replacement for the ``nominal`` target if its predicted margin (to the
    protective distance grown by ``grow`` m, for the person's headings ``spread`` rad to
    either side, and to the obstacles; the robot with its actuator lag) is below ``needed``
    m, else None.

    The replacement is the grid target with the best ``min(margin, comfort) - 0.02 * change``:
    margins count up to ``comfort`` m, and among equally safe targets the one closest to the
    nominal (``change`` in units of v_max and omega_max) wins. Without a ``person`` (lost)
    only the obstacles count.
    """
    r, s, k = params.robot, params.supervisor, params.keepout
    targets = np.vstack([nominal, _GRID * (r.v_max, r.omega_max)])
    if person is None:           # a protective distance of -inf: the person never counts
        person, grow = PersonState(robot.x, robot.y, 0.0, 0.0, 0.0), -math.inf
    spec = Rollout(person.x, person.y, person.theta, person.v, person.omega, k.person_accel,
                   k.protective_distance + grow, r.radius, min(s.accel_max, s.decel_max),
                   s.angular_accel_max, step, int(round(horizon / step)),
                   params.sensing.actuator_tau_s, spread)
    margin = _rollout_margins(robot.x, robot.y, robot.theta, float(current[0]),
                              float(current[1]), targets, spec, obstacle_arrays(obstacles))
    if margin[0] >= needed:
        return None
    change = np.hypot((targets[:, 0] - nominal[0]) / r.v_max,
                      (targets[:, 1] - nominal[1]) / r.omega_max)
    best = int(np.argmax(np.minimum(margin, comfort) - 0.02 * change))
    return float(targets[best, 0]), float(targets[best, 1])


def give_way_target(robot: Pose, current: tuple[float, float], nominal: tuple[float, float],
                    person: PersonState | None, obstacles: Sequence[Obstacle], params: Params,
                    grow: float = 0.0, spread: float = 0.0) -> tuple[float, float] | None:
    """Giving way: if a moving circle (a walker, at constant velocity) would come within
    ``keepout.give_way_margin`` of the footprint over the evasive horizon on the ``nominal``
    command's path, the evasive check's replacement (:func:`evasive_target`, everything
    counted; the person too unless ``person`` is None: lost) for that margin; else None.
    Whether the walker or the robot would close the gap does not matter here: a robot that
    can move does not stand in a walker's way."""
    r, s, k = params.robot, params.supervisor, params.keepout
    horizon = k.evasive_horizon_s
    if k.give_way_margin <= 0.0:
        return None
    movers = [o for o in obstacles if isinstance(o, Circle) and o.moving
              and math.hypot(o.x - robot.x, o.y - robot.y) - o.radius - r.radius
              <= (r.v_max + math.hypot(o.vx, o.vy)) * horizon + k.give_way_margin]
    if not movers:
        return None
    spec = Rollout(robot.x, robot.y, 0.0, 0.0, 0.0, 0.0, -math.inf, r.radius,
                   min(s.accel_max, s.decel_max), s.angular_accel_max, ROLLOUT_STEP,
                   int(round(horizon / ROLLOUT_STEP)), params.sensing.actuator_tau_s)
    margin = _rollout_margins(robot.x, robot.y, robot.theta, float(current[0]),
                              float(current[1]), np.array([nominal], dtype=float), spec,
                              obstacle_arrays(movers))
    if margin[0] >= k.give_way_margin:
        return None
    return evasive_target(robot, current, nominal, person, obstacles, params, grow, spread,
                          needed=k.give_way_margin, horizon=horizon)


