"""Impedance control (IC) baseline (after Tian et al. [17]).

The slot error in the person's frame obeys ``M e_ddot + D e_dot + K e = 0`` per axis
(longitudinal, lateral); the error velocity comes from the robot's actual velocity
(odometry, else the command actually sent: no wind-up), the slot velocity is fed forward.
docs/baselines.md gives the law and its tuning.
"""

from __future__ import annotations

from companion.control.base import in_force, saturate
from companion.control.slot import (
    ActualVelocity,
    from_frame,
    reference_point,
    slot_point,
    slot_velocity,
    to_frame,
    to_inputs,
)
from companion.params import Params
from companion.types import Command, Observation


class ImpedanceController(ActualVelocity):
    """Per-axis impedance on the slot error in the person frame; see the module docstring."""

    def __init__(self, params: Params):
        self.params = params
        self.reset()

    def step(self, obs: Observation) -> Command:
        p = in_force(self.params, obs)
        g = p.impedance
        r, h = obs.robot, obs.person
        d, dt, w = p.robot.d, p.dt, h.omega
        rx, ry = reference_point(r, d)
        sx, sy = slot_point(h, p)
        sdx, sdy = slot_velocity(h, p)
        rdx, rdy = self.point_velocity(obs, d, (sdx, sdy))
        e = to_frame(h.theta, rx - sx, ry - sy)
        ed_world = to_frame(h.theta, rdx - sdx, rdy - sdy)
        e_dot = (ed_world[0] + w * e[1], ed_world[1] - w * e[0])
        target = [e_dot[i] - dt * (g.damping[i] * e_dot[i] + g.stiffness[i] * e[i]) / g.mass[i]
                  for i in range(2)]
        cx, cy = from_frame(h.theta, target[0] - w * e[1], target[1] + w * e[0])
        v, om = saturate(*to_inputs(r.theta, sdx + cx, sdy + cy, d), p.robot)
        self._last = (v, om)
        return Command(v, om)
