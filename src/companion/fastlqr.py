"""Compiled LQR gain of the companion controller (numba).

The same computation as :meth:`companion.control.lqr.LqrController.gain`, i.e.

1. ``lin = [max(rho, rho_min), alpha, beta]``;
2. Jacobians of the companion model (:func:`companion.model.jacobians`);
3. discretisation, forward Euler or exact zero-order hold (:func:`companion.model.discretize`);
4. augmentation with the previous input (:func:`companion.lqr.augment`);
5. stabilising solution ``P`` of the discrete algebraic Riccati equation and
   ``K = (R + B'PB)^-1 B'PA`` (:func:`companion.lqr.dlqr`),

in ~10 microseconds instead of ~1 ms, for small dense matrices and without any Python
object in the hot path: :func:`model_euler_nb` / :func:`model_zoh_nb` (steps 1-4) and
:func:`dare_gain_nb` (step 5). The Riccati equation is solved with the structure-preserving
doubling algorithm (SDA) polished by a Newton step; the zero-order hold uses the
scaling-and-squaring Padé(13) matrix exponential. The compiled functions never raise on bad
numbers: they report failure with a status, :func:`stabilising_gain` settles the closed loops
the compiled stability test cannot decide with numpy's eigenvalues, and :func:`lqr_gain`
turns failure into ``numpy.linalg.LinAlgError`` like ``dlqr``. The controller step is
:func:`lqr_prepare_nb`, :func:`stabilising_gain` and :func:`lqr_output_nb`; the batch
simulation's lane kernels are at the end of the module.

All compiled functions use ``error_model="numpy"``: a division by zero gives inf/nan (then
caught by the finiteness checks) instead of raising.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from companion import _jitcache

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
#: when it stops shrinking, or after NEWTON_MAX_STEPS (see dare_gain_nb).
NEWTON_DONE = 1e-12
NEWTON_MAX_STEPS = 6
#: A Newton step is skipped (correction 0) when the Riccati residual of P is at most this
#: times max|P|: that is the rounding level of the residual's own evaluation, which a Newton
#: step cannot improve on. The SDA leaves 2e-16 (median) to 2e-14 (largest) over 2,000
#: walking operating points, so the polish costs its residual only (~0.5 us instead of ~3 us)
#: except where the doubling accumulated errors (ill-scaled weights, near the boundary).
NEWTON_SKIP = 1e-15
#: Same stability margin as :func:`companion.lqr.dlqr`: closed-loop spectral radius < 1 - 1e-9.
RADIUS_MARGIN = 1e-9

# Padé(13) coefficients and the 1-norm bound theta_13 of Higham (2005), as in scipy.linalg.expm.
_PADE13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0,
           1187353796428800.0, 129060195264000.0, 10559470521600.0, 670442572800.0,
           33522128640.0, 1323241920.0, 40840800.0, 960960.0, 16380.0, 182.0, 1.0)
_THETA13 = 5.371920351148152
# rho(M) <= ||M^4096||^(1/4096) < 0.5^(1/4096) = 1 - 1.69e-4: the squaring test of
# _radius_status only proves bounds above this.
_SHORTCUT_RADIUS = 0.5 ** (1.0 / 4096.0)

_JIT = {"cache": True, "error_model": "numpy", "no_cfunc_wrapper": True}
#: Functions only called from compiled code: no Python wrapper to compile.
_INNER = {**_JIT, "no_cpython_wrapper": True}
#: Lane kernels inlined into their callers at numba IR level: compiled once as part of the
#: caller instead of compiled on their own and then linked and optimised again.
_INLINE = {**_JIT, "inline": "always"}

#: Sizes of the augmented companion model: 5 states, 2 inputs.
NX, NU = 5, 2
#: Status of :func:`dare_gain_nb` (and of the stability tests).
GAIN_FAILED, GAIN_STABLE, GAIN_UNDECIDED = 0, 1, 2
#: Name of :func:`sda_nb` in the compile cache (:func:`compile_sda`).
SDA_KERNELS = "sda"
#: 5x5 scratch matrices of dare_gain_nb (_sda uses 0-7, the saved SDA solution is 8).
_WORKSPACE = 9

# The kernels below take their dimensions as arguments. Called from compiled code with literal
# sizes (NX = 5 in dare_gain_nb), numba compiles a specialisation for those literal values,
# LLVM sees constant trip counts and unrolls the loops: ~3x faster than the runtime-sized
# version, which generic callers (expm_nb, spectral_radius_below) use.
#
# Compile time (first call with an empty cache; docs/performance.md): each distinct
# specialisation and each compiled function costs ~0.2-1 s, and a function is compiled with
# all the code it calls linked in and optimised again. Hence one 5x5 product specialisation
# (transposes are explicit), a flat call tree under dare_gain_nb, helpers without Python or
# cfunc wrappers, and the zero-order hold and the eigenvalues kept out of the default path.
#
# Compile time: whole-array assignments (``x[:, :] = y``, ``x[:] = 0.0``), ``np.full`` and
# array operators pull in numba's generic broadcasting code, several seconds of compilation
# each on the project's machine (``gain[:, :] = k`` alone cost ~4 s). The kernels here and in
# the lane modules therefore copy and fill with explicit loops.


# ---------------------------------------------------------------------------------------------
# Small dense linear algebra kernels (explicit loops: for 5x5 matrices they beat BLAS/LAPACK).
# ---------------------------------------------------------------------------------------------

@njit(**_INNER)
def _matmul(a, b, out, n, k, m):
    """``out = a @ b`` for ``a`` (n, k), ``b`` (k, m); ``out`` must not alias ``a`` or ``b``."""
    for i in range(n):
        for j in range(m):
            s = 0.0
            for l in range(k):
                s += a[i, l] * b[l, j]
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


@njit(**_INNER)
def _nan_matrix(n):
    """An (n, n) matrix of nan."""
    out = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = np.nan
    return out


@njit(**_INNER)
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


@njit(**_INNER)
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


@njit(**_INNER)
def _augment(phi, gamma, a, b):
    """Write the augmented model ``A_bar = [[phi, gamma], [0, I]]``, ``B_bar = [[gamma], [I]]``
    (:func:`companion.lqr.augment`) into ``a`` (5, 5) and ``b`` (5, 2); ``phi`` is (3, 3) and
    ``gamma`` (3, 2)."""
    for i in range(NX):
        for j in range(NX):
            a[i, j] = 0.0
        for j in range(NU):
            b[i, j] = 0.0
    for i in range(3):
        for j in range(3):
            a[i, j] = phi[i, j]
        for j in range(NU):
            a[i, 3 + j] = gamma[i, j]
            b[i, j] = gamma[i, j]
    for i in range(NU):
        a[3 + i, 3 + i] = 1.0
        b[3 + i, i] = 1.0


@njit(**_JIT)
def model_euler_nb(rho, alpha, beta, v, omega, v_h, omega_h, d, dt, a, b):
    """Augmented companion model linearised at ``(chi, u, w)`` and discretised by forward
    Euler, ``(I + dt Jx, dt Ju)`` (the paper), written into ``a`` (5, 5) and ``b`` (5, 2).

    The same as ``augment(*discretize(*jacobians(chi, u, w, d), dt, "euler"))`` of
    :mod:`companion.model` and :mod:`companion.lqr`. ``rho`` must be non-zero (the callers
    floor it at ``lqr.rho_min``).
    """
    jx, ju = jacobians_nb(rho, alpha, beta, v, omega, v_h, omega_h, d)
    phi = np.empty((3, 3))
    gamma = np.empty((3, NU))
    for i in range(3):
        for j in range(3):
            phi[i, j] = dt * jx[i, j]
        phi[i, i] += 1.0
        for j in range(NU):
            gamma[i, j] = dt * ju[i, j]
    _augment(phi, gamma, a, b)


@njit(**_JIT)
def model_zoh_nb(rho, alpha, beta, v, omega, v_h, omega_h, d, dt, a, b):
    """:func:`model_euler_nb` with the exact zero-order-hold discretisation, read off
    ``expm(dt [[Jx, Ju], [0, 0]])`` (:func:`expm_nb`).

    A separate function, compiled only when a zero-order-hold controller runs (the matrix
    exponential is ~3 s of compilation)."""
    jx, ju = jacobians_nb(rho, alpha, beta, v, omega, v_h, omega_h, d)
    block = np.zeros((NX, NX))
    for i in range(3):
        for j in range(3):
            block[i, j] = dt * jx[i, j]
        for j in range(NU):
            block[i, 3 + j] = dt * ju[i, j]
    e = _expm(block, NX)
    phi = np.empty((3, 3))
    gamma = np.empty((3, NU))
    for i in range(3):
        for j in range(3):
            phi[i, j] = e[i, j]
        for j in range(NU):
            gamma[i, j] = e[i, 3 + j]
    _augment(phi, gamma, a, b)


def augmented_model(chi, u, w, d: float, dt: float, zoh: bool,
                    rho_min: float) -> tuple[np.ndarray, np.ndarray]:
    """``(A_bar, B_bar)``, shapes (5, 5) and (5, 2): the augmented companion model linearised
    at ``(chi, u, w)`` (rho floored at ``rho_min``), discretised by zero-order hold (``zoh``)
    or forward Euler; :func:`model_zoh_nb` or :func:`model_euler_nb`."""
    a, b = np.empty((NX, NX)), np.empty((NX, NU))
    model = model_zoh_nb if zoh else model_euler_nb
    model(max(float(chi[0]), rho_min), float(chi[1]), float(chi[2]), float(u[0]), float(u[1]),
          float(w[0]), float(w[1]), float(d), float(dt), a, b)
    return a, b


# ---------------------------------------------------------------------------------------------
# Riccati equation, gain and stability
# ---------------------------------------------------------------------------------------------
# Fixed sizes: the augmented model has NX = 5 states and NU = 2 inputs, Q and R are diagonal.
# The call tree is kept flat (dare_gain_nb calls every part itself): numba compiles each
# function with all the code it calls linked in and optimised again, so every level of
# nesting costs compilation time again.

@njit(**_INNER)
def _sda(a, b, q_diag, r_diag, h, ws):
    """Structure-preserving doubling for the DARE of ``a`` (5, 5), ``b`` (5, 2), ``Q =
    diag(q_diag)``, ``R = diag(r_diag)``; ``h`` receives the last iterate. ``ws`` is the
    (>= 9, 5, 5) workspace of :func:`dare_gain_nb`. Returns ``(converged, iterations)``."""
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
            for l in range(NX):
                x += b[l, i] * p[l, j]
            bt_p[i, j] = x
    s00, s01, s10, s11 = r_diag[0], 0.0, 0.0, r_diag[1]
    for l in range(NX):
        s00 += bt_p[0, l] * b[l, 0]
        s01 += bt_p[0, l] * b[l, 1]
        s10 += bt_p[1, l] * b[l, 0]
        s11 += bt_p[1, l] * b[l, 1]
    s01 = 0.5 * (s01 + s10)
    det = s00 * s11 - s01 * s01
    if not (det != 0.0 and abs(det) < np.inf):
        return False
    finite = True
    for j in range(NX):
        x0 = 0.0
        x1 = 0.0
        for l in range(NX):
            x0 += bt_p[0, l] * a[l, j]
            x1 += bt_p[1, l] * a[l, j]
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
def dare_gain_nb(a, b, q_diag, r_diag, p, k):
    """LQR gain of ``(A, B)`` = ``a`` (5, 5), ``b`` (5, 2) with ``Q = diag(q_diag)``,
    ``R = diag(r_diag)``: the stabilising solution ``P`` of the discrete algebraic Riccati
    equation ``P = A'PA - A'PB (R + B'PB)^-1 B'PA + Q`` and ``K = (R + B'PB)^-1 B'PA``.

    1. Structure-preserving doubling (SDA; Chu, Fan, Lin and Wang 2004), with ``A_0 = A``,
       ``G_0 = B R^-1 B'``, ``H_0 = Q`` and, for ``W_k = I + G_k H_k``::

           A_{k+1} = A_k W_k^-1 A_k
           G_{k+1} = G_k + A_k W_k^-1 G_k A_k'
           H_{k+1} = H_k + A_k' H_k W_k^-1 A_k

       ``H_k`` is the Riccati recursion from ``P = Q`` after ``2^k`` steps and increases
       monotonically to ``P``. When (A, B) is stabilisable and (Q, A) detectable the
       convergence is quadratic, the error shrinking like ``rho(A - BK)^(2^(k+1))``. The
       iteration stops when the largest entry of the update of ``H`` is at most ``DARE_TOL``
       (1e-8) times the largest entry of ``H``. Typically 8-11 iterations; close to the
       stabilisability boundary (closed-loop spectral radius ``1 - eps``) about
       ``log2(37 / eps)``, e.g. ~35 for ``eps = 1e-9``.
    2. Newton (Hewer) steps polish the result (:func:`_newton`), normally none beyond
       evaluating the residual (at the rounding level, ``NEWTON_SKIP``), else normally one,
       whose correction is below ``NEWTON_DONE``: the doubling accumulates rounding errors that,
       with ill-scaled weights (say R = diag(0.01, 44)), leave a relative Riccati residual of
       1e-11 and a relative error of ``K`` of ~3e-8, and near the stabilisability boundary
       errors of ``P`` up to 1e-4. Steps continue while each correction is at most a tenth
       of the previous one (quadratic convergence), up to ``NEWTON_MAX_STEPS``. If already
       the second correction does not shrink, the corrections are rounding noise amplified
       by an ill-conditioned Stein equation (seen for strongly non-normal closed loops, where
       they made ``K`` worse by 1e3) and the SDA solution is restored. Checked against a
       50-digit reference: the relative error of ``K`` was below 2e-10 wherever the
       closed-loop margin exceeds 1e-6 and below 1e-7 down to a margin of 1e-9, where scipy's
       ``solve_discrete_are`` was off by up to 0.5 or failed.
    3. ``K``, and the closed loop ``A - B K`` tested for spectral radius below
       ``1 - RADIUS_MARGIN`` (the test of :func:`companion.lqr.dlqr`) by repeated squaring
       (:func:`_radius_status`).

    Parameters
    ----------
    a : ndarray, shape (5, 5)
    b : ndarray, shape (5, 2)
    q_diag : ndarray, shape (5,)
        Diagonal of Q, >= 0.
    r_diag : ndarray, shape (2,)
        Diagonal of R, > 0.
    p : ndarray, shape (5, 5)
        Receives ``P`` (the last iterate if the doubling did not converge).
    k : ndarray, shape (2, 5)
        Receives ``K`` (undefined unless the status is stable or undecided).

    Returns
    -------
    status : int
        :data:`GAIN_STABLE`; :data:`GAIN_UNDECIDED` where the squaring cannot prove the
        closed loop stable (radius within ~1.7e-4 of 1, or a large transient): the caller
        decides with the eigenvalues (:func:`stabilising_gain`); :data:`GAIN_FAILED` where the
        doubling did not converge within ``DARE_MAX_ITER`` steps, met a singular ``W_k`` or
        non-finite numbers, a Newton step failed, or the closed loop is not finite.
    iterations : int
        Number of doubling steps taken.
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


@njit(**_JIT, nogil=True)
def sda_nb(a, b, q_diag, r_diag, p):
    """Step 1 of :func:`dare_gain_nb` alone (the structure-preserving doubling, no polish):
    True if it converged; ``p`` receives the last iterate. The lanes
    (:mod:`companion.control.lqr_lanes`) start their Newton iteration from it where their
    own start failed."""
    ok, _ = _sda(a, b, q_diag, r_diag, p, np.empty((_WORKSPACE, NX, NX)))
    return ok


def compile_sda() -> None:
    """Compile (or load from the cache) :func:`sda_nb` on a dummy model and mark it compiled
    (``SDA_KERNELS``); run in a helper process by a first batch
    (:func:`companion._jitcache.compile_in_helper`)."""
    sda_nb(0.5 * np.eye(NX), np.ones((NX, NU)), np.ones(NX), np.ones(NU), np.empty((NX, NX)))
    _jitcache.mark_compiled(SDA_KERNELS)


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
    """:func:`dare_gain_nb`, with the undecided closed loops settled by their eigenvalues:
    True if ``k`` holds a stabilising gain (spectral radius of ``A - B K`` below
    ``1 - RADIUS_MARGIN``)."""
    status, _ = dare_gain_nb(a, b, q_diag, r_diag, p, k)
    if status == GAIN_UNDECIDED:
        return spectral_radius_below(a - b @ k, 1.0 - RADIUS_MARGIN)
    return status == GAIN_STABLE


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
    a, b = augmented_model(chi, u, w, params.robot.d, params.dt, lqr.discretization == "zoh",
                           float(lqr.rho_min))
    k, p = np.empty((NU, NX)), np.empty((NX, NX))
    if not stabilising_gain(a, b, np.asarray(lqr.q, dtype=np.float64),
                            np.asarray(lqr.r, dtype=np.float64), p, k):
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


#: Layout of the ``config`` array of :func:`lqr_prepare_nb` and of a ``config`` row of
#: :mod:`companion.control.lqr_lanes` (see :func:`lqr_step_config`).
CONFIG_FIELDS = ("d", "dt", "zoh", "rho_min", "rho_d", "alpha_d", "geometric",
                 "measured", "clip_rho", "clip_alpha", "clip_beta", "v_max", "omega_max")


def lqr_step_config(params) -> np.ndarray:
    """The parameters of the compiled step and of an LQR lane, as a float array in
    :data:`CONFIG_FIELDS` order (flags as 0.0 / 1.0)."""
    lqr, f, r = params.lqr, params.formation, params.robot
    return np.array([r.d, params.dt, lqr.discretization == "zoh", lqr.rho_min, f.distance,
                     f.bearing, lqr.feedforward == "geometric", lqr.linearize_at == "measured",
                     *lqr.error_clip, r.v_max, r.omega_max], dtype=np.float64)


#: Layout of the ``op`` array of :func:`lqr_prepare_nb`: the operating point of the gain
#: (rho floored at ``rho_min``), the person velocity and the feedforward.
OP_FIELDS = ("rho", "alpha", "beta", "v", "omega", "v_h", "omega_h", "v_d", "omega_d", "beta_d")


@njit(**_JIT)
def lqr_prepare_nb(rx, ry, rth, hx, hy, hth, hv, hw, config, memory, op, xi, a, b):
    """Steps 1-4 of :meth:`companion.control.lqr.LqrController.step`: relative state,
    feedforward, operating point and clipped error.

    Parameters
    ----------
    rx, ry, rth : float
        Robot pose.
    hx, hy, hth, hv, hw : float
        Person state.
    config : ndarray, shape (13,)
        :func:`lqr_step_config`.
    memory : ndarray, shape (3,)
        ``[v_e(k-1), omega_e(k-1), has_gain]`` (read).
    op : ndarray, shape (10,)
        Receives the operating point, person velocity and feedforward (:data:`OP_FIELDS`).
    xi : ndarray, shape (5,)
        Receives the augmented state ``[rho_e, alpha_e, beta_e, v_e(k-1), omega_e(k-1)]``
        with the errors clipped to ``lqr.error_clip``.
    a, b : ndarrays, shapes (5, 5) and (5, 2)
        Receive the forward-Euler model at ``op`` (:func:`model_euler_nb`); a zero-order-hold
        controller replaces it with :func:`model_zoh_nb`.
    """
    d, dt, rho_min, rho_d, alpha_d = config[0], config[1], config[3], config[4], config[5]
    rho, alpha, beta = relative_state_nb(rx, ry, rth, hx, hy, hth, d)
    if config[6] != 0.0:
        beta_d, v_d, omega_d = slot_reference_nb(hv, hw, rho_d, alpha_d, d)
    else:
        beta_d, v_d, omega_d = 0.0, hv, hw
    e_v, e_w = memory[0], memory[1]
    if config[7] != 0.0:
        op[0], op[1], op[2], op[3], op[4] = rho, alpha, beta, v_d + e_v, omega_d + e_w
    else:
        op[0], op[1], op[2], op[3], op[4] = rho_d, alpha_d, beta_d, v_d, omega_d
    op[0] = max(op[0], rho_min)
    op[5], op[6], op[7], op[8], op[9] = hv, hw, v_d, omega_d, beta_d
    xi[0] = min(max(rho - rho_d, -config[8]), config[8])
    xi[1] = min(max(wrap_pi_nb(alpha - alpha_d), -config[9]), config[9])
    xi[2] = min(max(wrap_pi_nb(beta - beta_d), -config[10]), config[10])
    xi[3] = e_v
    xi[4] = e_w
    model_euler_nb(op[0], op[1], op[2], op[3], op[4], hv, hw, d, dt, a, b)


@njit(**_JIT)
def lqr_output_nb(found, k, gain, rest_gain, memory, xi, op, config):
    """Step 5 of :meth:`companion.control.lqr.LqrController.step`: ``u = u_d + u_e(k-1) -
    K xi`` clipped to the input limits.

    ``gain`` (2, 5) becomes ``k`` if ``found`` (a stabilising gain), else keeps the last good
    gain, or becomes ``rest_gain`` if there is none yet (``memory[2]`` 0). ``memory[:2]``
    becomes ``u_e(k)`` of the saturated output (the caller overwrites it with the finally
    applied command). ``xi`` and ``op`` are those of :func:`lqr_prepare_nb`. Returns
    ``(v, omega)``.
    """
    if found or memory[2] == 0.0:
        new = k if found else rest_gain
        for i in range(NU):
            for j in range(NX):
                gain[i, j] = new[i, j]
        memory[2] = 1.0
    du_v = 0.0
    du_w = 0.0
    for j in range(NX):
        du_v += gain[0, j] * xi[j]
        du_w += gain[1, j] * xi[j]
    v_d, omega_d = op[7], op[8]
    v = min(max(v_d + xi[3] - du_v, -config[11]), config[11])
    om = min(max(omega_d + xi[4] - du_w, -config[12]), config[12])
    memory[0] = v - v_d
    memory[1] = om - omega_d
    return v, om


# -- many Riccati equations at once (batch simulation) ----------------------------------------
# Arrays of shape (rows, cols, L) hold one matrix per lane (episode) with the lane index last
# and contiguous, so that every loop below runs over lanes innermost and compiles to SIMD
# instructions. The method is Newton's (Hewer's) iteration warm-started from each lane's
# previous Riccati solution (the operating point moves little in one period), with the Stein
# equations solved by Smith's doubling: matrix products only, no pivoting, no branches per
# lane. A lane without a previous solution starts from the solution at its rest operating
# point (computed once per parameter set). Lanes where the iteration fails (its start does not
# stabilise the model) restart from the doubling alone (sda_nb); converged lanes whose closed
# loop the squaring test cannot prove stable are decided by their eigenvalues; only a lane
# that fails after the restart takes the scalar solver (stabilising_gain). See
# companion.control.lqr_lanes.

#: A lane's Newton iteration stops after a correction below this times its P: the error left
#: is then of the order of its square (quadratic convergence), ~1e-18 ...
LANES_DONE = 1e-9
#: Newton steps per period for all lanes; lanes still iterating then go on alone, up to
#: LANES_LONG_STEPS in all (Newton's iteration from a stabilising start always converges;
#: from the rest solution or after a sudden change it needs more than a warm period's 1-3).
LANES_MAX_STEPS = 5
LANES_LONG_STEPS = 40
#: ... or when its next correction, predicted from the quadratic convergence with a safety
#: factor, is below LANES_PREDICTED (see solve_lanes). On the
#: figure-8 the measured ratio of a correction to the square of the previous one was 0.2-2.2.
LANES_PREDICTED = 1e-11
LANES_SAFETY = 4.0
LANES_QUAD_DECAY = 0.9
LANES_QUAD_MIN = 1e-7
#: ... and only for a correction below this: the ratio decays on a lane that converges in one
#: step for a long time, and the cap bounds what is left after a stop whatever the estimate
#: (the ratio times its square: ~9e-12 of P for the largest ratio measured). Measured on
#: the figure-8: lane gains within 5e-12 of the cold gains (8e-15 median).
LANES_ACCEPT_MAX = 2e-6
#: The Stein equation of a Newton step is solved to this relative accuracy, so that the
#: truncation (this times the correction) stays below the Newton error.
LANES_SMITH_TOL = 1e-7


@njit(**_INNER)
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


@njit(**_INNER)
def _mm_tn_lanes(a, b, out, n, m, lanes):
    """``out[:, :, e] = a[:, :, e].T @ b[:, :, e]`` for every lane; ``a`` (5, n, L), ``b``
    (5, m, L)."""
    for i in range(n):
        for j in range(m):
            for e in range(lanes):
                out[i, j, e] = (a[0, i, e] * b[0, j, e] + a[1, i, e] * b[1, j, e]
                                + a[2, i, e] * b[2, j, e] + a[3, i, e] * b[3, j, e]
                                + a[4, i, e] * b[4, j, e])


@njit(**_INLINE)
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


@njit(**_INLINE)
def newton_lanes(a, b, q_diag, r_diag, p, active, lanes, corr, proved):
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
    proved : ndarray of bool, shape (L,)
        For the active lanes: whether the squarings ``M = Ac^(2^s)`` of the Smith doubling
        proved the closed loop ``Ac = A - B K(P)`` of this step stable, as the squaring test
        of :func:`_radius_status` would (a norm below 0.5 at s <= 12 before any above 1e3;
        only squarings made while the lane was still iterating count, so that the answer does
        not depend on the other lanes).
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
    squarings_ok = np.empty(lanes, np.bool_)  # no squaring norm above 1e3 so far
    nrm = np.empty(lanes)
    row = np.empty(lanes)
    for e in range(lanes):
        squarings_ok[e] = True
        if active[e]:
            proved[e] = False
    shortcut = 1.0 - RADIUS_MARGIN > _SHORTCUT_RADIUS
    for it in range(DARE_MAX_ITER):
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
        if shortcut and it < 12:              # m_pow = Ac^(2^(it + 1))
            for e in range(lanes):
                nrm[e] = 0.0
            for i in range(n):
                for e in range(lanes):
                    row[e] = 0.0
                for j in range(n):
                    for e in range(lanes):
                        row[e] += abs(m_pow[i, j, e])
                for e in range(lanes):
                    nrm[e] = max(nrm[e], row[e])
            for e in range(lanes):
                if active[e] and not done[e] and squarings_ok[e]:
                    if nrm[e] < 0.5:
                        proved[e] = True
                    elif not nrm[e] < 1e3:
                        squarings_ok[e] = False
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


#: ``corr`` of a lane whose Newton iteration was still going when :func:`solve_lanes`
#: stopped.
LANES_UNFINISHED = 1.0
#: Name of :func:`solve_lanes` in the compile cache (:func:`compile_solve_lanes`).
SOLVE_LANES_KERNELS = "solve_lanes"


@njit(**_INNER)
def _warm_start_lane(p, past, history, lane, j):
    """Replace ``p[:, :, j]`` = P(t-1) by the prediction of P(t) and shift it into
    ``past[:, :, :, j]`` (P(t-2), P(t-3), P(t-4)), for a lane with ``history`` solved periods
    in a row.

    The prediction is the polynomial extrapolation of order 0 (``P(t-1)``), 1
    (``2 P(t-1) - P(t-2)``) or 2 (``3 P(t-1) - 3 P(t-2) + P(t-3)``) that would have predicted
    ``P(t-1)`` best from the periods before (order 0 with fewer than two periods, order 1
    after two, as nothing can be compared yet). On smooth motion that is order 2 (first
    Newton correction ~1e-6 of P instead of ~3e-5 with order 1 on the figure-8); with sensor
    noise, order 0 (the extrapolations amplify the noise)."""
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


@njit(**_JIT, nogil=True)
def solve_lanes(a, b, qd, rd, p, past, history, extrapolate, quad, active, steps, corr, proved,
                k):
    """At most ``steps`` Newton steps on the ``active`` lanes of every block, from their
    ``p`` (first replaced by :func:`_warm_start_lane`'s prediction if ``extrapolate``; the
    quadratic-convergence ratios then decay, see below). ``corr`` of an active lane ends 0
    where it converged, ``LANES_UNFINISHED`` where it was still iterating after ``steps`` and
    inf where a step failed (the lane's ``p`` is then its last successful iterate);
    ``proved`` True where its last step's squarings proved its closed loop stable; ``k``
    (blocks, 2, 5, L) each lane's gain from its ``p`` (:func:`_gain_lanes`) in the blocks with
    an active lane. Blocks without an active lane are skipped.

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
                _warm_start_lane(p[blk], past[blk], history, lane, j)
                quad[lane] *= LANES_QUAD_DECAY
        any_active = left
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
        if any_active:
            _gain_lanes(a[blk], b[blk], rd[blk], p[blk], k[blk], block)


def compile_solve_lanes() -> None:
    """Compile (or load from the cache) :func:`solve_lanes`, the largest lane kernel, by
    running it on one dummy lane; then mark it compiled. A first batch runs this in a helper
    process (:func:`companion._jitcache.compile_in_helper`) while it compiles the other
    kernels itself."""
    solve_lanes(np.zeros((1, NX, NX, 1)), np.zeros((1, NX, NU, 1)), np.ones((1, NX, 1)),
                np.ones((1, NU, 1)), np.zeros((1, NX, NX, 1)), np.zeros((1, 3, NX, NX, 1)),
                np.zeros(1, np.int64), True, np.zeros(1), np.zeros(1, np.bool_), 1,
                np.zeros((1, 1)), np.zeros((1, 1), np.bool_), np.zeros((1, NU, NX, 1)))
    _jitcache.mark_compiled(SOLVE_LANES_KERNELS)
