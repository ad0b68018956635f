"""The walker's motion model and filter: an interacting multiple model (IMM) of two
coordinated-turn unscented Kalman filters, a steady walk and a manoeuvre.

The state is ``(x, y, vx, vy, omega)``: the velocity turns at the rate ``omega`` at constant
speed. Cartesian velocity has no singularity at a standstill, so a person who stands may start
to walk in any direction. Both models share this motion; they differ in process noise (white
acceleration in x and y, and of the turn rate): the steady model is smooth, the manoeuvre
model follows starts, stops and sharp turns. Their probabilities follow the detections, and
the mixed covariance widens while the two disagree. The arithmetic is compiled
(:mod:`.imm`); docs/sensing.md explains the choices.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.geometry import unicycle_step, wrap_pi
from companion.params import SensingParams, TrackerParams
from companion.tracking.imm import compiled_predict, compiled_update, mixture
from companion.types import PersonDetection, PersonState

#: Smallest standard deviation of a measurement in the filter (m, rad, m/s, rad/s): an exact
#: measurement of part of the state would make the covariance singular and the filter
#: fragile. Only a detection of the whole state may be exact (:func:`is_exact`).
MIN_STD = 1e-3


def predict(person: PersonState, tau: float) -> PersonState:
    """The person ``tau`` s on at constant speed and turn rate (:func:`.imm.coordinated_turn`)."""
    x, y, th = unicycle_step(person.x, person.y, person.theta, person.v, person.omega, tau)
    return PersonState(x, y, wrap_pi(th), person.v, person.omega)


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
    covariance, and the models' probabilities. ``x`` and ``p`` are their mixture (computed
    here unless the kernel that made the belief gives them)."""

    xs: np.ndarray   # (2, 5)
    ps: np.ndarray   # (2, 5, 5)
    mu: np.ndarray   # (2,)
    x: np.ndarray = None   # (5,)
    p: np.ndarray = None   # (5, 5)

    def __post_init__(self) -> None:
        if self.x is None or self.p is None:
            x, p = mixture(self.xs, self.ps, self.mu)
            object.__setattr__(self, "x", x)
            object.__setattr__(self, "p", p)

    @property
    def exact(self) -> bool:
        return not self.ps.any()


class WalkerFilter:
    """The IMM over :class:`Belief` values (module docstring): :meth:`start`,
    :meth:`predict` and :meth:`update` return new beliefs and keep none, so a tracker can
    keep a history of them and re-filter late detections. The arithmetic is compiled
    (:mod:`.imm`); :class:`companion.tracking.reference.ReferenceFilter` is the same filter
    on filterpy's UKF, which the tests compare it with."""

    def __init__(self, params: TrackerParams, sensing: SensingParams | None = None):
        self.params = params.for_sensing(sensing or SensingParams())   # declared noise
        params = self.params
        self._noise = np.array(((params.accel_std, params.turn_accel_std),
                                (params.maneuver_accel_std, params.maneuver_turn_accel_std)))

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
        return Belief(*compiled_predict(b.xs, b.ps, b.mu, dt, self._noise,
                                        p.maneuver_start_rate, p.maneuver_end_rate))

    def update(self, b: Belief, d: PersonDetection, scale: float = 1.0) -> Belief:
        """``b`` (at ``d``'s time) updated with ``d`` (its position variance times ``scale``);
        the models' probabilities by how well each predicted it."""
        p = self.params
        if is_exact(d):
            return _both(exact_state(d), np.zeros((5, 5)), b.mu[1])
        z, r, heading, velocity = measurement(d, p, scale)
        return Belief(*compiled_update(b.xs, b.ps, b.mu, z, r, heading, velocity,
                                       p.max_person_speed, p.max_person_turn_rate))


