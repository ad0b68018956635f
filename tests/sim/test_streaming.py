"""A long episode in bounded memory: the log comes in blocks (episode_blocks, stream_one), the
metrics and the soak's summary are kept block by block, and the blocks add up to exactly the
log of a run in memory."""

import gc
import math
import tracemalloc
import weakref
from dataclasses import replace

import numpy as np
import pytest

from companion import metrics
from companion.apps.logfile import LogCsv, Thinned
from companion.params import REALISTIC
from companion.sim import soak
from companion.sim.person import Move, ScriptedWalk, integrate_move
from companion.sim.runner import run_one, stream_one
from companion.sim.scenario import load_scenario
from companion.types import LOG_COLUMNS, Log


def blocks_of(log: Log, sizes):
    """``log`` cut into consecutive blocks of the given sizes (the rest in one block)."""
    out, start = [], 0
    for size in sizes:
        out.append(Log({k: a[start:start + size] for k, a in log.columns.items()}))
        start += size
    out.append(Log({k: a[start:] for k, a in log.columns.items()}))
    return [b for b in out if len(b)]


def same_metrics(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key, x in a.items():
        if isinstance(x, float):
            assert x == pytest.approx(b[key], rel=1e-12, abs=1e-15), key
        elif isinstance(x, dict):
            same_metrics(x, b[key])
        else:
            assert x == b[key], key


@pytest.fixture(scope="module")
def corridor():
    """A run past walls and pillars with realistic sensing (degraded statuses, reasons)."""
    sc = load_scenario("corridor")
    spec = sc.episode()
    return replace(spec, params=spec.params.replace(sensing=REALISTIC), duration=20.0, seed=4)


def test_the_blocks_join_to_the_log_of_a_run_in_memory(corridor):
    whole = run_one(corridor)
    blocks = list(stream_one(corridor, rows=37))
    assert [len(b) for b in blocks] == [37] * (len(whole) // 37) + [len(whole) % 37]
    assert Log.concat(blocks).equals(whole)
    assert len(set(whole["status"])) > 1            # not a vacuous comparison of texts


@pytest.mark.parametrize("sizes", [[1], [37] * 20, [1, 1, 2, 3, 5, 8, 13, 21, 34, 55, 89]])
def test_metrics_kept_block_by_block_are_those_of_the_whole_log(corridor, sizes):
    whole = run_one(corridor)
    running = metrics.Running()
    for block in blocks_of(whole, sizes):
        running.add(block)
    m = running.value()
    same_metrics(m, metrics.compute(whole))
    assert m["min_obstacle_clearance_m"] is not None and m["share_ok"] < 1.0


def synthetic(rho_e, rho_ob):
    n = len(rho_e)
    cols = {c: np.zeros(n) for c in LOG_COLUMNS}
    cols["t"] = np.arange(n) * 0.05
    cols["rho"] = 1.0 + np.asarray(rho_e, float)
    cols["rho_d"][:] = 1.0
    cols["robot_y"][:] = 1.0
    cols["rho_ob"] = np.asarray(rho_ob, float)
    return Log(cols)


def test_settling_and_contacts_across_every_block_boundary():
    rho_e = np.r_[np.full(6, 0.5), np.full(3, 0.001), np.full(2, 0.5), np.full(7, 0.001)]
    rho_ob = np.r_[0.3, -0.1, -0.1, 0.2, -0.1, np.full(6, 0.4), -0.2, -0.2, np.full(5, np.nan)]
    log = synthetic(rho_e, rho_ob)
    whole = metrics.compute(log)
    assert whole["settling_time_s"] == pytest.approx(11 * 0.05)
    assert whole["obstacle_collisions"] == 3
    for cut in range(1, len(log)):
        for sizes in ([cut], [cut, 1], [1] * cut):
            running = metrics.Running()
            for block in blocks_of(log, sizes):
                running.add(block)
            same_metrics(running.value(), whole)
    never = synthetic(np.r_[np.zeros(5), 0.5], np.full(6, np.nan))
    running = metrics.Running()
    for block in blocks_of(never, [5]):
        running.add(block)
    assert running.value()["settling_time_s"] is None
    assert running.value()["min_obstacle_clearance_m"] is None


def test_soak_summary_block_by_block_is_that_of_the_whole_log():
    spec = soak.soak_episode(40.0, seed=2)
    whole = run_one(spec)
    summary = soak.Summary(spec.params)
    for block in stream_one(spec, rows=150):
        summary.add(block)
    got, expected = summary.value(), soak.summarize(whole, spec.params)
    same_metrics(got, expected)
    assert got["steps"] == 800 and got["finite"]


def test_the_scripted_walk_is_the_walk_integrated_on_its_grid():
    moves = [Move(2.0, 1.2), Move(0.7, 0.6, 1.5), Move(1.0, 0.0), Move(1.0, 0.0, math.pi),
             Move(3.0, 1.0, -0.3)]
    walk = ScriptedWalk((1.0, -2.0, 0.4), moves, accel=1.5, grid_step=0.02)
    rows = [(1.0, -2.0, 0.4, 0.0, 0.0)]
    for m in moves:
        rows += integrate_move(rows[-1], m, 1.5, 0.02)
    assert walk.duration == pytest.approx((len(rows) - 1) * 0.02)
    for k in [*range(len(rows) - 1), *range(len(rows) - 2, -1, -7)]:   # forwards and back
        h = walk.state(k * 0.02 + 0.01)
        a, b = rows[k], rows[k + 1]
        assert h.x == pytest.approx(0.5 * (a[0] + b[0]), abs=1e-12)
        assert h.v == pytest.approx(0.5 * (a[3] + b[3]), abs=1e-12)
        assert h.omega == b[4]
    end = walk.state(walk.duration + 1.0)
    assert (end.x, end.y, end.v) == (rows[-1][0], rows[-1][1], 0.0)


@pytest.mark.parametrize("limit, sizes", [(50, [7] * 100), (1000, [3, 500]), (1, [])])
def test_thinned_keeps_every_step_th_row_across_blocks(corridor, limit, sizes):
    whole = run_one(corridor)
    thinned = Thinned(len(whole), limit)
    for block in blocks_of(whole, sizes):
        thinned.add(block)
    kept = thinned.log()
    assert len(kept) <= max(limit, 1) and thinned.step == max(1, math.ceil(len(whole) / limit))
    for name in ("t", "robot_x", "status"):
        assert np.array_equal(kept[name], whole[name][::thinned.step])


def sinks(tmp_path, steps, limit):
    """What ``companion run --plot`` does with each block (commands._write_run)."""
    return LogCsv(tmp_path / "log.csv"), metrics.Running(), Thinned(steps, limit)


def test_no_block_is_kept_while_an_episode_streams_to_disk(tmp_path):
    spec = replace(load_scenario("figure8").episode(), duration=1000 * 0.05)
    out, running, thinned = sinks(tmp_path, 1000, 300)
    alive = []
    with out:
        for block in stream_one(spec, rows=50):
            out.log(block)
            running.add(block)
            thinned.add(block)
            alive.append(weakref.ref(block["t"].base))   # the block's array of numbers
            del block
    gc.collect()
    assert len(alive) == 20 and not any(ref() is not None for ref in alive)
    assert running.value()["steps"] == 1000 and len(thinned.log()) == 250


def test_memory_held_by_the_sinks_does_not_grow_with_the_blocks(tmp_path):
    """Memory held after 5 and after 40 blocks of 250 rows: a kept log would grow by 35
    blocks (about 1.9 MB of numbers alone); streamed, by less than a twentieth of that."""
    template = run_one(replace(load_scenario("figure8").episode(), duration=250 * 0.05))
    out, running, thinned = sinks(tmp_path, 40 * 250, 50)
    held = []
    tracemalloc.start()
    try:
        with out:
            for k in range(40):
                block = Log({**template.columns, "t": template["t"] + k * 12.5})
                out.log(block)
                running.add(block)
                thinned.add(block)
                del block
                held.append(tracemalloc.get_traced_memory()[0])
    finally:
        tracemalloc.stop()
    grown = held[-1] - held[4]
    assert grown < 0.05 * 35 * 250 * len(LOG_COLUMNS) * 8, (held[4], held[-1])
    assert running.value()["steps"] == 10000 and len(thinned.log()) == 50
