"""The safety supervisor: one named test per fault of docs/safety.md, plus its building blocks.

Every closed-loop test also checks the supervisor's guarantee (:func:`assert_within_limits`):
finite commands within the velocity and acceleration limits.
"""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.control import AvoidingController, SafetySupervisor, make_controller
from companion.control.checks import Clock
from companion.control.limits import limit_rate
from companion.geometry import unicycle_step
from companion.params import Params
from companion.perception import checked_scan, extract_obstacles
from companion.sim.episode import run_episode
from companion.sim.faults import Fault
from companion.sim.person import Move, ScriptedWalk, line
from companion.sim.recorded import load_person_csv
from companion.sim.sensing import make_perception
from companion.tracking import predict
from companion.types import Circle, Command, Observation, PersonState, Pose, Scan, Wall
from stepping import step

P = Params()
S = P.supervisor
TR = P.tracker
DT = P.dt
EPS = 1e-9
#: Without the search (the robot holds where the controlled stop left it): what fault 1 is.
HOLD = P.replace(search=dataclasses.replace(P.search, max_time_s=0.0))


def assert_within_limits(log, p=P):
    v, w = log["v"], log["omega"]
    assert np.all(np.isfinite(v)) and np.all(np.isfinite(w))
    assert np.all(np.abs(v) <= p.robot.v_max + EPS)
    assert np.all(np.abs(w) <= p.robot.omega_max + EPS)
    dv, dw = np.diff(v), np.diff(w)
    assert np.all(np.abs(dv) <= max(p.supervisor.accel_max, p.supervisor.decel_max) * p.dt
                  + EPS)
    assert np.all(np.abs(dw) <= p.supervisor.angular_accel_max * p.dt + EPS)
    # |v| shrinks at most at decel_max and grows at most at accel_max
    shrink = np.abs(v[1:]) < np.abs(v[:-1])
    assert np.all(np.abs(dv[~shrink]) <= p.supervisor.accel_max * p.dt + EPS)


def person_distance(log):
    return np.hypot(log["robot_x"] - log["person_x"], log["robot_y"] - log["person_y"])


def walk(duration=30.0):
    return line((0.0, 0.0, 0.0), 1.0), duration


def run(faults=(), name="lqr", person=None, duration=20.0, p=P, **kw):
    person = person or line((0.0, 0.0, 0.0), 1.0)
    return run_episode(make_controller(name, p), person, p, duration, faults=faults, **kw)


def rows(log, reason):
    return np.array([reason in r.split("+") for r in log["reason"]])


# -- building blocks -------------------------------------------------------------------------

def test_limit_rate_grows_and_shrinks_at_their_own_rates():
    assert limit_rate(5.0, 1.0, 2.0, 4.0, 0.1) == pytest.approx(1.2)      # grow at 2
    assert limit_rate(-5.0, 1.0, 2.0, 4.0, 0.1) == pytest.approx(0.6)     # shrink at 4
    assert limit_rate(-5.0, 0.2, 2.0, 4.0, 0.1) == pytest.approx(-0.1)    # 0.05 s to 0, then grow
    assert limit_rate(-5.0, -1.0, 2.0, 4.0, 0.1) == pytest.approx(-1.2)   # mirrored
    assert limit_rate(0.3, 0.25, 2.0, 4.0, 0.1) == 0.3                    # reachable: exact


def test_predict_follows_the_unicycle_arc():
    h = PersonState(0.0, 0.0, 0.0, 1.0, 0.5)
    q = predict(h, math.pi / 0.5)            # half a circle of radius 2
    assert (q.x, q.y) == pytest.approx((0.0, 4.0), abs=1e-9)
    assert predict(PersonState(1.0, 2.0, 0.0, 1.0, 0.0), 2.0).x == pytest.approx(3.0)


