"""The walker's motion model and filter: an interacting multiple model (IMM) of two
coordinated-turn unscented Kalman filters (filterpy), a steady walk and a manoeuvre.

The state is ``(x, y, vx, vy, omega)``: the velocity turns at the rate ``omega`` at constant
speed. Cartesian velocity has no singularity at a standstill, so a person who stands may start
to walk in any direction. Both models share this motion; they differ in process noise (white
acceleration in x and y, and of the turn rate): the steady model is smooth, the manoeuvre
model follows starts, stops and sharp turns. Their probabilities follow the detections, and
the mixed covariance widens while the two disagree. docs/sensing.md explains the choices.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from scipy.stats import multivariate_normal

from companion.geometry import unicycle_step, wrap_pi, wrap_pi_array
from companion.params import TrackerParams
from companion.types import PersonDetection, PersonState

#: Smallest standard deviation of a measurement in the filter (m, rad, m/s, rad/s): an exact
#: measurement of part of the state would make the covariance singular and the filter
#: fragile. Only a detection of the whole state may be exact (:func:`is_exact`).
MIN_STD = 1e-3


def coordinated_turn(x: np.ndarray, dt: float) -> np.ndarray:
    """The state ``(x, y, vx, vy, omega)`` ``dt`` s on: the velocity turns at the rate
    ``omega`` at constant speed (the unicycle arc)."""
    speed, heading = math.hypot(x[2], x[3]), math.atan2(x[3], x[2])
    px, py, th = unicycle_step(x[0], x[1], heading, speed, x[4], dt)
    return np.array((px, py, speed * math.cos(th), speed * math.sin(th), x[4]))


def predict(person: PersonState, tau: float) -> PersonState:
    """The person ``tau`` s on at constant speed and turn rate (:func:`coordinated_turn`)."""
    x, y, th = unicycle_step(person.x, person.y, person.theta, person.v, person.omega, tau)
    return PersonState(x, y, wrap_pi(th), person.v, person.omega)


def process_noise(dt: float, accel_std: float, turn_accel_std: float) -> np.ndarray:
    """Q over ``dt``: white acceleration in x and y (m/s^2) and of the turn rate (rad/s^2),
    discrete white-noise form."""
    q = np.zeros((5, 5))
    a2 = accel_std ** 2
    for i in (0, 1):
        q[i, i] = a2 * dt ** 4 / 4.0
        q[i, i + 2] = q[i + 2, i] = a2 * dt ** 3 / 2.0
        q[i + 2, i + 2] = a2 * dt * dt
    q[4, 4] = (turn_accel_std * dt) ** 2
    return q


def psd_sqrt(a: np.ndarray) -> np.ndarray:
    """``U`` with ``U' U = a`` for a symmetric positive semi-definite ``a``, negative rounding
    in its eigenvalues clipped (the sigma points' square root; a Cholesky factor would fail
    on a covariance that rounding made slightly indefinite)."""
    w, v = np.linalg.eigh(0.5 * (a + a.T))
    return np.sqrt(np.maximum(w, 0.0))[:, None] * v.T


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


def is_exact(d: PersonDetection) -> bool:
    """The detection gives the whole state with zero uncertainty (an ideal sensor)."""
    return (d.heading is not None and d.speed is not None and d.turn_rate is not None
            and d.covariance is not None and not any(d.covariance) and d.heading_std == 0.0
            and d.velocity_std is not None and not any(d.velocity_std))


def exact_detection(t: float, person: PersonState, frame: str = "world") -> PersonDetection:
    """A detection that gives ``person``'s whole state exactly (an ideal sensor)."""
    return PersonDetection(t, person.x, person.y, frame, (0.0, 0.0, 0.0, 0.0), person.theta,
                           0.0, person.v, person.omega, (0.0, 0.0))


@dataclass(frozen=True)
class Belief:
    """What the filter knows at one time: per model (steady, manoeuvre) the state and its
    covariance, and the models' probabilities. ``x`` and ``p`` are their mixture."""

    xs: np.ndarray   # (2, 5)
    ps: np.ndarray   # (2, 5, 5)
    mu: np.ndarray   # (2,)

    @property
    def x(self) -> np.ndarray:
        if np.array_equal(self.xs[0], self.xs[1]):    # exact where the models agree
            return self.xs[0].copy()
        return self.mu @ self.xs

    @property
    def p(self) -> np.ndarray:
        d = self.xs - self.x
        return np.einsum("m,mij->ij", self.mu, self.ps) + (d.T * self.mu) @ d

    @property
    def exact(self) -> bool:
        return not self.ps.any()


