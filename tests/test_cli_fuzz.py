"""``companion fuzz``: outputs, replay, exit codes and bad flags."""

import csv
import dataclasses
import json

import pytest

from companion.evaluate import fuzz_runs
from companion.params import Params
from companion.sim import fuzz
from test_cli import run  # the CLI in-process: exit code, stdout, stderr


def test_fuzz_writes_one_row_per_episode_and_a_replay_gives_the_same_counts(tmp_path, capsys):
    code, out, _ = run(["fuzz", "--steps", "600", "--seed", "2", "--controllers", "lqr,pid",
                        "--sensing", "ideal", "--workers", "1", "--out", str(tmp_path)], capsys)
    with open(tmp_path / "fuzz.csv") as fh:
        rows = list(csv.DictReader(fh))
    report = json.loads((tmp_path / "fuzz.json").read_text())
    assert sum(int(r["steps"]) for r in rows) == report["total"]["steps"] >= 600
    assert [r["controller"] for r in rows][:2] == ["lqr", "pid"]
    assert {r["sensing"] for r in rows} == {"ideal"}
    assert int(rows[0]["seed"]) == 2 * fuzz.SEED_STRIDE
    failed = [r for r in rows if r["failed"] == "1"]
    assert len(report["failed"]) == len(failed)
    assert set(report["by_pair"]) == {"lqr/ideal", "pid/ideal"}
    assert "lqr/ideal" in out and "all" in out
    rate = report["robot_failure_rate"]["ideal"]
    robot = sum(fuzz.robot_failed({k: int(r[k]) for k in fuzz.COUNTS if not k.startswith("min_")})
                for r in rows)
    assert (rate["episodes"], rate["robot_failed_episodes"]) == (len(rows), robot)
    assert code == (1 if robot else 0) and report["walker"] == "blind"   # ideal: none
    assert rate["ci95"][0] <= rate["rate"] <= rate["ci95"][1]
    assert f"ideal: the robot failed by its own doing in {robot} of {len(rows)} episodes" in out
    row = rows[0]
    code, out, _ = run(["fuzz", "--replay", row["seed"], "--controllers", "lqr", "--sensing",
                        "ideal", "--out", str(tmp_path)], capsys)
    assert code == fuzz.robot_failed({k: int(float(row[k])) for k in fuzz.COUNTS
                                      if not k.startswith("min_")})
    episode = json.loads((tmp_path / "episode.json").read_text())
    for key in fuzz.COUNTS:
        assert float(row[key]) == pytest.approx(episode["counts"][key], rel=1e-9)
    with open(tmp_path / "log.csv") as fh:
        assert sum(1 for _ in fh) == int(row["steps"]) + 1
    assert (tmp_path / "fuzz.csv").exists()             # the replay kept the run's files


def test_fuzz_exits_1_and_names_the_seed_of_a_failing_episode(tmp_path, capsys, monkeypatch):
    real = fuzz.episode_counts

    def collided(log, params, obstacles=()):
        counts = real(log, params, obstacles)
        return dict(counts, obstacle_collisions=1)

    monkeypatch.setattr(fuzz, "episode_counts", collided)
    code, out, _ = run(["fuzz", "--steps", "1", "--controllers", "vsm", "--sensing",
                        "realistic", "--workers", "1", "--out", str(tmp_path)], capsys)
    assert code == 1
    assert "FAIL seed 0 vsm/realistic: replay with companion fuzz --replay 0" in out
    assert json.loads((tmp_path / "fuzz.json").read_text())["failed"][0]["seed"] == 0


def test_a_short_fuzz_without_failure_exits_0_and_says_it_cannot_bound_the_rate(
        tmp_path, capsys, monkeypatch):
    real = fuzz.episode_counts

    def clean(log, params, obstacles=()):
        counts = real(log, params, obstacles)
        return dict(counts, person_collisions=0, person_collisions_robot=0,
                    obstacle_collisions=0, violations=0, nonfinite_steps=0)

    monkeypatch.setattr(fuzz, "episode_counts", clean)
    code, out, _ = run(["fuzz", "--steps", "1", "--controllers", "vsm", "--sensing",
                        "realistic", "--workers", "1", "--out", str(tmp_path)], capsys)
    assert code == 0
    assert "criterion not met: realistic: the robot-caused failure rate's 95 % upper bound" in out
    assert "no failure found, but the run is too short to bound the rate" in out
    assert json.loads((tmp_path / "fuzz.json").read_text())["missed_criteria"]


def test_fuzz_runs_on_the_parameters_of_params(tmp_path, capsys):
    params = tmp_path / "p.toml"
    params.write_text("[keepout]\nevasive_horizon_s = 2.0\n")
    argv = ["--steps", "300", "--controllers", "lqr", "--sensing", "ideal", "--workers", "1"]
    run(["fuzz", *argv, "--out", str(tmp_path / "a")], capsys)
    run(["fuzz", *argv, "--params", str(params), "--out", str(tmp_path / "b")], capsys)
    a, b = (json.loads((tmp_path / d / "fuzz.json").read_text()) for d in "ab")
    assert b["params"] == str(params) and a["params"] is None
    assert a["total"]["steps"] == b["total"]["steps"]
    assert a["total"]["degraded_steps"] != b["total"]["degraded_steps"]


