import math

import numpy as np
import pytest

from companion import metrics
from companion.types import LOG_COLUMNS, Log


def make_log(rho_e, alpha_e=None, beta=None, dt=0.05):
    n = len(rho_e)
    cols = {c: np.zeros(n) for c in LOG_COLUMNS}
    cols["t"] = np.arange(n) * dt
    cols["rho_d"][:] = 1.0
    cols["alpha_d"][:] = math.pi / 2
    cols["rho"] = 1.0 + np.asarray(rho_e, float)
    cols["alpha"] = math.pi / 2 + (np.zeros(n) if alpha_e is None else np.asarray(alpha_e))
    cols["beta"] = np.zeros(n) if beta is None else np.asarray(beta, float)
    cols["robot_y"][:] = 1.0
    cols["rho_ob"][:] = np.nan
    return Log(cols)


def test_rmse_closed_form():
    log = make_log([0.1, -0.1, 0.1, -0.1], beta=[0.0, 0.0, 0.2, 0.0])
    m = metrics.compute(log)
    assert m["rmse_rho_m"] == pytest.approx(0.1)
    assert m["rmse_beta_rad"] == pytest.approx(0.1)
    assert m["min_person_distance_m"] == pytest.approx(1.0)


def test_alpha_error_is_wrapped():
    # alpha just below 2*pi against alpha_d = 0 is a small error, not ~2*pi
    log = make_log([0.0, 0.0])
    log.columns["alpha_d"][:] = 0.0
    log.columns["alpha"][:] = 2 * math.pi - 0.01
    assert metrics.compute(log)["rmse_alpha_rad"] == pytest.approx(0.01)


def test_settling_time():
    e = np.r_[np.full(10, 0.5), np.full(5, 0.01), np.full(3, 0.5), np.full(20, 0.001)]
    assert metrics.settling_time(make_log(e)) == pytest.approx(18 * 0.05)
    assert metrics.settling_time(make_log(np.r_[np.zeros(5), 0.5])) is None
    assert metrics.settling_time(make_log(np.zeros(4))) == 0.0


def test_obstacle_metrics():
    log = make_log(np.zeros(8))
    assert metrics.compute(log)["min_obstacle_clearance_m"] is None
    assert metrics.compute(log)["obstacle_collisions"] == 0
    log.columns["rho_ob"][:] = [0.5, 0.1, -0.02, -0.01, 0.2, 0.0, 0.3, 0.4]
    m = metrics.compute(log)
    assert m["min_obstacle_clearance_m"] == pytest.approx(-0.02)
    assert m["obstacle_collisions"] == 2       # two separate contacts
    log.columns["rho_ob"][0] = -0.1
    assert metrics.compute(log)["obstacle_collisions"] == 3