class WalkerFilter:
    """The IMM over :class:`Belief` values (module docstring): :meth:`start`,
    :meth:`predict` and :meth:`update` return new beliefs and keep none, so a tracker can
    keep a history of them and re-filter late detections."""

    def __init__(self, params: TrackerParams):
        self.params = params
        points = MerweScaledSigmaPoints(5, 0.3, 2.0, 0.0, sqrt_method=psd_sqrt)
        self._ukf = _Ukf(5, 2, 0.05, hx=None, fx=coordinated_turn, points=points)
        self._noise = ((params.accel_std, params.turn_accel_std),
                       (params.maneuver_accel_std, params.maneuver_turn_accel_std))

    def start(self, d: PersonDetection) -> Belief:
        """A belief from one detection: what it measures, and wide priors for the rest (a
        person standing still, who may start to walk in any direction)."""
        p = self.params
        if is_exact(d):
            return _both(exact_state(d), np.zeros((5, 5)), p.initial_maneuver)
        cov = np.zeros((5, 5))
        cov[:2, :2] = position_cov(d, p)
        x = np.array((d.x, d.y, 0.0, 0.0, d.turn_rate or 0.0))
        if d.heading is not None and d.speed is not None:   # a velocity measured
            c, s = math.cos(d.heading), math.sin(d.heading)
            x[2:4] = d.speed * c, d.speed * s
            v_std = (d.velocity_std or (p.initial_speed_std,))[0]
            jac = np.array(((c, -d.speed * s), (s, d.speed * c)))
            cov[2:4, 2:4] = jac @ np.diag((v_std ** 2, heading_std(d, p) ** 2)) @ jac.T
        else:
            cov[2:4, 2:4] = p.initial_speed_std ** 2 * np.eye(2)
        w_std = p.initial_turn_rate_std if d.velocity_std is None else d.velocity_std[1]
        cov[4, 4] = w_std ** 2
        return _both(x, cov + MIN_STD ** 2 * np.eye(5), p.initial_maneuver)

    def predict(self, b: Belief, dt: float) -> Belief:
        """``b`` predicted ``dt`` s on: the models mixed by their chance of switching in
        ``dt``, then each predicted with its own process noise."""
        if dt <= 0.0:
            return b
        p = self.params
        start = 1.0 - math.exp(-p.maneuver_start_rate * dt)
        end = 1.0 - math.exp(-p.maneuver_end_rate * dt)
        switch = np.array(((1.0 - start, start), (end, 1.0 - end)))
        prior = switch.T @ b.mu                       # model probabilities after dt
        weights = switch * b.mu[:, None] / prior      # [i, j]: was i, given now j
        xs, ps = np.empty_like(b.xs), np.empty_like(b.ps)
        for j, noise in enumerate(self._noise):
            x0 = weights[:, j] @ b.xs
            d = b.xs - x0
            p0 = np.einsum("m,mij->ij", weights[:, j], b.ps) + (d.T * weights[:, j]) @ d
            q = process_noise(dt, *noise)
            if not p0.any():                          # exact: its prediction is exact too
                xs[j], ps[j] = coordinated_turn(x0, dt), q
                continue
            ukf = self._ukf
            ukf.x, ukf.P, ukf.Q = x0, p0, q
            ukf.predict(dt=dt, UT=_unscented_transform)
            # the mean is the model's motion of the mean: the sigma points' mean would shrink
            # the speed by E[cos(omega dt)] each step, a bias of a few percent at a steady walk
            xs[j], ps[j] = coordinated_turn(x0, dt), 0.5 * (ukf.P + ukf.P.T)
        return Belief(xs, ps, prior)

    def update(self, b: Belief, d: PersonDetection) -> Belief:
        """``b`` (at ``d``'s time) updated with ``d``; the models' probabilities by how well
        each predicted it."""
        p = self.params
        if is_exact(d):
            return _both(exact_state(d), np.zeros((5, 5)), b.mu[1])
        hx, z, r, angles = measurement(d, p)

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
                ukf.update(z, R=r, UT=_unscented_transform, hx=hx)
            except (ValueError, np.linalg.LinAlgError):   # a singular innovation: no update
                xs[j], ps[j], log_l[j] = b.xs[j], b.ps[j], -math.inf
                continue
            x = ukf.x.copy()
            speed = math.hypot(x[2], x[3])
            if speed > p.max_person_speed:
                x[2:4] *= p.max_person_speed / speed * (1.0 - 1e-12)   # rounding stays below
            x[4] = min(max(x[4], -p.max_person_turn_rate), p.max_person_turn_rate)
            xs[j], ps[j] = x, 0.5 * (ukf.P + ukf.P.T)
            log_l[j] = _log_likelihood(ukf.y, ukf.S)
        top = log_l.max()
        mu = b.mu * (np.exp(log_l - top) if math.isfinite(top) else 1.0)
        mu = np.clip(mu / mu.sum(), 1e-6, 1.0)
        return Belief(xs, ps, mu / mu.sum())


