"""Compiled batch of LQR episodes: the single-episode simulator's results, to 1e-9."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from companion import fastlqr
from companion.control.base import Pose
from companion.errors import ConfigError
from companion.kinematics import unicycle_step
from companion.obstacles import Circle
from companion.params import LqrParams, Params
from companion.sim.batch import EpisodeSpec, run_batch, run_one
from companion.sim.episode import SensorNoise
from companion.sim.fast_batch import BLOCK, remainder_2pi_nb, run_fast_batch, unicycle_step_nb
from companion.sim.person import Figure8, circle, line

from test_batch import same  # tests/sim is on sys.path (pytest prepend mode)


def varied_specs():
    """Episodes that differ in everything the batch supports."""
    base = Params()
    left = base.replace(formation=dataclasses.replace(base.formation, bearing=0.5 * math.pi))
    heavy = base.replace(lqr=dataclasses.replace(base.lqr, q=(50.0, 5.0, 10.0, 30.0, 30.0),
                                                 r=(10.0, 40.0)))
    zoh = base.replace(lqr=LqrParams(discretization="zoh"))
    persons = [Figure8(lap_time=60.0), line((0.0, 0.0, 0.3), 1.2),
               circle((1.0, 0.0, 0.0), 3.0, 0.8), Figure8(lap_time=45.0, phase=1.0)]
    noise = SensorNoise(position=0.02, heading=0.02, speed=0.02, turn_rate=0.02)
    specs = []
    for i in range(12):
        person = persons[i % 4]
        h0 = person.state(0.0)
        start = None if i % 3 == 0 else Pose(h0.x + 0.3 * (i % 5) - 0.6, h0.y - 1.2,
                                              h0.theta + 0.1 * i)
        specs.append(EpisodeSpec(["lqr", "lqr-paper", "lqr-tuned"][i % 3], person,
                                 [base, left, heavy, zoh][i % 4], 15.0, start=start, seed=i,
                                 noise=noise if i % 2 else SensorNoise(), stack=False))
    return specs


def with_solver(spec, solver):
    lqr = dataclasses.replace(spec.params.lqr, solver=solver)
    return dataclasses.replace(spec, params=spec.params.replace(lqr=lqr))


def test_compiled_batch_equals_the_single_episode_simulator():
    """The batch's gains (warm-started Newton) equal the single-episode controller's (cold
    doubling) to ~1e-12, so the metrics agree to 1e-9, except where the closed loop itself
    amplifies such differences: there the single-episode simulator with scipy's solver
    disagrees with the compiled one just as much. Such episodes are rare and excluded."""
    specs = varied_specs()
    got = run_fast_batch(specs, threads=2)
    sensitive = 0
    for spec, metrics in zip(specs, got):
        single = run_one(spec)
        reference = run_one(with_solver(spec, "scipy"))
        if abs(single["rmse_rho_m"] - reference["rmse_rho_m"]) > 1e-9:
            sensitive += 1
            continue
        same(metrics, single, tol=1e-9)
    assert sensitive <= 1
    # the episodes differ (so the order is checked too)
    assert len({round(m["rmse_rho_m"], 9) for m in got}) == len(got)


@pytest.mark.parametrize("name", ["pid", "vsm", "ic"])
def test_compiled_baselines_equal_their_classes(name):
    """Baseline lanes against PidController / VsmController / ImpedanceController in the
    single-episode simulator, over the same varied episodes, mixed with LQR lanes."""
    specs = [dataclasses.replace(s, controller=name) for s in varied_specs()]
    mixed = specs + varied_specs()[:2]
    got = run_fast_batch(mixed, threads=2)
    for spec, metrics in zip(specs, got):
        same(metrics, run_one(spec), tol=1e-9)


def test_auto_backend_picks_the_compiled_batch_and_processes_run_the_rest():
    specs = [varied_specs()[i] for i in (0, 1, 3)]              # not the sensitive one
    compiled = run_batch(specs, workers=1)                      # all supported: compiled
    processes = run_batch(specs, workers=1, backend="processes")
    for a, b in zip(compiled, processes):
        same(a, b, tol=1e-9)
    mixed = specs + [dataclasses.replace(specs[0], stack=True)]
    assert len(run_batch(mixed, workers=1)) == 4               # a stack: processes


def test_a_lane_does_not_depend_on_the_others():
    """Bit for bit: one thread or two, in a batch of twelve or alone."""
    specs = varied_specs()[:6]
    alone = run_fast_batch(specs[2:3], threads=1)[0]
    same(run_fast_batch(specs, threads=2)[2], alone, tol=0.0)
    for a, b in zip(run_fast_batch(specs, threads=1), run_fast_batch(specs, threads=2)):
        same(a, b, tol=0.0)


@pytest.mark.parametrize("change, message", [
    ({"controller": "mpc"}, "episode 0: the compiled batch cannot run it: controller 'mpc'"),
    ({"stack": True}, "standard stack"),
    ({"obstacles": (Circle(1.0, 1.0, 0.3),)}, "obstacles are not supported"),
    ({"params": Params().replace(lqr=LqrParams(solver="scipy"))}, "lqr.solver 'scipy'"),
])
def test_unsupported_specs_are_named(change, message):
    spec = dataclasses.replace(varied_specs()[0], **change)
    with pytest.raises(ConfigError, match=message):
        run_fast_batch([spec])
    with pytest.raises(ConfigError, match=message):
        run_batch([spec], backend="compiled")


def test_too_short_episode_and_bad_thread_count():
    spec = varied_specs()[0]
    with pytest.raises(ConfigError, match="episode 0: duration: expected at least one sample"):
        run_fast_batch([dataclasses.replace(spec, duration=0.01)])
    with pytest.raises(ConfigError, match="threads: expected a positive integer"):
        run_fast_batch([spec], threads=0)


def test_unknown_backend():
    with pytest.raises(ConfigError, match="backend: expected one of auto, compiled, processes"):
        run_batch(varied_specs()[:1], backend="gpu")


# -- building blocks ---------------------------------------------------------------------------

@settings(max_examples=300, deadline=None)
@given(st.floats(-50, 50), st.floats(-50, 50), st.floats(-20, 20), st.floats(-2, 2),
       st.floats(-3, 3), st.floats(0.001, 0.2))
def test_unicycle_twin_agrees(x, y, th, v, w, dt):
    np.testing.assert_allclose(unicycle_step_nb(x, y, th, v, w, dt),
                               unicycle_step(x, y, th, v, w, dt), rtol=1e-15, atol=1e-15)


@settings(max_examples=300, deadline=None)
@given(st.floats(-40, 40))
def test_remainder_twin_is_exact(theta):
    assert remainder_2pi_nb(theta) == math.remainder(theta, 2.0 * math.pi)


def lane_problems(n, seed, spread):
    """``n`` operating points near one another (a lane per point) with the cold solutions of
    a point ``spread`` away (the warm start) and of the point itself."""
    rng = np.random.default_rng(seed)
    a = np.empty((5, 5, n))
    b = np.empty((5, 2, n))
    p_warm = np.empty((5, 5, n))
    k_ref = np.empty((2, 5, n))
    q, r = np.array([25.0, 10.0, 25.0, 30.0, 30.0]), np.array([20.0, 20.0])
    for e in range(n):
        op = np.array([rng.uniform(0.5, 2.0), rng.uniform(0, 2 * math.pi),
                       rng.uniform(-0.5, 0.5), rng.uniform(0.3, 1.4), rng.uniform(-0.5, 0.5),
                       rng.uniform(0.3, 1.4), rng.uniform(-0.4, 0.4)])
        near = op + spread * rng.standard_normal(7)
        k = np.empty((2, 5))
        p = np.empty((5, 5))
        a_near, b_near = fastlqr.augmented_model(near[:3], near[3:5], near[5:], 0.25, 0.05,
                                                 False, 0.2)
        assert fastlqr.stabilising_gain(a_near, b_near, q, r, p, k)
        p_warm[:, :, e] = p
        a_op, b_op = fastlqr.augmented_model(op[:3], op[3:5], op[5:], 0.25, 0.05, False, 0.2)
        assert fastlqr.stabilising_gain(a_op, b_op, q, r, p, k)
        k_ref[:, :, e] = k
        a[:, :, e], b[:, :, e] = a_op, b_op
    return a, b, np.tile(q[:, None], (1, n)), np.tile(r[:, None], (1, n)), p_warm, k_ref


@pytest.mark.parametrize("spread", [1e-3, 3e-2])
def test_warm_newton_lanes_reach_the_cold_gain(spread):
    n = 32
    a, b, qd, rd, p, k_ref = lane_problems(n, seed=int(spread * 1e4), spread=spread)
    active = np.ones(n, np.bool_)
    corr = np.empty(n)
    proved = np.zeros(n, np.bool_)
    last_proved = np.zeros(n, np.bool_)
    for _ in range(fastlqr.LANES_MAX_STEPS):
        fastlqr.newton_lanes(a, b, qd, rd, p, active, n, corr, proved)
        last_proved[active] = proved[active]
        active &= corr > fastlqr.LANES_DONE
        if not active.any():
            break
    assert not active.any()
    k = np.empty((2, 5, n))
    fastlqr._gain_lanes(a, b, rd, p, k, n)
    scale = np.max(np.abs(k_ref), axis=(0, 1))
    assert np.max(np.max(np.abs(k - k_ref), axis=(0, 1)) / scale) < 1e-10
    assert last_proved.all()     # these closed loops have radius ~0.97: the squarings prove it


def test_newton_lanes_proves_stability_as_the_scalar_test():
    """With B = 0 the closed loop is A itself. A lane's proof uses the same squarings as the
    scalar test, so it proves only what the scalar test proves (the eigenvalues decide where
    the Smith doubling converged before a proof, lqr_lanes._cold); unstable lanes are never
    proved."""
    rng = np.random.default_rng(3)
    n = 40
    a = rng.standard_normal((5, 5, n)) * rng.uniform(0.05, 0.5, n)
    for e in range(0, n, 4):               # some lanes near or past the unit circle
        a[:, :, e] = np.diag(rng.uniform(0.9, 1.1, 5))
    b = np.zeros((5, 2, n))
    qd, rd = np.ones((5, n)), np.ones((2, n))
    p = np.zeros((5, 5, n))
    corr, proved = np.empty(n), np.zeros(n, np.bool_)
    fastlqr.newton_lanes(a, b, qd, rd, p, np.ones(n, np.bool_), n, corr, proved)
    bound = 1.0 - fastlqr.RADIUS_MARGIN
    scalar = [fastlqr._radius_status(a[:, :, e].copy(), bound, np.empty((5, 5)),
                                     np.empty((5, 5)), 5) for e in range(n)]
    radius = [float(np.max(np.abs(np.linalg.eigvals(a[:, :, e])))) for e in range(n)]
    for e in range(n):
        if proved[e]:
            assert scalar[e] == fastlqr.GAIN_STABLE and radius[e] < bound
        if radius[e] >= 1.0:
            assert not proved[e] and not corr[e] < np.inf
    stable = sum(s == fastlqr.GAIN_STABLE for s in scalar)
    assert 0.8 * stable <= proved.sum() < n


def test_lane_gains_stay_exact_after_a_long_straight_and_a_sudden_turn():
    """A lane that converged in one Newton step for many periods (straight walking) must not
    accept an unconverged gain when the operating point jumps (the person starts turning):
    every period's gain equals the cold gain of the lane's own model to 1e-9."""
    from companion.control.lqr_lanes import LaneSet, lane_params, step_lanes
    from companion.model import robot_pose_at

    params = Params()
    rows = lane_params([params])
    q, r = rows.q_diag, rows.r_diag
    lanes = LaneSet(np.zeros(1, np.int64), 1, rows)
    f, d, dt = params.formation, params.robot.d, params.dt
    hx, hy, hth, v = 0.0, 0.0, 0.0, 1.0
    worst = 0.0
    for period in range(360):
        # turning first (the lane measures its quadratic-convergence ratio), then straight
        # for 15 s (one Newton step a period), then a sudden turn
        omega = 0.3 * math.sin(0.5 * period) if period < 30 else (0.0 if period < 330 else 0.6)
        rx, ry, rth = robot_pose_at(f.distance, f.bearing, 0.05, hx, hy, hth, d)
        lanes.observed[0] = (hx, hy, hth, v, omega)
        lanes.pose[0] = (rx + (0.01 * math.sin(0.3 * period) if period < 30 else 0.0), ry, rth)
        step_lanes(lanes, rows)
        a = np.ascontiguousarray(lanes.a[0, :, :, 0])
        b = np.ascontiguousarray(lanes.b[0, :, :, 0])
        k, p = np.empty((2, 5)), np.empty((5, 5))
        assert fastlqr.stabilising_gain(a, b, q[0], r[0], p, k)
        worst = max(worst, float(np.max(np.abs(lanes.gain[0] - k)) / np.max(np.abs(k))))
        hx, hy, hth = hx + v * dt * math.cos(hth), hy + v * dt * math.sin(hth), hth + omega * dt
    assert worst <= 1e-9


@pytest.mark.parametrize("episodes, duration, noisy, restarts", [(2, 1.0, True, False),
                                                                 (8, 2.0, False, True)])
def test_lanes_start_from_the_rest_solution_without_the_scalar_solver(
        monkeypatch, episodes, duration, noisy, restarts):
    """Lanes without a previous solution start Newton from their rest solution; lanes that
    need more than the block's steps go on gathered (``_solve_on``); lanes whose start does
    not stabilise their model restart from the doubling (``sda_nb``). On the benchmark's
    first batch (figure-8, noisy, starts off the slot) no lane restarts; on 8 clean episodes
    some do in their first periods. No lane needs the scalar cold solver, and every lane's
    gain equals the cold gain of its model."""
    from companion.benchmark import batch_specs
    from companion.control import lqr_lanes
    from companion.sim.scenario import load_scenario

    cold, gathered, worst, sda = [], [], [0.0], []
    solve_on, control, sda_nb = lqr_lanes._solve_on, lqr_lanes._control, lqr_lanes.sda_nb
    sets = []
    init = lqr_lanes.LaneSet.__init__

    def record_init(self, *args):
        init(self, *args)
        sets.append(self)

    def record_solve_on(L, lanes, steps):
        gathered.append(lanes.size)
        solve_on(L, lanes, steps)

    def check_control(idx, config, gain, *args):
        L = sets[-1]
        if L.block != BLOCK:      # compile_kernels' dummy lane (first batch of a new cache)
            return control(idx, config, gain, *args)
        for lane in np.flatnonzero(idx >= 0):
            blk, j = divmod(int(lane), L.block)
            a = np.ascontiguousarray(L.a[blk, :, :, j])
            b = np.ascontiguousarray(L.b[blk, :, :, j])
            k, p = np.empty((2, 5)), np.empty((5, 5))
            assert fastlqr.stabilising_gain(a, b, L.qd[blk, :, j].copy(),
                                            L.rd[blk, :, j].copy(), p, k)
            worst[0] = max(worst[0], float(np.max(np.abs(gain[lane] - k)) / np.max(np.abs(k))))
        return control(idx, config, gain, *args)

    monkeypatch.setattr(lqr_lanes.LaneSet, "__init__", record_init)
    monkeypatch.setattr(lqr_lanes, "_solve_on", record_solve_on)
    monkeypatch.setattr(lqr_lanes, "_control", check_control)
    monkeypatch.setattr(lqr_lanes, "stabilising_gain",
                        lambda *args: cold.append(1) or fastlqr.stabilising_gain(*args))
    monkeypatch.setattr(lqr_lanes, "sda_nb", lambda *args: sda.append(sda_nb(*args)) or sda[-1])
    run_fast_batch(batch_specs(load_scenario("figure8"), episodes, duration, noisy=noisy),
                   threads=1)
    assert cold == [] and len(gathered) >= 1
    assert (len(sda) > 0 and all(sda)) if restarts else sda == []
    assert worst[0] <= 1e-9


def test_stop_and_go_person_equals_the_single_episode_simulator():
    """A person who stands, walks, turns on the spot and stands again: at rest the heading
    mode is uncontrollable, so lanes find no stabilising gain (the doubling restart fails and
    the lane keeps its last gain or the rest gain), and the restarts run each time the
    person sets off. The batch follows run_one to 1e-9."""
    from companion.sim.person import Move, ScriptedWalk

    person = ScriptedWalk((0.0, 0.0, 0.0), [Move(2.0, 0.0), Move(3.0, 1.0), Move(1.5, 0.0, 1.0),
                                            Move(3.0, 0.8, 0.3), Move(2.0, 0.0)])
    specs = [EpisodeSpec(name, person, Params(), 12.0, start=start, stack=False)
             for name in ("lqr", "lqr-paper", "lqr-tuned")
             for start in (None, Pose(0.5, -1.5, 0.3))]
    for spec, batch in zip(specs, run_fast_batch(specs, threads=1)):
        same(batch, run_one(spec), tol=1e-9)
