"""Person motions (Eq. 3): pure functions of time returning :class:`PersonState`.

* :class:`SegmentPath`: pieces of constant curvature with linearly ramped speed, integrated in
  closed form; :func:`line`, :func:`circle` and :func:`u_shape` are built from it.
* :class:`Figure8`: the lemniscate of Eq. (23), traversed once per ``lap_time`` (the printed
  ``t`` is a phase, not seconds: docs/model.md R10).
* :class:`companion.sim.recorded.RecordedPerson`: samples from a CSV file.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from companion.geometry import wrap_pi
from companion.types import PersonState


class PersonMotion(Protocol):
    def state(self, t: float) -> PersonState:
        """Person pose and velocity at time ``t`` (s)."""


@dataclass(frozen=True)
class Segment:
    """A piece of path with constant curvature (1/m, positive turns left) over ``duration`` s,
    the speed ramping linearly from ``v_start`` to ``v_end`` (m/s)."""

    duration: float
    v_start: float
    v_end: float
    curvature: float = 0.0


def _advance(x: float, y: float, theta: float, seg: Segment, tau: float
             ) -> PersonState:
    """State ``tau`` seconds into ``seg`` starting from pose (x, y, theta); exact."""
    accel = (seg.v_end - seg.v_start) / seg.duration if seg.duration > 0 else 0.0
    s = seg.v_start * tau + 0.5 * accel * tau * tau
    v = seg.v_start + accel * tau
    k = seg.curvature
    th = theta + k * s
    if abs(k * s) < 1e-9:
        nx, ny = x + s * math.cos(theta), y + s * math.sin(theta)
    else:
        nx = x + (math.sin(th) - math.sin(theta)) / k
        ny = y - (math.cos(th) - math.cos(theta)) / k
    return PersonState(nx, ny, th, v, k * v)


class SegmentPath:
    """Person walking a chain of :class:`Segment` from a start pose.

    After the last segment the person keeps its final speed and curvature.
    """

    def __init__(self, start: tuple[float, float, float], segments: Sequence[Segment]):
        if not segments:
            raise ValueError("SegmentPath: at least one segment is needed")
        for i, seg in enumerate(segments):
            if seg.duration <= 0 or seg.v_start < 0 or seg.v_end < 0:
                raise ValueError(f"SegmentPath: segment {i} needs duration > 0 and speeds >= 0")
        self.segments = tuple(segments)
        self._t0 = [0.0]
        self._starts = [PersonState(start[0], start[1], start[2], segments[0].v_start,
                                    segments[0].curvature * segments[0].v_start)]
        for seg in self.segments[:-1]:
            s0 = self._starts[-1]
            end = _advance(s0.x, s0.y, s0.theta, seg, seg.duration)
            self._starts.append(end)
            self._t0.append(self._t0[-1] + seg.duration)

    @property
    def duration(self) -> float:
        return self._t0[-1] + self.segments[-1].duration

    def state(self, t: float) -> PersonState:
        t = max(t, 0.0)
        i = bisect.bisect_right(self._t0, t) - 1
        seg, s0 = self.segments[i], self._starts[i]
        tau = t - self._t0[i]
        if tau > seg.duration:  # beyond the last segment: hold final speed and curvature
            end = _advance(s0.x, s0.y, s0.theta, seg, seg.duration)
            hold = Segment(tau - seg.duration, seg.v_end, seg.v_end, seg.curvature)
            return _advance(end.x, end.y, end.theta, hold, tau - seg.duration)
        return _advance(s0.x, s0.y, s0.theta, seg, tau)


def line(start: tuple[float, float, float], speed: float) -> SegmentPath:
    """Straight walk from ``start`` (x, y, heading) at constant ``speed``."""
    return SegmentPath(start, [Segment(1.0, speed, speed, 0.0)])


def circle(start: tuple[float, float, float], radius: float, speed: float,
           turn: str = "left") -> SegmentPath:
    """Walk on a circle of ``radius`` at ``speed``, turning ``left`` (CCW) or ``right`` (CW)."""
    sign = 1.0 if turn == "left" else -1.0
    return SegmentPath(start, [Segment(1.0, speed, speed, sign / radius)])


@dataclass(frozen=True)
class Figure8:
    """The 8-shaped walk of Eq. (23) with phase ``s = 2*pi*t/lap_time + phase``.

    x(s) = 10 sin s cos s / (1 + sin^2 s) + 5,   y(s) = 6 cos s / (1 + sin^2 s) - 3.
    At phase 0 the person is at (5, 3) walking along +x.
    """

    lap_time: float = 60.0
    phase: float = 0.0

    @staticmethod
    def _point(s: float) -> tuple[float, float]:
        den = 1.0 + math.sin(s) ** 2
        return 10.0 * math.sin(s) * math.cos(s) / den + 5.0, 6.0 * math.cos(s) / den - 3.0

    @staticmethod
    def _tangent(s: float) -> tuple[float, float]:
        """Exact d/ds of :meth:`_point`."""
        sn, cs = math.sin(s), math.cos(s)
        den = 1.0 + sn * sn
        dden = 2.0 * sn * cs
        num_x, dnum_x = 10.0 * sn * cs, 10.0 * (cs * cs - sn * sn)
        num_y, dnum_y = 6.0 * cs, -6.0 * sn
        return ((dnum_x * den - num_x * dden) / den ** 2,
                (dnum_y * den - num_y * dden) / den ** 2)

    def state(self, t: float) -> PersonState:
        rate = 2.0 * math.pi / self.lap_time
        s = rate * t + self.phase
        x, y = self._point(s)
        dx, dy = self._tangent(s)
        # Curvature from the tangent's derivative (central difference of the exact tangent).
        h = 1e-5
        (ax, ay), (bx, by) = self._tangent(s - h), self._tangent(s + h)
        ddx, ddy = (bx - ax) / (2 * h), (by - ay) / (2 * h)
        speed2 = dx * dx + dy * dy
        theta = math.atan2(dy, dx)
        return PersonState(x, y, theta, math.sqrt(speed2) * rate,
                           (dx * ddy - dy * ddx) / speed2 * rate)


def u_shape(start: tuple[float, float, float] = (0.0, 0.0, 0.0), radius: float = 2.0,
            turn: str = "left") -> SegmentPath:
    """A U-shaped walk like the paper's Fig. 6: a straight with a speed-up and a slow-down,
    a half circle at walking pace, and a straight back with another speed-up and slow-down."""
    k = (1.0 if turn == "left" else -1.0) / radius
    v_turn = 0.6
    half = math.pi * radius / v_turn
    return SegmentPath(start, [
        Segment(4.0, 0.4, 1.1), Segment(4.0, 1.1, 1.1), Segment(3.0, 1.1, v_turn),
        Segment(half, v_turn, v_turn, k),
        Segment(3.0, v_turn, 1.2), Segment(4.0, 1.2, 1.2), Segment(4.0, 1.2, 0.3),
    ])


@dataclass(frozen=True)
class Move:
    """One phase of a :class:`ScriptedWalk`: for ``duration`` s, head for speed ``speed``
    (m/s, >= 0) at the walker's acceleration limit while turning at ``turn_rate`` (rad/s)."""

    duration: float
    speed: float
    turn_rate: float = 0.0


