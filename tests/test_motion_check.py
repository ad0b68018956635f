"""Reported velocities checked against the positions (companion.tracking.motion): wrong but
in-range speeds and turn rates no longer move the estimate off the person, honest ones pass."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.control import CONTROLLERS, make_controller
from companion.geometry import base_step, wrap_pi
from companion.params import REALISTIC, Params
from companion.sim.episode import start_in_slot
from companion.sim.fuzz import WALKER
from companion.sim.soak import random_walk
from companion.tracking.motion import motion_nis as nis_of
from companion.tracking.motion import motion_of
from companion.tracking.tracker import PersonTracker
from companion.types import Command, Observation, PersonDetection, PersonState, Pose

P = Params()


def motion_nis(window, p):
    p = p.for_sensing(REALISTIC)
    return nis_of([motion_of(d, p) for d in window], p.motion_floor_mps)


def walk_window(speed, heading, reported_speed, reported_heading, n=10, std=0.05, seed=0):
    """``n`` detections 0.05 s apart of a straight walk, positions with ``std`` noise."""
    rng = np.random.default_rng(seed)
    c, s = math.cos(heading), math.sin(heading)
    return [PersonDetection(k * 0.05, speed * c * k * 0.05 + std * rng.normal(),
                            speed * s * k * 0.05 + std * rng.normal(),
                            covariance=(std ** 2, 0.0, 0.0, std ** 2), heading=reported_heading,
                            heading_std=0.05, speed=reported_speed, turn_rate=0.0,
                            velocity_std=(0.1, 0.1)) for k in range(n)]


@settings(max_examples=60, deadline=None)
@given(speed=st.floats(0.0, 2.5), heading=st.floats(-math.pi, math.pi),
       seed=st.integers(0, 1000))
def test_honest_reports_agree_with_the_positions(speed, heading, seed):
    window = walk_window(speed, heading, speed, heading, seed=seed)
    assert motion_nis(window, P.tracker) <= P.tracker.motion_gate_chi2


@settings(max_examples=60, deadline=None)
@given(speed=st.floats(0.0, 1.5), heading=st.floats(-math.pi, math.pi),
       error=st.floats(2.5, 3.0), seed=st.integers(0, 1000))
def test_a_speed_wrong_by_2_5_m_s_or_more_disagrees(speed, heading, error, seed):
    window = walk_window(speed, heading, speed + error, heading, seed=seed)
    assert motion_nis(window, P.tracker) > P.tracker.motion_gate_chi2


def test_too_short_a_window_or_no_speed_is_not_judged():
    wrong = walk_window(0.0, 0.0, 3.0, 0.0)
    assert motion_nis(wrong[:3], P.tracker) == 0.0
    bare = [dataclasses.replace(d, speed=None, turn_rate=None, velocity_std=None)
            for d in wrong]
    assert motion_nis(bare, P.tracker) == 0.0
    assert motion_nis(wrong, P.tracker) > P.tracker.motion_gate_chi2


def wrong_rates(t, latency=0.1):
    """A person standing at the origin, detected ``latency`` s late with 5 cm noise, reported
    walking at 3 m/s and turning at 2 pi rad/s (in range, wrong)."""
    return PersonDetection(t - latency, 0.0, 0.0, covariance=(0.0025, 0.0, 0.0, 0.0025),
                           heading=-2.9, heading_std=0.05, speed=3.0, turn_rate=2 * math.pi,
                           velocity_std=(0.3, 0.3))


@pytest.mark.parametrize("gate, off", [(P.tracker.motion_gate_chi2, 0.1), (math.inf, 0.4)])
def test_wrong_rates_are_dropped_and_the_estimate_stays_on_the_person(gate, off):
    """With the check the estimate is within 10 cm of the person from 0.5 s on; trusting the
    reports (gate inf) it is more than 40 cm off (the prediction over the latency)."""
    params = dataclasses.replace(P.tracker, motion_gate_chi2=gate)
    tracker = PersonTracker(params, REALISTIC)
    said, error = set(), []
    for k in range(40):
        t = 0.1 + 0.05 * k
        reasons = []
        tracker.add([wrong_rates(t)], t, reasons=reasons)
        est = tracker.estimate(t, reasons)
        said.update(reasons)
        if t >= 0.5:
            error.append(math.hypot(est.state.x, est.state.y))
    if math.isfinite(gate):
        assert max(error) < off and "person_motion_inconsistent" in said
    else:
        assert min(error) > off and "person_motion_inconsistent" not in said


def test_honest_reports_on_the_fuzz_walker_never_fire():
    """60 s of the fuzz walker (starts, stops, sharp turns, turnarounds) at 20 Hz, reports
    with the noise they declare: the check never fires."""
    rng = np.random.default_rng(3)
    walk = random_walk(rng, 60.0, (), 0.5, WALKER)
    tracker = PersonTracker(P.tracker, REALISTIC)
    fired = 0
    for k in range(1200):
        t = 0.05 * k
        h = walk.state(t)
        e = rng.normal(size=5)
        d = PersonDetection(t, h.x + 0.05 * e[0], h.y + 0.05 * e[1],
                            covariance=(0.0025, 0.0, 0.0, 0.0025), heading=h.theta + 0.05 * e[2],
                            heading_std=0.05, speed=h.v + 0.1 * e[3],
                            turn_rate=h.omega + 0.1 * e[4], velocity_std=(0.1, 0.1))
        reasons = []
        tracker.add([d], t, reasons=reasons)
        fired += "person_motion_inconsistent" in reasons
    assert fired == 0


def closest_approach(name, gate=P.tracker.motion_gate_chi2):
    """The closed loop of ``name``'s stack from its slot beside the standing person reported
    with wrong rates (the robot's motion integrated with the base model): the closest the
    robot centre comes to the person (m) in 15 s."""
    params = P.replace(formation=dataclasses.replace(P.formation, bearing=3.54),
                       tracker=dataclasses.replace(P.tracker, motion_gate_chi2=gate))
    stack = make_controller(name, params)
    start = start_in_slot(PersonState(0.0, 0.0, -2.9, 0.0, 0.0), params)
    x, y, th, va, wa = start.x, start.y, start.theta, 0.0, 0.0
    stack.applied(Command(0.0, 0.0))
    closest = math.inf
    for k in range(300):
        t = k * params.dt
        seen = (wrong_rates(t),) if t >= 0.1 else ()
        cmd = stack.step(Observation(t, Pose(x, y, wrap_pi(th)), detections=seen,
                                     robot_velocity=(va, wa)))
        x, y, th, va, wa = base_step(x, y, th, va, wa, cmd.v, cmd.omega, 0.0, params.dt)
        closest = min(closest, math.hypot(x, y))
    return closest


@pytest.mark.parametrize("name", sorted(CONTROLLERS))
def test_wrong_rates_never_bring_the_robot_inside_the_protective_distance(name):
    """Every controller's stack stays 0.8 m or more from the person (0.86-0.88 m measured;
    the protective distance is 0.5 m)."""
    assert closest_approach(name) > 0.8


@pytest.mark.parametrize("name", ["lqr", "pid"])
def test_trusting_wrong_rates_let_the_robot_inside(name):
    """The same loop with the reports trusted (gate inf): the LQR came to 0.48 m, the PID
    to 0.39 m, inside the protective distance."""
    assert closest_approach(name, math.inf) < P.keepout.protective_distance


def test_exact_detections_with_wrong_rates_are_checked_too():
    """A ROS Odometry /person with zero covariances is an exact detection: a person walking
    at 0.6 m/s reported at 3 m/s, turning at 2 pi rad/s and heading elsewhere. Trusted, the
    LQR came to 0.08 m of the person; checked, it keeps 1.06 m."""
    heading, walk = 2.1408, 0.6
    params = P.replace(formation=dataclasses.replace(P.formation, bearing=4.4914))
    closest = {}
    for gate in (P.tracker.motion_gate_chi2, math.inf):
        p = params.replace(tracker=dataclasses.replace(P.tracker, motion_gate_chi2=gate))
        stack = make_controller("lqr", p)
        person = lambda t: PersonState(walk * t * math.cos(heading),  # noqa: E731
                                       walk * t * math.sin(heading), heading, walk, 0.0)
        start = start_in_slot(person(0.0), p)
        x, y, th, va, wa = start.x, start.y, start.theta, 0.0, 0.0
        stack.applied(Command(0.0, 0.0))
        closest[gate] = math.inf
        for k in range(200):
            t = k * p.dt
            h = person(t)
            seen = PersonDetection(t, h.x, h.y, covariance=(0.0, 0.0, 0.0, 0.0),
                                   heading=-1.5545, heading_std=0.0, speed=3.0,
                                   turn_rate=2 * math.pi, velocity_std=(0.0, 0.0))
            cmd = stack.step(Observation(t, Pose(x, y, wrap_pi(th)), detections=(seen,),
                                         robot_velocity=(va, wa)))
            x, y, th, va, wa = base_step(x, y, th, va, wa, cmd.v, cmd.omega, 0.0, p.dt)
            closest[gate] = min(closest[gate], math.hypot(x - h.x, y - h.y))
    assert closest[P.tracker.motion_gate_chi2] > 1.0, closest
    assert closest[math.inf] < 0.2, closest
