"""Where the time of one compiled LQR step goes.

    python bench/step_parts.py [--calls N]

Times ``LqrController.step`` (default parameters, one fixed observation) and the compiled
calls it makes, ``lqr_prepare_nb``, ``dare_gain_nb`` (through ``stabilising_gain``) and
``lqr_output_nb``, called from Python with the controller's own buffers, plus a trivial
compiled function (the dispatch cost). Prints the best and the median of 5 rounds of N calls,
in microseconds per call (docs/performance.md).
"""

from __future__ import annotations

import argparse
import statistics
import time

from companion import fastlqr
from companion.control import LqrController, Observation, PersonState, Pose
from companion.params import Params


def per_call_us(function, args: tuple, calls: int) -> tuple[float, float]:
    rounds = []
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(calls):
            function(*args)
        rounds.append((time.perf_counter() - t) / calls * 1e6)
    return min(rounds), statistics.median(rounds)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=20_000)
    n = ap.parse_args().calls
    c = LqrController(Params())
    obs = Observation(0.0, Pose(0.0, -1.0, 0.0), PersonState(0.0, 0.0, 0.0, 1.0, 0.1))
    c.step(obs)
    r, h = obs.robot, obs.person
    parts = {
        "LqrController.step": (c.step, (obs,)),
        "lqr_prepare_nb": (fastlqr.lqr_prepare_nb,
                           (r.x, r.y, r.theta, h.x, h.y, h.theta, h.v, h.omega, c._config,
                            c._memory, c._op, c._xi, c._a, c._b)),
        "dare_gain_nb": (fastlqr.dare_gain_nb, (c._a, c._b, c._q_diag, c._r_diag, c._p, c._k)),
        "lqr_output_nb": (fastlqr.lqr_output_nb, (True, c._k, c._gain, c._rest_gain, c._memory,
                                                  c._xi, c._op, c._config)),
        "wrap_pi_nb (dispatch only)": (fastlqr.wrap_pi_nb, (1.0,)),
    }
    print(f"{'call':28s} {'best':>8s} {'median':>8s}  (us per call, 5 rounds of {n})")
    for name, (function, args) in parts.items():
        best, median = per_call_us(function, args, n)
        print(f"{name:28s} {best:8.2f} {median:8.2f}")


if __name__ == "__main__":
    main()
