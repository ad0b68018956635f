"""The LQR weighs its feedforward by the estimate's confidence (docs/model.md, section 4.5)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from companion.control.lqr import LEAST_TRUST, feedforward_weights
from companion.params import Params, load_sensing
from companion.sim.scenario import load_scenario, run_scenario

Q = np.array((25.0, 10.0, 25.0, 30.0, 30.0))
STD = st.floats(0.0, 5.0)


@given(STD, STD)
def test_only_the_input_weights_change_and_never_grow(speed, turn):
    q = feedforward_weights(Q, (speed, turn), (0.1, 0.1), 1.0)
    assert np.array_equal(q[:3], Q[:3])
    assert np.all(q[3:] <= Q[3:]) and np.all(q[3:] >= Q[3:] / LEAST_TRUST - 1e-12)


@given(STD, STD, st.floats(0.0, 1.0))
def test_a_less_certain_estimate_is_trusted_less(speed, turn, more):
    q = feedforward_weights(Q, (speed, turn), (0.1, 0.1), 1.0)
    worse = feedforward_weights(Q, (speed + more, turn + more), (0.1, 0.1), 1.0)
    assert np.all(worse[3:] <= q[3:])


def test_a_wild_estimate_still_leaves_a_tenth_of_the_trust():
    q = feedforward_weights(Q, (10.0, 10.0), (0.1, 0.1), 1.0)
    np.testing.assert_allclose(q[3:], Q[3:] / LEAST_TRUST)


def test_exact_or_always_trusted_leaves_the_weights():
    assert feedforward_weights(Q, None, (0.05, 0.05), 1.0) is Q
    trusted = feedforward_weights(Q, (0.3, 0.4), (math.inf, math.inf), 1.0)
    assert np.array_equal(trusted, Q)


def test_the_weight_halves_at_the_trusted_spread():
    q = feedforward_weights(Q, (0.0, 0.05), (0.05, 0.05), 0.0)
    assert q[4] == pytest.approx(15.0)
    assert q[3] == pytest.approx(30.0)      # rho_d = 0: the turn rate does not move the slot
    q = feedforward_weights(Q, (0.03, 0.0), (0.05, 0.05), 1.0)
    assert q[3] == pytest.approx(30.0 / (1.0 + 0.36))


def _bias(trusted: tuple[float, float]) -> tuple[float, float]:
    """Mean (rho - rho_d, alpha - alpha_d) of lqr on the circle after the first 10 s, with a
    clean position-only detector (3 cm, 10 Hz, no latency, no lag)."""
    sc = load_scenario("circle")
    sensing = dataclasses.replace(load_sensing("realistic"), person_rate_hz=10.0,
                                  person_position_noise_m=0.03, person_latency_s=0.0,
                                  person_dropout=0.0, actuator_tau_s=0.0)
    lqr = dataclasses.replace(sc.params.lqr, feedforward_std=trusted)
    sc = dataclasses.replace(sc, duration=40.0,
                             params=sc.params.replace(sensing=sensing, lqr=lqr))
    log = run_scenario(sc, "lqr")
    late = log["t"] > 10.0
    return (float(np.mean(log["rho"][late] - log["rho_d"][late])),
            float(np.mean(log["alpha"][late] - log["alpha_d"][late])))


def test_no_standing_offset_on_the_circle_from_detection_noise():
    """Fully trusted, the noisy feedforward holds the robot 0.20 m inside and 0.18 rad behind
    its slot on the circle; weighed by its confidence (the defaults), 5.5 cm and 0.07 rad."""
    rho_e, alpha_e = _bias((math.inf, math.inf))
    assert rho_e < -0.15 and alpha_e < -0.12
    rho_e, alpha_e = _bias(Params().lqr.feedforward_std)
    assert abs(rho_e) < 0.07 and abs(alpha_e) < 0.09
