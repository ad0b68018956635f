"""Property tests of the companion model (paper Sec. 2, Eq. 4-8; docs/model.md R1-R3, R6).

Checks derivatives against finite differences, geometric identities under rigid motions of
the whole scene, the model against the kinematics it is derived from, the slot reference as
an exact equilibrium, and the discretisations against closed forms.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from companion.geometry import TWO_PI, offset_point, unicycle_step, wrap_pi
from companion.model import (
    discretize,
    dynamics,
    jacobians,
    relative_state,
    robot_pose_at,
    slot_reference,
)
from companion.params import BEHIND, FRONT, LEFT, RIGHT

SETTINGS = settings(max_examples=150, deadline=None)

T = 0.05
D = 0.25

rhos = st.floats(0.3, 5.0)
angles = st.floats(-10.0, 10.0, allow_nan=False)
bearings = st.floats(0.0, TWO_PI, exclude_max=True)
headings_diff = st.floats(-math.pi, math.pi, exclude_min=True)
vs = st.floats(-1.5, 1.5)
omegas = st.floats(-0.5 * math.pi, 0.5 * math.pi)
offsets = st.floats(0.05, 0.5)
coords = st.floats(-20.0, 20.0)
person_v = st.floats(0.0, 1.5)
person_omega = st.floats(-0.6, 0.6)


def circ(a: float, b: float) -> float:
    """Signed circular difference a - b in (-pi, pi]."""
    return wrap_pi(a - b)


def fd_jacobian(f, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        cols.append((f(x + e) - f(x - e)) / (2 * h))
    return np.column_stack(cols)


# --------------------------------------------------------------------------- Jacobians

@SETTINGS
@given(rhos, angles, angles, vs, omegas, person_v, person_omega, offsets)
def test_jacobians_match_central_differences(rho, alpha, beta, v, om, vh, omh, d):
    chi = np.array([rho, alpha, beta])
    u = np.array([v, om])
    w = np.array([vh, omh])
    jx, ju = jacobians(chi, u, w, d)
    assert jx.shape == (3, 3) and ju.shape == (3, 2)
    fd_x = fd_jacobian(lambda c: dynamics(c, u, w, d), chi)
    fd_u = fd_jacobian(lambda uu: dynamics(chi, uu, w, d), u)
    np.testing.assert_allclose(jx, fd_x, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(ju, fd_u, rtol=1e-6, atol=1e-6)


@SETTINGS
@given(rhos, angles, angles, vs, omegas, person_v, person_omega, offsets)
def test_dynamics_periodic_in_angles(rho, alpha, beta, v, om, vh, omh, d):
    """f does not depend on the representative of alpha and beta mod 2*pi."""
    u, w = np.array([v, om]), np.array([vh, omh])
    f0 = dynamics(np.array([rho, alpha, beta]), u, w, d)
    f1 = dynamics(np.array([rho, alpha + TWO_PI, beta - 2 * TWO_PI]), u, w, d)
    np.testing.assert_allclose(f0, f1, rtol=0, atol=1e-10)


# --------------------------------------------------------------------------- geometry

def _place_reference_point(px, py, pth, local_x, local_y, robot_theta, d):
    """Robot pose whose reference point R is at (local_x, local_y) in the person's frame."""
    c, s = math.cos(pth), math.sin(pth)
    rx = px + c * local_x - s * local_y
    ry = py + s * local_x + c * local_y
    return rx - d * math.cos(robot_theta), ry - d * math.sin(robot_theta), robot_theta


@pytest.mark.parametrize("local, expected", [((0.0, 1.0), LEFT), ((0.0, -1.0), RIGHT),
                                             ((-1.0, 0.0), BEHIND), ((1.0, 0.0), FRONT)])
def test_bearing_sides_at_origin(local, expected):
    """Person at the origin heading +x (docs/model.md R1)."""
    for theta_r in (0.0, 0.7, -2.0, math.pi):
        pose = _place_reference_point(0.0, 0.0, 0.0, *local, theta_r, D)
        rho, alpha, beta = relative_state(*pose, 0.0, 0.0, 0.0, D)
        assert rho == pytest.approx(1.0, abs=1e-12)
        assert circ(alpha, expected) == pytest.approx(0.0, abs=1e-12)
        assert 0.0 <= alpha < TWO_PI
        assert beta == pytest.approx(wrap_pi(-theta_r), abs=1e-12)
    assert LEFT == pytest.approx(math.pi / 2) and RIGHT == pytest.approx(3 * math.pi / 2)
    assert BEHIND == pytest.approx(math.pi) and FRONT == 0.0


