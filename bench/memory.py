"""Peak memory against simulated duration, and loading a long recording (docs/performance.md).

    python bench/memory.py [--durations 600,3600,14400,86400] [--what run,soak,recording]
                           [--rows 1000000]

``run``: ``companion run figure8 --duration D --out DIR --plot`` (log.csv, metrics.json and
the plots); ``soak``: ``companion soak --duration D --log --out DIR``. Each command runs in
its own child process; its peak resident memory (``ru_maxrss`` from ``wait4``), wall time
and the size of the log it wrote are printed. ``recording``: a person CSV of ``--rows`` rows
(t, x, y at 1 kHz, a walk along a wavy line) is written to a temporary folder and loaded by
:func:`companion.sim.recorded.load_person_csv` in a child process, which reports the time of
reading the file alone, of the whole load (with smoothing) and its peak memory, beside the
peak memory of a child that only imports the same modules.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CLI = [sys.executable, "-c", "import sys; from companion.apps.cli import main; sys.exit(main())"]

LOADER = """
import json, resource, sys, time
from companion.sim import recorded
rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
if sys.argv[1] != "-":
    t, x, y = recorded.read_person_csv(sys.argv[1])
    t1 = time.perf_counter()
    person = recorded.load_person_csv(sys.argv[1])
    t2 = time.perf_counter()
    n = len(t)
else:
    t1 = t2 = t0
    n = 0
print(json.dumps({"rows": n, "read_s": t1 - t0, "load_s": t2 - t1,
                  "imports_rss_mb": rss0 / 1024,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def measured(cmd: list[str]) -> tuple[float, float, str]:
    """Run ``cmd`` in a child; returns (peak RSS in MB, wall time in s, its stdout)."""
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as out:
        child = subprocess.Popen(cmd, stdout=out, stderr=subprocess.DEVNULL)
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        out.seek(0)
        text = out.read().decode()
    if child.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(cmd)}: exit {child.returncode}\n{text}")
    return usage.ru_maxrss / 1024, wall, text


def bench_commands(what: str, durations: list[float]) -> None:
    print(f"\n{what}: duration_s  steps  peak_rss_MB  wall_s  log_MB")
    for d in durations:
        folder = Path(tempfile.mkdtemp(prefix="companion-mem-"))
        try:
            if what == "run":
                cmd = [*CLI, "run", "figure8", "--duration", f"{d:g}", "--out", str(folder),
                       "--plot"]
            else:
                cmd = [*CLI, "soak", "--duration", f"{d:g}", "--log", "--out", str(folder)]
            rss, wall, _ = measured(cmd)
            log = folder / "log.csv"
            size = log.stat().st_size / 1e6 if log.exists() else float("nan")
            print(f"{what}: {d:10g} {round(d / 0.05):6d} {rss:12.0f} {wall:7.1f} "
                  f"{size:7.0f}", flush=True)
        finally:
            shutil.rmtree(folder, ignore_errors=True)


def write_recording(path: Path, rows: int) -> None:
    t = np.arange(rows) * 1e-3
    x = 1.2 * t
    y = 0.5 * np.sin(0.3 * t)
    np.savetxt(path, np.column_stack([t, x, y]), fmt="%.6f", delimiter=",", header="t,x,y",
               comments="")


def bench_recording(rows: int) -> None:
    folder = Path(tempfile.mkdtemp(prefix="companion-rec-"))
    try:
        path = folder / "walk.csv"
        write_recording(path, rows)
        size = path.stat().st_size / 1e6
        _, _, base = measured([sys.executable, "-c", LOADER, "-"])
        rss, wall, text = measured([sys.executable, "-c", LOADER, str(path)])
        r = json.loads(text)
        b = json.loads(base)
        print(f"\nrecording: {r['rows']} rows ({size:.0f} MB), read {r['read_s']:.2f} s, "
              f"read and smoothed {r['load_s']:.2f} s, peak RSS {rss:.0f} MB "
              f"(a child that only imports: {b['peak_rss_mb']:.0f} MB), child wall {wall:.1f} s")
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--durations", default="600,3600,14400,86400")
    ap.add_argument("--what", default="run,soak,recording")
    ap.add_argument("--rows", type=int, default=1_000_000)
    args = ap.parse_args()
    durations = [float(d) for d in args.durations.split(",")]
    what = args.what.split(",")
    for name in ("run", "soak"):
        if name in what:
            bench_commands(name, durations)
    if "recording" in what:
        bench_recording(args.rows)


if __name__ == "__main__":
    main()
