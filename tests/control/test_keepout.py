"""The keep-out rules of the safety supervisor, each alone (companion.control.keepout)."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.control.evasive import (
    Rollout,
    _rollout_margins,
    evasive_target,
    rollout_margins,
    speed_up_distance,
)
from companion.control.keepout import (
    barrier_speed,
    braking_bound,
    braking_speed,
    heading_std,
)
from companion.control.limits import limit
from companion.geometry import clearance, lagged, obstacle_arrays, unicycle_step
from companion.params import REALISTIC, Params
from companion.tracking import predict
from companion.types import Circle, PersonEstimate, PersonState, Pose, Wall

P = Params()


@pytest.mark.parametrize("obstacle", [Circle(3.0, 0.0, 0.3), Wall(3.0, -2.0, 3.0, 2.0)])
def test_barrier_stops_head_on_approach(obstacle):
    """Driving straight at an obstacle, the barrier alone keeps the clearance."""
    pose = Pose(0.0, 0.0, 0.0)
    person = PersonState(0.0, 5.0, 0.0, 0.0, 0.0)
    for _ in range(400):
        v = barrier_speed(1.5, pose, person, [obstacle], P)
        pose = Pose(*unicycle_step(pose.x, pose.y, pose.theta, v, 0.0, P.dt))
    if isinstance(obstacle, Circle):
        clearance = math.hypot(pose.x - obstacle.x, pose.y - obstacle.y) - obstacle.radius
    else:
        clearance = obstacle.x0 - pose.x
    clearance -= P.robot.radius
    assert clearance == pytest.approx(P.keepout.obstacle_clearance, abs=0.01)


def test_barrier_keeps_person_clearance_and_backs_off():
    person = PersonState(2.0, 0.0, math.pi, 0.5, 0.0)   # walks towards the robot
    pose = Pose(0.0, 0.0, 0.0)
    closest = math.inf
    for _ in range(200):
        v = barrier_speed(1.0, pose, person, [], P)
        pose = Pose(*unicycle_step(pose.x, pose.y, pose.theta, v, 0.0, P.dt))
        person = PersonState(person.x - 0.5 * P.dt, 0.0, math.pi, 0.5, 0.0)
        closest = min(closest, math.hypot(pose.x - person.x, pose.y - person.y))
    assert closest >= P.keepout.person_clearance - 0.02


def test_barriers_off():
    k = dataclasses.replace(P.keepout, person_clearance=0.0, obstacle_clearance=0.0)
    p = dataclasses.replace(P, keepout=k)
    assert barrier_speed(1.2, Pose(0, 0, 0), PersonState(0.3, 0, 0, 0, 0), [Circle(0.5, 0, 0.2)],
                      p) == 1.2


@pytest.mark.parametrize("gap", [0.01, 0.3, 1.0, 5.0])
def test_braking_speed_stops_exactly_within_the_gap(gap):
    a, dt = 2.5, 0.05
    v = braking_speed(gap, a, dt)
    assert v * dt + v * v / (2 * a) == pytest.approx(gap)
    assert braking_speed(0.0, a, dt) == 0.0 and braking_speed(-1.0, a, dt) == 0.0


def test_braking_bound_stops_at_the_protective_distance_and_lets_the_robot_leave():
    person = PersonState(0.0, 0.0, 0.0, 0.0, 0.0)
    pose, reasons = Pose(-3.0, 0.0, 0.0), []
    for _ in range(200):                     # drive at the person, braking as allowed
        v = braking_bound(1.5, pose, person, (), P, reasons)
        pose = Pose(*unicycle_step(pose.x, pose.y, pose.theta, v, 0.0, P.dt))
    assert -pose.x >= P.keepout.protective_distance - 1e-9
    assert -pose.x == pytest.approx(P.keepout.protective_distance, abs=0.02)
    inside = Pose(-0.3, 0.0, 0.0)
    assert braking_bound(1.0, inside, person, (), P, reasons) <= 0.0   # no closer
    assert braking_bound(-1.0, inside, person, (), P, reasons) == -1.0  # away is fine
    assert "protective_zone" in reasons


def test_outside_the_zone_the_braking_bound_limits_the_robots_own_approach_only():
    """A person walking at the robot is the evasive check's to answer: outside the
    protective distance the bound does not make the robot back off along the line to it
    (that drove it into the path of people passing by), and the robot's own approach is
    bounded as for a standing person. Inside the zone it must still move away as fast as
    the person comes."""
    standing = PersonState(0.0, 0.0, math.pi, 0.0, 0.0)
    coming = PersonState(0.0, 0.0, math.pi, 1.2, 0.0)      # walks at the robot at 1.2 m/s
    robot = Pose(-1.2, 0.0, 0.0)                            # facing the person, 1.2 m away
    assert braking_bound(0.0, robot, coming, (), P, []) == 0.0
    assert braking_bound(1.5, robot, coming, (), P, []) == \
        pytest.approx(braking_bound(1.5, robot, standing, (), P, []), abs=1e-12)
    assert 0.0 < braking_bound(1.5, robot, coming, (), P, []) < 1.5
    inside = Pose(-0.4, 0.0, 0.0)
    assert braking_bound(0.0, inside, coming, (), P, []) == pytest.approx(-1.2)


def test_an_uncertain_person_is_kept_farther_away_and_the_lag_counts_as_reaction_time():
    person = PersonState(0.0, 0.0, 0.0, 0.0, 0.0)
    pose, grow = Pose(-3.0, 0.0, 0.0), 0.15
    for _ in range(200):
        v = braking_bound(1.5, pose, person, (), P, [], grow=grow)
        pose = Pose(*unicycle_step(pose.x, pose.y, pose.theta, v, 0.0, P.dt))
    assert -pose.x == pytest.approx(P.keepout.protective_distance + grow, abs=0.02)
    with_lag = P.replace(sensing=REALISTIC)          # 0.2 s of actuator lag
    far = Pose(-1.5, 0.0, 0.0)
    assert braking_bound(1.5, far, person, (), with_lag, []) \
        < braking_bound(1.5, far, person, (), P, []) - 0.2


@pytest.mark.parametrize("tau", [0.1, 0.2, 0.4])
def test_braking_counts_what_the_lag_carries_the_robot_on(tau):
    """Driving straight at a standing person through an actuator lag, from every start from
    which the bound's own stop fits in the gap: the robot never enters the protective
    distance, so it never moves towards the person inside it. Counting the lag as time at the
    command speed (the old bound) let a braking robot, faster than its command, in by up to
    1.5 cm at 0.1 s, 5.8 cm at 0.2 s and 18.9 cm at 0.4 s."""
    p = P.replace(sensing=dataclasses.replace(P.sensing, actuator_tau_s=tau))
    person, k = PersonState(0.0, 0.0, 0.0, 0.0, 0.0), p.keepout
    net = min(p.supervisor.accel_max, p.supervisor.decel_max) - k.person_accel
    closest, starts = math.inf, 0
    for x0 in np.linspace(-3.0, -1.0, 21):
        for v0 in (0.5, 1.0, 1.5):
            if -x0 - k.protective_distance < v0 * (p.dt + tau) + v0 * v0 / (2 * net):
                continue                                  # cannot stop in time: not a case
            starts += 1
            x, va, sent = x0, v0, (v0, 0.0)
            for _ in range(150):
                v = braking_bound(1.5, Pose(x, 0.0, 0.0), person, (), p, [], actual=va)
                sent = limit((v, 0.0), sent, p)
                va, mean = lagged(va, sent[0], tau, p.dt)
                x += mean * p.dt
                closest = min(closest, -x)
    assert starts >= 40
    assert closest >= k.protective_distance - 1e-9
    assert closest == pytest.approx(k.protective_distance, abs=0.03)   # and gets there


def _spec(person, p=P, horizon=1.2, step=0.1, lag=0.0, spread=0.0):
    s, k = p.supervisor, p.keepout
    return Rollout(person.x, person.y, person.theta, person.v, person.omega, k.person_accel,
                   k.protective_distance, p.robot.radius, min(s.accel_max, s.decel_max),
                   s.angular_accel_max, step, int(round(horizon / step)), lag, spread)


LAG_SPREAD = st.tuples(st.sampled_from((0.0, 0.2)), st.sampled_from((0.0, 0.3)))


@settings(max_examples=50, deadline=None)
@given(st.tuples(*[st.floats(-3, 3)] * 3), st.tuples(st.floats(-1.5, 1.5), st.floats(-1, 1)),
       st.tuples(*[st.floats(-3, 3)] * 3, st.floats(-0.5, 2.0), st.floats(-2, 2)),
       st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(0, 1)), max_size=3),
       st.lists(st.tuples(*[st.floats(-3, 3)] * 4), max_size=2), LAG_SPREAD)
def test_compiled_rollout_equals_its_python_source(pose, current, person, circles, walls,
                                                   lag_spread):
    obstacles = obstacle_arrays([Circle(*c) for c in circles] + [Wall(*w) for w in walls])
    targets = np.random.default_rng(0).uniform(-1.5, 1.5, (36, 2))
    spec = _spec(PersonState(*person), lag=lag_spread[0], spread=lag_spread[1])
    np.testing.assert_allclose(_rollout_margins(*pose, *current, targets, spec, obstacles),
                               rollout_margins(*pose, *current, targets, spec, obstacles),
                               rtol=1e-12, atol=1e-12)


def oracle_margins(pose, current, targets, person, obstacles, p=P, horizon=1.2, step=0.1,
                   lag=0.0, spread=0.0):
    """What the evasive rollout should predict, composed from the object-level functions."""
    s, k = p.supervisor, p.keepout
    people = [dataclasses.replace(person, theta=person.theta + j * spread)
              for j in ((-1, 0, 1) if spread else (0,))]
    out = []
    for tv, tw in targets:
        x, y, th = pose
        va, wa = current
        margin = math.inf
        for n in range(1, int(round(horizon / step)) + 1):
            t = n * step
            rate = min(s.accel_max, s.decel_max)
            v = current[0] + min(max(tv - current[0], -rate * t), rate * t)
            w = current[1] + min(max(tw - current[1], -s.angular_accel_max * t),
                                 s.angular_accel_max * t)
            va, wa = (lagged(va, v, lag, step)[0], lagged(wa, w, lag, step)[0]) if lag \
                else (v, w)
            x, y, th = unicycle_step(x, y, th, va, wa, step)
            for h0 in people:
                h = predict(h0, t)
                extra = speed_up_distance(h0.v, k.person_accel, t)
                hx, hy = h.x + extra * math.cos(h0.theta), h.y + extra * math.sin(h0.theta)
                margin = min(margin, math.hypot(x - hx, y - hy) - k.protective_distance)
            margin = min([margin] + [clearance(o, x, y, p.robot.radius) for o in obstacles])
        out.append(margin)
    return np.array(out)


@settings(max_examples=50, deadline=None)
@given(st.tuples(*[st.floats(-3, 3)] * 3), st.tuples(st.floats(-1.5, 1.5), st.floats(-1, 1)),
       st.tuples(*[st.floats(-3, 3)] * 3, st.floats(-0.5, 2.0), st.floats(-2, 2)),
       st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(0, 1)), max_size=3),
       st.lists(st.tuples(*[st.floats(-3, 3)] * 4), max_size=2), LAG_SPREAD)
def test_rollout_predicts_what_the_object_level_functions_give(pose, current, person, circles,
                                                               walls, lag_spread):
    obstacles = [Circle(*c) for c in circles] + [Wall(*w) for w in walls]
    targets = np.random.default_rng(1).uniform(-1.5, 1.5, (8, 2))
    h = PersonState(*person)
    lag, spread = lag_spread
    np.testing.assert_allclose(
        _rollout_margins(*pose, *current, targets, _spec(h, lag=lag, spread=spread),
                         obstacle_arrays(obstacles)),
        oracle_margins(pose, current, targets, h, obstacles, lag=lag, spread=spread),
        rtol=1e-9, atol=1e-9)


def test_rollout_margin_of_standing_still_is_the_gap_to_a_standing_person_and_a_wall():
    person = PersonState(2.0, 0.0, 0.0, 0.0, 0.0)
    wall = obstacle_arrays([Wall(-1.0, -1.0, 1.0, -1.0)])
    margin = _rollout_margins(0.0, 0.0, 0.0, 0.0, 0.0, np.zeros((1, 2)), _spec(person), wall)
    assert margin[0] == pytest.approx(min(2.0 - P.keepout.protective_distance,
                                          1.0 - P.robot.radius))
    # driving at the person at full speed closes the gap by more than the ramp allows to stop
    ahead = _rollout_margins(0.0, 0.0, 0.0, 0.0, 0.0, np.array([[1.5, 0.0]]), _spec(person),
                             obstacle_arrays([]))
    assert ahead[0] < 2.0 - P.keepout.protective_distance - 0.5


def test_evasive_target_replaces_a_command_into_the_person_only():
    person = PersonState(1.2, 0.0, math.pi, 1.0, 0.0)      # walks at the robot
    evade = evasive_target(Pose(0.0, 0.0, 0.0), (0.0, 0.0), (1.0, 0.0), person, (), P)
    assert evade is not None and evade[0] < 1.0
    far = PersonState(10.0, 5.0, 0.0, 1.0, 0.0)
    assert evasive_target(Pose(0.0, 0.0, 0.0), (0.0, 0.0), (1.0, 0.0), far, (), P) is None


def test_an_uncertain_heading_makes_the_evasive_check_plan_for_a_turn_towards_the_robot():
    """A person 0.8 m to the robot's left, walking alongside: safe if it keeps its heading,
    not if it may be walking 0.5 rad towards the robot (a turn the detections show late)."""
    person = PersonState(0.0, 0.8, 0.0, 1.2, 0.0)
    robot, nominal = Pose(0.0, 0.0, 0.0), (1.2, 0.0)
    assert evasive_target(robot, nominal, nominal, person, (), P) is None
    evade = evasive_target(robot, nominal, nominal, person, (), P, spread=0.5)
    assert evade is not None and evade[1] < 0.0           # turns away, to the right


def test_the_actuator_lag_shrinks_the_predicted_margin_of_a_late_evasion():
    person = PersonState(2.0, 0.0, math.pi, 1.0, 0.0)     # walks at the robot
    escape = np.array([[-1.5, 0.0]])                       # reverse at full speed
    free = _rollout_margins(0.0, 0.0, 0.0, 0.0, 0.0, escape, _spec(person), obstacle_arrays([]))
    slow = _rollout_margins(0.0, 0.0, 0.0, 0.0, 0.0, escape, _spec(person, lag=0.2),
                            obstacle_arrays([]))
    assert slow[0] < free[0] - 0.05


def test_heading_std_of_an_estimate():
    cov = np.zeros((5, 5))
    cov[2:4, 2:4] = np.diag((0.04, 0.01))                 # 0.1 m/s across a walk along x
    est = PersonEstimate(PersonState(0.0, 0.0, 0.0, 1.0, 0.0), 0.05, cov, 0.0, "seen",
                         PersonState(0.0, 0.0, 0.0, 1.0, 0.0))
    assert heading_std(est) == pytest.approx(0.1)
    standing = dataclasses.replace(est, state=PersonState(0.0, 0.0, 0.0, 0.0, 0.0))
    assert heading_std(standing) == 0.0