@SETTINGS
@given(coords, coords, angles, angles, rhos, offsets,
       st.sampled_from([((0.0, 1.0), LEFT), ((0.0, -1.0), RIGHT), ((-1.0, 0.0), BEHIND),
                        ((1.0, 0.0), FRONT)]))
def test_bearing_sides_invariant_under_rigid_motion(px, py, pth, theta_r, scale, d, case):
    (lx, ly), expected = case
    pose = _place_reference_point(px, py, pth, scale * lx, scale * ly, theta_r, d)
    rho, alpha, beta = relative_state(*pose, px, py, pth, d)
    assert rho == pytest.approx(scale, abs=1e-10)
    assert 0.0 <= alpha < TWO_PI
    assert -math.pi < beta <= math.pi
    assert circ(alpha, expected) == pytest.approx(0.0, abs=1e-9)
    assert circ(beta, pth - theta_r) == pytest.approx(0.0, abs=1e-12)


@SETTINGS
@given(coords, coords, angles, coords, coords, angles, offsets, coords, coords, angles)
def test_relative_state_invariant_under_rigid_motion(rx, ry, rth, px, py, pth, d, tx, ty, phi):
    """Rotating and translating robot and person together leaves chi unchanged."""
    assume(math.dist(offset_point(rx, ry, rth, d), (px, py)) > 1e-3)
    c, s = math.cos(phi), math.sin(phi)
    move = lambda x, y: (tx + c * x - s * y, ty + s * x + c * y)  # noqa: E731
    chi0 = relative_state(rx, ry, rth, px, py, pth, d)
    chi1 = relative_state(*move(rx, ry), rth + phi, *move(px, py), pth + phi, d)
    assert chi1[0] == pytest.approx(chi0[0], abs=1e-9)
    assert circ(chi1[1], chi0[1]) == pytest.approx(0.0, abs=1e-7)
    assert circ(chi1[2], chi0[2]) == pytest.approx(0.0, abs=1e-12)


@SETTINGS
@given(st.floats(0.05, 10.0), bearings, headings_diff, coords, coords, angles, offsets)
def test_robot_pose_round_trip(rho, alpha, beta, px, py, pth, d):
    pose = robot_pose_at(rho, alpha, beta, px, py, pth, d)
    r2, a2, b2 = relative_state(*pose, px, py, pth, d)
    assert r2 == pytest.approx(rho, rel=1e-9, abs=1e-9)
    assert circ(a2, alpha) == pytest.approx(0.0, abs=1e-8 / rho)
    assert circ(b2, beta) == pytest.approx(0.0, abs=1e-12)
    assert 0.0 <= a2 < TWO_PI and -math.pi < b2 <= math.pi


@SETTINGS
@given(coords, coords, angles, coords, coords, angles, offsets)
def test_relative_state_round_trip_from_pose(rx, ry, rth, px, py, pth, d):
    """relative_state then robot_pose_at gives the robot pose back."""
    assume(math.dist(offset_point(rx, ry, rth, d), (px, py)) > 1e-3)
    chi = relative_state(rx, ry, rth, px, py, pth, d)
    x, y, th = robot_pose_at(*chi, px, py, pth, d)
    assert x == pytest.approx(rx, abs=1e-9)
    assert y == pytest.approx(ry, abs=1e-9)
    assert circ(th, rth) == pytest.approx(0.0, abs=1e-12)


# --------------------------------------------------------------------------- model vs kinematics

@SETTINGS
@given(rhos, bearings, headings_diff, coords, coords, angles, vs, omegas, person_v, person_omega,
       offsets)
def test_dynamics_consistent_with_kinematics(rho, alpha, beta, px, py, pth, v, om, vh, omh, d):
    """Central difference of chi along the exact unicycle flows of robot and person == f."""
    robot = robot_pose_at(rho, alpha, beta, px, py, pth, d)
    person = (px, py, pth)
    h = 1e-5

    def chi_at(dt):
        r = unicycle_step(*robot, v, om, dt)
        p = unicycle_step(*person, vh, omh, dt)
        return relative_state(*r, *p, d)

    fwd, back = chi_at(h), chi_at(-h)
    rate = np.array([(fwd[0] - back[0]) / (2 * h),
                     circ(fwd[1], back[1]) / (2 * h),
                     circ(fwd[2], back[2]) / (2 * h)])
    f = dynamics(np.array([rho, alpha, beta]), np.array([v, om]), np.array([vh, omh]), d)
    np.testing.assert_allclose(rate, f, rtol=1e-5, atol=1e-5)


