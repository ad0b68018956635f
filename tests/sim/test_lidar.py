import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from companion.config import build, field_docs
from companion.errors import ConfigError
from companion.geometry import clearance
from companion.params import LidarParams
from companion.sim.lidar import WALL_END, beam_angles, cast, scan_points, wall_ends
from companion.types import Circle, Pose, Scan, Wall

EXACT = LidarParams(noise_std=0.0)
ORIGIN = Pose(0.0, 0.0, 0.0)


def beam(scan, angle):
    """Index of the beam at ``angle`` (must be a beam angle up to round-off)."""
    i = int(np.argmin(np.abs(scan.angles - angle)))
    assert scan.angles[i] == pytest.approx(angle, abs=1e-9)
    return i


def test_circle_ahead():
    scan = cast(ORIGIN, [Circle(3.0, 0.0, 0.5)], [], None, EXACT, None)
    assert scan.ranges[beam(scan, 0.0)] == pytest.approx(2.5, abs=1e-12)
    # every beam that hits sees the exact near root of the ray-circle equation
    for a, r in zip(scan.angles, scan.ranges):
        if math.isfinite(r):
            b = 3.0 * math.cos(a)
            assert r == pytest.approx(b - math.sqrt(b * b - (9.0 - 0.25)), abs=1e-9)
    half_width = math.asin(0.5 / 3.0)
    hit = np.isfinite(scan.ranges)
    assert np.all(np.abs(scan.angles[hit]) <= half_width + 1e-12)
    assert np.all(hit[np.abs(scan.angles) < half_width - 1e-9])


def test_wall_ranges_are_two_over_cos():
    scan = cast(ORIGIN, [], [Wall(2.0, -5.0, 2.0, 5.0)], None, EXACT, None)
    inside = np.abs(scan.angles) < math.atan2(5.0 - 2 * WALL_END, 2.0)   # off the ends
    assert inside.sum() > 100
    np.testing.assert_allclose(scan.ranges[inside], 2.0 / np.cos(scan.angles[inside]),
                               rtol=1e-12)
    beyond = np.abs(scan.angles) > math.atan2(5.0 + WALL_END, 2.0 - WALL_END)
    assert np.all(np.isinf(scan.ranges[beyond]))


def test_beam_parallel_to_wall_misses():
    scan = cast(ORIGIN, [], [Wall(-5.0, 1.0, 5.0, 1.0)], None, EXACT, None)
    assert math.isinf(scan.ranges[beam(scan, 0.0)])
    assert math.isinf(scan.ranges[beam(scan, -math.pi)])
    assert scan.ranges[beam(scan, 0.5 * math.pi)] == pytest.approx(1.0, abs=1e-12)


def test_beam_along_a_collinear_wall_hits_its_near_end():
    scan = cast(ORIGIN, [], [Wall(2.0, 0.0, 5.0, 0.0)], None, EXACT, None)
    assert scan.ranges[beam(scan, 0.0)] == pytest.approx(2.0 - WALL_END, abs=1e-12)


def test_a_wall_seen_edge_on_shows_its_end():
    """A robot in line with a wall (1 cm off it) sees the wall's end face, not through it:
    a zero-thickness end would be invisible, and a robot would drive into it."""
    scan = cast(ORIGIN, [], [Wall(2.0, 0.01, 5.0, 0.01)], None, EXACT, None)
    ahead = scan.ranges[np.abs(scan.angles) < 0.02]
    assert np.isfinite(ahead).any() and np.nanmin(ahead) < 2.0
    assert math.isinf(scan.ranges[beam(scan, -math.pi)])


def test_nearest_of_two_objects_wins():
    circles = [Circle(6.0, 0.0, 1.0), Circle(3.0, 0.0, 0.5)]
    scan = cast(ORIGIN, circles, [], None, EXACT, None)
    assert scan.ranges[beam(scan, 0.0)] == pytest.approx(2.5, abs=1e-12)
    scan = cast(ORIGIN, circles, [Wall(2.0, -1.0, 2.0, 1.0)], None, EXACT, None)
    assert scan.ranges[beam(scan, 0.0)] == pytest.approx(2.0, abs=1e-12)


def test_person_is_seen():
    params = dataclasses.replace(EXACT, person_radius=0.25)
    scan = cast(ORIGIN, [], [], (0.0, 3.0), params, None)
    assert scan.ranges[beam(scan, 0.5 * math.pi)] == pytest.approx(2.75, abs=1e-12)
    assert np.isfinite(scan.ranges).sum() > 5
    assert np.all(np.isinf(cast(ORIGIN, [], [], None, params, None).ranges))


def test_beyond_range_max_is_inf():
    far = [Circle(12.0, 0.0, 0.5)]
    assert np.all(np.isinf(cast(ORIGIN, far, [], None, EXACT, None).ranges))
    params = dataclasses.replace(EXACT, range_max=12.0)
    scan = cast(ORIGIN, far, [], None, params, None)
    assert scan.ranges[beam(scan, 0.0)] == pytest.approx(11.5, abs=1e-12)


