"""PID baseline companion controller (in the spirit of Sun et al. [6] and Yao et al. [13]).

The controlled point is the robot's reference point R (``robot.d`` ahead of the axle); its
setpoint is the slot ``S = h + rho_d e(theta_h + alpha_d)`` (:mod:`companion.control.slot`).
Errors, in the robot frame:

* ``e_x = e(theta).(S - R)`` (slot ahead of R: positive), ``e_y = e_perp(theta).(S - R)``
  (slot to the left: positive);
* ``e_theta = wrap(theta_h - beta_ref - theta)``, the heading error against the heading that
  holds the slot (:func:`companion.model.slot_reference`; ``beta_ref = 0`` on a straight walk).

Control law (two decoupled channels, standard for a differential-drive tracker)::

    v     = e(theta).S_dot + kp_x e_x + I_x + kd_x D_x
    omega = omega_h        + kp_y e_y + I_y + kd_y D_y + kp_theta e_theta

* feedforward: the slot velocity projected on the robot heading, and the person's turn rate;
  at the slot-holding equilibrium both are exactly the input that holds the slot;
* ``I = clamp(I + k_i e dt, +-i_limit)``, frozen while the channel is saturated (or, for v, cut by
  the keep-out barrier around the controller) in the direction the error would push it
  (conditional integration + clamping anti-windup);
* ``D`` is the derivative on measurement: the measured deviation of R from S has setpoint 0, so
  its backward difference ``(e_k - e_{k-1}) / dt`` passed through a first-order low-pass filter
  (time constant ``pid.derivative_tau``, discretised by backward Euler) has no setpoint kick; it
  is 0 on the first step after ``reset``.

The angular channel steers R laterally through the offset ``d`` (``R_dot.e_perp = d omega``) and
damps the heading: linearised on a straight walk at speed ``V`` the lateral loop has the
characteristic polynomial ``s^2 + (kp_y d + kp_theta) s + kp_y V``, stable for positive gains
when walking forward.
"""

from __future__ import annotations

import math

from companion.control.base import saturate
from companion.control.slot import reference_point, slot_point, slot_velocity, to_frame
from companion.geometry import wrap_pi
from companion.model import slot_reference
from companion.params import Params
from companion.types import Command, Observation


def _clamp(x: float, limit: float) -> float:
    return min(max(x, -limit), limit)


class PidController:
    """Two-channel PID regulating R onto the slot; see the module docstring."""

    def __init__(self, params: Params):
        self.params = params
        g = params.pid
        self._alpha = params.dt / (g.derivative_tau + params.dt)  # low-pass coefficient
        self.reset()

    def reset(self) -> None:
        self._i = [0.0, 0.0]                 # integral terms of v and omega
        self._prev: tuple[float, float] | None = None  # last (e_x, e_y)
        self._d = [0.0, 0.0]                 # filtered error rates
        self._own_v: float | None = None     # v this controller asked for last
        self._v_cut = 0                      # +1: outer layer lowered v, -1: raised it

    def step(self, obs: Observation) -> Command:
        p, g = self.params, self.params.pid
        r, h = obs.robot, obs.person
        d, f = p.robot.d, p.formation
        rx, ry = reference_point(r, d)
        sx, sy = slot_point(h, p)
        sdx, sdy = slot_velocity(h, p)
        e_x, e_y = to_frame(r.theta, sx - rx, sy - ry)
        ref = slot_reference(h.v, h.omega, f.distance, f.bearing, d)
        e_th = wrap_pi(h.theta - ref.beta - r.theta)

        if self._prev is not None:
            for i, (e, e0) in enumerate(zip((e_x, e_y), self._prev)):
                self._d[i] += self._alpha * ((e - e0) / p.dt - self._d[i])
        self._prev = (e_x, e_y)

        v_ff = math.cos(r.theta) * sdx + math.sin(r.theta) * sdy
        base_v = v_ff + g.kp_x * e_x + g.kd_x * self._d[0]
        base_w = h.omega + g.kp_y * e_y + g.kd_y * self._d[1] + g.kp_theta * e_th

        # Conditional integration: take the integrator step unless the output is (or the outer
        # layer held it) at a limit and the step pushes further into it.
        limits = (p.robot.v_max, p.robot.omega_max)
        steps = (g.ki_x * e_x * p.dt, g.ki_y * e_y * p.dt)
        bounds = (g.i_limit_v, g.i_limit_omega)
        for i, base in enumerate((base_v, base_w)):
            trial = _clamp(self._i[i] + steps[i], bounds[i])
            u = base + trial
            pushes = math.copysign(1.0, steps[i]) if steps[i] != 0.0 else 0.0
            saturated = (u > limits[i] and pushes > 0) or (u < -limits[i] and pushes < 0)
            held = i == 0 and self._v_cut != 0 and pushes == self._v_cut
            if not (saturated or held):
                self._i[i] = trial
        v, om = saturate(base_v + self._i[0], base_w + self._i[1], p.robot)
        self._own_v = v
        return Command(v, om)

    def applied(self, cmd: Command) -> None:
        """Note whether the keep-out barrier changed v (the integrator of v is then held in
        that direction on the next step)."""
        if self._own_v is None:
            return
        diff = self._own_v - cmd.v
        self._v_cut = 0 if abs(diff) < 1e-9 else (1 if diff > 0 else -1)
