"""Compiled batch simulation: many episodes at once, metrics only.

What one episode is: exactly :func:`companion.sim.episode.run_episode` with a bare registered
controller (``lqr``, ``lqr-paper``, ``lqr-tuned``, ``pid``, ``vsm`` or ``ic`` of
:data:`companion.control.CONTROLLERS`, without the avoidance layer and the safety
supervisor), no obstacles, ground-truth or noisy person observations; and its metrics are
those of :func:`companion.metrics.compute`. The results agree with the single-episode
simulator to 1e-9 (``tests/sim/test_fast_batch.py``).

How: episodes are lanes. LQR lanes run :mod:`companion.control.lqr_lanes` (the Riccati
equations of 64 lanes solved together, SIMD); baseline lanes run
:mod:`companion.control.baseline_lanes`. The lanes are split between threads (one per CPU;
the kernels release the GIL). Only running sums for the metrics are kept, so memory does not
grow with the episode length beyond the person's path and sensor noise (5 numbers per step),
and episodes are processed in chunks of 2,048, so it does not grow with their number.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from typing import Sequence

import numpy as np
from numba import njit

from companion import _jitcache
from companion.control import CONTROLLERS, lqr_lanes
from companion.errors import ConfigError
from companion.control.baseline_lanes import KINDS, STATE_SIZE, BaselineLanes, baseline_config
from companion.control.lqr_lanes import LaneSet, step_lanes
from companion.fastlqr import (SDA_KERNELS, SOLVE_LANES_KERNELS, relative_state_nb, sda_nb,
                               slot_reference_nb, solve_lanes)
from companion.kinematics import unicycle_step
from companion.metrics import Tolerance
from companion.model import robot_pose_at, slot_reference
from companion.params import Params
from companion.sim.batch import default_workers
from companion.sim.episode import SensorNoise

#: Controllers the compiled batch runs (bare, see the module docstring).
LQR_FAMILY = ("lqr", "lqr-paper", "lqr-tuned")
SUPPORTED = LQR_FAMILY + tuple(KINDS)
#: Lanes per block: one block is one thread's unit of work.
BLOCK = 64
#: Episodes per chunk (bounds the memory of the per-step person noise).
CHUNK = 2048

_TWO_PI = 2.0 * math.pi

# Columns of the per-lane accumulator array.
_SQ_RHO, _SQ_ALPHA, _SQ_BETA, _SQ_V, _SQ_W, _MIN_DIST, _LAST_OUT, _FIN_RHO, _FIN_ALPHA, \
    _FIN_BETA, _FINITE = range(11)
_N_ACC = 11


#: :func:`companion.kinematics.unicycle_step`, compiled from the same source.
unicycle_step_nb = njit(cache=True, error_model="numpy")(unicycle_step)


@njit(cache=True, error_model="numpy")
def remainder_2pi_nb(theta):
    """``math.remainder(theta, 2*pi)`` (exact; round half to even)."""
    n = np.rint(theta / _TWO_PI)
    r = theta - n * _TWO_PI
    # theta / 2pi rounds; correct the quotient where that moved r outside [-pi, pi].
    if r > math.pi:
        r -= _TWO_PI
    elif r < -math.pi:
        r += _TWO_PI
    return r


@njit(cache=True, error_model="numpy")
def _wrap_metric(a):
    """:func:`companion.metrics.wrap`: to [-pi, pi) by Python's float modulo."""
    return (a + math.pi) % _TWO_PI - math.pi


_NB = {"cache": True, "nogil": True, "error_model": "numpy", "no_cfunc_wrapper": True}


@njit(**_NB)
def _observe(step, idx, person, pidx, noise, noisy, observed):
    """What each lane's controller observes at ``step``: the person, plus sensor noise."""
    for lane in range(idx.size):
        g = idx[lane]
        if g < 0:
            continue
        for i in range(5):
            observed[lane, i] = person[pidx[g], step, i]
        if noisy[g]:
            for i in range(5):
                observed[lane, i] += noise[g, step, i]


