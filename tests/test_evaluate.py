"""companion evaluate: suites parse with clear errors, runs resume and do not depend on the
backend, and the statistics say what they should."""

import math

import numpy as np
import pytest

from companion.apps.args import shown
from companion.apps.cli import main
from companion.errors import ConfigError
from companion.evaluate import stats
from companion.evaluate.run import PARTIAL, run_suite
from companion.evaluate.suite import load_suite
from companion.params import REALISTIC
from companion.sim.scenario import load_scenario

SUITE = """
name = "tiny"
reference = "lqr"
controllers = ["lqr", "pid"]
sensing = ["realistic"]
sides = ["left", "right"]
seeds = 2
duration = 2.0
[motions]
scenarios = ["line"]
"""


def _suite(tmp_path, text=SUITE, name="s.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_suite_expands_to_every_combination_with_shared_seeds(tmp_path):
    suite = load_suite(_suite(tmp_path))
    assert len(suite.episodes) == 2 * 2 * 2          # sides x seeds x controllers
    by_pair = {}
    for e in suite.episodes:
        by_pair.setdefault(e.pair, []).append(e)
    assert len(by_pair) == 4
    for pair in by_pair.values():                    # both controllers of a pair: one seed
        assert {e.controller for e in pair} == {"lqr", "pid"}
        assert len({e.spec.seed for e in pair}) == 1
    assert len({e.spec.seed for e in suite.episodes}) == 2
    assert {e.spec.params.formation.bearing for e in suite.episodes} == \
        {0.5 * math.pi, 1.5 * math.pi}
    assert all(e.spec.duration == 2.0 for e in suite.episodes)


@pytest.mark.parametrize("change,message", [
    ('controllers = ["lqr", "pdi"]', "controllers[1].name: expected one of"),
    ('sides = ["up"]', "sides[0]: expected one of"),
    ('seeds = 0', "seeds: expected an integer in [1, 100000] or a list of seeds, got 0"),
    ('sensing = ["perfect"]', "sensing[0]:"),
    ('reference = "vsm"', "reference: expected one of the controllers"),
    ('colour = "red"', "colour: unknown key"),
    ('sides = ["left", "left"]', "two episodes would be"),
    ('scenarios = ["nowhere"]', "motions.scenarios[0]:"),
    ('sides = [7.0]', "sides[0]: expected an angle in [0, 2*pi) rad, got 7.0"),
    ('duration = nan', "duration: expected a number of seconds in (0, 86400], got nan"),
    ('duration = inf', "duration: expected a number of seconds in (0, 86400], got inf"),
    ('duration = 0.001', "duration: expected at least one sample period (params.dt = 0.05 s"),
    ('seeds = 1e9', "seeds: expected an integer in [1, 100000] or a list of seeds"),
    ('seeds = 1000000000', "seeds: expected an integer in [1, 100000] or a list of seeds"),
    ('seeds = [-1]', "seeds[0]: expected a seed >= 0"),
    ('seeds = 100000', "expected at most 100000 episodes, got 400000"),
    ('name = 3', "name: expected a string, got 3"),
    ('description = ["a"]', "description: expected a string, got ['a']"),
])
def test_bad_suites_name_the_file_and_key(tmp_path, change, message):
    key = change.split(" = ")[0]
    text = "\n".join(line for line in SUITE.splitlines() if not line.startswith(key + " "))
    if key == "scenarios":                          # a key of the [motions] table
        text = text + "\n" + change
    else:
        text = change + "\n" + text
    path = _suite(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_suite(path)
    assert str(err.value).startswith(f"{path}: ") and message in str(err.value)
    assert "\n" not in str(err.value)


def test_a_side_that_a_controller_cannot_hold_names_the_file_and_the_factors(tmp_path):
    """The slot 0.7 m in front puts the robot centre 0.45 m from the person: the side, the
    sensing and the controller that make it are named."""
    text = SUITE.replace('sides = ["left", "right"]', 'sides = ["left", "front"]').replace(
        'controllers = ["lqr", "pid"]',
        'controllers = ["lqr", {name = "lqr", params = {formation = {distance = 0.7}}, '
        'label = "near"}]')
    path = _suite(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_suite(path)
    assert str(err.value).startswith(
        f"{path}: sides[1], sensing[0], controllers[1]: formation.distance: the slot at 0.7 m")


def test_weights_without_a_gain_in_a_suite_name_the_file_and_the_factors(tmp_path):
    text = SUITE.replace('controllers = ["lqr", "pid"]',
                         'controllers = ["pid", {name = "lqr", params = {lqr = {q = [0, 0, 0, 0, '
                         '0]}}, label = "zero"}]').replace('reference = "lqr"', "")
    path = _suite(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_suite(path)
    assert str(err.value).startswith(f"{path}: sides[0], sensing[0], controllers[1]: ")
    assert "params.lqr.q: no stabilising LQR gain" in str(err.value)


@pytest.mark.parametrize("change,key", [
    ('sides = [7.0]', "sides[0]"), ('duration = nan', "duration"),
    ('duration = 0.001', "duration"), ('seeds = 1000000000', "seeds")])
def test_the_command_rejects_a_bad_suite_before_running(tmp_path, capsys, change, key):
    """Exit 2, one line naming the file and the key, no output folder (nor its partial one)."""
    text = "\n".join(line for line in SUITE.splitlines()
                     if not line.startswith(change.split(" = ")[0] + " "))
    bad = _suite(tmp_path, change + "\n" + text, "bad.toml")
    assert main(["evaluate", str(bad), "--out", str(tmp_path / "out"), "--workers", "1"]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and f"{bad}: {key}: expected" in err[0], captured
    assert not (tmp_path / "out").exists()


def test_a_killed_run_resumes_and_gives_the_uninterrupted_results(tmp_path):
    suite = load_suite(_suite(tmp_path))
    whole = run_suite(suite, tmp_path / "whole", workers=1)

    class Killed(Exception):
        pass

    def kill_after_three(done, total):
        if done == 3:
            raise Killed
    with pytest.raises(Killed):
        run_suite(suite, tmp_path / "cut", workers=1, progress=kill_after_three)
    lines = (tmp_path / "cut" / PARTIAL / "episodes.jsonl").read_text().splitlines()
    assert len(lines) == 1 + 3                       # the header and three episodes
    with open(tmp_path / "cut" / PARTIAL / "episodes.jsonl", "a") as f:
        f.write('{"key": "line:left:realis')        # a line a kill cut short
    first = []
    resumed = run_suite(suite, tmp_path / "cut", workers=1,
                        progress=lambda done, total: first.append(done))
    assert first[0] == 3                             # three were kept, five ran
    assert _numbers(resumed) == _numbers(whole)


def test_kept_episodes_of_another_companion_are_run_again(tmp_path, monkeypatch):
    from companion.evaluate import run

    suite = load_suite(_suite(tmp_path))

    def stop(done, total):
        raise KeyboardInterrupt
    with pytest.raises(KeyboardInterrupt):     # the first episode is kept, then a stop
        run_suite(suite, tmp_path / "o", workers=1,
                  progress=lambda done, total: done >= 1 and stop(done, total))
    monkeypatch.setattr(run, "code_digest", lambda: "an updated companion")
    first = []
    run_suite(suite, tmp_path / "o", workers=1, progress=lambda done, total: first.append(done))
    assert first[0] == 0                       # nothing kept from the old code


def _numbers(rows):
    return [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()}
            for r in rows]


def test_local_processes_and_a_dask_cluster_give_the_same_results(tmp_path):
    """Two worker processes and a loopback Dask LocalCluster of two workers give what one
    process gives."""
    pytest.importorskip("distributed")
    suite = load_suite(_suite(tmp_path))
    one = _numbers(run_suite(suite, tmp_path / "one", workers=1))
    assert _numbers(run_suite(suite, tmp_path / "two", workers=2)) == one
    assert _numbers(run_suite(suite, tmp_path / "dask", workers=2, dask="local")) == one


def test_binomial_interval_is_exact():
    low, high = stats.binomial_ci(0, 10)
    assert low == 0.0 and high == pytest.approx(1 - 0.025 ** 0.1, abs=1e-9)
    low, high = stats.binomial_ci(10, 10)
    assert high == 1.0 and low == pytest.approx(0.025 ** 0.1, abs=1e-9)


def test_paired_verdicts_only_where_the_interval_excludes_zero():
    rng = np.random.default_rng(0)
    ref = [{"pair": str(i), "rms_slot_error_m": 0.3 + 0.05 * rng.standard_normal()}
           for i in range(40)]
    better = [{"pair": r["pair"], "rms_slot_error_m": r["rms_slot_error_m"] - 0.02} for r in ref]
    noisy = [{"pair": r["pair"], "rms_slot_error_m": r["rms_slot_error_m"]
              + 0.02 * rng.standard_normal()} for r in ref]
    assert stats.paired(better, ref, "rms_slot_error_m")["verdict"] == "better"
    worse = [{"pair": r["pair"], "rms_slot_error_m": r["rms_slot_error_m"] + 0.02} for r in ref]
    assert stats.paired(worse, ref, "rms_slot_error_m")["verdict"] == "worse"
    p = stats.paired(noisy, ref, "rms_slot_error_m")
    assert p["verdict"] == "no difference shown" and p["low"] < 0.0 < p["high"]
    m, low, high = stats.median_ci([r["rms_slot_error_m"] for r in ref])
    assert low < m < high and high - low < 0.1
    # higher is better for the closest approach: keeping farther away is "better"
    near = [{"pair": str(i), "min_person_distance_m": 0.9 + 0.01 * i} for i in range(20)]
    far = [{"pair": r["pair"], "min_person_distance_m": r["min_person_distance_m"] + 0.05}
           for r in near]
    assert stats.paired(far, near, "min_person_distance_m")["verdict"] == "better"
    assert stats.paired(near, far, "min_person_distance_m")["verdict"] == "worse"
    # five pairs cannot show a difference at 95 %, however consistent
    assert stats.paired(better[:5], ref, "rms_slot_error_m")["verdict"] == \
        "no difference shown"
    assert stats.paired(better[:6], ref, "rms_slot_error_m")["verdict"] == "better"


def test_the_median_interval_of_paired_differences_covers_95_percent():
    """The order-statistic interval covers the true median at least 95 % of the time (here
    on skewed differences, 10 pairs, 2,000 draws)."""
    rng = np.random.default_rng(1)
    true = float(np.log(2.0))                       # the median of Exp(1)
    hits = 0
    for _ in range(2000):
        _, low, high = stats.median_sign_ci(rng.exponential(size=10))
        hits += low <= true <= high
    assert 0.95 <= hits / 2000 <= 0.995


def test_the_command_writes_its_outputs_and_rejects_a_bad_suite(tmp_path, capsys):
    path = _suite(tmp_path)
    assert main(["evaluate", str(path), "--out", str(tmp_path / "out"), "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    assert "| lqr | 4 |" in printed and "Paired with `lqr`" in printed
    names = {p.name for p in (tmp_path / "out").iterdir() if not p.name.startswith(".")}
    assert {"episodes.csv", "summary.json", "summary.md", "slot_realistic_line.png"} <= names
    assert not (tmp_path / "out" / PARTIAL).exists()
    rows = (tmp_path / "out" / "episodes.csv").read_text().splitlines()
    assert len(rows) == 1 + 8 and rows[0].startswith("episode,motion,group,side,sensing")
    bad = _suite(tmp_path, SUITE.replace('"pid"', '"pdi"'), "bad.toml")
    assert main(["evaluate", str(bad), "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{bad}: controllers[1].name" in err[0]


def test_every_shipped_suite_parses():
    """The suites in suites/ expand without error (a checker over every shipped suite)."""
    from pathlib import Path
    folder = Path(__file__).resolve().parents[1] / "suites"
    suites = sorted(folder.glob("*.toml"))
    assert len(suites) >= 2
    for path in suites:
        suite = load_suite(path)
        assert suite.episodes and suite.reference in {e.controller for e in suite.episodes}


def test_tuning_on_a_suite_improves_resumes_and_writes_a_params_file(tmp_path, capsys):
    """Optuna on a two-episode suite: the first trial is the current gains, the best is no
    worse, a second call on the same storage only adds the missing trials, and best.toml
    loads as parameters with the tuned gains."""
    pytest.importorskip("optuna")
    from companion.params import load_params
    path = _suite(tmp_path, SUITE.replace('controllers = ["lqr", "pid"]',
                                          'controllers = ["pid"]')
                  .replace('reference = "lqr"', "").replace("seeds = 2", "seeds = 1")
                  .replace('sides = ["left", "right"]', 'sides = ["left"]'))
    storage = f"sqlite:///{tmp_path / 'study.db'}"
    args = ["tune", "pid", "--suite", str(path), "--storage", storage, "--workers", "1",
            "--out", str(tmp_path / "out")]
    assert main([*args, "--trials", "3"]) == 0
    printed = capsys.readouterr().out
    start = float(printed.split("J: current parameters ")[1].split(",")[0])
    # the first trial is the current gains: its J is the suite's objective with them
    from companion.evaluate.run import run_all
    from companion.evaluate.tuning import objective
    direct = objective(run_all(load_suite(path), 1))
    assert start == pytest.approx(direct, abs=5e-5)
    trials = (tmp_path / "out" / "trials.csv").read_text().splitlines()
    assert len(trials) == 1 + 3
    assert main([*args, "--trials", "4"]) == 0
    assert "(4 trials)" in capsys.readouterr().out
    rows = (tmp_path / "out" / "trials.csv").read_text().splitlines()
    assert len(rows) == 1 + 4
    assert len({r.split(",")[1] for r in rows[1:]}) == 4, rows   # the resumed trial is new
    tuned = load_params(tmp_path / "out" / "best.toml")
    text = (tmp_path / "out" / "best.toml").read_text()
    assert f"kp_x = {tuned.pid.kp_x:.6g}" in text
    assert main(["tune", "lqr", "--suite", str(path), "--trials", "1",
                 "--out", str(tmp_path / "x")]) == 2
    assert "controllers: expected 'lqr'" in capsys.readouterr().err


@pytest.mark.parametrize("where", ["missing", "folder"])
def test_an_unopenable_storage_is_one_line_naming_it(tmp_path, capsys, where):
    pytest.importorskip("optuna")
    path = _suite(tmp_path, SUITE.replace('controllers = ["lqr", "pid"]', 'controllers = ["pid"]')
                  .replace('reference = "lqr"', ""))
    (tmp_path / "folder.db").mkdir()
    db = tmp_path / "nonexistent" / "dir" / "x.db" if where == "missing" else tmp_path / "folder.db"
    storage = f"sqlite:///{db}"
    assert main(["tune", "pid", "--suite", str(path), "--storage", storage, "--trials", "1",
                 "--workers", "1", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0] == f"companion: error: --storage {storage}: cannot open it (unable to open " \
                     f"database file)"


def test_the_tracker_is_tuned_on_a_suite_with_the_same_study(tmp_path):
    """The tracker's settings go through the same Optuna study as the gains: the first
    trial is the current settings, every trial stays in the search box, and the best are
    valid parameters."""
    pytest.importorskip("optuna")
    from companion.evaluate.tuning import TRACKER_SPACE, current, tune_on_suite
    from companion.params import Params
    path = _suite(tmp_path, SUITE.replace('controllers = ["lqr", "pid"]',
                                          'controllers = ["lqr"]').replace("seeds = 2",
                                                                           "seeds = 1")
                  .replace('sides = ["left", "right"]', 'sides = ["left"]'))
    tuned = tune_on_suite(load_suite(path), "lqr", 2, workers=1, dims=TRACKER_SPACE)
    assert tuned.trials == 2 and len(tuned.history) == 2
    assert tuned.history[0][1] == tuned.start_value
    values = current(tuned.params, TRACKER_SPACE)
    assert all(d.low <= v <= d.high for d, v in zip(TRACKER_SPACE, values))
    assert tuned.best_value == min(j for _, j in tuned.history)
    assert current(Params(), TRACKER_SPACE) != values or tuned.best_value == tuned.start_value


def test_inline_tables_for_params_sensing_and_scenarios(tmp_path):
    """A controller's params, a sensing profile and a scenario's obstacle source may be
    tables in the suite; they reach the episodes."""
    path = _suite(tmp_path, """
name = "inline"
controllers = ["lqr",
               {name = "lqr", label = "cautious", params = {keepout = {collision_risk = 0.1}}}]
sensing = [{label = "noisy", person_position_noise_m = 0.1}]
sides = ["scenario"]
[motions]
scenarios = [{name = "fig7", obstacles = "lidar", label = "eight"}]
""")
    suite = load_suite(path)
    assert [e.key for e in suite.episodes] == ["eight:scenario:noisy:lqr:0",
                                               "eight:scenario:noisy:cautious:0"]
    plain, cautious = (e.spec for e in suite.episodes)
    assert cautious.params.keepout.collision_risk == 0.1
    assert plain.params.keepout.collision_risk == 0.0
    assert plain.params.sensing.person_position_noise_m == 0.1
    assert plain.params.sensing.person_latency_s == REALISTIC.person_latency_s
    assert plain.obstacle_source == "lidar"
    assert plain.params.formation.bearing == load_scenario("fig7").params.formation.bearing


def test_an_unknown_suite_name_lists_the_shipped_ones(tmp_path):
    with pytest.raises(ConfigError, match=r"^pedestrian: no such suite file or shipped suite; "
                                          r"did you mean 'pedestrians'\? \(shipped: .*smoke"):
        load_suite("pedestrian")
    with pytest.raises(ConfigError, match="no such file"):
        load_suite(tmp_path / "missing.toml")



def test_an_interrupted_evaluate_says_what_it_kept_and_the_next_run_resumes(
        tmp_path, capsys, monkeypatch):
    """Ctrl-C after 3 of 8 episodes: exit 130, one line saying 3 of 8 are kept and that the
    same command continues; the next run says it resumes from them and finishes."""
    from companion.evaluate import run as engine

    real = engine._backend

    def interrupted(dask, workers, specs, reduce):
        for n, item in enumerate(real(dask, workers, specs, reduce)):
            if n == 3:
                raise KeyboardInterrupt
            yield item

    path, out = _suite(tmp_path), tmp_path / "out"
    args = ["evaluate", str(path), "--out", str(out), "--workers", "1"]
    monkeypatch.setattr(engine, "_backend", interrupted)
    assert main(args) == 130
    err = capsys.readouterr().err
    assert f"tiny: stopped; 3 of 8 episodes kept in {shown(out / '.evaluate.partial')}: the " \
           "same command continues from them" in err
    monkeypatch.setattr(engine, "_backend", real)
    assert main(args) == 0
    assert f"resuming: 3 of 8 episodes kept in {out / '.evaluate.partial'}" \
        in capsys.readouterr().out
