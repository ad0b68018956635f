"""Whether the velocity a detector reports agrees with where it puts the person.

A detector that reports speed and heading (a people tracker of its own, a worn sensor) may
report them wrong but in range: a person standing still reported walking at 3 m/s, turning
at 2 pi rad/s. The walker filter trusts what is reported, and a wrong velocity carried over
the detections' latency moves the estimate away from the person while its stated
uncertainty stays small; the keep-out rules, which trust the estimate, then let the robot
close in. The positions are the measurement that cannot be fooled this way: over a short
window their least-squares slope is the person's mean velocity there, and the mean of the
reported velocities over the same window must agree with it within their combined
uncertainty (:func:`motion_nis`). Where it does not, the tracker uses the detections for
their position only (docs/sensing.md).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import NamedTuple

from companion.params import TrackerParams
from companion.tracking.walker import MIN_STD
from companion.types import PersonDetection

#: Fewest detections, and shortest span of time (s), over which positions give a velocity;
#: the most that are used (the newest), which bounds the cost at a high detection rate.
MIN_DETECTIONS = 4
MIN_SPAN_S = 0.15
MAX_DETECTIONS = 6


def reports_motion(d: PersonDetection) -> bool:
    """``d`` reports a speed (and with it a turn rate, or a heading)."""
    return d.speed is not None


def without_motion(d: PersonDetection) -> PersonDetection:
    """``d`` as a detection of the position alone."""
    return dataclasses.replace(d, heading=None, heading_std=None, speed=None, turn_rate=None,
                               velocity_std=None)


class Motion(NamedTuple):
    """What one detection brings to the check: its time (s), position (m), position variance
    (m^2: the larger diagonal entry plus the off-diagonal one, a bound for any direction),
    and its report (``reported`` False: none): the speed (m/s, absolute), the velocity
    ``(vx, vy)`` (m/s, 0 without a heading), the speed's variance and the heading's times the
    speed squared (m^2/s^2)."""

    t: float
    x: float
    y: float
    var: float
    reported: bool
    directed: bool
    speed: float
    vx: float
    vy: float
    speed_var: float
    heading_var: float


def motion_of(d: PersonDetection, p: TrackerParams) -> Motion:
    """The :class:`Motion` of ``d`` (``p`` gives the noise of what it does not state)."""
    c = d.covariance
    var = max(c[0], c[3]) + abs(c[1]) if c else p.position_std_m ** 2
    if d.speed is None:
        return Motion(d.t, d.x, d.y, var, False, False, 0.0, 0.0, 0.0, 0.0, 0.0)
    speed_var = (d.velocity_std[0] if d.velocity_std else p.initial_speed_std) ** 2
    if d.heading is None:
        return Motion(d.t, d.x, d.y, var, True, False, abs(d.speed), 0.0, 0.0, speed_var, 0.0)
    h_std = p.heading_std_rad if d.heading_std is None else d.heading_std
    return Motion(d.t, d.x, d.y, var, True, True, abs(d.speed), d.speed * math.cos(d.heading),
                  d.speed * math.sin(d.heading), speed_var, (d.speed * h_std) ** 2)


def motion_nis(window: Sequence[Motion], floor_mps: float, scale: float = 1.0) -> float:
    """Squared distance between the mean of the velocities reported over ``window`` (time
    order, the newest last; the newest :data:`MAX_DETECTIONS` of it) and the slope of a
    weighted least-squares line through its positions against time (position variances
    times ``scale``), over their variances and ``floor_mps`` squared, the tolerance for a
    walk that is not straight over the window (``tracker.motion_floor_mps``). Compared with
    ``tracker.motion_gate_chi2`` (2 degrees of freedom; where a report has no heading the
    mean speed is compared with the slope's magnitude). 0 where the window reports no speed
    or is too short to tell (fewer than :data:`MIN_DETECTIONS`, or less than
    :data:`MIN_SPAN_S`)."""
    window = window[-MAX_DETECTIONS:]
    if len(window) < MIN_DETECTIONS or window[-1].t - window[0].t < MIN_SPAN_S:
        return 0.0
    t0, floor = window[-1].t, MIN_STD ** 2
    sw = swt = swtt = swx = swtx = swy = swty = 0.0      # the positions' line
    n = vx = vy = speed = var = across = 0.0             # the reports' mean and variance
    directed = True
    for t, x, y, p_var, reported, has_heading, s, mx, my, s_var, h_var in window:
        w = 1.0 / max(scale * p_var, floor)
        t -= t0
        sw, swt, swtt = sw + w, swt + w * t, swtt + w * t * t
        swx, swtx, swy, swty = swx + w * x, swtx + w * t * x, swy + w * y, swty + w * t * y
        if reported:
            n, speed, var, across = n + 1.0, speed + s, var + s_var, across + h_var
            vx, vy, directed = vx + mx, vy + my, directed and has_heading
    if not n:
        return 0.0
    spread = sw * swtt - swt * swt
    fx, fy = (sw * swtx - swt * swx) / spread, (sw * swty - swt * swy) / spread
    total = var / n + sw / spread + floor_mps ** 2   # reports, slope, floor
    if directed:
        nis = ((vx / n - fx) ** 2 + (vy / n - fy) ** 2) / (total + across / n)
    else:
        nis = (speed / n - math.hypot(fx, fy)) ** 2 / total
    return nis if math.isfinite(nis) else math.inf
