"""Outputs are all or nothing per run: a failed, interrupted or killed run leaves the folder as
it was; a new run replaces the previous run's files in one rename, so a kill at any moment of
the switch leaves one whole set; files follow the umask."""

import multiprocessing
import os
import shutil
import signal
import stat
import subprocess
import sys
import time

import pytest

from companion.apps import commands
from companion.apps.cli import main
from companion.io import Outputs, write_text

VISIBLE = ("errors.png", "inputs.png", "log.csv", "metrics.json", "trajectory.png")


def listing(folder):
    return sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))


def snapshot(folder):
    """What a reader sees: every visible name and its bytes (through the links)."""
    return {p.name: p.read_bytes() for p in folder.iterdir()
            if not p.name.startswith(".") and p.exists()}


def hidden(folder):
    """The hidden entries: the current link and its generation, nothing else when clean."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def clean(folder, command="run"):
    names = hidden(folder)
    generation = os.readlink(folder / f".{command}@current")
    return names == sorted([f".{command}@current", generation])


def test_a_new_run_replaces_every_file_of_the_previous_run(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")           # not a run's output: kept
    assert main(["run", "line", "--duration", "1", "--plot", "--out", str(tmp_path)]) == 0
    assert listing(tmp_path) == sorted((*VISIBLE, "notes.txt"))
    assert main(["run", "line", "--duration", "1", "--out", str(tmp_path)]) == 0
    assert listing(tmp_path) == ["log.csv", "metrics.json", "notes.txt"]   # no stale figures
    assert os.readlink(tmp_path / "log.csv") == ".run@current/log.csv"
    assert clean(tmp_path) and (tmp_path / "notes.txt").read_text() == "mine"


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


def test_what_a_dead_process_left_is_removed(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    stale = tmp_path / f".run@{dead.stdout.strip()}-1"
    stale.mkdir()
    (stale / "log.csv").write_text("half")
    (tmp_path / ".log.csv.abc.tmp").write_text("half")
    (tmp_path / "old.png").symlink_to(".run@current/old.png")    # dangling: not in current
    with Outputs(tmp_path, "run") as stage:
        write_text(stage / "log.csv", "whole")
    assert listing(tmp_path) == ["log.csv"] and clean(tmp_path)
    assert (tmp_path / "log.csv").read_text() == "whole"


def test_outputs_of_an_earlier_version_are_replaced(tmp_path):
    """Plain files listed in the manifest of earlier versions give way to the new set."""
    (tmp_path / ".run.outputs").write_text('["log.csv", "old.png"]\n')
    (tmp_path / "log.csv").write_text("old")
    (tmp_path / "old.png").write_text("old")
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "metadata.yaml").write_text("old")
    with Outputs(tmp_path, "run") as stage:
        write_text(stage / "log.csv", "new")
        (stage / "bag").mkdir()
        write_text(stage / "bag" / "metadata.yaml", "new")
    assert listing(tmp_path) == ["bag", "log.csv"] and clean(tmp_path)
    assert (tmp_path / "bag" / "metadata.yaml").read_text() == "new"


def _switch_killed_at(folder, k):
    """In a child process: write a second run's outputs and SIGKILL itself at the k-th step
    of the switch that changes the file system (link, rename, unlink, removal)."""
    calls = [0]

    def counted(fn):
        def step(*args, **kwargs):
            calls[0] += 1
            if calls[0] == k:
                os.kill(os.getpid(), signal.SIGKILL)
            return fn(*args, **kwargs)
        return step

    for module, name in ((os, "symlink"), (os, "replace"), (os, "unlink"), (shutil, "rmtree")):
        setattr(module, name, counted(getattr(module, name)))
    with Outputs(folder, "run") as stage:
        for name in ("log.csv", "metrics.json", "new.png"):
            (stage / name).write_text("run 2")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork")
def test_a_kill_at_any_step_of_the_switch_leaves_one_whole_set(tmp_path):
    """The previous run wrote log.csv, metrics.json, old.png; the next one writes log.csv,
    metrics.json, new.png and is killed at each step of the switch in turn: a reader always
    sees one run's whole set (the previous version moved the files one by one, so a kill
    could leave the new log.csv beside the old metrics.json), and the next run cleans up."""
    first = {"log.csv": b"run 1", "metrics.json": b"run 1", "old.png": b"run 1"}
    second = {"log.csv": b"run 2", "metrics.json": b"run 2", "new.png": b"run 2"}
    fork = multiprocessing.get_context("fork")
    seen = set()
    for k in range(1, 30):
        folder = tmp_path / f"k{k}"
        with Outputs(folder, "run") as stage:
            for name, data in first.items():
                (stage / name).write_bytes(data)
        child = fork.Process(target=_switch_killed_at, args=(folder, k))
        child.start()
        child.join(60)
        state = snapshot(folder)
        assert state in (first, second), (k, state)
        seen.add(state == second)
        with Outputs(folder, "run") as stage:              # the next run
            (stage / "log.csv").write_text("run 3")
        assert listing(folder) == ["log.csv"] and clean(folder), (k, hidden(folder))
        if child.exitcode == 0:
            break
    assert child.exitcode == 0 and seen == {False, True}   # every step was cut, both sets seen


def _start(out, duration="36000"):
    # SIGINT at its default in the child: a suite started in the background (a shell's
    # asynchronous job) hands its children SIGINT ignored, and Python keeps it so
    return subprocess.Popen([sys.executable, "-m", "companion.apps.cli", "run", "line",
                             "--duration", duration, "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


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
    assert snapshot(tmp_path) == before and clean(tmp_path)


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
    assert snapshot(tmp_path) == before
    assert main(["run", "line", "--duration", "1", "--out", str(tmp_path)]) == 0
    assert clean(tmp_path)
