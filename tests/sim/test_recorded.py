"""RecordedPerson and load_person_csv: derived motion from known paths and file validation."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from companion.errors import DataError
from companion.sim.recorded import RecordedPerson, load_person_csv

# Smoothing distorts the motion within a few time constants of the track ends (the spline's
# natural end conditions force zero curvature there), so comparisons skip this margin (s).
END_MARGIN = 3.0


def irregular_times(seed: int, duration: float = 40.0) -> np.ndarray:
    """Sample times with random steps in [0.05, 0.5] s, starting at 2.5 s."""
    rng = np.random.default_rng(seed)
    steps = rng.uniform(0.05, 0.5, size=int(duration / 0.05))
    t = np.concatenate([[0.0], np.cumsum(steps)])
    return 2.5 + t[t <= duration]


def write_csv(path: Path, t, x, y, header: str = "t,x,y") -> Path:
    lines = [header] + [f"{float(a)!r},{float(b)!r},{float(c)!r}" for a, b, c in zip(t, x, y)]
    path.write_text("\n".join(lines) + "\n")
    return path


def inner_times(person: RecordedPerson) -> np.ndarray:
    return np.arange(END_MARGIN, person.duration - END_MARGIN, 0.05)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_straight_line_at_constant_speed(tmp_path, seed):
    t = irregular_times(seed)
    speed, heading = 1.2, 0.7
    x = 1.0 + speed * math.cos(heading) * (t - t[0])
    y = -2.0 + speed * math.sin(heading) * (t - t[0])
    person = load_person_csv(write_csv(tmp_path / "line.csv", t, x, y))
    assert person.duration == pytest.approx(t[-1] - t[0])
    assert person.t0 == pytest.approx(t[0])
    # A straight line at constant speed is reproduced exactly, even at the ends.
    for tau in np.arange(0.0, person.duration, 0.05):
        s = person.state(tau)
        assert s.v == pytest.approx(speed, abs=1e-6)
        assert s.theta == pytest.approx(heading, abs=1e-6)
        assert s.omega == pytest.approx(0.0, abs=1e-6)
        assert s.x == pytest.approx(1.0 + speed * math.cos(heading) * tau, abs=1e-6)
        assert s.y == pytest.approx(-2.0 + speed * math.sin(heading) * tau, abs=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("turn", [1.0, -1.0])
def test_circle(tmp_path, seed, turn):
    """Radius 3 m at 1 m/s: turn rate 1/3 rad/s; the heading wraps several times."""
    t = irregular_times(seed, duration=60.0)
    radius, speed = 3.0, 1.0
    rate = turn * speed / radius
    phase = rate * (t - t[0])
    x = turn * radius * np.sin(phase)
    y = turn * radius * (1.0 - np.cos(phase))
    person = load_person_csv(write_csv(tmp_path / "circle.csv", t, x, y))
    for tau in inner_times(person):
        s = person.state(tau)
        assert s.v == pytest.approx(speed, abs=0.005)
        assert math.remainder(s.theta - rate * tau, 2 * math.pi) == pytest.approx(0.0, abs=0.01)
        assert s.omega == pytest.approx(rate, abs=0.01)
        assert -math.pi < s.theta <= math.pi
        assert s.x == pytest.approx(radius * math.sin(rate * tau) * turn, abs=0.01)
        assert s.y == pytest.approx(turn * radius * (1.0 - math.cos(rate * tau)), abs=0.01)


def test_smoothing_removes_kinks_of_piecewise_linear_tracks():
    """Like the ETH/UCY tracks: straight pieces 1.2 s long sampled every 0.4 s, here zigzagging
    at +-0.4 rad (a 2.4 s period). Finite differences jump by 0.8 rad at each joint; the
    default smoothing (tau = 0.5 s, gain ~1/4 at this period) keeps the heading within
    0.15 rad of the mean direction, the speed within 0.02 m/s of the mean speed and the turn
    rate finite and moderate."""
    speed = 1.2
    corners = [np.zeros(2)]
    for k in range(30):
        a = 0.4 if k % 2 == 0 else -0.4
        corners.append(corners[-1] + speed * 1.2 * np.array([math.cos(a), math.sin(a)]))
    corners = np.array(corners)
    t_corner = 1.2 * np.arange(len(corners))
    t = np.arange(0.0, t_corner[-1] + 1e-9, 0.4)
    x, y = np.interp(t, t_corner, corners[:, 0]), np.interp(t, t_corner, corners[:, 1])
    person = RecordedPerson(t, x, y)
    states = [person.state(tau) for tau in inner_times(person)]
    assert max(abs(s.theta) for s in states) < 0.15
    mean_speed = speed * math.cos(0.4)
    assert max(abs(s.v - mean_speed) for s in states) < 0.02
    assert max(abs(s.omega) for s in states) < 0.5


def test_standing_person_keeps_heading():
    """Walk along +y, stand for 5 s, walk along +x: heading is held while standing and the
    turn rate is 0 there."""
    t = np.arange(0.0, 30.0 + 1e-9, 0.2)
    x = np.where(t < 10, 0.0, np.where(t < 15, 0.0, t - 15.0))
    y = np.where(t < 10, t, 10.0)
    person = RecordedPerson(t, x, y)
    before = person.state(9.0)
    assert before.theta == pytest.approx(math.pi / 2, abs=0.02)
    # The smoothed stop and start take about 1.5 s (three time constants) each.
    for tau in np.arange(11.5, 13.5, 0.05):
        s = person.state(tau)
        assert s.v < 0.1
        assert s.theta == pytest.approx(math.pi / 2, abs=0.1)
        assert s.omega == 0.0
    assert person.state(20.0).theta == pytest.approx(0.0, abs=0.02)


def test_starts_standing_uses_first_walking_heading():
    t = np.arange(0.0, 20.0 + 1e-9, 0.4)
    x = np.where(t < 5, 3.0, 3.0 - (t - 5.0))
    y = np.full_like(t, 1.0)
    person = RecordedPerson(t, x, y)
    assert abs(person.state(0.0).theta) == pytest.approx(math.pi, abs=0.02)
    assert person.state(0.0).omega == 0.0


def test_never_moving_person_faces_zero():
    t = np.arange(0.0, 5.0, 0.4)
    person = RecordedPerson(t, np.full_like(t, 2.0), np.full_like(t, -1.0))
    s = person.state(1.0)
    assert (s.x, s.y, s.theta, s.omega) == pytest.approx((2.0, -1.0, 0.0, 0.0))
    assert s.v == pytest.approx(0.0, abs=1e-9)


def test_before_start_and_after_end():
    t = 7.0 + np.arange(0.0, 10.0 + 1e-9, 0.5)
    x, y = 0.8 * (t - 7.0), np.zeros_like(t)
    person = RecordedPerson(t, x, y)
    assert person.duration == pytest.approx(10.0)
    assert person.state(-3.0) == person.state(0.0)
    end = person.state(person.duration)
    assert end.v == pytest.approx(0.8)
    after = person.state(person.duration + 5.0)
    assert (after.x, after.y, after.theta) == pytest.approx((end.x, end.y, end.theta))
    assert (after.v, after.omega) == (0.0, 0.0)


def test_rejects_bad_arrays():
    t = np.arange(6.0)
    with pytest.raises(DataError, match="strictly increasing"):
        RecordedPerson(t[::-1], t, t)
    with pytest.raises(DataError, match="at least 5"):
        RecordedPerson(t[:4], t[:4], t[:4])
    with pytest.raises(DataError, match="finite"):
        RecordedPerson(t, np.where(t == 3, np.nan, t), t)
    with pytest.raises(DataError, match="smoothing"):
        RecordedPerson(t, t, t, smoothing=-1.0)


GOOD = ["t,x,y", "0,0,0", "0.4,0.5,0", "0.9,1.0,0.1", "1.2,1.5,0.1", "1.6,2.0,0.2"]


def test_header_and_cells_tolerate_spaces_and_blank_lines(tmp_path):
    path = tmp_path / "walk.csv"
    path.write_text(" t , x ,y\n" + "\n".join(GOOD[1:3]) + "\n\n 0.9 , 1.0, 0.1\n"
                    + "\n".join(GOOD[4:]) + "\n")
    assert load_person_csv(path).duration == pytest.approx(1.6)


@pytest.mark.parametrize("lines, line_no, words", [
    (["t,x"] + GOOD[1:], 1, ["header"]),
    (["time,x,y"] + GOOD[1:], 1, ["header"]),
    (["t,x,y,z"] + GOOD[1:], 1, ["header"]),
    (GOOD[:3] + ["0.7,1"] + GOOD[3:], 4, ["3 cells"]),
    (GOOD[:3] + ["0.7,1,2,3"] + GOOD[3:], 4, ["3 cells"]),
    (GOOD[:6] + ["2.0,abc,0"], 7, ["column 'x'", "expected a number", "'abc'"]),
    (GOOD[:2] + ["0.4,0.5,"] + GOOD[3:], 3, ["column 'y'", "expected a number"]),
    (GOOD[:3] + ["0.7,nan,0"] + GOOD[3:], 4, ["column 'x'", "finite"]),
    (GOOD[:3] + ["inf,1,0"] + GOOD[3:], 4, ["column 't'", "finite"]),
    (GOOD[:3] + ["0.4,1,0"] + GOOD[3:], 4, ["duplicate"]),
    (GOOD[:3] + ["0.2,1,0"] + GOOD[3:], 4, ["unsorted"]),
])
def test_malformed_file_names_file_and_line(tmp_path, lines, line_no, words):
    path = tmp_path / "walk.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError) as info:
        load_person_csv(path)
    message = str(info.value)
    assert "\n" not in message
    assert f"walk.csv:{line_no}:" in message
    for word in words:
        assert word in message


@pytest.mark.parametrize("content, words", [
    ("", ["walk.csv:1:", "empty"]),
    ("\n\n", ["walk.csv:1:", "empty"]),
    ("t,x,y\n", ["walk.csv", "at least 5 samples", "got 0"]),
    ("\n".join(GOOD[:5]) + "\n", ["walk.csv", "at least 5 samples", "got 4"]),
])
def test_empty_or_short_file(tmp_path, content, words):
    path = tmp_path / "walk.csv"
    path.write_text(content)
    with pytest.raises(DataError) as info:
        load_person_csv(path)
    for word in words:
        assert word in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(DataError, match="nowhere.csv: cannot read"):
        load_person_csv(tmp_path / "nowhere.csv")


def test_binary_file(tmp_path):
    path = tmp_path / "walk.csv"
    path.write_bytes(b"\xff\xfe\x00t,x,y\n")
    with pytest.raises(DataError, match="walk.csv"):
        load_person_csv(path)


def test_a_dense_recording_gives_the_same_person_as_a_sparser_one():
    """A 1 kHz recording is averaged into 20 ms bins before smoothing (it costs what a 50 Hz
    one does); the person it gives matches the same walk sampled at 50 Hz."""
    def walk(rate):
        t = np.arange(0.0, 60.0, 1.0 / rate)
        return t, 3.0 * np.sin(0.3 * t), 3.0 * (1.0 - np.cos(0.3 * t))

    dense, sparse = RecordedPerson(*walk(1000.0)), RecordedPerson(*walk(50.0))
    for t in np.arange(2.0, 58.0, 0.7):
        a, b = dense.state(t), sparse.state(t)
        assert math.hypot(a.x - b.x, a.y - b.y) < 0.005
        assert abs(a.v - b.v) < 0.01 and abs(a.omega - b.omega) < 0.01


def test_samples_too_close_together_are_one_line_naming_the_file(tmp_path):
    """50 samples 1 ns apart: the smoothing averages them into one, which is not a walk; the
    error names the file and the span (an IndexError traceback before)."""
    t = np.arange(50) * 1e-9
    path = write_csv(tmp_path / "ns.csv", t, 0.01 * np.arange(50), np.zeros(50))
    with pytest.raises(DataError, match=r"ns\.csv: the samples span 4\.9e-08 s; expected at "
                                        r"least 5 samples more than 0\.02 s apart"):
        load_person_csv(path)
