"""Every controller beside real walkers under ideal and realistic sensing (docs/sensing.md).

    python bench/sensing.py [--every N]

Runs each ETH/UCY track shipped with companion (companion/data/eth_ucy; mean speed > 0.6 m/s,
>= 15 s), robot starting in its slot on the left and on the right, with every controller, once
with the ``ideal`` and once with the ``realistic`` sensing profile (about 10 minutes on 2 cores;
``--every 3`` takes every third track). Prints per profile and controller the median and
90th percentile of the per-run RMSE rho, the median RMSE alpha and the closest approach to
the true person; where the slot error comes from (the estimate, the tracking of the
estimated slot, the keep-out; companion.metrics.Split); the LQR against each baseline on the
same runs; and the realistic profile's targets with PASS or MISS.
"""

from __future__ import annotations

import argparse

from companion.control import CONTROLLERS
from companion.data import pedestrians
from companion.evaluate import walkers
from companion.evaluate.run import run_all

#: The realistic-profile targets for the default LQR (median rho, median alpha, closest
#: approach): (key, bound, at most?).
TARGETS = (("median_rho_m", 0.07, True), ("median_alpha_rad", 0.20, True),
           ("min_distance_m", 0.5, False))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=1, help="take every N-th track")
    args = ap.parse_args()
    suite = walkers.tracks_suite(list(CONTROLLERS), ["ideal", "realistic"], every=args.every)
    print(f"{len(suite.episodes)} episodes: every shipped track x 2 sides x "
          f"{len(CONTROLLERS)} controllers x 2 sensing profiles")
    every = run_all(suite)
    for label in ("ideal", "realistic"):
        rows = [r for r in every if r["sensing"] == label]
        table = walkers.table(rows)
        print(f"\n{label}: {'controller':10s} {'median rho cm':>13s} {'p90 rho cm':>10s} "
              f"{'median alpha':>12s} {'closest m':>9s}")
        for name, t in table.items():
            print(f"{'':{len(label) + 1}s} {name:10s} {t['median_rho_m'] * 100:13.2f} "
                  f"{t['p90_rho_m'] * 100:10.2f} {t['median_alpha_rad']:12.3f} "
                  f"{t['min_distance_m']:9.3f}")
        print(f"{'':{len(label) + 1}s} where the slot error comes from (medians of each "
              f"run's RMS, cm; keep-out displacement m, share of steps it acted):")
        for name, t in table.items():
            cells = [t[f"median_rms_{k}_error_m"] for k in ("slot", "estimate", "tracking")]
            print(f"{'':{len(label) + 1}s} {name:10s} slot {cells[0] * 100:6.2f}  estimate "
                  f"{cells[1] * 100:6.2f}  tracking {cells[2] * 100:6.2f}  keep-out "
                  f"{t['median_safety_shift_m']:6.3f} m on {t['median_safety_share']:.1%}")
        for name, p in walkers.paired(rows, "lqr").items():
            print(f"  lqr vs {name:9s}: lower rho in {p['better_rho']:.0%} of runs (median "
                  f"diff {p['median_diff_rho'] * 100:+.2f} cm), lower alpha in "
                  f"{p['better_alpha']:.0%} ({p['median_diff_alpha']:+.3f} rad)")
    lqr = table["lqr"]
    print("\nrealistic targets (lqr):")
    for key, bound, at_most in TARGETS:
        ok = lqr[key] <= bound if at_most else lqr[key] >= bound
        print(f"  {key:16s} {lqr[key]:.3f} {'<=' if at_most else '>='} {bound}: "
              f"{'PASS' if ok else 'MISS'}")
    print(f"\nData: {pedestrians.CREDIT}")


if __name__ == "__main__":
    main()
