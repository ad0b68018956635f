"""Batch runner: same metrics as the single-episode simulator, in order, any worker count."""

import math

import pytest

from companion.control.base import Pose
from companion.errors import ConfigError
from companion.params import Params
from companion.sim.batch import EpisodeSpec, run_batch, run_one
from companion.sim.episode import SensorNoise
from companion.sim.person import Figure8, line


def specs():
    p = Params()
    noise = SensorNoise(position=0.02, heading=0.02)
    out = []
    for i, name in enumerate(["lqr", "pid", "vsm", "ic", "lqr-paper", "lqr"]):
        person = Figure8(lap_time=60.0, phase=0.3 * i) if i % 2 else line((0.0, 0.0, 0.0), 1.0)
        start = None if i % 3 == 0 else Pose(-0.5 * i, -1.0, 0.1 * i)
        out.append(EpisodeSpec(name, person, p, 6.0, start=start, seed=i, noise=noise))
    return out


def same(a, b, tol=1e-9):
    """Metric dicts equal: floats to ``tol``, everything else exactly."""
    assert a.keys() == b.keys()
    for key in a:
        x, y = a[key], b[key]
        if isinstance(x, dict):
            same(x, y, tol)
        elif isinstance(x, float) and isinstance(y, float):
            assert (math.isnan(x) and math.isnan(y)) or abs(x - y) <= tol, key
        else:
            assert x == y, key


def test_batch_in_workers_equals_single_episodes_in_order():
    batch = specs()
    expected = [run_one(s) for s in batch]
    seen = []
    got = run_batch(batch, workers=2, progress=seen.append)
    assert len(got) == len(expected)
    for a, b in zip(got, expected):
        same(a, b)
    assert seen == list(range(1, len(batch) + 1))
    # the episodes really differ (seeds, persons, starts, controllers)
    assert len({round(m["rmse_rho_m"], 9) for m in got}) == len(got)


def test_one_worker_runs_in_process():
    batch = specs()[:2]
    for a, b in zip(run_batch(batch, workers=1), [run_one(s) for s in batch]):
        same(a, b, tol=0.0)


@pytest.mark.parametrize("workers", [0, -1, 1.5])
def test_bad_worker_count(workers):
    with pytest.raises(ConfigError, match="workers: expected a positive integer"):
        run_batch(specs()[:1], workers=workers)