def position_nis(x: np.ndarray, cov: np.ndarray, d: PersonDetection, p: TrackerParams,
                 floor: float = MIN_STD, scale: float = 1.0) -> float:
    """Squared Mahalanobis distance of ``d``'s position (its variance times ``scale``) from
    the state ``x`` with covariance ``cov`` (both covariances and ``floor`` m of tolerance
    together; 2 degrees of freedom, so about 2 on average when the filter is honest); inf
    where it cannot be computed."""
    dx, dy = d.x - x[0], d.y - x[1]
    if d.covariance is None:
        ra, rb, rc = p.position_std_m ** 2, 0.0, p.position_std_m ** 2
    else:
        ra, rb, rc = d.covariance[0], 0.5 * (d.covariance[1] + d.covariance[2]), d.covariance[3]
    ra, rb, rc = scale * ra, scale * rb, scale * rc
    a = cov[0, 0] + ra + floor ** 2
    c = cov[1, 1] + rc + floor ** 2
    b = 0.5 * (cov[0, 1] + cov[1, 0]) + rb
    det = a * c - b * b
    if not det > 0.0:
        return math.inf
    nis = (c * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det
    return float(nis) if math.isfinite(nis) else math.inf


def widened(cov: np.ndarray, k: float) -> np.ndarray:
    """``cov`` with its position part widened ``k`` times (``D cov D``, ``D = diag(sqrt k,
    sqrt k, 1, 1, 1)``: the position variances times ``k``, their covariances with the rest
    times ``sqrt k``; still a covariance)."""
    if k == 1.0:
        return cov
    d = np.ones(len(cov))
    d[:2] = math.sqrt(k)
    return cov * np.outer(d, d)


def _both(x: np.ndarray, p: np.ndarray, maneuver: float) -> Belief:
    """Both models at ``(x, p)`` (so is their mixture)."""
    return Belief(np.array((x, x)), np.array((p, p)), np.array((1.0 - maneuver, maneuver)),
                  x, p)


def exact_state(d: PersonDetection) -> np.ndarray:
    """The filter state of an exact detection."""
    return np.array((d.x, d.y, d.speed * math.cos(d.heading), d.speed * math.sin(d.heading),
                     d.turn_rate))


def position_cov(d: PersonDetection, p: TrackerParams) -> np.ndarray:
    """The 2x2 covariance of the detection's position (the tracker's default without one)."""
    if d.covariance is None:
        return p.position_std_m ** 2 * np.eye(2)
    return np.array(d.covariance, dtype=float).reshape(2, 2)


def heading_std(d: PersonDetection, p: TrackerParams) -> float:
    return p.heading_std_rad if d.heading_std is None else d.heading_std


def measurement(d: PersonDetection, p: TrackerParams, scale: float = 1.0
                ) -> tuple[np.ndarray, np.ndarray, bool, bool]:
    """What ``d`` measures of the state: ``(z, R, heading, velocity)``, the measurement
    (:func:`.imm.measured`: position, the heading if ``heading``, the speed and turn rate if
    ``velocity``) and its noise covariance (the position's times ``scale``)."""
    z, stds = [d.x, d.y], []
    heading = d.heading is not None
    velocity = d.speed is not None and d.turn_rate is not None
    if heading:
        z.append(d.heading)
        stds.append(heading_std(d, p))
    if velocity:
        z += [d.speed, d.turn_rate]
        stds += list(d.velocity_std or (p.initial_speed_std, p.initial_turn_rate_std))
    r = np.zeros((len(z), len(z)))
    r[:2, :2] = scale * position_cov(d, p)
    for k, s in enumerate(stds, start=2):
        r[k, k] = s * s
    r += MIN_STD ** 2 * np.eye(len(z))   # floor
    return np.array(z, dtype=float), r, heading, velocity


def formation_person(state: PersonState, cov: np.ndarray, walking: float | None,
                     p: TrackerParams) -> tuple[PersonState, float]:
    """The formation's person for the estimate ``state`` with covariance ``cov``, and the
    heading of the last walking estimate (``walking``: the one before, None at first). While
    standing (speed below ``standing_speed``, or its heading less certain than
    ``walking_heading_std_rad``: positions tell no heading then) the person faces the way
    they last walked, without speed or turning. A walking person's turn rate is shrunk
    towards 0 by its uncertainty (a Wiener gain), so a poor estimate of it fades out of the
    controllers' feedforward."""
    across = np.array((-math.sin(state.theta), math.cos(state.theta)))
    heading_var = float(across @ cov[2:4, 2:4] @ across)   # velocity across its direction
    if walking is None or state.v >= p.standing_speed \
            and heading_var <= (p.walking_heading_std_rad * state.v) ** 2:
        w, var = state.omega, float(cov[4, 4])
        return (PersonState(state.x, state.y, state.theta, state.v,
                            w * w * w / (w * w + var) if var else w), state.theta)
    return PersonState(state.x, state.y, walking, 0.0, 0.0), walking
