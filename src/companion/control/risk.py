"""Collision risk: the chance that the person and the robot's footprint meet in the next
seconds, under the tracker's distribution of the person's state (docs/safety.md).

The robot follows a command through its rate limits and actuator lag (:func:`robot_path`,
which the evasive check's rollout shares); the person's mean walks on at its estimated speed
and turn rate, and its position spreads as the estimate's position and velocity covariance
propagate, plus a white acceleration of the walker (``tracker.accel_std``). At each step
the chance of meeting is that of the person's offset along the line to the robot closing the
gap to contact (a one-dimensional Gaussian tail); the risk is the largest over the horizon.
The evasive check acts only where it reaches ``keepout.collision_risk``.
"""

from __future__ import annotations

import math

import numpy as np

from companion._jit import jitable, kernel
from companion.geometry import lagged, unicycle_step


@jitable
def robot_path(x0: float, y0: float, th0: float, v0: float, w0: float, tv: float, tw: float,
               v_rate: float, w_rate: float, lag: float, step: float, n: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """The robot's positions at ``step``, ``2 step``, ... ``n step`` s when its command ramps
    from ``(v0, w0)`` to ``(tv, tw)`` at the rate limits (m/s^2, rad/s^2) and its velocity
    follows the command through a first-order ``lag`` (s)."""
    xs, ys = np.empty(n), np.empty(n)
    x, y, th, va, wa = x0, y0, th0, v0, w0
    for k in range(n):
        t = (k + 1) * step
        v = v0 + min(max(tv - v0, -v_rate * t), v_rate * t)
        w = w0 + min(max(tw - w0, -w_rate * t), w_rate * t)
        va = lagged(va, v, lag, step)[0]
        wa = lagged(wa, w, lag, step)[0]
        x, y, th = unicycle_step(x, y, th, va, wa, step)
        xs[k], ys[k] = x, y
    return xs, ys


@jitable
def meet_chance(gap: float, std: float) -> float:
    """The chance that a Gaussian offset of standard deviation ``std`` (m) closes ``gap`` m
    in one direction: ``Phi(-gap / std)`` (1/2 at no gap, 1 inside contact with no spread)."""
    if std <= 0.0:
        return 1.0 if gap <= 0.0 else 0.0
    return 0.5 * math.erfc(gap / (std * math.sqrt(2.0)))


@jitable
def collision_risk(xs: np.ndarray, ys: np.ndarray, step: float, px: float, py: float,
                   ptheta: float, pv: float, pomega: float, cov: np.ndarray, accel_std: float,
                   contact: float) -> float:
    """The largest chance over the robot's path (positions ``xs``, ``ys`` every ``step`` s)
    that the person, estimated at ``(px, py)`` walking at ``pv`` along ``ptheta`` and turning
    at ``pomega`` with state covariance ``cov`` (x, y, vx, vy, omega), comes within
    ``contact`` m of the robot's centre."""
    risk = 0.0
    for k in range(len(xs)):
        t = (k + 1) * step
        qx, qy, _ = unicycle_step(px, py, ptheta, pv, pomega, t)
        dx, dy = xs[k] - qx, ys[k] - qy
        dist = math.hypot(dx, dy)
        if dist < 1e-9:
            return 1.0
        nx, ny = dx / dist, dy / dist
        var = 0.0
        for i in range(2):
            for j in range(2):
                c = cov[i, j] + t * (cov[i, j + 2] + cov[i + 2, j]) + t * t * cov[i + 2, j + 2]
                var += (nx if i == 0 else ny) * (nx if j == 0 else ny) * c
        var += accel_std * accel_std * t * t * t / 3.0
        risk = max(risk, meet_chance(dist - contact, math.sqrt(max(var, 0.0))))
    return risk


@jitable
def command_risk(x0: float, y0: float, th0: float, v0: float, w0: float, tv: float,
                 tw: float, v_rate: float, w_rate: float, lag: float, step: float, n: int,
                 px: float, py: float, ptheta: float, pv: float, pomega: float,
                 cov: np.ndarray, accel_std: float, contact: float) -> float:
    """:func:`collision_risk` of the command ``(tv, tw)`` (:func:`robot_path`)."""
    xs, ys = robot_path(x0, y0, th0, v0, w0, tv, tw, v_rate, w_rate, lag, step, n)
    return collision_risk(xs, ys, step, px, py, ptheta, pv, pomega, cov, accel_std, contact)


compiled_command_risk = kernel(command_risk, lambda: (
    0.0, 0.0, 0.0, 0.5, 0.0, 0.5, 0.1, 1.0, 2.0, 0.1, 0.1, 3, 1.0, 1.0, 0.0, 1.0, 0.0,
    0.01 * np.eye(5), 0.5, 0.6))
