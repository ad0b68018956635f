"""A person driven by recorded positions: :class:`RecordedPerson` and :func:`load_person_csv`.

A recording holds only positions ``(t, x, y)``, at any rate. Heading, speed and turn rate
come from a cubic smoothing spline of x(t) and y(t) with time-proportional weights and
``lam = tau^4``, a low-pass filter with time constant ``tau`` (default 0.5 s) whatever the
sample rate, tabulated once on a dense grid (docs/model.md, section 7, explains the choice).
"""

from __future__ import annotations

import csv
import math
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.interpolate import make_smoothing_spline

from companion.config import MAX_DURATION
from companion.errors import DataError
from companion.geometry import wrap_pi
from companion.io import MAX_CELL, parse_number
from companion.types import PersonState

#: Column names a person CSV must have, in this order.
CSV_COLUMNS = ("t", "x", "y")
#: Fewest samples accepted; :func:`scipy.interpolate.make_smoothing_spline` needs 5.
MIN_SAMPLES = 5
#: Default smoothing time constant tau (s); see the module docstring.
DEFAULT_SMOOTHING = 0.5
#: Default speed (m/s) below which the person counts as standing.
DEFAULT_STANDING_SPEED = 0.1
#: Default step (s) of the grid on which the smoothed motion is tabulated.
DEFAULT_GRID_STEP = 0.01
#: A gap between samples is a hole (the person not observed) when it is longer than this (s)
#: and than HOLE_RATIO times the track's median sample interval (:func:`holes`).
HOLE_MIN_S = 1.0
HOLE_RATIO = 3.0


class RecordedPerson:
    """A person replaying recorded positions: the true path of a simulation, from which the
    sensing model samples detections (the controller never sees the spline itself).

    Implements the :class:`companion.sim.person.PersonMotion` protocol; :meth:`observed` is
    False inside the recording's holes (:func:`holes`), where no detection is made.

    Parameters
    ----------
    t, x, y : sequence of float
        Sample times (s, strictly increasing, any spacing) and positions (m), all finite, at
        least :data:`MIN_SAMPLES` samples. Time is shifted so that the first sample is at
        ``t = 0``; the original time of the first sample is kept in :attr:`t0`.
    smoothing : float
        Smoothing time constant ``tau`` (s), ``>= 0``; the spline's ``lam = tau**4`` with
        time-proportional weights (module docstring). ``0`` interpolates the samples.
    standing_speed : float
        Speed (m/s) below which the person is standing: the heading is held at its last value
        while moving (before the first movement: the first heading while moving; 0 if the
        person never moves) and the turn rate is 0.
    grid_step : float
        Step (s) of the grid on which the motion is tabulated.

    Attributes
    ----------
    t0 : float
        Original time (s) of the first sample.
    holes : tuple of (start, end)
        The recording's holes (s, relative to the first sample).
    samples_t, samples_x, samples_y : ndarray
        The samples, time shifted to start at 0.
    grid : dict of ndarray
        The tabulated motion: ``t``, ``x``, ``y``, ``theta`` (unwrapped), ``v``, ``omega``.

    Notes
    -----
    :meth:`state` returns, for ``0 <= t <= duration``, the *smoothed* position, speed
    ``v = |p'|``, heading ``atan2(y', x')`` and turn rate ``omega = (x' y'' - y' x'') / v^2``
    (the time derivative of that heading, exact for the spline), interpolated linearly on the
    grid (the heading through its unwrapped value, returned wrapped to (-pi, pi]). Before
    ``t = 0`` it returns the state at 0. After ``duration`` the person stops where the
    smoothed track ends: final position and heading, ``v = 0`` and ``omega = 0``.

    Raises
    ------
    DataError
        If the samples are too few, of different lengths, not finite or not strictly
        increasing in time, or a parameter is out of range.
    """

    def __init__(self, t: Sequence[float], x: Sequence[float], y: Sequence[float],
                 smoothing: float = DEFAULT_SMOOTHING,
                 standing_speed: float = DEFAULT_STANDING_SPEED,
                 grid_step: float = DEFAULT_GRID_STEP):
        t_arr, x_arr, y_arr = _check_samples(t, x, y)
        _check_parameters(smoothing, standing_speed, grid_step)
        self.t0 = float(t_arr[0])
        self.smoothing = float(smoothing)
        self.standing_speed = float(standing_speed)
        self.samples_t = t_arr - self.t0
        self.samples_x = x_arr
        self.samples_y = y_arr
        self.holes = holes(self.samples_t)
        grid = _tabulate(self.samples_t, x_arr, y_arr, self.smoothing, self.standing_speed,
                         grid_step)
        self._step = float(grid["t"][1] - grid["t"][0])
        self._last = len(grid["t"]) - 1
        # Plain lists: scalar indexing in state() is several times faster than on arrays.
        self._x = grid["x"].tolist()
        self._y = grid["y"].tolist()
        self._theta = grid["theta"].tolist()
        self._v = grid["v"].tolist()
        self._omega = grid["omega"].tolist()
        self.grid = grid

    @property
    def duration(self) -> float:
        """Time (s) from the first to the last sample."""
        return float(self.samples_t[-1])

    def observed(self, t: float) -> bool:
        """Whether the person could be detected at ``t`` (not inside a hole)."""
        return not any(a < t < b for a, b in self.holes)

    def state(self, t: float) -> PersonState:
        """Smoothed person state at time ``t`` (s, first sample at 0); see the class notes."""
        t = float(t)
        if t > self.duration:
            return PersonState(self._x[-1], self._y[-1], wrap_pi(self._theta[-1]), 0.0, 0.0)
        s = max(t, 0.0) / self._step
        i = min(int(s), self._last - 1)
        return self._at(i, min(s - i, 1.0))

    def _at(self, i: int, frac: float) -> PersonState:
        """Linear interpolation between grid points ``i`` and ``i + 1`` (``frac`` in [0, 1])."""
        def lerp(a: list[float]) -> float:
            return a[i] + frac * (a[i + 1] - a[i])

        return PersonState(lerp(self._x), lerp(self._y), wrap_pi(lerp(self._theta)),
                           lerp(self._v), lerp(self._omega))


