"""The LQR controller step for many lanes (episodes or robots) at once, compiled.

Each lane is one :class:`companion.control.lqr.LqrController`: per sample period its relative
state, feedforward and linearisation (:func:`_prepare`; zero-order-hold lanes then
:func:`_zoh_models`), its Riccati equation (:func:`companion.fastlqr.solve_lanes`: Newton's
iteration from an extrapolation of the lane's previous solutions, or from the solution at
its rest operating point for a lane without one, for all lanes of a block at once,
vectorised by :func:`companion.fastlqr.newton_lanes`; lanes that need more steps go on
gathered into one block, :func:`_solve_on`; and the gains), a stability check
(:func:`_check`), a restart from the doubling for lanes whose iteration failed
(:func:`_sda_start`, then the gathered pass), the eigenvalues for converged lanes the check
could not prove stable and the scalar solver for lanes that fail after the restart
(:func:`_cold`), and the output (:func:`_control`). :class:`LaneParams` holds the per-row
parameters, :class:`LaneSet` the arrays; :func:`step_lanes` runs one period.

The batch simulator (:mod:`companion.sim.fast_batch`) runs sets of many lanes. A lane's result
does not depend on the other lanes of its set (a set of one gives the same bits). The gain
of a lane equals that of :meth:`companion.control.lqr.LqrController.gain` (cold doubling at
every period) to about 1e-11 relative (``tests/sim/test_fast_batch.py``), so a lane follows
the single-episode controller to that precision, except in closed loops that amplify such
differences (docs/performance.md).
"""

from __future__ import annotations

import subprocess
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from companion import _jitcache
from companion.control.lqr import reference_solution, rest_operating_point
from companion.fastlqr import (CONFIG_FIELDS, LANES_LONG_STEPS, LANES_MAX_STEPS,
                               LANES_UNFINISHED, RADIUS_MARGIN, lqr_step_config,
                               model_euler_nb, model_zoh_nb, relative_state_nb,
                               sda_nb, slot_reference_nb, solve_lanes, stabilising_gain,
                               wrap_pi_nb)
from companion.params import Params


_NB = {"cache": True, "nogil": True, "error_model": "numpy", "no_cfunc_wrapper": True}
#: Functions only called from compiled code: no Python wrapper to compile.
_INNER = {**_NB, "no_cpython_wrapper": True}


@njit(**_INNER)
def _to_lane(a2, b2, a, b, j):
    """Copy the model ``a2`` (5, 5), ``b2`` (5, 2) into lane ``j`` of a block's ``a``
    (5, 5, L) and ``b`` (5, 2, L)."""
    for r in range(5):
        for c in range(5):
            a[r, c, j] = a2[r, c]
        for c in range(2):
            b[r, c, j] = b2[r, c]


@njit(**_NB)
def _prepare(idx, observed, pose, config, mem, ref, err, lin, a, b, warm, rest_p, p, history,
             active):
    """Per lane: feedforward, errors, operating point and model from the observed person
    ``observed[lane]`` (x, y, theta, v, omega) and robot ``pose[lane]`` (x, y, theta); a lane
    without a previous solution (not ``warm``) starts from its row's ``rest_p``. Every lane
    in use becomes ``active``."""
    block = a.shape[3]
    a2, b2 = np.empty((5, 5)), np.empty((5, 2))
    for lane in range(idx.size):
        g = idx[lane]
        active[lane] = False
        if g < 0:
            continue
        c = config[g]
        hx, hy, hth = observed[lane, 0], observed[lane, 1], observed[lane, 2]
        hv, hw = observed[lane, 3], observed[lane, 4]
        d, rho_d, alpha_d = c[0], c[4], c[5]
        rho, alpha, beta = relative_state_nb(pose[lane, 0], pose[lane, 1], pose[lane, 2], hx,
                                             hy, hth, d)
        if c[6] != 0.0:
            beta_d, v_d, omega_d = slot_reference_nb(hv, hw, rho_d, alpha_d, d)
        else:
            beta_d, v_d, omega_d = 0.0, hv, hw
        ref[lane, 0], ref[lane, 1], ref[lane, 2] = v_d, omega_d, beta_d
        err[lane, 0] = rho - rho_d
        err[lane, 1] = wrap_pi_nb(alpha - alpha_d)
        err[lane, 2] = wrap_pi_nb(beta - beta_d)
        if c[7] != 0.0:
            op = (rho, alpha, beta, v_d + mem[lane, 0], omega_d + mem[lane, 1])
        else:
            op = (rho_d, alpha_d, beta_d, v_d, omega_d)
        lin[lane, 0], lin[lane, 1], lin[lane, 2], lin[lane, 3], lin[lane, 4] = op
        lin[lane, 5], lin[lane, 6] = hv, hw
        model_euler_nb(max(op[0], c[3]), op[1], op[2], op[3], op[4], hv, hw, d, c[1], a2, b2)
        blk, j = lane // block, lane % block
        _to_lane(a2, b2, a[blk], b[blk], j)
        if not warm[lane]:
            for r in range(5):
                for col in range(5):
                    p[blk, r, col, j] = rest_p[g, r, col]
            history[lane] = 0
        active[lane] = True