@njit(**_NB)
def _account(step, dt, idx, person, pidx, geo, vw, pose, tol, acc):
    """Per lane: the metrics' running sums against the true person, then the plant.
    ``geo`` rows: d, rho_d, alpha_d."""
    for lane in range(idx.size):
        g = idx[lane]
        if g < 0:
            continue
        d, rho_d, alpha_d = geo[g, 0], geo[g, 1], geo[g, 2]
        v, om = vw[lane, 0], vw[lane, 1]
        h = person[pidx[g], step]
        x, y, th = pose[lane, 0], pose[lane, 1], pose[lane, 2]
        rho, alpha, beta = relative_state_nb(x, y, th, h[0], h[1], h[2], d)
        beta_ref, _, _ = slot_reference_nb(h[3], h[4], rho_d, alpha_d, d)
        e_rho = rho - rho_d
        e_alpha = _wrap_metric(alpha - alpha_d)
        e_beta = _wrap_metric(beta)
        e_ref = _wrap_metric(beta - beta_ref)
        row = acc[g]
        row[_SQ_RHO] += e_rho * e_rho
        row[_SQ_ALPHA] += e_alpha * e_alpha
        row[_SQ_BETA] += e_beta * e_beta
        row[_SQ_V] += (v - h[3]) * (v - h[3])
        row[_SQ_W] += (om - h[4]) * (om - h[4])
        row[_MIN_DIST] = min(row[_MIN_DIST], math.hypot(x - h[0], y - h[1]))
        if not (abs(e_rho) < tol[0] and abs(e_alpha) < tol[1] and abs(e_ref) < tol[2]):
            row[_LAST_OUT] = step
        row[_FIN_RHO], row[_FIN_ALPHA], row[_FIN_BETA] = abs(e_rho), abs(e_alpha), abs(e_ref)
        if not (math.isfinite(v) and math.isfinite(om)):
            row[_FINITE] = 0.0
        x, y, th = unicycle_step_nb(x, y, th, v, om, dt)
        pose[lane, 0], pose[lane, 1], pose[lane, 2] = x, y, remainder_2pi_nb(th)


def unsupported(spec) -> str:
    """Why the compiled batch cannot run ``spec`` (empty string if it can)."""
    if spec.controller not in SUPPORTED:
        return f"controller {spec.controller!r} is not one of {', '.join(SUPPORTED)}"
    if spec.stack:
        return "the standard stack (avoidance layer and supervisor) is not compiled"
    if spec.obstacles:
        return "obstacles are not supported"
    if spec.controller in LQR_FAMILY and spec.params.lqr.solver != "compiled":
        return "lqr.solver 'scipy' is the single-episode reference; the batch is compiled"
    return ""


def _person_key(person) -> object:
    """Equal persons share one table of their path: the person itself where it is hashable
    (frozen dataclasses such as Figure8), else its identity."""
    try:
        hash(person)
    except TypeError:
        return ("id", id(person))
    return person


def _person_states(person, steps: int, dt: float) -> np.ndarray:
    out = np.empty((steps, 5))
    for k in range(steps):
        h = person.state(k * dt)
        out[k] = (h.x, h.y, h.theta, h.v, h.omega)
    return out


def _metrics(row: np.ndarray, steps: int, dt: float) -> dict:
    """The keys of :func:`companion.metrics.compute` from one lane's accumulators."""
    rms = [math.sqrt(row[i] / steps) for i in (_SQ_RHO, _SQ_ALPHA, _SQ_BETA, _SQ_V, _SQ_W)]
    last_out = int(row[_LAST_OUT])
    settle = None if last_out == steps - 1 else (last_out + 1) * dt
    finite = bool(row[_FINITE]) and math.isfinite(rms[0]) and math.isfinite(rms[1])
    return {
        "rmse_rho_m": rms[0], "rmse_alpha_rad": rms[1], "rmse_beta_rad": rms[2],
        "rmsv_v_mps": rms[3], "rmsv_omega_radps": rms[4],
        "min_person_distance_m": float(row[_MIN_DIST]),
        "settling_time_s": settle,
        "final_abs_error": {"rho_m": float(row[_FIN_RHO]), "alpha_rad": float(row[_FIN_ALPHA]),
                            "beta_rad": float(row[_FIN_BETA])},
        "duration_s": (steps - 1) * dt + dt if steps > 1 else 0.0,   # as metrics._duration
        "steps": steps,
        "min_obstacle_clearance_m": None, "obstacle_collisions": 0,
        "share_ok": 1.0, "share_degraded": 0.0, "share_stopped": 0.0,
        "finite": finite,
    }


