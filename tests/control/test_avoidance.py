"""Behavioural-dynamics avoidance (Eq. 17-20): the avoidance layer only adds u_ob."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.control import make_controller
from companion.control.avoidance import (
    AvoidingController,
    angular_acceleration,
    collision_cone,
    influence_range,
    steering_bearing,
    total_acceleration,
)
from companion.params import AvoidanceParams, Params
from companion.types import Circle, Command, Observation, PersonState, Pose, Wall

A = AvoidanceParams()
P = Params()


def test_obstacle_on_the_left_turns_right():
    assert angular_acceleration(0.3, 0.2, A) < 0.0
    assert angular_acceleration(-0.3, 0.2, A) > 0.0
    assert angular_acceleration(0.0, 0.2, A) == 0.0


@settings(max_examples=200, deadline=None)
@given(st.floats(0.01, 1.5), st.floats(0.0, 2.0), st.floats(0.01, 2.0))
def test_magnitude_falls_with_distance(phi, rho, extra):
    assert abs(angular_acceleration(phi, rho + extra, A)) < abs(angular_acceleration(phi, rho, A))


@settings(max_examples=200, deadline=None)
@given(st.floats(1.0 / 1.5, 3.0), st.floats(0.01, 1.0), st.floats(0.0, 2.0))
def test_magnitude_falls_with_bearing_beyond_the_peak(phi, extra, rho):
    """|phi| exp(-c1 |phi|) peaks at 1/c1 and falls beyond it (Eq. 17)."""
    assert abs(angular_acceleration(phi + extra, rho, A)) < abs(angular_acceleration(phi, rho, A))


def test_closed_form_value():
    phi, rho = 0.4, 0.3
    expected = -28.0 * 0.4 * math.exp(-1.5 * 0.4) * math.exp(-0.9 * 0.3)
    assert angular_acceleration(phi, rho, A) == pytest.approx(expected)


def test_influence_range():
    assert influence_range(Circle(0, 0, 0.15), A) == pytest.approx(0.4)      # r / K_ob
    assert influence_range(Circle(0, 0, 0.4875), A) == pytest.approx(1.3)
    assert influence_range(Circle(0, 0, 0.15, influence=0.7), A) == 0.7
    assert influence_range(Wall(0, 0, 1, 0), A) == A.wall_influence


def test_no_effect_outside_range_or_behind():
    # robot at origin heading +x, footprint 0.25; obstacle r = 0.15 -> range 0.4 m
    far = Circle(0.25 + 0.15 + 0.41, 0.1, 0.15)
    assert total_acceleration(0.0, 0.0, 0.0, [far], P) == 0.0
    near = Circle(0.25 + 0.15 + 0.3, 0.1, 0.15)
    assert total_acceleration(0.0, 0.0, 0.0, [near], P) < 0.0
    behind = Circle(-0.6, 0.1, 0.15)
    assert total_acceleration(0.0, 0.0, 0.0, [behind], P) == 0.0


def test_contributions_add_up():
    a, b = Circle(0.7, 0.3, 0.15), Circle(0.7, -0.5, 0.15)
    total = total_acceleration(0.0, 0.0, 0.0, [a, b], P)
    assert total == pytest.approx(total_acceleration(0.0, 0.0, 0.0, [a], P)
                                  + total_acceleration(0.0, 0.0, 0.0, [b], P))


def test_collision_cone_and_steering_bearing():
    ob = Circle(2.0, 0.0, 0.15)
    cone = collision_cone(ob, 0.0, 0.0, 0.35)
    assert cone == pytest.approx(math.asin(0.5 / 2.0))
    assert steering_bearing(0.5, cone, 1.0, 0.15) == 0.5        # outside: the paper's phi
    assert steering_bearing(0.01, cone, 1.0, 0.15) == cone      # person left: pass on the right
    assert steering_bearing(-0.01, cone, -1.0, 0.15) == -cone
    assert steering_bearing(-0.2, cone, 1.0, 0.15) == -cone     # clearly right: its own side


def _obs(robot, obstacles, person=PersonState(0.0, 5.0, 0.0, 0.0, 0.0)):
    return Observation(0.0, robot, person, tuple(obstacles))


class Straight:
    """A stand-in controller: always drives straight at 1 m/s; records what was applied."""

    def __init__(self):
        self.log = []

    def reset(self):
        self.log.clear()

    def step(self, obs):
        return Command(1.0, 0.0)

    def applied(self, cmd):
        self.log.append(cmd)


def test_u_ob_leaks_back_to_zero_and_respects_limits():
    inner = Straight()
    ctl = AvoidingController(inner, P)
    ob = Circle(0.7, 0.05, 0.15)
    u = [ctl.step(_obs(Pose(0.0, 0.0, 0.0), [ob])).u_ob for _ in range(10)]
    assert u[-1] < 0.0 and abs(u[-1]) <= P.robot.omega_max
    out = [ctl.step(_obs(Pose(0.0, 0.0, 0.0), [])) for _ in range(60)]
    assert abs(out[-1].u_ob) < 1e-2 * abs(u[-1])                 # decays (tau = 0.5 s)
    assert all(abs(c.omega) <= P.robot.omega_max for c in out)
    assert all(c.v == 1.0 for c in out)                           # v is not this layer's
    assert inner.log == []                                        # applied() is not its own
    ctl.applied(out[-1])
    assert inner.log == [out[-1]]                                 # but it is passed on


@pytest.mark.parametrize("name", ["lqr", "lqr-paper"])
def test_avoidance_off_without_obstacles_changes_nothing(name):
    from companion.sim.episode import run_episode
    from companion.sim.person import Figure8
    log = run_episode(make_controller(name, P), Figure8(60.0), P, 10.0)
    assert np.all(log["u_ob"] == 0.0)
    assert np.all(np.isnan(log["rho_ob"]))


def test_lqr_stores_what_the_layers_sent():
    """No wind-up on the real path: when the barrier cuts v, the LQR's u_e(k-1) is the
    command actually sent minus u_d (and minus u_ob)."""
    ctl = make_controller("lqr", P)
    ctl.reset()
    lqr = ctl.inner.inner   # supervisor -> avoidance -> LQR
    # robot right behind the person and facing them: the barrier must cut v
    obs = Observation(0.0, Pose(-0.7, 0.0, 0.0), PersonState(0.0, 0.0, 0.0, 0.0, 0.0),
                      (Circle(-0.3, 0.9, 0.15),))
    for k in range(5):
        cmd = ctl.step(dataclasses.replace(obs, t=k * P.dt))
        u_d = np.array(lqr.last.u_d)
        np.testing.assert_allclose(lqr.u_e_prev,
                                   np.array([cmd.v, cmd.omega - cmd.u_ob]) - u_d, atol=1e-12)
        # the barrier allows approaching at most 2/s * (0.7 m - 0.6 m) = 0.2 m/s here
        assert cmd.v <= 0.2 + 1e-9
    from companion.control import LqrController
    alone = LqrController(P)
    alone.reset()
    assert alone.step(obs).v > 0.2 + 1e-3      # so the layer did change the command
