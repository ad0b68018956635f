"""The reference walker filter: the IMM of :mod:`.walker` on filterpy's
``UnscentedKalmanFilter``, in Python. It is what the compiled filter (:mod:`.imm`) is checked
against, as the Riccati solver is checked against scipy; the tracker does not use it."""

from __future__ import annotations

import math

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from scipy.stats import multivariate_normal

from companion.geometry import wrap_pi_array
from companion.params import TrackerParams
from companion.tracking.imm import (
    ALPHA,
    BETA,
    KAPPA,
    coordinated_turn,
    measured,
    process_noise,
    psd_sqrt,
)
from companion.tracking.walker import (
    Belief,
    WalkerFilter,
    _both,
    exact_state,
    is_exact,
    measurement,
)
from companion.types import PersonDetection


def _unscented_transform(sigmas, wm, wc, noise_cov=None, mean_fn=None, residual_fn=None):
    """filterpy's unscented transform, with the residuals of all sigma points at once."""
    x = wm @ sigmas if mean_fn is None else mean_fn(sigmas, wm)
    y = sigmas - x if residual_fn is None else residual_fn(sigmas, x)
    p = (y.T * wc) @ y
    return x, p if noise_cov is None else p + noise_cov


class _Ukf(UnscentedKalmanFilter):
    """filterpy's UKF with the cross variance computed for all sigma points at once."""

    def cross_variance(self, x, z, sigmas_f, sigmas_h):
        return ((sigmas_f - x).T * self.Wc) @ self.residual_z(sigmas_h, z)


def _log_likelihood(y: np.ndarray, s: np.ndarray) -> float:
    """log N(y; 0, S) of the innovation, S symmetrised; -inf where it is not a covariance."""
    s = 0.5 * (s + s.T)
    try:
        value = multivariate_normal.logpdf(y, cov=s, allow_singular=True)
    except (ValueError, np.linalg.LinAlgError):
        return -math.inf
    return float(value) if math.isfinite(value) else -math.inf


class ReferenceFilter(WalkerFilter):
    """:class:`.walker.WalkerFilter` with filterpy doing each model's predict and update."""

    def __init__(self, params: TrackerParams):
        super().__init__(params)
        points = MerweScaledSigmaPoints(5, ALPHA, BETA, KAPPA, sqrt_method=psd_sqrt)
        self._ukf = _Ukf(5, 2, 0.05, hx=None, fx=coordinated_turn, points=points)

    def predict(self, b: Belief, dt: float) -> Belief:
        if dt <= 0.0:
            return b
        p = self.params
        start = 1.0 - math.exp(-p.maneuver_start_rate * dt)
        end = 1.0 - math.exp(-p.maneuver_end_rate * dt)
        switch = np.array(((1.0 - start, start), (end, 1.0 - end)))
        prior = switch.T @ b.mu
        weights = switch * b.mu[:, None] / prior      # [i, j]: was i, given now j
        xs, ps = np.empty_like(b.xs), np.empty_like(b.ps)
        for j, noise in enumerate(self._noise):
            x0 = weights[:, j] @ b.xs
            d = b.xs - x0
            p0 = np.einsum("m,mij->ij", weights[:, j], b.ps) + (d.T * weights[:, j]) @ d
            q = process_noise(dt, *noise)
            if not p0.any():
                xs[j], ps[j] = coordinated_turn(x0, dt), q
                continue
            ukf = self._ukf
            ukf.x, ukf.P, ukf.Q = x0, p0, q
            ukf.predict(dt=dt, UT=_unscented_transform)
            xs[j], ps[j] = coordinated_turn(x0, dt), 0.5 * (ukf.P + ukf.P.T)
        return Belief(xs, ps, prior)

    def update(self, b: Belief, d: PersonDetection) -> Belief:
        p = self.params
        if is_exact(d):
            return _both(exact_state(d), np.zeros((5, 5)), b.mu[1])
        z, r, heading, velocity = measurement(d, p)
        angles = [2] if heading else []

        def residual(a, c):
            out = a - c
            for k in angles:
                out[..., k] = wrap_pi_array(out[..., k])
            return out

        ukf = self._ukf
        ukf.residual_z = residual
        xs, ps, log_l = np.empty_like(b.xs), np.empty_like(b.ps), np.empty(2)
        for j in range(2):
            ukf.x, ukf.P = b.xs[j].copy(), b.ps[j] + 1e-12 * np.eye(5)
            ukf.sigmas_f = ukf.points_fn.sigma_points(ukf.x, ukf.P)
            try:
                ukf.update(z, R=r, UT=_unscented_transform,
                           hx=lambda s: measured(s, heading, velocity))
            except (ValueError, np.linalg.LinAlgError):
                xs[j], ps[j], log_l[j] = b.xs[j], b.ps[j], -math.inf
                continue
            x = ukf.x.copy()
            speed = math.hypot(x[2], x[3])
            if speed > p.max_person_speed:
                x[2:4] *= p.max_person_speed / speed * (1.0 - 1e-12)
            x[4] = min(max(x[4], -p.max_person_turn_rate), p.max_person_turn_rate)
            xs[j], ps[j] = x, 0.5 * (ukf.P + ukf.P.T)
            log_l[j] = _log_likelihood(ukf.y, ukf.S)
        top = log_l.max()
        mu = b.mu * (np.exp(log_l - top) if math.isfinite(top) else 1.0)
        mu = np.clip(mu / mu.sum(), 1e-6, 1.0)
        return Belief(xs, ps, mu / mu.sum())
