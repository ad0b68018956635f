"""Long inputs cost what they should: ``companion run`` and ``companion soak`` stream log.csv
to disk block by block (equal to the log of a run in memory to the last digit), and a long
person CSV is read without a Python object per row (the row-by-row reader still names a bad
line: tests/test_bad_files.py)."""

import json
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from companion import metrics
from companion.apps import logfile, plots
from companion.apps.cli import main
from companion.io import leftovers
from companion.params import REALISTIC
from companion.sim import recorded
from companion.sim.episode import BLOCK_ROWS
from companion.sim.runner import run_one
from companion.sim.scenario import load_scenario
from companion.sim.soak import soak_episode
from companion.types import LOG_COLUMNS, TEXT_COLUMNS


def csv_text(log) -> str:
    """The log as CSV text, written independently of the package's writers."""
    lines = [",".join((*LOG_COLUMNS, *TEXT_COLUMNS))]
    for i in range(len(log)):
        lines.append(",".join([f"{float(log[c][i]):.10g}" for c in LOG_COLUMNS]
                              + [str(log[c][i]) for c in TEXT_COLUMNS]))
    return "\n".join(lines) + "\n"


@pytest.fixture
def blocks_written(monkeypatch):
    sizes = []
    write = logfile.LogCsv.log
    monkeypatch.setattr(logfile.LogCsv, "log",
                        lambda self, block: (sizes.append(len(block)), write(self, block)))
    return sizes