@njit(**_NB)
def _zoh_models(idx, config, lin, a, b):
    """Replace the forward-Euler model of :func:`_prepare` by the zero-order-hold one in the
    lanes whose controller asks for it (a separate kernel: the matrix exponential is compiled
    only when such a lane runs)."""
    block = a.shape[3]
    a2, b2 = np.empty((5, 5)), np.empty((5, 2))
    for lane in range(idx.size):
        g = idx[lane]
        if g < 0 or config[g, 2] == 0.0:
            continue
        c, op = config[g], lin[lane]
        model_zoh_nb(max(op[0], c[3]), op[1], op[2], op[3], op[4], op[5], op[6], c[0], c[1],
                     a2, b2)
        _to_lane(a2, b2, a[lane // block], b[lane // block], lane % block)


@njit(**_NB)
def _check(idx, k, corr, proved, active, retry, warm, history, gain, has_gain, need_cold):
    """For the lanes solved by :func:`companion.fastlqr.solve_lanes` (``active``, which
    this clears): accept a lane's gain if its Newton iteration converged and the squarings of
    its last Smith doubling proved the closed loop stable (``proved``, see
    :func:`companion.fastlqr.newton_lanes`). If ``retry``, a lane still iterating stays
    active for a longer solve; the number of such lanes is returned. Every other lane is
    flagged (``need_cold``) for :func:`_sda_start` (its iteration failed) or :func:`_cold`;
    ``need_cold`` of the lanes not active is left as it is. The proof concerns the gain the
    last Newton step started from, which differs from the accepted one by that step's
    correction (below 1e-9, or below 2e-6 and predicted below 1e-11, of P), against a margin
    of at least 1.7e-4 in spectral radius that the proof gives."""
    blocks, block = k.shape[0], k.shape[3]
    retries = 0
    for blk in range(blocks):
        for j in range(block):
            lane = blk * block + j
            if idx[lane] < 0 or not active[lane]:
                continue
            active[lane] = False
            need_cold[lane] = False
            if corr[blk, j] == 0.0 and proved[blk, j]:
                for r in range(2):
                    for c in range(5):
                        gain[lane, r, c] = k[blk, r, c, j]
                has_gain[lane] = True
                warm[lane] = True
                history[lane] = min(history[lane] + 1, 4)
            elif retry and corr[blk, j] == LANES_UNFINISHED:
                active[lane] = True
                retries += 1
            else:
                need_cold[lane] = True
    return retries


@njit(**_NB)
def _control(idx, config, gain, mem, ref, err, xi, vw):
    """Per lane: ``u = u_d + u_e(k-1) - K xi`` clipped to the input limits, into ``vw``;
    ``mem`` becomes ``u_e(k)`` of the saturated output and ``xi`` the augmented state."""
    for lane in range(idx.size):
        g = idx[lane]
        if g < 0:
            continue
        c = config[g]
        xi[lane, 0] = min(max(err[lane, 0], -c[8]), c[8])
        xi[lane, 1] = min(max(err[lane, 1], -c[9]), c[9])
        xi[lane, 2] = min(max(err[lane, 2], -c[10]), c[10])
        xi[lane, 3] = mem[lane, 0]
        xi[lane, 4] = mem[lane, 1]
        du_v = 0.0
        du_w = 0.0
        for j in range(5):
            du_v += gain[lane, 0, j] * xi[lane, j]
            du_w += gain[lane, 1, j] * xi[lane, j]
        v_d, omega_d = ref[lane, 0], ref[lane, 1]
        v = min(max(v_d + mem[lane, 0] - du_v, -c[11]), c[11])
        om = min(max(omega_d + mem[lane, 1] - du_w, -c[12]), c[12])
        mem[lane, 0] = v - v_d
        mem[lane, 1] = om - omega_d
        vw[lane, 0] = v
        vw[lane, 1] = om


@dataclass(frozen=True)
class LaneParams:
    """Per-row parameters of LQR lanes (a lane's row is its ``LaneSet.idx`` entry); built by
    :func:`lane_params`.

    Attributes
    ----------
    config : ndarray, shape (rows, len(CONFIG_FIELDS))
        :func:`companion.fastlqr.lqr_step_config`.
    q_diag, r_diag : ndarrays, shapes (rows, 5) and (rows, 2)
    rest_gain, rest_p : ndarrays, shapes (rows, 2, 5) and (rows, 5, 5)
        Gain and Riccati solution at the rest operating point
        (:func:`companion.control.lqr.rest_operating_point`): the gain is the fallback of a
        lane that has never had a stabilising gain, the solution the start of a lane's
        Newton iteration when it has no previous one. Both come from scipy's solver (the
        single-episode controller computes its fallback gain with the compiled one; they
        agree to ~1e-13 relative), so that a batch compiles no scalar solver for them.
    """

    config: np.ndarray
    q_diag: np.ndarray
    r_diag: np.ndarray
    rest_gain: np.ndarray
    rest_p: np.ndarray


def lane_params(rows: Sequence[Params | None]) -> LaneParams:
    """:class:`LaneParams` of each row's controller parameters (None: a row no lane uses).
    The rest solutions come from the reference solver
    (:func:`companion.control.lqr.reference_solution`), once per distinct ``Params``."""
    n = len(rows)
    out = LaneParams(np.zeros((n, len(CONFIG_FIELDS))), np.ones((n, 5)), np.ones((n, 2)),
                     np.zeros((n, 2, 5)), np.zeros((n, 5, 5)))
    rest: dict[Params, tuple[np.ndarray, np.ndarray]] = {}
    for g, params in enumerate(rows):
        if params is None:
            continue
        if params not in rest:
            rest[params] = reference_solution(*rest_operating_point(params), params)
        out.config[g] = lqr_step_config(params)
        out.q_diag[g] = params.lqr.q
        out.r_diag[g] = params.lqr.r
        out.rest_gain[g], out.rest_p[g] = rest[params]
    return out


class LaneSet:
    """The arrays of a set of lanes.

    Parameters
    ----------
    idx : ndarray of int, shape (n,)
        Row of each lane in the :class:`LaneParams`; -1 marks padding. ``n`` must be a
        multiple of ``block``.
    block : int
        Lanes solved together (SIMD width and cache use; 1 for a single controller).
    params : LaneParams
    """

    def __init__(self, idx: np.ndarray, block: int, params: LaneParams):
        n = idx.size
        if n % block:
            raise ValueError(f"LaneSet: {n} lanes are not a whole number of blocks of {block}")
        blocks = n // block
        self.idx = idx
        self.block = block
        self.a = np.zeros((blocks, 5, 5, block))
        self.b = np.zeros((blocks, 5, 2, block))
        self.p = np.zeros((blocks, 5, 5, block))
        self.past = np.zeros((blocks, 3, 5, 5, block))   # P of the 3 periods before p's
        self.quad = np.zeros(n)                # quadratic-convergence constant (solve_lanes)
        self.k = np.zeros((blocks, 2, 5, block))
        self.qd = np.ones((blocks, 5, block))
        self.rd = np.ones((blocks, 2, block))
        for lane in np.flatnonzero(idx >= 0):
            blk, j = divmod(int(lane), block)
            self.qd[blk, :, j] = params.q_diag[idx[lane]]
            self.rd[blk, :, j] = params.r_diag[idx[lane]]
        self.corr = np.zeros((blocks, block))
        self.proved = np.zeros((blocks, block), np.bool_)   # closed loop proved stable
        self.history = np.zeros(n, np.int64)   # solved periods in a row (up to 4)
        self.warm = np.zeros(n, np.bool_)      # p holds the previous period's solution
        self.active = np.zeros(n, np.bool_)
        self.need_cold = np.zeros(n, np.bool_)
        self.has_gain = np.zeros(n, np.bool_)
        self.gain = np.zeros((n, 2, 5))
        self.mem = np.zeros((n, 2))            # u_e(k-1)
        self.ref = np.zeros((n, 3))            # v_d, omega_d, beta_d
        self.err = np.zeros((n, 3))            # rho_e, alpha_e, beta_e
        self.lin = np.zeros((n, 7))            # operating point of the gain
        self.xi = np.zeros((n, 5))
        self.vw = np.zeros((n, 2))             # output v, omega
        self.observed = np.zeros((n, 5))       # person x, y, theta, v, omega (input)
        self.pose = np.zeros((n, 3))           # robot x, y, theta (input)
        #: A process compiling :func:`companion.fastlqr.sda_nb`
        #: (:func:`companion.fastlqr.compile_sda`), waited for before its first use, so that
        #: this process loads it instead.
        self.sda_helper: subprocess.Popen | None = None


def _lane_model(L: LaneSet, lane: int) -> tuple[np.ndarray, np.ndarray]:
    blk, j = divmod(lane, L.block)
    return (np.ascontiguousarray(L.a[blk, :, :, j]), np.ascontiguousarray(L.b[blk, :, :, j]))


def _no_gain(L: LaneSet, lane: int, params: LaneParams) -> None:
    """A lane without a stabilising gain this period keeps its last one (or gets its row's
    rest gain) and starts its next period from the rest solution."""
    L.warm[lane] = False
    L.history[lane] = 0
    if not L.has_gain[lane]:
        L.gain[lane] = params.rest_gain[L.idx[lane]]
        L.has_gain[lane] = True


def _accept(L: LaneSet, lane: int, k: np.ndarray) -> None:
    L.gain[lane] = k
    L.has_gain[lane] = True
    L.warm[lane] = True
    L.history[lane] = min(L.history[lane] + 1, 4)


def _sda_start(L: LaneSet, params: LaneParams) -> int:
    """For the lanes whose iteration failed (:func:`_check` flagged them, ``corr`` inf: the
    start did not stabilise the lane's model): start again from the doubling of
    :func:`companion.fastlqr.sda_nb` (made active for the long pass; returns how many), or,
    where it does not converge (no stabilising solution), no gain this period."""
    corr = L.corr.reshape(-1)
    failed = np.flatnonzero(L.need_cold & (corr == np.inf))
    if failed.size == 0:
        return 0
    _jitcache.wait_helper(L.sda_helper)
    L.sda_helper = None
    p = np.empty((5, 5))
    started = 0
    for lane in failed:
        lane = int(lane)
        g = L.idx[lane]
        a, b = _lane_model(L, lane)
        L.need_cold[lane] = False
        if sda_nb(a, b, params.q_diag[g], params.r_diag[g], p):
            blk, j = divmod(lane, L.block)
            L.p[blk, :, :, j] = p
            L.history[lane] = 0
            L.active[lane] = True
            started += 1
        else:
            _no_gain(L, lane, params)
    return started


def _cold(L: LaneSet, params: LaneParams) -> None:
    """The lanes :func:`_check` flagged after the long pass. A converged lane whose closed
    loop the squarings could not prove stable is decided by its eigenvalues (as the scalar
    solver decides its undecided closed loops); any other (the iteration from the doubling
    failed too: none in the figure-8 batches, some while a person stops and sets off) takes
    the scalar solver
    (:func:`companion.fastlqr.stabilising_gain`: doubling, Newton polish and stability test);
    a lane without a stabilising gain gets :func:`_no_gain`."""
    if not L.need_cold.any():
        return
    corr = L.corr.reshape(-1)
    k_cold = np.empty((2, 5))
    p_cold = np.empty((5, 5))
    for lane in np.flatnonzero(L.need_cold):
        lane = int(lane)
        g = L.idx[lane]
        blk, j = divmod(lane, L.block)
        a, b = _lane_model(L, lane)
        if corr[lane] == 0.0:
            k = np.ascontiguousarray(L.k[blk, :, :, j])
            if float(np.max(np.abs(np.linalg.eigvals(a - b @ k)))) < 1.0 - RADIUS_MARGIN:
                _accept(L, lane, k)
            else:
                _no_gain(L, lane, params)
        elif stabilising_gain(a, b, params.q_diag[g], params.r_diag[g], p_cold, k_cold):
            L.p[blk, :, :, j] = p_cold
            L.history[lane] = 0
            _accept(L, lane, k_cold)
        else:
            _no_gain(L, lane, params)


def _lanes_solve(L: LaneSet, params: LaneParams) -> None:
    """The compiled part of a period up to the cold solver: model, Newton (all lanes
    ``LANES_MAX_STEPS`` steps; then the lanes still iterating, and those whose start failed
    from the doubling, gathered into one block, up to ``LANES_LONG_STEPS`` in all), check."""
    config = params.config
    _prepare(L.idx, L.observed, L.pose, config, L.mem, L.ref, L.err, L.lin, L.a, L.b, L.warm,
             params.rest_p, L.p, L.history, L.active)
    if config[:, 2].any():
        _zoh_models(L.idx, config, L.lin, L.a, L.b)
    solve_lanes(L.a, L.b, L.qd, L.rd, L.p, L.past, L.history, True, L.quad, L.active,
                LANES_MAX_STEPS, L.corr, L.proved, L.k)
    retries = _check(L.idx, L.k, L.corr, L.proved, L.active, True, L.warm, L.history, L.gain,
                     L.has_gain, L.need_cold)
    if retries + _sda_start(L, params):
        _solve_on(L, np.flatnonzero(L.active), LANES_LONG_STEPS - LANES_MAX_STEPS)
        _check(L.idx, L.k, L.corr, L.proved, L.active, False, L.warm, L.history, L.gain,
               L.has_gain, L.need_cold)


def _solve_on(L: LaneSet, lanes: np.ndarray, steps: int) -> None:
    """:func:`companion.fastlqr.solve_lanes` on the given lanes only, gathered into one block (a
    few lanes scattered over many blocks would otherwise cost a whole block's work each);
    a lane's result does not depend on where it is solved."""
    blk, j = np.divmod(lanes, L.block)

    def gather(x: np.ndarray) -> np.ndarray:   # x[blk, ..., j] -> (1, ..., len(lanes))
        return np.ascontiguousarray(np.moveaxis(x[blk, ..., j], 0, -1))[None]

    a, b, qd, rd, p = gather(L.a), gather(L.b), gather(L.qd), gather(L.rd), gather(L.p)
    k = np.empty((1, 2, 5, lanes.size))
    quad = L.quad[lanes]
    corr = np.empty((1, lanes.size))
    proved = np.zeros((1, lanes.size), np.bool_)
    active = np.ones(lanes.size, np.bool_)
    # past and history are in the set's layout, not the gathered one: unused without
    # extrapolation (the lanes were extrapolated in their first pass).
    solve_lanes(a, b, qd, rd, p, L.past, L.history, False, quad, active, steps, corr, proved,
                k)
    L.p[blk, ..., j] = np.moveaxis(p[0], -1, 0)
    L.k[blk, ..., j] = np.moveaxis(k[0], -1, 0)
    L.quad[lanes] = quad
    L.corr[blk, j] = corr[0]
    L.proved[blk, j] = proved[0]


def step_lanes(lanes: LaneSet, params: LaneParams) -> None:
    """One controller period of every lane: from ``lanes.observed`` and ``lanes.pose`` to
    ``lanes.vw`` (see the module docstring)."""
    L = lanes
    _lanes_solve(L, params)
    _cold(L, params)
    _control(L.idx, params.config, L.gain, L.mem, L.ref, L.err, L.xi, L.vw)


def _dummy() -> tuple[LaneSet, LaneParams]:
    """One lane with the default parameters but no rest solution (to compile the kernels
    on, without the reference solver)."""
    params = LaneParams(lqr_step_config(Params())[None, :], np.ones((1, 5)), np.ones((1, 2)),
                        np.zeros((1, 2, 5)), np.zeros((1, 5, 5)))
    return LaneSet(np.zeros(1, np.int64), 1, params), params


def compile_kernels() -> None:
    """Compile (or load from the cache) the lane kernels of :func:`step_lanes` except
    :func:`companion.fastlqr.solve_lanes`, the doubling and scalar solvers of restarts and
    cold solves, and the zero-order-hold models, by running them on one dummy lane."""
    L, params = _dummy()
    config = params.config
    _prepare(L.idx, L.observed, L.pose, config, L.mem, L.ref, L.err, L.lin, L.a, L.b, L.warm,
             params.rest_p, L.p, L.history, L.active)
    _check(L.idx, L.k, L.corr, L.proved, L.active, True, L.warm, L.history, L.gain,
           L.has_gain, L.need_cold)
    _control(L.idx, config, L.gain, L.mem, L.ref, L.err, L.xi, L.vw)