@settings(max_examples=30, deadline=None)
@given(rhos, bearings, headings_diff, vs, omegas, person_v, person_omega, offsets)
def test_dynamics_integrates_to_kinematics(rho, alpha, beta, v, om, vh, omh, d):
    """Over a finite horizon, integrating chi_dot = f matches the two exact unicycle flows."""
    horizon = 0.5
    robot = robot_pose_at(rho, alpha, beta, 0.0, 0.0, 0.0, d)
    r = unicycle_step(*robot, v, om, horizon)
    p = unicycle_step(0.0, 0.0, 0.0, vh, omh, horizon)
    rho1, a1, b1 = relative_state(*r, *p, d)
    assume(rho1 > 0.1)
    # rho stays away from 0 over the whole horizon (f is singular there).
    for t in np.linspace(0.0, horizon, 21):
        assume(relative_state(*unicycle_step(*robot, v, om, t),
                              *unicycle_step(0.0, 0.0, 0.0, vh, omh, t), d)[0] > 0.1)
    u, w = np.array([v, om]), np.array([vh, omh])
    sol = solve_ivp(lambda t, c: dynamics(c, u, w, d), (0.0, horizon), [rho, alpha, beta],
                    method="DOP853", rtol=1e-11, atol=1e-12)
    assert sol.success
    end = sol.y[:, -1]
    assert end[0] == pytest.approx(rho1, abs=1e-7)
    assert circ(end[1], a1) == pytest.approx(0.0, abs=1e-6)
    assert circ(end[2], b1) == pytest.approx(0.0, abs=1e-9)


def test_faster_robot_on_left_moves_ahead():
    """docs/model.md R3: on the left, a robot faster than the person makes alpha decrease."""
    chi = np.array([1.0, LEFT, 0.0])
    f = dynamics(chi, np.array([1.2, 0.0]), np.array([1.0, 0.0]), D)
    assert f[1] < 0.0
    # and on the right side alpha increases (R moves ahead, bearing 3pi/2 -> 2pi).
    f = dynamics(np.array([1.0, RIGHT, 0.0]), np.array([1.2, 0.0]), np.array([1.0, 0.0]), D)
    assert f[1] > 0.0


# --------------------------------------------------------------------------- slot reference

def _slot_speed(v_h, omega_h, rho_d, alpha_d):
    """|V| of the desired reference point (person frame)."""
    return math.hypot(v_h - rho_d * omega_h * math.sin(alpha_d),
                      rho_d * omega_h * math.cos(alpha_d))


@SETTINGS
@given(person_v, person_omega, st.floats(0.3, 3.0), bearings, offsets)
def test_slot_reference_is_exact_equilibrium(v_h, omega_h, rho_d, alpha_d, d):
    # An equilibrium exists only if the slot moves at least as fast as R must move sideways
    # while the robot turns at omega_h: |V| >= d |omega_h| (see the xfail test below).
    assume(_slot_speed(v_h, omega_h, rho_d, alpha_d) >= d * abs(omega_h) + 1e-6)
    ref = slot_reference(v_h, omega_h, rho_d, alpha_d, d)
    assert -math.pi < ref.beta <= math.pi
    assert ref.omega == omega_h
    f = dynamics(np.array([rho_d, alpha_d, ref.beta]), np.array([ref.v, ref.omega]),
                 np.array([v_h, omega_h]), d)
    np.testing.assert_allclose(f, 0.0, atol=1e-9)


@SETTINGS
@given(person_v, st.floats(0.3, 3.0), bearings, offsets)
def test_slot_reference_straight_walk(v_h, rho_d, alpha_d, d):
    ref = slot_reference(v_h, 0.0, rho_d, alpha_d, d)
    assert ref.beta == 0.0
    assert ref.v == pytest.approx(v_h, abs=1e-9)   # v_h < 1e-9 is treated as standing still
    assert ref.omega == 0.0