def test_clock_alone_counts_bad_steps_as_one_period():
    clock = Clock(DT, S.max_step_ratio)
    assert clock.tick(10.0) == (0.0, "ok") and clock.now == 10.0
    assert clock.tick(10.05) == (pytest.approx(0.05), "ok")
    for bad in (10.05, 9.0, math.nan):
        assert clock.tick(bad) == (DT, "clock")
    assert clock.tick(11.0)[1] == "clock_gap"
    assert clock.now == pytest.approx(10.05 + 3 * DT + (11.0 - 9.0))


def test_started_in_the_slot_it_is_ok_throughout():
    log = run()
    assert set(log["status"]) == {"ok"}
    assert_within_limits(log)


# -- fault 1: person missing or stale ------------------------------------------------------

def test_fault1_person_lost_brakes_to_a_stop_and_holds():
    start, end = 5.0, 12.0
    log = run([Fault("person_dropout", start, end)], duration=20.0, p=HOLD)
    t, last = log["t"], start - DT          # the last detection
    coasting = (t >= start) & (t <= last + TR.coast_after_s - EPS)
    assert set(log["status"][coasting]) == {"ok"}                 # a short gap is normal
    predicted = (t > last + TR.coast_after_s + EPS) & (t <= last + TR.lost_after_s - EPS)
    assert predicted.sum() >= 3 and set(log["status"][predicted]) == {"degraded"}
    assert np.all(rows(log, "person_predicted")[predicted])
    lost = (t > last + TR.lost_after_s + EPS) & (t < end)
    assert set(log["status"][lost]) == {"stopped"}
    assert np.all(rows(log, "person_lost")[lost])
    v = log["v"][lost]
    # brakes at the deceleration limit (to within one period) and then holds zero
    brake_steps = int(math.ceil(abs(v[0]) / (S.decel_max * DT))) + 1
    assert np.all(np.diff(np.abs(v)) <= EPS)
    assert np.all(v[brake_steps:] == 0.0) and np.all(log["omega"][lost][brake_steps:] == 0.0)
    # never drives on towards the last known point: it stops within its braking distance
    i0 = np.flatnonzero(lost)[0]
    travel = math.hypot(log["robot_x"][lost][-1] - log["robot_x"][i0],
                        log["robot_y"][lost][-1] - log["robot_y"][i0])
    assert travel <= v[0] ** 2 / (2 * S.decel_max) + abs(v[0]) * DT + 1e-6
    assert_within_limits(log)


def test_fault1_short_gap_is_bridged_by_prediction():
    log = run([Fault("person_dropout", 5.0, 5.3)], duration=10.0)
    assert "stopped" not in set(log["status"])
    assert np.max(np.abs(log["rho"] - log["rho_d"])) < 0.01   # constant-velocity prediction


# -- fault 2: NaN or Inf in any input ------------------------------------------------------

@pytest.mark.parametrize("kind, status, reason", [
    ("person_nan", "degraded", "person_invalid"),
    ("robot_nan", "stopped", "robot_pose_invalid"),
    ("obstacle_nan", "degraded", "obstacle_invalid"),
])
def test_fault2_non_finite_inputs_are_treated_as_missing(kind, status, reason):
    log = run([Fault(kind, 5.0, 5.4)], duration=12.0)
    during = (log["t"] >= 5.0) & (log["t"] < 5.4)
    assert set(log["status"][during]) == {status}
    assert np.all(rows(log, reason)[during])
    assert_within_limits(log)
    assert np.all(np.isfinite(log["robot_x"]))
    assert set(log["status"][log["t"] > 9.0]) == {"ok"}   # and it recovers


