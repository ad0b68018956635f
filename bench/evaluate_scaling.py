"""How an evaluation scales: episodes per second of one suite in this process (local, 1
worker), on 2 local worker processes and on a Dask LocalCluster of 1 and 2 workers (bound to
127.0.0.1), and each backend's overhead per episode (docs/evaluation.md).

    python bench/evaluate_scaling.py [--suite suites/smoke.toml]

Every run starts from an empty output folder (nothing resumed). The numbers of every run are
checked to be equal to the in-process ones.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

from companion.evaluate.run import run_suite
from companion.evaluate.suite import load_suite
from companion.sim.runner import warm_up


def _numbers(rows):
    return [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()}
            for r in rows]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", default=str(Path(__file__).resolve().parents[1] / "suites"
                                           / "smoke.toml"))
    args = ap.parse_args()
    suite = load_suite(args.suite)
    n = len(suite.episodes)
    warm_up()
    runs = [("in process", 1, None), ("local processes", 2, None),
            ("dask LocalCluster", 1, "local"), ("dask LocalCluster", 2, "local")]
    results, reference = {}, None
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, workers, dask) in enumerate(runs):
            t0 = time.perf_counter()
            rows = run_suite(suite, Path(tmp) / str(i), workers, dask)
            wall = time.perf_counter() - t0
            if reference is None:
                reference = _numbers(rows)
            assert _numbers(rows) == reference, f"{name} x{workers}: other numbers"
            results[(name, workers)] = wall
    base = results[("in process", 1)]
    print(f"{suite.name}: {n} episodes, the same numbers on every backend")
    print(f"in this process (= local, 1 worker): {n / base:.2f} episodes/s")
    local = results[("local processes", 2)]
    print(f"local processes, 2 workers: {n / local:.2f} episodes/s, {base / local:.2f}x; "
          f"overhead {(2 * local - base) / n * 1000:+.0f} worker-ms per episode")
    one, two = results[("dask LocalCluster", 1)], results[("dask LocalCluster", 2)]
    print(f"dask LocalCluster: 1 worker {n / one:.2f} episodes/s (overhead "
          f"{(one - base) / n * 1000:+.0f} ms per episode, cluster start included), "
          f"2 workers {n / two:.2f} episodes/s, {one / two:.2f}x")


if __name__ == "__main__":
    main()
