import math

import numpy as np
import pytest

from companion.control import make_controller
from companion.geometry import unicycle_step, wrap_pi, wrap_pi_array
from companion.params import Params
from companion.sim.episode import SensorNoise, run_episode
from companion.sim.person import Figure8, circle, line
from companion.types import LOG_COLUMNS, TEXT_COLUMNS


def test_start_in_slot_is_on_the_desired_side():
    p = Params()
    log = run_episode(make_controller("lqr", p), line((0.0, 0.0, 0.0), 1.0), p, 0.05)
    assert log["rho"][0] == pytest.approx(1.0)
    assert log["alpha"][0] == pytest.approx(math.pi / 2)
    assert log["beta"][0] == pytest.approx(0.0)
    # reference point R on the left: y = 1, the axle is d behind it
    assert (log["robot_x"][0], log["robot_y"][0]) == pytest.approx((-0.25, 1.0))


def test_plant_is_exact_unicycle():
    p = Params()
    log = run_episode(make_controller("lqr", p), Figure8(60.0), p, 3.0)
    for k in range(len(log) - 1):
        x, y, th = unicycle_step(log["robot_x"][k], log["robot_y"][k], log["robot_theta"][k],
                                 log["v"][k], log["omega"][k], p.dt)
        assert (x, y) == pytest.approx((log["robot_x"][k + 1], log["robot_y"][k + 1]),
                                       abs=1e-12)
        assert wrap_pi(th - log["robot_theta"][k + 1]) == pytest.approx(0, abs=1e-12)


def test_log_columns_and_length():
    p = Params()
    log = run_episode(make_controller("lqr", p), line((0.0, 0.0, 0.0), 1.0), p, 2.0)
    assert set(log.columns) == set(LOG_COLUMNS) | set(TEXT_COLUMNS)
    assert len(log) == 40
    assert set(log["status"]) == {"ok"} and set(log["reason"]) == {""}
    assert log["t"][-1] == pytest.approx(1.95)


def test_noise_is_deterministic_under_seed():
    p = Params()
    noise = SensorNoise(position=0.02, heading=0.02)
    person = circle((0.0, 0.0, 0.0), 3.0, 1.0)
    runs = [run_episode(make_controller("lqr", p), person, p, 5.0, seed=s, noise=noise)
            for s in (7, 7, 8)]
    np.testing.assert_array_equal(runs[0]["v"], runs[1]["v"])
    assert not np.array_equal(runs[0]["v"], runs[2]["v"])


@pytest.mark.parametrize("side, bearing", [("left", 0.5 * math.pi), ("right", 1.5 * math.pi),
                                           ("behind", math.pi), ("angle", 2.3)])
def test_any_bearing_on_a_circle(side, bearing):
    """Our LQR holds any bearing while the person walks a circle (turns included)."""
    import dataclasses
    p = Params()
    p = dataclasses.replace(p, formation=dataclasses.replace(p.formation, bearing=bearing))
    log = run_episode(make_controller("lqr", p), circle((0.0, 0.0, 0.0), 3.0, 1.0), p, 40.0)
    tail = slice(len(log) // 2, None)
    assert np.max(np.abs(log["rho"][tail] - 1.0)) < 0.01
    alpha_e = wrap_pi_array(log["alpha"][tail] - bearing)
    assert np.max(np.abs(alpha_e)) < 0.01
    dist = np.hypot(log["robot_x"] - log["person_x"], log["robot_y"] - log["person_y"])
    assert np.min(dist) > 0.5
