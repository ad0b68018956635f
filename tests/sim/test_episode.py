import math

import numpy as np
import pytest

from companion.control import make_bare, make_controller
from companion.errors import ConfigError
from companion.geometry import lagged, unicycle_step, wrap_pi, wrap_pi_array
from companion.metrics import compute
from companion.params import REALISTIC, Params
from companion.sim.episode import run_episode
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


def test_realistic_sensing_is_deterministic_under_seed():
    p = Params(sensing=REALISTIC)
    person = circle((0.0, 0.0, 0.0), 3.0, 1.0)
    runs = [run_episode(make_controller("lqr", p), person, p, 5.0, seed=s) for s in (7, 7, 8)]
    assert runs[0].equals(runs[1])
    assert not np.array_equal(runs[0]["v"], runs[2]["v"])


def test_the_base_follows_the_command_through_its_lag():
    p = Params(sensing=REALISTIC)
    tau, dt = p.sensing.actuator_tau_s, p.dt
    log = run_episode(make_controller("lqr", p), Figure8(60.0), p, 3.0)
    a = math.exp(-dt / tau)
    for k in range(len(log) - 1):
        v_next = log["v"][k] + (log["robot_v"][k] - log["v"][k]) * a
        assert log["robot_v"][k + 1] == pytest.approx(v_next, abs=1e-12)
        v_mean = lagged(log["robot_v"][k], log["v"][k], tau, dt)[1]
        w_mean = lagged(log["robot_omega"][k], log["omega"][k], tau, dt)[1]
        x, y, _ = unicycle_step(log["robot_x"][k], log["robot_y"][k], log["robot_theta"][k],
                                v_mean, w_mean, dt)
        assert (x, y) == pytest.approx((log["robot_x"][k + 1], log["robot_y"][k + 1]),
                                       abs=1e-12)
    # the mean over a period of a lag from 0 towards 1: 1 - tau / dt (1 - e^(-dt / tau))
    assert lagged(0.0, 1.0, tau, dt)[1] == pytest.approx(1.0 - tau / dt * (1.0 - a))
    assert lagged(0.3, 1.0, 0.0, dt) == (1.0, 1.0)


def test_the_log_holds_the_estimate_beside_the_truth():
    ideal = run_episode(make_controller("lqr", Params()), Figure8(60.0), Params(), 3.0)
    for name in ("x", "y", "theta", "v", "omega"):
        np.testing.assert_allclose(ideal[f"person_est_{name}"], ideal[f"person_{name}"],
                                   atol=1e-12)
    assert np.all(ideal["person_est_std"] == 0.0)
    p = Params(sensing=REALISTIC)
    log = run_episode(make_controller("lqr", p), Figure8(60.0), p, 10.0, seed=1)
    err = np.hypot(log["person_est_x"] - log["person_x"], log["person_est_y"] - log["person_y"])
    assert 0.005 < np.sqrt(np.mean(err ** 2)) < 0.1
    assert np.all((log["person_est_std"] > 0.01) & (log["person_est_std"] < 0.15))


def test_a_bare_controller_needs_ideal_sensing():
    p = Params(sensing=REALISTIC)
    with pytest.raises(ConfigError, match="sensing: a controller without the standard stack"):
        run_episode(make_bare("lqr", p), line((0.0, 0.0, 0.0), 1.0), p, 1.0)


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


def test_the_slot_error_splits_into_estimate_tracking_and_safety():
    """Per sample: the slot error is at most the estimate's error plus the tracking error
    (a triangle); with ideal sensing the estimate is exact; the keep-out's shift is 0 where
    it did not act and the metrics sum what the log holds."""
    ideal = run_episode(make_controller("lqr", Params()), Figure8(60.0), Params(), 10.0)
    np.testing.assert_allclose(ideal["estimate_error_m"], 0.0, atol=1e-9)
    np.testing.assert_allclose(ideal["tracking_error_m"], ideal["slot_error_m"], atol=1e-9)
    p = Params(sensing=REALISTIC)
    log = run_episode(make_controller("lqr", p), Figure8(60.0), p, 20.0, seed=1)
    seen = np.isfinite(log["estimate_error_m"])
    assert seen.mean() > 0.9
    slot, est, track = (log[k][seen] for k in ("slot_error_m", "estimate_error_m",
                                                "tracking_error_m"))
    assert np.all(slot <= est + track + 1e-9)
    assert 0.01 < np.median(est) < 0.3
    quiet = np.array(["evasive" not in r and "protective_zone" not in r and "stop_path" not in r
                      for r in log["reason"]])
    assert np.all(log["safety_shift_m"][quiet] == 0.0)
    m = compute(log)
    assert m["safety_shift_m"] == pytest.approx(float(np.sum(log["safety_shift_m"])))
    assert m["safety_share"] == pytest.approx(np.mean(log["safety_shift_m"] > 1e-9))
    assert m["rms_estimate_error_m"] == pytest.approx(np.sqrt(np.mean(est ** 2)))
    assert m["rms_slot_error_m"] <= m["rms_estimate_error_m"] + m["rms_tracking_error_m"] + 1e-9