def run_fast_batch(specs: Sequence, tol: Tolerance = Tolerance(), threads: int | None = None
                  ) -> list[dict]:
    """Metrics of every episode in ``specs`` (:class:`companion.sim.batch.EpisodeSpec` with
    ``stack=False``, a controller of :data:`SUPPORTED` and no obstacles), in order.

    Parameters
    ----------
    specs : sequence of EpisodeSpec
    tol : Tolerance
        Of the settling time, as in :func:`companion.metrics.compute`.
    threads : int, optional
        Threads that share the lanes (default: one per CPU this process may use).

    Raises
    ------
    ConfigError
        If a spec is not supported (see :func:`unsupported`) or shorter than one period,
        naming its index, or ``threads`` is not a positive integer.
    """
    for i, spec in enumerate(specs):
        reason = unsupported(spec)
        if reason:
            raise ConfigError(f"episode {i}: the compiled batch cannot run it: {reason}")
    threads = default_workers() if threads is None else threads
    if not isinstance(threads, int) or threads < 1:
        raise ConfigError(f"threads: expected a positive integer, got {threads!r}")
    out: list[dict | None] = [None] * len(specs)
    groups: dict[tuple[int, float], list[int]] = {}
    for i, spec in enumerate(specs):
        dt = spec.params.dt
        steps = int(round(spec.duration / dt))
        if steps < 1:
            raise ConfigError(f"episode {i}: duration: expected at least one sample period "
                              f"({dt:g} s), got {spec.duration:g} s")
        groups.setdefault((steps, dt), []).append(i)
    tolerance = np.array([tol.rho, tol.alpha, tol.beta])
    helper = sda_helper = None
    try:
        if not solve_lanes.signatures and any(s.controller in LQR_FAMILY for s in specs):
            # First LQR batch of this process: if the lanes' Riccati solver is not in the
            # cache yet, a helper process compiles it while this one compiles the other
            # kernels, and a second one, at a lower priority, the doubling that restarts
            # lanes whose iteration failed (most batches need it for a few lanes in their
            # first periods).
            helper = _jitcache.compile_in_helper(SOLVE_LANES_KERNELS, "companion.fastlqr",
                                                 "compile_solve_lanes")
            if helper is not None and not sda_nb.signatures:
                sda_helper = _jitcache.compile_in_helper(SDA_KERNELS, "companion.fastlqr",
                                                         "compile_sda", nice=10)
        for (steps, dt), members in groups.items():
            for c0 in range(0, len(members), CHUNK):
                chunk = members[c0:c0 + CHUNK]
                rows = _run_chunk([specs[i] for i in chunk], steps, dt, tolerance, threads,
                                  helper, sda_helper)
                helper = None
                for i, row in zip(chunk, rows):
                    out[i] = _metrics(row, steps, dt)
        _jitcache.wait_helper(sda_helper)   # let the doubling reach the cache for later batches
    finally:
        _jitcache.stop_helper(helper)
        _jitcache.stop_helper(sda_helper)
    return out  # type: ignore[return-value]


