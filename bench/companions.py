"""The robot and the human companion beside the same person, on a few real walking pairs
(docs/companions.md).

    python bench/companions.py [--figure PNG] [--controller lqr]

For three walking pairs (a slow, a middling and a brisk one; each the first of the shipped
pairs in its speed band that is at least 10 s long) draws, in the person's frame, where the
human companion walked and where the robot (its reference point) walked in their place,
under ideal and realistic sensing, and prints each run's slot error against the human's
deviation.

Data: companion.data.pairs.CREDIT.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from companion.data.pairs import load_pairs
from companion.metrics import compute
from companion.params import Params, load_sensing
from companion.sim.pairs import offsets, pair_episode, pair_row, paired
from companion.sim.runner import run_one

BANDS = ((0.6, 0.9), (1.0, 1.25), (1.3, 1.45))


def chosen() -> list:
    pairs = load_pairs()
    out = []
    for lo, hi in BANDS:
        out.append(next(p for p in pairs if p.duration >= 10.0
                        and lo <= float(np.mean(p.speeds())) <= hi))
    return out


def main() -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from companion.io import save_figure

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--figure", type=Path, default=Path("out/companions.png"))
    ap.add_argument("--controller", default="lqr")
    args = ap.parse_args()
    pairs = chosen()
    fig, axes = plt.subplots(2, len(pairs), figsize=(4.2 * len(pairs), 7.5), sharex=True,
                             sharey=True)
    for row, sensing in enumerate(("ideal", "realistic")):
        params = Params().replace(sensing=load_sensing(sensing))
        for col, pair in enumerate(pairs):
            person = paired(pair)
            spec = pair_episode(person, params, args.controller)
            log = run_one(spec)
            m, p = compute(log), pair_row(person, spec.params, log)
            c, d = person.companion, spec.params.robot.d
            rx = log["robot_x"] + d * np.cos(log["robot_theta"])
            ry = log["robot_y"] + d * np.sin(log["robot_theta"])
            human = offsets(person, c.t, c.x, c.y)
            inside = log["t"] <= c.t[-1]
            robot = offsets(person, log["t"][inside], rx[inside], ry[inside])
            f = spec.params.formation
            ax = axes[row, col]
            ax.plot(0.0, 0.0, "o", ms=12, color="tab:red", label="person (heading +x)")
            ax.plot(human[:, 0], human[:, 1], "o-", ms=3, lw=0.6, color="tab:green",
                    label="human companion")
            ax.plot(robot[:, 0], robot[:, 1], lw=1.0, color="tab:blue",
                    label=f"robot ({args.controller})")
            ax.plot(f.distance * math.cos(f.bearing), f.distance * math.sin(f.bearing), "kx",
                    ms=9, label="slot (the companion's average)")
            ax.set_aspect("equal")
            ax.grid(alpha=0.3)
            ax.set_title(f"{pair.scene} {pair.a}+{pair.b}, {c.speed:.2f} m/s, {sensing}\n"
                         f"robot {100 * m['rms_slot_error_m']:.0f} cm RMS from the slot, human "
                         f"{100 * c.deviation:.0f} cm; keep-out {m['safety_share']:.0%}",
                         fontsize=8)
            print(f"{pair.scene}/{pair.a}+{pair.b} {sensing}: {c.speed:.2f} m/s, slot "
                  f"{c.distance:.2f} m; robot {100 * m['rms_slot_error_m']:.1f} cm from the "
                  f"slot, {100 * p['companion_distance_m']:.1f} cm from the companion's path; "
                  f"human {100 * c.deviation:.1f} cm; keep-out {m['safety_share']:.0%}")
    for ax in axes[-1]:
        ax.set_xlabel("forward of the person (m)")
    for ax in axes[:, 0]:
        ax.set_ylabel("left of the person (m)")
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.suptitle("The robot in the human companion's place, in the person's frame (data: "
                 "ETH/UCY)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, args.figure)
    plt.close(fig)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
