"""The walker filter's arithmetic, compiled: an interacting multiple model (IMM) of two
coordinated-turn unscented Kalman filters over the state ``(x, y, vx, vy, omega)``.

These are plain functions (:func:`~companion._jit.jitable`) that the tests run as Python and
:func:`imm_predict` / :func:`imm_update` run compiled (:func:`~companion._jit.kernel`).
They compute what filterpy's ``UnscentedKalmanFilter`` with Merwe's scaled sigma points
computes (:mod:`companion.tracking.reference` is that filter, and the tests compare the two);
the walker filter (:mod:`companion.tracking.walker`) decides what to measure and when.
"""

from __future__ import annotations

import math

import numpy as np

from companion._jit import jitable, kernel
from companion.geometry import unicycle_step, wrap_pi

#: Merwe's scaled sigma points: spread, prior knowledge (2: Gaussian) and secondary scaling.
ALPHA, BETA, KAPPA = 0.3, 2.0, 0.0
#: An innovation covariance eigenvalue at or below this fraction of the largest: singular
#: (or indefinite), and the update is skipped.
SINGULAR = 1e-14


@jitable
def coordinated_turn(x: np.ndarray, dt: float) -> np.ndarray:
    """The state ``(x, y, vx, vy, omega)`` ``dt`` s on: the velocity turns at the rate
    ``omega`` at constant speed (the unicycle arc)."""
    speed, heading = math.hypot(x[2], x[3]), math.atan2(x[3], x[2])
    px, py, th = unicycle_step(x[0], x[1], heading, speed, x[4], dt)
    return np.array((px, py, speed * math.cos(th), speed * math.sin(th), x[4]))


@jitable
def process_noise(dt: float, accel_std: float, turn_accel_std: float) -> np.ndarray:
    """Q over ``dt``: white acceleration in x and y (m/s^2) and of the turn rate (rad/s^2),
    discrete white-noise form."""
    q = np.zeros((5, 5))
    a2 = accel_std ** 2
    for i in range(2):
        q[i, i] = a2 * dt ** 4 / 4.0
        q[i, i + 2] = a2 * dt ** 3 / 2.0
        q[i + 2, i] = a2 * dt ** 3 / 2.0
        q[i + 2, i + 2] = a2 * dt * dt
    q[4, 4] = (turn_accel_std * dt) ** 2
    return q


@jitable
def psd_sqrt(a: np.ndarray) -> np.ndarray:
    """``U`` with ``U' U = a`` for a symmetric positive semi-definite ``a``: its upper
    Cholesky factor (filterpy's default square root), or where rounding made ``a`` not
    positive definite, the eigen-decomposition's root with negative eigenvalues clipped."""
    n = len(a)
    u = np.zeros((n, n))
    for j in range(n):
        d = a[j, j]
        for i in range(j):
            d -= u[i, j] * u[i, j]
        if not d > 0.0:
            w, v = np.linalg.eigh(0.5 * (a + a.T))
            return np.sqrt(np.maximum(w, 0.0)).reshape(-1, 1) * v.T
        u[j, j] = math.sqrt(d)
        for k in range(j + 1, n):
            e = 0.5 * (a[j, k] + a[k, j])
            for i in range(j):
                e -= u[i, j] * u[i, k]
            u[j, k] = e / u[j, j]
    return u


