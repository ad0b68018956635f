"""The collision risk that gates the evasive check (control.risk), the uncertainty band of
rule 3 (control.keepout), and the delays the supervisor measures (control.delays)."""

import dataclasses
import math

import numpy as np
import pytest

from companion.control import make_controller
from companion.control.delays import DelayMeter
from companion.control.keepout import person_interval, risk_of
from companion.control.risk import collision_risk, meet_chance, robot_path
from companion.params import REALISTIC, Params
from companion.sim.episode import run_episode
from companion.sim.person import Figure8
from companion.types import PersonDetection, PersonEstimate, PersonState, Pose

P = Params(sensing=REALISTIC)


def estimate(x, y, theta, v, pos_std=0.05, vel_std=0.1):
    cov = np.diag((pos_std ** 2, pos_std ** 2, vel_std ** 2, vel_std ** 2, 0.1))
    s = PersonState(x, y, theta, v, 0.0)
    return PersonEstimate(s, pos_std, cov, 0.0, "seen", s)


def test_meet_chance_is_a_gaussian_tail():
    assert meet_chance(0.0, 0.3) == pytest.approx(0.5)
    assert meet_chance(0.3, 0.3) == pytest.approx(0.158655, abs=1e-6)
    assert meet_chance(-0.1, 0.0) == 1.0 and meet_chance(0.1, 0.0) == 0.0
    assert meet_chance(0.2, 0.1) < meet_chance(0.2, 0.2) < meet_chance(0.1, 0.2)


def test_the_robot_path_is_the_rollouts_and_at_rest_stays_put():
    xs, ys = robot_path(1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.5, 3.2, 0.2, 0.1, 12)
    np.testing.assert_allclose(xs, 1.0)
    np.testing.assert_allclose(ys, 2.0)
    xs, _ = robot_path(0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 2.5, 3.2, 0.0, 0.1, 10)
    np.testing.assert_allclose(xs, 0.1 * np.arange(1, 11))


def test_a_walker_straight_beside_the_robot_is_a_low_risk_and_one_walking_at_it_high():
    """Robot in its slot 1 m to the right of a walker, both at 1 m/s: a chance of about 2 %
    (so a threshold of 5 % would leave such a walker alone; docs/safety.md, "How cautious");
    a walker who walks at a robot standing still: high; more uncertainty: more risk."""
    robot, v_now = Pose(0.0, -1.0, 0.0), (1.0, 0.0)
    beside = risk_of((1.0, 0.0), robot, v_now, estimate(0.0, 0.0, 0.0, 1.0), P)
    at_it = risk_of((0.0, 0.0), robot, (0.0, 0.0), estimate(0.0, 0.0, -math.pi / 2, 1.0), P)
    unsure = risk_of((1.0, 0.0), robot, v_now, estimate(0.0, 0.0, 0.0, 1.0, 0.2, 0.5), P)
    assert 0.005 < beside < 0.05 < 0.5 < at_it
    assert unsure > beside
    # far away nothing can meet
    far = risk_of((1.0, 0.0), Pose(0.0, -20.0, 0.0), v_now, estimate(0.0, 0.0, 0.0, 1.0), P)
    assert far < 1e-12


def test_collision_risk_is_the_largest_over_the_horizon():
    xs, ys = np.array((2.0, 1.0, 0.6)), np.zeros(3)
    cov = np.zeros((5, 5))
    risk = collision_risk(xs, ys, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0, cov, 0.3, 0.45)
    var = 0.09 * 0.3 ** 3 / 3.0
    assert risk == pytest.approx(meet_chance(0.6 - 0.45, math.sqrt(var)))


def test_in_the_uncertainty_band_the_robot_need_not_flee_a_person_who_approaches():
    """Outside the protective distance but inside its growth by the person's uncertainty,
    rule 3 forbids only the robot's own approach; inside the distance itself the robot moves
    away at least as fast as the person comes."""
    coming = PersonState(0.0, 0.0, -math.pi / 2, 0.8, 0.0)     # walks at the robot
    band = Pose(0.0, -0.6, -math.pi / 2)                       # facing away, 0.6 m
    lo, hi = person_interval(band, coming, P, [], grow=0.2)
    assert lo == pytest.approx(0.0) and hi == math.inf      # any v >= 0: no retreat forced
    inside = Pose(0.0, -0.45, -math.pi / 2)
    lo, _ = person_interval(inside, coming, P, [], grow=0.2)
    assert lo == pytest.approx(0.8)


@pytest.mark.parametrize("tau, latency", [(0.2, 0.1), (0.35, 0.2), (0.05, 0.03)])
def test_the_supervisor_measures_the_base_lag_and_the_detection_age(tau, latency):
    sensing = dataclasses.replace(REALISTIC, actuator_tau_s=tau, person_latency_s=latency)
    p = Params(sensing=sensing)
    stack = make_controller("lqr", p)
    run_episode(stack, Figure8(60.0), p, 20.0)
    assert stack.delays.tau == pytest.approx(tau, abs=1e-6)
    # a detection arrives at the first step after its latency: up to one period later
    assert latency <= stack.delays.latency <= latency + p.dt
    measured = stack.delays.params(p).sensing
    assert measured.actuator_tau_s == pytest.approx(tau, abs=0.005)


def test_until_enough_is_seen_the_declared_delays_stand():
    meter = DelayMeter(P)
    assert meter.params(P) is P and meter.tau is None and meter.latency is None
    meter.detections([PersonDetection(0.0, 0.0, 0.0, "world")] * 3, 0.1)
    assert meter.latency is None
    meter.motion(0.0, (0.0, 0.0))
    meter.motion(0.05, None)       # no odometry: nothing learnt, the chain restarts
    assert meter.tau is None


def test_a_repeated_odometry_sample_teaches_nothing():
    meter = DelayMeter(P)
    meter.sent(0.0, (1.0, 0.0))
    meter.motion(0.0, (0.0, 0.0))
    for _ in range(30):
        meter.motion(0.0, (0.0, 0.0))       # the same stamp again: ignored
    assert meter.tau is None
