"""The walker filter's predict and update: compiled (companion.tracking.imm) against the
filterpy reference (companion.tracking.reference), in the same run (docs/sensing.md).

    python bench/tracker_speed.py [--repeats 3000]

Times one IMM predict (0.05 s) and one update with a position detection, both on a belief
taken from a noisy walk, and prints the medians (us) and their ratio.
"""

from __future__ import annotations

import argparse
import statistics
import time

from companion.params import TrackerParams
from companion.tracking.reference import ReferenceFilter
from companion.tracking.walker import WalkerFilter
from companion.types import PersonDetection


def timed(fn, repeats: int) -> float:
    """Median wall time (us) of ``fn()`` over ``repeats`` calls, in batches of 10."""
    fn()
    out = []
    for _ in range(repeats // 10):
        t = time.perf_counter()
        for _ in range(10):
            fn()
        out.append((time.perf_counter() - t) / 10 * 1e6)
    return statistics.median(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3000)
    args = ap.parse_args()
    p = TrackerParams()
    cov = (0.0025, 0.0, 0.0, 0.0025)
    walk = [PersonDetection(0.1 * k, 0.12 * k, 0.01 * k * k, "world", cov) for k in range(20)]
    print(f"{'filter':10s} {'predict us':>10s} {'update us':>10s}")
    results = {}
    for name, filt in (("compiled", WalkerFilter(p)), ("filterpy", ReferenceFilter(p))):
        b = filt.start(walk[0])
        for prev, d in zip(walk, walk[1:]):
            b = filt.update(filt.predict(b, d.t - prev.t), d)
        d = PersonDetection(walk[-1].t, walk[-1].x + 0.01, walk[-1].y, "world", cov)
        results[name] = (timed(lambda f=filt, b=b: f.predict(b, 0.05), args.repeats),
                         timed(lambda f=filt, b=b, d=d: f.update(b, d), args.repeats))
        print(f"{name:10s} {results[name][0]:10.1f} {results[name][1]:10.1f}")
    c, f = results["compiled"], results["filterpy"]
    print(f"filterpy / compiled: predict {f[0] / c[0]:.0f}x, update {f[1] / c[1]:.0f}x")


if __name__ == "__main__":
    main()
