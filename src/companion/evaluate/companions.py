"""The robot against the human companion, beside real walking pairs (docs/companions.md).

From a suite's rows beside pairs (:func:`companion.sim.pairs.pair_row`): per sensing,
controller and band of the pair's speed, the walks, the robot's median slot error against
the human companion's own median deviation about the same slot, the share of walks in which
the robot was the steadier, its median distance from where the companion walked, the closest
approach and the keep-out's share of the steps. ``pairs.md`` and ``pairs.csv``.

Any result on these pairs carries :data:`companion.data.pairs.CREDIT`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from companion.data.pairs import CREDIT
from companion.io import CsvWriter, atomic_write

#: Bands of the pair's mean speed (m/s): the robot's 1.5 m/s limit leaves no margin to catch
#: up with the fastest walkers.
BANDS = ((0.0, 1.0), (1.0, 1.3), (1.3, 1.45), (1.45, math.inf))
#: Bands of the companion's own distance from the person (m, their average slot).
DISTANCES = ((0.0, 0.7), (0.7, 0.9), (0.9, math.inf))
#: The pairs of the targets: walking up to this speed (m/s).
TARGET_SPEED = 1.3
COLUMNS = ("sensing", "controller", "band", "walks", "robot_median_cm", "human_median_cm",
           "robot_steadier", "companion_distance_median_cm", "closest_m",
           "keepout_share_median", "slots_moved")


def beside_pairs(rows: Sequence[dict]) -> list[dict]:
    """The rows of episodes beside a walking pair."""
    return [r for r in rows if "human_deviation_m" in r]


def _band(rows: list[dict], sensing: str, controller: str, label: str) -> dict:
    robot = np.array([r["rms_slot_error_m"] for r in rows])
    human = np.array([r["human_deviation_m"] for r in rows])
    return {"sensing": sensing, "controller": controller, "band": label, "walks": len(rows),
            "robot_median_cm": 100 * float(np.median(robot)),
            "human_median_cm": 100 * float(np.median(human)),
            "robot_steadier": float(np.mean(robot < human)),
            "companion_distance_median_cm": 100 * float(np.median(
                [r["companion_distance_m"] for r in rows])),
            "closest_m": float(min(r["min_person_distance_m"] for r in rows)),
            "keepout_share_median": float(np.median([r["safety_share"] for r in rows])),
            "slots_moved": sum(r["slot_moved_m"] > 0 for r in rows)}


def _human_distance(row: dict) -> float:
    return row["slot_distance_m"] - row["slot_moved_m"]


def table(rows: Sequence[dict], by: str = "speed") -> list[dict]:
    """Per sensing and controller: one line per band of the pair's speed (``by="speed"``,
    then one for every walk up to :data:`TARGET_SPEED`) or of the companion's distance
    (``by="distance"``) that has walks, and one for all."""
    rows = beside_pairs(rows)
    value, bands = ((lambda r: r["pair_speed_mps"]), BANDS) if by == "speed" else \
        (_human_distance, DISTANCES)
    out = []
    for sensing in dict.fromkeys(r["sensing"] for r in rows):
        for controller in dict.fromkeys(r["controller"] for r in rows):
            mine = [r for r in rows if r["sensing"] == sensing and r["controller"] == controller]
            if not mine:
                continue
            for lo, hi in bands:
                band = [r for r in mine if lo < value(r) <= hi]
                if band:
                    label = f"> {lo:g}" if hi == math.inf else f"{lo:g}-{hi:g}"
                    out.append(_band(band, sensing, controller, label))
            slow = [r for r in mine if r["pair_speed_mps"] <= TARGET_SPEED]
            if by == "speed" and slow:
                out.append(_band(slow, sensing, controller, f"<= {TARGET_SPEED:g}"))
            out.append(_band(mine, sensing, controller, "all"))
    return out


def _lines(lines: Sequence[dict], band: str) -> list[str]:
    text = [f"| sensing | controller | {band} | walks | robot (cm) | human (cm) | robot "
            "steadier | from the companion's path (cm) | closest (m) | keep-out share | "
            "slots moved |", "|---" * 11 + "|"]
    for d in lines:
        text.append(f"| {d['sensing']} | {d['controller']} | {d['band']} | {d['walks']} | "
                    f"{d['robot_median_cm']:.1f} | {d['human_median_cm']:.1f} | "
                    f"{d['robot_steadier']:.0%} | {d['companion_distance_median_cm']:.1f} | "
                    f"{d['closest_m']:.2f} | {d['keepout_share_median']:.0%} | "
                    f"{d['slots_moved']} |")
    return text


def markdown(lines: Sequence[dict], rows: Sequence[dict],
             distances: Sequence[dict] = ()) -> str:
    """The table by speed (and by the companion's distance) as markdown, with how many
    slots were moved out of the keep-out and why, and the data's credit."""
    rows = beside_pairs(rows)
    moved = [r for r in rows if r["slot_moved_m"] > 0]
    walks = {r["motion"] for r in rows}
    text = ["## The robot against the human companion", "",
            f"{len(walks)} walks (each pair both ways round), the robot in the companion's "
            f"place at their average slot in the person's frame. Slot error: the robot's RMS "
            f"distance from that slot; the human's: the companion's own RMS deviation about "
            f"it. Medians; steadier: the share of walks in which the robot's slot error is "
            f"below the human's.", ""]
    if moved:
        text += [f"{len({r['motion'] for r in moved})} of {len(walks)} walks had their slot "
                 f"inside the keep-out's person clearance (the robot centre nearer the person "
                 f"than keepout.person_clearance or keepout.protective_distance): the robot "
                 f"held the nearest slot outside it at the same bearing, on median "
                 f"{100 * float(np.median([r['slot_moved_m'] for r in moved])):.0f} cm "
                 f"farther (slot_moved_m in episodes.csv); their errors are against that slot, "
                 f"the human's against theirs.", ""]
    text += _lines(lines, "pair speed (m/s)")
    if distances:
        text += ["", "By the companion's own distance from the person:", "",
                 *_lines(distances, "companion's distance (m)")]
    return "\n".join(text + ["", "Data: " + CREDIT]) + "\n"


def short(rows: Sequence[dict]) -> str:
    """The lines of every walk up to :data:`TARGET_SPEED` and of all walks, per sensing and
    controller, as markdown (the bands are in ``pairs.md``)."""
    lines = [d for d in table(rows) if d["band"] in (f"<= {TARGET_SPEED:g}", "all")]
    return "\n".join(["## The robot against the human companion (medians; every band in "
                      "pairs.md)", "", *_lines(lines, "pair speed (m/s)")]) + "\n"


def write(folder: Path, rows: Sequence[dict]) -> None:
    """``pairs.md`` and ``pairs.csv`` in ``folder``."""
    lines, distances = table(rows), table(rows, "distance")
    atomic_write(folder / "pairs.md", lambda p: p.write_text(
        markdown(lines, rows, distances), encoding="utf-8"))
    with CsvWriter(folder / "pairs.csv", ["by", *COLUMNS]) as out:
        out.add([by, *(d[k] for k in COLUMNS)] for by, part in (("speed", lines),
                                                                ("distance", distances))
                for d in part)
