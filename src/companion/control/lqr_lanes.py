"""The LQR controller step for many lanes (episodes or robots) at once, compiled.

Each lane is one :class:`companion.control.lqr.LqrController`: per sample period its relative
state, feedforward and linearisation (:func:`_prepare`; zero-order-hold lanes then
:func:`_zoh_models`), its Riccati equation (:func:`_solve`: Newton's iteration from an
extrapolation of the lane's previous solutions (:func:`_warm_start`), or from the solution at
its rest operating point for a lane without one, for all lanes of a block at once,
vectorised by :func:`companion.fastlqr.newton_lanes`; lanes that need more steps go on
gathered into one block, :func:`_solve_on`), the gains (:func:`_gains`), a stability check
(:func:`_check`), the scalar cold solver for lanes whose iteration failed (:func:`_cold`),
and the output (:func:`_control`). :class:`LaneParams` holds the per-row parameters,
:class:`LaneSet` the arrays; :func:`step_lanes` runs one period.

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
from companion.fastlqr import (CONFIG_FIELDS, LANES_ACCEPT_MAX, LANES_DONE,
                               LANES_LONG_STEPS, LANES_MAX_STEPS, LANES_PREDICTED,
                               LANES_QUAD_DECAY, LANES_QUAD_MIN, LANES_SAFETY, _gain_lanes,
                               lqr_step_config, model_euler_nb, model_zoh_nb, newton_lanes,
                               relative_state_nb, slot_reference_nb, stabilising_gain,
                               wrap_pi_nb)
from companion.params import Params

#: Name of :func:`_solve` in the compile cache (:func:`compile_solver`).
SOLVER = "lqr_lanes_solve"
#: Name of the scalar cold solver in the compile cache (:func:`compile_cold_solver`).
COLD = "lqr_lanes_cold"

_NB = {"cache": True, "nogil": True, "error_model": "numpy", "no_cfunc_wrapper": True}
#: Functions only called from compiled code: no Python wrapper to compile.
_INNER = {**_NB, "no_cpython_wrapper": True}
#: ``corr`` of a lane whose Newton iteration was still going when :func:`_solve` stopped.
LANES_UNFINISHED = 1.0


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


@njit(**_INNER)
def _warm_start(p, past, history, lane, j):
    """Replace ``p[:, :, j]`` = P(t-1) by the prediction of P(t) and shift it into
    ``past[:, :, :, j]`` (P(t-2), P(t-3), P(t-4)), for a lane with ``history`` solved periods
    in a row.

    The prediction is the polynomial extrapolation of order 0 (``P(t-1)``), 1
    (``2 P(t-1) - P(t-2)``) or 2 (``3 P(t-1) - 3 P(t-2) + P(t-3)``) that would have predicted
    ``P(t-1)`` best from the periods before (order 0 with fewer than two periods, order 1 after two, as nothing can
    be compared yet). On smooth motion that is order 2 (first Newton correction ~1e-6 of P
    instead of ~3e-5 with order 1 on the figure-8); with sensor noise, order 0 (the
    extrapolations amplify the noise)."""
    h = history[lane]
    order = 0
    if h == 2:
        order = 1
    elif h >= 3:
        e0 = 0.0
        e1 = 0.0
        e2 = 0.0 if h >= 4 else np.inf
        for r in range(5):
            for c in range(5):
                p1, p2, p3, p4 = p[r, c, j], past[0, r, c, j], past[1, r, c, j], past[2, r, c, j]
                e0 = max(e0, abs(p1 - p2))
                e1 = max(e1, abs(p1 - (2.0 * p2 - p3)))
                if h >= 4:
                    e2 = max(e2, abs(p1 - (3.0 * p2 - 3.0 * p3 + p4)))
        order = 0 if e0 <= min(e1, e2) else (1 if e1 <= e2 else 2)
    for r in range(5):
        for c in range(5):
            p1, p2, p3 = p[r, c, j], past[0, r, c, j], past[1, r, c, j]
            if order == 1:
                p[r, c, j] = 2.0 * p1 - p2
            elif order == 2:
                p[r, c, j] = 3.0 * p1 - 3.0 * p2 + p3
            past[2, r, c, j] = p3
            past[1, r, c, j] = p2
            past[0, r, c, j] = p1


@njit(**_NB)
def _solve(a, b, qd, rd, p, past, history, extrapolate, quad, active, steps, corr, proved):
    """At most ``steps`` Newton steps on the ``active`` lanes of every block, from their
    ``p`` (first replaced by :func:`_warm_start`'s prediction if ``extrapolate``; the
    quadratic-convergence ratios then decay, see below). ``corr`` of an active lane ends 0 where it converged, ``LANES_UNFINISHED`` where it
    was still iterating after ``steps`` and inf where a step failed (the lane's ``p`` is then
    its last successful iterate); ``proved`` True where its last step's squarings proved its
    closed loop stable. Blocks without an active lane are skipped.

    A lane has converged after a step whose relative correction ``c`` is at most
    ``LANES_DONE``, or when the next correction, predicted by the quadratic convergence of
    Newton's method as ``quad c^2``, is below ``LANES_PREDICTED`` even with a safety factor
    ``LANES_SAFETY`` (the error left in P is of the order of that next correction).
    ``quad`` (per lane) is the largest recent ratio of a correction to the square of the one
    before, decaying by ``LANES_QUAD_DECAY`` per period; it is only
    measured from corrections above ``LANES_QUAD_MIN``, where rounding does not dominate the
    next one. The predicted stop applies only to corrections below ``LANES_ACCEPT_MAX`` (2e-6
    of P), so that an underestimated ratio (decayed, or not measured yet) leaves at most the
    true ratio times 4e-12."""
    blocks, block = a.shape[0], a.shape[3]
    act = np.empty(block, np.bool_)
    step_corr = np.empty(block)
    last = np.empty(block)
    for blk in range(blocks):
        left = False
        for j in range(block):
            lane = blk * block + j
            act[j] = active[lane]
            left = left or act[j]
            last[j] = np.inf
            if act[j] and extrapolate:
                _warm_start(p[blk], past[blk], history, lane, j)
                quad[lane] *= LANES_QUAD_DECAY
        for _ in range(steps):
            if not left:
                break
            newton_lanes(a[blk], b[blk], qd[blk], rd[blk], p[blk], act, block, step_corr,
                         proved[blk])
            left = False
            for j in range(block):
                if not act[j]:
                    continue
                lane = blk * block + j
                c = step_corr[j]
                if not c < np.inf:
                    act[j] = False
                    corr[blk, j] = np.inf
                    continue
                if last[j] >= LANES_QUAD_MIN and last[j] < np.inf:
                    quad[lane] = max(quad[lane], c / (last[j] * last[j]))
                predicted = LANES_SAFETY * quad[lane] * c * c
                if c <= LANES_DONE or (c <= LANES_ACCEPT_MAX and predicted <= LANES_PREDICTED):
                    act[j] = False
                    corr[blk, j] = 0.0
                else:
                    last[j] = c
                    left = True
        for j in range(block):
            if act[j]:
                corr[blk, j] = LANES_UNFINISHED


@njit(**_NB)
def _gains(a, b, rd, p, k, active):
    """Each lane's gain from its ``p`` (:func:`companion.fastlqr._gain_lanes`), in the blocks
    with an active lane."""
    blocks, block = a.shape[0], a.shape[3]
    for blk in range(blocks):
        if active[blk * block:(blk + 1) * block].any():
            _gain_lanes(a[blk], b[blk], rd[blk], p[blk], k[blk], block)


@njit(**_NB)
def _check(idx, k, corr, proved, active, retry, warm, history, gain, has_gain, need_cold):
    """For the lanes solved by :func:`_solve` (``active``, which this clears): accept a
    lane's gain if its Newton iteration converged and the squarings of its last Smith
    doubling proved the closed loop stable (``proved``, see
    :func:`companion.fastlqr.newton_lanes`). If ``retry``, a lane still iterating stays
    active for a longer :func:`_solve`; the number of such lanes is returned. Every other lane
    is flagged for the cold solver (which also settles undecided closed loops by their
    eigenvalues); ``need_cold`` of the lanes not active is left as it is. The proof concerns the gain the last Newton step started from, which
    differs from the accepted one by that step's correction (below 1e-9, or below 2e-6 and
    predicted below 1e-11, of P), against a margin of at least 1.7e-4 in spectral radius that
    the proof gives."""
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
        Newton iteration when it has no previous one.
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
        self.quad = np.zeros(n)                # quadratic-convergence constant (see _solve)
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
        #: A process compiling the scalar cold solver (:func:`compile_cold_solver`), waited
        #: for before the first cold solve, so that this process loads it instead.
        self.cold_helper: subprocess.Popen | None = None


def _cold(lanes: LaneSet, params: LaneParams) -> None:
    """The scalar solver (:func:`companion.fastlqr.stabilising_gain`, cold doubling) for the
    lanes :func:`_check` flagged, on the lane's model; a lane without any stabilising gain
    keeps its last one (or gets its row's rest gain) and starts its next period from the rest
    solution."""
    if not lanes.need_cold.any():
        return
    _jitcache.wait_helper(lanes.cold_helper)
    lanes.cold_helper = None
    k_cold = np.empty((2, 5))
    p_cold = np.empty((5, 5))
    for lane in np.flatnonzero(lanes.need_cold):
        g = lanes.idx[lane]
        blk, j = divmod(int(lane), lanes.block)
        a = np.ascontiguousarray(lanes.a[blk, :, :, j])
        b = np.ascontiguousarray(lanes.b[blk, :, :, j])
        if stabilising_gain(a, b, params.q_diag[g], params.r_diag[g], p_cold, k_cold):
            lanes.gain[lane] = k_cold
            lanes.has_gain[lane] = True
            lanes.p[blk, :, :, j] = p_cold
            lanes.warm[lane] = True
            lanes.history[lane] = 1
        else:
            lanes.warm[lane] = False
            lanes.history[lane] = 0
            if not lanes.has_gain[lane]:
                lanes.gain[lane] = params.rest_gain[g]
                lanes.has_gain[lane] = True


def _lanes_solve(L: LaneSet, params: LaneParams) -> None:
    """The compiled part of a period up to the cold solver: model, Newton (all lanes
    ``LANES_MAX_STEPS`` steps, then the lanes still iterating gathered into one block, up
    to ``LANES_LONG_STEPS`` in all), check."""
    config = params.config
    _prepare(L.idx, L.observed, L.pose, config, L.mem, L.ref, L.err, L.lin, L.a, L.b, L.warm,
             params.rest_p, L.p, L.history, L.active)
    if config[:, 2].any():
        _zoh_models(L.idx, config, L.lin, L.a, L.b)
    _solve(L.a, L.b, L.qd, L.rd, L.p, L.past, L.history, True, L.quad, L.active,
           LANES_MAX_STEPS, L.corr, L.proved)
    _gains(L.a, L.b, L.rd, L.p, L.k, L.active)
    if _check(L.idx, L.k, L.corr, L.proved, L.active, True, L.warm, L.history, L.gain,
              L.has_gain, L.need_cold):
        _solve_on(L, np.flatnonzero(L.active), LANES_LONG_STEPS - LANES_MAX_STEPS)
        _check(L.idx, L.k, L.corr, L.proved, L.active, False, L.warm, L.history, L.gain,
               L.has_gain, L.need_cold)


def _solve_on(L: LaneSet, lanes: np.ndarray, steps: int) -> None:
    """:func:`_solve` and :func:`_gains` on the given lanes only, gathered into one block (a
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
    _solve(a, b, qd, rd, p, L.past, L.history, False, quad, active, steps, corr, proved)
    _gains(a, b, rd, p, k, active)
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


def compile_solver() -> None:
    """Compile (or load from the cache) :func:`_solve`, the largest lane kernel, by running
    it on one dummy lane; then mark it compiled (:func:`companion._jitcache.mark_compiled`).
    :mod:`companion.sim.fast_batch` runs this in a helper process on a first batch, while it
    compiles the other kernels itself (:func:`compile_kernels`)."""
    L, _ = _dummy()
    _solve(L.a, L.b, L.qd, L.rd, L.p, L.past, L.history, True, L.quad, L.active, 1, L.corr,
           L.proved)
    _jitcache.mark_compiled(SOLVER)


def compile_cold_solver() -> None:
    """Compile (or load from the cache) the scalar cold solver of :func:`_cold`
    (:func:`companion.fastlqr.stabilising_gain`) on a dummy model, then mark it compiled.
    :mod:`companion.sim.fast_batch` runs this in a helper process while a first batch
    runs."""
    a, b = 0.5 * np.eye(5), np.ones((5, 2))
    stabilising_gain(a, b, np.ones(5), np.ones(2), np.empty((5, 5)), np.empty((2, 5)))
    _jitcache.mark_compiled(COLD)


def compile_kernels() -> None:
    """Compile (or load from the cache) the lane kernels of :func:`step_lanes` except
    :func:`_solve`, the scalar cold solver and the zero-order-hold models, by running them on
    one dummy lane."""
    L, params = _dummy()
    config = params.config
    _prepare(L.idx, L.observed, L.pose, config, L.mem, L.ref, L.err, L.lin, L.a, L.b, L.warm,
             params.rest_p, L.p, L.history, L.active)
    _gains(L.a, L.b, L.rd, L.p, L.k, L.active)
    _check(L.idx, L.k, L.corr, L.proved, L.active, True, L.warm, L.history, L.gain,
           L.has_gain, L.need_cold)
    _control(L.idx, config, L.gain, L.mem, L.ref, L.err, L.xi, L.vw)
