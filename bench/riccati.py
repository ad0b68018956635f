"""The compiled Riccati solver against scipy's over random walking operating points.

    python bench/riccati.py [--points N] [--seed S]

For each discretisation ('euler', the default, and 'zoh') prints the median and 99th
percentile time per gain of :func:`companion.riccati.dare_gain` (called from Python, on the
controller's model) and of scipy's ``solve_discrete_are`` path (:func:`companion.riccati.dlqr`),
the doubling iterations, and the largest relative difference between the two gains. BLAS is
limited to one thread.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
import scipy.linalg  # noqa: F401  (loaded before threadpool_limits, which only limits loaded libs)
from threadpoolctl import threadpool_limits

from companion import riccati
from companion.control.lqr import augmented_model
from companion.params import LqrParams, Params


def operating_points(n: int, seed: int) -> list[tuple[tuple, tuple, tuple]]:
    """Random controller operating points ``(chi, u, w)`` with the person walking."""
    rng = np.random.default_rng(seed)
    return [((rng.uniform(0.3, 3.0), rng.uniform(0.0, 2.0 * math.pi),
              rng.uniform(-math.pi, math.pi)),
             (rng.uniform(-1.5, 1.5), rng.uniform(-0.5 * math.pi, 0.5 * math.pi)),
             (rng.uniform(0.2, 1.5), rng.uniform(-1.0, 1.0))) for _ in range(n)]


def stats(seconds: list[float]) -> str:
    us = np.asarray(seconds) * 1e6
    return f"median {np.median(us):8.1f} us, p99 {np.percentile(us, 99):8.1f} us"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=2000, help="operating points (default 2000)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    points = operating_points(args.points, args.seed)
    print(f"{len(points)} operating points, seed {args.seed}")
    for method in ("euler", "zoh"):
        params = Params().replace(lqr=LqrParams(discretization=method))
        q, r = np.array(params.lqr.q), np.array(params.lqr.r)
        p, k = np.empty((5, 5)), np.empty((2, 5))
        compiled, scipy_s, iterations, worst = [], [], [], 0.0
        for chi, u, w in points:
            a, b = augmented_model(chi, u, w, params)
            t = time.perf_counter()
            status, it = riccati.dare_gain(a, b, q, r, p, k)
            compiled.append(time.perf_counter() - t)
            t = time.perf_counter()
            try:
                k_ref, _ = riccati.dlqr(a, b, np.diag(q), np.diag(r), check=False)
            except np.linalg.LinAlgError:
                continue
            scipy_s.append(time.perf_counter() - t)
            iterations.append(it)
            if status == riccati.GAIN_FAILED:
                print(f"  compiled solver failed where scipy succeeded: {chi} {u} {w}")
                continue
            worst = max(worst, float(np.max(np.abs(k - k_ref)) / np.max(np.abs(k_ref))))
        print(f"{method}: compiled {stats(compiled)}; scipy {stats(scipy_s)}; "
              f"{np.median(scipy_s) / np.median(compiled):.0f}x; doubling iterations median "
              f"{np.median(iterations):.0f}, max {max(iterations)}; largest relative gain "
              f"difference {worst:.1e}")


if __name__ == "__main__":
    with threadpool_limits(limits=1):
        main()