@jitable
def weights(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(Wm, Wc)``: the weights of the mean and of the covariance of Merwe's ``2n + 1``
    scaled sigma points."""
    lam = ALPHA ** 2 * (n + KAPPA) - n
    wm = np.full(2 * n + 1, 0.5 / (n + lam))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = lam / (n + lam) + (1.0 - ALPHA ** 2 + BETA)
    return wm, wc


@jitable
def sigma_points(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Merwe's scaled sigma points of mean ``x`` and covariance ``p``, one per row."""
    n = len(x)
    lam = ALPHA ** 2 * (n + KAPPA) - n
    u = psd_sqrt((lam + n) * p)
    s = np.empty((2 * n + 1, n))
    s[0] = x
    for k in range(n):
        s[k + 1] = x + u[k]
        s[n + k + 1] = x - u[k]
    return s


@jitable
def weighted_cov(wc: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``sum_i wc[i] a[i] b[i]'`` for rows ``a[i]``, ``b[i]``."""
    out = np.zeros((a.shape[1], b.shape[1]))
    for i in range(len(wc)):
        for j in range(a.shape[1]):
            wa = wc[i] * a[i, j]
            for k in range(b.shape[1]):
                out[j, k] += wa * b[i, k]
    return out


@jitable
def ukf_predict(x: np.ndarray, p: np.ndarray, dt: float, q: np.ndarray) -> np.ndarray:
    """The covariance of the coordinated turn of ``(x, p)`` over ``dt`` plus ``q`` (the
    sigma points' spread around their mean). The mean the filter keeps is
    ``coordinated_turn(x, dt)``: the sigma points' mean would shrink the speed by
    ``E[cos(omega dt)]`` each step, a bias of a few percent at a steady walk."""
    wm, wc = weights(len(x))
    s = sigma_points(x, p)
    f = np.empty_like(s)
    for i in range(len(s)):
        f[i] = coordinated_turn(s[i], dt)
    y = f - wm @ f
    out = weighted_cov(wc, y, y) + q
    return 0.5 * (out + out.T)


@jitable
def measured(s: np.ndarray, heading: bool, velocity: bool) -> np.ndarray:
    """What a detection measures of the state ``s``: position, then the heading of the
    velocity if ``heading``, then the speed and turn rate if ``velocity``."""
    m = 2 + int(heading) + 2 * int(velocity)
    z = np.empty(m)
    z[0], z[1] = s[0], s[1]
    k = 2
    if heading:
        z[2] = math.atan2(s[3], s[2])
        k = 3
    if velocity:
        z[k] = math.hypot(s[2], s[3])
        z[k + 1] = s[4]
    return z


@jitable
def ukf_update(x: np.ndarray, p: np.ndarray, z: np.ndarray, r: np.ndarray, heading: bool,
               velocity: bool) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """``(x, p)`` updated with the measurement ``z`` of noise ``r`` (:func:`measured`):
    ``(x, p, log_likelihood, ok)``, the log-likelihood of ``z`` under the prediction;
    ``ok`` False (and ``(x, p)`` unchanged) where the innovation covariance is not finite
    or not positive definite. (It can be indefinite: the central sigma point's weight is
    negative, and the heading of a nearly standing walker is very nonlinear. filterpy
    inverts it anyway; that update would be noise.)"""
    wm, wc = weights(len(x))
    pj = p + 1e-12 * np.eye(len(x))
    s = sigma_points(x, pj)
    m = len(z)
    h = np.empty((len(s), m))
    for i in range(len(s)):
        h[i] = measured(s[i], heading, velocity)
    zp = wm @ h
    dz = h - zp
    y = z - zp
    if heading:
        for i in range(len(s)):
            dz[i, 2] = wrap_pi(dz[i, 2])
        y[2] = wrap_pi(y[2])
    cov = weighted_cov(wc, dz, dz) + r
    cov = 0.5 * (cov + cov.T)
    if not np.all(np.isfinite(cov)) or not np.all(np.isfinite(y)):
        return x, p, -math.inf, False
    w, v = np.linalg.eigh(cov)
    if w[0] <= SINGULAR * max(w[-1], 0.0):
        return x, p, -math.inf, False
    inv = (v / w) @ v.T
    gain = weighted_cov(wc, s - x, dz) @ inv
    a = v.T @ y
    log_l = -0.5 * (m * math.log(2.0 * math.pi) + np.sum(np.log(w)) + np.sum(a * a / w))
    xn = x + gain @ y
    pn = pj - gain @ cov @ gain.T
    return xn, 0.5 * (pn + pn.T), log_l, True


@jitable
def mixture(xs: np.ndarray, ps: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mean and covariance of the two models mixed by ``mu`` (the mean exactly the
    models' where they agree)."""
    d = xs[0] - xs[1]
    x = xs[0].copy() if not np.any(d) else mu[0] * xs[0] + mu[1] * xs[1]
    return x, mu[0] * ps[0] + mu[1] * ps[1] + (mu[0] * mu[1]) * np.outer(d, d)


@jitable
def imm_predict(xs: np.ndarray, ps: np.ndarray, mu: np.ndarray, dt: float,
                noise: np.ndarray, start_rate: float, end_rate: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The two models (rows of ``xs``, ``ps``; probabilities ``mu``) predicted ``dt`` s on:
    mixed by their chance of switching in ``dt`` (a steady walk turns into a manoeuvre at
    ``start_rate``, a manoeuvre ends at ``end_rate``, 1/s), then each predicted with its
    process noise (row ``j`` of ``noise``: acceleration and turn acceleration std).
    A model whose mixed covariance is 0 (exact) is predicted exactly. Returns the models'
    states, covariances and probabilities and their :func:`mixture`."""
    start = 1.0 - math.exp(-start_rate * dt)
    end = 1.0 - math.exp(-end_rate * dt)
    switch = np.array(((1.0 - start, start), (end, 1.0 - end)))
    prior = switch.T @ mu
    xn, pn = np.empty_like(xs), np.empty_like(ps)
    for j in range(2):
        w = switch[:, j] * mu / prior[j]          # was i, given now j
        x0 = w[0] * xs[0] + w[1] * xs[1]
        p0 = w[0] * ps[0] + w[1] * ps[1]
        for i in range(2):
            d = xs[i] - x0
            for a in range(5):
                for b in range(5):
                    p0[a, b] += w[i] * d[a] * d[b]
        q = process_noise(dt, noise[j, 0], noise[j, 1])
        xn[j] = coordinated_turn(x0, dt)
        pn[j] = q if not np.any(p0) else ukf_predict(x0, p0, dt, q)
    x, p = mixture(xn, pn, prior)
    return xn, pn, prior, x, p


@jitable
def imm_update(xs: np.ndarray, ps: np.ndarray, mu: np.ndarray, z: np.ndarray, r: np.ndarray,
               heading: bool, velocity: bool, max_speed: float, max_turn_rate: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Both models updated with ``z`` (:func:`ukf_update`), speeds clipped to ``max_speed``
    and turn rates to ``max_turn_rate``; the models' probabilities by how well each
    predicted ``z`` (at least 1e-6 each); and their :func:`mixture`."""
    xn, pn, log_l = np.empty_like(xs), np.empty_like(ps), np.empty(2)
    for j in range(2):
        x, p, log_l[j], ok = ukf_update(xs[j], ps[j], z, r, heading, velocity)
        if ok:
            speed = math.hypot(x[2], x[3])
            if speed > max_speed:
                x[2:4] *= max_speed / speed * (1.0 - 1e-12)   # rounding stays below
            x[4] = min(max(x[4], -max_turn_rate), max_turn_rate)
        xn[j], pn[j] = x, p
    top = max(log_l[0], log_l[1])
    m = mu * np.exp(log_l - top) if math.isfinite(top) else mu.copy()
    m = np.minimum(np.maximum(m / m.sum(), 1e-6), 1.0)
    m = m / m.sum()
    x, p = mixture(xn, pn, m)
    return xn, pn, m, x, p


def _example_belief() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two models' states, covariances and probabilities: the kernels' example arguments."""
    return np.zeros((2, 5)), np.tile(np.eye(5), (2, 1, 1)), np.array((0.9, 0.1))


compiled_predict = kernel(imm_predict, lambda: (
    *_example_belief(), 0.05, np.array(((0.5, 0.5), (1.0, 1.0))), 0.1, 0.5))
compiled_update = kernel(imm_update, lambda: (
    *_example_belief(), np.zeros(2), 0.01 * np.eye(2), False, False, 3.0, 3.0))
