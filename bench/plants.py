"""The plants side by side (docs/plants.md): every controller's slot error on the kinematic
and on the MuJoCo base, and how fast each plant runs.

    python bench/plants.py [--workers N] [--out DIR] [--skip-suite]

Times one figure-8 episode (60 s, lqr, realistic sensing) on each plant in this process and
prints its real-time factor and steps per second, and the MuJoCo physics alone (its steps
per second and real-time factor); then runs the shipped suite ``plants`` one plant at a time
(kept and resumable in ``--out``), prints the episodes per second with each plant (all
workers) and, per plant, sensing and controller, the median slot error, RMSE rho, the
closest approach, the share of episodes with a physics contact and the odometry's drift at
the end.

Results on the tracks carry the credit of companion.data.pedestrians.CREDIT.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from pathlib import Path

from companion.config import load_toml
from companion.evaluate.run import run_suite
from companion.evaluate.suite import suite_from_mapping, suite_path
from companion.params import Params, params_from_mapping
from companion.sim.mujoco_base import MujocoPlant
from companion.sim.scenario import load_scenario, run_scenario
from companion.types import Pose


def one_episode(kind: str) -> tuple[float, int]:
    """Wall time (s) and steps of the figure-8 (60 s, lqr, realistic) on plant ``kind``."""
    sc = load_scenario("figure8", {"sensing": "realistic", "plant": {"kind": kind}})
    run_scenario(dataclasses.replace(sc, duration=2.0))          # load and compile first
    t = time.perf_counter()
    log = run_scenario(sc)
    return time.perf_counter() - t, len(log["t"])


def physics_alone(seconds: float = 60.0) -> tuple[float, int]:
    """Wall time (s) and physics steps of the MuJoCo base alone over ``seconds`` of an arc."""
    p = params_from_mapping({"plant": {"kind": "mujoco"}})
    plant = MujocoPlant(p)
    plant.reset(Pose(0.0, 0.0, 0.0), (1.0, 0.3))
    n = int(round(seconds / p.dt))
    t = time.perf_counter()
    for k in range(n):
        plant.step((1.0, 0.3), k * p.dt)
    return time.perf_counter() - t, n * plant.substeps


def table(rows: list[dict]) -> list[str]:
    """Per plant, sensing and controller: medians over the suite's episodes."""
    keys = dict.fromkeys((r["plant"], r["sensing"].split("/")[0], r["controller"])
                         for r in rows)
    out = ["| plant | sensing | controller | episodes | slot error (cm) | RMSE rho (cm) | "
           "closest (m) | physics contact | odometry drift (cm) |", "|---" * 9 + "|"]
    for plant, sensing, controller in keys:
        cell = [r for r in rows if (r["plant"], r["sensing"].split("/")[0], r["controller"])
                == (plant, sensing, controller)]

        def med(key: str, cell: list[dict] = cell) -> float:
            return statistics.median(float(r[key]) for r in cell)

        contact = sum(float(r["plant_contacts"]) > 0 for r in cell) if plant == "mujoco" \
            else None
        out.append(f"| {plant} | {sensing} | {controller} | {len(cell)} | "
                   f"{100 * med('rms_slot_error_m'):.1f} | {100 * med('rmse_rho_m'):.1f} | "
                   f"{min(float(r['min_person_distance_m']) for r in cell):.2f} | "
                   f"{'-' if contact is None else f'{contact} of {len(cell)}'} | "
                   f"{100 * med('odometry_drift_m'):.1f} |")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--out", type=Path, default=Path("out") / "plants")
    ap.add_argument("--skip-suite", action="store_true", help="only the timings")
    args = ap.parse_args()
    dt = Params().dt
    for kind in ("kinematic", "mujoco"):
        wall, steps = one_episode(kind)
        print(f"{kind}: one figure-8 episode (60 s, lqr, realistic): {wall:.2f} s, real-time "
              f"factor {steps * dt / wall:.0f}x, {steps / wall:.0f} steps/s")
    wall, steps = physics_alone()
    print(f"mujoco physics alone (60 s arc, {steps} physics steps): real-time factor "
          f"{60.0 / wall:.0f}x, {steps / wall:.0f} physics steps/s")
    if args.skip_suite:
        return
    data = load_toml(suite_path("plants"))
    rows = []
    print()
    for kind in data["plants"]:
        suite = suite_from_mapping(dict(data, plants=[kind]), suite_path("plants"))
        t = time.perf_counter()
        mine = run_suite(suite, args.out / kind, args.workers)
        wall = time.perf_counter() - t
        print(f"suite plants, {kind}: {len(mine)} episodes in {wall:.0f} s, "
              f"{len(mine) / wall:.2f} episodes/s")
        rows += mine
    print()
    print("\n".join(table(rows)))


if __name__ == "__main__":
    main()