Row = tuple[float, float, float, float, float]   # x, y, theta (unwrapped), v, omega


def integrate_move(row: Row, move: Move, accel: float, grid_step: float) -> list[Row]:
    """The walker's states every ``grid_step`` s through ``move``, starting from ``row``
    (exact unicycle arcs, speed ramping towards ``move.speed`` at ``accel``)."""
    x, y, th, v, _ = row
    w = move.turn_rate
    out = []
    for _ in range(max(1, int(round(move.duration / grid_step)))):
        v_next = min(max(move.speed, v - accel * grid_step), v + accel * grid_step)
        s = 0.5 * (v + v_next) * grid_step
        if abs(w * grid_step) < 1e-12:
            x, y = x + s * math.cos(th), y + s * math.sin(th)
        else:
            r = s / (w * grid_step)
            x += r * (math.sin(th + w * grid_step) - math.sin(th))
            y -= r * (math.cos(th + w * grid_step) - math.cos(th))
        th += w * grid_step
        v = v_next
        out.append((x, y, th, v, w))
    return out


class ScriptedWalk:
    """A person walking a script of :class:`Move` phases: stop-and-go, turns on the spot,
    turnarounds. The unicycle is integrated exactly on a ``grid_step`` grid with the speed
    ramping towards each phase's target at ``accel`` (m/s^2); :meth:`state` interpolates it
    linearly. After the script the person stands still."""

    def __init__(self, start: tuple[float, float, float], moves: Sequence[Move],
                 accel: float = 1.5, grid_step: float = 0.01):
        if not moves or accel <= 0.0 or grid_step <= 0.0:
            raise ValueError("ScriptedWalk: needs moves, accel > 0 and grid_step > 0")
        for i, m in enumerate(moves):
            if not (m.duration > 0.0 and m.speed >= 0.0 and math.isfinite(m.turn_rate)):
                raise ValueError(f"ScriptedWalk: move {i} needs duration > 0, speed >= 0 and "
                                 "a finite turn rate")
        self.moves = tuple(moves)
        self.step = grid_step
        self.accel = accel
        # Only the row each move starts from is kept; a move's rows are integrated again when
        # asked for (a day's walk on a 0.02 s grid would be 4 million rows).
        self._starts: list[Row] = []
        self._ends: list[int] = []        # grid index of each move's last row
        row, end = (start[0], start[1], start[2], 0.0, 0.0), 0
        for m in self.moves:
            self._starts.append(row)
            rows = integrate_move(row, m, accel, grid_step)
            end += len(rows)
            self._ends.append(end)
            row = rows[-1]
        self._final = row
        self._cache: dict[int, list[Row]] = {}

    @property
    def duration(self) -> float:
        return self._ends[-1] * self.step

    def _move_rows(self, m: int) -> list[Row]:
        """The rows of move ``m`` after its start row (the last few moves' kept)."""
        rows = self._cache.get(m)
        if rows is None:
            if len(self._cache) >= 4:
                del self._cache[next(iter(self._cache))]
            rows = self._cache[m] = integrate_move(self._starts[m], self.moves[m], self.accel,
                                                   self.step)
        return rows

    def state(self, t: float) -> PersonState:
        last = self._ends[-1]
        s = max(t, 0.0) / self.step
        if s >= last:
            x, y, th, _, _ = self._final
            return PersonState(x, y, wrap_pi(th), 0.0, 0.0)
        i = min(int(s), last - 1)
        frac = min(s - i, 1.0)
        m = bisect.bisect_left(self._ends, i + 1)      # the move of grid rows i + 1
        first = self._ends[m - 1] if m else 0          # its start row
        rows = self._move_rows(m)
        a, b = (self._starts[m] if i == first else rows[i - first - 1]), rows[i - first]
        x, y, th, v = (a[j] + frac * (b[j] - a[j]) for j in range(4))
        return PersonState(x, y, wrap_pi(th), v, b[4])
