"""Baseline controllers (PID, VSM, IC; docs/baselines.md) on the line and circle walks."""

import math

import numpy as np
import pytest

from companion import metrics
from companion.control import make_controller
from companion.control.pid import PidController
from companion.model import robot_pose_at, slot_reference
from companion.params import Params
from companion.sim.episode import run_episode
from companion.sim.person import circle, line
from companion.types import Observation, PersonState, Pose

BASELINES = ("pid", "vsm", "ic")

# Person at the origin walking +x at 1 m/s, slot on the left: R belongs at (0, 1), so the robot's
# axle at (-d, 1) = (-0.25, 1) with heading 0.
OFF_SLOT = {"behind": Pose(-1.25, 1.0, 0.0), "outside": Pose(-0.25, 2.0, 0.0),
            "ahead": Pose(0.75, 1.0, 0.0)}


def within_limits(log, p):
    return (np.all(np.abs(log["v"]) <= p.robot.v_max + 1e-12)
            and np.all(np.abs(log["omega"]) <= p.robot.omega_max + 1e-12))


VSM_LIMIT_CYCLE = pytest.mark.xfail(
    strict=True, reason="under the supervisor's angular acceleration limit the VSM falls into "
    "a limit cycle from this start (docs/baselines.md)")


@pytest.mark.parametrize("name", BASELINES)
@pytest.mark.parametrize("where", sorted(OFF_SLOT))
def test_converges_on_line_from_one_metre_off(name, where, request):
    if (name, where) == ("vsm", "outside"):
        request.applymarker(VSM_LIMIT_CYCLE)
    p = Params()
    log = run_episode(make_controller(name, p), line((0.0, 0.0, 0.0), 1.0), p, 25.0,
                      start=OFF_SLOT[where])
    e = metrics.errors(log)
    late = log["t"] >= 20.0
    assert np.max(np.abs(e["rho"][late])) < 0.05
    assert np.max(np.abs(e["alpha"][late])) < 0.05
    assert within_limits(log, p)


@pytest.mark.parametrize("name", BASELINES)
def test_far_start_saturates_without_wild_overshoot(name, request):
    if name == "vsm":
        request.applymarker(VSM_LIMIT_CYCLE)
    p = Params()
    log = run_episode(make_controller(name, p), line((0.0, 0.0, 0.0), 1.0), p, 30.0,
                      start=Pose(-4.0, 4.0, 0.0))
    assert within_limits(log, p)
    assert np.max(np.abs(log["v"])) == pytest.approx(p.robot.v_max)  # it does saturate
    alpha_e = np.abs(metrics.errors(log)["alpha"])
    first = np.flatnonzero(alpha_e < 0.1)[0]
    assert np.max(alpha_e[first:]) < 0.3
    assert abs(metrics.errors(log)["rho"][-1]) < 0.05


@pytest.mark.parametrize("name", BASELINES)
def test_circle_rmse(name):
    p = Params()
    log = run_episode(make_controller(name, p), circle((0.0, 0.0, 0.0), 3.0, 1.0), p, 60.0)
    m = metrics.compute(log)
    assert m["rmse_rho_m"] < 0.3
    assert within_limits(log, p)


@pytest.mark.parametrize("name", BASELINES)
def test_exact_at_the_circle_equilibrium(name):
    """Started in the slot with the slot-holding heading, each law holds it (no standing
    error from the feedforward)."""
    p = Params()
    person = circle((0.0, 0.0, 0.0), 3.0, 1.0)
    h, f, d = person.state(0.0), p.formation, p.robot.d
    ref = slot_reference(h.v, h.omega, f.distance, f.bearing, d)
    start = Pose(*robot_pose_at(f.distance, f.bearing, ref.beta, h.x, h.y, h.theta, d))
    log = run_episode(make_controller(name, p), person, p, 20.0, start=start,
                      start_velocity=(ref.v, ref.omega))
    e = metrics.errors(log)
    assert np.max(np.abs(e["rho"])) < 1e-6
    assert np.max(np.abs(e["alpha"])) < 1e-6
    assert np.max(np.abs(e["beta_ref"])) < 1e-6


def test_pid_integrators_do_not_wind_up_in_saturation():
    p = Params()
    c = PidController(p)
    c.reset()
    # Person 10 m ahead walking away: v saturates at v_max from the first step on.
    obs = Observation(0.0, Pose(0.0, 0.0, 0.0), PersonState(10.0, -1.0, 0.0, 1.0, 0.0))
    for _ in range(200):
        cmd = c.step(obs)
        assert cmd.v == p.robot.v_max
    assert c._i[0] == 0.0  # conditional integration: frozen while pushing into the limit


def test_pid_integral_term_is_clamped():
    p = Params()
    c = PidController(p)
    c.reset()
    # Slot 0.2 m ahead of R: v is not saturated, the integral grows but stops at i_limit_v.
    obs = Observation(0.0, Pose(-0.45, 1.0, 0.0), PersonState(0.0, 0.0, 0.0, 0.0, 0.0))
    for _ in range(20000):
        c.step(obs)
    assert c._i[0] == pytest.approx(p.pid.i_limit_v)
    assert math.isfinite(c._i[1])
