"""Moving things tracked with their velocities (companion.perception.movers) and the
prediction of moving obstacles (companion.geometry.predicted)."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from companion.geometry import closest_approach_time, predicted
from companion.params import MoverParams
from companion.perception import MovingTracker
from companion.types import Circle, Wall

MP = MoverParams()


def test_a_walker_gets_its_velocity_and_a_standing_cluster_none():
    rng = np.random.default_rng(3)
    tracker = MovingTracker(MP)
    moving_ok, standing_still = [], []
    for k in range(60):                                  # 6 s of 10 Hz scans
        t = 0.1 * k
        walker = Circle(1.0 + 1.2 * t + rng.normal(0, 0.04), 2.0 + rng.normal(0, 0.04), 0.25)
        post = Circle(5.0 + rng.normal(0, 0.04), -1.0 + rng.normal(0, 0.04), 0.2)
        wall = Circle(0.0, -3.0, 0.3, influence=0.5, piece=True)   # a piece of a wall
        out = tracker.update([walker, post, wall], t)
        assert out[2] == wall                            # passed through untouched
        if k >= 10:
            moving_ok.append(math.hypot(out[0].vx - 1.2, out[0].vy) < 0.25)
            standing_still.append(not out[1].moving)
    assert np.mean(moving_ok) >= 0.95
    assert np.mean(standing_still) >= 0.95


def test_crossing_walkers_keep_their_own_velocities():
    tracker = MovingTracker(MP)
    for k in range(40):
        t = 0.1 * k
        a = Circle(-2.0 + 1.0 * t, 0.0, 0.25)            # along +x
        b = Circle(0.0, -2.0 + 1.0 * t, 0.25)            # along +y, crossing a's path
        out = tracker.update([a, b], t)
    assert (out[0].vx, out[0].vy) == pytest.approx((1.0, 0.0), abs=0.1)
    assert (out[1].vx, out[1].vy) == pytest.approx((0.0, 1.0), abs=0.1)


def test_tracks_are_confirmed_predicted_and_forgotten():
    tracker = MovingTracker(MP)
    tracker.update([Circle(0.0, 0.0, 0.25)], 0.0)
    assert tracker.circles(0.0) == ()                    # not confirmed yet
    for k in range(1, 10):
        tracker.update([Circle(0.1 * k, 0.0, 0.25)], 0.1 * k)
    (c,) = tracker.circles(1.1)
    assert c.x == pytest.approx(1.1, abs=0.05) and c.vx == pytest.approx(1.0, abs=0.1)
    assert tracker.circles(0.9 + MP.forget_s + 0.01) == ()
    tracker.update([Circle(5.0, 5.0, 0.25)], 0.5)        # the clock went back: start over
    assert tracker.circles(0.5) == ()


@given(st.floats(-5, 5), st.floats(-5, 5), st.floats(-2, 2), st.floats(-2, 2),
       st.floats(0, 4), st.floats(0, 4))
def test_closest_approach_time_is_the_closest(dx, dy, dvx, dvy, horizon, other):
    t = closest_approach_time(dx, dy, dvx, dvy, horizon)
    assert 0.0 <= t <= horizon
    other = min(other, horizon)
    assert math.hypot(dx + dvx * t, dy + dvy * t) <= math.hypot(dx + dvx * other,
                                                                dy + dvy * other) + 1e-9


def test_avoidance_sees_a_walker_where_it_will_be():
    walker = Circle(4.0, 2.0, 0.25, vx=0.0, vy=-1.0)     # crossing ahead of a robot at 1 m/s
    wall = Wall(0.0, 3.0, 5.0, 3.0)
    ahead = predicted((walker, wall), 0.0, 0.0, 1.0, 0.0, horizon=2.0)
    assert ahead[1] == wall
    assert (ahead[0].x, ahead[0].y) == pytest.approx((4.0, 0.0), abs=1e-9)   # closest at 3 s
    assert predicted((walker,), 0.0, 0.0, 1.0, 0.0, horizon=5.0)[0].y == pytest.approx(-1.0)
    assert predicted((walker,), 0.0, 0.0, 1.0, 0.0, horizon=0.0)[0] == walker
    passing = Circle(4.0, 1.5, 0.25, vx=-1.0)            # head-on, 1.5 m to the side
    assert predicted((passing,), 0.0, 0.0, 1.0, 0.0, 2.0, reach=0.35)[0] == passing
    assert predicted((walker,), 0.0, 0.0, 2.0, 0.0, 2.0, reach=0.35)[0].y == pytest.approx(0.0)
