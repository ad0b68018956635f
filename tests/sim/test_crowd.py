"""Crowd scenes: ORCA walkers (pyrvo) who avoid each other, the person and the robot;
deterministic for a seed; contacts counted by who moved into whom; the social measures."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from companion import metrics
from companion import social as measures
from companion.errors import ConfigError
from companion.geometry import line_of_sight
from companion.params import REALISTIC, Params
from companion.sim.crowd import WALKER_RADIUS, Crowd, Scene, Walker
from companion.sim.crowd_scenes import SCENES
from companion.sim.episode import Simulator, _WalkerContacts
from companion.sim.runner import run_one
from companion.sim.scenario import load_scenario, scenario_from_mapping
from companion.sim.sensing import in_view
from companion.types import LOG_COLUMNS, Circle, Command, Log, PersonState, Pose, Wall


def _walk(crowd: Crowd, steps: int, robot=(1e6, 1e6, 0.0, 0.0)) -> np.ndarray:
    """Positions of everyone (walkers, then the person) after each of ``steps`` periods."""
    out = []
    for _ in range(steps):
        crowd.step(robot)
        out.append(crowd.positions.copy())
    return np.array(out)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_scene_is_deterministic_for_a_seed_and_walkers_keep_apart(name):
    crowd = Crowd(SCENES[name], 20)
    runs = []
    for seed in (3, 3, 4):
        c = crowd.fresh()
        c.reset(np.random.default_rng(seed), 0.3)
        runs.append(_walk(c, 300))
    assert np.array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])
    walkers = runs[0][:, :-1, :]
    gaps = np.linalg.norm(walkers[:, :, None, :] - walkers[:, None, :, :], axis=-1)
    gaps[:, np.arange(walkers.shape[1]), np.arange(walkers.shape[1])] = np.inf
    assert gaps.min() >= 2 * WALKER_RADIUS - 0.02        # bodies never overlap
    person = runs[0][:, -1, :]
    assert np.linalg.norm(walkers - person[:, None, :], axis=-1).min() >= 2 * WALKER_RADIUS
    assert person[-1, 0] > 5.0                             # the person gets on its way


def test_a_walker_gives_way_to_a_robot_standing_in_its_path():
    scene = Scene("one", "", Walker(((0.0, -20.0), (0.0, -30.0))), (),
                  lambda rng, n: (Walker(((-5.0, 0.1), (5.0, 0.1)), 1.2),))
    crowd = Crowd(scene, 1).fresh()
    crowd.reset(np.random.default_rng(0), 0.3)
    path = _walk(crowd, 200, robot=(0.0, 0.0, 0.0, 0.0))[:, 0, :]
    assert path[-1, 0] > 4.0                               # it got past
    assert np.hypot(path[:, 0], path[:, 1]).min() > 0.3 + WALKER_RADIUS


class _Still:
    """A crowd whose one walker stands at ``x``, 0 or moves as told."""

    def __init__(self, x):
        self.n, self.positions = 1, np.array([[x, 0.0], [50.0, 0.0]])


def test_contacts_are_counted_by_who_moved_into_whom():
    p = Params()
    touch = p.robot.radius + WALKER_RADIUS
    robot_moves = _WalkerContacts(p)
    crowd = _Still(touch + 0.05)
    assert robot_moves.sample(0.0, 0.0, crowd) == pytest.approx((0.05, 0.0))
    gap, code = robot_moves.sample(0.1, 0.0, crowd)      # the robot drove 0.1 m into it
    assert gap == pytest.approx(-0.05) and code == 1.0
    walker_moves = _WalkerContacts(p)
    assert walker_moves.sample(0.0, 0.0, crowd)[1] == 0.0
    crowd.positions[0, 0] = touch - 0.05                   # the walker walked into the robot
    assert walker_moves.sample(0.0, 0.0, crowd) == pytest.approx((-0.05, 2.0))
    assert walker_moves.sample(0.0, 0.0, crowd)[1] == 0.0  # a contact counts when it begins
    assert _WalkerContacts(p).sample(0.0, 0.0, None)[1] == 0.0
    assert math.isnan(_WalkerContacts(p).sample(0.0, 0.0, None)[0])


def test_a_crowd_episode_runs_every_controller_with_the_walkers_as_obstacles():
    sc = load_scenario("crowd-crossing")
    for controller in ("lqr", "pid"):
        m = metrics.compute(run_one(sc.episode(controller)))
        assert m["finite"] and m["min_walker_gap_m"] is not None
        assert m["path_length_m"] > 20.0
        assert m["walker_contacts_robot"] >= 0 and m["walker_contacts_walker"] >= 0
    sim = Simulator(sc.person, sc.params, 2.0)
    obs = sim.reset(5)
    assert sim.crowd is not sc.person                      # the episode's own copy
    assert len(obs.obstacles) == sim.crowd.n == 10        # the walkers, seen
    first = sim.crowd.positions.copy()
    sim.step(Command(0.0, 0.0))
    assert not np.array_equal(first, sim.crowd.positions)


def test_crowd_tables_are_checked():
    base = {"name": "c", "crowd": {"scene": "parallel", "walkers": 5}}
    sc = scenario_from_mapping(base, "c.toml", Path("."))
    assert isinstance(sc.person, Crowd) and sc.person.count == 5
    for change, message in [({"crowd": {"scene": "mall"}}, "crowd.scene: expected one of"),
                            ({"crowd": {"scene": "parallel", "walkers": 99}},
                             "crowd.walkers: expected an integer in [0, 60]"),
                            ({"crowd": {"scene": "parallel", "people": 3}}, "crowd.people"),
                            ({"person": {"kind": "line"}}, "[person] or [crowd], not both")]:
        with pytest.raises(ConfigError) as err:
            scenario_from_mapping({**base, **change}, "c.toml", Path("."))
        assert str(err.value).startswith("c.toml: ") and message in str(err.value)


def test_social_measures_of_a_straight_steady_walk():
    n, dt = 200, 0.05
    t = np.arange(n) * dt
    cols = {c: np.zeros(n) for c in LOG_COLUMNS}
    cols.update(t=t, robot_x=1.0 * t, robot_v=np.full(n, 1.0), walker_gap_m=np.full(n, np.nan),
                person_gap_m=np.where(t < 4.0, 0.3, 0.8))
    cols["walker_contact"][[10, 20]] = (1.0, 2.0)
    log = Log({**cols, "status": np.array(["ok"] * n), "reason": np.array([""] * n)})
    social = measures.Social()
    for a in range(0, n, 37):                             # in blocks, as a run streams it
        social.add(Log({k: v[a:a + 37] for k, v in log.columns.items()}))
    m = social.value()
    assert m["path_length_m"] == pytest.approx(t[-1])
    assert m["jerk_rms_mps3"] == pytest.approx(0.0)
    assert m["person_intimate_s"] == pytest.approx(4.0)
    assert m["person_personal_s"] == pytest.approx(n * dt - 4.0)
    assert (m["walker_contacts_robot"], m["walker_contacts_walker"]) == (1, 1)
    assert m["min_walker_gap_m"] is None and m["walker_intimate_s"] == 0.0
    assert m["longest_stop_s"] == 0.0
    cols["robot_v"][50:90] = 0.0                           # a 2 s stop across blocks
    cols["robot_v"][150:160] = 0.0
    cols["person_v"][:] = 1.0
    cols["person_v"][50:75] = 0.0                          # the person stood for 1.25 s of it
    stopped = Log({**cols, "status": log["status"], "reason": log["reason"]})
    for sizes in ([n], [37] * 6, [1] * n):
        social = measures.Social()
        start = 0
        for size in sizes:
            social.add(Log({k: v[start:start + size] for k, v in stopped.columns.items()}))
            start += size
        assert social.value()["longest_stop_s"] == pytest.approx(40 * dt)
        assert social.value()["longest_stop_person_walking_s"] == pytest.approx(15 * dt)


def test_a_crowd_episode_is_the_same_in_a_worker_process():
    from companion.sim.runner import run_many
    specs = [load_scenario("crowd-corridor").episode()] * 2
    here, there = run_one(specs[0]), run_many(specs, 2)
    for log in there:
        assert np.array_equal(log["robot_x"], here["robot_x"])
        assert np.array_equal(log["walker_gap_m"], here["walker_gap_m"], equal_nan=True)


def test_losing_refinding_searching_and_view_are_counted_across_blocks():
    n = 100
    cols = {c: np.zeros(n) for c in LOG_COLUMNS}
    cols.update(t=np.arange(n) * 0.05, walker_gap_m=np.full(n, np.nan),
                person_in_view=np.where(np.arange(n) < 75, 1.0, 0.0))
    reason = np.array([""] * n, dtype=object)
    reason[20:30] = "person_lost"
    reason[30:40] = "person_lost+search_turn"
    reason[40:45] = "reacquiring"                          # still lost until the track resumes
    reason[80:] = "person_lost"                             # lost again, not re-found
    log = Log({**cols, "status": np.array(["ok"] * n), "reason": reason.astype(str)})
    for size in (n, 7, 1):
        social = measures.Social()
        for a in range(0, n, size):
            social.add(Log({k: v[a:a + size] for k, v in log.columns.items()}))
        m = social.value()
        assert (m["person_losses"], m["person_refinds"]) == (2, 1)
        assert m["person_refind_chances"] == 1      # in view 1.25 s of the first loss only
        assert m["search_time_s"] == pytest.approx(0.5)
        assert m["person_in_view_share"] == pytest.approx(0.75)


def test_the_detector_sees_within_its_range_and_not_through_walkers():
    sc = load_scenario("crowd-crossing")
    # the robot walks 1.0-1.24 m from the person here: a 1.22 m range loses them at times
    near = sc.params.replace(sensing=dataclasses.replace(REALISTIC, person_range_m=1.22))
    m = metrics.compute(run_one(dataclasses.replace(sc, params=near).episode("lqr")))
    assert 0.0 < m["person_in_view_share"] < 1.0 and m["person_losses"] >= 1
    m = metrics.compute(run_one(dataclasses.replace(
        sc, params=sc.params.replace(sensing=REALISTIC)).episode("lqr")))
    assert m["person_in_view_share"] == 1.0 and m["person_losses"] == 0
    robot, person = Pose(0.0, 0.0, 0.0), PersonState(3.0, 0.0, 0.0, 1.0, 0.0)
    walker = (Circle(1.5, 0.1, 0.25),)
    hides = dataclasses.replace(REALISTIC, person_occlusion=True)
    assert in_view(robot, person, walker, REALISTIC)
    assert not in_view(robot, person, walker, hides)
    assert in_view(robot, person, (Circle(1.5, 0.4, 0.25),), hides)
    assert not in_view(robot, person, (), dataclasses.replace(REALISTIC, person_range_m=2.9))


def test_line_of_sight_is_blocked_by_circles_and_crossing_walls():
    assert line_of_sight(0.0, 0.0, 4.0, 0.0, (Circle(2.0, 0.3, 0.25),))
    assert not line_of_sight(0.0, 0.0, 4.0, 0.0, (Circle(2.0, 0.2, 0.25),))
    assert not line_of_sight(0.0, 0.0, 4.0, 0.0, (Wall(2.0, -1.0, 2.0, 1.0),))
    assert line_of_sight(0.0, 0.0, 4.0, 0.0, (Wall(5.0, -1.0, 5.0, 1.0),
                                              Wall(1.0, 0.5, 3.0, 0.5)))
