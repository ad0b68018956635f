"""Fig. 3 acceptance: all 48 multi-start runs settle within 20 s, never closer than 0.5 m."""

import pytest

from companion import metrics
from companion.params import Params
from companion.sim import convergence
from companion.sim.runner import run_many, run_one
from companion.types import Pose

CASES = list(convergence.cases())


@pytest.fixture(scope="module")
def results():
    """Metrics of every case, run through the runner's worker processes."""
    specs = [convergence.episode(case, "lqr", Params(), duration=30.0) for case in CASES]
    return dict(zip(CASES, run_many(specs, workers=2, summarize=metrics.compute)))


def test_grid_has_48_cases():
    assert len(CASES) == 48
    assert sum(c.start.y == 3.0 for c in CASES) == 16  # both sides from (0, 3)


@pytest.mark.parametrize("case", CASES,
                         ids=lambda c: f"{c.speed}-{c.label}-{c.start.theta:.2f}-{c.side}")
def test_settles_and_keeps_distance(case, results):
    m = results[case]
    assert m["settling_time_s"] is not None and m["settling_time_s"] <= 20.0, m
    assert m["min_person_distance_m"] >= 0.5, m
    assert m["finite"]


def test_paper_literal_design_does_not_converge_from_behind():
    """docs/model.md R5: linearising only at the desired state fails from
    behind starts."""
    case = convergence.Case(1.0, Pose(0.0, 3.0, 0.0), "left")
    m = metrics.compute(run_one(convergence.episode(case, "lqr-paper", Params(), 30.0)))
    assert m["settling_time_s"] is None
