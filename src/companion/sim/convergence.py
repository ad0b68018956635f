"""The multi-start convergence experiment of the paper's Fig. 3.

The person starts at (3, 3) and walks along +x. The robot starts at each of (3, 6), (0, 5),
(0, 3), (0, 1), (3, 0) with headings 0, pi/2, -pi/2, pi, and accompanies on the left if it
starts above y = 3, on the right if below, and on both sides (two runs) from (0, 3).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from companion.params import LEFT, RIGHT, Params
from companion.sim.person import line
from companion.sim.runner import EpisodeSpec
from companion.types import Pose

PERSON_START = (3.0, 3.0, 0.0)
STARTS = ((3.0, 6.0), (0.0, 5.0), (0.0, 3.0), (0.0, 1.0), (3.0, 0.0))
HEADINGS = (0.0, 0.5 * math.pi, -0.5 * math.pi, math.pi)
SPEEDS = (0.5, 1.0)
#: The paper's formation: its fixed bearing, on the side the robot starts on.
PAPER = {"formation": {"policy": "fixed"}}


@dataclass(frozen=True)
class Case:
    speed: float   # person speed (m/s)
    start: Pose    # robot start
    side: str      # "left" or "right"

    @property
    def label(self) -> str:
        return f"({self.start.x:g}, {self.start.y:g})"


def cases(speeds: Sequence[float] = SPEEDS) -> Iterator[Case]:
    """All Fig. 3 cases: 5 starts x 4 headings, both sides from (0, 3), for each speed."""
    for speed in speeds:
        for x, y in STARTS:
            sides = ("left",) if y > PERSON_START[1] else ("right",) if y < PERSON_START[1] \
                else ("left", "right")
            for side in sides:
                for heading in HEADINGS:
                    yield Case(speed, Pose(x, y, heading), side)


def episode(case: Case, controller: str, params: Params, duration: float = 30.0
            ) -> EpisodeSpec:
    """The runner's episode of one case."""
    bearing = LEFT if case.side == "left" else RIGHT
    p = dataclasses.replace(params, formation=dataclasses.replace(
        params.formation, bearing=bearing, policy=PAPER["formation"]["policy"]))
    return EpisodeSpec(controller, line(PERSON_START, case.speed), p, duration,
                       start=case.start)


CSV_COLUMNS = ("person_speed_mps", "start_x_m", "start_y_m", "start_theta_rad", "side",
               "settling_time_s", "min_person_distance_m")


def csv_row(case: Case, m: dict) -> tuple:
    """One row of :data:`CSV_COLUMNS` (settling time empty when the run never settles)."""
    settle = m["settling_time_s"]
    return (case.speed, case.start.x, case.start.y, case.start.theta, case.side,
            "" if settle is None else settle, m["min_person_distance_m"])
