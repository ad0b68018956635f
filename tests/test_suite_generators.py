"""Suite generators run by the one engine: a row function of their own, results in the
suite's order whatever the backend, and the fuzz's plan and the soak resumed from what a
killed run kept."""

import dataclasses
import json
import math

import pytest

from companion.evaluate import fuzz_runs
from companion.evaluate.generators import scenario_episodes, soak_suite, suite_of
from companion.evaluate.run import PARTIAL, run_results, run_suite
from companion.params import Params
from companion.sim import fuzz, soak
from companion.sim.runner import run_one


def steps_and_seed(spec):
    """A row function of the test's own: the episode's length and its noise seed."""
    return {"steps": len(run_one(spec)), "seed": spec.seed, "controller": spec.controller}


def test_a_generated_suite_gives_its_own_rows_in_suite_order(tmp_path):
    """Episodes of differing lengths, so that two workers finish them out of order: the rows
    keep the suite's order, hold what the row function gives, and equal one process's."""
    episodes = [*scenario_episodes("circle", ["pid"]), *scenario_episodes("line", ["lqr"]),
                *scenario_episodes("fig7", ["vsm"], obstacles="lidar")]
    episodes = [dataclasses.replace(e, spec=dataclasses.replace(e.spec, duration=d))
                for e, d in zip(episodes, (6.0, 1.0, 3.0))]
    suite = suite_of("mine", episodes, steps_and_seed)
    assert [e.key for e in suite.episodes] == ["circle:scenario:scenario:pid:0",
                                               "line:scenario:scenario:lqr:0",
                                               "fig7+lidar:scenario:scenario:vsm:0"]
    assert suite.reference == "pid"
    two = run_results(suite, None, workers=2)
    assert two == [{"steps": 120, "seed": 0, "controller": "pid"},
                   {"steps": 20, "seed": 0, "controller": "lqr"},
                   {"steps": 60, "seed": 0, "controller": "vsm"}]
    rows = run_suite(suite, tmp_path / "o", workers=1)       # kept: JSON, the same rows
    assert [r["steps"] for r in rows] == [120, 20, 60]
    assert [r["episode"] for r in rows] == [e.key for e in suite.episodes]
    header = (tmp_path / "o" / PARTIAL / "episodes.jsonl").read_text().splitlines()[0]
    assert "test_suite_generators.steps_and_seed" in json.loads(header)["digest"]
    with pytest.raises(ValueError, match="two episodes share a key"):
        suite_of("twice", [*episodes, episodes[0]])


def _plain(counts):
    return [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in c.items()}
            for c in counts]


def test_a_killed_fuzz_resumes_and_gives_the_uninterrupted_counts(tmp_path):
    """The fuzz's plan as a suite of counts: a run stopped after two episodes keeps them in
    --out, and the next call runs only the others (here on a two-worker Dask cluster, the
    row function a partial of the fuzz's parameters) for the counts of an uninterrupted
    run; other parameters are another suite and start over."""
    episodes = fuzz.plan(3000, 4, ("lqr", "pid"), ("ideal",))
    assert len(episodes) >= 4
    cases, whole = fuzz_runs.run(episodes, 1)
    assert [c.seed for c in cases] == [s for s, _, _ in episodes]
    assert whole[0] == fuzz_runs.replay(*episodes[0])[1]

    def stop_after_two(done):
        if done == 2:
            raise KeyboardInterrupt
    with pytest.raises(KeyboardInterrupt):
        fuzz_runs.run(episodes, 1, stop_after_two, out=tmp_path)
    first = []
    dask = "local" if _has_dask() else None
    again, resumed = fuzz_runs.run(episodes, 2, first.append, out=tmp_path, dask=dask)
    assert first[0] == 2 and again == cases
    assert _plain(resumed) == _plain(whole)
    suite, _ = fuzz_runs.fuzz_suite(episodes)
    cautious = Params().replace(keepout=dataclasses.replace(Params().keepout,
                                                            evasive_horizon_s=2.0))
    other, _ = fuzz_runs.fuzz_suite(episodes, base=cautious)
    assert other.digest != suite.digest


def _has_dask():
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def test_the_soak_as_a_suite_gives_the_summary_of_its_whole_log(tmp_path):
    suite = soak_suite(30.0, seed=2)
    (result,) = run_results(suite, tmp_path, workers=1)
    spec = suite.episodes[0].spec
    assert result == soak.summarize(run_one(spec), spec.params)
    assert result["steps"] == 600