def test_fault2_inf_in_the_person_and_obstacles_is_never_propagated():
    sup = make_controller("lqr", P)
    sup.reset()
    bad = [PersonState(math.inf, 0.0, 0.0, 1.0, 0.0), PersonState(0.0, 1.0, -math.inf, 1.0, 0.0),
           PersonState(0.0, 1.0, 0.0, math.nan, 0.0)]
    good = PersonState(0.25, 1.0, 0.0, 1.0, 0.0)
    for k in range(40):
        h = bad[k % 3] if 10 <= k < 16 else good
        obs = Observation(k * DT, Pose(0.0, 0.0, 0.0), h,
                          (Circle(math.inf, 0.0, 1.0), Wall(0.0, math.nan, 1.0, 1.0)))
        cmd = sup.step(obs)
        assert math.isfinite(cmd.v) and math.isfinite(cmd.omega)
        assert "obstacle_invalid" in sup.report.reason
        if 10 <= k < 16:
            assert "person_invalid" in sup.report.reason


@pytest.mark.parametrize("v, omega", [(0.0, 1.4980776123852631e+308), (-1e308, 0.0),
                                      (5.0, -20.0)])
def test_fault2_huge_person_rates_are_clipped(v, omega):
    """Finite but absurd person rates would overflow the forward prediction (found by the fuzz
    test): the controller only ever sees them clipped to the plausible bounds."""
    seen = []

    class Recorder(Spy):
        def step(self, obs):
            seen.append(obs.person)
            return super().step(obs)

    sup = SafetySupervisor(Recorder(), P)
    for k, t in enumerate([0.0, 0.05, 0.1, 0.15]):
        h = PersonState(-3.0, 0.0, 0.0, v, omega) if k % 2 == 0 else None  # odd: predicted
        cmd = sup.step(Observation(t, Pose(0.0, 0.0, 0.0), h))
        assert math.isfinite(cmd.v) and math.isfinite(cmd.omega)
        if h is not None:
            assert "person_rate_clipped" in sup.report.reason.split("+")
    assert len(seen) == 4
    for person in seen:
        assert abs(person.v) <= TR.max_person_speed
        assert abs(person.omega) <= TR.max_person_turn_rate
        assert all(math.isfinite(x) for x in (person.x, person.y, person.theta))


# -- fault 3: identity switch ----------------------------------------------------------------

def test_fault3_person_jump_is_rejected_as_an_outlier():
    log = run([Fault("person_jump", 5.0, 5.3, dx=0.0, dy=2.0)], duration=10.0)
    during = (log["t"] >= 5.0) & (log["t"] < 5.3)
    assert np.all(rows(log, "person_outlier")[during])
    assert np.max(np.abs(log["rho"] - log["rho_d"])) < 0.01   # it did not chase the jump
    assert_within_limits(log)


def test_fault3_persistent_switch_stops_then_reacquires():
    log = run([Fault("person_jump", 5.0, 30.0, dx=3.0, dy=-3.0)], duration=14.0)
    t = log["t"]
    lost = 5.0 - DT + TR.lost_after_s
    assert set(log["status"][(t > lost + EPS) & (t < lost + TR.reacquire_time_s)]) \
        == {"stopped"}
    assert "reacquiring" in "+".join(log["reason"])
    assert set(log["status"][t > 12.0]) <= {"ok", "degraded"}   # follows the new track
    assert_within_limits(log)


# -- fault 4: bad time steps ------------------------------------------------------------------

class Spy:
    """A controller that records resets, steps and what it is told was applied, and always
    asks for full speed."""

    def __init__(self):
        self.resets, self.times, self.told = 0, [], []

    def reset(self):
        self.resets += 1

    def step(self, obs):
        self.times.append(obs.t)
        return Command(1.5, 1.0)

    def applied(self, cmd):
        self.told.append(cmd)


