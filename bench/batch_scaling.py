"""How the compiled batch's cost grows with the number of episodes and their length.

    python bench/batch_scaling.py

Prints wall time and controller steps per second of the compiled batch (bare LQR,
figure-8, exact observations, starts off the slot) for N = 10 ... 4000 episodes of 60 s and
for N = 1000 episodes of 15 ... 240 s, one run each after a warm-up (docs/performance.md).
"""

from __future__ import annotations

import time

from threadpoolctl import threadpool_limits

from companion.benchmark import batch_specs
from companion.sim.batch import run_batch
from companion.sim.scenario import load_scenario


def measure(n: int, duration: float) -> tuple[float, float]:
    specs = batch_specs(load_scenario("figure8"), n, duration)
    t = time.perf_counter()
    metrics = run_batch(specs, backend="compiled")
    seconds = time.perf_counter() - t
    return seconds, sum(m["steps"] for m in metrics) / seconds


def main() -> None:
    with threadpool_limits(limits=1):
        measure(4, 1.0)   # load the compiled kernels
        print("episodes  duration_s  wall_s  steps_per_s")
        for n, duration in [(10, 60.0), (100, 60.0), (1000, 60.0), (4000, 60.0),
                            (1000, 15.0), (1000, 120.0), (1000, 240.0)]:
            seconds, rate = measure(n, duration)
            print(f"{n:8d}  {duration:10.0f}  {seconds:6.2f}  {rate:11,.0f}")


if __name__ == "__main__":
    main()
