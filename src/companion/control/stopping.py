"""Rule 4 of the keep-out rules: the robot can always still brake to a stop short of every
known obstacle, along the path it would actually turn along (docs/safety.md, fault 6).

A command is **admissible** if, held for one period ``dt`` from the robot's current state and
then followed by the **stop manoeuvre** (the command ramped to ``(0, 0)`` at the
deceleration limits, one period at a time, the actual velocity following through the
actuator lag ``sensing.actuator_tau_s``, as :func:`companion.sim.episode.run_episode` moves
the robot), it keeps the footprint ``keepout.contact_margin`` plus :func:`sample_dip` from
every obstacle at every sample (:func:`stop_margins`), so at least ``contact_margin`` between
them. If the command the other rules leave is not admissible, it is replaced by the
admissible command closest to it among a grid of the commands reachable within one period's
rate limits (steering as well as braking).

Why this holds by construction: the command sent at step ``k`` was admissible, so at step
``k + 1`` the stop manoeuvre from the new state (the braking command, then braking on) is
the tail of that prediction and still clear: an admissible command exists again. From a
start whose stop manoeuvre keeps the margin, the robot never comes closer than
``contact_margin``. From one whose stop manoeuvre is clear but keeps less (or after an
obstacle appears close by), a command is admissible if its margin is at least the braking
command's, so the margin of the stop manoeuvre never shrinks and the robot never touches;
it may still move away. Assumptions: the obstacles are static and known, the robot moves as
modelled (rate limits, first-order lag, odometry), and between two samples along an arc.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from companion._jit import jitable, kernel
from companion.control.limits import limit, limit_rate, reachable
from companion.geometry import (
    ObstacleArrays,
    base_step,
    clearance,
    min_clearance,
    obstacle_arrays,
    sample_obstacles,
)
from companion.params import Params
from companion.types import Obstacle, Pose

#: Rollouts are compared to ``contact_margin`` with this tolerance (m): the plant repeats the
#: prediction's arithmetic, up to the wrapping of the heading.
TOLERANCE = 1e-6
#: Extra distance (m) beyond the farthest reach of a stop within which obstacles are checked.
REACH_MARGIN = 0.1
#: Points per axis of the grid of reachable commands (plus the braking command itself).
GRID_POINTS = 5


class Plant(NamedTuple):
    """The robot as :func:`stop_margins` predicts it: period (s), lag (s), rate limits
    (m/s^2 grow and shrink, rad/s^2), velocity limits (m/s, rad/s) and footprint radius (m)."""

    dt: float
    tau: float
    accel: float
    decel: float
    w_rate: float
    v_max: float
    w_max: float
    radius: float


def plant(params: Params) -> Plant:
    """The :class:`Plant` of ``params``."""
    s, r = params.supervisor, params.robot
    return Plant(params.dt, params.sensing.actuator_tau_s, s.accel_max, s.decel_max,
                 s.angular_accel_max, r.v_max, r.omega_max, r.radius)


def sample_dip(robot: Plant) -> float:
    """How much closer (m) than at the two samples around it the footprint can come to an
    obstacle between them: a chord of length ``L = v_max dt`` between points at least the
    footprint radius ``R`` from an obstacle comes within ``R - sqrt(R^2 - L^2 / 4)`` of it,
    and the arc is at most its sagitta ``L omega_max dt / 8`` from the chord."""
    length, r = robot.v_max * robot.dt, robot.radius
    return r - math.sqrt(max(r * r - 0.25 * length * length, 0.0)) \
        + 0.125 * length * robot.w_max * robot.dt


@jitable
def stop_margins(x0: float, y0: float, th0: float, va0: float, wa0: float,
                 commands: np.ndarray, robot: Plant, obstacles: ObstacleArrays) -> np.ndarray:
    """Smallest footprint clearance (m) to the obstacles, at the samples, of each
    ``(v, omega)`` row of ``commands`` (already within the rate limits) held one period from
    the pose and actual velocity ``(va0, wa0)``, then followed by the stop manoeuvre until
    the command is zero and the lag has decayed for ``3 tau`` more; the motion left after
    that, at most ``tau |v|`` long, is subtracted."""
    dt, tau = robot.dt, robot.tau
    tail = int(math.ceil(3.0 * tau / dt))
    out = np.empty(commands.shape[0])
    for i in range(commands.shape[0]):
        x, y, th, va, wa = x0, y0, th0, va0, wa0
        cv, cw = commands[i, 0], commands[i, 1]
        margin = min_clearance(x, y, obstacles, robot.radius)
        left = tail
        while left >= 0:
            x, y, th, va, wa = base_step(x, y, th, va, wa, cv, cw, tau, dt)
            margin = min(margin, min_clearance(x, y, obstacles, robot.radius))
            if cv == 0.0 and cw == 0.0:
                left -= 1
            cv = limit_rate(0.0, cv, robot.accel, robot.decel, dt)
            cw = limit_rate(0.0, cw, robot.w_rate, robot.w_rate, dt)
        out[i] = min(margin, min_clearance(x, y, obstacles, robot.radius) - tau * abs(va))
    return out


_stop_margins = kernel(stop_margins, lambda: (
    0.0, 0.0, 0.0, 0.5, 0.0, np.array([(0.5, 0.0), (0.0, 0.0)]), plant(Params()),
    sample_obstacles()))


def reach(speed: float, robot: Plant, margin: float) -> float:
    """Farthest clearance (m) that matters: an obstacle farther than this from the footprint
    stays beyond ``margin`` whatever command within the limits is held one period before the
    stop manoeuvre (travel at most ``v_max dt + v_max^2 / (2 decel)`` plus ``tau`` times the
    larger of ``|speed|`` (the actual speed) and ``v_max``)."""
    v = robot.v_max
    return v * robot.dt + v * v / (2.0 * robot.decel) + robot.tau * max(abs(speed), v) \
        + margin + REACH_MARGIN


@jitable
def command_grid(prev_v: float, prev_w: float, robot: Plant) -> np.ndarray:
    """Commands reachable from ``(prev_v, prev_w)`` within one period: the braking command
    (the next step of the stop manoeuvre) first, then a grid of :data:`GRID_POINTS` per axis
    over the box the rate limits allow, each axis with its braking value added."""
    dt, n = robot.dt, GRID_POINTS
    vs, ws = np.empty(n + 1), np.empty(n + 1)
    vs[0] = reachable(0.0, prev_v, robot.accel, robot.decel, robot.v_max, dt)
    ws[0] = reachable(0.0, prev_w, robot.w_rate, robot.w_rate, robot.w_max, dt)
    v_lo = reachable(-math.inf, prev_v, robot.accel, robot.decel, robot.v_max, dt)
    v_hi = reachable(math.inf, prev_v, robot.accel, robot.decel, robot.v_max, dt)
    w_lo = reachable(-math.inf, prev_w, robot.w_rate, robot.w_rate, robot.w_max, dt)
    w_hi = reachable(math.inf, prev_w, robot.w_rate, robot.w_rate, robot.w_max, dt)
    for j in range(n):
        vs[j + 1] = v_lo + (v_hi - v_lo) * j / (n - 1)
        ws[j + 1] = w_lo + (w_hi - w_lo) * j / (n - 1)
    out = np.empty(((n + 1) * (n + 1), 2))
    for i in range(n + 1):
        for j in range(n + 1):
            out[i * (n + 1) + j, 0] = vs[i]
            out[i * (n + 1) + j, 1] = ws[j]
    return out


_command_grid = kernel(command_grid, lambda: (0.5, 0.0, plant(Params())))


def stop_path_target(target: tuple[float, float], robot: Pose, v_now: tuple[float, float],
                     prev: tuple[float, float], obstacles: Sequence[Obstacle], params: Params,
                     allowed: tuple[float, float] = (-math.inf, math.inf)
                     ) -> tuple[float, float] | None:
    """Rule 4: None if the ``target`` (v, omega), limited from the last command ``prev``, is
    admissible (module docstring) or no obstacle is within :func:`reach`; else the admissible
    candidate closest to it (in units of v_max and omega_max), preferring those whose ``v``
    lies in ``allowed`` (the person's braking interval). ``v_now`` is the robot's actual
    velocity."""
    if not obstacles:
        return None
    model = plant(params)
    need = params.keepout.contact_margin + sample_dip(model)
    far = reach(v_now[0], model, need)
    near = [ob for ob in obstacles if clearance(ob, robot.x, robot.y, model.radius) < far]
    if not near:
        return None
    nominal = limit(target, prev, params)
    braking = limit((0.0, 0.0), prev, params)
    arrays = obstacle_arrays(near)
    x, y, th, va, wa = robot.x, robot.y, robot.theta, float(v_now[0]), float(v_now[1])
    first = _stop_margins(x, y, th, va, wa, np.array([nominal, braking]), model, arrays)
    if first[0] >= min(need, first[1]) - TOLERANCE:
        return None
    commands = _command_grid(float(prev[0]), float(prev[1]), model)   # row 0: braking
    margin = _stop_margins(x, y, th, va, wa, commands, model, arrays)
    ok = margin >= min(need, first[1]) - TOLERANCE
    r = params.robot
    change = np.hypot((commands[:, 0] - nominal[0]) / r.v_max,
                      (commands[:, 1] - nominal[1]) / r.omega_max)
    outside = np.maximum(np.maximum(allowed[0] - commands[:, 0], commands[:, 0] - allowed[1]),
                         0.0)
    outside = np.where(ok | (np.arange(len(ok)) == 0), outside, math.inf)
    best = int(np.argmin(np.where(outside <= outside.min() + 1e-12, change, math.inf)))
    return float(commands[best, 0]), float(commands[best, 1])