def test_applied_is_called_once_per_step_with_the_final_command():
    """Through the whole stack (supervisor, avoidance layer, controller) the controller is told
    exactly once per step what was finally sent, and nothing when it was not stepped."""
    spy = Spy()
    sup = SafetySupervisor(AvoidingController(spy, P), P)
    h = PersonState(-3.0, 0.0, 0.0, 0.0, 0.0)
    ahead = (Circle(1.0, 0.1, 0.3),)                  # avoidance and barrier both act
    finals = [sup.step(Observation(k * DT, Pose(0.0, 0.0, 0.0), h, ahead)) for k in range(20)]
    assert len(spy.told) == len(spy.times) == 20
    assert [(c.v, c.omega, c.u_ob) for c in spy.told] == [(c.v, c.omega, c.u_ob) for c in finals]
    assert any(c.u_ob != 0.0 for c in finals)
    sup.step(Observation(math.nan, Pose(0.0, 0.0, 0.0), h, ahead))   # not stepped: not told
    assert len(spy.told) == 20


@pytest.mark.parametrize("bad_t", [0.5, 0.4, math.nan, math.inf])   # zero, negative, not finite
def test_fault4_zero_negative_or_nan_step_holds_and_resets(bad_t):
    spy = Spy()
    sup = SafetySupervisor(spy, P)
    h = PersonState(-3.0, 0.0, 0.0, 0.0, 0.0)   # standing well behind: no keep-out effect
    times = [0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, bad_t, 0.55]
    cmds = [sup.step(Observation(t, Pose(0.0, 0.0, 0.0), h)) for t in times[:11]]
    resets = spy.resets
    held = sup.step(Observation(bad_t, Pose(0.0, 0.0, 0.0), h))
    assert (held.v, held.omega) == (cmds[-1].v, cmds[-1].omega)
    assert held.status == "degraded" and "clock" in sup.report.reason.split("+")
    nxt = sup.step(Observation(0.55, Pose(0.0, 0.0, 0.0), h))
    assert spy.resets == resets + 1          # filters reset before the next step
    assert all(b > a for a, b in zip(spy.times, spy.times[1:]))   # time handed on advances
    assert abs(nxt.v - held.v) <= S.accel_max * DT + EPS


def test_fault4_long_step_resets_filters_without_a_jump():
    spy = Spy()
    sup = SafetySupervisor(spy, P)
    h = PersonState(-3.0, 0.0, 0.0, 0.0, 0.0)
    a = sup.step(Observation(0.0, Pose(0.0, 0.0, 0.0), h))
    resets = spy.resets
    b = sup.step(Observation(10.0, Pose(0.0, 0.0, 0.0), h))   # 200 periods late
    assert "clock_gap" in sup.report.reason
    assert abs(b.v - a.v) <= S.accel_max * DT + EPS          # no huge integration
    # the person must be confirmed again after so long; then the filters start afresh
    later = [sup.step(Observation(10.0 + k * DT, Pose(0.0, 0.0, 0.0), h)) for k in range(1, 9)]
    assert spy.resets == resets + 1 and later[-1].status == "ok"


def test_fault4_a_held_command_still_obeys_the_keep_out_rules():
    """On a clock fault the last command is held, but the obstacle barrier still slows it."""
    sup = SafetySupervisor(Spy(), P)
    h = PersonState(0.0, 5.0, 0.0, 0.0, 0.0)
    wall = (Circle(0.75, 0.0, 0.2),)          # 0.3 m clearance ahead: barrier allows 0.4 m/s
    sup.step(Observation(0.0, Pose(0.0, 0.0, 0.0), h, wall))
    sup.applied(Command(0.475, 0.0))
    held = sup.step(Observation(0.0, Pose(0.0, 0.0, 0.0), h, wall))     # zero time step
    assert "clock" in sup.report.reason.split("+")
    allowed = P.keepout.barrier_rate * (0.3 - P.keepout.obstacle_clearance)
    assert held.v == pytest.approx(allowed)


@pytest.mark.parametrize("kind", ["clock_freeze", "clock_backward", "stall"])
def test_fault4_clock_faults_in_closed_loop(kind):
    log = run([Fault(kind, 5.0, 5.5)], duration=12.0)
    assert_within_limits(log)
    assert np.max(np.abs(log["rho"] - log["rho_d"])[log["t"] > 9.0]) < 0.02


