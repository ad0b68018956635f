"""Contract tests run over every registered controller (Gymnasium-style checker)."""

import math

import numpy as np
import pytest

from companion.control import CONTROLLERS, make_controller
from companion.errors import ConfigError
from companion.params import Params
from companion.sim.episode import run_episode
from companion.sim.person import line
from companion.types import Observation, PersonState, Pose


@pytest.fixture(params=sorted(CONTROLLERS))
def name(request):
    return request.param


def random_obs(rng):
    return Observation(0.0, Pose(*rng.uniform(-5, 5, 2), rng.uniform(-4, 4)),
                       PersonState(*rng.uniform(-5, 5, 2), rng.uniform(-4, 4),
                                   rng.uniform(0, 2.0), rng.uniform(-1, 1)))


def test_commands_finite_and_within_limits(name):
    p = Params()
    c = make_controller(name, p)
    c.reset()
    rng = np.random.default_rng(1)
    for _ in range(300):
        cmd = c.step(random_obs(rng))
        assert math.isfinite(cmd.v) and math.isfinite(cmd.omega)
        assert abs(cmd.v) <= p.robot.v_max + 1e-12
        assert abs(cmd.omega) <= p.robot.omega_max + 1e-12


def test_deterministic_and_reset(name):
    p = Params()
    c = make_controller(name, p)
    person = line((0.0, 0.0, 0.0), 1.0)
    a = run_episode(c, person, p, 5.0, start=Pose(-1.0, 1.5, 0.3))
    b = run_episode(c, person, p, 5.0, start=Pose(-1.0, 1.5, 0.3))  # same object, reset inside
    np.testing.assert_array_equal(a["v"], b["v"])
    np.testing.assert_array_equal(a["omega"], b["omega"])


def test_holds_formation_on_straight_line(name):
    p = Params()
    log = run_episode(make_controller(name, p), line((0.0, 0.0, 0.0), 1.0), p, 20.0)
    assert np.max(np.abs(log["rho"] - 1.0)) < 1e-6
    assert np.max(np.abs(log["v"] - 1.0)) < 1e-6


def test_unknown_controller_hint():
    with pytest.raises(ConfigError, match="did you mean 'lqr'"):
        make_controller("lqrr", Params())
