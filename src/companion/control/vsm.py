"""Virtual spring model (VSM) baseline (after Morioka et al. [15] and Hu et al. [16]).

A spring-damper between R and the slot S pulls a virtual mass at R; one explicit Euler step
gives the velocity of R, mapped to ``(v, omega)`` by the offset-point kinematics. The mass
starts from the robot's actual velocity (odometry, else the command actually sent), so
saturation and the base's lag cannot wind it up. docs/baselines.md gives the law and its tuning.
"""

from __future__ import annotations

from companion.control.base import in_force, saturate
from companion.control.slot import (
    ActualVelocity,
    reference_point,
    slot_point,
    slot_velocity,
    to_inputs,
)
from companion.params import Params
from companion.types import Command, Observation


class VsmController(ActualVelocity):
    """Spring-damper-mass between R and the slot; see the module docstring."""

    def __init__(self, params: Params):
        self.params = params
        self.reset()

    def step(self, obs: Observation) -> Command:
        p = in_force(self.params, obs)
        g = p.vsm
        r, h = obs.robot, obs.person
        d = p.robot.d
        rx, ry = reference_point(r, d)
        sx, sy = slot_point(h, p)
        sdx, sdy = slot_velocity(h, p)
        rdx, rdy = self.point_velocity(obs, d, (sdx, sdy))
        fx = g.stiffness * (sx - rx) - g.damping * (rdx - sdx)
        fy = g.stiffness * (sy - ry) - g.damping * (rdy - sdy)
        vx, vy = rdx + p.dt * fx / g.mass, rdy + p.dt * fy / g.mass
        v, om = saturate(*to_inputs(r.theta, vx, vy, d), p.robot)
        self._last = (v, om)
        return Command(v, om)
