"""How far each controller is from the estimate it is given (docs/sensing.md, "Robustness").

    python bench/robustness.py [--workers N] [--out DIR] [--figure PNG]

Runs the shipped suite ``robustness`` (the paper's shapes, a subset of the walking tracks and
of the walking pairs, five detectors, every controller; kept and resumable in ``--out``) and
prints, per motion group, detector and controller, the medians over its episodes of the slot
error and of the estimate's own slot error (the floor: where the estimate puts the slot
against where the true person's is), their ratio, the keep-out's share of the steps and the
closest approach; a controller more than 1 m from its slot on median has lost the person
(``lost``). Where the floor is below a millimetre (ideal sensing) there is no ratio.
``--figure`` draws the ratio as a heat map.

Results on the tracks and pairs carry the credits of companion.data.pedestrians.CREDIT and
companion.data.pairs.CREDIT.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from companion.evaluate.run import run_suite
from companion.evaluate.suite import load_suite

LOST_M = 1.0
#: A floor below this (m) is no floor: the estimate is the truth (ideal sensing).
NO_FLOOR = 0.001
#: Slot errors below this (cm) are not compared as ratios.
MIN_CM = 0.05


def cells(rows: list[dict]) -> list[dict]:
    """One line per (group, sensing, controller) with the medians described above."""
    out = []
    keys = dict.fromkeys((r["group"], r["sensing"], r["controller"]) for r in rows)
    for group, sensing, controller in keys:
        mine = [r for r in rows if (r["group"], r["sensing"], r["controller"])
                == (group, sensing, controller)]
        slot = float(np.median([r["rms_slot_error_m"] for r in mine]))
        floor = float(np.nanmedian([r["rms_estimate_error_m"] for r in mine]))
        out.append({"group": group, "sensing": sensing, "controller": controller,
                    "episodes": len(mine), "slot_cm": 100 * slot, "floor_cm": 100 * floor,
                    "ratio": slot / floor if floor >= NO_FLOOR else math.nan,
                    "keepout": float(np.median([r["safety_share"] for r in mine])),
                    "closest_m": float(min(r["min_person_distance_m"] for r in mine)),
                    "lost": slot > LOST_M})
    return out


def _ratio(value: float) -> str:
    return "-" if math.isnan(value) else f"{value:.2f}"


def text(lines: list[dict]) -> str:
    head = ("| motion | detector | controller | slot error (cm) | floor (cm) | ratio | "
            "keep-out share | closest (m) |\n|---|---|---|---|---|---|---|---|")
    body = [f"| {d['group']} | {d['sensing']} | {d['controller']} | {d['slot_cm']:.1f} | "
            f"{d['floor_cm']:.1f} | {_ratio(d['ratio'])}{' (lost)' if d['lost'] else ''} | "
            f"{d['keepout']:.0%} | {d['closest_m']:.2f} |" for d in lines]
    return "\n".join([head, *body])


def against_best(lines: list[dict], reference: str = "lqr") -> str:
    """Per motion group and detector: the floor, ``reference``'s slot error and ratio, the
    best controller's slot error (other than lqr-paper, the printed design) and
    ``reference``'s keep-out share and closest approach."""
    head = (f"| motion | detector | floor (cm) | {reference} (cm) | {reference} / floor | "
            f"best (cm) | {reference} / best | keep-out share | closest (m) |\n"
            "|---|---|---|---|---|---|---|---|---|")
    body = []
    for group, sensing in dict.fromkeys((d["group"], d["sensing"]) for d in lines):
        cell = [d for d in lines if (d["group"], d["sensing"]) == (group, sensing)]
        ref = next(d for d in cell if d["controller"] == reference)
        best = min((d for d in cell if d["controller"] != "lqr-paper"),
                   key=lambda d: d["slot_cm"])
        versus = ref["slot_cm"] / best["slot_cm"] if best["slot_cm"] >= MIN_CM else math.nan
        body.append(f"| {group} | {sensing} | {ref['floor_cm']:.1f} | {ref['slot_cm']:.1f}"
                    f"{' (lost)' if ref['lost'] else ''} | {_ratio(ref['ratio'])} | "
                    f"{best['slot_cm']:.1f} ({best['controller']}) | "
                    f"{_ratio(versus)} | "
                    f"{ref['keepout']:.0%} | {ref['closest_m']:.2f} |")
    return "\n".join([head, *body])


def figure(lines: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from companion.io import save_figure
    columns = list(dict.fromkeys((d["group"], d["sensing"]) for d in lines
                                if d["sensing"] != "ideal"))
    controllers = list(dict.fromkeys(d["controller"] for d in lines))
    grid = np.full((len(controllers), len(columns)), np.nan)
    for d in lines:
        if (d["group"], d["sensing"]) in columns:
            grid[controllers.index(d["controller"]),
                 columns.index((d["group"], d["sensing"]))] = d["ratio"]
    fig, ax = plt.subplots(figsize=(max(8, 0.45 * len(columns)), 3.8))
    image = ax.imshow(np.log2(np.clip(grid, 0.125, 16)), cmap="RdYlGn_r", vmin=-3, vmax=4,
                      aspect="auto")
    for i in range(grid.shape[0]):
        for j in range(grid.shape[1]):
            ax.text(j, i, _ratio(grid[i, j]), ha="center", va="center", fontsize=5)
    ax.set_xticks(range(len(columns)), [f"{g}\n{s}" for g, s in columns], fontsize=6,
                  rotation=90)
    ax.set_yticks(range(len(controllers)), controllers, fontsize=8)
    ax.set_title("median slot error / the estimate's own (below 1: better than the estimate)",
                 fontsize=9)
    fig.colorbar(image, ax=ax, label="log2 ratio")
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--out", type=Path, default=Path("out/bench-robustness"))
    ap.add_argument("--figure", type=Path, default=None)
    args = ap.parse_args()
    rows = run_suite(load_suite("robustness"), args.out, args.workers)
    lines = cells(rows)
    print(against_best(lines))
    print()
    print(text(lines))
    if args.figure is not None:
        figure(lines, args.figure)
        print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
