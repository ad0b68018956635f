"""Is the person tracker's uncertainty honest? Its position error against its own standard
deviation, on real walkers and on the closed-loop fuzz's walker (docs/sensing.md).

    python bench/tracker_consistency.py [--every N] [--episodes N] [--params FILE]

Runs the default LQR with ``realistic`` sensing beside every ``--every``-th ETH/UCY walking
track (robot on the left and on the right) and beside the first ``--episodes`` walkers of
``companion fuzz`` (seed 0; up to 2 m/s, turnarounds, sharp turns), and prints for each the
percentiles of the estimate's position error at the control instant, of its standard
deviation (``person_est_std``: the larger axis), and the share of steps whose error exceeds 2
and 3 of them. For an error that is Gaussian with the reported covariance those shares are at
most 13.5 % and 1.1 % (the Rayleigh tails; at most, because the larger axis is used), so a
larger share means the tracker is overconfident on that kind of walker.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from companion.apps import pedestrians as walkers
from companion.apps.args import file_params
from companion.data import pedestrians
from companion.errors import CompanionError
from companion.params import REALISTIC
from companion.sim import fuzz
from companion.sim.runner import run_many

#: Rayleigh tails: P(|e| > k sigma) for a 2D Gaussian of per-axis std sigma.
RAYLEIGH = {2: float(np.exp(-2.0)), 3: float(np.exp(-4.5))}


def errors(log) -> np.ndarray:
    """(error, std) per step with an estimate."""
    e = np.hypot(log["person_est_x"] - log["person_x"], log["person_est_y"] - log["person_y"])
    s = log["person_est_std"]
    ok = np.isfinite(e) & np.isfinite(s) & (s > 0.0)
    return np.stack([e[ok], s[ok]])


def report(name: str, parts: list[np.ndarray]) -> None:
    e, s = np.concatenate(parts, axis=1)
    r = e / s
    print(f"{name}: {len(e):,} steps; error p50/p90/p99 {np.percentile(e, 50):.3f}/"
          f"{np.percentile(e, 90):.3f}/{np.percentile(e, 99):.3f} m; std p50/p99 "
          f"{np.percentile(s, 50):.3f}/{np.percentile(s, 99):.3f} m; error/std p99 "
          f"{np.percentile(r, 99):.2f}; beyond 2 std {np.mean(r > 2):.1%} "
          f"(Gaussian <= {RAYLEIGH[2]:.1%}), beyond 3 std {np.mean(r > 3):.2%} "
          f"(<= {RAYLEIGH[3]:.2%})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=3, help="every N-th walking track (3)")
    ap.add_argument("--episodes", type=int, default=60, help="fuzz walkers (60)")
    ap.add_argument("--params", help="TOML file of parameter overrides")
    args = ap.parse_args()
    try:
        base = file_params(args)
    except CompanionError as exc:
        sys.exit(f"tracker_consistency: {exc}")
    params = base.replace(sensing=REALISTIC)
    tracks = pedestrians.select_tracks(pedestrians.load_scenes())[::args.every]
    specs = [walkers.episode(t, params, side=side) for t in tracks for side in ("left", "right")]
    report(f"ETH/UCY walkers ({len(specs)} runs)", run_many(specs, summarize=errors))
    drawn = [fuzz.draw(seed, "lqr", "realistic", base) for seed in range(args.episodes)]
    report(f"fuzz walkers ({args.episodes} episodes)",
           run_many([spec for _, spec in drawn], summarize=errors))
    print(f"\nData: {pedestrians.CREDIT}")


if __name__ == "__main__":
    main()
