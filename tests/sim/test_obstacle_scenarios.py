"""Issue acceptance: fig4, fig7 (and the corridor) with ground-truth and LiDAR obstacles."""

import dataclasses
import math

import numpy as np
import pytest

from companion import metrics
from companion.control import make_controller
from companion.perception import extract_obstacles
from companion.sim.episode import run_episode
from companion.sim.scenario import load_scenario
from companion.sim.sensing import LidarPerception, make_perception
from companion.types import Circle


def run(name, source):
    sc = load_scenario(name)
    log = run_episode(make_controller(sc.controller, sc.params), sc.person, sc.params,
                      sc.duration, start=sc.start, seed=sc.seed, obstacles=sc.obstacles,
                      perception=make_perception(source, sc.params))
    return sc, log, metrics.compute(log)


@pytest.mark.parametrize("source", ["truth", "lidar"])
@pytest.mark.parametrize("name", ["fig4", "fig7", "corridor"])
def test_no_collisions(name, source):
    sc, log, m = run(name, source)
    assert m["obstacle_collisions"] == 0, m
    assert m["min_obstacle_clearance_m"] >= 0.05, m
    assert m["min_person_distance_m"] >= 0.5, m
    assert m["finite"] and np.all(np.isfinite(log["robot_x"]))
    assert np.max(np.abs(log["omega"])) <= sc.params.robot.omega_max + 1e-12
    assert np.max(np.abs(log["v"])) <= sc.params.robot.v_max + 1e-12


def test_fig4_avoidance_acts_inside_the_influence_range():
    sc, log, m = run("fig4", "truth")
    inside = log["rho_ob"] < 0.4
    assert inside.any()
    assert np.max(np.abs(log["u_ob"][inside])) > 0.5          # it steers
    # u_ob only builds up inside the range and then leaks away (tau = 0.5 s)
    first = np.flatnonzero(inside)[0]
    assert np.all(log["u_ob"][:first] == 0.0)


def test_fig4_scenario_matches_the_paper():
    sc = load_scenario("fig4")
    assert sc.obstacles == (Circle(5.1, -1.8, 0.15, 0.4),)
    assert sc.params.formation.bearing == pytest.approx(1.5 * math.pi)
    sc7 = load_scenario("fig7")
    assert {(o.x, o.y, o.radius, o.influence) for o in sc7.obstacles} == {
        (1.75, -9.0, 0.4875, 1.3), (5.15, -1.6, 0.4875, 1.3)}


def test_lidar_perception_sees_the_obstacle_and_not_the_person():
    sc = load_scenario("fig4")
    p = dataclasses.replace(sc.params, lidar=dataclasses.replace(sc.params.lidar,
                                                                 noise_std=0.0))
    perc = LidarPerception(p)
    rng = np.random.default_rng(0)
    from companion.types import Pose
    robot = Pose(4.0, -1.8, 0.0)
    person = (4.0, -0.8)
    known, scan = perc.sense(0, robot, sc.obstacles, person, rng)
    assert known == () and scan.t == 0.0
    seen = extract_obstacles(scan, person, p.extractor)
    assert len(seen) == 1
    assert (seen[0].x, seen[0].y) == pytest.approx((5.1, -1.8), abs=0.05)
    # held between scans (10 Hz at dt = 0.05 s: every 2nd step)
    assert perc.sense(1, Pose(0, 0, 0), (), person, rng) == ((), scan)
