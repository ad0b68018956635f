import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from companion.sim.person import Figure8, Segment, SegmentPath, circle, line, u_shape


def test_line():
    p = line((1.0, 2.0, 0.5), 1.2)
    s = p.state(10.0)
    assert s.x == pytest.approx(1.0 + 12.0 * math.cos(0.5))
    assert s.y == pytest.approx(2.0 + 12.0 * math.sin(0.5))
    assert (s.v, s.omega, s.theta) == pytest.approx((1.2, 0.0, 0.5))


def test_circle_returns_after_one_lap():
    p = circle((0.0, 0.0, 0.0), 3.0, 1.0, "left")
    lap = 2 * math.pi * 3.0
    s = p.state(lap)
    assert (s.x, s.y) == pytest.approx((0.0, 0.0), abs=1e-9)
    assert p.state(lap / 2).y == pytest.approx(6.0)
    assert p.state(1.0).omega == pytest.approx(1.0 / 3.0)
    assert circle((0.0, 0.0, 0.0), 3.0, 1.0, "right").state(lap / 2).y == pytest.approx(-6.0)


def _integrate(path, t_end):
    def f(t, z):
        s = path.state(t)
        return [s.v * math.cos(z[2]), s.v * math.sin(z[2]), s.omega]
    s0 = path.state(0.0)
    sol = solve_ivp(f, (0, t_end), [s0.x, s0.y, s0.theta], rtol=1e-10, atol=1e-10,
                    max_step=0.05)
    return sol.y[:, -1]


def test_segments_are_exact_unicycle_motion():
    path = SegmentPath((1.0, -1.0, 0.3), [Segment(3.0, 0.2, 1.0, 0.0),
                                           Segment(4.0, 1.0, 0.5, -0.4),
                                           Segment(2.0, 0.5, 0.5, 0.0)])
    for t_end in (2.0, 5.5, 9.0, 11.0):
        x, y, th = _integrate(path, t_end)
        s = path.state(t_end)
        assert (s.x, s.y) == pytest.approx((x, y), abs=1e-6)
        assert s.theta == pytest.approx(th, abs=1e-6)


def test_u_shape_turns_around_and_stays_continuous():
    p = u_shape((0.0, 0.0, 0.0), radius=2.0)
    ts = np.arange(0.0, p.duration, 0.01)
    states = [p.state(t) for t in ts]
    xy = np.array([(s.x, s.y) for s in states])
    steps = np.hypot(*np.diff(xy, axis=0).T)
    assert steps.max() < 0.013  # no jumps: at most v_max * dt
    end = states[-1]
    assert math.cos(end.theta) == pytest.approx(-1.0, abs=1e-6)  # walking back along -x
    assert end.y == pytest.approx(4.0, abs=1e-6)
    speeds = [s.v for s in states]
    assert min(speeds) == pytest.approx(0.3, abs=0.01) and max(speeds) == pytest.approx(1.2)


def test_figure8_matches_eq23_and_notes():
    f = Figure8(lap_time=60.0)
    s0 = f.state(0.0)
    assert (s0.x, s0.y, s0.theta) == pytest.approx((5.0, 3.0, 0.0), abs=1e-12)
    assert f.state(60.0).x == pytest.approx(5.0, abs=1e-9)
    ts = np.linspace(0, 60, 6001)
    states = [f.state(t) for t in ts]
    peak_v = max(s.v for s in states)
    peak_w = max(abs(s.omega) for s in states)
    assert peak_v == pytest.approx(1.05, abs=0.01)   # docs/model.md R10
    assert peak_w == pytest.approx(0.34, abs=0.01)
    # speed and turn rate agree with finite differences of the position and heading
    xy = np.array([(s.x, s.y) for s in states])
    th = np.unwrap([s.theta for s in states])
    dt = ts[1] - ts[0]
    v_fd = np.hypot(*np.gradient(xy, dt, axis=0).T)
    w_fd = np.gradient(th, dt)
    assert np.max(np.abs(v_fd[1:-1] - [s.v for s in states[1:-1]])) < 1e-3
    assert np.max(np.abs(w_fd[1:-1] - [s.omega for s in states[1:-1]])) < 1e-3
