"""A lost person: a controlled stop, then (search.max_time_s > 0) a search that faces and
approaches where the person was going, bounded in time and distance, stopping short of what
it sees, and ends when the person is found again."""

import dataclasses
import math

import numpy as np
import pytest

from companion import metrics
from companion.control.choice import Choosing
from companion.control.delays import DelayMeter
from companion.control.search import Search, search_goal
from companion.control.stages import Step
from companion.params import REALISTIC, Params
from companion.sim.faults import faults_from_list
from companion.sim.person import line
from companion.sim.runner import EpisodeSpec, run_one
from companion.types import Circle, Observation, PersonEstimate, PersonState, Pose

#: The detector goes silent from 5 to 12 s while the person walks on at 1 m/s.
SILENT = faults_from_list([{"kind": "person_dropout", "start": 5.0, "end": 12.0}], "test")


def _run(obstacles=(), **search):
    p = Params(sensing=REALISTIC)
    p = p.replace(search=dataclasses.replace(p.search, **search))
    log = run_one(EpisodeSpec("lqr", line((0.0, 0.0, 0.0), 1.0), p, 30.0, seed=1,
                              faults=SILENT, obstacles=obstacles))
    return log, p


def _phases(log):
    return [r for r in log["reason"] if "search" in r]


def test_search_goal_walks_the_last_estimate_on():
    state = PersonState(1.0, 2.0, math.pi / 2, 0.8, 0.0)
    last = PersonEstimate(state, 0.05, np.eye(5), 0.0, "seen", state)
    assert search_goal(last, 2.5) == pytest.approx((1.0, 4.0))


def test_without_a_search_the_robot_stops_and_holds():
    log, _ = _run(max_time_s=0.0)
    lost = np.char.find(log["reason"].astype(str), "person_lost") >= 0
    assert lost.any() and not _phases(log)
    k = np.flatnonzero(lost)
    held = k[np.abs(log["robot_v"][k]) < 1e-3]      # once braked
    assert np.ptp(log["robot_x"][held]) < 0.05 and np.ptp(log["robot_y"][held]) < 0.05


def test_the_search_turns_then_approaches_and_the_robot_finds_the_person_again():
    log, p = _run(max_time_s=15.0)
    held, _ = _run(max_time_s=0.0)
    phases = _phases(log)
    first = [ph for i, ph in enumerate(phases) if i == 0 or phases[i - 1] != ph]
    assert first[:2] == ["person_lost+search_turn", "person_lost+search_approach"]
    searching = np.char.find(log["reason"].astype(str), "search_") >= 0
    assert np.all(np.abs(log["v"][searching]) <= p.search.speed + 1e-9)
    assert np.all(np.abs(log["omega"][searching]) <= p.search.turn_rate + 1e-9)
    # the rate limits hold through the loss, the search and the return: no jump in command
    dv = np.abs(np.diff(log["v"]))
    assert np.all(dv <= max(p.supervisor.accel_max, p.supervisor.decel_max) * p.dt + 1e-9)
    # found again: following resumes, and the search shortened the way back
    assert log["status"][-1] != "stopped" and not searching[-100:].any()
    assert log["slot_error_m"][-1] < 0.5 < held["slot_error_m"][-1]
    assert metrics.compute(log)["min_person_distance_m"] >= 0.5


def test_the_search_is_bounded_in_time_and_distance():
    log, p = _run(max_time_s=2.0)
    t = log["t"][np.char.find(log["reason"].astype(str), "search_") >= 0]
    assert 1.5 <= t[-1] - t[0] <= 2.0 + p.dt
    log, p = _run(max_time_s=15.0, max_distance_m=0.4)
    k = np.flatnonzero(np.char.find(log["reason"].astype(str), "search_") >= 0)
    start = np.array([log["robot_x"][k[0]], log["robot_y"][k[0]]])
    moved = np.hypot(log["robot_x"][k] - start[0], log["robot_y"][k] - start[1])
    assert moved.max() <= 0.4 + 0.3 * p.dt + 0.05      # the braking after the bound


def test_the_search_stops_short_of_an_obstacle_in_its_way():
    pillar = Circle(6.2, 0.45, 0.3)                    # on the way to where the person went
    log, _ = _run(obstacles=(pillar,), max_time_s=15.0)
    assert _phases(log)
    assert np.nanmin(log["rho_ob"]) > 0.0


def _searching(t, robot, v_now=0.0, **search):
    """The command of a search begun at t = 0 for a person last seen at the origin walking
    along +x at 1 m/s."""
    p = Params()
    p = p.replace(search=dataclasses.replace(p.search, **search))
    state = PersonState(0.0, 0.0, 0.0, 1.0, 0.0)
    s = Search(p)
    s.begin(0.0, Pose(0.0, -3.0, 0.0), PersonEstimate(state, 0.05, np.eye(5), 0.0, "seen", state))
    return s.target(t, robot, (), v_now)


def test_the_search_looks_where_the_person_would_be_by_now():
    """At first where the person was going (horizon_s on), later where they would be by now:
    a robot at x = 3.5 turns back to x = 2 one second in, and drives on to x = 6 six
    seconds in."""
    ahead = Pose(3.5, 0.0, 0.0)
    v, _, phase = _searching(1.0, ahead)
    assert phase == "search_turn" and v == 0.0
    v, _, phase = _searching(6.0, ahead)
    assert phase == "search_approach" and v == pytest.approx(1.5)


def test_the_search_stops_short_of_where_the_person_would_be():
    """It never drives at full speed into the person it looks for: near where the prediction
    puts them (6 s in: x = 6) its speed is the braking bound of a person standing there."""
    v = [_searching(6.0, Pose(x, 0.0, 0.0), 1.5, horizon_s=0.0, arrive_m=0.1)[0]
         for x in (2.0, 5.0, 5.6)]              # 4, 1 and 0.4 m from the predicted person
    assert v[0] == pytest.approx(1.5)
    assert 0.0 < v[1] < 1.4
    assert v[2] == 0.0                           # inside the protective distance: no closer


@pytest.mark.parametrize("prev", [(0.04, 0.0), (0.0, 0.09), (0.0, 0.0)])
def test_the_choosing_stage_waits_for_rest_before_a_search(prev):
    """The stage alone: a lost person and the last command ``prev``: the search's first
    command comes only once the robot is at rest (it used to start below 0.05 m/s and
    0.1 rad/s)."""
    p = Params()
    stage = Choosing(p, DelayMeter(p))
    seen = PersonState(1.0, 0.0, 0.0, 1.0, 0.0)
    stage(Step(Observation(0.0, Pose(0.0, 0.0, 0.0)), p, prev,
               estimate=PersonEstimate(seen, 0.05, np.eye(5), 0.0, "seen", seen)))
    s = Step(Observation(0.05, Pose(0.0, 0.0, 0.0)), p, prev, lost=True)
    stage(s)
    assert (s.manoeuvre is not None) == (prev == (0.0, 0.0))
    assert s.stop == ("" if prev == (0.0, 0.0) else "person_lost")
