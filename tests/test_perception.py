import dataclasses
import math

import numpy as np
import pytest

from companion.config import build, field_docs
from companion.errors import ConfigError
from companion.geometry import clearance
from companion.params import ExtractorParams, LidarParams
from companion.perception import extract_obstacles
from companion.sim.lidar import cast, scan_points
from companion.types import Circle, Pose, Scan, Wall

EXACT = LidarParams(noise_std=0.0)
PARAMS = ExtractorParams()
ORIGIN = Pose(0.0, 0.0, 0.0)


def covers(circle, x, y, tol=1e-9):
    return math.hypot(x - circle.x, y - circle.y) <= circle.radius + tol


def assert_all_points_covered(scan, circles, exclude=None, tol=1e-9):
    """Every return (except those near ``exclude``) is inside some reported circle."""
    for x, y in scan_points(scan):
        if exclude is not None and math.hypot(x - exclude[0], y - exclude[1]) < 0.5:
            continue
        assert any(covers(c, x, y, tol) for c in circles), (x, y)


def assert_no_phantoms(circles, objects, tol=0.3):
    """Every reported circle comes within ``tol`` of a real object."""
    for c in circles:
        assert min(clearance(o, c.x, c.y) for o in objects) - c.radius <= tol, c


def assert_faces_pillars(scan, circles, pillars, tol=0.05):
    """The circle nearest each pillar has its face turned to the sensor on the pillar's."""
    for p in pillars:
        c = nearest(circles, p.x, p.y)
        ux, uy = c.x - scan.x, c.y - scan.y
        d = math.hypot(ux, uy)
        face = (c.x - c.radius * ux / d, c.y - c.radius * uy / d)
        assert abs(clearance(p, *face)) <= tol, (p, c)


def nearest(circles, x, y):
    return min(circles, key=lambda c: math.hypot(c.x - x, c.y - y))


def test_one_pillar():
    scan = cast(ORIGIN, [Circle(3.0, 0.0, 0.15)], [], None, EXACT, None)
    (c,) = extract_obstacles(scan, None, PARAMS)
    assert math.hypot(c.x - 3.0, c.y) < 0.05
    assert abs(c.radius - 0.15) < 0.05


@pytest.mark.parametrize("pose", [Pose(1.0, -2.0, 2.5), Pose(-1.5, 1.0, -1.0)])
def test_one_pillar_from_other_poses(pose):
    scan = cast(pose, [Circle(2.0, 1.0, 0.15)], [], None, EXACT, None)
    (c,) = extract_obstacles(scan, None, PARAMS)
    assert math.hypot(c.x - 2.0, c.y - 1.0) < 0.05
    assert abs(c.radius - 0.15) < 0.05


def test_two_separated_pillars():
    truth = [Circle(3.0, 0.0, 0.15), Circle(-1.0, 2.5, 0.3)]
    scan = cast(Pose(0.0, 0.0, 0.4), truth, [], None, EXACT, None)
    found = extract_obstacles(scan, None, PARAMS)
    assert len(found) == 2
    for t in truth:
        c = nearest(found, t.x, t.y)
        assert math.hypot(c.x - t.x, c.y - t.y) < 0.05
        assert abs(c.radius - t.radius) < 0.05


def test_large_pillar_is_one_circle():
    scan = cast(ORIGIN, [Circle(3.0, 0.0, 0.4875)], [], None, EXACT, None)
    (c,) = extract_obstacles(scan, None, PARAMS)
    assert abs(c.radius - 0.4875) < 0.05
    assert math.hypot(c.x - 3.0, c.y) < 0.05


def _wall_points_between_returns(scan, wall, step=0.01):
    """Points of the wall between its extreme seen returns (the part inside the scan)."""
    pts = scan_points(scan)
    ex, ey = wall.x1 - wall.x0, wall.y1 - wall.y0
    length2 = ex * ex + ey * ey
    s = ((pts[:, 0] - wall.x0) * ex + (pts[:, 1] - wall.y0) * ey) / length2
    on = np.array([clearance(wall, x, y) < 1e-6 for x, y in pts])
    s0, s1 = s[on].min(), s[on].max()
    ss = np.linspace(s0, s1, max(2, int((s1 - s0) * math.sqrt(length2) / step)))
    return np.column_stack((wall.x0 + ss * ex, wall.y0 + ss * ey))


