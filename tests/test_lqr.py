"""Property tests of the augmented-state LQR (paper Sec. 3.2, Eq. 11-16) and its controller.

Modelled on python-control's dlqr tests: the Riccati residual, closed-loop stability, the
closed form of K from P and the optimality of u = -K x, rather than stored numbers.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from companion.control import LqrController, paper_lqr
from companion.geometry import TWO_PI, unicycle_step
from companion.model import discretize, jacobians, slot_reference
from companion.params import LEFT, Formation, Params
from companion.riccati import augment, dlqr, riccati_residual
from companion.types import Observation, PersonState, Pose

SETTINGS = settings(max_examples=120, deadline=None)

# Table 1.
Q = np.diag([25.0, 10.0, 25.0, 30.0, 30.0])
R = np.diag([20.0, 20.0])
T = 0.05
D = 0.25
V_MAX, OMEGA_MAX = 1.5, 0.5 * math.pi

rhos = st.floats(0.2, 5.0)
bearings = st.floats(0.0, TWO_PI, exclude_max=True)
betas = st.floats(-math.pi, math.pi, exclude_min=True)
vs = st.floats(-V_MAX, V_MAX)
omegas = st.floats(-OMEGA_MAX, OMEGA_MAX)
person_v = st.floats(0.0, 1.5)
person_omega = st.floats(-0.6, 0.6)
methods = st.sampled_from(["euler", "zoh"])


def stabilisability_margin(a: np.ndarray, b: np.ndarray) -> float:
    """PBH margin: min sigma_min([A - lam I, B]) over the eigenvalues of A near or outside the
    unit circle. Zero means an unstabilisable mode, for which no stabilising DARE solution
    exists (e.g. robot and person both at rest)."""
    n = a.shape[0]
    out = math.inf
    for lam in np.linalg.eigvals(a):
        if abs(lam) >= 1.0 - 1e-2:
            s = np.linalg.svd(np.hstack([a - lam * np.eye(n), b]), compute_uv=False)[-1]
            out = min(out, float(s))
    return out


def augmented_model(chi, u, w, method="euler", d=D, dt=T):
    a, b = discretize(*jacobians(np.asarray(chi, float), np.asarray(u, float),
                                 np.asarray(w, float), d), dt, method)
    return a, b, *augment(a, b)


def check_dlqr(a_bar: np.ndarray, b_bar: np.ndarray) -> None:
    k, p = dlqr(a_bar, b_bar, Q, R)
    assert k.shape == (2, 5) and p.shape == (5, 5)
    assert np.all(np.isfinite(k)) and np.all(np.isfinite(p))
    # P is the symmetric positive semi-definite solution of Eq. 15.
    scale = max(1.0, float(np.max(np.abs(p))))
    np.testing.assert_allclose(p, p.T, atol=1e-9 * scale)
    assert np.min(np.linalg.eigvalsh(0.5 * (p + p.T))) >= -1e-9 * scale
    assert riccati_residual(a_bar, b_bar, Q, R, p) < 1e-8 * scale
    # Closed loop strictly inside the unit circle.
    assert np.max(np.abs(np.linalg.eigvals(a_bar - b_bar @ k))) < 1.0
    # Eq. 14: K = (R + B'PB)^-1 B'PA.
    k_closed = np.linalg.inv(R + b_bar.T @ p @ b_bar) @ b_bar.T @ p @ a_bar
    np.testing.assert_allclose(k, k_closed, rtol=1e-8, atol=1e-10 * max(1.0, np.abs(k).max()))


# --------------------------------------------------------------------------- augment

@SETTINGS
@given(st.integers(1, 5), st.integers(1, 4), st.integers(0, 2**32 - 1))
def test_augment_block_structure(n, m, seed):
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(n, n)), rng.normal(size=(n, m))
    a_bar, b_bar = augment(a, b)
    assert a_bar.shape == (n + m, n + m) and b_bar.shape == (n + m, m)
    np.testing.assert_array_equal(a_bar[:n, :n], a)
    np.testing.assert_array_equal(a_bar[:n, n:], b)
    np.testing.assert_array_equal(a_bar[n:, :n], np.zeros((m, n)))
    np.testing.assert_array_equal(a_bar[n:, n:], np.eye(m))
    np.testing.assert_array_equal(b_bar[:n], b)
    np.testing.assert_array_equal(b_bar[n:], np.eye(m))
    # Semantics: xi(k+1) = A_bar xi + B_bar du reproduces x(k+1) = A x + B (u_prev + du).
    x, u_prev, du = rng.normal(size=n), rng.normal(size=m), rng.normal(size=m)
    nxt = a_bar @ np.concatenate([x, u_prev]) + b_bar @ du
    np.testing.assert_allclose(nxt[:n], a @ x + b @ (u_prev + du), atol=1e-12)
    np.testing.assert_allclose(nxt[n:], u_prev + du, atol=1e-12)


def test_augment_rejects_mismatched_a():
    with pytest.raises(ValueError, match=r"\bA\b"):
        augment(np.eye(4), np.ones((3, 2)))
    with pytest.raises(ValueError, match=r"\bA\b"):
        augment(np.ones((3, 2)), np.ones((3, 2)))


# --------------------------------------------------------------------------- dlqr sweep

@SETTINGS
@given(rhos, bearings, betas, vs, omegas, person_v, person_omega, methods)
def test_dlqr_at_measured_operating_points(rho, alpha, beta, v, om, vh, omh, method):
    """Linearisation at a measured state and the last applied input (the controller's default)."""
    a, b, a_bar, b_bar = augmented_model((rho, alpha, beta), (v, om), (vh, omh), method)
    assume(stabilisability_margin(a, b) > 1e-5)
    check_dlqr(a_bar, b_bar)


@SETTINGS
@given(st.floats(0.3, 3.0), bearings, person_v, person_omega, methods,
       st.sampled_from(["geometric", "person"]))
def test_dlqr_at_desired_operating_points(rho_d, alpha_d, vh, omh, method, feedforward):
    """Linearisation at (rho_d, alpha_d, beta_d) with u = u_d (paper Eq. 8; both feedforwards)."""
    if feedforward == "person":
        beta_d, u_d = 0.0, (vh, omh)
    else:
        ref = slot_reference(vh, omh, rho_d, alpha_d, D)
        beta_d, u_d = ref.beta, (ref.v, ref.omega)
    a, b, a_bar, b_bar = augmented_model((rho_d, alpha_d, beta_d), u_d, (vh, omh), method)
    assume(stabilisability_margin(a, b) > 1e-5)
    check_dlqr(a_bar, b_bar)


@pytest.mark.parametrize("alpha_d", [LEFT, 1.5 * math.pi, math.pi, 0.0])
@pytest.mark.parametrize("vh", [0.5, 1.0, 1.5])
def test_dlqr_table1_straight_walk(alpha_d, vh):
    """The paper's own operating points (straight walk, each side) are well posed."""
    a, b, a_bar, b_bar = augmented_model((1.0, alpha_d, 0.0), (vh, 0.0), (vh, 0.0))
    assert stabilisability_margin(a, b) > 1e-3
    check_dlqr(a_bar, b_bar)


@SETTINGS
@given(rhos, bearings, betas, vs, omegas, person_v, person_omega,
       st.lists(st.floats(-1.0, 1.0), min_size=5, max_size=5),
       st.lists(st.floats(-1.0, 1.0), min_size=2, max_size=2))
def test_dlqr_gain_minimises_bellman_equation(rho, alpha, beta, v, om, vh, omh, x, delta):
    """x'Px = min_u x'Qx + u'Ru + (Ax+Bu)'P(Ax+Bu), attained at u = -Kx."""
    a, b, a_bar, b_bar = augmented_model((rho, alpha, beta), (v, om), (vh, omh))
    assume(stabilisability_margin(a, b) > 1e-5)
    k, p = dlqr(a_bar, b_bar, Q, R)
    x = np.array(x)

    def bellman(u):
        nxt = a_bar @ x + b_bar @ u
        return x @ Q @ x + u @ R @ u + nxt @ p @ nxt

    u_opt = -k @ x
    best = bellman(u_opt)
    scale = max(1.0, float(np.abs(p).max())) * (1.0 + x @ x)
    assert best == pytest.approx(x @ p @ x, abs=1e-8 * scale)
    assert bellman(u_opt + np.array(delta)) >= best - 1e-9 * scale


def test_dlqr_scalar_closed_form():
    """Scalar DARE p = a^2 p - a^2 b^2 p^2 / (r + b^2 p) + q has a known positive root."""
    for a, b, q, r in [(1.0, 1.0, 1.0, 1.0), (2.0, 0.5, 3.0, 0.7), (0.3, 2.0, 1.0, 5.0)]:
        # r p + b^2 p^2 = a^2 r p + q r + q b^2 p  ->  b^2 p^2 + (r - a^2 r - q b^2) p - q r = 0
        c1 = r - a * a * r - q * b * b
        p_exp = (-c1 + math.sqrt(c1 * c1 + 4 * b * b * q * r)) / (2 * b * b)
        k, p = dlqr(np.array([[a]]), np.array([[b]]), np.array([[q]]), np.array([[r]]))
        assert p[0, 0] == pytest.approx(p_exp, rel=1e-10)
        assert k[0, 0] == pytest.approx(a * b * p_exp / (r + b * b * p_exp), rel=1e-10)
        assert abs(a - b * k[0, 0]) < 1.0


def test_dlqr_unstabilisable_raises():
    # Person and robot at rest, robot at the default (left) slot: jx = 0, A = I, rank B = 2.
    a, b, a_bar, b_bar = augmented_model((1.0, LEFT, 0.0), (0.0, 0.0), (0.0, 0.0))
    assert stabilisability_margin(a, b) < 1e-12
    with pytest.raises(np.linalg.LinAlgError, match="no stabilising solution"):
        dlqr(a_bar, b_bar, Q, R)


# --------------------------------------------------------------------------- dlqr input checks

def _model():
    _, _, a_bar, b_bar = augmented_model((1.0, LEFT, 0.0), (1.0, 0.0), (1.0, 0.0))
    return a_bar, b_bar


@pytest.mark.parametrize("which, a, b, q, r", [
    ("A", np.eye(4), None, None, None),
    ("A", np.ones((5, 4)), None, None, None),
    ("Q", None, None, np.eye(4), None),
    ("Q", None, None, np.ones(5), None),
    ("Q", None, None, np.diag([25.0, 10, 25, 30, 30]) + np.triu(np.ones((5, 5)), 1), None),
    ("Q", None, None, np.diag([25.0, 10, 25, 30, -30]), None),
    ("R", None, None, None, np.eye(3)),
    ("R", None, None, None, np.array([20.0, 20.0])),
    ("R", None, None, None, np.array([[20.0, 1.0], [0.0, 20.0]])),
    ("R", None, None, None, np.diag([20.0, 0.0])),
    ("R", None, None, None, np.diag([20.0, -1.0])),
    ("R", None, None, None, np.array([[1.0, 2.0], [2.0, 1.0]])),   # symmetric, indefinite
])
def test_dlqr_input_checks_name_the_matrix(which, a, b, q, r):
    a_bar, b_bar = _model()
    a = a_bar if a is None else a
    b = b_bar if b is None else b
    q = Q if q is None else q
    r = R if r is None else r
    with pytest.raises(ValueError, match=rf"\b{which}\b"):
        dlqr(a, b, q, r)


@pytest.mark.parametrize("b", [np.ones(5), np.ones((5, 2, 1))])
def test_dlqr_bad_b_dimension_names_b(b):
    a_bar, _ = _model()
    with pytest.raises(ValueError, match=r"\bB\b"):
        dlqr(a_bar, b, Q, R)


# --------------------------------------------------------------------------- controller

def _controller(kind: str, bearing: float, distance: float):
    p = Params(formation=Formation(distance=distance, bearing=bearing))
    if kind == "paper":
        return paper_lqr(p)
    lqr = p.lqr
    if kind == "zoh":
        lqr = dataclasses.replace(lqr, discretization="zoh")
    elif kind == "desired":
        lqr = dataclasses.replace(lqr, linearize_at="desired")
    elif kind == "person-ff":
        lqr = dataclasses.replace(lqr, feedforward="person")
    return LqrController(dataclasses.replace(p, lqr=lqr))


poses = st.builds(Pose, st.floats(-10, 10), st.floats(-10, 10), st.floats(-10, 10))
# A moving person (v_h >= 0.05 m/s); a person at rest: test_controller_first_step_person_at_rest.
people = st.builds(PersonState, st.floats(-10, 10), st.floats(-10, 10), st.floats(-10, 10),
                   st.floats(0.05, 1.5), st.one_of(st.floats(-0.6, 0.6), st.just(0.0)))
kinds = st.sampled_from(["default", "paper", "zoh", "desired", "person-ff"])
formation_bearings = st.one_of(st.sampled_from([LEFT, 1.5 * math.pi, math.pi, 0.0]), bearings)


def _check_command(c, cmd):
    assert math.isfinite(cmd.v) and math.isfinite(cmd.omega)
    assert abs(cmd.v) <= V_MAX and abs(cmd.omega) <= OMEGA_MAX
    # No wind-up: the stored u_e(k-1) is the applied command minus the feedforward.
    u_d = np.array(c.last.u_d)
    np.testing.assert_allclose(c.u_e_prev, np.array([cmd.v, cmd.omega]) - u_d, rtol=0,
                               atol=1e-12)
    assert np.all(np.isfinite(c.last.gain)) and np.all(np.isfinite(c.last.xi))


@settings(max_examples=100, deadline=None)
@given(kinds, formation_bearings, st.floats(0.9, 2.0),  # >= 0.85: slot outside the keep-out
       st.lists(st.tuples(poses, people), min_size=1, max_size=4))
def test_controller_commands_within_limits(kind, bearing, distance, observations):
    c = _controller(kind, bearing, distance)
    c.reset()
    for i, (robot, person) in enumerate(observations):
        cmd = c.step(Observation(t=i * T, robot=robot, person=person))
        _check_command(c, cmd)


@pytest.mark.parametrize("kind", ["default", "paper", "zoh", "desired", "person-ff"])
def test_controller_no_windup_after_saturation(kind):
    """Far from the slot the command saturates; u_e(k-1) is the saturated input minus u_d."""
    c = _controller(kind, LEFT, 1.0)
    person = PersonState(0.0, 0.0, 0.0, 1.0, 0.1)
    saturated = 0
    robot = Pose(-6.0, -4.0, math.pi)   # far behind-right, facing away
    for i in range(60):
        cmd = c.step(Observation(t=i * T, robot=robot, person=person))
        robot = Pose(*unicycle_step(robot.x, robot.y, robot.theta, cmd.v, cmd.omega, T))
        person = PersonState(*unicycle_step(person.x, person.y, person.theta, person.v,
                                            person.omega, T), person.v, person.omega)
        _check_command(c, cmd)
        saturated += abs(cmd.v) == V_MAX or abs(cmd.omega) == OMEGA_MAX
        # u_e(k-1) must stay within the input limits shifted by u_d (a wound-up integrator
        # would leave them).
        u_d = np.array(c.last.u_d)
        assert np.all(np.abs(c.u_e_prev + u_d) <= np.array([V_MAX, OMEGA_MAX]) + 1e-12)
    assert saturated > 0


@pytest.mark.parametrize("kind", ["default", "paper"])
def test_controller_first_step_person_at_rest(kind):
    c = _controller(kind, 1.5 * math.pi, 1.0)     # right side, rho_d = 1 m
    # Robot about 1 m to the right of a person standing still: close to its slot.
    cmd = c.step(Observation(t=0.0, robot=Pose(0.0, 0.0, 0.0),
                             person=PersonState(0.0, 1.0, 0.0, 0.0, 0.0)))
    _check_command(c, cmd)
