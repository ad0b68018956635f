"""Rate and velocity limits, the last step of the safety supervisor (docs/safety.md)."""

from __future__ import annotations

from companion._jit import jitable
from companion.params import Params


@jitable
def limit_rate(target: float, prev: float, grow: float, shrink: float, dt: float) -> float:
    """The value closest to ``target`` reachable from ``prev`` in ``dt`` when ``|x|`` may grow
    at most at rate ``grow`` and shrink at most at rate ``shrink`` (crossing zero: shrink to
    0 first, then grow for the rest of the period)."""
    sign = -1.0 if prev < 0.0 else 1.0       # mirror a negative prev onto a positive one
    target, prev = sign * target, sign * prev
    hi = prev + grow * dt
    to_zero = prev / shrink
    lo = prev - shrink * dt if to_zero >= dt else -grow * (dt - to_zero)
    return sign * min(max(target, lo), hi)


@jitable
def reachable(target: float, prev: float, grow: float, shrink: float, bound: float,
              dt: float) -> float:
    """``target`` held to the bound ``|x| <= bound``, then reached from ``prev`` under one
    period's rate limit (:func:`limit_rate`): one axis of :func:`limit`. With ``|prev| <=
    bound`` the result is within the bound; a ``prev`` beyond it (the bound was lowered while
    running) comes down at the rate limit instead of jumping."""
    return limit_rate(min(max(target, -bound), bound), prev, grow, shrink, dt)


def limit(target: tuple[float, float], prev: tuple[float, float], params: Params
          ) -> tuple[float, float]:
    """``target`` (v, omega) after the acceleration limits from ``prev``, one period ``dt``
    on, then the velocity limits."""
    s, r, dt = params.supervisor, params.robot, params.dt
    return (reachable(target[0], prev[0], s.accel_max, s.decel_max, r.v_max, dt),
            reachable(target[1], prev[1], s.angular_accel_max, s.angular_accel_max,
                      r.omega_max, dt))