def position_nis(x: np.ndarray, cov: np.ndarray, d: PersonDetection, p: TrackerParams,
                 floor: float = MIN_STD) -> float:
    """Squared Mahalanobis distance of ``d``'s position from the state ``x`` with covariance
    ``cov`` (both covariances and ``floor`` m of tolerance together; 2 degrees of freedom, so
    about 2 on average when the filter is honest); inf where it cannot be computed."""
    innov = np.array((d.x - x[0], d.y - x[1]))
    s = cov[:2, :2] + position_cov(d, p) + floor ** 2 * np.eye(2)
    try:
        nis = float(innov @ np.linalg.solve(s, innov))
    except np.linalg.LinAlgError:
        return math.inf
    return nis if math.isfinite(nis) else math.inf


def widened(cov: np.ndarray, k: float) -> np.ndarray:
    """``cov`` with its position part widened ``k`` times (``D cov D``, ``D = diag(sqrt k,
    sqrt k, 1, 1, 1)``: the position variances times ``k``, their covariances with the rest
    times ``sqrt k``; still a covariance)."""
    if k == 1.0:
        return cov
    d = np.ones(len(cov))
    d[:2] = math.sqrt(k)
    return cov * np.outer(d, d)


def _log_likelihood(y: np.ndarray, s: np.ndarray) -> float:
    """log N(y; 0, S) of the innovation, with S symmetrised (the unscented transform leaves it
    asymmetric by rounding) and -inf where it is not a covariance (never raises)."""
    s = 0.5 * (s + s.T)
    try:
        value = multivariate_normal.logpdf(y, cov=s, allow_singular=True)
    except (ValueError, np.linalg.LinAlgError):
        return -math.inf
    return float(value) if math.isfinite(value) else -math.inf


def _both(x: np.ndarray, p: np.ndarray, maneuver: float) -> Belief:
    return Belief(np.array((x, x)), np.array((p, p)), np.array((1.0 - maneuver, maneuver)))


def exact_state(d: PersonDetection) -> np.ndarray:
    """The filter state of an exact detection."""
    return np.array((d.x, d.y, d.speed * math.cos(d.heading), d.speed * math.sin(d.heading),
                     d.turn_rate))


def position_cov(d: PersonDetection, p: TrackerParams) -> np.ndarray:
    """The 2x2 covariance of the detection's position (the tracker's default without one)."""
    if d.covariance is None:
        return p.position_std_m ** 2 * np.eye(2)
    return np.reshape(np.asarray(d.covariance, dtype=float), (2, 2))


def heading_std(d: PersonDetection, p: TrackerParams) -> float:
    return p.heading_std_rad if d.heading_std is None else d.heading_std


def measurement(d: PersonDetection, p: TrackerParams):
    """What ``d`` measures of the state: ``(hx, z, R, angles)``, the measurement function,
    the measurement, its noise covariance and which of its components are angles."""
    parts: list[Callable[[np.ndarray], list[float]]] = [lambda s: [s[0], s[1]]]
    z, stds, angles = [d.x, d.y], [], []
    if d.heading is not None:
        parts.append(lambda s: [math.atan2(s[3], s[2])])
        angles.append(len(z))
        z.append(d.heading)
        stds.append(heading_std(d, p))
    if d.speed is not None and d.turn_rate is not None:
        parts.append(lambda s: [math.hypot(s[2], s[3]), s[4]])
        z += [d.speed, d.turn_rate]
        stds += list(d.velocity_std or (p.initial_speed_std, p.initial_turn_rate_std))
    r = np.zeros((len(z), len(z)))
    r[:2, :2] = position_cov(d, p)
    for k, s in enumerate(stds, start=2):
        r[k, k] = s * s
    r += MIN_STD ** 2 * np.eye(len(z))   # floor

    def hx(s: np.ndarray) -> np.ndarray:
        return np.array([v for part in parts for v in part(s)])

    return hx, np.array(z), r, angles