# -- fault 5: rho near zero, person inside the protective distance ---------------------------

@pytest.mark.parametrize("name", ["lqr", "pid", "vsm", "ic"])
@pytest.mark.parametrize("where", [(0.25, 0.0), (0.3, 0.1), (-0.3, 0.0), (0.0, 0.35)])
def test_fault5_inside_the_protective_distance_no_motion_towards_the_person(name, where):
    """The person stands at R (rho = 0) or within 0.5 m of the robot centre, in any direction;
    for 2 s the robot may rotate or back off but never move towards the person."""
    sup = make_controller(name, P)
    sup.reset()
    h = PersonState(where[0], where[1], 0.3, 0.0, 0.0)
    pose = Pose(0.0, 0.0, 0.0)
    start = math.hypot(h.x, h.y)
    for k in range(40):
        cmd = sup.step(Observation(k * DT, pose, h))
        assert math.isfinite(cmd.v) and math.isfinite(cmd.omega)
        nx, ny = pose.x - h.x, pose.y - h.y
        if math.hypot(nx, ny) < P.keepout.protective_distance:
            assert "protective_zone" in sup.report.reason
            assert cmd.v * (math.cos(pose.theta) * nx + math.sin(pose.theta) * ny) >= -EPS
        pose = Pose(*unicycle_step(pose.x, pose.y, pose.theta, cmd.v, cmd.omega, DT))
        assert math.hypot(pose.x - h.x, pose.y - h.y) >= start - 1e-9   # never closer


# -- fault 6: the person stops abruptly or walks towards the robot ----------------------------

def _behind(p=P):
    return dataclasses.replace(p, formation=dataclasses.replace(p.formation, bearing=math.pi))


FAULT6 = {
    # behind the person, who stops dead (the walker's 1.5 m/s^2 limit is lifted to 20)
    "stops_abruptly": (_behind(), [Move(6.0, 1.2), Move(6.0, 0.0)], 20.0),
    # behind the person, who stops, turns round on the spot and walks back at the robot
    "turns_around": (_behind(), [Move(6.0, 1.0), Move(1.0, 0.0), Move(1.0, 0.0, math.pi),
                                 Move(6.0, 1.0)], 3.0),
    # beside (left), the person turns left towards the robot and walks into it
    "walks_into_robot": (P, [Move(6.0, 1.0), Move(0.5, 0.6, math.pi), Move(6.0, 1.0)], 1.5),
}


@pytest.mark.parametrize("name", ["lqr", "pid", "vsm", "ic"])
@pytest.mark.parametrize("case", sorted(FAULT6))
def test_fault6_no_overshoot_into_the_protective_distance(case, name):
    p, moves, accel = FAULT6[case]
    person = ScriptedWalk((0.0, 0.0, 0.0), moves, accel=accel)
    log = run_episode(make_controller(name, p), person, p, person.duration + 3.0)
    assert np.min(person_distance(log)) >= p.keepout.protective_distance
    assert_within_limits(log, p)


# -- fault 7: obstacle inside the footprint, invalid scans ----------------------------------

def test_fault7_obstacle_inside_the_footprint_stops():
    sup = make_controller("lqr", P)
    sup.reset()
    h = PersonState(0.25, 1.0, 0.0, 1.0, 0.0)
    cmds = [step(sup, Observation(k * DT, Pose(0.0, 0.0, 0.0), h, (Circle(0.3, 0.0, 0.1),)))
            for k in range(30)]
    assert {c.status for c in cmds} == {"stopped"}
    assert all(c.reason == "obstacle_in_footprint" for c in cmds)
    assert cmds[-1].v == 0.0 and cmds[-1].omega == 0.0