@pytest.mark.parametrize("wall, pose", [(Wall(2.0, -5.0, 2.0, 5.0), ORIGIN),
                                        (Wall(-3.0, 1.0, 4.0, 2.5), Pose(0.5, -0.5, 1.0)),
                                        (Wall(1.0, 1.0, 6.0, 6.0), Pose(0.0, 2.0, 0.0))])
def test_wall_is_covered_by_several_circles(wall, pose):
    scan = cast(pose, [], [wall], None, EXACT, None)
    found = extract_obstacles(scan, None, PARAMS)
    assert len(found) >= 4
    for x, y in _wall_points_between_returns(scan, wall):
        assert any(covers(c, x, y, 1e-6) for c in found), (x, y)
    assert all(c.radius <= 1.5 * PARAMS.max_radius for c in found)
    assert_no_phantoms(found, [wall])


def test_room_corners_and_pillars_covered():
    half = 4.0
    walls = [Wall(-half, -half, half, -half), Wall(half, -half, half, half),
             Wall(half, half, -half, half), Wall(-half, half, -half, -half)]
    pillars = [Circle(2.0, 1.0, 0.2), Circle(-1.5, -2.0, 0.4)]
    scan = cast(Pose(0.3, 0.2, 0.1), pillars, walls, None, EXACT, None)
    found = extract_obstacles(scan, None, PARAMS)
    assert_all_points_covered(scan, found)
    assert_no_phantoms(found, walls + pillars)
    assert_faces_pillars(scan, found, pillars)
    for p in pillars:
        c = nearest(found, p.x, p.y)
        assert math.hypot(c.x - p.x, c.y - p.y) < 0.05


def test_person_excluded_only_when_given():
    person = (2.0, 1.0)
    scan = cast(ORIGIN, [Circle(3.0, -1.0, 0.15)], [], person, EXACT, None)
    everything = extract_obstacles(scan, None, PARAMS)
    assert len(everything) == 2
    c = nearest(everything, *person)
    assert math.hypot(c.x - person[0], c.y - person[1]) < 0.05
    assert abs(c.radius - EXACT.person_radius) < 0.05
    (only,) = extract_obstacles(scan, person, PARAMS)
    assert math.hypot(only.x - 3.0, only.y + 1.0) < 0.05
    # a tracking error of 0.4 m still excludes the person
    assert len(extract_obstacles(scan, (2.3, 1.25), PARAMS)) == 1


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("noise", [0.01, 0.02])
def test_noisy_scans(seed, noise):
    pillars = [Circle(3.0, 0.0, 0.15), Circle(-2.0, 2.0, 0.3), Circle(0.5, -3.5, 0.4875),
               Circle(-4.0, -1.0, 0.1)]
    walls = [Wall(-6.0, 5.0, 6.0, 5.0), Wall(6.0, -6.0, 6.0, 5.0)]
    person = (1.5, 1.5)
    params = LidarParams(noise_std=noise)
    scan = cast(Pose(0.0, 0.0, 0.3), pillars, walls, person, params,
                np.random.default_rng(seed))
    found = extract_obstacles(scan, person, PARAMS)
    for p in pillars:                              # every true obstacle detected
        assert any(math.hypot(c.x - p.x, c.y - p.y) < p.radius + 0.3 for c in found), p
    for w in walls:
        assert any(clearance(w, c.x, c.y) < c.radius for c in found), w
    assert_all_points_covered(scan, found, exclude=person)
    assert_no_phantoms(found, pillars + walls)
    assert_faces_pillars(scan, found, pillars, tol=0.1)
    assert all(math.hypot(c.x - person[0], c.y - person[1]) > 0.7 for c in found)