def test_run_streams_the_log_equal_to_the_log_in_memory(tmp_path, capsys, blocks_written):
    assert main(["run", "line", "--duration", "210", "--sensing", "realistic",
                 "--out", str(tmp_path)]) == 0
    n = 4200
    assert blocks_written == [BLOCK_ROWS] * (n // BLOCK_ROWS) + [n % BLOCK_ROWS]
    sc = load_scenario("line")
    log = run_one(replace(sc.episode(), duration=210.0,
                          params=sc.params.replace(sensing=REALISTIC)))
    assert len(set(log["status"])) > 1
    assert (tmp_path / "log.csv").read_text() == csv_text(log)
    got = json.loads((tmp_path / "metrics.json").read_text())
    expected = metrics.compute(log)
    for key, value in expected.items():
        if isinstance(value, float):
            assert got[key] == pytest.approx(value, rel=1e-12), key
        elif not isinstance(value, dict):
            assert got[key] == value, key
    assert leftovers(tmp_path) == []


def test_soak_streams_its_log(tmp_path, capsys, blocks_written):
    code = main(["soak", "--duration", "210", "--seed", "1", "--log", "--out", str(tmp_path)])
    assert code == 0
    assert blocks_written == [BLOCK_ROWS, 4200 - BLOCK_ROWS]
    log = run_one(soak_episode(210.0, seed=1))
    assert (tmp_path / "log.csv").read_text() == csv_text(log)
    assert json.loads((tmp_path / "soak.json").read_text())["steps"] == 4200


def test_plots_of_a_long_run_get_a_thinned_log(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(logfile, "PLOT_ROWS", 1000)
    seen = []
    errors_over_time = plots.errors_over_time
    monkeypatch.setattr(plots, "errors_over_time",
                        lambda runs, title="": (seen.append(len(next(iter(runs.values())))),
                                                errors_over_time(runs, title))[1])
    assert main(["run", "line", "--duration", "150", "--plot", "--out", str(tmp_path)]) == 0
    assert seen == [1000]                   # 3000 steps, every third row
    assert (tmp_path / "errors.png").stat().st_size > 10_000


def write_walk(path, n, rate=100.0):
    t = np.arange(n) / rate
    np.savetxt(path, np.column_stack([t + 3.0, 1.1 * t, 0.4 * np.sin(0.5 * t)]),
               fmt="%.9g", delimiter=",", header="t,x,y", comments="")
    return t + 3.0


def test_a_long_recording_is_read_without_the_row_by_row_reader(tmp_path, monkeypatch):
    t = write_walk(tmp_path / "walk.csv", 200_000)
    monkeypatch.setattr(recorded, "_parse_rows", None)     # would fail if called
    got_t, got_x, _ = recorded.read_person_csv(tmp_path / "walk.csv")
    assert isinstance(got_t, np.ndarray) and got_t.shape == (200_000,)
    assert np.array_equal(got_t, [float(f"{v:.9g}") for v in t])
    assert got_x[-1] == pytest.approx(1.1 * 1999.99, rel=1e-9)


@pytest.mark.parametrize("text", [
    "\ufeff t , x , y \r\n0,0,0\r\n\r\n 0.5 , 0.5,0\r\n1,1,0\r\n1.5,1.5,0\r\n2,2,0\r\n",
    "\n\nt,x,y\n0,0,0\n0.5,0.5,0\n1,1,0\n1.5,1.5,0\n2,2,0",
    't,x,y\n"0",0,0\n0.5,0.5,0\n   \n1,1,0\n1.5,1.5,0\n2,2e0,0\n',    # row by row: quotes
    "t,x,y\n0,0,0\n0.5,0.5,0\n1,1,0\n1.5,1_5e-1,0\n2,2,0\n",           # row by row: 1_5
])
def test_both_readers_agree_on_good_files(tmp_path, text):
    path = tmp_path / "walk.csv"
    path.write_bytes(text.encode("utf-8"))
    t, x, y = recorded.read_person_csv(path)
    assert np.array_equal(t, [0.0, 0.5, 1.0, 1.5, 2.0])
    assert x[:3].tolist() == [0.0, 0.5, 1.0] and not np.any(y)


def peak_memory(args: list[str]) -> int:
    """Peak resident memory (bytes) of ``python args`` run to success in a child process."""
    child = subprocess.Popen([sys.executable, *args], stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0
    return usage.ru_maxrss * 1024   # ru_maxrss is in KiB on Linux


@pytest.mark.slow
def test_peak_memory_of_a_run_does_not_grow_with_its_duration(tmp_path):
    """``companion run figure8`` for 1800 and 3600 s in child processes: the second would
    hold 36,000 more rows of its log if it kept it (about 30 MB: 8 MB of numbers, the rest
    text)."""
    peaks = [peak_memory(["-m", "companion.apps.cli", "run", "figure8", "--duration", duration,
                          "--out", str(tmp_path / duration)]) for duration in ("1800", "3600")]
    assert peaks[1] - peaks[0] < 10e6, peaks


PLOTS_OF_LAPS = """
import sys
import numpy as np
from companion.apps import plots
from companion.apps.logfile import PLOT_ROWS
from companion.io import save_figure
from companion.params import Params
from companion.types import LOG_COLUMNS, Log

laps, out = int(sys.argv[1]), sys.argv[2]
phase = np.linspace(0.0, 2.0 * np.pi * laps, PLOT_ROWS)
columns = {c: np.sin(phase + i) for i, c in enumerate(LOG_COLUMNS)}
columns.update(t=60.0 * phase / (2.0 * np.pi), person_x=4.0 * np.sin(phase),
               person_y=2.0 * np.sin(2.0 * phase), robot_x=4.5 * np.sin(phase),
               robot_y=2.5 * np.sin(2.0 * phase), status=np.full(PLOT_ROWS, "ok"),
               reason=np.full(PLOT_ROWS, ""))
runs = {"lqr": Log(columns)}
for name, fig in [("trajectory", plots.trajectories(runs)),
                  ("errors", plots.errors_over_time(runs)),
                  ("inputs", plots.inputs_over_time(runs, Params()))]:
    save_figure(fig, f"{out}-{name}.png")
    plots.close(fig)
"""


def test_memory_of_the_plots_does_not_grow_with_the_laps_they_draw(tmp_path):
    """The figures of ``companion run --plot`` from :data:`logfile.PLOT_ROWS` rows of one lap
    of a figure-8 and of 1,440 (a day-long run's thinned log), in child processes: with each
    line rasterized in one piece, the second took about 240 MB more."""
    peaks = [peak_memory(["-c", PLOTS_OF_LAPS, str(laps), str(tmp_path / str(laps))])
             for laps in (1, 1440)]
    assert peaks[1] - peaks[0] < 20e6, peaks