@pytest.mark.parametrize("obstacle", [Circle(0.0, 0.0, 0.1), Wall(-1.0, 0.0, 1.0, 0.0)])
def test_fault7_obstacle_right_at_the_robot_centre_stops(obstacle):
    sup = make_controller("lqr", P)
    cmd = sup.step(Observation(0.0, Pose(0.0, 0.0, 0.0), PersonState(0.25, 1.0, 0.0, 1.0, 0.0),
                               (obstacle,)))
    assert cmd.status == "stopped" and sup.report.reason == "obstacle_in_footprint"


def _scan(ranges):
    ranges = np.asarray(ranges, dtype=float)
    return Scan(np.linspace(-math.pi, math.pi, ranges.size, endpoint=False), ranges, 0.0, 0.0,
                0.0)


@pytest.mark.parametrize("ranges, status, reason", [
    ([math.nan] * 360, "stopped", "scan_invalid"),
    ([math.nan] * 200 + [math.inf] * 160, "stopped", "scan_invalid"),   # < half valid
    ([math.nan] * 100 + [math.inf] * 260, "degraded", "scan_partial"),
    ([math.inf] * 359 + [-math.inf], "stopped", "obstacle_in_footprint"),   # REP 117 too close
    ([math.inf] * 359 + [0.1], "stopped", "obstacle_in_footprint"),
])
def test_fault7_invalid_returns_are_not_free_space(ranges, status, reason):
    sup = make_controller("lqr", P)
    sup.reset()
    h = PersonState(0.25, 1.0, 0.0, 1.0, 0.0)
    cmd = sup.step(Observation(0.0, Pose(0.0, 0.0, 0.0), h, (), _scan(ranges)))
    assert cmd.status == status and reason in sup.report.reason.split("+")


ANGLES = np.linspace(-math.pi, math.pi, 360, endpoint=False)


@pytest.mark.parametrize("scan", [
    Scan(ANGLES, np.full(359, math.inf), 0.0, 0.0, 0.0),                  # lengths differ
    Scan(ANGLES.reshape(2, 180), np.full((2, 180), math.inf), 0.0, 0.0, 0.0),   # not 1-D
    Scan(np.where(ANGLES > 1.0, math.nan, ANGLES), np.full(360, math.inf), 0.0, 0.0, 0.0),
    Scan(ANGLES, np.full(360, math.inf), math.nan, 0.0, 0.0),             # pose unknown
    Scan(ANGLES, None, 0.0, 0.0, 0.0),
    Scan(ANGLES, ["far"] * 360, 0.0, 0.0, 0.0),
])
def test_fault7_a_malformed_scan_stops_the_robot_and_never_raises(scan):
    sup = make_controller("lqr", P)
    sup.reset()
    h = PersonState(0.25, 1.0, 0.0, 1.0, 0.0)
    cmd = sup.step(Observation(0.0, Pose(0.0, 0.0, 0.0), h, (), scan))
    assert cmd.status == "stopped" and sup.report.reason.split("+")[0] == "scan_invalid"


def test_fault7_ranges_as_drivers_send_them():
    """FLT_MAX, 1e20 and anything above range_max mean "no return"; a range below range_min
    is an invalid beam; a list of ranges is read like an array."""
    flt_max = float(np.finfo(np.float32).max)
    ranges = [flt_max] * 100 + [1e20] * 100 + [50.0] * 100 + [0.01] * 60
    scan = Scan(list(ANGLES), ranges, 0.0, 0.0, 0.0, range_min=0.05, range_max=30.0)
    checked = checked_scan(scan)
    assert np.all(np.isposinf(checked.ranges[:300])) and np.all(np.isnan(checked.ranges[300:]))
    assert extract_obstacles(scan, None, P.extractor) == []
    sup = make_controller("lqr", P)
    sup.reset()
    cmd = sup.step(Observation(0.0, Pose(0.0, 0.0, 0.0), PersonState(0.25, 1.0, 0.0, 1.0, 0.0),
                               (), scan))
    assert cmd.status == "degraded" and "scan_partial" in sup.report.reason.split("+")


