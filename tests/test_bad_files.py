"""Bad files through the command line: exit code 2, one line naming the file and the line or
key, and nothing written; output files are written whole or not at all."""

import pytest

from companion import io
from companion.apps.cli import main

GOOD_CSV = ["t,x,y", "0.0,0,0", "0.4,0.4,0", "0.8,0.8,0", "1.2,1.2,0", "1.6,1.6,0",
            "2.0,2.0,0"]


def run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize("row, where, words", [
    ("1.0,abc,0", "walk.csv:5:", ["column 'x'", "expected a number", "'abc'"]),
    ("1.0,nan,0", "walk.csv:5:", ["column 'x'", "finite"]),
    ("1.0,1,inf", "walk.csv:5:", ["column 'y'", "finite"]),
    ("0.8,1,0", "walk.csv:5:", ["duplicate timestamp"]),
    ("0.5,1,0", "walk.csv:5:", ["unsorted timestamp"]),
])
def test_bad_person_csv(tmp_path, capsys, row, where, words):
    f = tmp_path / "walk.csv"
    f.write_text("\n".join(GOOD_CSV[:4] + [row] + GOOD_CSV[4:]) + "\n")
    code, _, err = run(["run", "line", "--person-csv", str(f), "--out", str(tmp_path / "o")],
                       capsys)
    assert code == 2 and err.count("\n") == 1
    assert where in err and all(w in err for w in words)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("text, words", [
    ("[lqr\nq = 1\n", ["p.toml", "invalid TOML", "line 1"]),
    ("[lqr]\nqq = [1, 2, 3, 4, 5]\n", ["p.toml: lqr.qq: unknown key", "did you mean 'q'"]),
    ("[supervisor]\ndecel = 2.0\n", ["p.toml: supervisor.decel: unknown key",
                                      "did you mean 'decel_max'"]),
    ("[safety]\nperson_clearance = 0.7\n", ["p.toml: safety: moved to keepout"]),
    ("[supervisor]\nprotective_distance = 0.4\n",
     ["p.toml: supervisor.protective_distance: moved to keepout.protective_distance"]),
    ('dt = "fast"\n', ["p.toml: dt: expected a number", "'fast'"]),
    ("[tracker]\nlost_after_s = -0.5\n", ["p.toml: tracker.lost_after_s",
                                           "expected a finite positive number"]),
    ("[supervisor]\nperson_timeout = 0.5\n",
     ["p.toml: supervisor.person_timeout: moved to tracker.lost_after_s"]),
    ("[sensing]\nperson_rate = 10\n", ["p.toml: sensing.person_rate", "person_rate_hz"]),
    ("[sensing]\nperson_dropout = 1.0\n", ["p.toml: sensing.person_dropout",
                                            "a probability in [0, 1)"]),
    ("[lidar]\nrate = 10\n", ["p.toml: lidar.rate: moved to sensing.lidar_rate_hz"]),
    ("[supervisor]\nmin_valid_returns = 1.5\n", ["p.toml: supervisor.min_valid_returns",
                                                  "fraction in [0, 1]"]),
    ("[robot]\nv_max = nan\n", ["p.toml: robot.v_max: expected a number, got nan"]),
    ("[lqr]\nq = [1, 2, 3, 4, true]\n", ["p.toml: lqr.q[4]: expected a number"]),
    ("[lqr]\nq = [0, 0, 0, 0, 0]\n", ["p.toml: ", "lqr.q: no stabilising LQR gain"]),
    ("[lqr]\nq = [1e300, 1, 1, 1, 1]\n", ["p.toml: lqr.q[0]: expected a finite number of "
                                          "magnitude at most 1e+06"]),
    ("[formation]\ndistance = inf\n", ["p.toml: formation.distance: expected a finite number"]),
    ("[robot]\ncommand_timeout_s = inf\n[robot.bogus]\n", ["p.toml: robot.bogus: unknown key"]),
])
@pytest.mark.parametrize("command", [["run", "line"], ["soak", "--duration", "1"]])
def test_bad_params_file(tmp_path, capsys, text, words, command):
    f = tmp_path / "p.toml"
    f.write_text(text)
    code, _, err = run(command + ["--params", str(f), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert all(w in err for w in words), err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("faults, words", [
    ('[[faults]]\nkind = "stal"\nstart = 1\nend = 2\n',
     ["s.toml: faults[0].kind: expected one of", "did you mean 'stall'"]),
    ('[[faults]]\nkind = "stall"\nstart = 2\nend = 1\n',
     ["s.toml: faults[0].end: expected a time after start"]),
    ('[[faults]]\nkind = "stall"\nstart = 1\n', ["s.toml: faults[0].end: missing"]),
    ('[[faults]]\nkind = "person_jump"\nstart = 1\nend = 2\ndz = 1\n',
     ["s.toml: faults[0].dz: unknown key"]),
    ('faults = 3\n', ["s.toml: faults: expected an array of tables"]),
])
def test_bad_faults_in_a_scenario(tmp_path, capsys, faults, words):
    f = tmp_path / "s.toml"
    head, rest = faults.split("[[faults]]", 1) if "[[faults]]" in faults else (faults, None)
    body = head + '[person]\nkind = "line"\n' + ("" if rest is None else "[[faults]]" + rest)
    f.write_text(body)
    code, _, err = run(["run", str(f), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert all(w in err for w in words), err


def test_scenario_faults_run_and_show_in_the_log(tmp_path, capsys):
    f = tmp_path / "s.toml"
    f.write_text('duration = 16.0\n[person]\nkind = "line"\n'
                 '[[faults]]\nkind = "person_dropout"\nstart = 2.0\nend = 5.0\n')
    code, out, _ = run(["run", str(f), "--out", str(tmp_path / "o")], capsys)
    assert code == 0
    text = (tmp_path / "o" / "log.csv").read_text().splitlines()
    assert text[0].endswith(",status,reason")
    assert any(",stopped,person_lost" in line for line in text)
    assert any(",degraded,person_lost+search_approach" in line for line in text)  # then looks
    assert text[-1].endswith(",ok,")


def test_outputs_are_written_whole_or_not_at_all(tmp_path):
    target = tmp_path / "table.csv"
    target.write_text("old complete content\n")

    def half_then_fail(path):
        path.write_text("half a fi")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        io.atomic_write(target, half_then_fail)
    assert target.read_text() == "old complete content\n"   # untouched
    assert [p.name for p in tmp_path.iterdir()] == ["table.csv"]   # no temporary left
    io.write_csv(target, ("a", "b"), [(1.0, "x")])
    assert target.read_text() == "a,b\n1,x\n"


@pytest.mark.parametrize("flag, text, words", [
    ("fast", None, ["--sensing: expected ideal or realistic or em-tracker or a .toml file",
                    "'fast'"]),
    ("FILE", "person_rate_hz = 10\nperson_noise = 0.1\n",
     ["sens.toml: person_noise: unknown key", "did you mean", "person_position_noise_m"]),
    ("FILE", "person_latency_s = -0.1\n", ["sens.toml: person_latency_s", "expected"]),
    ("FILE", "person_rate_hz = \"ten\"\n", ["sens.toml: person_rate_hz: expected a number"]),
])
def test_bad_sensing_flag_or_file(tmp_path, capsys, flag, text, words):
    f = tmp_path / "sens.toml"
    if text is not None:
        f.write_text(text)
    code, _, err = run(["run", "line", "--sensing", str(f) if flag == "FILE" else flag,
                        "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert all(w in err for w in words), err
    assert not (tmp_path / "o").exists()


def test_bad_sensing_table_in_a_scenario_names_the_file_and_key(tmp_path, capsys):
    f = tmp_path / "s.toml"
    f.write_text('duration = 2.0\nsensing = "realistc"\n[person]\nkind = "line"\n')
    code, _, err = run(["run", str(f), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "s.toml: sensing" in err and "realistic" in err, err
    f.write_text('duration = 2.0\n[sensing]\nactuator_tau = 0.2\n[person]\nkind = "line"\n')
    code, _, err = run(["run", str(f), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "s.toml: sensing.actuator_tau: unknown key" in err, err
    assert not (tmp_path / "o").exists()
