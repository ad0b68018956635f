"""The one runner of many episodes (companion.sim.runner): worker processes give the same logs
as one-at-a-time runs, for every kind of episode."""

import pytest

from companion import metrics
from companion.errors import ConfigError
from companion.params import REALISTIC, Params
from companion.sim.faults import Fault
from companion.sim.person import Figure8, line
from companion.sim.runner import EpisodeSpec, run_many, run_one
from companion.sim.scenario import load_scenario
from companion.types import Circle, Pose

P = Params()


def specs():
    fig4 = load_scenario("fig4")
    return [
        EpisodeSpec("lqr", Figure8(60.0), P, 6.0, start=Pose(5.5, 1.5, 0.3)),
        EpisodeSpec("pid", line((0.0, 0.0, 0.0), 1.0), P.replace(sensing=REALISTIC), 4.0,
                    seed=3),
        EpisodeSpec("vsm", line((0.0, 0.0, 0.0), 1.0), P, 4.0,
                    faults=(Fault("person_dropout", 1.0, 2.0),)),
        EpisodeSpec("ic", Figure8(60.0), P, 5.0, obstacles=(Circle(5.5, 2.0, 0.2),)),
        fig4.episode("lqr-paper", obstacle_source="lidar"),
    ]


def test_worker_processes_give_the_logs_of_one_at_a_time_runs():
    alone = [run_one(s) for s in specs()]
    done = []
    parallel = run_many(specs(), workers=2, progress=done.append)
    assert len(parallel) == len(alone)
    for a, b in zip(alone, parallel):
        assert a.equals(b)
    assert done == list(range(1, len(alone) + 1))
    # the runs differ from each other: the comparison is not vacuous
    assert not alone[0].equals(alone[3])


def test_summaries_are_made_in_the_workers():
    rows = run_many(specs()[:3], workers=2, summarize=metrics.compute)
    assert [r["steps"] for r in rows] == [120, 80, 80]
    assert rows[2]["share_stopped"] > 0.0          # the dropout stopped the robot


def test_the_same_seed_gives_the_same_noise_and_another_seed_does_not():
    noisy = specs()[1]
    a, b = run_one(noisy), run_one(noisy)
    assert a.equals(b)
    other = run_one(EpisodeSpec(**{**noisy.__dict__, "seed": 4}))
    assert not a.equals(other)


@pytest.mark.parametrize("workers", [0, -1, 1.5, True])
def test_bad_worker_counts_are_named(workers):
    with pytest.raises(ConfigError, match="workers: expected a positive integer"):
        run_many(specs()[:1], workers=workers)


def test_unknown_controller_and_obstacle_source_are_named():
    with pytest.raises(ConfigError, match="unknown controller 'lqrr'; did you mean 'lqr'"):
        run_one(EpisodeSpec("lqrr", line((0, 0, 0), 1.0), P, 1.0))
    with pytest.raises(ConfigError, match="obstacle_source: expected one of truth, lidar"):
        run_one(EpisodeSpec("lqr", line((0, 0, 0), 1.0), P, 1.0, obstacle_source="radar"))
