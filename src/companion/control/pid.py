"""PID baseline companion controller (after Sun et al. [6] and Yao et al. [13]).

Two channels regulate the reference point R onto the slot S: ``v`` from the error ahead,
``omega`` from the error to the left and the heading error against the slot-holding heading,
each with feedforward, a clamped and conditionally frozen integral (anti-windup, also when an
outer layer cut ``v``) and a filtered derivative on measurement. docs/baselines.md gives the
law and its tuning.
"""

from __future__ import annotations

import math

from companion.control.base import in_force, saturate
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
        p = in_force(self.params, obs)
        g = p.pid
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
