"""LQR companion controller (paper Sec. 3.2, Eq. 10-16) with our corrections (docs/model.md).

Per sample period:

1. measure ``chi`` from the robot and person poses;
2. feedforward ``u_d`` and heading target ``beta_d``: the paper's ``u_d = u_h``, ``beta_d = 0``
   or the slot reference that holds the formation (:func:`companion.model.slot_reference`);
3. linearise Eq. (7) at the desired state (paper) or the measured one (ours), discretise and
   augment with the last input (:func:`augmented_model`);
4. weigh the feedforward by its confidence (:func:`feedforward_weights`), solve the Riccati
   equation for ``K`` (:func:`companion.riccati.solve_gain`, compiled or scipy) and apply
   ``u = u_d + u_e(k-1) - K xi`` (Eq. 16) with the state error clipped to ``lqr.error_clip``,
   saturated to the input limits.

``u_e(k-1)`` is the command actually sent minus ``u_d`` (told through :meth:`applied`), so
saturation and the outer layers cannot wind it up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion._jit import jitable, kernel
from companion.control.base import in_force, saturate
from companion.errors import ConfigError
from companion.geometry import wrap_pi
from companion.model import discretize, euler, jacobians, relative_state, slot_reference
from companion.params import Params
from companion.riccati import augment, augmented, solve_gain
from companion.types import Command, Observation

#: Person speed (m/s) of the operating point of the fallback gain.
REST_SPEED = 0.5
#: The feedforward's weights shrink at most by this factor (:func:`feedforward_weights`).
LEAST_TRUST = 10.0


@jitable
def euler_model(rho: float, alpha: float, beta: float, v: float, omega: float, v_h: float,
                d: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(A_bar, B_bar)``: the companion model linearised at ``chi = (rho, alpha, beta)``,
    ``u = (v, omega)`` and person speed ``v_h``, discretised by forward Euler and augmented."""
    jx, ju = jacobians((rho, alpha, beta), (v, omega), (v_h, 0.0), d)
    a, b = euler(jx, ju, dt)
    return augmented(a, b)


_euler_model = kernel(euler_model, lambda: (1.0, 1.5, 0.0, 1.0, 0.0, 1.0, 0.25, 0.05))


