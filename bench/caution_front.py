"""How cautious to be: the front of ``keepout.collision_risk`` between companionship and safety
under realistic sensing (docs/safety.md).

    python bench/caution_front.py [--risks 0,0.01,0.05,0.1,0.2] [--steps 300000] [--every 3]

For each setting: the default LQR beside the shipped ETH/UCY walkers (``--every N``: every
N-th track, both sides; median RMSE rho and alpha, median slot error, the share of steps the
keep-out acted, the closest approach), and the closed-loop fuzz under realistic sensing
(every controller, ``--steps`` steps of seed 0, the same episodes for every setting): the
share of episodes the robot failed by its own doing with its exact 95 % interval, the
robot-caused contacts and protective steps, and the closest approach. About 4 minutes per
setting on 2 cores.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from companion.control import CONTROLLERS
from companion.data import pedestrians
from companion.evaluate import fuzz_runs as fuzz_app
from companion.evaluate import walkers
from companion.evaluate.run import run_all
from companion.params import Params
from companion.sim import fuzz


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--risks", default="0,0.01,0.05,0.1,0.2")
    ap.add_argument("--steps", type=int, default=300_000)
    ap.add_argument("--every", type=int, default=3)
    args = ap.parse_args()
    risks = [float(r) for r in args.risks.split(",")]
    tracks = pedestrians.select_tracks(pedestrians.load_scenes())[::args.every]
    episodes = fuzz.plan(args.steps, 0, tuple(CONTROLLERS), ("realistic",))
    print(f"{len(tracks)} tracks x 2 sides; fuzz: {len(episodes)} realistic episodes "
          f"({args.steps:,} steps)\n")
    print(f"{'risk':>5s} {'rho cm':>7s} {'alpha':>6s} {'slot cm':>8s} {'acting':>7s} "
          f"{'closest':>7s} | {'failed':>7s} {'rate':>6s} {'95 % interval':>15s} "
          f"{'contacts':>8s} {'steps':>5s} {'closest':>7s} {'time s':>6s}")
    for risk in risks:
        t0 = time.perf_counter()
        base = Params()
        base = base.replace(keepout=dataclasses.replace(base.keepout, collision_risk=risk))
        lqr = {"name": "lqr", "label": "lqr",
               "params": {"keepout": {"collision_risk": risk}}}
        rows = run_all(walkers.tracks_suite([lqr], ["realistic"], every=args.every))
        w = walkers.table(rows)["lqr"]
        cases, counts = fuzz_app.run(episodes, None, base=base)
        rate = fuzz_app.failure_rates(cases, counts)["realistic"]
        total = fuzz.totals(counts)
        print(f"{risk:5g} {w['median_rho_m'] * 100:7.2f} {w['median_alpha_rad']:6.3f} "
              f"{w['median_rms_slot_error_m'] * 100:8.2f} {w['median_safety_share']:7.1%} "
              f"{w['min_distance_m']:7.3f} | {rate['robot_failed_episodes']:3d}/"
              f"{rate['episodes']:<3d} {rate['rate']:6.1%} "
              f"{rate['ci95'][0]:6.1%} to {rate['ci95'][1]:5.1%} "
              f"{total['person_collisions_robot']:8d} {total['violations']:5d} "
              f"{total['min_person_distance_m']:7.3f} {time.perf_counter() - t0:6.0f}",
              flush=True)
    print(f"\nData: {pedestrians.CREDIT}")


if __name__ == "__main__":
    main()
