"""Property tests of the raw inputs of the standard stack (issue 21): for any generated LiDAR
scan, odometry stream or set of person detections the command is finite and within the
velocity and acceleration limits, and the step never raises. Counted per family
(tests/sweeps.py); odometry faults have their named reasons (docs/safety.md, fault 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import strategies as st

from companion.control import make_controller
from companion.control.base import saturate
from companion.params import Params
from companion.types import Observation, PersonDetection, PersonState, Pose, Scan
from stepping import step
from sweeps import QUICK, SLOW, assert_none_failed, sweep

P = Params()
S = P.supervisor
DV = max(S.accel_max, S.decel_max) * P.dt + 1e-9
DW = S.angular_accel_max * P.dt + 1e-9
PERSON = PersonState(0.25, 1.0, 0.0, 1.0, 0.0)
ANY = st.floats(allow_nan=True, allow_infinity=True)
WILD = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0, 1e308, -1e308, 1e-308])
NUM = ANY | WILD | st.floats(-5.0, 5.0)


def within_rate(cmd, v: float, omega: float) -> bool:
    return abs(cmd.v - v) <= DV and abs(cmd.omega - omega) <= DW


def drive(observations) -> None:
    """Step the lqr stack through ``observations``; every command finite, within the velocity
    limits and within the acceleration limits of the previous command, except that once the
    rate limits may restart from the first measured velocity (stops sent before any odometry
    say nothing of how the robot moves)."""
    sup = make_controller("lqr", P)
    sup.reset()
    prev, restarted = None, False
    for obs in observations:
        try:
            cmd = step(sup, obs)
        except Exception as exc:
            raise AssertionError(f"step raised {type(exc).__name__}: {exc}") from None
        assert math.isfinite(cmd.v) and math.isfinite(cmd.omega), cmd
        assert abs(cmd.v) <= P.robot.v_max + 1e-9 and abs(cmd.omega) <= P.robot.omega_max + 1e-9
        if prev is not None and not within_rate(cmd, prev.v, prev.omega):
            assert not restarted and obs.robot_velocity is not None, (cmd, prev)
            restarted = True
            v, omega = saturate(*obs.robot_velocity, P.robot)
            assert within_rate(cmd, v, omega), (cmd, obs.robot_velocity)
        prev = cmd


# -- scans -----------------------------------------------------------------------------------

def scans():
    n = st.integers(0, 40)
    arrays = n.flatmap(lambda k: st.tuples(st.lists(NUM, min_size=k, max_size=k),
                                           st.lists(NUM, min_size=k, max_size=k)))
    ragged = st.tuples(st.lists(NUM, max_size=5), st.lists(NUM, max_size=7))
    return st.tuples(arrays | ragged, NUM, NUM, NUM, NUM, NUM).map(
        lambda c: Scan(np.array(c[0][0]), np.array(c[0][1]), c[1], c[2], c[3], c[4], c[5]))


def check_scan(scan) -> None:
    drive(Observation(k * P.dt, Pose(0.0, 0.0, 0.0), PERSON, scan=scan) for k in range(3))


# -- odometry --------------------------------------------------------------------------------

def odometry_streams():
    sample = st.tuples(NUM | st.floats(0.0, 2.0), NUM, NUM, NUM,
                       st.none() | st.tuples(NUM, NUM))
    return st.lists(sample, min_size=1, max_size=12)


def check_odometry(stream) -> None:
    drive(Observation(t, Pose(x, y, th), PERSON, robot_velocity=v)
          for t, x, y, th, v in stream)


# -- person detections -----------------------------------------------------------------------

def detections():
    det = st.builds(PersonDetection, NUM, NUM, NUM, st.sampled_from(["world", "robot", "map"]),
                    st.none() | st.tuples(NUM, NUM, NUM, NUM), st.none() | NUM,
                    st.none() | NUM, st.none() | NUM, st.none() | NUM,
                    st.none() | st.tuples(NUM, NUM), st.none() | st.integers(-5, 5))
    return st.lists(st.lists(det, max_size=3), min_size=1, max_size=8)


def check_detections(batches) -> None:
    drive(Observation(k * P.dt, Pose(0.0, 0.0, 0.0), detections=tuple(b))
          for k, b in enumerate(batches))


FAMILIES = {"scan": (scans(), check_scan), "odometry": (odometry_streams(), check_odometry),
            "detections": (detections(), check_detections)}


@pytest.mark.parametrize("family", FAMILIES)
def test_any_raw_input_gives_a_finite_command_within_limits(family):
    strategy, check = FAMILIES[family]
    assert_none_failed(family, *sweep(family, strategy, check, QUICK))


@pytest.mark.slow
@pytest.mark.parametrize("family", FAMILIES)
def test_sweep_raw_inputs(family):
    strategy, check = FAMILIES[family]
    assert_none_failed(family, *sweep(family, strategy, check, SLOW))


# -- odometry faults by name -----------------------------------------------------------------

def reasons(cmd) -> list[str]:
    return cmd.reason.split("+")


@pytest.mark.parametrize("fault", ["jump", "turn", "backwards"])
def test_an_odometry_jump_or_time_going_back_is_missing_odometry_then_a_stop(fault):
    """A pose that jumps farther than twice v_max allows (or turns faster than twice
    omega_max), or a stamp earlier than the last one, is reported at once and holds the
    last command; if it persists for supervisor.odometry_timeout_s the robot stops
    (odometry_lost); plausible odometry resumes."""
    sup = make_controller("lqr", P)
    sup.reset()
    h = PersonState(0.0, 1.0, 0.0, 1.0, 0.0)
    pose = Pose(-0.25, 0.0, 0.0)
    first = step(sup, Observation(0.0, pose, h, robot_velocity=(1.0, 0.0)))
    assert "odometry_jump" not in first.reason
    n = int(S.odometry_timeout_s / P.dt) + 4
    out = []
    for k in range(1, n + 1):
        if fault == "jump":        # 1 m every period: 20 m/s, over twice v_max
            obs = Observation(k * P.dt, Pose(-0.25 + k, 0.0, 0.0), h, robot_velocity=(1.0, 0.0))
        elif fault == "turn":      # 1 rad every period: 20 rad/s
            obs = Observation(k * P.dt, Pose(-0.25, 0.0, float(k)), h, robot_velocity=(1.0, 0.0))
        else:                      # the stamp runs backwards
            obs = Observation(-k * P.dt, pose, h, robot_velocity=(1.0, 0.0))
        out.append(step(sup, obs))
    name = "odometry_time" if fault == "backwards" else "odometry_jump"
    assert all(name in reasons(c) for c in out)
    assert out[0].status == "degraded" and (out[0].v, out[0].omega) == pytest.approx(
        (first.v, first.omega), abs=DV)
    # A stamp that goes back discards the whole observation (a clock fault), so the person's
    # detections are missing too and its equal timeout may name the stop first.
    first_stop = ("odometry_lost", "person_lost") if fault == "backwards" else ("odometry_lost",)
    assert out[-1].status == "stopped" and out[-1].reason.startswith(first_stop)
    last = out[-1]
    t, p = (n + 1) * P.dt, (Pose(-0.25 + n, 0.0, 0.0) if fault == "jump" else
                            Pose(-0.25, 0.0, float(n)) if fault == "turn" else pose)
    if fault == "backwards":
        t = 1.0                   # later than every stamp so far
    resumed = [step(sup, Observation(t + k * P.dt, p, PersonState(p.x + 0.25, p.y + 1.0, p.theta,
                                                                  0.0, 0.0),
                                    robot_velocity=(last.v, 0.0))) for k in range(2)]
    assert not any(r in reasons(resumed[-1]) for r in ("odometry_jump", "odometry_time",
                                                       "odometry_lost"))


def test_one_relocalisation_jump_is_one_missing_sample():
    """A single jump (a localisation correction) costs one sample: the next ones, consistent
    with the new pose, are odometry again."""
    sup = make_controller("lqr", P)
    sup.reset()
    h = PersonState(0.0, 1.0, 0.0, 0.0, 0.0)
    out = [step(sup, Observation(k * P.dt, Pose(-0.25 + (0.5 if k >= 3 else 0.0), 0.0, 0.0), h,
                                robot_velocity=(0.0, 0.0))) for k in range(6)]
    flagged = ["odometry_jump" in reasons(c) for c in out]
    assert flagged == [False, False, False, True, False, False]
