"""The adaptive formation policy: the side the robot is on at the start and after the person
turns round, never on a gradual turn; the fixed policy (the paper's) as before."""

import dataclasses
import math

import numpy as np
import pytest

from companion import metrics
from companion.control import LqrController, make_controller
from companion.control.formation import BEARING_RATE, FormationPolicy, side_of, side_room
from companion.params import BEHIND, LEFT, RIGHT, Params
from companion.sim.crowd import Crowd
from companion.sim.crowd_scenes import SCENES
from companion.sim.episode import run_episode
from companion.sim.person import circle, line
from companion.sim.runner import EpisodeSpec, run_one
from companion.sim.scenario import load_scenario
from companion.types import Circle, PersonState, Pose, Wall


def _params(policy: str, bearing: float = LEFT) -> Params:
    p = Params()
    return p.replace(formation=dataclasses.replace(p.formation, policy=policy,
                                                   bearing=bearing))


def test_the_policy_takes_the_robots_side_at_first_and_after_a_turnaround_only():
    walking = PersonState(0.0, 0.0, 0.0, 1.0, 0.0)
    assert side_of(Pose(0.0, 1.0, 0.0), walking) == 1.0
    assert side_of(Pose(0.0, -1.0, 0.0), walking) == -1.0
    policy = FormationPolicy(_params("adaptive"))
    assert policy.update(Pose(0.0, -1.0, 0.0), walking) == RIGHT      # it starts on the right
    turned = dataclasses.replace(walking, theta=2.0)                    # a turn, not round
    assert policy.update(Pose(0.0, 1.0, 0.0), turned) == RIGHT
    back = dataclasses.replace(walking, theta=math.pi)                  # turned round
    assert policy.update(Pose(0.0, -1.0, 0.0), back) == LEFT            # now on its left
    assert policy.update(Pose(0.0, -1.0, 0.0), dataclasses.replace(back, v=0.0)) == LEFT
    assert FormationPolicy(_params("adaptive", BEHIND)).update(Pose(0.0, -1.0, 0.0),
                                                               walking) == BEHIND


def test_a_person_first_seen_standing_who_sets_off_keeps_the_side():
    """A heading seen while the person stands is no reference: setting off in any direction
    is not a turnaround (a switch then, with the robot beside a person who starts walking,
    led to a contact beside a recorded walker, students003/219)."""
    policy = FormationPolicy(_params("adaptive", RIGHT))
    robot = Pose(0.5, 1.0, 0.0)
    standing = PersonState(0.0, 0.0, 2.0, 0.1, 0.0)
    assert side_of(robot, standing) == -1.0
    assert policy.update(robot, standing) == RIGHT
    off = PersonState(0.0, 0.0, -0.2, 0.8, 0.0)
    assert side_of(robot, off) == 1.0                                    # now on its left
    assert policy.update(robot, off) == RIGHT
    back = dataclasses.replace(off, theta=math.pi - 0.2)                 # a walking turnaround
    assert policy.update(Pose(0.5, -1.0, 0.0), back) == LEFT             # the robot's side


def test_a_side_set_while_running_is_taken_not_the_robots():
    walking = PersonState(0.0, 0.0, 0.0, 1.0, 0.0)
    policy = FormationPolicy(_params("adaptive", RIGHT), given=True)
    assert policy.update(Pose(0.0, 1.0, 0.0), walking) == RIGHT         # the robot is left
    back = dataclasses.replace(walking, theta=math.pi)                  # turned round: the
    assert policy.update(Pose(0.0, 1.0, 0.0), back) == RIGHT            # robot's side again
    assert FormationPolicy(_params("adaptive", RIGHT)).update(Pose(0.0, 1.0, 0.0),
                                                              walking) == LEFT


def _turnaround(policy: str):
    p = _params(policy)
    return run_one(EpisodeSpec("lqr", Crowd(SCENES["turnaround"], 0, dt=p.dt), p, 35.0)), p