def augmented_model(chi, u, w, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """``(A_bar, B_bar)``, shapes (5, 5) and (5, 2), of the LQR at the operating point
    ``(chi, u, w)`` with rho floored at ``lqr.rho_min``, discretised as ``lqr.discretization``
    says (forward Euler compiled from :func:`euler_model`)."""
    lqr, d, dt = params.lqr, params.robot.d, params.dt
    rho = max(float(chi[0]), lqr.rho_min)
    if lqr.discretization == "euler":
        return _euler_model(rho, float(chi[1]), float(chi[2]), float(u[0]), float(u[1]),
                            float(w[0]), float(d), float(dt))
    jx, ju = jacobians((rho, chi[1], chi[2]), u, w, d)
    return augment(*discretize(jx, ju, dt, lqr.discretization))


def feedforward_weights(q: np.ndarray, person_std: tuple[float, float] | None,
                        trusted: tuple[float, float], rho_d: float) -> np.ndarray:
    """The LQR's state weights ``q`` with those on ``v_e`` and ``omega_e`` divided by
    ``1 + (std / trusted)^2``, where ``std`` is that of the feedforward's speed (the person's
    speed and ``rho_d`` times their turn rate: the slot's velocity) and turn rate.

    ``u_e`` is the input's deviation from the feedforward; weighing it says how far to trust
    the feedforward. Built from a noisy estimate, a fully trusted feedforward holds the robot
    off its slot on average (docs/model.md, section 4.6). The weights shrink at most
    :data:`LEAST_TRUST`-fold: a fresh track, metres off with a wide spread, would otherwise
    leave the LQR on feedback alone to it. ``person_std`` None (an exact person) or
    ``trusted`` inf leaves ``q`` as it is.
    """
    if person_std is None:
        return q
    speed, turn = person_std
    out = q.copy()
    out[3] /= min(1.0 + (speed * speed + (rho_d * turn) ** 2) / (trusted[0] * trusted[0]),
                  LEAST_TRUST)
    out[4] /= min(1.0 + (turn / trusted[1]) ** 2, LEAST_TRUST)
    return out


def rest_operating_point(params: Params) -> tuple[tuple, tuple, tuple]:
    """``(chi, u, w)`` of the fallback gain: the slot for a person walking straight at
    :data:`REST_SPEED`."""
    f = params.formation
    ref = slot_reference(REST_SPEED, 0.0, f.distance, f.bearing, params.robot.d)
    return (f.distance, f.bearing, ref.beta), (ref.v, ref.omega), (REST_SPEED, 0.0)


@dataclass(frozen=True)
class LqrStep:
    """Diagnostics of one controller step (for logs, tests and plots)."""

    xi: np.ndarray      # augmented state [rho_e, alpha_e, beta_e, v_e(k-1), omega_e(k-1)]
    gain: np.ndarray    # K, shape (2, 5)
    u_d: tuple[float, float]
    beta_d: float


class LqrController:
    """Augmented-state LQR companion controller; see the module docstring."""

    def __init__(self, params: Params):
        self.params = params
        self._q = np.array(params.lqr.q, dtype=float)
        self._r = np.array(params.lqr.r, dtype=float)
        # For operating points without a stabilising gain (robot and person at rest: the
        # heading mode is then uncontrollable in the linearisation) before any gain is known.
        # Solving once here also checks the weights: none that fail reach a step.
        try:
            self._rest_gains = {params.formation: self.gain(*rest_operating_point(params))}
        except np.linalg.LinAlgError:
            raise ConfigError(f"lqr.q: no stabilising LQR gain for the slot with "
                              f"q = {params.lqr.q}, r = {params.lqr.r} (every weight of q "
                              f"> 0 gives one)") from None
        self.reset()

    def reset(self) -> None:
        self._u_e = (0.0, 0.0)                 # u_e(k-1)
        self._gain: np.ndarray | None = None   # last stabilising gain
        self._last: tuple | None = None        # (xi, gain, (v_d, omega_d), beta_d)

    @property
    def u_e_prev(self) -> tuple[float, float]:
        """``u_e(k-1)``: the last applied input minus its feedforward."""
        return self._u_e

    @property
    def last(self) -> LqrStep | None:
        """Diagnostics of the last step (None before the first; copies)."""
        if self._last is None:
            return None
        xi, gain, u_d, beta_d = self._last
        return LqrStep(xi.copy(), gain.copy(), u_d, beta_d)

    def reference(self, v_h: float, omega_h: float, params: Params | None = None
                  ) -> tuple[float, float, float]:
        """``(beta_d, v_d, omega_d)`` of the configured feedforward for a person velocity
        (the formation of ``params``, default the configured one)."""
        p = params or self.params
        if p.lqr.feedforward == "person":
            return 0.0, v_h, omega_h
        ref = slot_reference(v_h, omega_h, p.formation.distance, p.formation.bearing, p.robot.d)
        return ref.beta, ref.v, ref.omega

    def rest_gain(self, params: Params) -> np.ndarray:
        """The fallback gain for the formation of ``params`` (:func:`rest_operating_point`),
        solved once per formation."""
        f = params.formation
        if f not in self._rest_gains:
            self._rest_gains[f] = self.gain(*rest_operating_point(params))
        return self._rest_gains[f]

    def gain(self, chi, u, w) -> np.ndarray:
        """LQR gain ``K`` (2, 5) of the model linearised at ``(chi, u, w)`` with the
        configured ``lqr.solver``; ``numpy.linalg.LinAlgError`` where none stabilises."""
        k = solve_gain(*augmented_model(chi, u, w, self.params), self._q, self._r,
                       self.params.lqr.solver)
        if k is None:
            raise np.linalg.LinAlgError("LqrController.gain: no stabilising solution of the "
                                        "Riccati equation at this operating point")
        return k

    def step(self, obs: Observation) -> Command:
        p, r, h = in_force(self.params, obs), obs.robot, obs.person
        rho_d, alpha_d = p.formation.distance, p.formation.bearing
        rho, alpha, beta = relative_state(r.x, r.y, r.theta, h.x, h.y, h.theta, p.robot.d)
        beta_d, v_d, omega_d = self.reference(h.v, h.omega, p)
        e_v, e_w = self._u_e
        if p.lqr.linearize_at == "desired":
            chi, u = (rho_d, alpha_d, beta_d), (v_d, omega_d)
        else:
            chi, u = (rho, alpha, beta), (v_d + e_v, omega_d + e_w)
        q = feedforward_weights(self._q, obs.person_std, p.lqr.feedforward_std, rho_d)
        k = solve_gain(*augmented_model(chi, u, (h.v, h.omega), p), q, self._r, p.lqr.solver)
        if k is not None:
            self._gain = k
        elif self._gain is None:
            self._gain = self.rest_gain(p)
        c_rho, c_alpha, c_beta = p.lqr.error_clip
        xi = np.array((min(max(rho - rho_d, -c_rho), c_rho),
                       min(max(wrap_pi(alpha - alpha_d), -c_alpha), c_alpha),
                       min(max(wrap_pi(beta - beta_d), -c_beta), c_beta), e_v, e_w))
        du_v, du_w = (self._gain @ xi).tolist()
        v, om = saturate(v_d + e_v - du_v, omega_d + e_w - du_w, p.robot)
        self._u_e = (v - v_d, om - omega_d)
        self._last = (xi, self._gain, (v_d, omega_d), beta_d)
        return Command(v, om)

    def applied(self, cmd: Command) -> None:
        """Store ``u_e(k-1)`` from the command actually sent, without the avoidance part
        ``u_ob`` (Eq. 20 adds it outside the LQR)."""
        if self._last is not None:
            v_d, omega_d = self._last[2]
            self._u_e = (cmd.v - v_d, cmd.omega - cmd.u_ob - omega_d)
