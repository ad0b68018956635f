"""How often does the tracker's check of reported velocities fire on honest reports?
(docs/sensing.md, "Reported velocities checked against the positions")

    python bench/motion_check.py [--walks N] [--duration S]

The fuzz's walker (starts, stops, sharp turns, turnarounds up to 2 m/s) walks ``--walks``
seeded routes of ``--duration`` s each; a detector reports its position, heading, speed and
turn rate with the noise it declares, at four settings (rate, position, heading and velocity
noise), and the tracker takes every detection. Prints, per setting, how many detections were
marked ``person_motion_inconsistent``: a false alarm each, since every report is honest.
"""

from __future__ import annotations

import argparse

import numpy as np

from companion.params import REALISTIC, Params
from companion.sim.fuzz import WALKER
from companion.sim.soak import random_walk
from companion.tracking.tracker import PersonTracker
from companion.types import PersonDetection

#: (rate Hz, position std m, heading std rad, speed and turn-rate std m/s, rad/s)
SETTINGS = ((10.0, 0.15, 0.1, 0.2), (20.0, 0.05, 0.05, 0.1), (30.0, 0.02, 0.02, 0.05),
            (50.0, 0.05, 0.05, 0.1))


def false_alarms(rate: float, pos: float, heading: float, vel: float, walks: int,
                 duration: float) -> tuple[int, int]:
    """(detections marked inconsistent, detections) over ``walks`` seeded walks."""
    params = Params()
    fired = total = 0
    for seed in range(walks):
        walk = random_walk(np.random.default_rng(seed), duration, (), 0.5, WALKER)
        tracker = PersonTracker(params.tracker, REALISTIC)
        noise = np.random.default_rng(seed + 1000)
        for k in range(int(duration * rate)):
            t = k / rate
            h = walk.state(t)
            e = noise.normal(size=5)
            d = PersonDetection(t, h.x + pos * e[0], h.y + pos * e[1],
                                covariance=(pos ** 2, 0.0, 0.0, pos ** 2),
                                heading=h.theta + heading * e[2], heading_std=heading,
                                speed=h.v + vel * e[3], turn_rate=h.omega + vel * e[4],
                                velocity_std=(vel, vel))
            reasons: list[str] = []
            tracker.add([d], t, reasons=reasons)
            fired += "person_motion_inconsistent" in reasons
            total += 1
    return fired, total


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--walks", type=int, default=20)
    ap.add_argument("--duration", type=float, default=120.0)
    args = ap.parse_args()
    for rate, pos, heading, vel in SETTINGS:
        fired, total = false_alarms(rate, pos, heading, vel, args.walks, args.duration)
        print(f"{rate:g} Hz, position {pos:g} m, heading {heading:g} rad, velocity {vel:g}: "
              f"{fired} of {total} detections marked inconsistent", flush=True)


if __name__ == "__main__":
    main()
