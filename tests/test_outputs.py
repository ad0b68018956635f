"""Outputs are plain files, all or nothing per run: a failed, interrupted or killed run leaves
the folder as it was; a new run's folder is built beside the output folder and swapped in by
one rename (or two, recovered by the next run), so a kill at any moment of the switch leaves
one whole set; other files in the folder are kept; files follow the umask."""

import json
import multiprocessing
import os
import shutil
import signal
import stat
import subprocess
import sys
import time

import pytest

from companion import swap
from companion.apps import commands
from companion.apps.cli import main
from companion.io import Outputs, leftovers, write_text

VISIBLE = ("errors.png", "inputs.png", "log.csv", "metrics.json", "trajectory.png")


def listing(folder):
    return sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))


def snapshot(folder):
    """What a reader sees: every visible name and its bytes (None: no folder)."""
    if not folder.exists():
        return None
    return {p.name: p.read_bytes() for p in folder.iterdir() if not p.name.startswith(".")}


def hidden(folder):
    """The hidden entries inside and beside the folder: the manifests, nothing else when
    clean."""
    return sorted([p.name for p in folder.iterdir() if p.name.startswith(".")]
                  + [p.name for p in folder.parent.iterdir() if ".companion-" in p.name])


def clean(folder, commands=("run",)):
    """Only plain files and folders, the commands' manifests, and nothing beside."""
    plain = not any(p.is_symlink() for p in folder.rglob("*"))
    return plain and leftovers(folder) == [] \
        and hidden(folder) == sorted(f".{c}.outputs" for c in commands)