@SETTINGS
@given(person_v, person_omega, st.floats(0.3, 3.0), bearings, offsets, angles, coords, coords)
def test_slot_reference_holds_slot_in_world(v_h, omega_h, rho_d, alpha_d, d, pth, px, py):
    """Simulating both exact flows from the slot for 1 s keeps chi at (rho_d, alpha_d, beta)."""
    assume(_slot_speed(v_h, omega_h, rho_d, alpha_d) >= d * abs(omega_h) + 1e-6)
    ref = slot_reference(v_h, omega_h, rho_d, alpha_d, d)
    robot = robot_pose_at(rho_d, alpha_d, ref.beta, px, py, pth, d)
    r = unicycle_step(*robot, ref.v, ref.omega, 1.0)
    p = unicycle_step(px, py, pth, v_h, omega_h, 1.0)
    rho, alpha, beta = relative_state(*r, *p, d)
    assert rho == pytest.approx(rho_d, abs=1e-9)
    assert circ(alpha, alpha_d) == pytest.approx(0.0, abs=1e-8)
    assert circ(beta, ref.beta) == pytest.approx(0.0, abs=1e-9)


def test_slot_reference_infeasible_turn_is_signalled():
    # Default geometry: left side, rho_d = 1, d = 0.25; person walks a 1 m radius left turn,
    # so the desired slot is the centre of the person's circle and does not move.
    v_h, omega_h, rho_d, alpha_d = 0.5, 0.5, 1.0, LEFT
    assert _slot_speed(v_h, omega_h, rho_d, alpha_d) < D * abs(omega_h)
    ref = slot_reference(v_h, omega_h, rho_d, alpha_d, D)
    assert ref.feasible is False
    assert math.isfinite(ref.beta) and math.isfinite(ref.v)
    assert slot_reference(1.0, 0.2, rho_d, alpha_d, D).feasible is True


# --------------------------------------------------------------------------- printed Jacobian

@SETTINGS
@given(st.floats(0.3, 3.0), bearings, headings_diff, person_v, person_omega, offsets)
def test_discretized_jacobian_matches_corrected_paper_form(rho_d, alpha_d, beta_d, v_h, omega_h,
                                                           d):
    """Eq. 8 entries with the corrections of docs/model.md R3, at u = u_d = u_h (K_f = 1)."""
    chi = np.array([rho_d, alpha_d, beta_d])
    u = w = np.array([v_h, omega_h])
    a, b = discretize(*jacobians(chi, u, w, d), T, "euler")
    g = alpha_d + beta_d
    sg, cg, sa, ca = math.sin(g), math.cos(g), math.sin(alpha_d), math.cos(alpha_d)
    v_d, om_d = v_h, omega_h
    a_exp = np.array([
        [1.0, T * (-v_h * sg + v_h * sa + d * omega_h * cg), -T * (v_h * sg - d * omega_h * cg)],
        [-T / rho_d**2 * (v_h * sa - v_h * sg + d * omega_h * cg),
         T / rho_d * (v_h * ca - v_d * cg - d * om_d * sg) + 1.0,
         -T / rho_d * (v_d * cg + d * om_d * sg)],
        [0.0, 0.0, 1.0],
    ])
    b_exp = np.array([
        [T * cg, T * d * sg],
        [-T / rho_d * sg, T / rho_d * d * cg],   # printed with +(T/rho_d) sin(gamma)
        [0.0, -T],
    ])
    np.testing.assert_allclose(a, a_exp, rtol=0, atol=1e-14)
    np.testing.assert_allclose(b, b_exp, rtol=0, atol=1e-14)


@pytest.mark.parametrize("alpha_d", [LEFT, RIGHT])
def test_printed_b21_sign_is_wrong(alpha_d):
    """B~[1, 0] = -(T/rho_d) sin(gamma): the opposite sign of the printed entry."""
    rho_d = 1.0
    chi = np.array([rho_d, alpha_d, 0.0])
    u = w = np.array([1.0, 0.0])
    _, b = discretize(*jacobians(chi, u, w, D), T, "euler")
    printed = T / rho_d * math.sin(alpha_d)
    assert b[1, 0] == pytest.approx(-printed, abs=1e-15)
    assert abs(b[1, 0] - printed) == pytest.approx(2 * T / rho_d)


# --------------------------------------------------------------------------- discretize

@SETTINGS
@given(rhos, angles, angles, vs, omegas, person_v, person_omega, offsets,
       st.floats(1e-3, 0.2))
