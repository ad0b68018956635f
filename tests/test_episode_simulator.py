"""The steppable simulator: driven by hand it is the episode runner; reset(seed) repeats."""

import dataclasses
import math

import numpy as np
import pytest

from companion.apps.cli import main
from companion.control import make_controller
from companion.params import REALISTIC, Params
from companion.sim.episode import Simulator, run_episode
from companion.sim.faults import Fault
from companion.sim.person import Figure8, line
from companion.sim.recorder import Recorder
from companion.sim.scenario import load_scenario
from companion.sim.sensing import make_perception
from companion.types import Circle, Command

P = Params(sensing=REALISTIC)
FAULTS = (Fault("stall", 2.0, 3.2), Fault("person_dropout", 4.0, 4.3))


def _by_hand(seed, controller="lqr", duration=6.0):
    """Step the simulator and the stack from outside and record the log as the runner does:
    the first observation, the log and the simulator."""
    ctrl = make_controller(controller, P)
    sim = Simulator(Figure8(), P, duration, faults=FAULTS)
    ctrl.reset()
    obs = sim.reset(seed)
    ctrl.applied(Command(*sim.start_velocity))
    recorder, first = Recorder(P, sim.steps), obs
    while obs is not None:
        cmd = None if sim.stalled else ctrl.step(obs)
        obs = sim.step(cmd)
        recorder.add(sim.sample, None if cmd is None else ctrl.report)
    return first, recorder.log(), sim


def test_stepping_by_hand_is_the_episode_runner():
    """The same controller stepped from outside gives the runner's log, row for row
    (realistic sensing, a stall and a dropout)."""
    _, log_by_hand, sim = _by_hand(4)
    log = run_episode(make_controller("lqr", P), Figure8(), P, 6.0, seed=4, faults=FAULTS)
    assert len(log_by_hand) == sim.steps == len(log)
    assert log_by_hand.equals(log)


def test_reset_with_a_seed_repeats_the_episode_and_other_seeds_differ():
    first_a, log_a, sim = _by_hand(7)
    first_b, log_b, _ = _by_hand(7)
    _, log_c, _ = _by_hand(8)
    assert first_a.detections == first_b.detections
    assert log_a.equals(log_b) and not log_a.equals(log_c)
    with pytest.raises(RuntimeError, match="episode is over"):
        sim.step(None)
    again = sim.reset(7)                   # the same simulator object starts over
    assert again.detections == first_a.detections and sim.k == 0


def test_a_stalled_controller_holds_then_the_base_brakes():
    """No command from t = 2 s to 3.2 s: the last stays in force for the base's command
    timeout (0.5 s; the log shows it held), then the base brakes at the deceleration limit,
    logged as stopped: command_timeout with the command the base executes."""
    _, col, _ = _by_hand(1)
    reason = col["reason"]
    t, v, robot_v = col["t"], col["v"], col["robot_v"]
    timeout = P.robot.command_timeout_s
    held = (t >= 2.0) & (t < 2.0 - P.dt + timeout - 1e-9)
    assert np.all(v[held] == v[np.argmax(held)]) and v[np.argmax(held)] > 0.5
    assert "command_timeout" not in set(reason[held])
    braking = (t >= 2.0 - P.dt + timeout - 1e-9) & (t < 3.2)
    assert set(reason[braking]) == {"command_timeout"}
    assert np.all(np.diff(v[braking]) <= 0.0) and v[braking][-1] == 0.0
    assert np.all(-np.diff(v[braking]) <= P.supervisor.decel_max * P.dt + 1e-12)
    assert robot_v[np.argmax(braking)] - robot_v[np.flatnonzero(braking)[-1]] > 0.1


def test_run_takes_a_seed(tmp_path, capsys):
    """companion run --seed N: the same seed gives the same log, another seed another."""
    logs = []
    for seed in (3, 3, 4):
        out = tmp_path / f"s{seed}-{len(logs)}"
        assert main(["run", "line", "--sensing", "realistic", "--duration", "3", "--seed",
                     str(seed), "--out", str(out)]) == 0
        assert f"seed {seed}," in capsys.readouterr().out
        logs.append((out / "log.csv").read_text())
    assert logs[0] == logs[1] != logs[2]
    assert main(["run", "line", "--seed", "-1", "--out", str(tmp_path / "bad")]) == 2
    assert "--seed" in capsys.readouterr().err


def test_two_controllers_on_one_seed_see_the_same_detections_with_the_lidar_on():
    """Each noise source has its own stream: lqr and pid beside the fig7 walker among two
    pillars, seen by the simulated LiDAR, drive differently yet get the same person
    detections at every step, and the first scan (same pose) has the same noise."""
    sc = load_scenario("fig7")
    params = sc.params.replace(sensing=REALISTIC)
    seen, scans, paths = {}, {}, {}
    for name in ("lqr", "pid"):
        ctrl = make_controller(name, params)
        sim = Simulator(sc.person, params, 20.0, obstacles=sc.obstacles,
                        perception=make_perception("lidar", params))
        ctrl.reset()
        obs = sim.reset(3)
        ctrl.applied(Command(*sim.start_velocity))
        seen[name], scans[name], paths[name] = [], obs.scan, []
        while obs is not None:
            seen[name].append(obs.detections)
            obs = sim.step(ctrl.step(obs))
            paths[name].append((sim.sample.robot.x, sim.sample.robot.y))
    assert sum(len(d) for d in seen["lqr"]) > 150
    assert seen["lqr"] == seen["pid"]
    np.testing.assert_array_equal(scans["lqr"].ranges, scans["pid"].ranges)
    gap = np.max(np.hypot(*(np.array(paths["lqr"]) - np.array(paths["pid"])).T))
    assert gap > 0.05                         # the robots did move differently


def test_a_lost_person_hides_nothing_from_the_lidar():
    """The LiDAR's obstacles leave out the person where the robot believes them to be; once
    the person is lost there is no such place, so a pillar standing where they were last
    seen is an obstacle (hidden, a searching robot drove into a door's wall end where the
    person had last been seen). The ROS node follows the same rule."""
    params = Params(sensing=dataclasses.replace(REALISTIC, person_range_m=3.0))
    pillar = Circle(6.3, 0.4, 0.3)      # near where they are last seen (x about 6)
    sim = Simulator(line((0.0, 0.0, 0.0), 2.5), params, 6.0, obstacles=(pillar,),
                    perception=make_perception("lidar", params))   # runs out of range
    ctrl = make_controller("lqr", params)
    ctrl.reset()
    obs = sim.reset(0)
    seen = {}
    while obs is not None:
        cmd = ctrl.step(obs)
        known = ctrl.report.obstacles
        near = any(math.hypot(o.x - pillar.x, o.y - pillar.y) < 0.3 for o in known)
        seen.setdefault(ctrl.report.estimate is None, []).append(near)
        obs = sim.step(cmd)
    assert seen[True] and all(seen[True][2:])   # lost: the pillar is there (after one scan)
