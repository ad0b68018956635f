"""Outputs are all or nothing per run: a failed, interrupted or killed run leaves the folder as
it was; a new run replaces the previous run's files; files follow the umask."""

import json
import os
import signal
import stat
import subprocess
import sys
import time

import pytest

from companion.apps import commands
from companion.apps.cli import main
from companion.io import STAGING, Outputs, write_text

VISIBLE = ("errors.png", "inputs.png", "log.csv", "metrics.json", "trajectory.png")


def listing(folder):
    return sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))


def snapshot(folder):
    return {p.name: p.read_bytes() for p in folder.iterdir()}


def test_a_new_run_replaces_every_file_of_the_previous_run(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")           # not a run's output: kept
    assert main(["run", "line", "--duration", "1", "--plot", "--out", str(tmp_path)]) == 0
    assert listing(tmp_path) == sorted((*VISIBLE, "notes.txt"))
    assert main(["run", "line", "--duration", "1", "--out", str(tmp_path)]) == 0
    assert listing(tmp_path) == ["log.csv", "metrics.json", "notes.txt"]   # no stale figures
    assert json.loads((tmp_path / ".run.outputs").read_text()) == ["log.csv", "metrics.json"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith((STAGING, ".log"))]


def test_a_run_that_fails_while_writing_leaves_the_earlier_run(tmp_path, monkeypatch):
    assert main(["run", "line", "--duration", "1", "--plot", "--out", str(tmp_path)]) == 0
    before = snapshot(tmp_path)

    def broken(path, data):
        raise OSError("disk full")

    monkeypatch.setattr(commands, "write_json", broken)
    with pytest.raises(OSError, match="disk full"):
        main(["run", "circle", "--duration", "2", "--out", str(tmp_path)])
    assert snapshot(tmp_path) == before


def test_outputs_follow_the_umask(tmp_path):
    with Outputs(tmp_path, "x") as stage:
        write_text(stage / "a.txt", "a")
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o666 & ~mask


def test_staging_left_by_a_dead_process_is_removed(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    stale = tmp_path / f"{STAGING}run-{dead.stdout.strip()}"
    stale.mkdir()
    (stale / "log.csv").write_text("half")
    (tmp_path / ".log.csv.abc.tmp").write_text("half")
    with Outputs(tmp_path, "run") as stage:
        write_text(stage / "log.csv", "whole")
    assert sorted(p.name for p in tmp_path.iterdir()) == [".run.outputs", "log.csv"]


def _start(out, duration="600"):
    return subprocess.Popen([sys.executable, "-m", "companion.apps.cli", "run", "line",
                             "--duration", duration, "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def _wait_until_running(proc, timeout=60.0):
    """Until the command has installed its SIGTERM handler (Linux: /proc's caught-signal
    mask), i.e. it has parsed its arguments and is working."""
    end = time.monotonic() + timeout
    while proc.poll() is None:
        with open(f"/proc/{proc.pid}/status") as fh:
            caught = next(int(line.split()[1], 16) for line in fh if line.startswith("SigCgt"))
        if caught >> (signal.SIGTERM - 1) & 1:
            time.sleep(0.5)               # well into the simulation
            return
        assert time.monotonic() < end, "the run never started"
        time.sleep(0.05)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_an_interrupted_run_leaves_the_folder_as_it_was(tmp_path, sig):
    assert main(["run", "line", "--duration", "1", "--out", str(tmp_path)]) == 0
    before = snapshot(tmp_path)
    proc = _start(tmp_path)
    try:
        _wait_until_running(proc)
        proc.send_signal(sig)
        code = proc.wait(timeout=60)
    finally:
        proc.kill()
    # 128 + signal from our handler; -signal if it arrives while numba first compiles (LLVM
    # then handles SIGINT by dying of it): both mean "interrupted", and nothing is written
    assert code in (128 + sig, -sig), proc.stderr.read()
    assert snapshot(tmp_path) == before
    assert not list(tmp_path.glob(f"{STAGING}*"))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_killed_run_leaves_the_folder_as_it_was_and_the_next_run_cleans_up(tmp_path):
    assert main(["run", "line", "--duration", "1", "--out", str(tmp_path)]) == 0
    before = snapshot(tmp_path)
    proc = _start(tmp_path)
    try:
        _wait_until_running(proc)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        proc.kill()
    assert {k: v for k, v in snapshot(tmp_path).items() if not k.startswith(STAGING)} == before
    assert main(["run", "line", "--duration", "1", "--out", str(tmp_path)]) == 0
    assert not list(tmp_path.glob(f"{STAGING}*"))