def test_zoh_agrees_with_euler_to_second_order(rho, alpha, beta, v, om, vh, omh, d, dt):
    jx, ju = jacobians(np.array([rho, alpha, beta]), np.array([v, om]), np.array([vh, omh]), d)
    ae, be = discretize(jx, ju, dt, "euler")
    az, bz = discretize(jx, ju, dt, "zoh")
    nj = np.linalg.norm(jx, 2)
    grow = math.exp(dt * nj)
    # e^{J dt} - (I + J dt) = sum_{k>=2} (J dt)^k / k!  and  the B analogue.
    assert np.linalg.norm(az - ae, 2) <= 0.5 * (dt * nj) ** 2 * grow + 1e-13
    assert np.linalg.norm(bz - be, 2) <= 0.5 * dt**2 * nj * np.linalg.norm(ju, 2) * grow + 1e-13
    # and the leading term is exactly J^2 dt^2 / 2 (resp. J B dt^2 / 2).
    assert np.linalg.norm(az - ae - 0.5 * dt**2 * jx @ jx, 2) <= (dt * nj) ** 3 * grow / 6 + 1e-13


@SETTINGS
@given(rhos, angles, angles, vs, omegas, person_v, person_omega, offsets, st.floats(1e-3, 0.5))
def test_zoh_semigroup(rho, alpha, beta, v, om, vh, omh, d, dt):
    """ZOH over 2 dt == two ZOH steps of dt with the input held: A2 = A^2, B2 = A B + B."""
    jx, ju = jacobians(np.array([rho, alpha, beta]), np.array([v, om]), np.array([vh, omh]), d)
    a1, b1 = discretize(jx, ju, dt, "zoh")
    a2, b2 = discretize(jx, ju, 2 * dt, "zoh")
    np.testing.assert_allclose(a2, a1 @ a1, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(b2, a1 @ b1 + b1, rtol=1e-10, atol=1e-12)


@SETTINGS
@given(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(1e-3, 1.0))
def test_zoh_closed_forms(lam1, lam2, dt):
    # Double integrator: A = [[1, dt], [0, 1]], B = [[dt^2/2], [dt]].
    a, b = discretize(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), dt, "zoh")
    np.testing.assert_allclose(a, [[1.0, dt], [0.0, 1.0]], atol=1e-14)
    np.testing.assert_allclose(b, [[0.5 * dt * dt], [dt]], atol=1e-14)
    # Diagonal: A = diag(e^{l dt}), B_i = (e^{l_i dt} - 1) / l_i * b_i.
    jx = np.diag([lam1, lam2])
    ju = np.array([[1.0, 2.0], [-1.0, 0.5]])
    a, b = discretize(jx, ju, dt, "zoh")
    def phi(lam):
        x = lam * dt
        return dt if x == 0.0 else dt * (math.expm1(x) / x)

    np.testing.assert_allclose(a, np.diag([math.exp(lam1 * dt), math.exp(lam2 * dt)]),
                               rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(b, np.diag([phi(lam1), phi(lam2)]) @ ju, rtol=1e-10, atol=1e-14)


@SETTINGS
@given(rhos, bearings, headings_diff, person_v, person_omega, offsets, st.floats(1e-3, 0.2))
def test_zoh_exact_for_model_at_rest_input(rho, alpha, beta, vh, omh, d, dt):
    """With u = 0 and w = 0 the linearisation has jx = 0: ZOH and Euler are both exact."""
    jx, ju = jacobians(np.array([rho, alpha, beta]), np.zeros(2), np.zeros(2), d)
    np.testing.assert_array_equal(jx, np.zeros((3, 3)))
    for method in ("euler", "zoh"):
        a, b = discretize(jx, ju, dt, method)
        np.testing.assert_allclose(a, np.eye(3), atol=1e-15)
        np.testing.assert_allclose(b, dt * ju, atol=1e-15)


@SETTINGS
@given(rhos, angles, angles, vs, omegas, person_v, person_omega, offsets, st.floats(1e-3, 0.2),
       st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1))
def test_zoh_matches_linear_ode(rho, alpha, beta, v, om, vh, omh, d, dt, x1, x2, x3, u1, u2):
    jx, ju = jacobians(np.array([rho, alpha, beta]), np.array([v, om]), np.array([vh, omh]), d)
    a, b = discretize(jx, ju, dt, "zoh")
    x0, u0 = np.array([x1, x2, x3]), np.array([u1, u2])
    sol = solve_ivp(lambda t, x: jx @ x + ju @ u0, (0.0, dt), x0, method="DOP853",
                    rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(a @ x0 + b @ u0, sol.y[:, -1], rtol=1e-9, atol=1e-11)
    # and expm of the block matrix is what it claims
    np.testing.assert_allclose(a, expm(jx * dt), rtol=1e-12, atol=1e-14)


def test_discretize_rejects_unknown_method():
    with pytest.raises(ValueError, match="method"):
        discretize(np.zeros((3, 3)), np.zeros((3, 2)), T, "tustin")
