"""Closed-loop fuzz (companion.sim.fuzz): what an episode draws, how it is counted, and a short
run of every controller with ideal and realistic sensing (``companion fuzz`` runs 1,000,000
steps; docs/safety.md)."""

import math

import numpy as np
import pytest

from companion.control import CONTROLLERS
from companion.evaluate import fuzz_runs
from companion.geometry import obstacle_arrays, path_clearance
from companion.params import PROFILES, Params
from companion.sim import fuzz
from companion.sim.episode import nearest_clearance, start_in_slot
from companion.types import LOG_COLUMNS, Log, PersonState

SEEDS = range(40)


@pytest.fixture(scope="module")
def drawn():
    return [fuzz.draw(s, "lqr", "ideal") for s in SEEDS]


def test_the_draws_cover_the_ranges_and_start_clear(drawn):
    params = Params()
    kinds, bearings, fast = set(), [], 0
    for case, spec in drawn:
        assert fuzz.DISTANCE[0] <= case.distance_drawn <= fuzz.DISTANCE[1]
        assert case.distance >= case.distance_drawn
        assert spec.params.formation.distance == case.distance      # accepted by Params
        assert fuzz.DURATION[0] - 0.05 <= spec.duration <= fuzz.DURATION[1] + 0.05
        kinds.add(case.start)
        bearings.append(case.bearing)
        h0 = spec.person.state(0.0)
        robot = spec.start or start_in_slot(h0, spec.params)
        v0 = spec.start_velocity[0] if spec.start_velocity else 0.0
        room = fuzz.stopping_room(v0, spec.params)
        assert nearest_clearance(robot.x, robot.y, spec.obstacles, params.robot.radius) > room
        assert math.hypot(robot.x - h0.x, robot.y - h0.y) > \
            params.keepout.protective_distance + (room if spec.start else 0.0)
        t = np.arange(0.0, spec.duration, 0.05)
        states = [spec.person.state(x) for x in t]
        xs, ys = np.array([h.x for h in states]), np.array([h.y for h in states])
        assert path_clearance(xs, ys, obstacle_arrays(spec.obstacles), 0.0) >= \
            case.person_margin - 1e-9
        v = np.array([h.v for h in states])
        assert np.max(v) <= 2.0 + 1e-9
        fast += np.max(v) > 1.8
    assert kinds == set(fuzz.START_KINDS)
    assert min(bearings) < 1.0 and max(bearings) > 2 * math.pi - 1.0
    assert fast >= 5
    assert any(c.pillars == 0 for c, _ in drawn) or max(c.pillars for c, _ in drawn) >= 10


def test_an_infeasible_formation_moves_out_to_the_protective_ring():
    params = Params()
    for bearing in np.linspace(0.0, 2 * math.pi, 13)[:-1]:
        d = fuzz.feasible_distance(0.3, bearing, params)
        f = params.formation.__class__(d, bearing)
        centre = start_in_slot(PersonState(0.0, 0.0, 0.0, 0.0, 0.0), params.replace(formation=f))
        assert math.hypot(centre.x, centre.y) == pytest.approx(0.61, abs=1e-9)
    assert fuzz.feasible_distance(2.0, math.pi, params) == 2.0


def test_an_episode_depends_on_its_seed_alone():
    a_case, a = fuzz.draw(7, "pid", "realistic")
    b_case, b = fuzz.draw(7, "lqr", "ideal")
    assert a.obstacles == b.obstacles and a.start == b.start
    assert a.person.state(20.0) == b.person.state(20.0)
    assert a.params.sensing == PROFILES["realistic"] and b.params.sensing == PROFILES["ideal"]
    assert fuzz.draw(8, "lqr", "ideal")[1].obstacles != b.obstacles