def _run_chunk(specs: Sequence, steps: int, dt: float, tol: np.ndarray, threads: int,
               helper=None, sda_helper=None) -> np.ndarray:
    """Metric accumulators of ``specs`` (one chunk of one length). ``helper`` compiles the
    lanes' solver (waited for before the first period), ``sda_helper`` the doubling of the
    lanes' restarts (waited for at the first restart); either may be None."""
    n = len(specs)
    persons: dict[object, int] = {}
    tables = []
    pidx = np.empty(n, np.int64)
    start = np.empty((n, 3))
    geo = np.empty((n, 3))
    base_config = np.zeros((n, 17))
    base_state = np.zeros((n, STATE_SIZE))
    lqr_rows: list[Params | None] = [None] * n
    noisy = np.zeros(n, np.bool_)
    noise = np.zeros((n, steps if any(s.noise != SensorNoise() for s in specs) else 1, 5))
    for e, spec in enumerate(specs):
        params = CONTROLLERS[spec.controller].adjust(spec.params)
        f, d = params.formation, params.robot.d
        geo[e] = (d, f.distance, f.bearing)
        key = _person_key(spec.person)
        if key not in persons:
            persons[key] = len(tables)
            tables.append(_person_states(spec.person, steps, dt))
        pidx[e] = persons[key]
        if spec.start is None:
            h0 = spec.person.state(0.0)
            start[e] = robot_pose_at(f.distance, f.bearing, 0.0, h0.x, h0.y, h0.theta, d)
            # run_episode tells the controller the slot velocity before the first step
            ref = slot_reference(h0.v, h0.omega, f.distance, f.bearing, d)
            base_state[e, :3] = (ref.v, ref.omega, 1.0)
        else:
            start[e] = (spec.start.x, spec.start.y, spec.start.theta)
        if spec.controller in LQR_FAMILY:
            lqr_rows[e] = params
        else:
            base_config[e] = baseline_config(spec.controller, params)
            if spec.controller == "pid":
                base_state[e] = 0.0       # PidController ignores a command before its first step
        if spec.noise != SensorNoise():
            noisy[e] = True
            sn = spec.noise
            noise[e] = np.random.default_rng(spec.seed).normal(size=(steps, 5)) * np.array(
                [sn.position, sn.position, sn.heading, sn.speed, sn.turn_rate])
    person = np.stack(tables)
    lane_params = lqr_lanes.lane_params(lqr_rows)
    acc = np.zeros((n, _N_ACC))
    acc[:, _MIN_DIST] = np.inf
    acc[:, _LAST_OUT] = -1.0
    acc[:, _FINITE] = 1.0
    shared = (person, pidx, noise, noisy, geo, tol, acc)
    is_lqr = np.array([s.controller in LQR_FAMILY for s in specs])
    tasks = []
    for family in (np.flatnonzero(is_lqr), np.flatnonzero(~is_lqr)):
        for part in np.array_split(family, min(threads, family.size)) if family.size else []:
            idx = _padded(part)
            if is_lqr[part[0]]:
                lanes = LaneSet(idx, BLOCK, lane_params)
                control = partial(step_lanes, lanes, lane_params)
            else:
                lanes = BaselineLanes(idx)
                lanes.state[:part.size] = base_state[part]
                control = partial(lanes.step, base_config)
            lanes.pose[:part.size] = start[part]
            tasks.append((lanes, control))
    if helper is not None:
        # Compile (or load) this process's kernels while the helper compiles the solver.
        lqr_lanes.compile_kernels()
        none = np.empty(0, np.int64)
        _observe(0, none, person, pidx, noise, noisy, np.empty((0, 5)))
        _account(0, dt, none, person, pidx, geo, np.empty((0, 2)), np.empty((0, 3)), tol, acc)
    _jitcache.wait_helper(helper)
    for lanes, _ in tasks:
        if isinstance(lanes, LaneSet):
            lanes.sda_helper = sda_helper
    if len(tasks) == 1:
        _drive(*tasks[0], steps, dt, shared)
    else:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            for future in [pool.submit(_drive, lanes, control, steps, dt, shared)
                           for lanes, control in tasks]:
                future.result()
    return acc


def _padded(part: np.ndarray) -> np.ndarray:
    """Episode indices padded with -1 to a whole number of blocks."""
    size = -(-part.size // BLOCK) * BLOCK
    out = np.full(size, -1, np.int64)
    out[:part.size] = part
    return out


def _drive(lanes, control, steps: int, dt: float, shared: tuple) -> None:
    """Run one set of lanes through every period (the kernels release the GIL)."""
    person, pidx, noise, noisy, geo, tol, acc = shared
    for step in range(steps):
        _observe(step, lanes.idx, person, pidx, noise, noisy, lanes.observed)
        control()
        _account(step, dt, lanes.idx, person, pidx, geo, lanes.vw, lanes.pose, tol, acc)