@settings(max_examples=60, deadline=None)
@given(st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                          st.sampled_from([1e20, -1e20, 3.4028234663852886e38])),
                min_size=0, max_size=40),
       st.integers(-2, 2),
       st.tuples(*[st.floats(allow_nan=True, allow_infinity=True)] * 3))
def test_any_scan_gives_a_finite_command_within_limits(ranges, extra, pose):
    angles = np.linspace(-math.pi, math.pi, max(len(ranges) + extra, 0), endpoint=False)
    sup = make_controller("lqr", P)
    sup.reset()
    h = PersonState(0.0, 1.0, 0.0, 1.0, 0.0)
    scan = Scan(angles, ranges, *pose)
    for k in range(3):
        cmd = sup.step(Observation(k * DT, Pose(0.0, 0.0, 0.0), h, (), scan))
        assert math.isfinite(cmd.v) and math.isfinite(cmd.omega)
        assert abs(cmd.v) <= P.robot.v_max and abs(cmd.omega) <= P.robot.omega_max


def test_fault7_scan_blackout_in_closed_loop_with_lidar():
    p = P
    log = run_episode(make_controller("lqr", p), line((0.0, 0.0, 0.0), 1.0), p, 10.0,
                      obstacles=(Circle(30.0, 5.0, 0.3),), perception=make_perception("lidar", p),
                      faults=[Fault("scan_blackout", 3.0, 6.0)])
    during = (log["t"] >= 3.0) & (log["t"] < 6.0)
    assert set(log["status"][during]) == {"stopped"}
    assert np.all(rows(log, "scan_invalid")[during])
    assert_within_limits(log)


# -- fault 8: resume after an outage ---------------------------------------------------------

VSM_CYCLE = pytest.mark.xfail(strict=True, reason="the search leaves the robot 2.4 m out, "
                               "where the VSM falls into its limit cycle (docs/baselines.md)")


@pytest.mark.parametrize("name", ["lqr", "pid", "vsm", "ic"])
@pytest.mark.parametrize("search", [True, False], ids=["search", "hold"])
def test_fault8_resume_after_outage_without_a_jump(name, search, request):
    if search and name == "vsm":
        request.applymarker(VSM_CYCLE)
    log = run([Fault("person_dropout", 5.0, 8.0)], name=name, duration=25.0,
              p=P if search else HOLD)
    t, lost = log["t"], rows(log, "person_lost")
    assert np.all(lost[(t > 5.6) & (t < 8.0)])          # stopped, then searching
    resumed = np.flatnonzero((t >= 8.0) & (log["status"] != "stopped") & ~lost)[0]
    assert t[resumed] <= 8.0 + TR.reacquire_time_s + 2 * DT
    assert_within_limits(log)                   # the ramp back up obeys the limits
    late = t > 22.0
    assert np.max(np.abs(log["rho"] - log["rho_d"])[late]) < 0.05   # and it catches up


# -- recorded person CSVs: holes are outages ------------------------------------------------

def test_recorded_hole_is_an_outage_and_a_sparse_track_is_not(tmp_path):
    f = tmp_path / "walk.csv"
    times = [i * 0.1 for i in range(50)] + [8.0 + i * 0.1 for i in range(150)]  # 3.1 s hole
    f.write_text("t,x,y\n" + "".join(f"{t:.2f},{t:.3f},0\n" for t in times))
    person = load_person_csv(f)
    log = run_episode(make_controller("lqr", HOLD), person, HOLD, person.duration)
    hole = (log["t"] > 4.9 + TR.lost_after_s + EPS) & (log["t"] < 8.0)
    assert set(log["status"][hole]) == {"stopped"}
    assert np.all(rows(log, "person_lost")[hole])
    after = log["t"] > 8.0 + TR.reacquire_time_s + 0.5
    assert "stopped" not in set(log["status"][after])
    assert set(log["reason"][after]) <= {"", "slot_error"}      # catching up, then ok
    assert log["status"][-1] == "ok"
    assert_within_limits(log)
    sparse = tmp_path / "sparse.csv"                  # 2.5 Hz throughout: no hole
    sparse.write_text("t,x,y\n" + "".join(f"{0.4 * i:.2f},{0.4 * i:.3f},0\n"
                                          for i in range(40)))
    person = load_person_csv(sparse)
    log = run_episode(make_controller("lqr", P), person, P, person.duration)
    assert "stopped" not in set(log["status"])