def test_a_bad_params_file_for_fuzz_names_the_file_and_key(tmp_path, capsys):
    params = tmp_path / "p.toml"
    params.write_text("[keepout]\nevasive_horizon_s = 0.0\n")
    code, _, err = run(["fuzz", "--params", str(params), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert f"{params}: keepout.evasive_horizon_s: expected a time in [0.1, 10] s" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv, message", [
    (["--steps", "0"], "--steps: expected 1 <= N <= 1e9, got '0'"),
    (["--steps", "2000000000"], "--steps: expected 1 <= N <= 1e9, got '2000000000'"),
    (["--steps", "2e6"], "argument --steps: invalid int value: '2e6'"),
    (["--seed", "-1"], "--seed: expected 0 <= N <= 2**63-1, got '-1'"),
    (["--controllers", "lqr,foo"], "--controllers: expected distinct names from lqr, lqr-paper"),
    (["--controllers", "lqr,lqr"], "--controllers: expected distinct names"),
    (["--sensing", "noisy"], "--sensing: expected ideal or realistic or em-tracker or a .toml "
     "file, got 'noisy'"),
    (["--sensing", "ideal,,realistic"], "--sensing: expected distinct profile names or .toml "
     "files separated by commas"),
    (["--sensing", "ideal,ideal"], "--sensing: expected distinct profile names"),
    (["--workers", "0"], "--workers: expected 1 <= N <= 256, got '0'"),
    (["--replay", "3"], "--replay: give the episode's controller and sensing"),
    (["--replay", "-3", "--controllers", "lqr", "--sensing", "ideal"], "--replay: expected 0 "
     "<= SEED <= 2**63*10**7-1, got '-3'"),
])
def test_bad_fuzz_flags_exit_2_with_one_line(argv, message, capsys, tmp_path):
    code, out, err = run(["fuzz", *argv, "--out", str(tmp_path)], capsys)
    assert code == 2
    assert message in err
    assert err.count("\n") == 1
    assert not list(tmp_path.iterdir())


def test_fuzz_takes_a_sensing_file_and_replays_its_episodes(tmp_path, capsys):
    """--sensing takes TOML files of sensing keys beside the profile names, as the other
    commands do: a base with lag and an exact person here. The file's path names the
    profile in fuzz.csv, and a replay with it gives the same counts."""
    lag = tmp_path / "lag.toml"
    lag.write_text("person_rate_hz = inf\nperson_position_noise_m = 0.0\n"
                   "person_latency_s = 0.0\nperson_dropout = 0.0\nactuator_tau_s = 0.2\n")
    code, out, _ = run(["fuzz", "--steps", "1500", "--controllers", "pid", "--sensing",
                        f"ideal,{lag}", "--workers", "1", "--out", str(tmp_path / "o")], capsys)
    with open(tmp_path / "o" / "fuzz.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["sensing"] for r in rows][:2] == ["ideal", str(lag)]
    report = json.loads((tmp_path / "o" / "fuzz.json").read_text())
    assert set(report["robot_failure_rate"]) == {"ideal", str(lag)}
    lagged = rows[1]
    code, out, _ = run(["fuzz", "--replay", lagged["seed"], "--controllers", "pid",
                        "--sensing", str(lag), "--out", str(tmp_path / "r")], capsys)
    episode = json.loads((tmp_path / "r" / "episode.json").read_text())
    assert episode["case"]["sensing"] == str(lag)
    for key in fuzz.COUNTS:
        assert float(lagged[key]) == pytest.approx(episode["counts"][key], rel=1e-9)
    # the same seed under ideal sensing is another episode of the same world: the lag shows
    code, _, _ = run(["fuzz", "--replay", lagged["seed"], "--controllers", "pid", "--sensing",
                      "ideal", "--out", str(tmp_path / "i")], capsys)
    plain = json.loads((tmp_path / "i" / "episode.json").read_text())["counts"]
    assert plain["steps"] == episode["counts"]["steps"]
    assert plain != episode["counts"]


def test_a_bad_sensing_file_for_fuzz_names_the_file_and_key(tmp_path, capsys):
    bad = tmp_path / "s.toml"
    bad.write_text("actuator_tau_s = -1\n")
    code, _, err = run(["fuzz", "--sensing", f"ideal,{bad}", "--out", str(tmp_path / "o")],
                       capsys)
    assert code == 2
    assert f"--sensing: {bad}: actuator_tau_s: expected a finite number >= 0" in err
    assert err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_fuzz_exits_on_its_criteria_only():
    rate = {"episodes": 400, "robot_failed_episodes": 0, "rate": 0.0, "ci95": [0.0, 0.0092]}
    assert fuzz_runs.missed_criteria({"ideal": rate, "realistic": rate}) == []
    one = dict(rate, robot_failed_episodes=1, ci95=[0.0001, 0.0139])
    missed = fuzz_runs.missed_criteria({"ideal": one, "realistic": one})
    assert missed[0].startswith("ideal: the robot failed by its own doing in 1 of 400")
    assert missed[1].startswith("realistic: the robot-caused failure rate's 95 % upper bound "
                                "is 1.4% over 400 episodes")


def test_a_fuzz_episode_keeps_the_formation_policy_of_its_parameters():
    base = Params().replace(formation=dataclasses.replace(Params().formation,
                                                          policy="fixed"))
    case, spec = fuzz.draw(3, "lqr", "ideal", base)
    assert spec.params.formation.policy == "fixed"
    assert spec.params.formation.distance == case.distance
