"""Tracking moving things: circles over time -> the same circles with their velocities.

LiDAR clusters of body size and the other people detected on the person topic are tracked
one constant-velocity Kalman filter each (filterpy), state ``(x, vx, y, vy)``. Each update
predicts the tracks to the new time, assigns circles to tracks by least total distance
(scipy's ``linear_sum_assignment``) within a gate that grows with the time since a track's
last circle, starts tracks for the circles left over and drops tracks unseen for
``forget_s``. A track is reported after ``confirm`` circles; it is reported moving when its
speed is at least ``min_speed`` and more than 3 standard deviations from 0, else standing
(velocity 0): a standing cluster's fits wander with the side the LiDAR sees. docs/crowds.md.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter
from scipy.optimize import linear_sum_assignment

from companion.params import MoverParams
from companion.types import Circle

#: chi-square (2 degrees of freedom) of 3 standard deviations: a velocity this far from 0.
_MOVING_CHI2 = 9.0


@dataclass
class _Track:
    kf: KalmanFilter
    t: float            # time of the last circle
    hits: int = 1
    radius: float = 0.0


class MovingTracker:
    """See the module docstring. :meth:`update` takes the circles seen at one time;
    :meth:`circles` gives the confirmed tracks predicted to a time."""

    def __init__(self, params: MoverParams):
        self.params = params
        self.reset()

    def reset(self) -> None:
        self._tracks: list[_Track] = []
        self._t: float | None = None

    def update(self, circles: Sequence[Circle], t: float) -> tuple[Circle, ...]:
        """Take the circles seen at time ``t`` (s); return them in order, those that belong to
        a confirmed moving track with its velocity. Circles too large to be a person, pieces of
        walls (``piece``) and a repeated time are passed through; a time before the
        last starts over."""
        p = self.params
        if self._t is not None and t <= self._t:
            if t == self._t or not math.isfinite(t):
                return tuple(circles)
            self.reset()                  # the clock went back (a replay restarted)
        self._t = t
        index = [i for i, c in enumerate(circles)
                 if not c.piece and c.radius <= p.max_radius]
        self._tracks = [tr for tr in self._tracks if t - tr.t <= p.forget_s]
        for tr in self._tracks:
            self._predict(tr.kf, t - tr.t)
        pairs = self._assign([circles[i] for i in index], t)
        out = list(circles)
        used = set()
        for j, k in pairs:
            i, tr = index[j], self._tracks[k]
            c = circles[i]
            tr.kf.update(np.array((c.x, c.y)))
            tr.t, tr.hits, tr.radius = t, tr.hits + 1, c.radius
            used.add(j)
            vx, vy = self._velocity(tr)
            if vx or vy:
                out[i] = dataclasses.replace(c, vx=vx, vy=vy)
        for j, i in enumerate(index):
            if j not in used:
                self._tracks.append(self._start(circles[i], t))
        return tuple(out)

    def circles(self, t: float) -> tuple[Circle, ...]:
        """The confirmed tracks predicted to ``t`` (s) at their reported velocities, as circles
        with them (a standing one: where it was last seen, velocity 0)."""
        out = []
        for tr in self._tracks:
            if tr.hits < self.params.confirm or t - tr.t > self.params.forget_s:
                continue
            vx, vy = self._velocity(tr)       # a standing track is not moved by its noise
            dt = max(t - tr.t, 0.0)
            out.append(Circle(float(tr.kf.x[0] + vx * dt), float(tr.kf.x[2] + vy * dt),
                              tr.radius, None, vx, vy))
        return tuple(out)

    # -- the pieces -------------------------------------------------------------------------

    def _start(self, c: Circle, t: float) -> _Track:
        p = self.params
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.x = np.array((c.x, 0.0, c.y, 0.0))
        kf.P = np.diag((p.position_std ** 2, p.max_speed ** 2 / 4.0,
                        p.position_std ** 2, p.max_speed ** 2 / 4.0))
        kf.H = np.array(((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0)))
        kf.R = np.eye(2) * p.position_std ** 2
        return _Track(kf, t, 1, c.radius)

    def _predict(self, kf: KalmanFilter, dt: float) -> None:
        if dt <= 0.0:
            return
        kf.F = np.array(((1.0, dt, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0),
                         (0.0, 0.0, 1.0, dt), (0.0, 0.0, 0.0, 1.0)))
        kf.Q = Q_discrete_white_noise(2, dt, self.params.accel_std ** 2, block_size=2)
        kf.predict()

    def _assign(self, circles: list[Circle], t: float) -> list[tuple[int, int]]:
        """(circle, track) pairs of least total distance, each within its track's gate."""
        if not circles or not self._tracks:
            return []
        p = self.params
        seen = np.array([(c.x, c.y) for c in circles])
        at = np.array([(tr.kf.x[0], tr.kf.x[2]) for tr in self._tracks])
        gate = np.array([p.gate_m + p.max_speed * (t - tr.t) for tr in self._tracks])
        cost = np.hypot(seen[:, None, 0] - at[None, :, 0], seen[:, None, 1] - at[None, :, 1])
        big = 1e6
        rows, cols = linear_sum_assignment(np.where(cost <= gate[None, :], cost, big))
        return [(int(j), int(k)) for j, k in zip(rows, cols) if cost[j, k] <= gate[k]]

    def _velocity(self, tr: _Track) -> tuple[float, float]:
        """The track's velocity if it is confirmed and moving, else (0, 0)."""
        p = self.params
        if tr.hits < p.confirm:
            return 0.0, 0.0
        v = np.array((tr.kf.x[1], tr.kf.x[3]))
        cov = tr.kf.P[np.ix_((1, 3), (1, 3))]
        speed = math.hypot(*v)
        try:
            far = float(v @ np.linalg.solve(cov, v)) > _MOVING_CHI2
        except np.linalg.LinAlgError:
            far = False
        if speed < max(p.min_speed, 1e-9) or not far:
            return 0.0, 0.0
        return float(v[0]), float(v[1])
