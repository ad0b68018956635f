"""How companionship degrades with the detector: the default LQR on the shipped walking tracks
under detectors varied one axis at a time around ``realistic`` (the shipped suite
``sensing-sweep``), and the other controllers on three of its cells (``sensing-corners``)
(docs/sensing.md).

    python bench/sensing_sweep.py [--every N] [--out DIR] [--workers N]

Axes (the others at ``realistic``): detection rate 5, 10, 20 Hz; position noise 0.02, 0.05,
0.10 m; latency 0.05, 0.1, 0.2 s; base lag 0.1, 0.2, 0.3 s; heading measured (0.1 rad) or
not; plus the all-worse and all-better corners, and every controller on ``realistic`` and
the two corners. Each cell runs every ETH/UCY track shipped with companion (``--every N``:
every N-th), robot in its slot on the left and on the right. Per cell it prints the median
and p90 over runs of the slot error (RMS distance from the robot's reference point to the
true person's slot), the floor (RMS distance from the slot the estimate implies to the true
slot: what a robot exactly at the estimated slot would get), their ratio, the median RMSE rho
and alpha, and the closest approach to the true person; then the issue's targets with PASS
or MISS. Writes ``sweep.csv`` and ``sweep.png`` (slot error against floor) in ``--out``.
About 25 minutes on 2 cores with every track; ``--every 3`` about 9.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from companion.config import load_toml
from companion.data import pedestrians
from companion.evaluate.generators import suite_of
from companion.evaluate.run import run_all
from companion.evaluate.suite import Suite, suite_from_mapping, suite_path
from companion.io import save_figure, write_csv

COLUMNS = ("controller", "cell", "runs", "median_slot_m", "p90_slot_m", "median_floor_m",
           "ratio", "median_rho_m", "median_alpha_rad", "closest_m")


def load(name: str, every: int) -> Suite:
    """The shipped suite ``name`` on every ``every``-th track."""
    data = load_toml(suite_path(name))
    data["motions"]["every"] = every
    return suite_from_mapping(data, suite_path(name))


def row(controller: str, label: str, runs: list[dict]) -> list:
    slot = np.array([r["rms_slot_error_m"] for r in runs])
    floor = np.array([r["rms_estimate_error_m"] for r in runs
                      if math.isfinite(r["rms_estimate_error_m"])])
    return [controller, label, len(runs), float(np.median(slot)),
            float(np.percentile(slot, 90)), float(np.median(floor)),
            float(np.median(slot) / np.median(floor)),
            float(np.median([r["rmse_rho_m"] for r in runs])),
            float(np.median([r["rmse_alpha_rad"] for r in runs])),
            float(min(r["min_person_distance_m"] for r in runs))]


def figure(rows: list[list], path: Path) -> None:
    """Median slot error against the floor per cell, log-log, with the 1x and 1.6x lines;
    the default LQR's cells labelled."""
    fig, ax = plt.subplots(figsize=(8.0, 6.5))
    lo = 0.5 * min(min(r[3], r[5]) for r in rows)
    hi = 2.0 * max(max(r[3], r[5]) for r in rows)
    ax.plot([lo, hi], [lo, hi], color="0.6", lw=1, label="slot error = floor")
    ax.plot([lo, hi], [1.6 * lo, 1.6 * hi], color="0.6", lw=1, ls="--", label="1.6 x floor")
    for name, marker in zip(dict.fromkeys(r[0] for r in rows), "osD^v<>"):
        mine = [r for r in rows if r[0] == name]
        ax.scatter([r[5] for r in mine], [r[3] for r in mine], marker=marker, label=name,
                   s=36 if name == "lqr" else 22, zorder=3)
        if name == "lqr":
            for r in mine:
                ax.annotate(r[1], (r[5], r[3]), fontsize=7, xytext=(4, -3),
                            textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_xlabel("floor: median RMS error of the slot the estimate implies (m)")
    ax.set_ylabel("median RMS slot error (m)")
    ax.set_title("Slot error against its floor, per detector (ETH/UCY tracks)")
    ax.legend(fontsize=8, loc="upper left")
    save_figure(fig, path)
    plt.close(fig)


def plot_csv(csv_path: Path, path: Path) -> None:
    """The figure again from a written sweep.csv."""
    import csv

    with open(csv_path, newline="") as fh:
        rows = [[r[0], r[1], int(r[2]), *map(float, r[3:])] for r in list(csv.reader(fh))[1:]]
    figure(rows, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=1, help="take every N-th track (1)")
    ap.add_argument("--out", type=Path, default=Path("out") / "sensing_sweep")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--plot", type=Path, metavar="CSV", help="only draw sweep.png again from "
                    "a sweep.csv (into --out)")
    args = ap.parse_args()
    if args.plot:
        args.out.mkdir(parents=True, exist_ok=True)
        plot_csv(args.plot, args.out / "sweep.png")
        return
    sweep, corners = load("sensing-sweep", args.every), load("sensing-corners", args.every)
    episodes = [e for e in corners.episodes if e.controller != "lqr"]   # lqr: in the sweep
    print(f"{len(sweep.episodes)} + {len(episodes)} episodes (the sensing-sweep suite, the "
          f"other controllers of sensing-corners)")
    t0 = time.perf_counter()
    both = suite_of("sensing-sweep+corners", (*sweep.episodes, *episodes),
                    parts=(sweep.digest, corners.digest))
    results = run_all(both, args.workers)
    grouped: dict[tuple[str, str], list[dict]] = {}
    for r in results:
        grouped.setdefault((r["controller"], r["sensing"]), []).append(r)
    rows = [row(c, label, runs) for (c, label), runs in grouped.items()]
    print(f"{len(results)} runs in {time.perf_counter() - t0:.0f} s\n")
    print(f"{'controller':10s} {'cell':24s} {'slot cm':>8s} {'p90':>6s} {'floor':>6s} "
          f"{'ratio':>6s} {'rho cm':>7s} {'alpha':>6s} {'closest':>7s}")
    for r in rows:
        print(f"{r[0]:10s} {r[1]:24s} {r[3] * 100:8.2f} {r[4] * 100:6.2f} {r[5] * 100:6.2f} "
              f"{r[6]:6.2f} {r[7] * 100:7.2f} {r[8]:6.3f} {r[9]:7.3f}")
    base = next(r for r in rows if r[0] == "lqr" and r[1] == "realistic")
    near = next(r for r in rows if r[0] == "lqr" and r[1].startswith("near"))
    lqr = [r for r in rows if r[0] == "lqr"]
    checks = [
        ("realistic median RMSE rho <= 7 cm", base[7] <= 0.07, f"{base[7] * 100:.2f} cm"),
        ("realistic median RMSE alpha <= 0.20 rad", base[8] <= 0.20, f"{base[8]:.3f} rad"),
        ("every lqr cell's median slot error <= 1.6 x its floor",
         all(r[6] <= 1.6 for r in lqr), f"worst {max(r[6] for r in lqr):.2f} x"),
        ("a detector within 25 % of realistic costs <= 1.5 x realistic's slot error",
         near[3] <= 1.5 * base[3], f"{near[3] / base[3]:.2f} x"),
        ("closest approach >= 0.5 m in every run", all(r[9] >= 0.5 for r in rows),
         f"{min(r[9] for r in rows):.3f} m"),
    ]
    print("\ntargets (default lqr):")
    for text, ok, value in checks:
        print(f"  {'PASS' if ok else 'MISS'}  {text}: {value}")
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "sweep.csv", COLUMNS, rows)
    figure(rows, args.out / "sweep.png")
    print(f"\nwrote sweep.csv and sweep.png in {args.out}")
    print(f"\nData: {pedestrians.CREDIT}")
    if any(not math.isfinite(r[3]) for r in rows):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