def test_a_stalled_controller_is_stopped_by_the_base_command_timeout():
    """The controller is not called for 2 s: the base holds the last command for
    robot.command_timeout_s, then brakes to a stop at the deceleration limits."""
    log = run([Fault("stall", 5.0, 7.0)], duration=10.0)
    t, v = log["t"], log["robot_v"]
    timeout = P.robot.command_timeout_s
    last = 5.0 - DT                                   # the last command before the stall
    held = (t > 5.0) & (t <= last + timeout + EPS)
    assert np.allclose(v[held], v[np.searchsorted(t, 5.0)], atol=1e-9)
    stop_by = 5.0 + timeout + P.robot.v_max / S.decel_max + 2 * DT
    assert np.all(np.abs(v[(t > stop_by) & (t < 7.0)]) < 1e-9)
    assert np.all(np.abs(np.diff(v[(t > 5.0) & (t < 7.0)])) <= S.decel_max * DT + EPS)


def test_rate_limits_start_from_the_measured_velocity():
    """A supervisor started on a robot already moving at 1 m/s (odometry), without being
    told, does not command a sudden stop."""
    sup = make_controller("lqr", P)
    sup.reset()
    h = PersonState(0.0, 1.0, 0.0, 1.0, 0.0)
    cmd = sup.step(Observation(0.0, Pose(-0.25, 0.0, 0.0), h, robot_velocity=(1.0, 0.0)))
    assert abs(cmd.v - 1.0) <= S.accel_max * DT + EPS


@pytest.mark.parametrize("name", ["lqr", "pid", "vsm", "ic"])
def test_fault2_an_absurd_robot_pose_stops_the_robot(name):
    """A finite but absurd pose (1e300 m) is as invalid as NaN: no controller sees it."""
    sup = make_controller(name, P)
    sup.reset()
    h = PersonState(0.0, 1.0, 0.0, 1.0, 0.0)
    for k in range(40):
        cmd = sup.step(Observation(k * DT, Pose(1e300, 0.0, 0.0), h))
        assert cmd.status == "stopped" and sup.report.reason.startswith("robot_pose_invalid")
    assert cmd.v == 0.0 and cmd.omega == 0.0


def test_invalid_odometry_is_reported_then_stops_the_robot():
    """NaN or impossible odometry is not the robot's velocity: reported at once, and after
    supervisor.odometry_timeout_s a controlled stop; valid odometry resumes."""
    sup = make_controller("lqr", P)
    sup.reset()
    h = PersonState(0.0, 1.0, 0.0, 1.0, 0.0)
    pose = Pose(-0.25, 0.0, 0.0)
    sup.step(Observation(0.0, pose, h, robot_velocity=(1.0, 0.0)))
    bad = [(math.nan, 0.0), (50.0, 0.0)]
    statuses = []
    n = int(S.odometry_timeout_s / DT) + 5
    for k in range(1, n + 1):
        cmd = sup.step(Observation(k * DT, pose, h, robot_velocity=bad[k % 2]))
        assert "odometry_invalid" in sup.report.reason.split("+")
        statuses.append(cmd.status)
    assert statuses[0] == "degraded" and statuses[-1] == "stopped"
    assert sup.report.reason.startswith("odometry_lost")
    cmd = sup.step(Observation((n + 1) * DT, pose, h, robot_velocity=(0.0, 0.0)))
    assert cmd.status != "stopped"
