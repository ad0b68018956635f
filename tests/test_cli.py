import csv
import json
import math

import pytest

from companion.apps.cli import main
from companion.types import LOG_COLUMNS

METRIC_KEYS = {"rmse_rho_m", "rmse_alpha_rad", "rmse_beta_rad", "rmsv_v_mps",
               "rmsv_omega_radps", "min_person_distance_m", "settling_time_s",
               "final_abs_error"}


def run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse usage errors
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


def test_run_writes_log_metrics_and_plots(tmp_path, capsys):
    code, out, _ = run(["run", "line", "--duration", "3", "--out", str(tmp_path), "--plot"],
                       capsys)
    assert code == 0
    assert "RMSE rho" in out
    with open(tmp_path / "log.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert set(LOG_COLUMNS) <= set(rows[0])
    assert len(rows) == 60
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert METRIC_KEYS <= set(m)
    assert set(m["final_abs_error"]) == {"rho_m", "alpha_rad", "beta_rad"}
    assert m["rmse_rho_m"] < 1e-6  # starts in its slot on a straight line
    for name in ("trajectory.png", "errors.png", "inputs.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".*.tmp"))


def test_side_distance_start_and_controller(tmp_path, capsys):
    code, _, _ = run(["run", "line", "--side", "right", "--distance", "1.5",
                      "--start=-3,-2,0.5", "--duration", "25", "--controller", "lqr",
                      "--out", str(tmp_path)], capsys)
    assert code == 0
    with open(tmp_path / "log.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert (float(rows[0]["robot_x"]), float(rows[0]["robot_y"])) == (-3.0, -2.0)
    last = rows[-1]
    assert float(last["rho"]) == pytest.approx(1.5, abs=0.02)
    assert float(last["alpha"]) == pytest.approx(1.5 * math.pi, abs=0.02)


def test_bearing_option(tmp_path, capsys):
    code, _, _ = run(["run", "line", "--bearing", "3.14159", "--duration", "1",
                      "--out", str(tmp_path)], capsys)
    assert code == 0
    with open(tmp_path / "log.csv") as fh:
        first = next(csv.DictReader(fh))
    assert float(first["alpha_d"]) == pytest.approx(3.14159)


def test_person_csv(tmp_path, capsys):
    f = tmp_path / "walk.csv"
    lines = ["t,x,y"] + [f"{0.4 * i:.1f},{0.4 * i * 1.1:.4f},0" for i in range(60)]
    f.write_text("\n".join(lines) + "\n")
    code, out, _ = run(["run", "line", "--person-csv", str(f), "--out", str(tmp_path / "o")],
                       capsys)
    assert code == 0
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["duration_s"] == pytest.approx(23.6, abs=0.06)
    assert m["min_person_distance_m"] > 0.9


def test_scenarios_lists_builtins(capsys):
    code, out, _ = run(["scenarios"], capsys)
    assert code == 0
    names = {line.split()[0] for line in out.splitlines()}
    assert {"fig3", "line", "circle", "figure8", "ushape", "fig4", "fig7", "corridor"} <= names


def test_run_with_obstacles_writes_avoidance_metrics_and_panel(tmp_path, capsys):
    code, out, _ = run(["run", "fig4", "--obstacles", "lidar", "--duration", "20",
                        "--out", str(tmp_path), "--plot"], capsys)
    assert code == 0
    assert "collisions 0" in out
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m["obstacle_collisions"] == 0 and m["min_obstacle_clearance_m"] >= 0.05
    assert (tmp_path / "avoidance.png").read_bytes()[:4] == b"\x89PNG"
    with open(tmp_path / "log.csv") as fh:
        assert {"u_ob", "rho_ob"} <= set(next(csv.DictReader(fh)))


@pytest.mark.parametrize("argv, flag", [
    (["run", "line", "--out", ""], "--out"), (["run", "line", "--params", " "], "--params"),
    (["run", ""], "scenario"), (["node", "--zenoh-connect", ""], "--zenoh-connect"),
    (["replay", ""], "bag")])
def test_an_empty_value_is_an_error_not_the_default(argv, flag, capsys, tmp_path, monkeypatch):
    """``--out ""`` would otherwise read as no --out and write out/line: one line, nothing
    written."""
    monkeypatch.chdir(tmp_path)
    code, _, err = run(argv, capsys)
    assert code == 2 and err == f"companion: error: {flag}: expected a value, got an empty text\n"
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("argv, message", [
    (["run", "nosuch"], "nosuch: no built-in scenario"),
    (["run", "figur8"], "did you mean 'figure8'"),
    (["run", "line", "--start", "1,2"], "--start: expected 3 comma-separated"),
    (["run", "line", "--distance", "-1"], "--distance: expected 0 < M <= 1e+06 m, got '-1'"),
    (["run", "line", "--duration", "abc"], "--duration: expected a number, got 'abc'"),
    (["run", "line", "--duration", "1e9"], "--duration: expected a finite number of magnitude"),
    (["run", "line", "--duration", "1e5"], "--duration: expected 0 < S <= 86400 s, got '1e5'"),
    (["run", "line", "--start=1e308,0,0"], "--start: expected 3 comma-separated finite numbers"),
    (["run", "line", "--distance", "inf"], "--distance: expected a finite number"),
    (["run", "line", "--distance", "0.3"], "error: --distance: params.formation.distance: the "
                                           "slot at 0.3 m"),
    (["soak", "--seed", "-1", "--duration", "1"], "--seed: expected 0 <= N <= 2**63-1, got '-1'"),
    (["soak", "--duration", "1e308"], "--duration: expected a finite number of magnitude"),
    (["run", "line", "--side", "left", "--bearing", "1"], "give one, not both"),
    (["run", "line", "--person-csv", "/nonexistent/walk.csv"], "walk.csv"),
    (["run", "line", "--side", "up"], "invalid choice: 'up'"),
    (["run", "line", "--start", "-1,2,0"], "--start: expected one argument"),
    (["run"], "the following arguments are required: scenario"),
])
def test_bad_usage_exits_2_with_one_line(argv, message, capsys, tmp_path):
    code, out, err = run(argv + ["--out", str(tmp_path)], capsys)
    assert code == 2
    assert message in err
    assert err.count("\n") == 1
    assert not (tmp_path / "log.csv").exists()


@pytest.mark.parametrize("text, message", [
    ('name = "x"\n[person]\nkind = "line"\nspeed = -1\n',
     "person.speed: expected a number in [0.01, 3] m/s"),
    ('[person]\nkind = "lin"\n', "person.kind: expected one of"),
    ('[person]\nkind = "line"\nspede = 1\n', "person.spede: unknown key; did you mean 'speed'"),
    ('duraton = 3\n[person]\nkind = "line"\n', "duraton: unknown key; did you mean 'duration'"),
    ('[person]\nkind = "line"\n[params.lqr]\nq = [1, 2]\n', "params.lqr.q: expected 5 values"),
    ('[person]\nkind = "line"\n[params.formation]\nbearing = "auto"\n', "'auto' needs robot.start"),
    ('[person]\nkind = "csv"\npath = "missing.csv"\n', "missing.csv: cannot read file"),
    ('[person\nkind = "line"\n', "invalid TOML"),
    ('duration = 3\n', "person: missing table"),
    ('[person]\nkind = "line"\n[[obstacles]]\nkind = "box"\n',
     "obstacles[0].kind: expected 'circle' or 'wall'"),
    ('[person]\nkind = "line"\n[[obstacles]]\nkind = "circle"\nradius = -1\n',
     "obstacles[0].radius: expected a finite positive"),
    ('[person]\nkind = "line"\n[[obstacles]]\nkind = "circle"\nradus = 1\n',
     "obstacles[0].radus: unknown key; did you mean 'radius'"),
    ('[person]\nkind = "line"\n[[obstacles]]\nkind = "wall"\nstart = [1, 1]\nend = [1, 1]\n',
     "obstacles[0]: expected a wall of positive length"),
    ('obstacle_source = "radar"\n[person]\nkind = "line"\n',
     "obstacle_source: expected one of truth, lidar"),
    ('[person]\nkind = "line"\n[[obstacles]]\nkind = "circle"\nx = inf\ny = 0\n',
     "obstacles[0].x: expected a finite number of magnitude at most 1e+06, got inf"),
    ('[person]\nkind = "line"\n[robot]\nstart = [1e308, 0, 0]\n',
     "robot.start[0]: expected a finite number of magnitude at most 1e+06"),
    ('[person]\nkind = "figure8"\nlap_time = 1e-300\n',
     "person.lap_time: expected a number >= 20.944 s"),
    ('[person]\nkind = "circle"\nradius = 1e-300\n',
     "person.radius: expected a number >= 0.2 m"),
    ('[person]\nkind = "line"\nspeed = 50\n',
     "person.speed: expected a number in [0.01, 3] m/s"),
    ('[person]\nkind = "segments"\n[[person.segments]]\ncurvature = inf\n',
     "person.segments[0].curvature: expected a finite number"),
    ('controller = "lqrr"\n[person]\nkind = "line"\n',
     "bad.toml: controller: unknown controller 'lqrr'; did you mean 'lqr'"),
    ('duration = 1e9\n[person]\nkind = "line"\n',
     "duration: expected a number of seconds in (0, 86400]"),
    ('[person]\nkind = "line"\n[params.lqr]\nq = [0, 0, 0, 0, 0]\n',
     "bad.toml: params.lqr.q: no stabilising LQR gain for the slot with q = (0.0, 0.0, 0.0, "
     "0.0, 0.0)"),
])
def test_bad_scenario_file(tmp_path, capsys, text, message):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    code, _, err = run(["run", str(f), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert message in err
    assert "bad.toml" in err or "missing.csv" in message  # names the file that is wrong
    assert err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_custom_scenario_segments(tmp_path, capsys):
    f = tmp_path / "walk.toml"
    f.write_text('name = "walk"\nduration = 10\n[person]\nkind = "segments"\nstart = [0, 0, 0]\n'
                 '[[person.segments]]\nduration = 5\nv_start = 0.5\nv_end = 1.0\n'
                 '[[person.segments]]\nduration = 5\nv_start = 1.0\nv_end = 1.0\ncurvature = 0.2\n'
                 '[robot]\nstart = [-1, -1, 0]\n[params.formation]\nbearing = "auto"\n')
    code, out, _ = run(["run", str(f), "--out", str(tmp_path / "o")], capsys)
    assert code == 0
    with open(tmp_path / "o" / "log.csv") as fh:
        first = next(csv.DictReader(fh))
    assert float(first["alpha_d"]) == pytest.approx(1.5 * math.pi)  # started on the right


def test_params_file_override(tmp_path, capsys):
    f = tmp_path / "p.toml"
    f.write_text("[formation]\ndistance = 2.0\n")
    code, _, _ = run(["run", "line", "--params", str(f), "--duration", "1",
                      "--out", str(tmp_path / "o")], capsys)
    assert code == 0
    with open(tmp_path / "o" / "log.csv") as fh:
        assert float(next(csv.DictReader(fh))["rho_d"]) == 2.0
    f.write_text("[formation]\ndistanc = 2.0\n")
    code, _, err = run(["run", "line", "--params", str(f), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "p.toml: formation.distanc: unknown key; did you mean 'distance'" in err


def test_readme_test_command_is_what_ci_runs():
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    readme = (root / "README.md").read_text()
    ci = (root / ".ci" / "run").read_text()
    test_cmd = [line for line in readme.splitlines()
                if "pytest" in line and line.startswith("python3")]
    assert len(test_cmd) == 1
    assert test_cmd[0] in ci.splitlines()


def test_convergence_command_is_the_convergence_suite(tmp_path, capsys):
    code, out, _ = run(["convergence", "--speeds", "1.0", "--out", str(tmp_path)], capsys)
    assert code == 0
    assert "24/24 runs meet settling_time_s <= 20 and min_person_distance_m >= 0.5" in out
    with open(tmp_path / "episodes.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 24 and {r["group"] for r in rows} == {"fig3-1mps"}
    assert max(float(r["settling_time_s"]) for r in rows) <= 20.0
    assert min(float(r["min_person_distance_m"]) for r in rows) >= 0.5
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["failed"] == [] and len(summary["criteria"]) == 2
    # a limit no run meets: every episode fails the criteria, exit 1, each one named
    code, out, _ = run(["convergence", "--speeds", "1.0", "--settle-limit", "0.5",
                        "--out", str(tmp_path / "tight")], capsys)
    assert code == 1 and "0/24 runs meet settling_time_s <= 0.5" in out
    assert out.count("FAIL: settling_time_s <= 0.5") == 24


def test_bench_json_has_the_documented_keys(tmp_path, capsys):
    out = tmp_path / "bench.json"
    code, text, _ = run(["bench", "--json", "--episodes", "3", "--duration", "1",
                         "--workers", "2", "--no-first-step", "--out", str(out)], capsys)
    assert code == 0
    result = json.loads(text)
    assert json.loads(out.read_text()) == result
    assert set(result["step_us"]) == {"lqr", "lqr-paper", "lqr-tuned", "pid", "vsm", "ic",
                                      "lqr with scipy"}
    for name, figures in result["step_us"].items():
        wheres = ("alone", "stack", "stack_realistic") if name != "lqr with scipy" else ("alone",)
        for where in wheres:
            assert 0.0 < figures[where]["median"] <= figures[where]["p99"]
    dare = result["dare_us"]
    assert 0.0 < dare["median"] <= dare["p99"]
    assert result["stack_per_dare"]["lqr"]["stack_realistic"] == pytest.approx(
        result["step_us"]["lqr"]["stack_realistic"]["median"] / dare["median"])
    # scipy's Riccati solver is much slower than the compiled one, even on a busy machine
    assert (result["step_us"]["lqr with scipy"]["alone"]["median"]
            > 5.0 * result["step_us"]["lqr"]["alone"]["median"])
    tp = result["throughput"]
    assert tp["episodes"] == 3 and tp["workers"] == 2
    assert tp["steps_per_s_one_worker"] > 0.0 and tp["steps_per_s_all_workers"] > 0.0
    assert result["peak_rss_mb"] > 10.0 and result["episode_steps"] == 20


@pytest.mark.parametrize("argv, message", [
    (["bench", "--episodes", "0"], "--episodes: expected 1 <= N <= 1e+06, got '0'"),
    (["bench", "--workers", "0"], "--workers: expected 1 <= N <= 256, got '0'"),
    (["bench", "--duration", "-1"], "--duration: expected 0 < S <= 86400 s, got '-1'"),
])
def test_bench_bad_usage(argv, message, capsys):
    code, _, err = run(argv, capsys)
    assert code == 2 and message in err and err.count("\n") == 1


def test_bench_out_that_is_a_folder_is_refused_before_the_run(tmp_path, capsys):
    """The JSON file's name is checked first (an IsADirectoryError after the whole run
    before)."""
    folder = tmp_path / "bench.json"
    folder.mkdir()
    code, out, err = run(["bench", "--out", str(folder)], capsys)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert f"--out {folder}: is a folder, expected a file name" in err


def test_person_csv_of_samples_nanoseconds_apart_is_one_line(tmp_path, capsys):
    path = tmp_path / "ns.csv"
    path.write_text("t,x,y\n" + "".join(f"{k * 1e-9:.10f},{0.01 * k},0\n" for k in range(50)))
    code, _, err = run(["run", "line", "--person-csv", str(path), "--out", str(tmp_path / "o")],
                       capsys)
    assert code == 2 and err.count("\n") == 1 and f"{path}: the samples span" in err


def test_a_reader_that_goes_away_ends_the_command_quietly_with_every_file_written(tmp_path):
    """``companion run ... | true``: no BrokenPipeError traceback, exit 0, outputs complete."""
    import subprocess
    import sys

    out = tmp_path / "run"
    cmd = (f"{sys.executable} -m companion.apps.cli run line --duration 1 --plot "
           f"--out {out} | true")
    done = subprocess.run(["bash", "-c", f"set -o pipefail; {cmd}"], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0 and done.stderr == ""
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "errors.png", "inputs.png", "log.csv", "metrics.json", "trajectory.png"]


def test_run_with_realistic_sensing_logs_the_estimate(tmp_path, capsys):
    code, out, _ = run(["run", "line", "--duration", "4", "--sensing", "realistic", "--out",
                        str(tmp_path)], capsys)
    assert code == 0
    header = (tmp_path / "log.csv").read_text().splitlines()[0].split(",")
    for name in ("person_est_x", "person_est_y", "person_est_theta", "person_est_v",
                 "person_est_omega", "person_est_std", "robot_v", "robot_omega"):
        assert name in header
    assert "realistic" in out


def test_scenario_sensing_table_is_used_and_the_flag_overrides_it(tmp_path, capsys):
    f = tmp_path / "s.toml"
    f.write_text('duration = 3.0\n[sensing]\nperson_rate_hz = 5.0\nperson_dropout = 0.0\n'
                 '[person]\nkind = "line"\n')
    assert run(["run", str(f), "--out", str(tmp_path / "a")], capsys)[0] == 0
    assert run(["run", str(f), "--sensing", "ideal", "--out", str(tmp_path / "b")],
               capsys)[0] == 0
    a = (tmp_path / "a" / "log.csv").read_text().splitlines()
    b = (tmp_path / "b" / "log.csv").read_text().splitlines()
    std = a[0].split(",").index("person_est_std")
    assert float(a[-1].split(",")[std]) > 0.0       # 5 Hz noisy detections: uncertain
    assert float(b[-1].split(",")[std]) == 0.0      # ideal: exact


@pytest.mark.parametrize("argv, message", [
    (["runn"], "companion: error: argument command: invalid choice: 'runn' (choose from"),
    (["runn"], "; did you mean 'run'? (see --help)"),
    (["run", "line", "--controler", "lqr"], "unrecognized arguments: --controler lqr; did you "
                                             "mean '--controller'?"),
    (["run", "line", "--controller", "lqr-papr"], "error: run: argument --controller: invalid "
                                                   "choice"),
    (["run", "line", "--controller", "lqr-papr"], "did you mean 'lqr-paper'?"),
    (["run", "line", "--sensing", "realstic"], "did you mean 'realistic'?"),
    (["run", "line", "--side", "lef"], "did you mean 'left'?"),
    (["evaluate", "smok"], "smok: no such suite file or shipped suite; did you mean 'smoke'?"),
    (["tune", "lqr", "--suite", "smok"], "did you mean 'smoke'?"),
    (["fuzz", "--contrllers", "lqr"], "did you mean '--controllers'?"),
])
def test_misspelt_commands_flags_and_choices_get_a_suggestion(argv, message, capsys):
    code, out, err = run(argv, capsys)
    assert code == 2 and message in err and err.count("\n") == 1
    assert err.count("companion:") == 1


def test_version_is_the_package_version(capsys):
    from importlib.metadata import version

    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"companion {version('companion')}"


def test_cli_choices_are_the_registries():
    from companion.apps import cli, flags
    from companion.control import CONTROLLERS
    from companion.evaluate.tuning import SPACES
    from companion.params import PLANTS, SIDES

    assert flags.PLANTS == PLANTS
    assert cli.CONTROLLERS == tuple(sorted(CONTROLLERS))
    assert cli.TUNABLE == tuple(sorted(SPACES))
    assert cli.SIDES == tuple(sorted(SIDES))


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["run", "line", "--bogus"]])
def test_help_and_usage_errors_load_no_numerics(argv):
    """--help and usage errors answer without importing numpy, numba, scipy or matplotlib
    (they would take a second and hundreds of MB)."""
    import subprocess
    import sys

    code = (f"import sys\nfrom companion.apps.cli import main\ntry:\n    main({argv!r})\n"
            "except SystemExit:\n    pass\n"
            "print(sorted(m for m in ('numpy', 'numba', 'scipy', 'matplotlib') "
            "if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.stdout.strip().splitlines()[-1] == "[]", done.stdout + done.stderr
