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


@pytest.mark.parametrize("n", [1, 7, 379, 100_000])
def test_binomial_interval_with_no_failure_is_the_rule_of_three_exactly(n):
    """k = 0: the exact upper end solves (1 - p)^n = 0.025, the lower end is 0."""
    lo, hi = metrics.binomial_interval(0, n)
    assert lo == 0.0
    assert hi == pytest.approx(1.0 - 0.025 ** (1.0 / n), rel=1e-9)


@pytest.mark.parametrize("k, n", [(1, 10), (7, 379), (50, 100), (379, 379)])
def test_binomial_interval_holds_the_estimate_and_narrows_with_more_episodes(k, n):
    lo, hi = metrics.binomial_interval(k, n)
    assert 0.0 <= lo <= k / n <= hi <= 1.0
    lo10, hi10 = metrics.binomial_interval(10 * k, 10 * n)
    assert hi10 - lo10 < hi - lo
    # symmetric: k failures of n and n - k successes of n
    lo_c, hi_c = metrics.binomial_interval(n - k, n)
    assert (lo_c, hi_c) == pytest.approx((1.0 - hi, 1.0 - lo), abs=1e-12)


def test_binomial_interval_refuses_counts_that_cannot_be():
    with pytest.raises(ValueError, match="k=5, n=3"):
        metrics.binomial_interval(5, 3)
    assert metrics.binomial_interval(0, 0) == (0.0, 1.0)
