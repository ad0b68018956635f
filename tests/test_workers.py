"""Worker processes die with their parent: a SIGKILLed ``companion evaluate --workers 2``
leaves no worker running (prctl's parent-death signal on Linux, else a thread that watches
the parent)."""

import os
import signal
import subprocess
import sys
import time

import pytest

SUITE = """
name = "tiny"
controllers = ["lqr", "pid"]
sensing = ["realistic"]
sides = ["left", "right"]
seeds = 2
duration = 60.0
[motions]
scenarios = ["line"]
"""


def _children(pid):
    """{pid: start time} of the live (not zombie) processes whose parent is ``pid``."""
    out = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    fields = fh.read().rsplit(")", 1)[1].split()
            except OSError:                        # gone meanwhile
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                out[int(entry)] = fields[19]
    return out


def _alive(pid, start):
    try:
        with open(f"/proc/{pid}/stat") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
    except OSError:
        return False
    return fields[0] != "Z" and fields[19] == start     # not a zombie, nor a new process


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_worker_processes_die_with_a_killed_evaluate(tmp_path):
    """SIGKILL an ``evaluate --workers 2``: its two workers are gone within 5 s."""
    path = tmp_path / "s.toml"
    path.write_text(SUITE)
    proc = subprocess.Popen([sys.executable, "-m", "companion.apps.cli", "evaluate", str(path),
                             "--workers", "2", "--out", str(tmp_path / "out")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers: dict = {}
    try:
        end = time.monotonic() + 120.0
        while len(workers) < 2 and proc.poll() is None and time.monotonic() < end:
            time.sleep(0.1)
            workers = _children(proc.pid)
        assert len(workers) >= 2, "the workers never started"
        proc.kill()
        proc.wait(timeout=10)
        end = time.monotonic() + 5.0
        while any(_alive(*w) for w in workers.items()) and time.monotonic() < end:
            time.sleep(0.1)
        assert not [pid for pid, start in workers.items() if _alive(pid, start)]
    finally:
        _reap(proc, workers)


_ORPHAN = """
import os, sys, time
from companion.sim import runner
runner.PARENT_POLL = 0.05
parent = os.getpid()
child = os.fork()
if child == 0:
    sys.platform = "elsewhere"               # no prctl: the thread that watches the parent
    runner.die_with_parent(parent)
    time.sleep(60)
    os._exit(0)
print(child, flush=True)
time.sleep(60)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_without_prctl_a_worker_still_dies_with_its_parent():
    proc = subprocess.Popen([sys.executable, "-c", _ORPHAN], stdout=subprocess.PIPE)
    child: dict = {}
    try:
        pid = int(proc.stdout.readline())
        child = {pid: _children(proc.pid)[pid]}
        time.sleep(0.2)
        assert _alive(pid, child[pid])            # alive while its parent is
        proc.kill()
        proc.wait(timeout=10)
        end = time.monotonic() + 2.0
        while _alive(pid, child[pid]) and time.monotonic() < end:
            time.sleep(0.05)
        assert not _alive(pid, child[pid])
    finally:
        _reap(proc, child)


def _reap(proc: subprocess.Popen, children: dict[int, float]) -> None:
    """Stop the test's process and any child of it still alive (the test cleans up after
    itself whether it passed or not)."""
    proc.kill()
    proc.wait(timeout=10)
    for pid, start in children.items():
        if _alive(pid, start):
            os.kill(pid, signal.SIGKILL)