def test_the_plan_reaches_the_steps_and_shares_them_between_the_pairs():
    episodes = fuzz.plan(20_000, 3, ["lqr", "pid"], ["ideal", "realistic"])
    steps = [fuzz.draw(*e)[1].duration / Params().dt for e in episodes]
    assert sum(steps) >= 20_000 > sum(steps[:-1])
    assert [e[0] for e in episodes] == [3 * fuzz.SEED_STRIDE + i for i in range(len(episodes))]
    pairs = [(c, s) for _, c, s in episodes]
    assert pairs[:4] == [("lqr", "ideal"), ("pid", "ideal"), ("lqr", "realistic"),
                         ("pid", "realistic")]


def _log(robot_x, person_x, estimate_x=None):
    n = len(robot_x)
    c = {k: np.zeros(n) for k in LOG_COLUMNS}
    c["t"] = np.arange(n) * Params().dt
    c["robot_x"], c["person_x"] = np.asarray(robot_x, float), np.asarray(person_x, float)
    c["person_est_x"] = np.asarray(person_x if estimate_x is None else estimate_x, float)
    c["rho_ob"] = np.full(n, 5.0)
    c["status"], c["reason"] = np.array(["ok"] * n), np.array([""] * n)
    return Log(c)


def test_only_the_robots_own_approach_inside_the_protective_distance_is_a_violation():
    params = Params()
    towards = fuzz.episode_counts(_log(np.linspace(0.0, 0.5, 11), np.full(11, 0.8)), params)
    # the robot drives from 0.8 m to 0.3 m of a standing person: 0.45, 0.40, 0.35 -> 0.30
    assert (towards["protective_steps"], towards["violations"]) == (4, 3)
    assert towards["person_collisions"] == 1 and fuzz.failed(towards)
    walked_in = fuzz.episode_counts(_log(np.zeros(11), np.linspace(0.8, 0.3, 11)), params)
    assert walked_in["protective_steps"] == 4 and walked_in["violations"] == 0
    assert walked_in["person_collisions"] == 1          # a collision all the same
    misled = fuzz.episode_counts(_log(np.linspace(0.0, 0.5, 11), np.full(11, 0.8),
                                      estimate_x=np.full(11, 3.0)), params)
    assert misled["violations"] == misled["violations_estimate"] == 3
    away = fuzz.episode_counts(_log(np.linspace(0.33, -0.17, 11), np.full(11, 0.8)), params)
    assert away["protective_steps"] == 1 and away["violations"] == 0 and not fuzz.failed(away)


def test_a_collision_is_the_robots_doing_only_if_its_own_motion_closed_in_the_step_into_it():
    params = Params()
    # the robot drives into a standing person: 0.8 m, then 0.75, 0.70, ... 0.30 m apart
    driven = fuzz.episode_counts(_log(np.linspace(0.0, 0.5, 11), np.full(11, 0.8)), params)
    assert (driven["person_collisions"], driven["person_collisions_robot"]) == (1, 1)
    # the person walks into a standing robot: a collision all the same, but the person's
    walked = fuzz.episode_counts(_log(np.zeros(11), np.linspace(0.8, 0.3, 11)), params)
    assert (walked["person_collisions"], walked["person_collisions_robot"]) == (1, 0)
    assert fuzz.failed(walked) and not fuzz.robot_failed(walked)
    assert fuzz.robot_failed(driven)
    assert fuzz.totals([driven, walked])["robot_failed_episodes"] == 1
    # ... or into a robot that backs away more slowly than the person comes
    backed = fuzz.episode_counts(_log(np.linspace(0.0, -0.2, 11), np.linspace(0.8, 0.2, 11)),
                                 params)
    assert (backed["person_collisions"], backed["person_collisions_robot"]) == (1, 0)
    # the robot closes at 0.005 m/s (below fuzz.TOLERANCE) while the person walks in: theirs
    creep = np.linspace(0.0, 0.005 * 10 * params.dt, 11)
    crept = fuzz.episode_counts(_log(creep, np.linspace(0.8, 0.3, 11)), params)
    assert (crept["person_collisions"], crept["person_collisions_robot"]) == (1, 0)
    # two contacts, the second one driven by the robot
    robot_x = np.array([0.0, 0.0, 0.0, -0.4, -0.4, -0.2, -0.2, -0.2])
    person_x = np.array([0.8, 0.5, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2])
    twice = fuzz.episode_counts(_log(robot_x, person_x), params)
    assert (twice["person_collisions"], twice["person_collisions_robot"]) == (2, 1)


