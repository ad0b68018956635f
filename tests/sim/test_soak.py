"""Soak: a random walker (stop-and-go, sharp turns, turnarounds) among pillars and walls.

The short run is part of the default suite; the simulated hour is marked ``slow``
(``pytest -m slow tests/sim/test_soak.py``, or ``companion soak``)."""

import numpy as np
import pytest

from companion.geometry import obstacle_arrays, path_clearance
from companion.params import Params
from companion.sim.soak import make_world, run_soak


def check(summary):
    assert summary["finite"]
    assert summary["person_collisions"] == 0
    assert summary["obstacle_collisions"] == 0
    assert summary["min_person_distance_m"] >= Params().keepout.protective_distance
    assert summary["min_obstacle_clearance_m"] > 0.0


def test_the_walker_keeps_its_margin_and_does_everything():
    world = make_world(seed=3, duration=600.0)
    t = np.arange(0.0, 600.0, 0.1)
    states = [world.person.state(x) for x in t]
    x, y = np.array([h.x for h in states]), np.array([h.y for h in states])
    assert path_clearance(x, y, obstacle_arrays(world.obstacles), 0.0) >= 1.2 - 1e-9
    v = np.array([h.v for h in states])
    w = np.array([h.omega for h in states])
    assert np.any(v == 0.0) and np.max(v) > 1.2             # stops and brisk walking
    assert np.any((v == 0.0) & (np.abs(w) > 3.0))           # turnarounds on the spot


@pytest.mark.parametrize("seed", [0, 1])
def test_short_soak(seed):
    summary, log = run_soak(180.0, seed=seed)
    check(summary)
    assert summary["share_ok"] > 0.8


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0])
def test_one_hour_soak(seed):
    summary, _ = run_soak(3600.0, seed=seed)
    check(summary)
