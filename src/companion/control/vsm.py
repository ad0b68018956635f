"""Virtual spring model (VSM) baseline companion controller (after Morioka et al. [15] and
Hu et al. [16]).

A virtual spring-damper joins the robot's reference point R to the slot S
(:mod:`companion.control.slot`) and pulls a virtual mass ``m`` located at R::

    F = k (S - R) - c (R_dot - S_dot)
    V = R_dot + (dt / m) F            (one explicit Euler step of m R_ddot = F)
    v = e(theta).V,   omega = e_perp(theta).V / d

* ``S_dot`` is the slot velocity computed from the person's velocity ``(v_h, omega_h)``;
* ``R_dot`` is the velocity of R under the robot's last command as actually sent (after the
  avoidance and keep-out layers, reported through :meth:`VsmController.applied`), at the current
  heading. The virtual mass therefore always starts from the robot's real velocity: saturation
  cannot wind up the virtual state. After ``reset`` (no command yet) the robot is assumed to move
  with the slot (``R_dot = S_dot``, a bumpless start);
* the heading is not controlled directly: with ``d > 0`` it follows from the offset-point
  kinematics (it turns towards the direction R moves in).

In the slot of a person walking straight, ``F = 0`` and ``V = S_dot``: the law holds the
formation exactly. Like any spring law, the isotropic spring treats the distance to the
person and the position along the walk alike.
"""

from __future__ import annotations

from companion.control.base import saturate
from companion.control.slot import (
    LastCommand,
    last_velocity,
    reference_point,
    slot_point,
    slot_velocity,
    to_inputs,
)
from companion.params import Params
from companion.types import Command, Observation


class VsmController(LastCommand):
    """Spring-damper-mass between R and the slot; see the module docstring."""

    def __init__(self, params: Params):
        self.params = params
        self.reset()

    def step(self, obs: Observation) -> Command:
        p, g = self.params, self.params.vsm
        r, h = obs.robot, obs.person
        d = p.robot.d
        rx, ry = reference_point(r, d)
        sx, sy = slot_point(h, p)
        sdx, sdy = slot_velocity(h, p)
        rdx, rdy = last_velocity(r.theta, self._last, d, (sdx, sdy))
        fx = g.stiffness * (sx - rx) - g.damping * (rdx - sdx)
        fy = g.stiffness * (sy - ry) - g.damping * (rdy - sdy)
        vx, vy = rdx + p.dt * fx / g.mass, rdy + p.dt * fy / g.mass
        v, om = saturate(*to_inputs(r.theta, vx, vy, d), p.robot)
        self._last = (v, om)
        return Command(v, om)
