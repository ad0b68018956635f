"""The LQR controller step for many lanes (episodes or robots) at once, compiled.

Each lane is one :class:`companion.control.lqr.LqrController`: per sample period its relative
state, feedforward and linearisation (:func:`_prepare`; zero-order-hold lanes then
:func:`_zoh_models`), its Riccati equation (:func:`_solve`: Newton's iteration from an
extrapolation of the lane's previous solutions (:func:`_warm_start`), for all lanes of a block
at once, vectorised by :func:`companion.fastlqr.newton_lanes`), a stability check
(:func:`_check`), the cold solver for lanes without a usable warm start (:func:`_cold`), and the
output (:func:`_control`). :class:`LaneSet` holds the arrays; :func:`step_lanes` runs one
period.

The batch simulator (:mod:`companion.sim.fast_batch`) runs sets of many lanes. A lane's result
does not depend on the other lanes of its set (a set of one gives the same bits). The gain
of a lane equals that of :meth:`companion.control.lqr.LqrController.gain` (cold doubling at
every period) to about 1e-11 relative (``tests/sim/test_fast_batch.py``), so a lane follows
the single-episode controller to that precision, except in closed loops that amplify such
differences (docs/performance.md).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from companion import _jitcache
from companion.fastlqr import (LANES_ACCEPT_MAX, LANES_DONE, LANES_MAX_STEPS,
                               LANES_PREDICTED, LANES_QUAD_DECAY, LANES_QUAD_MIN,
                               LANES_SAFETY, _gain_lanes, lqr_step_config, model_euler_nb,
                               model_zoh_nb, newton_lanes, relative_state_nb,
                               slot_reference_nb, stabilising_gain, wrap_pi_nb)
from companion.params import Params

#: Name of the lane kernels in the compile cache (:func:`compile_kernels`).
KERNELS = "lqr_lanes"

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
def _prepare(idx, observed, pose, config, mem, ref, err, lin, a, b, warm, active):
    """Per lane: feedforward, errors, operating point and model from the observed person
    ``observed[lane]`` (x, y, theta, v, omega) and robot ``pose[lane]`` (x, y, theta)."""
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
        _to_lane(a2, b2, a[lane // block], b[lane // block], lane % block)
        active[lane] = warm[lane]


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
    ``P(t-1)`` best from the periods before (order 1 after two periods, as nothing can be
    compared yet). On smooth motion that is order 2 (first Newton correction ~1e-6 of P
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
def _solve(a, b, qd, rd, p, past, history, quad, k, active, corr, proved):
    """Newton steps on the warm (``active``) lanes of every block, from the prediction of
    :func:`_warm_start`. ``corr`` ends 0 where a lane converged and inf elsewhere, ``proved``
    True where the last step's squarings proved its closed loop stable; ``k`` gets each lane's
    gain from its ``p``.

    A lane has converged after a step whose relative correction ``c`` is at most
    ``LANES_DONE``, or when the next correction, predicted by the quadratic convergence of
    Newton's method as ``quad c^2``, is below ``LANES_PREDICTED`` even with a safety factor
    ``LANES_SAFETY`` (the error left in P is of the order of that next correction).
    ``quad`` (per lane) is the largest recent ratio of a correction to the square of the one
    before, decaying by ``LANES_QUAD_DECAY`` per period; it is only measured from corrections
    above ``LANES_QUAD_MIN``, where rounding does not dominate the next one. The predicted
    stop applies only to corrections below ``LANES_ACCEPT_MAX`` (2e-6 of P), so that an
    underestimated ratio (decayed, or not measured yet) leaves at most the true ratio times
    4e-12."""
    blocks, block = a.shape[0], a.shape[3]
    converged = np.zeros(block, np.bool_)
    step_corr = np.empty(block)
    last = np.empty(block)
    for blk in range(blocks):
        act = active[blk * block:(blk + 1) * block]
        for j in range(block):
            converged[j] = False
            proved[blk, j] = False
            last[j] = np.inf
            if act[j]:
                lane = blk * block + j
                _warm_start(p[blk], past[blk], history, lane, j)
                quad[lane] *= LANES_QUAD_DECAY
        for _ in range(LANES_MAX_STEPS):
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
                    continue
                if last[j] >= LANES_QUAD_MIN and last[j] < np.inf:
                    quad[lane] = max(quad[lane], c / (last[j] * last[j]))
                predicted = LANES_SAFETY * quad[lane] * c * c
                if c <= LANES_DONE or (c <= LANES_ACCEPT_MAX and predicted <= LANES_PREDICTED):
                    act[j] = False
                    converged[j] = True
                else:
                    last[j] = c
                    left = True
            if not left:
                break
        for j in range(block):
            corr[blk, j] = 0.0 if converged[j] else np.inf
        _gain_lanes(a[blk], b[blk], rd[blk], p[blk], k[blk], block)


@njit(**_NB)
def _check(idx, k, corr, proved, warm, history, gain, has_gain, need_cold):
    """Accept each warm lane's gain if its Newton iteration converged and the squarings of
    its last Smith doubling proved the closed loop stable (``proved``, see
    :func:`companion.fastlqr.newton_lanes`); else flag a cold solve (which settles undecided
    closed loops by their eigenvalues). The proof concerns the gain the last Newton step
    started from, which differs from the accepted one by that step's correction (below 1e-9,
    or below 2e-6 and predicted below 1e-11, of P), against a margin of at least 1.7e-4 in spectral radius
    that the proof gives."""
    blocks, block = k.shape[0], k.shape[3]
    for blk in range(blocks):
        for j in range(block):
            lane = blk * block + j
            need_cold[lane] = False
            if idx[lane] < 0:
                continue
            if warm[lane] and corr[blk, j] == 0.0 and proved[blk, j]:
                for r in range(2):
                    for c in range(5):
                        gain[lane, r, c] = k[blk, r, c, j]
                has_gain[lane] = True
                history[lane] = min(history[lane] + 1, 4)
            else:
                need_cold[lane] = True


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


class LaneSet:
    """The arrays of a set of lanes.

    Parameters
    ----------
    idx : ndarray of int, shape (n,)
        Row of each lane in the per-lane parameter arrays (``config``, ``q_diag``,
        ``r_diag``, ``rest_gain``); -1 marks padding. ``n`` must be a multiple of ``block``.
    block : int
        Lanes solved together (SIMD width and cache use; 1 for a single controller).
    q_diag, r_diag : ndarrays, shapes (rows, 5) and (rows, 2)
    """

    def __init__(self, idx: np.ndarray, block: int, q_diag: np.ndarray, r_diag: np.ndarray):
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
            self.qd[blk, :, j] = q_diag[idx[lane]]
            self.rd[blk, :, j] = r_diag[idx[lane]]
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


def _cold(lanes: LaneSet, q_diag: np.ndarray, r_diag: np.ndarray,
          rest_gain: np.ndarray) -> None:
    """The scalar solver (:func:`companion.fastlqr.stabilising_gain`, cold doubling) for the
    lanes :func:`_check` flagged, on the lane's model; a lane without any stabilising gain
    keeps its last one (or gets ``rest_gain``)."""
    if not lanes.need_cold.any():
        return
    k_cold = np.empty((2, 5))
    p_cold = np.empty((5, 5))
    for lane in np.flatnonzero(lanes.need_cold):
        g = lanes.idx[lane]
        blk, j = divmod(int(lane), lanes.block)
        a = np.ascontiguousarray(lanes.a[blk, :, :, j])
        b = np.ascontiguousarray(lanes.b[blk, :, :, j])
        if stabilising_gain(a, b, q_diag[g], r_diag[g], p_cold, k_cold):
            lanes.gain[lane] = k_cold
            lanes.has_gain[lane] = True
            lanes.p[blk, :, :, j] = p_cold
            lanes.warm[lane] = True
            lanes.history[lane] = 1
        else:
            lanes.warm[lane] = False
            lanes.history[lane] = 0
            if not lanes.has_gain[lane]:
                lanes.gain[lane] = rest_gain[g]
                lanes.has_gain[lane] = True


def _warm_solve(L: LaneSet, config: np.ndarray) -> None:
    """The compiled part of a period up to the cold solver: model, warm Newton, check."""
    _prepare(L.idx, L.observed, L.pose, config, L.mem, L.ref, L.err, L.lin, L.a, L.b, L.warm,
             L.active)
    if config[:, 2].any():
        _zoh_models(L.idx, config, L.lin, L.a, L.b)
    _solve(L.a, L.b, L.qd, L.rd, L.p, L.past, L.history, L.quad, L.k, L.active, L.corr,
           L.proved)
    _check(L.idx, L.k, L.corr, L.proved, L.warm, L.history, L.gain, L.has_gain, L.need_cold)


def step_lanes(lanes: LaneSet, config: np.ndarray, q_diag: np.ndarray, r_diag: np.ndarray,
               rest_gain: np.ndarray) -> None:
    """One controller period of every lane: from ``lanes.observed`` and ``lanes.pose`` to
    ``lanes.vw`` (see the module docstring). ``config`` rows are
    :func:`companion.fastlqr.lqr_step_config`."""
    L = lanes
    _warm_solve(L, config)
    _cold(L, q_diag, r_diag, rest_gain)
    _control(L.idx, config, L.gain, L.mem, L.ref, L.err, L.xi, L.vw)


def compile_kernels() -> None:
    """Compile (or load from the cache) the kernels of :func:`step_lanes`, except the scalar
    cold solver and the zero-order-hold models, by running them on one dummy lane; then mark
    them compiled (:func:`companion._jitcache.mark_compiled`). :mod:`companion.sim.fast_batch` runs this in
    a helper process on a first batch, while it compiles the scalar solver itself."""
    config = lqr_step_config(Params())[None, :]
    L = LaneSet(np.zeros(1, np.int64), 1, np.ones((1, 5)), np.ones((1, 2)))
    _warm_solve(L, config)
    _control(L.idx, config, L.gain, L.mem, L.ref, L.err, L.xi, L.vw)
    _jitcache.mark_compiled(KERNELS)