@pytest.mark.parametrize("theta, k", [(0.7, 60), (-2.0, -300), (3.0, 200), (0.0, -719 // 2)])
def test_heading_rotation(theta, k):
    """A world object at bearing (theta + a) from the robot is seen by the beam at a."""
    a = k * EXACT.resolution
    pose = Pose(1.0, 2.0, theta)
    d, r = 4.0, 0.3
    obj = Circle(1.0 + d * math.cos(theta + a), 2.0 + d * math.sin(theta + a), r)
    scan = cast(pose, [obj], [], None, EXACT, None)
    i = beam(scan, math.remainder(a, 2 * math.pi) if abs(a) > math.pi else a)
    assert scan.ranges[i] == pytest.approx(d - r, abs=1e-9)
    assert np.nanargmin(scan.ranges) == i
    x, y = scan_points(dataclasses.replace(scan, ranges=np.where(
        np.arange(len(scan.ranges)) == i, scan.ranges, np.inf)))[0]
    assert (x, y) == pytest.approx((1.0 + (d - r) * math.cos(theta + a),
                                    2.0 + (d - r) * math.sin(theta + a)), abs=1e-9)
    assert (scan.x, scan.y, scan.theta) == (1.0, 2.0, theta)


def test_full_circle_beams():
    angles = beam_angles(LidarParams())
    assert len(angles) == 720
    assert angles[0] == pytest.approx(-math.pi)
    assert angles[-1] < math.pi - 1e-6
    steps = np.diff(np.concatenate((angles, [angles[0] + 2 * math.pi])))
    np.testing.assert_allclose(steps, 2 * math.pi / 720, rtol=1e-9)   # no duplicate at +-pi
    assert np.min(np.abs(angles)) == 0.0                               # a beam straight ahead
    odd = beam_angles(LidarParams(resolution=0.007))                   # does not divide 2*pi
    assert len(odd) % 2 == 0
    np.testing.assert_allclose(np.diff(odd), 2 * math.pi / len(odd), rtol=1e-9)
    assert abs(2 * math.pi / len(odd) - 0.007) < 0.007 / len(odd)


@pytest.mark.parametrize("fov, res, n", [(0.5 * math.pi, math.radians(1.0), 91),
                                         (1.0, 0.3, 3), (math.pi, math.radians(0.5), 361),
                                         (0.01, 0.1, 1)])
def test_limited_fov_beams(fov, res, n):
    angles = beam_angles(LidarParams(fov=fov, resolution=res))
    assert len(angles) == n
    assert np.all(np.diff(angles) > 0)
    np.testing.assert_allclose(angles, -angles[::-1], atol=1e-12)     # centred on the heading
    assert np.all(np.abs(angles) <= 0.5 * fov + 1e-9)
    if n > 1:
        np.testing.assert_allclose(np.diff(angles), res, rtol=1e-9)


def test_limited_fov_does_not_see_behind():
    params = dataclasses.replace(EXACT, fov=0.5 * math.pi)
    behind = [Circle(-3.0, 0.0, 0.5), Circle(0.0, 3.0, 0.5)]
    scan = cast(ORIGIN, behind, [], None, params, None)
    assert len(scan.ranges) == len(scan.angles) == 181
    assert np.all(np.isinf(scan.ranges))
    scan = cast(Pose(0.0, 0.0, math.pi), behind, [], None, params, None)
    assert scan.ranges[beam(scan, 0.0)] == pytest.approx(2.5, abs=1e-12)


def _box(half):
    return [Wall(-half, -half, half, -half), Wall(half, -half, half, half),
            Wall(half, half, -half, half), Wall(-half, half, -half, -half)]


def test_noise_is_gaussian_with_given_std():
    walls = _box(3.0)
    exact = cast(ORIGIN, [], walls, None, EXACT, None)
    params = LidarParams(noise_std=0.02)
    rng = np.random.default_rng(1)
    err = np.concatenate([cast(ORIGIN, [], walls, None, params, rng).ranges - exact.ranges
                          for _ in range(10)])
    assert len(err) == 7200
    assert abs(err.mean()) < 4 * 0.02 / math.sqrt(len(err))
    assert err.std() == pytest.approx(0.02, rel=0.05)
    assert np.mean(np.abs(err) < 0.02) == pytest.approx(0.6827, abs=0.03)
    assert np.mean(np.abs(err) < 0.04) == pytest.approx(0.9545, abs=0.02)


def test_noise_reproducible_and_only_on_finite_ranges():
    params = LidarParams(noise_std=0.05)
    world = ([Circle(3.0, 0.0, 0.5)], [Wall(-1.0, 2.0, 1.0, 2.0)])
    a = cast(ORIGIN, *world, None, params, np.random.default_rng(7))
    b = cast(ORIGIN, *world, None, params, np.random.default_rng(7))
    c = cast(ORIGIN, *world, None, params, np.random.default_rng(8))
    exact = cast(ORIGIN, *world, None, params, None)
    np.testing.assert_array_equal(a.ranges, b.ranges)
    assert not np.array_equal(a.ranges[np.isfinite(a.ranges)], c.ranges[np.isfinite(c.ranges)])
    np.testing.assert_array_equal(np.isinf(a.ranges), np.isinf(exact.ranges))
    assert not np.isnan(a.ranges).any()
    zero = cast(ORIGIN, *world, None, dataclasses.replace(params, noise_std=0.0),
                np.random.default_rng(7))
    np.testing.assert_array_equal(zero.ranges, exact.ranges)


def test_noisy_ranges_clipped_at_zero():
    params = LidarParams(noise_std=0.05)
    scan = cast(ORIGIN, [Circle(0.501, 0.0, 0.5)], [], None, params, np.random.default_rng(0))
    finite = scan.ranges[np.isfinite(scan.ranges)]
    assert finite.min() == 0.0 and np.all(finite >= 0.0)


def test_ray_from_inside_a_circle_returns_zero():
    scan = cast(Pose(3.1, 0.0, 0.3), [Circle(3.0, 0.0, 0.5), Circle(9.0, 0.0, 1.0)], [], None,
                EXACT, None)
    np.testing.assert_array_equal(scan.ranges, 0.0)
    on_person = cast(ORIGIN, [], [], (0.1, 0.0), EXACT, None)
    np.testing.assert_array_equal(on_person.ranges, 0.0)


def test_robot_on_a_wall_returns_zero():
    scan = cast(Pose(2.0, 0.0, 0.0), [], [Wall(2.0, -5.0, 2.0, 5.0)], None, EXACT, None)
    np.testing.assert_array_equal(scan.ranges, 0.0)


def test_empty_world_and_scan_points():
    scan = cast(ORIGIN, [], [], None, LidarParams(), np.random.default_rng(0))
    assert np.all(np.isinf(scan.ranges))
    assert scan_points(scan).shape == (0, 2)
    hand = Scan(np.array([-0.1, 0.0, 0.1]), np.array([1.0, np.nan, np.inf]), 1.0, 1.0,
                0.5 * math.pi)
    np.testing.assert_allclose(scan_points(hand), [[1.0 + math.sin(0.1), 1.0 + math.cos(0.1)]])


def test_params_from_toml_mapping():
    p = build(LidarParams, {"fov": 3.0, "range_max": 5, "noise_std": 0.0})
    assert (p.fov, p.range_max, p.noise_std) == (3.0, 5.0, 0.0)
    assert build(LidarParams, {"fov": 2 * math.pi}).fov == 2 * math.pi
    for bad in ({"fov": 7.0}, {"fov": 0.0}, {"range_max": -1.0}, {"resolution": 0.0},
                {"noise_std": -0.1}, {"rate": 10.0}, {"person_radius": 0.0}, {"fvo": 1.0}):
        with pytest.raises(ConfigError):
            build(LidarParams, bad)
    keys = {row[0] for row in field_docs(LidarParams)}
    assert keys == {"fov", "range_max", "resolution", "noise_std", "person_radius", "timeout_s"}
    assert all(row[1] and row[3] for row in field_docs(LidarParams))


coord = st.floats(-6.0, 6.0, allow_nan=False)


@st.composite
def worlds(draw):
    circles = [Circle(draw(coord), draw(coord), draw(st.floats(0.05, 1.5)))
               for _ in range(draw(st.integers(0, 6)))]
    walls = [Wall(draw(coord), draw(coord), draw(coord), draw(coord))
             for _ in range(draw(st.integers(0, 4)))]
    person = draw(st.none() | st.tuples(coord, coord))
    pose = Pose(draw(coord), draw(coord), draw(st.floats(-4.0, 4.0)))
    return circles, walls, person, pose


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(worlds())
def test_every_return_lies_on_a_surface(world):
    circles, walls, person, pose = world
    params = LidarParams(noise_std=0.0, range_max=8.0, resolution=math.radians(1.0))
    objects = list(circles) + list(walls) + wall_ends(walls)
    if person is not None:
        objects.append(Circle(person[0], person[1], params.person_radius))
    assume(all(clearance(o, pose.x, pose.y) > 1e-6 for o in objects))
    scan = cast(pose, circles, walls, person, params, None)
    assert not np.isnan(scan.ranges).any()
    finite = np.isfinite(scan.ranges)
    assert np.all(scan.ranges[finite] <= params.range_max)
    # nothing is hit nearer than the nearest surface
    nearest = min((clearance(o, pose.x, pose.y) for o in objects), default=math.inf)
    assert np.all(scan.ranges[finite] >= nearest - 1e-9)
    for x, y in scan_points(scan):
        gap = min(abs(clearance(o, x, y)) for o in objects)
        assert gap <= 1e-9 * (1.0 + math.hypot(x - pose.x, y - pose.y))