def test_a_new_run_replaces_every_file_of_the_previous_run(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")           # not a run's output: kept
    assert main(["run", "line", "--duration", "1", "--plot", "--out", str(tmp_path)]) == 0
    assert listing(tmp_path) == sorted((*VISIBLE, "notes.txt"))
    assert main(["run", "line", "--duration", "1", "--out", str(tmp_path)]) == 0
    assert listing(tmp_path) == ["log.csv", "metrics.json", "notes.txt"]   # no stale figures
    assert clean(tmp_path) and (tmp_path / "notes.txt").read_text() == "mine"
    assert json.loads((tmp_path / ".run.outputs").read_text()) == ["log.csv", "metrics.json"]


def test_other_commands_files_and_the_kept_episodes_survive_a_switch(tmp_path):
    """fuzz --replay writes beside a fuzz run's files, and evaluate's resumable store is not
    an output: both are carried into the new folder (as hard links, not copies)."""
    with Outputs(tmp_path, "fuzz") as stage:
        write_text(stage / "fuzz.csv", "fuzz")
    (tmp_path / ".evaluate.partial").mkdir()
    (tmp_path / ".evaluate.partial" / "episodes.jsonl").write_text("kept\n")
    (tmp_path / "mine.tmp").write_text("mine")                # a user's file, whatever its name
    inode = (tmp_path / "fuzz.csv").stat().st_ino
    with Outputs(tmp_path, "fuzz-replay") as stage:
        write_text(stage / "log.csv", "replay")
    assert listing(tmp_path) == ["fuzz.csv", "log.csv", "mine.tmp"]
    assert (tmp_path / "fuzz.csv").stat().st_ino == inode
    assert (tmp_path / ".evaluate.partial" / "episodes.jsonl").read_text() == "kept\n"
    with Outputs(tmp_path, "fuzz") as stage:                # replaces its own files only
        write_text(stage / "fuzz.json", "fuzz 2")
    assert listing(tmp_path) == ["fuzz.json", "log.csv", "mine.tmp"]


def test_the_folder_keeps_its_mode_and_a_link_to_it_keeps_pointing_at_it(tmp_path):
    real = tmp_path / "real"
    real.mkdir(mode=0o750)
    os.chmod(real, 0o750)
    (tmp_path / "out").symlink_to("real")
    with Outputs(tmp_path / "out", "run") as stage:
        write_text(stage / "log.csv", "new")
    assert (tmp_path / "out").is_symlink() and (tmp_path / "real" / "log.csv").exists()
    assert stat.S_IMODE(real.stat().st_mode) == 0o750


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
    pid = dead.stdout.strip()
    folder = tmp_path / "o"
    folder.mkdir()
    for kind in ("tmp", "new", "old"):        # beside: a write, a complete set, a set aside
        stale = tmp_path / f".o.companion-{pid}-1.{kind}"
        stale.mkdir()
        (stale / "log.csv").write_text("half")
    stale = folder / f".run@{pid}-1"            # inside: the layout of the previous version
    stale.mkdir()
    (stale / "log.csv").write_text("half")
    (folder / ".log.csv.abc.tmp").write_text("half")
    (folder / "old.png").symlink_to(".run@current/old.png")    # dangling: not in current
    with Outputs(folder, "run") as stage:
        assert leftovers(folder) == sorted([f".run@{pid}-1", ".log.csv.abc.tmp",
                                            stage.name])
        write_text(stage / "log.csv", "whole")
    assert listing(folder) == ["log.csv"] and clean(folder)
    assert (folder / "log.csv").read_text() == "whole"


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


def test_the_links_of_the_previous_version_become_plain_files(tmp_path):
    """Each name was a link through .<command>@current into a hidden generation: the first
    switch leaves plain files, other commands' included (with their manifest)."""
    for command, names in (("run", ["log.csv", "old.png"]), ("fuzz", ["fuzz.csv"])):
        generation = tmp_path / f".{command}@123-1"
        generation.mkdir()
        (tmp_path / f".{command}@current").symlink_to(generation.name)
        for name in names:
            (generation / name).write_text(f"{command} 1")
            (tmp_path / name).symlink_to(f".{command}@current/{name}")
    with Outputs(tmp_path, "run") as stage:
        write_text(stage / "log.csv", "run 2")
    assert snapshot(tmp_path) == {"fuzz.csv": b"fuzz 1", "log.csv": b"run 2"}
    assert clean(tmp_path, ("fuzz", "run"))
    with Outputs(tmp_path, "fuzz") as stage:
        write_text(stage / "fuzz.json", "fuzz 2")
    assert snapshot(tmp_path) == {"fuzz.json": b"fuzz 2", "log.csv": b"run 2"}


def test_a_folder_that_holds_the_current_one_is_refused(tmp_path, monkeypatch):
    """Replacing it would leave the shell in a removed folder: an error before any work."""
    monkeypatch.chdir(tmp_path)
    code = main(["run", "line", "--duration", "1", "--out", "."])
    assert code == 2 and list(tmp_path.iterdir()) == []


STEPS = ((os, "link"), (os, "replace"), (os, "unlink"), (os, "mkdir"), (shutil, "rmtree"),
         (shutil, "copytree"), (swap, "exchange"))


def _switch_killed_at(folder, k, two_renames=False):
    """In a child process: write a second run's outputs and SIGKILL itself at the k-th step
    of the switch that changes the file system (link, rename, exchange, unlink, removal)."""
    calls = [0]

    def counted(fn):
        def step(*args, **kwargs):
            calls[0] += 1
            if calls[0] == k:
                os.kill(os.getpid(), signal.SIGKILL)
            return fn(*args, **kwargs)
        return step

    if two_renames:                            # a system without RENAME_EXCHANGE
        swap.exchange = lambda a, b: False
    for module, name in STEPS:
        setattr(module, name, counted(getattr(module, name)))
    with Outputs(folder, "run") as stage:
        for name in ("log.csv", "metrics.json", "new.png"):
            (stage / name).write_text("run 2")


NOTES = {"notes.txt": b"mine"}              # another command's file: carried over


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork")
@pytest.mark.parametrize("two_renames", [False, True])
def test_a_kill_at_any_step_of_the_switch_leaves_one_whole_set(tmp_path, two_renames):
    """The previous run wrote log.csv, metrics.json, old.png beside notes.txt; the next one
    writes log.csv, metrics.json, new.png and is killed at each step of the switch in turn: a
    reader always sees one run's whole set (with notes.txt), or, between the two renames of a
    system without an exchange, no folder for a moment, and the next run finishes the switch
    and cleans up."""
    first = {"log.csv": b"run 1", "metrics.json": b"run 1", "old.png": b"run 1", **NOTES}
    second = {"log.csv": b"run 2", "metrics.json": b"run 2", "new.png": b"run 2", **NOTES}
    fork = multiprocessing.get_context("fork")
    seen = []
    for k in range(1, 60):
        folder = tmp_path / f"k{k}"
        with Outputs(folder, "run") as stage:
            for name, data in first.items():
                (stage / name).write_bytes(data)
        (folder / ".run.outputs").write_text('["log.csv", "metrics.json", "old.png"]')
        child = fork.Process(target=_switch_killed_at, args=(folder, k, two_renames))
        child.start()
        child.join(60)
        state = snapshot(folder)
        assert state in (first, second, None if two_renames else first), (k, state)
        seen.append(state)
        with Outputs(folder, "run") as stage:              # the next run
            assert snapshot(folder) in (first, second), (k, "not recovered")
            (stage / "log.csv").write_text("run 3")
        assert snapshot(folder) == {"log.csv": b"run 3", **NOTES}, k
        assert clean(folder), (k, hidden(folder))
        if child.exitcode == 0:
            break
    assert child.exitcode == 0                             # every step was cut
    assert first in seen and second in seen and (None in seen) == two_renames


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork")
def test_a_kill_between_the_two_renames_is_finished_by_the_next_run(tmp_path):
    """Where the folders cannot be exchanged in one step, the old folder is renamed aside,
    then the complete new one into place: killed in between, the next run puts the new set
    in place before anything else."""
    folder = tmp_path / "o"
    with Outputs(folder, "run") as stage:
        (stage / "log.csv").write_text("run 1")
    fork = multiprocessing.get_context("fork")
    child = fork.Process(target=_killed_between_the_renames, args=(folder,))
    child.start()
    child.join(60)
    assert child.exitcode == -signal.SIGKILL and not folder.exists()
    assert len(leftovers(folder)) == 2                   # the new set and the old one
    with Outputs(folder, "run") as stage:
        assert snapshot(folder) == {"log.csv": b"run 2"}
        (stage / "log.csv").write_text("run 3")
    assert snapshot(folder) == {"log.csv": b"run 3"} and clean(folder)


def _killed_between_the_renames(folder):
    replace = os.replace

    def step(src, dst):
        if str(src).endswith(".new") and not os.path.exists(dst):
            os.kill(os.getpid(), signal.SIGKILL)
        replace(src, dst)

    swap.exchange = lambda a, b: False
    os.replace = step
    with Outputs(folder, "run") as stage:
        (stage / "log.csv").write_text("run 2")


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
