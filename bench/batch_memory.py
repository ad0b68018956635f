"""Peak memory of a large batch: 10,000 figure-8 episodes of 1,200 steps, metrics only.

    python bench/batch_memory.py [--episodes 10000] [--duration 60] [--noisy]

Runs the compiled batch (bare LQR, :mod:`companion.sim.fast_batch`) and prints the episodes,
controller steps, wall time, throughput and the peak resident memory of the process
(docs/performance.md).
"""

from __future__ import annotations

import argparse
import time

from threadpoolctl import threadpool_limits

from companion.benchmark import batch_specs, peak_rss_mb
from companion.sim.batch import run_batch
from companion.sim.scenario import load_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=10_000)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--noisy", action="store_true", help="sensor noise, a seed per episode")
    args = ap.parse_args()
    specs = batch_specs(load_scenario("figure8"), args.episodes, args.duration, args.noisy)
    t = time.perf_counter()
    with threadpool_limits(limits=1):
        results = run_batch(specs, backend="compiled")
    seconds = time.perf_counter() - t
    steps = sum(m["steps"] for m in results)
    print(f"{len(results)} episodes, {steps} controller steps in {seconds:.0f} s "
          f"({steps / seconds:,.0f} steps/s), all finite: {all(m['finite'] for m in results)}")
    print(f"peak resident memory: {peak_rss_mb():.0f} MB")


if __name__ == "__main__":
    main()