def test_at_a_turnaround_the_adaptive_robot_switches_side_instead_of_running_round():
    adaptive, p = _turnaround("adaptive")
    fixed, _ = _turnaround("fixed")
    switches = np.flatnonzero(np.abs(np.diff(adaptive["alpha_d"])) > 0.1)
    assert len(switches) == 1
    assert adaptive["alpha_d"][0] == pytest.approx(LEFT)
    assert adaptive["alpha_d"][-1] == pytest.approx(RIGHT)
    assert np.all(fixed["alpha_d"] == LEFT)
    assert adaptive["robot_y"].min() > 0.0 > fixed["robot_y"][-1]       # it never crossed
    a, f = metrics.compute(adaptive), metrics.compute(fixed)
    assert a["rms_slot_error_m"] < 0.6 * f["rms_slot_error_m"]
    assert a["path_length_m"] < f["path_length_m"]
    assert a["min_person_distance_m"] >= 0.5
    dv = np.abs(np.diff(adaptive["v"]))                                 # no jump in command
    assert np.all(dv <= max(p.supervisor.accel_max, p.supervisor.decel_max) * p.dt + 1e-9)


def test_started_on_the_other_side_the_adaptive_robot_stays_there():
    start = Pose(0.0, -1.0, 0.0)                     # right of a person walking along +x
    runs = {policy: run_one(EpisodeSpec("lqr", line((0.25, 0.0, 0.0), 0.8),
                                        _params(policy), 15.0, start=start))
            for policy in ("adaptive", "fixed")}
    assert np.all(runs["adaptive"]["alpha_d"] == RIGHT)
    assert runs["adaptive"]["robot_y"].max() < 0.0
    assert runs["fixed"]["robot_y"][-1] > 0.0        # crossed over to the left


def test_a_gradual_turn_never_switches():
    log = run_one(EpisodeSpec("lqr", circle((0.0, 0.0, 0.0), 3.0, 1.0, "left"),
                              _params("adaptive"), 40.0))
    assert np.all(log["alpha_d"] == LEFT)


def test_side_room_sees_a_door_ahead_and_a_wall_beside():
    walking = PersonState(12.5, 0.0, 0.0, 1.0, 0.0)
    door = (Wall(15.0, -6.0, 15.0, -0.8), Wall(15.0, 0.8, 15.0, 6.0))
    assert side_room(walking, 1.0, door) == pytest.approx(0.8)
    assert side_room(walking, -1.0, door) == pytest.approx(0.8)
    assert side_room(dataclasses.replace(walking, x=10.0), 1.0, door) == math.inf  # 5 m away
    assert side_room(walking, 1.0, (Wall(10.0, 1.5, 20.0, 1.5),)) == pytest.approx(1.5)
    assert side_room(walking, 1.0, (Wall(14.0, -1.0, 14.0, 1.0),)) == 0.0   # across the way
    pillar = Circle(13.0, 1.2, 0.3)                   # sideways from 0.9 to 1.5 m
    assert side_room(walking, -1.0, (pillar,)) == math.inf
    assert side_room(walking, 1.0, (pillar,), lane=1.1) == math.inf     # passed beyond
    near = Wall(10.0, 2.0, 20.0, 2.0)                 # 0.5 m beyond it: too little
    assert side_room(walking, 1.0, (pillar, near), lane=1.1) == pytest.approx(0.9)
    far = Wall(10.0, 3.0, 20.0, 3.0)                  # 1.5 m beyond it: the robot passes
    assert side_room(walking, 1.0, (pillar, far), lane=1.1) == pytest.approx(3.0)
    piece = dataclasses.replace(pillar, piece=True)   # a piece of a wall the LiDAR saw
    assert side_room(walking, 1.0, (piece,), lane=1.1) == pytest.approx(0.9)
    assert side_room(walking, 1.0, (pillar, far)) == pytest.approx(0.9)    # no lane: any


