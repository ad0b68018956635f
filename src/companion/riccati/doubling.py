"""Compiled solver of the discrete algebraic Riccati equation for the 5x5 augmented model with
diagonal weights: structure-preserving doubling, a Newton polish and a stability test by
repeated squaring (docs/performance.md). Compiled-only: its reference is scipy's solver.

Explicit loops on fixed sizes: for 5x5 matrices they beat BLAS/LAPACK, and whole-array
operations would cost seconds of compilation each. The call tree is flat (dare_gain calls
every part itself), since numba compiles a function with all the code it calls. Kernels never
raise on bad numbers: they return a status.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from companion._jit import register
from companion.riccati.reference import RADIUS_MARGIN

#: Doubling stops when the update of P is below this times max|P| (quadratic convergence:
#: the iterate is then within ~1e-14, and the Newton polish finishes it).
DARE_TOL = 1e-8
#: Cap on doubling steps (each doubles the horizon; convergent cases need < 40).
DARE_MAX_ITER = 100
#: Smith doubling inside a Newton step stops at an update below this times the correction.
NEWTON_TOL = 1e-3
#: Newton steps stop at a correction below this times P, or after NEWTON_MAX_STEPS.
NEWTON_DONE = 1e-12
NEWTON_MAX_STEPS = 6
#: A Newton step is skipped where the Riccati residual is at most this times max|P| (the
#: rounding level of the residual itself; 99 % of walking operating points).
NEWTON_SKIP = 1e-15
#: Sizes of the augmented companion model: 5 states, 2 inputs.
NX, NU = 5, 2
#: Status of :func:`dare_gain` and of the stability tests.
GAIN_FAILED, GAIN_STABLE, GAIN_UNDECIDED = 0, 1, 2
#: rho(M) <= ||M^4096||^(1/4096) < 0.5^(1/4096): the squaring test only proves bounds above this.
_SHORTCUT_RADIUS = 0.5 ** (1.0 / 4096.0)
#: 5x5 scratch matrices of dare_gain (_sda uses 0-7, the saved doubling solution is 8).
_WORKSPACE = 9

_JIT = {"cache": True, "error_model": "numpy", "no_cfunc_wrapper": True}
#: Kernels only called from compiled code: no Python wrapper to compile.
_INNER = {**_JIT, "no_cpython_wrapper": True}


@njit(**_INNER)
def _matmul(a, b, out, n, k, m):
    """``out = a @ b`` for ``a`` (n, k), ``b`` (k, m); ``out`` must not alias ``a`` or ``b``."""
    for i in range(n):
        for j in range(m):
            s = 0.0
            for h in range(k):
                s += a[i, h] * b[h, j]
            out[i, j] = s


@njit(**_INNER)
def _lu_factor(a, piv, n):
    """LU factorisation with partial pivoting of the (n, n) ``a``, in place.

    Returns False if a pivot is zero or not finite (singular or non-finite matrix).
    """
    for k in range(n):
        p = k
        big = abs(a[k, k])
        for i in range(k + 1, n):
            if abs(a[i, k]) > big:
                big = abs(a[i, k])
                p = i
        if not (big > 0.0 and big < np.inf):
            return False
        piv[k] = p
        if p != k:
            for j in range(n):
                a[k, j], a[p, j] = a[p, j], a[k, j]
        for i in range(k + 1, n):
            f = a[i, k] / a[k, k]
            a[i, k] = f
            for j in range(k + 1, n):
                a[i, j] -= f * a[k, j]
    return True


@njit(**_INNER)
def _lu_solve(lu, piv, b, n, m):
    """Solve ``A X = b`` in place for the (n, m) ``b``, given ``_lu_factor`` of A."""
    for k in range(n):
        p = piv[k]
        if p != k:
            for j in range(m):
                b[k, j], b[p, j] = b[p, j], b[k, j]
    for i in range(1, n):
        for h in range(i):
            f = lu[i, h]
            for j in range(m):
                b[i, j] -= f * b[h, j]
    for i in range(n - 1, -1, -1):
        for h in range(i + 1, n):
            f = lu[i, h]
            for j in range(m):
                b[i, j] -= f * b[h, j]
        d = lu[i, i]
        for j in range(m):
            b[i, j] /= d


@njit(**_INNER)
def _sda(a, b, q_diag, r_diag, h, ws):
    """Structure-preserving doubling for the DARE of ``a`` (5, 5), ``b`` (5, 2), ``Q =
    diag(q_diag)``, ``R = diag(r_diag)``; ``h`` receives the last iterate. ``ws`` is the
    (>= 9, 5, 5) workspace of :func:`dare_gain`. Returns ``(converged, iterations)``."""
    g, ak, w, w_ia, w_ig, tmp, dh, at = ws[0], ws[1], ws[2], ws[3], ws[4], ws[5], ws[6], ws[7]
    for i in range(NX):
        for j in range(NX):
            # G_0 = B R^-1 B', H_0 = Q, A_0 = A
            g[i, j] = b[i, 0] * b[j, 0] / r_diag[0] + b[i, 1] * b[j, 1] / r_diag[1]
            h[i, j] = 0.0
            ak[i, j] = a[i, j]
        h[i, i] = q_diag[i]
    piv = np.empty(NX, np.int64)
    for it in range(1, DARE_MAX_ITER + 1):
        _matmul(g, h, w, NX, NX, NX)
        for i in range(NX):
            w[i, i] += 1.0
        if not _lu_factor(w, piv, NX):
            return False, it
        for i in range(NX):
            for j in range(NX):
                w_ia[i, j] = ak[i, j]
                w_ig[i, j] = g[i, j]
                at[i, j] = ak[j, i]
        _lu_solve(w, piv, w_ia, NX, NX)
        _lu_solve(w, piv, w_ig, NX, NX)
        _matmul(h, w_ia, tmp, NX, NX, NX)
        _matmul(at, tmp, dh, NX, NX, NX)        # A_k' H_k W^-1 A_k
        _matmul(ak, w_ig, tmp, NX, NX, NX)
        _matmul(tmp, at, w, NX, NX, NX)         # A_k W^-1 G_k A_k' (W is free now)
        _matmul(ak, w_ia, tmp, NX, NX, NX)      # A_{k+1} = A_k W^-1 A_k
        for i in range(NX):
            for j in range(NX):
                ak[i, j] = tmp[i, j]
        step = 0.0                              # max |H_{k+1} - H_k|
        size = 0.0                              # max |H_{k+1}|
        total = 0.0                             # not finite iff an entry of G or H is not
        for i in range(NX):
            for j in range(i, NX):
                x = 0.5 * (dh[i, j] + dh[j, i])
                h[i, j] = h[j, i] = h[i, j] + x
                g[i, j] = g[j, i] = g[i, j] + 0.5 * (w[i, j] + w[j, i])
                step = max(step, abs(x))
                size = max(size, abs(h[i, j]))
                total += h[i, j] + g[i, j]
        if not abs(total) < np.inf:
            return False, it
        if step <= DARE_TOL * size:
            return True, it
    return False, DARE_MAX_ITER


@njit(**_INNER)
def _gain(a, b, r_diag, p, k):
    """``k = (R + B'PB)^-1 B'PA`` (2, 5), the 2x2 system solved in closed form; False if
    ``R + B'PB`` is singular or a number is not finite."""
    # Written out rather than _matmul: each other shape of _matmul is one more compilation.
    bt_p = np.empty((NU, NX))
    for i in range(NU):
        for j in range(NX):
            x = 0.0
            for h in range(NX):
                x += b[h, i] * p[h, j]
            bt_p[i, j] = x
    s00, s01, s10, s11 = r_diag[0], 0.0, 0.0, r_diag[1]
    for h in range(NX):
        s00 += bt_p[0, h] * b[h, 0]
        s01 += bt_p[0, h] * b[h, 1]
        s10 += bt_p[1, h] * b[h, 0]
        s11 += bt_p[1, h] * b[h, 1]
    s01 = 0.5 * (s01 + s10)
    det = s00 * s11 - s01 * s01
    if not (det != 0.0 and abs(det) < np.inf):
        return False
    finite = True
    for j in range(NX):
        x0 = 0.0
        x1 = 0.0
        for h in range(NX):
            x0 += bt_p[0, h] * a[h, j]
            x1 += bt_p[1, h] * a[h, j]
        k[0, j] = (s11 * x0 - s01 * x1) / det
        k[1, j] = (s00 * x1 - s01 * x0) / det
        finite = finite and abs(k[0, j]) < np.inf and abs(k[1, j]) < np.inf
    return finite


@njit(**_INNER)
def _closed_loop(a, b, k, out):
    """``out = A - B K`` (5, 5)."""
    for i in range(NX):
        for j in range(NX):
            out[i, j] = a[i, j] - (b[i, 0] * k[0, j] + b[i, 1] * k[1, j])


@njit(**_INNER)
def _newton(a, b, q_diag, r_diag, p, ws):
    """One Newton (Hewer) step on an approximate stabilising DARE solution ``p``, in place.

    With ``K = K(P)`` and ``Ac = A - B K``, the correction ``D`` solves the Stein equation
    ``D - Ac' D Ac = Q + K'RK + Ac' P Ac - P`` (the right-hand side is the Riccati residual of
    ``P``), by Smith's doubling ``D <- D + M' D M``, ``M <- M^2`` from ``D = residual``,
    ``M = Ac``, until the update is below ``NEWTON_TOL`` times ``D``; ``p`` becomes the Newton
    iterate ``P + D``. Returns ``max|D| / max|P + D|``, 0 without changing ``p`` where the
    residual is at most ``NEWTON_SKIP`` times ``max|P|``, or -1 if the Smith doubling does not
    converge (closed loop not stable) or produces non-finite numbers. Uses ``ws[0:5]``.
    """
    k = np.empty((NU, NX))
    if not _gain(a, b, r_diag, p, k):
        return -1.0
    mj, tmp, d, mt, t = ws[0], ws[1], ws[2], ws[3], ws[4]
    _closed_loop(a, b, k, mj)
    for i in range(NX):
        for j in range(NX):
            mt[i, j] = mj[j, i]
    _matmul(p, mj, tmp, NX, NX, NX)
    _matmul(mt, tmp, d, NX, NX, NX)                 # Ac' P Ac
    residual = 0.0
    scale = 0.0
    for i in range(NX):
        for j in range(i, NX):
            krk = r_diag[0] * k[0, i] * k[0, j] + r_diag[1] * k[1, i] * k[1, j]
            x = 0.5 * (d[i, j] + d[j, i]) + krk - p[i, j]
            if i == j:
                x += q_diag[i]
            d[i, j] = d[j, i] = x
            residual = max(residual, abs(x))
            scale = max(scale, abs(p[i, j]))
    if residual <= NEWTON_SKIP * scale:
        return 0.0
    for _ in range(DARE_MAX_ITER):
        _matmul(d, mj, tmp, NX, NX, NX)
        _matmul(mt, tmp, t, NX, NX, NX)             # M' D M
        step = 0.0
        size = 0.0
        total = 0.0                                 # not finite iff an entry of D is not
        for i in range(NX):
            for j in range(i, NX):
                x = 0.5 * (t[i, j] + t[j, i])
                y = d[i, j] + x
                d[i, j] = d[j, i] = y
                step = max(step, abs(x))
                size = max(size, abs(y))
                total += y
        if not abs(total) < np.inf:
            return -1.0
        if step <= NEWTON_TOL * size:
            scale = 0.0
            for i in range(NX):
                for j in range(NX):
                    p[i, j] += d[i, j]
                    scale = max(scale, abs(p[i, j]))
            return size / scale if scale > 0.0 else size
        _matmul(mt, mt, tmp, NX, NX, NX)            # (M^2)' = M' M'
        for i in range(NX):
            for j in range(NX):
                mt[i, j] = tmp[i, j]
                mj[i, j] = tmp[j, i]
    return -1.0


@njit(**_JIT)
def _radius_status(m, bound, x, y, n):
    """Whether the spectral radius of the (n, n) ``m`` is below ``bound``, as far as
    repeated squaring can tell: :data:`GAIN_STABLE` (proved), :data:`GAIN_FAILED` (an entry is
    not finite) or :data:`GAIN_UNDECIDED` (the eigenvalues must decide). ``x`` and ``y`` are
    (n, n) scratch.

    ``rho(M)^j <= ||M^j||`` for any j and norm: if a power ``M^(2^s)``, s = 1..12, has
    infinity-norm below 0.5, then ``rho(M) <= 0.5^(1/4096) = 1 - 1.69e-4``, which answers yes
    for any ``bound`` above that. The 0.5 margin dwarfs the rounding errors of the squarings,
    which are only continued while the norm stays below 1e3. For the LQR closed loops here a
    few squarings settle it (~0.1-0.5 us in all, where eigenvalues take ~7 us).
    """
    total = 0.0
    for i in range(n):
        for j in range(n):
            x[i, j] = m[i, j]
            total += abs(m[i, j])
    if not total < np.inf:
        return GAIN_FAILED
    if bound > _SHORTCUT_RADIUS:
        for _ in range(12):
            _matmul(x, x, y, n, n, n)
            nrm = 0.0
            for i in range(n):
                row = 0.0
                for j in range(n):
                    row += abs(y[i, j])
                    x[i, j] = y[i, j]
                nrm = max(nrm, row)
            if nrm < 0.5:
                return GAIN_STABLE
            if not nrm < 1e3:    # (m is finite and |y| <= |x|^2 < 1e6: no overflow here)
                break
    return GAIN_UNDECIDED


@njit(**_JIT)
def dare_gain(a, b, q_diag, r_diag, p, k):
    """LQR gain of ``(A, B)`` = ``a`` (5, 5), ``b`` (5, 2) with ``Q = diag(q_diag)``,
    ``R = diag(r_diag)``: the stabilising solution ``P`` of the DARE (Eq. 15), written into
    ``p``, and ``K = (R + B'PB)^-1 B'PA``, written into ``k``.

    Structure-preserving doubling (:func:`_sda`), polished by Newton steps (:func:`_newton`)
    while each correction shrinks at least tenfold (else the doubling's result is kept), then
    the closed loop ``A - B K`` is tested by :func:`_radius_status`. docs/performance.md
    describes the method and its accuracy against a 50-digit reference.

    Returns ``(status, iterations)``: :data:`GAIN_STABLE`, :data:`GAIN_UNDECIDED` (the
    eigenvalues must decide, :func:`stabilising_gain`) or :data:`GAIN_FAILED` (no
    convergence, a singular step, non-finite numbers), and the number of doubling steps.
    """
    ws = np.empty((_WORKSPACE, NX, NX))
    ok, iterations = _sda(a, b, q_diag, r_diag, p, ws)
    if not ok:
        return GAIN_FAILED, iterations
    p_sda = ws[8]
    for i in range(NX):
        for j in range(NX):
            p_sda[i, j] = p[i, j]
    last = np.inf
    for step in range(NEWTON_MAX_STEPS):
        correction = _newton(a, b, q_diag, r_diag, p, ws)
        if not correction >= 0.0:
            return GAIN_FAILED, iterations
        if correction <= NEWTON_DONE:
            break
        if correction > 0.1 * last:
            if step == 1:
                for i in range(NX):
                    for j in range(NX):
                        p[i, j] = p_sda[i, j]
            break
        last = correction
    if not _gain(a, b, r_diag, p, k):
        return GAIN_FAILED, iterations
    _closed_loop(a, b, k, ws[0])
    return _radius_status(ws[0], 1.0 - RADIUS_MARGIN, ws[1], ws[2], NX), iterations


register(_radius_status, lambda: (0.5 * np.eye(NX), 0.9, np.empty((NX, NX)),
                                  np.empty((NX, NX)), NX))
register(dare_gain, lambda: (0.9 * np.eye(NX), np.ones((NX, NU)), np.ones(NX), np.ones(NU),
                             np.empty((NX, NX)), np.empty((NU, NX))))


def spectral_radius_below(m, bound: float) -> bool:
    """Whether the spectral radius of the square real ``m`` is below ``bound``: the squaring
    test of :func:`_radius_status`, and where it cannot decide, the eigenvalues
    (``numpy.linalg.eigvals``). False also if ``m`` has a non-finite entry."""
    m = np.array(m, dtype=np.float64, order="C")
    n = m.shape[0]
    status = _radius_status(m, float(bound), np.empty_like(m), np.empty_like(m), n)
    if status == GAIN_UNDECIDED:
        return float(np.max(np.abs(np.linalg.eigvals(m)))) < bound
    return status == GAIN_STABLE


def stabilising_gain(a: np.ndarray, b: np.ndarray, q_diag: np.ndarray, r_diag: np.ndarray,
                     p: np.ndarray, k: np.ndarray) -> bool:
    """:func:`dare_gain`, with the undecided closed loops settled by their eigenvalues:
    True if ``k`` holds a stabilising gain (spectral radius of ``A - B K`` below
    ``1 - RADIUS_MARGIN``)."""
    status, _ = dare_gain(a, b, q_diag, r_diag, p, k)
    if status == GAIN_UNDECIDED:
        return spectral_radius_below(a - b @ k, 1.0 - RADIUS_MARGIN)
    return status == GAIN_STABLE
