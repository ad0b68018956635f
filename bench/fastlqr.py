"""Time the compiled LQR gain (companion.fastlqr) against the scipy path.

    python bench/fastlqr.py [--points N] [--seed S]

For each discretisation ('euler', the default, and 'zoh') and the same random operating points
(default Params otherwise), prints the median and 99th percentile time per gain of:

* ``dare_gain_nb`` (Riccati equation, gain, stability test) on a prebuilt model, called from a
  compiled loop (no Python in between): per operating point, the mean over REPEAT calls, then
  median / p99 over the points;
* ``dare_gain_nb`` called from Python, one timed call at a time (numba dispatch included);
* the Python function ``lqr_gain(chi, u, w, params)`` (model, gain, arrays, dispatch);
* the scipy path ``LqrController(params).gain(chi, u, w)`` with ``lqr.solver = "scipy"``;

and the speed-up of each over scipy (ratio of medians), plus the SDA iteration counts and the
largest relative difference between the compiled and the scipy gains on these points. BLAS is
limited to one thread.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
import scipy.linalg  # noqa: F401  (loaded before threadpool_limits, which only limits loaded libs)
from numba import njit
from threadpoolctl import threadpool_limits

from companion import fastlqr
from companion.control.lqr import LqrController
from companion.params import LqrParams, Params

REPEAT = 200  # calls per operating point in the compiled loop


def operating_points(n: int, seed: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Random controller operating points ``(chi, u, w)`` with the person walking."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        chi = np.array([rng.uniform(0.3, 3.0), rng.uniform(0.0, 2.0 * math.pi),
                        rng.uniform(-math.pi, math.pi)])
        u = np.array([rng.uniform(-1.5, 1.5), rng.uniform(-0.5 * math.pi, 0.5 * math.pi)])
        w = np.array([rng.uniform(0.2, 1.5), rng.uniform(-1.0, 1.0)])
        out.append((chi, u, w))
    return out


def model(chi, u, w, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """The augmented model of an operating point, as the controller builds it."""
    lqr = params.lqr
    return fastlqr.augmented_model(chi, u, w, params.robot.d, params.dt,
                                   lqr.discretization == "zoh", lqr.rho_min)


def stats(seconds: list[float] | np.ndarray) -> tuple[float, float]:
    """Median and 99th percentile in microseconds."""
    us = np.asarray(seconds) * 1e6
    return float(np.median(us)), float(np.percentile(us, 99))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=2000, help="operating points (default 2000)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    @njit
    def repeat(n, a, b, q, r, p, k):
        status = 0
        for _ in range(n):
            status, _ = fastlqr.dare_gain_nb(a, b, q, r, p, k)
        return status

    points = operating_points(args.points, args.seed)
    print(f"{len(points)} operating points, seed {args.seed}")
    for method in ("euler", "zoh"):
        params = Params().replace(lqr=LqrParams(discretization=method))
        q, r = np.array(params.lqr.q), np.array(params.lqr.r)
        k, p = np.empty((2, 5)), np.empty((5, 5))
        t = time.perf_counter()
        fastlqr.lqr_gain(*points[0], params)
        first = time.perf_counter() - t
        controller = LqrController(params.replace(lqr=LqrParams(discretization=method, solver="scipy")))

        # Keep the points where scipy finds a gain (all, for walking persons) and record the
        # SDA iterations and the difference of the gains.
        kept, iterations, worst = [], [], 0.0
        for chi, u, w in points:
            try:
                k_ref = controller.gain(chi, u, w)
            except np.linalg.LinAlgError:
                continue
            a, b = model(chi, u, w, params)
            status, it = fastlqr.dare_gain_nb(a, b, q, r, p, k)
            if status != fastlqr.GAIN_STABLE:
                print(f"  compiled gain not proved stabilising where scipy succeeded: "
                      f"{chi} {u} {w} (status {status})")
                continue
            worst = max(worst, float(np.max(np.abs(k - k_ref)) / np.max(np.abs(k_ref))))
            iterations.append(it)
            kept.append((chi, u, w))

        models = [model(*point, params) for point in kept]
        repeat(1, *models[0], q, r, p, k)  # compile the loop
        loop = []
        for a, b in models:
            t = time.perf_counter()
            repeat(REPEAT, a, b, q, r, p, k)
            loop.append((time.perf_counter() - t) / REPEAT)
        from_python = []
        for a, b in models:
            t = time.perf_counter()
            fastlqr.dare_gain_nb(a, b, q, r, p, k)
            from_python.append(time.perf_counter() - t)
        wrapper = []
        for chi, u, w in kept:
            t = time.perf_counter()
            fastlqr.lqr_gain(chi, u, w, params)
            wrapper.append(time.perf_counter() - t)
        scipy_path = []
        for chi, u, w in kept:
            t = time.perf_counter()
            controller.gain(chi, u, w)
            scipy_path.append(time.perf_counter() - t)

        ref_median = stats(scipy_path)[0]
        its = np.array(iterations)
        print(f"\ndiscretization={method}: {len(kept)} points with a gain; first call "
              f"{first:.3f} s; SDA iterations median {np.median(its):.0f}, "
              f"p99 {np.percentile(its, 99):.0f}, max {its.max()}; "
              f"max |K - K_scipy| / max|K_scipy| = {worst:.1e}")
        print(f"  {'path':34s} {'median':>10s} {'p99':>10s} {'speed-up':>9s}")
        for name, times in (("dare_gain_nb, compiled loop", loop),
                            ("dare_gain_nb, from Python", from_python),
                            ("lqr_gain (model + gain)", wrapper),
                            ("LqrController.gain (scipy)", scipy_path)):
            median, p99 = stats(times)
            print(f"  {name:34s} {median:8.2f}us {p99:8.2f}us {ref_median / median:8.0f}x")


if __name__ == "__main__":
    with threadpool_limits(limits=1):
        main()
