"""LQR companion controller (paper Sec. 3.2, Eq. 10-16) with our two corrections.

Per sample period:

1. measure ``chi`` from the robot and person poses;
2. feedforward ``u_d`` and heading target ``beta_d``: either the paper's ``u_d = u_h``,
   ``beta_d = 0`` or the geometry-consistent slot reference (:func:`companion.model.slot_reference`);
3. linearise Eq. (7) at the desired state (paper) or the measured one (ours), discretise, augment;
4. clip the state error to ``lqr.error_clip`` (ours; the quadratic model is local, so far from
   the slot the controller acts on a bounded error, like tracking a virtual slot that leads the
   robot towards the real one);
5. solve the Riccati equation for ``K`` and apply ``u = u_d + u_e(k-1) - K xi`` (Eq. 16), clipped
   to the input limits; the stored ``u_e(k-1)`` is what was actually applied minus ``u_d``, so
   saturation cannot wind it up (the layers around the controller report the final command
   through :meth:`LqrController.applied`).

docs/model.md explains the choices and their measured effect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.control.base import Command, Observation, saturate
from companion.kinematics import wrap_pi
from companion.lqr import augment, dlqr
from companion.model import discretize, jacobians, relative_state, slot_reference
from companion.params import Params


REST_SPEED = 0.5  # m/s, person speed assumed by the fallback gain


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
        self._q = np.diag(params.lqr.q)
        self._r = np.diag(params.lqr.r)
        self._clip = np.array(params.lqr.error_clip)
        f = params.formation
        # Fallback gain for operating points without a stabilising Riccati solution (robot and
        # person at rest: the heading mode is then uncontrollable in the linearisation). It is
        # the gain at the desired slot for a person walking straight at REST_SPEED.
        ref = slot_reference(REST_SPEED, 0.0, f.distance, f.bearing, params.robot.d)
        self._rest_gain = self.gain(np.array([f.distance, f.bearing, ref.beta]),
                                    np.array([ref.v, ref.omega]), np.array([REST_SPEED, 0.0]),
                                    check=True)
        self.reset()

    def reset(self) -> None:
        self._u_e_prev = np.zeros(2)
        self._gain: np.ndarray | None = None
        self.last: LqrStep | None = None

    def reference(self, v_h: float, omega_h: float) -> tuple[float, float, float]:
        """``(beta_d, v_d, omega_d)`` of the configured feedforward for a person velocity."""
        p = self.params
        if p.lqr.feedforward == "person":
            return 0.0, v_h, omega_h
        ref = slot_reference(v_h, omega_h, p.formation.distance, p.formation.bearing, p.robot.d)
        return ref.beta, ref.v, ref.omega

    def gain(self, chi: np.ndarray, u: np.ndarray, w: np.ndarray, check: bool = False
             ) -> np.ndarray:
        """LQR gain ``K`` of the augmented model linearised at ``(chi, u, w)``.

        Raises ``numpy.linalg.LinAlgError`` where no stabilising gain exists.
        """
        p = self.params
        lin = np.array([max(chi[0], p.lqr.rho_min), chi[1], chi[2]])
        jx, ju = jacobians(lin, u, w, p.robot.d)
        a, b = discretize(jx, ju, p.dt, p.lqr.discretization)
        a_bar, b_bar = augment(a, b)
        k, _ = dlqr(a_bar, b_bar, self._q, self._r, check=check)
        return k

    def step(self, obs: Observation) -> Command:
        p = self.params
        r, h = obs.robot, obs.person
        rho, alpha, beta = relative_state(r.x, r.y, r.theta, h.x, h.y, h.theta, p.robot.d)
        beta_d, v_d, omega_d = self.reference(h.v, h.omega)
        u_d = np.array([v_d, omega_d])
        rho_d, alpha_d = p.formation.distance, p.formation.bearing
        chi_e = np.array([rho - rho_d, wrap_pi(alpha - alpha_d), wrap_pi(beta - beta_d)])
        w = np.array([h.v, h.omega])
        if p.lqr.linearize_at == "desired":
            chi_lin, u_lin = np.array([rho_d, alpha_d, beta_d]), u_d
        else:
            chi_lin, u_lin = np.array([rho, alpha, beta]), u_d + self._u_e_prev
        try:
            self._gain = self.gain(chi_lin, u_lin, w)
        except (np.linalg.LinAlgError, ValueError):
            # No stabilising Riccati solution here: keep the last good gain, or use the
            # fallback computed at construction.
            if self._gain is None:
                self._gain = self._rest_gain
        xi = np.concatenate([np.clip(chi_e, -self._clip, self._clip), self._u_e_prev])
        du = -self._gain @ xi
        u = u_d + self._u_e_prev + du
        v, om = saturate(float(u[0]), float(u[1]), p.robot)
        self._u_e_prev = np.array([v, om]) - u_d
        self.last = LqrStep(xi=xi, gain=self._gain, u_d=(v_d, omega_d), beta_d=beta_d)
        return Command(v, om)

    def applied(self, cmd: Command) -> None:
        """Store ``u_e(k-1)`` from the command actually sent (after the safety and avoidance
        layers), without the avoidance part ``u_ob`` (Eq. 20 adds it outside the LQR)."""
        if self.last is not None:
            self._u_e_prev = np.array([cmd.v - self.last.u_d[0],
                                       cmd.omega - cmd.u_ob - self.last.u_d[1]])
