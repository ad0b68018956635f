"""Impedance control (IC) baseline companion controller (after Tian et al. [17]).

The error of the robot's reference point R from the slot S (:mod:`companion.control.slot`) is
expressed in the person's frame (x along the person's heading: longitudinal; y to its left:
lateral), ``e = Rot(theta_h)^T (R - S)``, and made to obey, per axis ``i``, the impedance

    M_i e_ddot_i + D_i e_dot_i + K_i e_i = 0.

Per sample period:

1. ``e_dot`` is measured from the velocity of R under the robot's last command as actually sent
   (after the avoidance and keep-out layers; reported through :meth:`ImpedanceController.applied`)
   and the slot velocity ``S_dot`` of the person's ``(v_h, omega_h)``, taking the rotation of the
   person frame into account: ``e_dot = Rot^T (R_dot - S_dot) - omega_h J e`` with ``J`` the
   rotation by +90 degrees. After ``reset`` ``R_dot = S_dot`` is assumed (bumpless start);
2. the impedance gives ``e_ddot = -M^-1 (D e_dot + K e)`` and the error velocity for the next
   period ``e_dot* = e_dot + dt e_ddot``;
3. the desired velocity of R is the person-driven slot velocity (feedforward) plus that error
   velocity mapped back to the world: ``V = S_dot + Rot (e_dot* + omega_h J e)``;
4. offset-point kinematics give ``v = e(theta).V``, ``omega = e_perp(theta).V / d``, clipped to
   the input limits. Heading follows from these kinematics (``d > 0``).

Because ``e_dot`` is re-measured from the input actually applied, saturation cannot wind up the
law. In the slot of a person walking with constant ``(v_h, omega_h)`` and the slot-holding
heading, ``e = e_dot = 0`` and ``V = S_dot``: the input is exactly the one that holds the slot.
"""

from __future__ import annotations

from companion.control.base import saturate
from companion.control.slot import (
    LastCommand,
    from_frame,
    last_velocity,
    reference_point,
    slot_point,
    slot_velocity,
    to_frame,
    to_inputs,
)
from companion.params import Params
from companion.types import Command, Observation


class ImpedanceController(LastCommand):
    """Per-axis impedance on the slot error in the person frame; see the module docstring."""

    def __init__(self, params: Params):
        self.params = params
        self.reset()

    def step(self, obs: Observation) -> Command:
        p, g = self.params, self.params.impedance
        r, h = obs.robot, obs.person
        d, dt, w = p.robot.d, p.dt, h.omega
        rx, ry = reference_point(r, d)
        sx, sy = slot_point(h, p)
        sdx, sdy = slot_velocity(h, p)
        rdx, rdy = last_velocity(r.theta, self._last, d, (sdx, sdy))
        e = to_frame(h.theta, rx - sx, ry - sy)
        ed_world = to_frame(h.theta, rdx - sdx, rdy - sdy)
        e_dot = (ed_world[0] + w * e[1], ed_world[1] - w * e[0])
        target = [e_dot[i] - dt * (g.damping[i] * e_dot[i] + g.stiffness[i] * e[i]) / g.mass[i]
                  for i in range(2)]
        cx, cy = from_frame(h.theta, target[0] - w * e[1], target[1] + w * e[0])
        v, om = saturate(*to_inputs(r.theta, sdx + cx, sdy + cy, d), p.robot)
        self._last = (v, om)
        return Command(v, om)