def _check_samples(t: Sequence[float], x: Sequence[float], y: Sequence[float]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate recorded samples and return them as float arrays."""
    arrays = [np.asarray(a, dtype=float) for a in (t, x, y)]
    if any(a.ndim != 1 for a in arrays) or len({len(a) for a in arrays}) != 1:
        raise DataError("RecordedPerson: t, x and y must be 1-D sequences of equal length, "
                        f"got lengths {[a.size for a in arrays]}")
    t_arr, x_arr, y_arr = arrays
    if len(t_arr) < MIN_SAMPLES:
        raise DataError(f"RecordedPerson: expected at least {MIN_SAMPLES} samples, "
                        f"got {len(t_arr)}")
    for name, a in zip(CSV_COLUMNS, arrays):
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise DataError(f"RecordedPerson: {name}[{bad[0]}] is {a[bad[0]]}, "
                            "expected a finite number")
    bad = np.flatnonzero(np.diff(t_arr) <= 0.0)
    if bad.size:
        k = bad[0] + 1
        raise DataError(f"RecordedPerson: t must be strictly increasing, got t[{k}] = "
                        f"{t_arr[k]} after t[{k - 1}] = {t_arr[k - 1]}")
    return t_arr, x_arr, y_arr


def _check_parameters(smoothing: float, standing_speed: float, grid_step: float) -> None:
    if not 0.0 <= smoothing < math.inf:
        raise DataError(f"RecordedPerson: smoothing: expected a time in s >= 0, got {smoothing}")
    if not 0.0 <= standing_speed < math.inf:
        raise DataError("RecordedPerson: standing_speed: expected a speed in m/s >= 0, "
                        f"got {standing_speed}")
    if not 0.0 < grid_step < math.inf:
        raise DataError(f"RecordedPerson: grid_step: expected a time in s > 0, got {grid_step}")


def sample_weights(t: np.ndarray) -> np.ndarray:
    """Time each sample stands for: half the span to its neighbours (s)."""
    gaps = np.diff(t)
    w = np.empty_like(t)
    w[0], w[-1] = 0.5 * gaps[0], 0.5 * gaps[-1]
    w[1:-1] = 0.5 * (gaps[:-1] + gaps[1:])
    return w


def smooth(t: np.ndarray, values: np.ndarray, smoothing: float):
    """Cubic smoothing spline of ``values(t)`` with time constant ``smoothing`` (s).

    Returns a :class:`scipy.interpolate.BSpline`; ``lam = smoothing**4`` with the weights of
    :func:`sample_weights` (module docstring).
    """
    return make_smoothing_spline(t, values, w=sample_weights(t), lam=smoothing ** 4)


def hold_heading(theta: np.ndarray, moving: np.ndarray) -> np.ndarray:
    """Replace the heading while not ``moving`` by the last heading while moving.

    Before the first moving sample the first moving heading is used; if the person never
    moves the heading is 0.
    """
    if not moving.any():
        return np.zeros_like(theta)
    idx = np.where(moving, np.arange(len(theta)), -1)
    idx = np.maximum.accumulate(idx)
    idx[idx < 0] = np.argmax(moving)
    return theta[idx]


#: Samples closer together than the smoothing time constant over this are averaged before
#: smoothing (:func:`binned`): the spline's cost grows with the samples, not its result.
BIN_FRACTION = 25.0


def binned(t: np.ndarray, x: np.ndarray, y: np.ndarray, width: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The samples averaged over consecutive bins ``width`` s wide, when they are denser than
    that (a 1 kHz recording); sparser tracks are returned as they are."""
    if width <= 0.0 or len(t) < 3 or float(np.median(np.diff(t))) >= width:
        return t, x, y
    _, which = np.unique(np.floor(t / width).astype(np.int64), return_inverse=True)
    count = np.bincount(which)
    return (np.bincount(which, t) / count, np.bincount(which, x) / count,
            np.bincount(which, y) / count)


def _tabulate(t: np.ndarray, x: np.ndarray, y: np.ndarray, smoothing: float,
              standing_speed: float, grid_step: float) -> dict[str, np.ndarray]:
    """Smoothed position, heading (unwrapped), speed and turn rate on a grid over [0, t[-1]]."""
    n = max(int(math.ceil(t[-1] / grid_step)), 1) + 1
    tg = np.linspace(0.0, t[-1], n)
    width, span = smoothing / BIN_FRACTION, t[-1] - t[0]
    t, x, y = binned(t, x, y, width)
    if len(t) < MIN_SAMPLES:
        raise DataError(f"RecordedPerson: the samples span {span:.3g} s; expected at "
                        f"least {MIN_SAMPLES} samples more than {width:g} s apart (the "
                        f"smoothing of {smoothing:g} s averages closer ones)")
    sx, sy = smooth(t, x, smoothing), smooth(t, y, smoothing)
    dx, dy = sx.derivative(1)(tg), sy.derivative(1)(tg)
    ddx, ddy = sx.derivative(2)(tg), sy.derivative(2)(tg)
    speed = np.hypot(dx, dy)
    moving = speed >= standing_speed
    if standing_speed == 0.0:
        moving &= speed > 0.0
    theta = np.unwrap(hold_heading(np.arctan2(dy, dx), moving))
    omega = np.zeros_like(speed)
    omega[moving] = (dx * ddy - dy * ddx)[moving] / speed[moving] ** 2
    return {"t": tg, "x": sx(tg), "y": sy(tg), "theta": theta, "v": speed, "omega": omega}


def load_person_csv(path: str | Path, smoothing: float = DEFAULT_SMOOTHING,
                    standing_speed: float = DEFAULT_STANDING_SPEED,
                    grid_step: float = DEFAULT_GRID_STEP) -> RecordedPerson:
    """Load a recorded person from a CSV file.

    The file is UTF-8 text with a header of exactly the three columns ``t,x,y`` (time in s,
    position in m; spaces around names and values are allowed) and then one sample per row.
    Extra columns are an error (so that a file meant for something else is not silently
    misread). Blank lines are skipped. The sample rate may be irregular; times must be strictly
    increasing and are shifted so that the first sample is at ``t = 0``.

    Parameters
    ----------
    path : str or Path
    smoothing, standing_speed, grid_step : float
        As for :class:`RecordedPerson`.

    Raises
    ------
    DataError
        With a one-line message naming the file, the line and what was expected, e.g.
        ``walk.csv:7: column 'x': expected a number, got 'abc'``: for a missing, unreadable
        or empty file, a wrong header, a row with the wrong number of cells, a cell that is
        not a finite number, a timestamp that is a duplicate of or earlier than the one before
        it, or fewer than :data:`MIN_SAMPLES` samples.
    """
    t, x, y = read_person_csv(path)
    try:
        return RecordedPerson(t, x, y, smoothing, standing_speed, grid_step)
    except DataError as exc:
        raise DataError(f"{path}: {str(exc).removeprefix('RecordedPerson: ')}") from None


def read_person_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read and validate the samples of a person CSV (see :func:`load_person_csv`).

    A well-formed file is read by numpy's compiled CSV reader, without a Python object per
    row (a million rows in about a second); a file it rejects, or whose numbers fail a check,
    is read again row by row, which names the first bad line."""
    name = str(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            fast = _parse_fast(f)
        if fast is not None:
            return fast
        with open(path, newline="", encoding="utf-8-sig") as f:
            return tuple(np.array(c) for c in _parse_rows(name, csv.reader(f)))
    except OSError as e:
        raise DataError(f"{name}: cannot read file: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise DataError(f"{name}: not a UTF-8 text file ({e.reason})") from None
    except csv.Error as e:
        raise DataError(f"{name}: malformed CSV: {e}") from None


def _parse_fast(f) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The samples of a well-formed person CSV read at once, or None for anything else
    (:func:`_parse_rows` then finds what is wrong)."""
    header = f.readline()
    while header and not header.strip():
        header = f.readline()
    if tuple(c.strip() for c in header.split(",")) != CSV_COLUMNS:
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")     # "input contained no data"
            data = np.loadtxt(f, delimiter=",", comments=None, ndmin=2)
    except (ValueError, UserWarning):
        return None
    if data.shape[1] != len(CSV_COLUMNS) or len(data) < MIN_SAMPLES \
            or not np.all(np.abs(data) <= MAX_CELL) or not np.all(np.diff(data[:, 0]) > 0.0) \
            or data[-1, 0] - data[0, 0] > MAX_DURATION:
        return None
    return data[:, 0].copy(), data[:, 1].copy(), data[:, 2].copy()


def _parse_rows(name: str, reader) -> tuple[list[float], list[float], list[float]]:
    header = next(reader, None)
    while header is not None and not any(c.strip() for c in header):
        header = next(reader, None)
    if header is None:
        raise DataError(f"{name}:1: expected header 't,x,y', the file is empty")
    _check_header(name, reader.line_num, header)
    columns: tuple[list[float], list[float], list[float]] = ([], [], [])
    last_line = 0
    for row in reader:
        if not any(c.strip() for c in row):
            continue
        line = reader.line_num
        values = _parse_row(name, line, row)
        if columns[0] and values[0] <= columns[0][-1]:
            kind = "duplicate" if values[0] == columns[0][-1] else "unsorted"
            raise DataError(f"{name}:{line}: column 't': {kind} timestamp {values[0]:g}, "
                            f"expected a time after {columns[0][-1]:g} (line {last_line})")
        if columns[0] and values[0] - columns[0][0] > MAX_DURATION:
            raise DataError(f"{name}:{line}: column 't': timestamp {values[0]!r} is "
                            f"{values[0] - columns[0][0]:g} s after the first, expected a "
                            f"recording of at most {MAX_DURATION:g} s (a day)")
        for col, value in zip(columns, values):
            col.append(value)
        last_line = line
    if len(columns[0]) < MIN_SAMPLES:
        raise DataError(f"{name}: expected at least {MIN_SAMPLES} samples, "
                        f"got {len(columns[0])}")
    return columns


def _check_header(name: str, line: int, header: list[str]) -> None:
    got = [c.strip() for c in header]
    if tuple(got) != CSV_COLUMNS:
        raise DataError(f"{name}:{line}: expected header 't,x,y', got {','.join(got)!r}")


def _parse_row(name: str, line: int, row: list[str]) -> tuple[float, float, float]:
    if len(row) != len(CSV_COLUMNS):
        raise DataError(f"{name}:{line}: expected {len(CSV_COLUMNS)} cells (t,x,y), "
                        f"got {len(row)}")
    t, x, y = (parse_number(f"{name}:{line}", col, cell)
               for col, cell in zip(CSV_COLUMNS, row))
    return t, x, y


def holes(t: np.ndarray, min_gap: float = HOLE_MIN_S, ratio: float = HOLE_RATIO
          ) -> tuple[tuple[float, float], ...]:
    """The gaps between samples at ``t`` where the person was not observed: gaps longer than
    ``min_gap`` s and than ``ratio`` times the track's median sample interval. A sparse but
    regular track has none."""
    gaps = np.diff(t)
    if gaps.size == 0:
        return ()
    long = (gaps > min_gap) & (gaps > ratio * float(np.median(gaps)))
    return tuple((float(t[i]), float(t[i + 1])) for i in np.flatnonzero(long))