def test_empty_scan():
    scan = cast(ORIGIN, [], [], None, LidarParams(), np.random.default_rng(0))
    assert extract_obstacles(scan, None, PARAMS) == []
    assert extract_obstacles(scan, (1.0, 0.0), PARAMS) == []
    empty = Scan(np.zeros(0), np.zeros(0), 0.0, 0.0, 0.0)
    assert extract_obstacles(empty, None, PARAMS) == []


def _hand_scan(ranges, step=math.radians(0.5)):
    ranges = np.asarray(ranges, float)
    angles = (np.arange(len(ranges)) - len(ranges) // 2) * step
    return Scan(angles, ranges, 0.0, 0.0, 0.0)


def test_small_clusters_dropped():
    inf = math.inf
    scan = _hand_scan([inf, 2.0, 2.0, inf, inf, 3.0, 3.0, 3.0, inf, inf, 4.0, inf])
    found = extract_obstacles(scan, None, PARAMS)
    assert len(found) == 1                          # only the 3-point cluster at 3 m
    assert 2.9 < math.hypot(found[0].x, found[0].y) < 3.5
    assert len(extract_obstacles(scan, None, dataclasses.replace(PARAMS, min_points=1))) == 3
    assert len(extract_obstacles(scan, None, dataclasses.replace(PARAMS, min_points=4))) == 0


def test_missing_beam_and_gap_split_clusters():
    # a NaN (invalid) or inf beam inside a row of returns splits it; so does a range jump
    row = [2.0] * 5
    for hole in (math.nan, math.inf):
        found = extract_obstacles(_hand_scan(row + [hole] + row), None, PARAMS)
        assert len(found) == 2
    found = extract_obstacles(_hand_scan(row + [2.5] * 5), None, PARAMS)
    assert len(found) == 2
    assert len(extract_obstacles(_hand_scan(row * 2), None, PARAMS)) == 1


def test_hand_made_arc_and_far_side():
    # the near side of a circle r = 0.3 at (2, 0), 9 returns: centre behind the points
    a = np.linspace(-0.12, 0.12, 9)
    b = 2.0 * np.cos(a)
    r = b - np.sqrt(b * b - (4.0 - 0.09))
    (c,) = extract_obstacles(Scan(a, r, 0.0, 0.0, 0.0), None, PARAMS)
    assert c.x == pytest.approx(2.0, abs=0.01) and c.y == pytest.approx(0.0, abs=0.01)
    assert c.radius == pytest.approx(0.3, abs=0.01)
    # a concave arc (bulging away from the sensor): no centre on the sensor's side
    concave = 1.5 + 0.2 * (a / 0.12) ** 2
    (c,) = extract_obstacles(Scan(a, concave, 0.0, 0.0, 0.0), None, PARAMS)
    assert c.x > 1.5
    assert_all_points_covered(Scan(a, concave, 0.0, 0.0, 0.0), [c])


def test_straight_and_tiny_clusters_use_a_covering_fallback():
    # three collinear returns on the wall x = 2 and three identical returns
    a = np.array([-0.01, 0.0, 0.01])
    flat = Scan(a, 2.0 / np.cos(a), 0.0, 0.0, 0.0)
    (c,) = extract_obstacles(flat, None, PARAMS)
    assert c.x > 2.0 and abs(c.y) < 1e-9
    assert_all_points_covered(flat, [c])
    same = Scan(a, np.array([2.0, 2.0, 2.0]), 0.0, 0.0, 0.0)
    (c,) = extract_obstacles(dataclasses.replace(same, angles=np.zeros(3)), None, PARAMS)
    assert c.radius == pytest.approx(PARAMS.min_radius)
    assert c.x == pytest.approx(2.0 + PARAMS.min_radius)


def test_full_circle_seam_is_joined():
    # a pillar straight behind the robot straddles the +-pi seam of a 360 degree scan
    scan = cast(ORIGIN, [Circle(-3.0, 0.0, 0.3)], [], None, EXACT, None)
    assert np.isfinite(scan.ranges[0]) and np.isfinite(scan.ranges[-1])
    (c,) = extract_obstacles(scan, None, PARAMS)
    assert math.hypot(c.x + 3.0, c.y) < 0.05
    # a closed ring of returns (robot inside a box) is covered all the way round
    box = [Wall(-1, -1, 1, -1), Wall(1, -1, 1, 1), Wall(1, 1, -1, 1), Wall(-1, 1, -1, -1)]
    scan = cast(ORIGIN, [], box, None, EXACT, None)
    found = extract_obstacles(scan, None, PARAMS)
    for w in box:
        for s in np.linspace(0.0, 1.0, 101):
            x, y = w.x0 + s * (w.x1 - w.x0), w.y0 + s * (w.y1 - w.y0)
            assert any(covers(c, x, y, 1e-6) for c in found), (x, y)


def test_radius_clamped_to_min():
    scan = cast(ORIGIN, [Circle(1.0, 0.0, 0.02)], [], None, EXACT, None)
    (c,) = extract_obstacles(scan, None, dataclasses.replace(PARAMS, min_points=2))
    # clamped up to min_radius, then enlarged just enough to cover the returns
    assert PARAMS.min_radius <= c.radius <= PARAMS.min_radius + 0.01
    assert math.hypot(c.x - 1.0, c.y) < 0.05
    assert_all_points_covered(scan, [c])


def test_params_from_toml_mapping():
    p = build(ExtractorParams, {"cluster_gap": 0.2, "min_points": 5})
    assert (p.cluster_gap, p.min_points) == (0.2, 5)
    for bad in ({"cluster_gap": 0.0}, {"min_points": 0}, {"min_points": 2.5},
                {"max_radius": -1.0}, {"person_exclusion": "x"}, {"max_segmnt": 1.0}):
        with pytest.raises(ConfigError):
            build(ExtractorParams, bad)
    assert all(row[1] and row[3] for row in field_docs(ExtractorParams))


def test_adaptive_breakpoint_keeps_a_slanted_wall_together():
    # seen from (0, 2), the far part of this wall is hit at ~16 degrees from grazing, where
    # returns are more than cluster_gap apart; the adaptive breakpoint keeps them together
    wall, pose = Wall(1.0, 1.0, 6.0, 6.0), Pose(0.0, 2.0, 0.0)
    scan = cast(pose, [], [wall], None, EXACT, None)
    far = _wall_points_between_returns(scan, wall)[-1]
    found = extract_obstacles(scan, None, PARAMS)
    assert any(covers(c, *far, 1e-6) for c in found)
    fixed = extract_obstacles(scan, None, dataclasses.replace(PARAMS, breakpoint_angle=0.0))
    assert not any(covers(c, *far, 1e-6) for c in fixed)


def test_all_cluster_points_covered_in_random_worlds():
    for seed in range(30):
        rng = np.random.default_rng(seed)
        pillars = [Circle(*rng.uniform(-6, 6, 2), rng.uniform(0.05, 0.8)) for _ in range(5)]
        walls = [Wall(*rng.uniform(-7, 7, 4)) for _ in range(3)]
        objects = pillars + walls
        if min(clearance(o, 0.0, 0.0) for o in objects) < 0.3:
            continue
        scan = cast(ORIGIN, pillars, walls, None, LidarParams(noise_std=0.02), rng)
        found = extract_obstacles(scan, None, PARAMS)
        kept = dataclasses.replace(PARAMS, min_points=1)
        # with min_points = 1 nothing is dropped, so every return must be covered
        assert_all_points_covered(scan, extract_obstacles(scan, None, kept))
        assert_no_phantoms(found, objects)


@pytest.mark.parametrize("huge", [float(np.float32(3.4028235e38)), 1e20, 1e4])
def test_driver_no_return_ranges_with_default_range_max(huge):
    # range_max left infinite: FLT_MAX, 1e20 (and anything beyond 1 km) is "no return"
    scan = _hand_scan([2.0] * 5 + [huge] * 5 + [3.0] * 5)
    assert scan.range_max == math.inf
    found = extract_obstacles(scan, None, PARAMS)
    assert len(found) == 2
    assert [round(math.hypot(c.x, c.y)) for c in found] == [2, 3]
    assert extract_obstacles(_hand_scan([huge] * 6), None, PARAMS) == []