def test_in_the_corridor_the_adaptive_robot_passes_the_pillars_beside_the_person():
    """The corridor's pillars leave room on their far side: the robot stays beside, as with
    the fixed bearing."""
    runs = {}
    for policy in ("fixed", "adaptive"):
        sc = load_scenario("corridor", {"formation": {"policy": policy}})
        runs[policy] = run_one(sc.episode("lqr"))
    assert np.all(runs["adaptive"]["alpha_d"] == LEFT)
    np.testing.assert_allclose(runs["adaptive"]["robot_y"], runs["fixed"]["robot_y"])


def test_through_a_door_the_adaptive_robot_falls_in_behind_and_returns_to_the_side():
    sc = load_scenario("crowd-doorway")
    runs = {}
    for policy in ("fixed", "adaptive"):
        p = sc.params.replace(formation=dataclasses.replace(sc.params.formation, policy=policy))
        runs[policy] = run_one(EpisodeSpec("lqr", Crowd(SCENES["doorway"], 0, dt=p.dt), p,
                                           35.0, obstacles=sc.obstacles))
    adaptive, fixed = runs["adaptive"], runs["fixed"]
    bearing = adaptive["alpha_d"]
    assert bearing.max() == pytest.approx(BEHIND) and bearing[-1] == pytest.approx(LEFT)
    assert np.abs(np.diff(bearing)).max() <= BEARING_RATE * p.dt + 1e-9   # the slot moves on
    behind = adaptive["robot_x"][np.argmax(bearing)]
    assert 10.0 < behind < 16.0                                  # at the door
    a, f = metrics.compute(adaptive), metrics.compute(fixed)
    assert a["path_length_m"] > 30.0 > f["path_length_m"]       # through, not stuck
    assert a["obstacle_collisions"] == 0 and a["min_person_distance_m"] >= 0.5
    assert adaptive["slot_error_m"][-1] < 0.2 < fixed["slot_error_m"][-1]


DOOR = (Wall(15.0, -6.0, 15.0, -0.8), Wall(15.0, 0.8, 15.0, 6.0))


@pytest.mark.parametrize("policy", ["fixed", "adaptive"])
def test_a_robot_held_up_before_the_door_gets_through_round_the_wall(policy):
    """The person is through the door (2 m on, walking); the robot stands before the wall on
    the left of the opening, its slot straight beyond the wall. The adaptive robot goes
    round the door's edge (``rejoin``), through the opening, and ends in its slot; the fixed
    bearing's slot holds it against the wall."""
    p = _params(policy)
    log = run_one(EpisodeSpec("lqr", line((17.0, 0.0, 0.0), 0.8), p, 25.0,
                              start=Pose(14.4, 1.6, 0.0), obstacles=DOOR))
    m = metrics.compute(log)
    assert m["obstacle_collisions"] == 0 and m["min_person_distance_m"] >= 0.5
    through = log["robot_x"][-1] > 16.0
    if policy == "fixed":
        assert not through and not any("rejoin" in r for r in log["reason"])
        return
    assert through and any("rejoin" in r for r in log["reason"])
    k = int(np.argmax(log["robot_x"] > 15.0))                    # through the opening
    assert abs(log["robot_y"][k]) < 0.8 - p.robot.radius
    assert log["slot_error_m"][-1] < 0.3 and log["alpha_d"][-1] == pytest.approx(LEFT)


def test_a_change_of_side_makes_no_controller_anew(monkeypatch):
    """The bearing in force is an input of the controller's step (``Observation.formation``):
    at the turnaround the side changes and no controller (nor its fallback Riccati solve at
    construction) is made during the episode."""
    p = _params("adaptive")
    stack = make_controller("lqr", p)
    inner = stack.inner
    made = []
    original = LqrController.__init__
    monkeypatch.setattr(LqrController, "__init__",
                        lambda self, params: (made.append(params), original(self, params))[1])
    log = run_episode(stack, Crowd(SCENES["turnaround"], 0, dt=p.dt), p, 35.0)
    assert log["alpha_d"][0] == pytest.approx(LEFT) and log["alpha_d"][-1] == pytest.approx(RIGHT)
    assert stack.inner is inner and made == []
