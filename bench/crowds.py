"""The crowd bench (docs/crowds.md): the shipped suite ``crowds`` (every crowd scene, 20
seeds, every controller, ideal and realistic sensing) and its social-navigation measures;
``--suite crowds-robot`` runs the scenes as a robot senses them (LiDAR, an occluded 8 m
person detector) with and without a search.

    python bench/crowds.py [--suite NAME] [--seeds N] [--controllers A,B] [--workers N]

Per sensing, scene and controller it prints the share of successful episodes with its exact
95 % interval (success: no contact with a walker that the robot caused, none with a wall or
pillar, never closer than 0.5 m to the person, every value finite), the contacts with walkers
by who moved into whom, the median [95 % interval] of the slot error, the closest gap to a
walker, the time inside a walker's intimate zone, the time the person's gap lies in the
personal zone, the path length, the RMS jerk and the longest stop (/ the longest while the
person walked), the share of time the person was in the detector's view, losses re-found of
those with a chance (the person in view for 0.5 s while lost) and the longest search; then
the targets of docs/crowds.md for the suite's reference
controller under its realistic sensing, with PASS or MISS.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from companion.config import load_toml
from companion.evaluate.run import run_all
from companion.evaluate.stats import binomial_ci, median_ci
from companion.evaluate.suite import suite_from_mapping, suite_path

#: A robot this close to its slot (m) at the end of a doorway or corridor episode got through.
THROUGH_M = 1.5


def success(r: dict) -> bool:
    return (r["walker_contacts_robot"] == 0 and r["min_person_distance_m"] >= 0.5
            and r["obstacle_collisions"] == 0 and bool(r["finite"]))


def _ci(values: list[float], scale: float = 1.0, digits: int = 2) -> str:
    m, lo, hi = median_ci(values)
    return f"{m * scale:.{digits}f} [{lo * scale:.{digits}f}, {hi * scale:.{digits}f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", default="crowds")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--controllers", help="comma-separated (default: the suite's)")
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args()
    data = load_toml(suite_path(args.suite))
    data["seeds"] = args.seeds
    if args.controllers:
        data["controllers"] = args.controllers.split(",")
        data["reference"] = data["controllers"][0]
    suite = suite_from_mapping(data, suite_path(args.suite))
    t0 = time.perf_counter()
    rows = run_all(suite, args.workers)
    print(f"{len(rows)} episodes in {time.perf_counter() - t0:.0f} s\n")
    head = (f"{'sensing':9s} {'scene':18s} {'controller':10s} {'success (95 % CI)':>22s} "
            f"{'contacts r/w':>12s} {'slot cm':>20s} {'walker gap m':>20s} "
            f"{'intimate s':>9s} {'personal':>8s} {'path m':>6s} {'jerk':>6s} {'stop s':>9s} "
            f"{'in view':>7s} {'refound':>9s} {'search s':>8s}")
    print(head)
    groups: dict[tuple[str, str, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["sensing"], r["motion"], r["controller"]), []).append(r)
    for (sensing, scene, controller), mine in groups.items():
        ok = sum(success(r) for r in mine)
        lo, hi = binomial_ci(ok, len(mine))
        robot = sum(int(r["walker_contacts_robot"]) for r in mine)
        walker = sum(int(r["walker_contacts_walker"]) for r in mine)
        personal = [r["person_personal_s"] / r["duration_s"] for r in mine]
        print(f"{sensing:9s} {scene:18s} {controller:10s} {ok:3d}/{len(mine):<3d} "
              f"[{lo:4.0%}, {hi:4.0%}] {robot:5d}/{walker:<6d} "
              f"{_ci([r['rms_slot_error_m'] for r in mine], 100, 1):>20s} "
              f"{_ci([r['min_walker_gap_m'] for r in mine]):>20s} "
              f"{_median(r['walker_intimate_s'] for r in mine):9.2f} "
              f"{_median(personal):8.0%} {_median(r['path_length_m'] for r in mine):6.1f} "
              f"{_median(r['jerk_rms_mps3'] for r in mine):6.1f} "
              f"{max(r['longest_stop_s'] for r in mine):4.1f}/"
              f"{max(r['longest_stop_person_walking_s'] for r in mine):<4.1f} "
              f"{_median(r['person_in_view_share'] for r in mine):7.0%} "
              f"{_refound(mine):>9s} {max(r['search_time_s'] for r in mine):8.1f}")
    lqr = [r for r in rows if r["controller"] == suite.reference
           and r["sensing"] in ("realistic", "robot")]
    if lqr:
        ok = sum(r["walker_contacts_robot"] == 0 for r in lqr)
        near = [r for r in lqr if r["min_person_distance_m"] < 0.5]
        passage = [r for r in lqr if r["motion"] in ("crowd-corridor", "crowd-doorway")]
        stop = max(r["longest_stop_s"] for r in passage) if passage else 0.0
        left = max(r["longest_stop_person_walking_s"] for r in passage) if passage else 0.0
        chances = [r for r in lqr if r["person_refind_chances"] > 0]
        refound = sum(r["person_refinds"] >= r["person_refind_chances"] for r in chances)
        print(f"\ntargets ({suite.reference}, {lqr[0]['sensing']} sensing):")
        for text, good, value in [
            (">= 95 % of episodes without a robot-caused walker contact",
             ok >= 0.95 * len(lqr), f"{ok}/{len(lqr)}"),
            ("0 robot-caused walker contacts (these walkers see the robot)",
             all(r["walker_contacts_robot"] == 0 for r in lqr),
             f"{sum(int(r['walker_contacts_robot']) for r in lqr)}"),
            ("corridor and doorway without a stop longer than 2 s", stop <= 2.0,
             f"longest {stop:.1f} s"),
            ("  ... while the person walks (0.3 m/s or more)", left <= 2.0,
             f"longest {left:.1f} s"),
            ("through the door and the corridor (within 1.5 m of its slot at the end)",
             all(r["final_slot_error_m"] <= THROUGH_M for r in passage),
             f"{sum(r['final_slot_error_m'] <= THROUGH_M for r in passage)}/{len(passage)}"),
            ("never within 0.5 m of the person", not near, f"{len(near)} episodes"),
            ("the person re-found in >= 95 % of the episodes with a chance",
             refound >= 0.95 * len(chances) if chances else None,
             f"{refound}/{len(chances)}" if chances else "no episode lost the person"),
        ]:
            mark = "n/a " if good is None else "PASS" if good else "MISS"
            print(f"  {mark}  {text}: {value}")


def _refound(rows: list[dict]) -> str:
    """Episodes whose every loss with a chance was re-found, of those with a chance."""
    chances = [r for r in rows if r["person_refind_chances"] > 0]
    ok = sum(r["person_refinds"] >= r["person_refind_chances"] for r in chances)
    return f"{ok}/{len(chances)}"


def _median(values) -> float:
    return float(np.nanmedian(list(values)))


if __name__ == "__main__":
    main()
