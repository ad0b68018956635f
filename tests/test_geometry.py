"""Property tests of the geometry: angles, the unicycle (paper Eq. 1-2) and obstacle clearance.

Mathematical properties only (ranges, congruences, agreement with an independent numerical
integration of Eq. 1, the semigroup property), no stored numbers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from companion.geometry import (
    TWO_PI,
    clearance,
    min_clearance,
    obstacle_arrays,
    offset_point,
    path_clearance,
    point_clearances,
    unicycle_step,
    wrap_2pi,
    wrap_pi,
    wrap_pi_array,
)
from companion.types import Circle, Wall

SETTINGS = settings(max_examples=150, deadline=None, derandomize=True)

# Angles: moderate ones for congruence checks (the angle's own rounding stays small), any
# finite float for range checks.
moderate_angles = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)
any_angles = st.floats(allow_nan=False, allow_infinity=False)
special_angles = st.sampled_from([0.0, -0.0, math.pi, -math.pi, TWO_PI, -TWO_PI, 3 * math.pi,
                                  -3 * math.pi, 0.5 * math.pi, -0.5 * math.pi,
                                  math.nextafter(math.pi, 10), math.nextafter(-math.pi, -10),
                                  math.nextafter(math.pi, 0), math.nextafter(-math.pi, 0),
                                  math.nextafter(TWO_PI, 10), math.nextafter(TWO_PI, 0),
                                  -1e-300, 1e-300, -5e-324, 5e-324])
angles = st.one_of(moderate_angles, special_angles)

coords = st.floats(-50.0, 50.0, allow_nan=False)
headings = st.floats(-20.0, 20.0, allow_nan=False)
speeds = st.floats(-1.5, 1.5, allow_nan=False)
tiny_rates = st.sampled_from([0.0, -0.0, 1e-15, -1e-12, 1e-9, -1e-8, 1e-7, -1e-6, 2e-6, 1e-5,
                              -1e-4])
rates = st.one_of(st.floats(-0.5 * math.pi, 0.5 * math.pi, allow_nan=False), tiny_rates)
steps = st.floats(0.0, 1.0, allow_nan=False)


def _congruence_error(angle: float, wrapped: float) -> float:
    """Distance of ``(angle - wrapped) / 2pi`` from the nearest integer, in radians."""
    turns = (angle - wrapped) / TWO_PI
    return abs(turns - round(turns)) * TWO_PI


def _tol(angle: float) -> float:
    # angle + pi and fmod rounding: a few ulps of the angle (and of 2pi).
    return 8.0 * math.ulp(max(abs(angle), TWO_PI))


# --------------------------------------------------------------------------- wrap_pi / wrap_2pi

@SETTINGS
@given(st.one_of(any_angles, special_angles))
def test_wrap_pi_range(angle):
    w = wrap_pi(angle)
    assert math.isfinite(w)
    assert -math.pi < w <= math.pi


@SETTINGS
@given(st.one_of(any_angles, special_angles))
def test_wrap_2pi_range(angle):
    w = wrap_2pi(angle)
    assert math.isfinite(w)
    assert 0.0 <= w < TWO_PI


@SETTINGS
@given(angles)
def test_wrap_pi_congruent(angle):
    assert _congruence_error(angle, wrap_pi(angle)) <= _tol(angle)


@SETTINGS
@given(angles)
def test_wrap_2pi_congruent(angle):
    assert _congruence_error(angle, wrap_2pi(angle)) <= _tol(angle)


@SETTINGS
@given(st.floats(-math.pi, math.pi, allow_nan=False, exclude_min=True))
def test_wrap_pi_identity_inside_range(angle):
    assert wrap_pi(angle) == angle


@SETTINGS
@given(st.floats(0.0, TWO_PI, allow_nan=False, exclude_max=True))
def test_wrap_2pi_identity_inside_range(angle):
    assert wrap_2pi(angle) == angle


@SETTINGS
@given(angles)
def test_wraps_agree_and_idempotent(angle):
    a, b = wrap_pi(angle), wrap_2pi(angle)
    # Same point on the circle.
    assert abs(math.sin(a) - math.sin(b)) <= 1e-12 * max(1.0, abs(angle))
    assert abs(math.cos(a) - math.cos(b)) <= 1e-12 * max(1.0, abs(angle))
    # Wrapping a wrapped angle changes nothing.
    assert wrap_2pi(b) == b
    assert wrap_pi(a) == a


@SETTINGS
@given(st.lists(angles, min_size=1, max_size=20))
def test_array_wrap_is_the_scalar_wrap(values):
    assert wrap_pi_array(np.array(values)).tolist() == [wrap_pi(a) for a in values]


def test_wrap_boundaries():
    assert wrap_pi_array(np.array([-math.pi, math.pi])).tolist() == [math.pi, math.pi]
    assert wrap_pi(math.pi) == math.pi
    assert wrap_pi(-math.pi) == math.pi          # (-pi, pi]: -pi maps to +pi
    assert wrap_pi(3 * math.pi) == pytest.approx(math.pi)
    assert wrap_2pi(TWO_PI) == 0.0
    assert wrap_2pi(-1e-300) == 0.0              # tiny negative must not give 2*pi
    assert wrap_2pi(-TWO_PI) == 0.0


# --------------------------------------------------------------------------- unicycle_step

def _integrate(x, y, theta, v, omega, dt):
    """Eq. 1 integrated numerically (DOP853, tight tolerances), independent of the closed form."""
    if dt == 0.0:
        return x, y, theta
    sol = solve_ivp(lambda t, s: [v * math.cos(s[2]), v * math.sin(s[2]), omega],
                    (0.0, dt), [x, y, theta], method="DOP853", rtol=1e-12, atol=1e-13)
    if not sol.success:   # DOP853's step control fails on speeds like 3e-158 (CI found one)
        return _rk4(x, y, theta, v, omega, dt)
    return tuple(sol.y[:, -1])


def _rk4(x, y, theta, v, omega, dt, n=200):
    s = np.array([x, y, theta], dtype=float)
    f = lambda s: np.array([v * math.cos(s[2]), v * math.sin(s[2]), omega])  # noqa: E731
    h = dt / n
    for _ in range(n):
        k1 = f(s)
        k2 = f(s + 0.5 * h * k1)
        k3 = f(s + 0.5 * h * k2)
        k4 = f(s + h * k3)
        s = s + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return tuple(s)


@SETTINGS
@given(coords, coords, headings, speeds, rates, steps)
def test_unicycle_step_matches_ode_integration(x, y, theta, v, omega, dt):
    exact = unicycle_step(x, y, theta, v, omega, dt)
    ref = _integrate(x, y, theta, v, omega, dt)
    np.testing.assert_allclose(exact, ref, rtol=0, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(coords, coords, headings, speeds, rates, steps)
def test_unicycle_step_matches_rk4(x, y, theta, v, omega, dt):
    np.testing.assert_allclose(unicycle_step(x, y, theta, v, omega, dt),
                               _rk4(x, y, theta, v, omega, dt), rtol=0, atol=1e-10)


@SETTINGS
@given(coords, coords, headings, speeds, rates, st.floats(0.0, 2.0, allow_nan=False))
def test_unicycle_step_composition(x, y, theta, v, omega, dt):
    """Two half steps equal one full step (the exact flow is a semigroup)."""
    half = unicycle_step(*unicycle_step(x, y, theta, v, omega, 0.5 * dt), v, omega, 0.5 * dt)
    full = unicycle_step(x, y, theta, v, omega, dt)
    np.testing.assert_allclose(half, full, rtol=0, atol=1e-12 * (1.0 + abs(x) + abs(y)
                                                                  + abs(theta)))


@SETTINGS
@given(coords, coords, headings, speeds, rates, st.floats(0.0, 2.0, allow_nan=False))
def test_unicycle_step_reversible(x, y, theta, v, omega, dt):
    """Stepping back by -dt undoes a step (the closed form is valid for negative dt)."""
    fwd = unicycle_step(x, y, theta, v, omega, dt)
    back = unicycle_step(*fwd, v, omega, -dt)
    np.testing.assert_allclose(back, (x, y, theta), rtol=0,
                               atol=1e-12 * (1.0 + abs(x) + abs(y) + abs(theta)))


@SETTINGS
@given(coords, coords, headings, speeds, rates, steps)
def test_unicycle_step_invariants(x, y, theta, v, omega, dt):
    """theta advances by omega*dt; chord length is |v| dt |sinc(omega dt/2)| <= |v| dt."""
    nx, ny, nt = unicycle_step(x, y, theta, v, omega, dt)
    assert nt == pytest.approx(theta + omega * dt, abs=1e-15 * (1 + abs(theta)))
    chord = math.hypot(nx - x, ny - y)
    assert chord <= abs(v) * dt * (1 + 1e-12) + 1e-12
    h = 0.5 * omega * dt
    expected = abs(v) * dt * (abs(math.sin(h) / h) if h != 0.0 else 1.0)
    assert chord == pytest.approx(expected, abs=1e-10)


@SETTINGS
@given(headings, speeds, st.floats(0.05, 1.0), st.floats(1e-7, 1e-5))
def test_unicycle_step_continuous_at_series_switch(theta, v, dt, eps):
    """The sinc series branch (|omega dt/2| < 1e-6) joins the closed form smoothly."""
    omega_switch = 2e-6 / dt
    lo = unicycle_step(0.0, 0.0, theta, v, omega_switch * (1 - 1e-9), dt)
    hi = unicycle_step(0.0, 0.0, theta, v, omega_switch * (1 + 1e-9), dt)
    np.testing.assert_allclose(lo, hi, rtol=0, atol=1e-13)
    zero = unicycle_step(0.0, 0.0, theta, v, 0.0, dt)
    small = unicycle_step(0.0, 0.0, theta, v, eps, dt)
    # First-order change in omega: |d(x, y)/d omega| <= v dt^2 / 2.
    assert math.dist(zero[:2], small[:2]) <= abs(v) * dt * dt * eps + 1e-15


@SETTINGS
@given(coords, coords, headings, speeds, steps)
def test_unicycle_step_straight_line(x, y, theta, v, dt):
    nx, ny, nt = unicycle_step(x, y, theta, v, 0.0, dt)
    assert nt == theta
    assert nx == pytest.approx(x + v * dt * math.cos(theta), abs=1e-12)
    assert ny == pytest.approx(y + v * dt * math.sin(theta), abs=1e-12)


# --------------------------------------------------------------------------- offset_point

@SETTINGS
@given(coords, coords, headings, st.floats(-1.0, 1.0, allow_nan=False))
def test_offset_point(x, y, theta, d):
    px, py = offset_point(x, y, theta, d)
    assert math.hypot(px - x, py - y) == pytest.approx(abs(d), abs=1e-12)
    # Along the heading: the cross product with e(theta) vanishes, the dot product is d.
    c, s = math.cos(theta), math.sin(theta)
    assert (px - x) * c + (py - y) * s == pytest.approx(d, abs=1e-12)
    assert (px - x) * s - (py - y) * c == pytest.approx(0.0, abs=1e-12)


@SETTINGS
@given(coords, coords, headings, speeds, st.floats(-0.5 * math.pi, 0.5 * math.pi),
       st.floats(0.05, 0.5))
def test_offset_point_velocity(x, y, theta, v, omega, d):
    """R moves with v e(theta) + d omega e_perp(theta) (the basis of Eq. 7)."""
    h = 1e-6
    fwd = offset_point(*unicycle_step(x, y, theta, v, omega, h), d)
    back = offset_point(*unicycle_step(x, y, theta, v, omega, -h), d)
    vel = ((fwd[0] - back[0]) / (2 * h), (fwd[1] - back[1]) / (2 * h))
    c, s = math.cos(theta), math.sin(theta)
    expected = (v * c - d * omega * s, v * s + d * omega * c)
    np.testing.assert_allclose(vel, expected, rtol=0, atol=1e-7)


# --------------------------------------------------------------------------- clearance

def test_clearance_of_circles_and_walls():
    assert clearance(Circle(1.0, 0.0, 0.5), 0.0, 0.0, 0.25) == pytest.approx(0.25)
    assert clearance(Wall(3.0, 1.0, 5.0, 1.0), 3.0, 0.0, 0.25) == pytest.approx(0.75)
    assert clearance(Wall(3.0, 1.0, 5.0, 1.0), 0.0, 1.0) == pytest.approx(3.0)   # end point
    assert clearance(Circle(0.0, 0.0, 0.5), 0.0, 0.0) == pytest.approx(-0.5)     # inside


@SETTINGS
@given(st.floats(-5, 5), st.floats(-5, 5),
       st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(0, 1)), max_size=3),
       st.lists(st.tuples(*[st.floats(-3, 3)] * 4), max_size=3), st.floats(0, 0.5))
def test_min_clearance_is_the_smallest_clearance(x, y, circles, walls, footprint):
    obstacles = [Circle(*c) for c in circles] + [Wall(*w) for w in walls]
    want = min((clearance(o, x, y, footprint) for o in obstacles), default=math.inf)
    arrays = obstacle_arrays(obstacles)
    assert min_clearance(x, y, arrays, footprint) == want
    far = min_clearance(x + 10.0, y, arrays, footprint)
    assert path_clearance(np.array([x, x + 10.0]), np.array([y, y]), arrays,
                          footprint) == pytest.approx(min(want, far), abs=1e-12)
    each = point_clearances(np.array([x, x + 10.0]), np.array([y, y]), arrays, footprint)
    assert each.tolist() == pytest.approx([want, far], abs=1e-12)
