"""One tuning procedure and budget for every controller (``companion tune``).

Procedure: seeded random search. Candidate 0 is the controller's current gains; the other
``budget - 1`` candidates are drawn log-uniformly inside the box :data:`SPACES` gives for the
controller. Each candidate runs the three tuning scenarios of :func:`tuning_scenarios`, which
are *not* evaluation scenarios (those are the straight line at 1 m/s, the 3 m circle, the
figure-8, Fig. 3, Fig. 4 and Fig. 7), and scores

    J = mean over scenarios of (RMSE rho / 0.05 m + RMSE alpha / 0.05 rad)

plus 100 per scenario that comes closer than 0.5 m to the person or produces a non-finite
value. The candidate with the lowest J wins. Every controller gets the same budget (default 64
candidates) and the same scenarios, so none is favoured.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from companion import metrics
from companion.evaluate.tuning import SPACES, Dim, apply, current
from companion.params import Params
from companion.sim.person import PersonMotion, Segment, SegmentPath, circle, line
from companion.sim.runner import EpisodeSpec, run_many
from companion.types import Pose


@dataclass(frozen=True)
class TuningCase:
    name: str
    person: PersonMotion
    duration: float
    start: Pose | None
    bearing: float


def tuning_scenarios() -> list[TuningCase]:
    """Three scenarios unlike the evaluation ones: a 4 m circle to the right at 0.8 m/s (robot
    outside), an S-curve with speed changes, and a catch-up from 1.5 m behind the slot."""
    s_curve = SegmentPath((0.0, 0.0, 0.0), [
        Segment(4.0, 0.5, 1.2), Segment(6.0, 1.2, 1.2, 0.35), Segment(6.0, 1.2, 0.8, -0.35),
        Segment(4.0, 0.8, 0.8)])
    return [
        TuningCase("circle-4m-right", circle((0.0, 0.0, 0.0), 4.0, 0.8, "right"), 30.0, None,
                   0.5 * math.pi),
        TuningCase("s-curve", s_curve, 20.0, None, 1.5 * math.pi),
        TuningCase("catch-up", line((0.0, 0.0, 0.0), 0.8), 25.0, Pose(-1.75, 1.0, 0.0),
                   0.5 * math.pi),
    ]


def episodes(controller: str, params: Params, cases: Sequence[TuningCase]
             ) -> list[EpisodeSpec]:
    """The runner's episodes of ``params`` on the tuning cases."""
    return [EpisodeSpec(controller, case.person,
                        dataclasses.replace(params, formation=dataclasses.replace(
                            params.formation, bearing=case.bearing)),
                        case.duration, start=case.start) for case in cases]


def case_score(m: dict) -> float:
    """One case's term of J from its metrics: the normalised RMSE, plus 100 if the robot came
    closer than 0.5 m to the person or a value was not finite."""
    j = m["rmse_rho_m"] / 0.05 + m["rmse_alpha_rad"] / 0.05
    if not m["finite"] or not math.isfinite(j) or m["min_person_distance_m"] < 0.5:
        j = 100.0 + (j if math.isfinite(j) else 0.0)
    return j


def score(controller: str, params: Params, cases: Sequence[TuningCase],
          workers: int | None = 1) -> float:
    """The tuning objective J (module docstring) of ``params`` for ``controller``."""
    results = run_many(episodes(controller, params, cases), workers, summarize=metrics.compute)
    return sum(case_score(m) for m in results) / len(cases)


@dataclass(frozen=True)
class TuneResult:
    controller: str
    dims: tuple[Dim, ...]
    best: tuple[float, ...]
    best_score: float
    start_score: float
    evaluations: int


def tune(controller: str, params: Params = Params(), budget: int = 64, seed: int = 0,
         workers: int | None = None, progress: Callable[[int], None] | None = None
         ) -> TuneResult:
    """Seeded random search (module docstring) with ``budget`` candidates, every episode
    through the runner in ``workers`` processes (``progress``: episodes done)."""
    dims = SPACES[controller]
    cases = tuning_scenarios()
    rng = np.random.default_rng(seed)
    lows = np.log([d.low for d in dims])
    highs = np.log([d.high for d in dims])
    candidates = [current(params, dims)] + [list(np.exp(rng.uniform(lows, highs)))
                                            for _ in range(budget - 1)]
    specs = [spec for c in candidates
             for spec in episodes(controller, apply(params, dims, c), cases)]
    results = run_many(specs, workers, summarize=metrics.compute, progress=progress)
    n = len(cases)
    scores = [sum(case_score(m) for m in results[i:i + n]) / n
              for i in range(0, len(results), n)]
    best = int(np.argmin(scores))
    return TuneResult(controller, dims, tuple(candidates[best]), scores[best], scores[0],
                      budget)
