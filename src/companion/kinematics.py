"""Unicycle kinematics (paper Eq. 1-3) and angle helpers.

All quantities are SI: metres, radians, seconds.
"""

from __future__ import annotations

import math

TWO_PI = 2.0 * math.pi


def wrap_pi(angle: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    a = math.fmod(angle + math.pi, TWO_PI)
    if a <= 0.0:
        a += TWO_PI
    return a - math.pi


def wrap_2pi(angle: float) -> float:
    """Wrap an angle to [0, 2*pi)."""
    a = math.fmod(angle, TWO_PI)
    if a < 0.0:
        a += TWO_PI
    # fmod of a tiny negative number plus 2*pi can round to exactly 2*pi.
    return 0.0 if a >= TWO_PI else a


def unicycle_step(x: float, y: float, theta: float, v: float, omega: float, dt: float
                  ) -> tuple[float, float, float]:
    """Integrate the unicycle (Eq. 1) exactly over ``dt`` with constant ``v`` and ``omega``.

    The path is a circular arc (a straight segment when ``omega`` is zero); the closed form
    uses ``sinc``-style terms so that it is exact and smooth as ``omega -> 0``.

    Returns
    -------
    (x, y, theta) after ``dt``; theta is not wrapped.
    """
    half = 0.5 * omega * dt
    if abs(half) < 1e-6:
        # Series of sin(h)/h to fourth order: exact to machine precision here.
        sinc = 1.0 - half * half / 6.0
    else:
        sinc = math.sin(half) / half
    dist = v * dt * sinc
    mid = theta + half
    return x + dist * math.cos(mid), y + dist * math.sin(mid), theta + omega * dt


def offset_point(x: float, y: float, theta: float, d: float) -> tuple[float, float]:
    """Reference point R at distance ``d`` ahead of the wheel-axle centre (Eq. 2)."""
    return x + d * math.cos(theta), y + d * math.sin(theta)
