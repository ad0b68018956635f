"""Compiled LQR gain of the companion controller (numba).

The same computation as :meth:`companion.control.lqr.LqrController.gain`, i.e.

1. ``lin = [max(rho, rho_min), alpha, beta]``;
2. Jacobians of the companion model (:func:`companion.model.jacobians`);
3. discretisation, forward Euler or exact zero-order hold (:func:`companion.model.discretize`);
4. augmentation with the previous input (:func:`companion.lqr.augment`);
5. stabilising solution ``P`` of the discrete algebraic Riccati equation and
   ``K = (R + B'PB)^-1 B'PA`` (:func:`companion.lqr.dlqr`),

in ~10 microseconds instead of ~0.7 ms, for small dense matrices and without any Python
object in the hot path. The Riccati equation is solved with the structure-preserving
doubling algorithm (SDA) polished by a Newton step; the zero-order hold uses the
scaling-and-squaring Padé(13) matrix exponential. The compiled functions never raise on bad
numbers: they report failure with a flag, and :func:`lqr_gain` turns it into
``numpy.linalg.LinAlgError`` like ``dlqr``.

All compiled functions use ``error_model="numpy"``: a division by zero gives inf/nan (then
caught by the finiteness checks) instead of raising.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: SDA stops when the largest entry of the update of P is below this times the largest of P;
#: the convergence is quadratic, so the iterate is then within ~1e-14 and the Newton polish
#: (one step) finishes it. (1e-14 here costs one more doubling for the same result.)
DARE_TOL = 1e-8
#: SDA iteration cap: each iteration doubles the horizon; convergent cases need < 40.
DARE_MAX_ITER = 100
#: Smith doubling in a Newton step stops when its update is below this times the correction
#: (the correction itself is normally ~1e-11 of P or less, so this is ample).
NEWTON_TOL = 1e-3
#: Newton steps stop when the correction is below this times P (after one step, normally),
#: when it stops shrinking, or after NEWTON_MAX_STEPS (see _polish).
NEWTON_DONE = 1e-12
NEWTON_MAX_STEPS = 6
#: Same stability margin as :func:`companion.lqr.dlqr`: closed-loop spectral radius < 1 - 1e-9.
RADIUS_MARGIN = 1e-9

# Padé(13) coefficients and the 1-norm bound theta_13 of Higham (2005), as in scipy.linalg.expm.
_PADE13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0,
           1187353796428800.0, 129060195264000.0, 10559470521600.0, 670442572800.0,
           33522128640.0, 1323241920.0, 40840800.0, 960960.0, 16380.0, 182.0, 1.0)
_THETA13 = 5.371920351148152
# rho(M) <= ||M^4096||^(1/4096) < 0.5^(1/4096) = 1 - 1.69e-4: the shortcut of
# spectral_radius_below only proves bounds above this.
_SHORTCUT_RADIUS = 0.5 ** (1.0 / 4096.0)

_JIT = {"cache": True, "error_model": "numpy"}

# The kernels below take their dimensions as arguments. Called from compiled code with literal
# sizes (the 5x5 / 5x2 LQR problem in lqr_gain_nb), numba compiles a specialisation for those
# literal values, LLVM sees constant trip counts and unrolls the loops: ~3x faster than the
# runtime-sized version, which generic callers (solve_dare_nb, expm_nb) use.
#
# Compile time: whole-array assignments (``x[:, :] = y``, ``x[:] = 0.0``), ``np.full`` and
# array operators pull in numba's generic broadcasting code, several seconds of compilation
# each on the project's machine (``gain[:, :] = k`` alone cost ~4 s). The kernels here and in
# the lane modules therefore copy and fill with explicit loops.


# ---------------------------------------------------------------------------------------------
# Small dense linear algebra kernels (explicit loops: for 5x5 matrices they beat BLAS/LAPACK).
# ---------------------------------------------------------------------------------------------

@njit(**_JIT)
def _matmul(a, b, out, n, k, m):
    """``out = a @ b`` for ``a`` (n, k), ``b`` (k, m); ``out`` must not alias ``a`` or ``b``."""
    for i in range(n):
        for j in range(m):
            s = 0.0
            for l in range(k):
                s += a[i, l] * b[l, j]
            out[i, j] = s


@njit(**_JIT)
def _matmul_tn(a, b, out, n, k, m):
    """``out = a.T @ b`` for ``a`` (k, n), ``b`` (k, m); ``out`` must not alias them."""
    for i in range(n):
        for j in range(m):
            s = 0.0
            for l in range(k):
                s += a[l, i] * b[l, j]
            out[i, j] = s


@njit(**_JIT)
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


@njit(**_JIT)
def _lu_solve(lu, piv, b, n, m):
    """Solve ``A X = b`` in place for the (n, m) ``b``, given ``_lu_factor`` of A."""
    for k in range(n):
        p = piv[k]
        if p != k:
            for j in range(m):
                b[k, j], b[p, j] = b[p, j], b[k, j]
    for i in range(1, n):
        for l in range(i):
            f = lu[i, l]
            for j in range(m):
                b[i, j] -= f * b[l, j]
    for i in range(n - 1, -1, -1):
        for l in range(i + 1, n):
            f = lu[i, l]
            for j in range(m):
                b[i, j] -= f * b[l, j]
        d = lu[i, i]
        for j in range(m):
            b[i, j] /= d


@njit(**_JIT)
def _copy(src, dst, n, m):
    """``dst[:n, :m] = src[:n, :m]``."""
    for i in range(n):
        for j in range(m):
            dst[i, j] = src[i, j]


@njit(**_JIT)
def _nan_matrix(n):
    """An (n, n) matrix of nan."""
    out = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = np.nan
    return out


@njit(**_JIT)
def _max_abs(a, n, m):
    """Largest absolute entry of the (n, m) ``a``; nan if an entry is nan."""
    out = 0.0
    for i in range(n):
        for j in range(m):
            x = abs(a[i, j])
            if not x <= out:  # also catches nan
                out = x
    return out


@njit(**_JIT)
def _norm_inf(a, n, m):
    """Infinity-norm (largest absolute row sum) of the (n, m) ``a``; nan if an entry is nan."""
    out = 0.0
    for i in range(n):
        s = 0.0
        for j in range(m):
            s += abs(a[i, j])
        if not s <= out:
            out = s
    return out


# ---------------------------------------------------------------------------------------------
# Model
# ---------------------------------------------------------------------------------------------

@njit(**_JIT)
def jacobians_nb(rho, alpha, beta, v, omega, v_h, omega_h, d):
    """Exact Jacobians of the companion dynamics, as :func:`companion.model.jacobians`.

    Parameters
    ----------
    rho, alpha, beta : float
        State ``chi``; rho must be non-zero.
    v, omega : float
        Robot input ``u``.
    v_h, omega_h : float
        Person velocity ``w`` (``omega_h`` does not enter the Jacobians).
    d : float
        Offset of the reference point ahead of the axle (m).

    Returns
    -------
    jx : ndarray, shape (3, 3)
        ``df/dchi``.
    ju : ndarray, shape (3, 2)
        ``df/du``.
    """
    g = alpha + beta
    sg, cg = math.sin(g), math.cos(g)
    sa, ca = math.sin(alpha), math.cos(alpha)
    dr_dg = -v * sg + d * omega * cg
    num = v_h * sa - v * sg + d * omega * cg
    dnum_dg = -v * cg - d * omega * sg
    jx = np.zeros((3, 3))
    jx[0, 1] = dr_dg + v_h * sa
    jx[0, 2] = dr_dg
    jx[1, 0] = -num / (rho * rho)
    jx[1, 1] = (v_h * ca + dnum_dg) / rho
    jx[1, 2] = dnum_dg / rho
    ju = np.zeros((3, 2))
    ju[0, 0] = cg
    ju[0, 1] = d * sg
    ju[1, 0] = -sg / rho
    ju[1, 1] = d * cg / rho
    ju[2, 1] = -1.0
    return jx, ju


@njit(**_JIT)
def expm_nb(x):
    """Matrix exponential by scaling and squaring with the Padé(13) approximant.

    Higham (2005), "The scaling and squaring method for the matrix exponential revisited":
    scale by ``2^-s`` so that ``||x / 2^s||_1 <= theta_13``, evaluate the [13/13] Padé
    approximant, square ``s`` times. Backward error below the unit roundoff for any ``x``
    (scipy.linalg.expm uses the same approximant, with lower degrees for small norms).

    Parameters
    ----------
    x : ndarray, shape (n, n)

    Returns
    -------
    ndarray, shape (n, n)
        ``exp(x)``; all nan if ``x`` has a non-finite entry.
    """
    return _expm(x, x.shape[0])


@njit(**_JIT)
def _expm(x, n):
    """Body of :func:`expm_nb` for an (n, n) ``x``."""
    nrm = _norm_inf(x.T, n, n)  # 1-norm of x
    if not nrm < np.inf:
        return _nan_matrix(n)
    s = 0
    if nrm > _THETA13:
        s = math.ceil(math.log2(nrm / _THETA13))
    scale = 0.5 ** s
    c = _PADE13
    a = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            a[i, j] = x[i, j] * scale
    a2 = np.empty((n, n))
    a4 = np.empty((n, n))
    a6 = np.empty((n, n))
    _matmul(a, a, a2, n, n, n)
    _matmul(a2, a2, a4, n, n, n)
    _matmul(a4, a2, a6, n, n, n)
    # U = a [a6 (c13 a6 + c11 a4 + c9 a2) + c7 a6 + c5 a4 + c3 a2 + c1 I]
    # V =    a6 (c12 a6 + c10 a4 + c8 a2) + c6 a6 + c4 a4 + c2 a2 + c0 I
    uh = np.empty((n, n))
    vh = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            uh[i, j] = c[13] * a6[i, j] + c[11] * a4[i, j] + c[9] * a2[i, j]
            vh[i, j] = c[12] * a6[i, j] + c[10] * a4[i, j] + c[8] * a2[i, j]
    ul = np.empty((n, n))
    v = np.empty((n, n))
    _matmul(a6, uh, ul, n, n, n)
    _matmul(a6, vh, v, n, n, n)
    for i in range(n):
        for j in range(n):
            ul[i, j] += c[7] * a6[i, j] + c[5] * a4[i, j] + c[3] * a2[i, j]
            v[i, j] += c[6] * a6[i, j] + c[4] * a4[i, j] + c[2] * a2[i, j]
        ul[i, i] += c[1]
        v[i, i] += c[0]
    u = uh
    _matmul(a, ul, u, n, n, n)
    # exp(a) ~ (V - U)^-1 (V + U)
    lu = np.empty((n, n))
    r = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            lu[i, j] = v[i, j] - u[i, j]
            r[i, j] = v[i, j] + u[i, j]
    piv = np.empty(n, np.int64)
    if not _lu_factor(lu, piv, n):
        return _nan_matrix(n)
    _lu_solve(lu, piv, r, n, n)
    tmp = a2
    for _ in range(s):
        _matmul(r, r, tmp, n, n, n)
        r, tmp = tmp, r
    return r


@njit(**_JIT)
def discretize_nb(jx, ju, dt, zoh):
    """Discretise ``dx/dt = jx x + ju u`` with sample period ``dt``, as ``model.discretize``.

    Parameters
    ----------
    jx : ndarray, shape (n, n)
    ju : ndarray, shape (n, m)
    dt : float
    zoh : bool
        False: forward Euler ``(I + dt jx, dt ju)`` (the paper); True: exact zero-order hold,
        read off ``expm(dt [[jx, ju], [0, 0]])``.

    Returns
    -------
    a : ndarray, shape (n, n)
    b : ndarray, shape (n, m)
    """
    n, m = ju.shape
    return _discretize(jx, ju, dt, zoh, n, m, n + m)


@njit(**_JIT)
def _discretize(jx, ju, dt, zoh, n, m, nm):
    """Body of :func:`discretize_nb` for (n, n) ``jx`` and (n, m) ``ju``; ``nm = n + m``."""
    a = np.empty((n, n))
    b = np.empty((n, m))
    if zoh:
        block = np.zeros((nm, nm))
        for i in range(n):
            for j in range(n):
                block[i, j] = dt * jx[i, j]
            for j in range(m):
                block[i, n + j] = dt * ju[i, j]
        e = _expm(block, nm)
        for i in range(n):
            for j in range(n):
                a[i, j] = e[i, j]
            for j in range(m):
                b[i, j] = e[i, n + j]
    else:
        for i in range(n):
            for j in range(n):
                a[i, j] = dt * jx[i, j]
            a[i, i] += 1.0
            for j in range(m):
                b[i, j] = dt * ju[i, j]
    return a, b


@njit(**_JIT)
def augment_nb(a, b):
    """``(A_bar, B_bar) = ([[A, B], [0, I]], [[B], [I]])``, as :func:`companion.lqr.augment`.

    Parameters
    ----------
    a : ndarray, shape (n, n)
    b : ndarray, shape (n, m)

    Returns
    -------
    a_bar : ndarray, shape (n + m, n + m)
    b_bar : ndarray, shape (n + m, m)
    """
    n, m = b.shape
    a_bar = np.zeros((n + m, n + m))
    b_bar = np.zeros((n + m, m))
    for i in range(n):
        for j in range(n):
            a_bar[i, j] = a[i, j]
        for j in range(m):
            a_bar[i, n + j] = b_bar[i, j] = b[i, j]
    for i in range(m):
        a_bar[n + i, n + i] = 1.0
        b_bar[n + i, i] = 1.0
    return a_bar, b_bar


# ---------------------------------------------------------------------------------------------
# Riccati equation, stability test and gain
# ---------------------------------------------------------------------------------------------

@njit(**_JIT)
def _sda(a, b, q, r, p_out, n, m):
    """Body of :func:`solve_dare_nb` for an (n, n) ``a`` and (n, m) ``b``."""
    # G_0 = B R^-1 B', H_0 = Q (both symmetrised), A_0 = A.
    r_lu = r.copy()
    piv_m = np.empty(m, np.int64)
    if not _lu_factor(r_lu, piv_m, m):
        return False, 0
    rinv_bt = np.empty((m, n))
    for i in range(m):
        for j in range(n):
            rinv_bt[i, j] = b[j, i]
    _lu_solve(r_lu, piv_m, rinv_bt, m, n)
    g = np.empty((n, n))
    _matmul(b, rinv_bt, g, n, m, n)
    h = p_out
    for i in range(n):
        for j in range(i, n):
            g[i, j] = g[j, i] = 0.5 * (g[i, j] + g[j, i])
            h[i, j] = h[j, i] = 0.5 * (q[i, j] + q[j, i])
    ak = a.copy()
    w = np.empty((n, n))
    piv = np.empty(n, np.int64)
    w_ia = np.empty((n, n))         # W_k^-1 A_k
    w_ig = np.empty((n, n))         # W_k^-1 G_k
    tmp = np.empty((n, n))
    dh = np.empty((n, n))
    dg = np.empty((n, n))
    for it in range(1, DARE_MAX_ITER + 1):
        _matmul(g, h, w, n, n, n)
        for i in range(n):
            w[i, i] += 1.0
        if not _lu_factor(w, piv, n):
            return False, it
        _copy(ak, w_ia, n, n)
        _copy(g, w_ig, n, n)
        _lu_solve(w, piv, w_ia, n, n)
        _lu_solve(w, piv, w_ig, n, n)
        _matmul(h, w_ia, tmp, n, n, n)
        _matmul_tn(ak, tmp, dh, n, n, n)        # A_k' H_k W^-1 A_k
        _matmul(ak, w_ig, tmp, n, n, n)
        _matmul(tmp, ak.T, dg, n, n, n)         # A_k W^-1 G_k A_k'
        _matmul(ak, w_ia, tmp, n, n, n)         # A_{k+1} = A_k W^-1 A_k
        ak, tmp = tmp, ak
        step = 0.0                              # max |H_{k+1} - H_k|
        size = 0.0                              # max |H_{k+1}|
        total = 0.0                             # not finite iff an entry of G or H is not
        for i in range(n):
            for j in range(i, n):
                x = 0.5 * (dh[i, j] + dh[j, i])
                h[i, j] = h[j, i] = h[i, j] + x
                g[i, j] = g[j, i] = g[i, j] + 0.5 * (dg[i, j] + dg[j, i])
                step = max(step, abs(x))
                size = max(size, abs(h[i, j]))
                total += h[i, j] + g[i, j]
        if not abs(total) < np.inf:
            return False, it
        if step <= DARE_TOL * size:
            return _polish(a, b, q, r, h, n, m), it
    return False, DARE_MAX_ITER


@njit(**_JIT)
def _polish(a, b, q, r, p, n, m):
    """Newton steps on the converged SDA solution ``p`` (in place), while they converge.

    Normally one step, whose correction is below ``NEWTON_DONE``. Otherwise steps continue
    while each correction is at most a tenth of the previous one (quadratic convergence) and
    stop at ``NEWTON_DONE``, when the correction stops shrinking (it has reached the rounding
    floor of the residual) or after ``NEWTON_MAX_STEPS``. If already the second correction
    does not shrink, the Newton corrections are rounding noise amplified by an ill-conditioned
    Stein equation (seen for strongly non-normal closed loops, where they made ``K`` worse by
    1e3) and the SDA solution is restored. Returns False only if a step fails (non-finite
    numbers or a closed loop that is not stable).
    """
    p_sda = p.copy()
    last = np.inf
    for step in range(NEWTON_MAX_STEPS):
        correction = _newton_step(a, b, q, r, p, n, m)
        if not correction >= 0.0:
            return False
        if correction <= NEWTON_DONE:
            return True
        if correction > 0.1 * last:
            if step == 1:
                _copy(p_sda, p, n, n)
            return True
        last = correction
    return True


@njit(**_JIT)
def _gain(a, b, r, p, k_out, n, m):
    """``k_out = (R + B'PB)^-1 B'PA``; False if ``R + B'PB`` is singular."""
    bt_p = np.empty((m, n))
    _matmul_tn(b, p, bt_p, m, n, n)
    s = np.empty((m, m))
    _matmul(bt_p, b, s, m, n, m)
    for i in range(m):
        for j in range(m):
            s[i, j] += r[i, j]
    _matmul(bt_p, a, k_out, m, n, n)
    piv = np.empty(m, np.int64)
    if not _lu_factor(s, piv, m):
        return False
    _lu_solve(s, piv, k_out, m, n)
    return True


@njit(**_JIT)
def _closed_loop(a, b, k, out, n, m):
    """``out = A - B K``."""
    _matmul(b, k, out, n, m, n)
    for i in range(n):
        for j in range(n):
            out[i, j] = a[i, j] - out[i, j]


@njit(**_JIT)
def _newton_step(a, b, q, r, p, n, m):
    """One Newton (Hewer) step on an approximate stabilising DARE solution ``p``, in place.

    With ``K = K(P)`` and ``Ac = A - B K``, the correction ``D`` solves the Stein equation
    ``D - Ac' D Ac = Q + K'RK + Ac' P Ac - P`` (the right-hand side is the Riccati residual of
    ``P``), by Smith's doubling ``D <- D + M' D M``, ``M <- M^2`` from ``D = residual``,
    ``M = Ac``, until the update is below ``NEWTON_TOL`` times ``D``; ``p`` becomes the Newton
    iterate ``P + D``. Returns ``max|D| / max|P + D|``, or -1 if the Smith doubling does not
    converge (closed loop not stable) or produces non-finite numbers.
    """
    k = np.empty((m, n))
    if not _gain(a, b, r, p, k, n, m):
        return -1.0
    ac = np.empty((n, n))
    _closed_loop(a, b, k, ac, n, m)
    tmp = np.empty((n, n))
    d = np.empty((n, n))
    _matmul(p, ac, tmp, n, n, n)
    _matmul_tn(ac, tmp, d, n, n, n)                 # Ac' P Ac
    rk = np.empty((m, n))
    _matmul(r, k, rk, m, m, n)
    krk = np.empty((n, n))
    _matmul_tn(k, rk, krk, n, m, n)                 # K' R K
    for i in range(n):
        for j in range(i, n):
            x = 0.5 * ((q[i, j] + krk[i, j] + d[i, j]) + (q[j, i] + krk[j, i] + d[j, i]))
            d[i, j] = d[j, i] = x - p[i, j]
    mj = ac
    mm = np.empty((n, n))
    t = np.empty((n, n))
    for _ in range(DARE_MAX_ITER):
        _matmul(d, mj, tmp, n, n, n)
        _matmul_tn(mj, tmp, t, n, n, n)             # M' D M
        step = 0.0
        size = 0.0
        total = 0.0
        for i in range(n):
            for j in range(i, n):
                x = 0.5 * (t[i, j] + t[j, i])
                d[i, j] = d[j, i] = d[i, j] + x
                step = max(step, abs(x))
                size = max(size, abs(d[i, j]))
                total += d[i, j]
        if not abs(total) < np.inf:
            return -1.0
        if step <= NEWTON_TOL * size:
            for i in range(n):
                for j in range(n):
                    p[i, j] += d[i, j]
            scale = _max_abs(p, n, n)
            return size / scale if scale > 0.0 else size
        _matmul(mj, mj, mm, n, n, n)
        mj, mm = mm, mj
    return -1.0


@njit(**_JIT)
def solve_dare_nb(a, b, q, r, p_out):
    """Stabilising solution of ``P = A'PA - A'PB (R + B'PB)^-1 B'PA + Q`` by doubling (SDA).

    Structure-preserving doubling algorithm (Chu, Fan, Lin and Wang 2004), with
    ``A_0 = A``, ``G_0 = B R^-1 B'``, ``H_0 = Q`` and, for ``W_k = I + G_k H_k``::

        A_{k+1} = A_k W_k^-1 A_k
        G_{k+1} = G_k + A_k W_k^-1 G_k A_k'
        H_{k+1} = H_k + A_k' H_k W_k^-1 A_k

    ``H_k`` is the Riccati recursion from ``P = Q`` after ``2^k`` steps and increases
    monotonically to ``P``. When (A, B) is stabilisable and (Q, A) detectable the
    convergence is quadratic, the error shrinking like ``rho(A - BK)^(2^(k+1))``. The
    iteration stops when the largest entry of the update of ``H`` is at most ``DARE_TOL``
    (1e-8) times the largest entry of ``H``: the updates shrink quadratically, so the next
    one would be ~1e-14, which the Newton polish removes. Typically 8-11 iterations; close to the
    stabilisability boundary (closed-loop spectral radius ``1 - eps``) about
    ``log2(37 / eps)``, e.g. ~35 for ``eps = 1e-9``.

    The converged iterate is then polished by Newton (Hewer) steps (:func:`_polish`), one in
    the usual case: the doubling accumulates rounding errors that, with ill-scaled weights
    (say R = diag(0.01, 44)) leave a relative Riccati residual of 1e-11 and a relative error
    of ``K`` of ~3e-8, and near the stabilisability boundary (a closed-loop pole within ~1e-5
    of the unit circle) errors of ``P`` up to 1e-4. Checked against a 50-digit reference:
    after polishing, the relative error of ``K`` was below 2e-10 wherever the closed-loop
    margin exceeds 1e-6 and below 1e-7 down to a margin of 1e-9, where scipy's
    ``solve_discrete_are`` was off by up to 0.5 or failed. Where the Newton corrections do not
    converge (rounding noise of a very ill-conditioned problem) the SDA solution is kept.

    Parameters
    ----------
    a : ndarray, shape (n, n)
    b : ndarray, shape (n, m)
    q : ndarray, shape (n, n)
        Symmetric positive semi-definite.
    r : ndarray, shape (m, m)
        Symmetric positive definite.
    p_out : ndarray, shape (n, n)
        Receives ``P`` (the last iterate if not converged).

    Returns
    -------
    converged : bool
        False if the doubling did not converge within ``DARE_MAX_ITER`` steps, met a singular
        ``W_k`` or ``R`` or non-finite numbers, or a Newton step failed. Convergence alone
        does not prove that ``P`` is stabilising: check the closed loop (as
        :func:`lqr_gain_nb` does).
    iterations : int
        Number of doubling steps taken.
    """
    n, m = b.shape
    return _sda(a, b, q, r, p_out, n, m)


@njit(**_JIT)
def _radius_below(m, bound, n):
    """Body of :func:`spectral_radius_below` for an (n, n) ``m``."""
    if not _max_abs(m, n, n) < np.inf:
        return False
    if bound > _SHORTCUT_RADIUS:
        x = m.copy()
        y = np.empty((n, n))
        for _ in range(12):
            _matmul(x, x, y, n, n, n)
            nrm = _norm_inf(y, n, n)
            if nrm < 0.5:
                return True
            if not nrm < 1e3:
                break
            x, y = y, x
    return _eig_radius(m) < bound


@njit(**_JIT)
def _eig_radius(m):
    """Spectral radius from the eigenvalues (LAPACK ``zgeev``: numba rejects a real matrix
    whose eigenvalues are complex, so the matrix is passed as complex)."""
    radius = 0.0
    for lam in np.linalg.eigvals(m.astype(np.complex128)):
        radius = max(radius, abs(lam))
    return radius


@njit(**_JIT)
def spectral_radius_below(m, bound):
    """Whether the spectral radius of the square real ``m`` is below ``bound``.

    Cheap sufficient test first: ``rho(M)^j <= ||M^j||`` for any j and norm, so if a power
    ``M^(2^s)``, s = 1..12, computed by repeated squaring, has infinity-norm below 0.5, then
    ``rho(M) <= 0.5^(1/4096) = 1 - 1.69e-4`` and, for ``bound`` above that, the answer is yes
    without eigenvalues. The 0.5 margin dwarfs the rounding errors of the squarings, which
    are only continued while the norm stays below 1e3. Otherwise (slow or no decay, or a
    large transient) the eigenvalues are computed with LAPACK (``np.linalg.eigvals`` on a
    complex copy: numba rejects a real matrix with complex eigenvalues) and compared with
    ``bound``. For the LQR closed loops here the shortcut needs a few squarings (~0.1-0.5 us
    in all) where the eigenvalues take ~7 us.

    Parameters
    ----------
    m : ndarray, shape (n, n)
    bound : float

    Returns
    -------
    bool
        False also if ``m`` has a non-finite entry.
    """
    return _radius_below(m, bound, m.shape[0])


@njit(**_JIT)
def lqr_gain_nb(rho, alpha, beta, v, omega, v_h, omega_h, d, dt, zoh, rho_min,
                q_diag, r_diag, k_out):
    """LQR gain ``K`` of the augmented companion model linearised at ``(chi, u, w)``.

    Steps 1-5 of :meth:`companion.control.lqr.LqrController.gain` (see the module docstring),
    with the Riccati equation solved by :func:`solve_dare_nb`.

    Parameters
    ----------
    rho, alpha, beta : float
        State ``chi`` at which to linearise (rho is floored at ``rho_min``).
    v, omega : float
        Robot input ``u``.
    v_h, omega_h : float
        Person velocity ``w``.
    d : float
        Offset of the reference point (m).
    dt : float
        Sample period (s).
    zoh : bool
        Zero-order-hold discretisation (True) or forward Euler (False).
    rho_min : float
        Floor on rho in the Jacobians.
    q_diag : ndarray, shape (5,)
        Diagonal of Q.
    r_diag : ndarray, shape (2,)
        Diagonal of R.
    k_out : ndarray, shape (2, 5)
        Receives ``K`` (undefined when the function returns False).

    Returns
    -------
    bool
        False where no stabilising gain was found: the SDA or its Newton polish did not
        converge (see :func:`solve_dare_nb`), a number is not finite, or the closed loop
        ``A_bar - B_bar K`` has spectral radius >= 1 - 1e-9 (the test of
        :func:`companion.lqr.dlqr`; see :func:`spectral_radius_below`).
    """
    return lqr_gain_p_nb(rho, alpha, beta, v, omega, v_h, omega_h, d, dt, zoh, rho_min,
                         q_diag, r_diag, k_out, np.empty((5, 5)))


@njit(**_JIT)
def augmented_model_nb(rho, alpha, beta, v, omega, v_h, omega_h, d, dt, zoh, rho_min):
    """``(A_bar, B_bar)``: the augmented companion model linearised at ``(chi, u, w)`` (rho
    floored at ``rho_min``), discretised (zero-order hold or forward Euler)."""
    jx, ju = jacobians_nb(max(rho, rho_min), alpha, beta, v, omega, v_h, omega_h, d)
    a, b = _discretize(jx, ju, dt, zoh, 3, 2, 5)
    return augment_nb(a, b)


@njit(**_JIT)
def lqr_gain_p_nb(rho, alpha, beta, v, omega, v_h, omega_h, d, dt, zoh, rho_min,
                  q_diag, r_diag, k_out, p_out):
    """:func:`lqr_gain_nb` that also returns the Riccati solution in ``p_out`` (5, 5)."""
    nx, nu = 5, 2
    a_bar, b_bar = augmented_model_nb(rho, alpha, beta, v, omega, v_h, omega_h, d, dt, zoh,
                                      rho_min)
    q = np.zeros((nx, nx))
    for i in range(nx):
        q[i, i] = q_diag[i]
    r = np.zeros((nu, nu))
    for i in range(nu):
        r[i, i] = r_diag[i]
    ok, _ = _sda(a_bar, b_bar, q, r, p_out, nx, nu)
    if not (ok and _gain(a_bar, b_bar, r, p_out, k_out, nx, nu)):
        return False
    if not _max_abs(k_out, nu, nx) < np.inf:
        return False
    closed = np.empty((nx, nx))
    _closed_loop(a_bar, b_bar, k_out, closed, nx, nu)
    return _radius_below(closed, 1.0 - RADIUS_MARGIN, nx)


def lqr_gain(chi, u, w, params) -> np.ndarray:
    """LQR gain of :meth:`companion.control.lqr.LqrController.gain`, compiled.

    Parameters
    ----------
    chi : array_like, shape (3,)
        ``[rho, alpha, beta]`` at which to linearise.
    u : array_like, shape (2,)
        Robot input ``[v, omega]``.
    w : array_like, shape (2,)
        Person velocity ``[v_h, omega_h]``.
    params : companion.params.Params
        Uses ``robot.d``, ``dt``, ``lqr.discretization``, ``lqr.rho_min``, ``lqr.q``, ``lqr.r``.

    Returns
    -------
    ndarray, shape (2, 5)
        ``K``; the control law is ``du = -K xi``.

    Raises
    ------
    ValueError
        If ``params.lqr.discretization`` is neither 'euler' nor 'zoh'.
    numpy.linalg.LinAlgError
        Where no stabilising gain exists.
    """
    lqr = params.lqr
    if lqr.discretization not in ("euler", "zoh"):
        raise ValueError(f"lqr_gain: discretization must be 'euler' or 'zoh', "
                         f"got {lqr.discretization!r}")
    k = np.empty((2, 5))
    ok = lqr_gain_nb(float(chi[0]), float(chi[1]), float(chi[2]), float(u[0]), float(u[1]),
                     float(w[0]), float(w[1]), float(params.robot.d), float(params.dt),
                     lqr.discretization == "zoh", float(lqr.rho_min),
                     np.asarray(lqr.q, dtype=np.float64), np.asarray(lqr.r, dtype=np.float64), k)
    if not ok:
        raise np.linalg.LinAlgError("lqr_gain: no stabilising solution of the Riccati equation")
    return k


# -- the whole controller step ---------------------------------------------------------------
# Compiled twins of companion.kinematics.wrap_pi / wrap_2pi and companion.model.relative_state /
# slot_reference (used by companion.control.lqr_lanes): the same floating-point operations in
# the same order. Results agree to rounding, not always bit for bit (Python's math.hypot is its own
# correctly rounded algorithm, numba's is not); tests/test_fastlqr.py checks them.

_TWO_PI = 2.0 * math.pi


@njit(**_JIT)
def wrap_pi_nb(angle):
    """:func:`companion.kinematics.wrap_pi`: wrap to (-pi, pi]."""
    a = np.fmod(angle + math.pi, _TWO_PI)
    if a <= 0.0:
        a += _TWO_PI
    return a - math.pi


@njit(**_JIT)
def wrap_2pi_nb(angle):
    """:func:`companion.kinematics.wrap_2pi`: wrap to [0, 2*pi)."""
    a = np.fmod(angle, _TWO_PI)
    if a < 0.0:
        a += _TWO_PI
    return 0.0 if a >= _TWO_PI else a


@njit(**_JIT)
def relative_state_nb(robot_x, robot_y, robot_theta, person_x, person_y, person_theta, d):
    """:func:`companion.model.relative_state`: ``(rho, alpha, beta)``."""
    dx = robot_x + d * math.cos(robot_theta) - person_x
    dy = robot_y + d * math.sin(robot_theta) - person_y
    rho = math.hypot(dx, dy)
    alpha = wrap_2pi_nb(math.atan2(dy, dx) - person_theta)
    beta = wrap_pi_nb(person_theta - robot_theta)
    return rho, alpha, beta


@njit(**_JIT)
def slot_reference_nb(v_h, omega_h, rho_d, alpha_d, d):
    """:func:`companion.model.slot_reference` without the ``feasible`` flag:
    ``(beta, v, omega)``."""
    vx = v_h - rho_d * omega_h * math.sin(alpha_d)
    vy = rho_d * omega_h * math.cos(alpha_d)
    speed = math.hypot(vx, vy)
    lateral = d * omega_h
    if speed < 1e-9:
        return 0.0, 0.0, omega_h
    psi = math.atan2(vy, vx)
    ratio = max(-1.0, min(1.0, lateral / speed))
    delta = math.asin(ratio)
    along = math.sqrt(max(speed * speed - lateral * lateral, 0.0))
    theta_fwd = psi - delta
    theta_rev = psi + math.pi + delta
    if abs(wrap_pi_nb(theta_fwd)) <= abs(wrap_pi_nb(theta_rev)):
        return wrap_pi_nb(-theta_fwd), along, omega_h
    return wrap_pi_nb(-theta_rev), -along, omega_h


#: Layout of the ``config`` array of :func:`lqr_step_nb` and of a ``config`` row of
#: :mod:`companion.control.lqr_lanes` (see :func:`lqr_step_config`).
CONFIG_FIELDS = ("d", "dt", "zoh", "rho_min", "rho_d", "alpha_d", "geometric",
                 "measured", "clip_rho", "clip_alpha", "clip_beta", "v_max", "omega_max")


def lqr_step_config(params) -> np.ndarray:
    """The parameters :func:`lqr_step_nb` and an LQR lane need, as a float array in
    :data:`CONFIG_FIELDS` order (flags as 0.0 / 1.0)."""
    lqr, f, r = params.lqr, params.formation, params.robot
    return np.array([r.d, params.dt, lqr.discretization == "zoh", lqr.rho_min, f.distance,
                     f.bearing, lqr.feedforward == "geometric", lqr.linearize_at == "measured",
                     *lqr.error_clip, r.v_max, r.omega_max], dtype=np.float64)


@njit(**_JIT)
def lqr_step_nb(rx, ry, rth, hx, hy, hth, hv, hw, config, q_diag, r_diag, memory, gain,
                rest_gain, xi):
    """One step of :class:`companion.control.lqr.LqrController` with the compiled gain.

    Parameters
    ----------
    rx, ry, rth : float
        Robot pose.
    hx, hy, hth, hv, hw : float
        Person state.
    config : ndarray, shape (13,)
        :func:`lqr_step_config`.
    q_diag, r_diag : ndarray, shapes (5,) and (2,)
    memory : ndarray, shape (3,)
        ``[v_e(k-1), omega_e(k-1), has_gain]``, updated in place (``u_e`` from the saturated
        output; the caller overwrites it with the finally applied command).
    gain : ndarray, shape (2, 5)
        Last good gain, updated in place.
    rest_gain : ndarray, shape (2, 5)
        Fallback while no gain has been found.
    xi : ndarray, shape (5,)
        Receives the augmented state.

    Returns
    -------
    (v, omega, v_d, omega_d, beta_d) : floats
    """
    d, dt, zoh, rho_min = config[0], config[1], config[2] != 0.0, config[3]
    rho_d, alpha_d = config[4], config[5]
    rho, alpha, beta = relative_state_nb(rx, ry, rth, hx, hy, hth, d)
    if config[6] != 0.0:
        beta_d, v_d, omega_d = slot_reference_nb(hv, hw, rho_d, alpha_d, d)
    else:
        beta_d, v_d, omega_d = 0.0, hv, hw
    e_v, e_w = memory[0], memory[1]
    if config[7] != 0.0:
        lin = (rho, alpha, beta, v_d + e_v, omega_d + e_w)
    else:
        lin = (rho_d, alpha_d, beta_d, v_d, omega_d)
    k = np.empty((2, 5))
    if lqr_gain_nb(lin[0], lin[1], lin[2], lin[3], lin[4], hv, hw, d, dt, zoh, rho_min,
                   q_diag, r_diag, k):
        _copy(k, gain, 2, 5)
        memory[2] = 1.0
    elif memory[2] == 0.0:
        _copy(rest_gain, gain, 2, 5)
        memory[2] = 1.0
    xi[0] = min(max(rho - rho_d, -config[8]), config[8])
    xi[1] = min(max(wrap_pi_nb(alpha - alpha_d), -config[9]), config[9])
    xi[2] = min(max(wrap_pi_nb(beta - beta_d), -config[10]), config[10])
    xi[3] = e_v
    xi[4] = e_w
    du_v = 0.0
    du_w = 0.0
    for j in range(5):
        du_v += gain[0, j] * xi[j]
        du_w += gain[1, j] * xi[j]
    v = min(max(v_d + e_v - du_v, -config[11]), config[11])
    om = min(max(omega_d + e_w - du_w, -config[12]), config[12])
    memory[0] = v - v_d
    memory[1] = om - omega_d
    return v, om, v_d, omega_d, beta_d


# -- many Riccati equations at once (batch simulation) ----------------------------------------
# Arrays of shape (rows, cols, L) hold one matrix per lane (episode) with the lane index last
# and contiguous, so that every loop below runs over lanes innermost and compiles to SIMD
# instructions. The method is Newton's (Hewer's) iteration warm-started from each lane's
# previous Riccati solution (the operating point moves little in one period), with the Stein
# equations solved by Smith's doubling: matrix products only, no pivoting, no branches per
# lane. Lanes without a warm start or where the iteration fails take the scalar cold path
# (lqr_gain_p_nb).

#: A lane's Newton iteration stops after a correction below this times its P: the error left
#: is then of the order of its square (quadratic convergence), ~1e-12 and less.
LANES_DONE = 1e-9
LANES_MAX_STEPS = 5
#: The Stein equation of a Newton step is solved to this relative accuracy, so that the
#: truncation (this times the correction) stays below the Newton error.
LANES_SMITH_TOL = 1e-7


@njit(**_JIT)
def _mm_lanes(a, b, out, n, m, lanes):
    """``out[:, :, e] = a[:, :, e] @ b[:, :, e]`` for every lane ``e``; ``a`` (n, 5, L),
    ``b`` (5, m, L). The inner dimension is written out, so that each output stays in a
    register while the lane loop runs on SIMD units."""
    for i in range(n):
        for j in range(m):
            for e in range(lanes):
                out[i, j, e] = (a[i, 0, e] * b[0, j, e] + a[i, 1, e] * b[1, j, e]
                                + a[i, 2, e] * b[2, j, e] + a[i, 3, e] * b[3, j, e]
                                + a[i, 4, e] * b[4, j, e])


@njit(**_JIT)
def _mm_tn_lanes(a, b, out, n, m, lanes):
    """``out[:, :, e] = a[:, :, e].T @ b[:, :, e]`` for every lane; ``a`` (5, n, L), ``b``
    (5, m, L)."""
    for i in range(n):
        for j in range(m):
            for e in range(lanes):
                out[i, j, e] = (a[0, i, e] * b[0, j, e] + a[1, i, e] * b[1, j, e]
                                + a[2, i, e] * b[2, j, e] + a[3, i, e] * b[3, j, e]
                                + a[4, i, e] * b[4, j, e])


@njit(**_JIT)
def _gain_lanes(a, b, r_diag, p, k, lanes):
    """``K = (R + B'PB)^-1 B'PA`` per lane (the 2x2 solve in closed form)."""
    n, m = b.shape[0], b.shape[1]   # runtime sizes: loops over lanes are the hot ones
    bt_p = np.empty((m, n, lanes))
    s = np.empty((m, m, lanes))
    _mm_tn_lanes(b, p, bt_p, m, n, lanes)
    _mm_lanes(bt_p, b, s, m, m, lanes)
    _mm_lanes(bt_p, a, k, m, n, lanes)
    for e in range(lanes):
        s00 = s[0, 0, e] + r_diag[0, e]
        s11 = s[1, 1, e] + r_diag[1, e]
        s01 = 0.5 * (s[0, 1, e] + s[1, 0, e])
        det = s00 * s11 - s01 * s01
        for j in range(n):
            x0, x1 = k[0, j, e], k[1, j, e]
            k[0, j, e] = (s11 * x0 - s01 * x1) / det
            k[1, j, e] = (s00 * x1 - s01 * x0) / det


@njit(**_JIT)
def newton_lanes(a, b, q_diag, r_diag, p, active, lanes, corr):
    """One Newton (Hewer) step on the Riccati equations of ``lanes`` lanes, in place.

    Parameters
    ----------
    a : ndarray, shape (5, 5, L)
    b : ndarray, shape (5, 2, L)
    q_diag, r_diag : ndarrays, shapes (5, L) and (2, L)
    p : ndarray, shape (5, 5, L)
        Stabilising approximations of the solutions; replaced by the Newton iterates.
    active : ndarray of bool, shape (L,)
        Lanes to update (the others are computed but left unchanged).
    lanes : int
        Number of lanes in use (``<= L``).
    corr : ndarray, shape (L,)
        Receives ``max|correction| / max|P|`` per lane, or ``inf`` where the Stein equation
        did not converge (closed loop not stable) or a number is not finite.
    """
    n = a.shape[0]
    k = np.empty((2, n, lanes))
    _gain_lanes(a, b, r_diag, p, k, lanes)
    ac = np.empty((n, n, lanes))
    for i in range(n):
        for j in range(n):
            for e in range(lanes):
                ac[i, j, e] = a[i, j, e] - (b[i, 0, e] * k[0, j, e] + b[i, 1, e] * k[1, j, e])
    tmp = np.empty((n, n, lanes))
    d = np.empty((n, n, lanes))
    _mm_lanes(p, ac, tmp, n, n, lanes)
    _mm_tn_lanes(ac, tmp, d, n, n, lanes)
    for i in range(n):
        for j in range(n):
            for e in range(lanes):
                krk = r_diag[0, e] * k[0, i, e] * k[0, j, e] + r_diag[1, e] * k[1, i, e] * k[1, j, e]
                d[i, j, e] += krk - p[i, j, e]
            if i == j:
                for e in range(lanes):
                    d[i, i, e] += q_diag[i, e]
    # Smith's doubling for D - Ac' D Ac = residual: D += M' D M, M <- M^2.
    m_pow = ac
    m_sq = np.empty((n, n, lanes))
    t = np.empty((n, n, lanes))
    done = np.empty(lanes, np.bool_)
    for e in range(lanes):
        done[e] = not active[e]   # inactive lanes take no part (a stale P must not stall the block)
    step = np.empty(lanes)
    size = np.empty(lanes)
    for _ in range(DARE_MAX_ITER):
        _mm_lanes(d, m_pow, tmp, n, n, lanes)
        _mm_tn_lanes(m_pow, tmp, t, n, n, lanes)
        for e in range(lanes):
            step[e] = 0.0
            size[e] = 0.0
        for i in range(n):
            for j in range(n):
                for e in range(lanes):
                    # A lane that is done keeps its D: its result must not depend on the
                    # other lanes of the block (a lane alone gives the same bits).
                    x = d[i, j, e] if done[e] else d[i, j, e] + t[i, j, e]
                    d[i, j, e] = x
                    step[e] = max(step[e], abs(t[i, j, e]))
                    size[e] = max(size[e], abs(x))
        all_done = True
        for e in range(lanes):
            if not done[e]:
                if step[e] <= LANES_SMITH_TOL * size[e] or not step[e] < np.inf:
                    done[e] = True
                else:
                    all_done = False
        if all_done:
            break
        _mm_lanes(m_pow, m_pow, m_sq, n, n, lanes)
        m_pow, m_sq = m_sq, m_pow
    for e in range(lanes):
        dmax = 0.0
        pmax = 0.0
        total = 0.0
        for i in range(n):
            for j in range(i, n):
                x = 0.5 * (d[i, j, e] + d[j, i, e])
                y = p[i, j, e] + x
                dmax = max(dmax, abs(x))
                pmax = max(pmax, abs(y))
                total += y
        if not done[e] or not abs(total) < np.inf:
            corr[e] = np.inf
            continue
        corr[e] = dmax / pmax if pmax > 0.0 else dmax
        if active[e]:
            for i in range(n):
                for j in range(i, n):
                    x = p[i, j, e] + 0.5 * (d[i, j, e] + d[j, i, e])
                    p[i, j, e] = x
                    p[j, i, e] = x


@njit(**_JIT)
def stable_lanes(a, b, k, lanes, ok):
    """Whether each lane's closed loop ``A - B K`` has spectral radius below
    ``1 - RADIUS_MARGIN``, as :func:`spectral_radius_below` decides it: the squaring shortcut
    for all lanes at once, the eigenvalues for the lanes it cannot settle. ``a`` (5, 5, L),
    ``b`` (5, 2, L), ``k`` (2, 5, L); ``ok`` (L,) receives the answers."""
    n = a.shape[0]
    x = np.empty((n, n, lanes))
    y = np.empty((n, n, lanes))
    for i in range(n):
        for j in range(n):
            for e in range(lanes):
                x[i, j, e] = a[i, j, e] - (b[i, 0, e] * k[0, j, e] + b[i, 1, e] * k[1, j, e])
    closed = x.copy()
    pending = np.zeros(lanes, np.bool_)
    nrm = np.empty(lanes)
    row = np.empty(lanes)
    for e in range(lanes):
        ok[e] = False
        pending[e] = _max_abs(closed[:, :, e].copy(), n, n) < np.inf
    scalar = pending.copy()      # lanes to settle one by one if the shortcut does not
    if 1.0 - RADIUS_MARGIN > _SHORTCUT_RADIUS:
        for _ in range(12):
            _mm_lanes(x, x, y, n, n, lanes)
            for e in range(lanes):
                nrm[e] = 0.0
            for i in range(n):
                for e in range(lanes):
                    row[e] = 0.0
                for j in range(n):
                    for e in range(lanes):
                        row[e] += abs(y[i, j, e])
                for e in range(lanes):
                    nrm[e] = max(nrm[e], row[e])
            left = False
            for e in range(lanes):
                if pending[e]:
                    if nrm[e] < 0.5:
                        ok[e] = True
                        pending[e] = False
                        scalar[e] = False
                    elif not nrm[e] < 1e3:
                        pending[e] = False
                    else:
                        left = True
            if not left:
                break
            x, y = y, x
    for e in range(lanes):
        if scalar[e]:
            ok[e] = _radius_below(closed[:, :, e].copy(), 1.0 - RADIUS_MARGIN, n)