def test_the_robots_motion_while_the_person_walks_through_it_is_counted_apart():
    params = Params()
    # the robot backs away along -x at 0.4 m/s; the person comes along x at 2 m/s, walks into
    # it and through it, and the robot's motion now leads towards the person behind it
    k = np.arange(31)
    log = _log(-0.02 * k, 1.0 - 0.1 * k)
    counts = fuzz.episode_counts(log, params)
    assert (counts["person_collisions"], counts["person_collisions_robot"]) == (1, 0)
    assert counts["violations"] == 0
    # steps 13-18: the person is behind the robot, within 0.5 m, and the robot backs onwards
    assert counts["violations_walkthrough"] == 6
    # a robot that drives into the person is not excused by the person walking on
    into = fuzz.episode_counts(_log(0.04 * k, np.full(31, 1.0)), params)
    assert into["person_collisions_robot"] == 1 and into["violations_walkthrough"] == 0
    assert into["violations"] > 0


def test_walkthroughs_last_until_the_person_is_out_of_the_zone():
    dist = np.array([0.8, 0.44, 0.2, 0.3, 0.49, 0.5, 0.3, 0.44, 0.6])
    entries = np.zeros(len(dist), dtype=bool)
    entries[[1, 7]] = True
    np.testing.assert_array_equal(fuzz.walkthroughs(entries, dist, 0.5),
                                  [False, True, True, True, True, False, False, True, False])


# The first episodes of ``companion fuzz`` (seed 0, every controller, both profiles).
SHORT_STEPS = 20_000


@pytest.fixture(scope="module")
def short_run():
    episodes = fuzz.plan(SHORT_STEPS, 0, list(CONTROLLERS), list(fuzz.FUZZ_PROFILES))
    return fuzz_runs.run(episodes, None)           # the engine, as companion fuzz runs it


def test_short_fuzz_covers_every_pair_and_stays_finite(short_run):
    cases, counts = short_run
    total = fuzz.totals(counts)
    assert total["steps"] >= SHORT_STEPS
    assert {(c.controller, c.sensing) for c in cases} == \
        {(c, s) for c in CONTROLLERS for s in fuzz.FUZZ_PROFILES}
    assert total["nonfinite_steps"] == 0


def test_short_fuzz_no_obstacle_collision_and_ideal_sensing_is_never_the_robots_fault(
        short_run):
    cases, counts = short_run
    assert sum(n["obstacle_collisions"] for n in counts) == 0
    ideal = [n for c, n in zip(cases, counts) if c.sensing == "ideal"]
    assert sum(n["violations"] + n["person_collisions_robot"] for n in ideal) == 0


def test_short_fuzz_with_ideal_sensing_the_walker_never_reaches_the_robot(short_run):
    """Rule 3 bounds the robot's own approach outside the protective distance and leaves a
    person's approach to the evasive check: backing off along the line to the walker drove
    the robot into its path (the 1,000,000-step run: 15 ideal contacts before, 1 after)."""
    cases, counts = short_run
    ideal = [n for c, n in zip(cases, counts) if c.sensing == "ideal"]
    assert sum(n["person_collisions"] for n in ideal) == 0


# Issue 21's full criterion on the short run's 25 episodes (every controller, ideal and
# realistic sensing). They pass with the per-source noise streams; the 1,000,000-step run
# still has robot-caused failures under realistic sensing (docs/safety.md), so a change that
# makes these fail is a regression on episodes that were clean.
def test_short_fuzz_no_robot_caused_violation(short_run):
    cases, counts = short_run
    assert [c.seed for c, n in zip(cases, counts) if n["violations"]] == []


def test_short_fuzz_no_collision(short_run):
    cases, counts = short_run
    bad = [(c.seed, c.controller, c.sensing) for c, n in zip(cases, counts)
           if n["person_collisions"] or n["obstacle_collisions"]]
    assert bad == []
