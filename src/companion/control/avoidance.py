"""Behavioural-dynamics obstacle avoidance (paper Sec. 3.3, Eq. 17-20), for any controller.

Every obstacle within its influence range and ahead gives an angular acceleration
``A_ob = -eta phi exp(-c1 |phi|) exp(-c2 rho_ob)`` (Eq. 17, phi > 0 on the left turns right);
their sum (Eq. 19) is integrated with a leak into ``u_ob``, which is added to the wrapped
controller's omega (Eq. 20) within the headroom ``omega_max`` leaves. This layer only steers:
keeping clear is the safety supervisor's duty (:mod:`companion.control.keepout`).
docs/model.md, section 8, gives the choices where the paper is silent.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from companion.control.base import Controller
from companion.geometry import clearance, nearest_point, predicted, wrap_pi
from companion.params import AvoidanceParams, Params
from companion.types import Circle, Command, Observation, Obstacle


def influence_range(obstacle: Obstacle, avoidance: AvoidanceParams) -> float:
    """rho_o: the obstacle's own ``influence`` if set, else r / K_ob (circles) or the wall
    default."""
    if obstacle.influence is not None:
        return obstacle.influence
    if isinstance(obstacle, Circle):
        return obstacle.radius / avoidance.k_ob
    return avoidance.wall_influence


def angular_acceleration(phi: float, rho_ob: float, avoidance: AvoidanceParams) -> float:
    """Eq. (17) for one obstacle at bearing ``phi`` (rad) and clearance ``rho_ob`` (m)."""
    a = avoidance
    return -a.eta * phi * math.exp(-a.c1 * abs(phi)) * math.exp(-a.c2 * rho_ob)


def steering_bearing(phi: float, cone: float, person_side: float, tie_band: float) -> float:
    """The bearing Eq. (17) is evaluated at.

    ``phi`` is the obstacle's bearing and ``cone`` the half-angle of its collision cone (the
    headings that come too close). Outside the cone this is ``phi`` (the paper). Inside, the
    heading is blocked and Eq. (17) would steer weakly (it is zero dead ahead): we evaluate it
    at the cone's edge, on the obstacle's own side (``sign(phi)``), or, when the obstacle is
    nearly dead ahead (``|phi| < tie_band``), on the side away from the person
    (``person_side`` +1: person on the robot's left, pass the obstacle on its right), as a
    walking pair does not split around an obstacle.
    """
    if abs(phi) >= cone:
        return phi
    if abs(phi) < tie_band:
        return cone if person_side >= 0.0 else -cone
    return math.copysign(cone, phi)


def total_acceleration(x: float, y: float, theta: float, obstacles: Sequence[Obstacle],
                       params: Params, person_side: float = 0.0) -> float:
    """Sum of Eq. (17) over the obstacles in range and ahead (Eq. 19)."""
    a = params.avoidance
    total = 0.0
    for ob in obstacles:
        rho_ob = clearance(ob, x, y, params.robot.radius)
        if rho_ob >= influence_range(ob, a):
            continue
        px, py = nearest_point(ob, x, y)
        phi = wrap_pi(math.atan2(py - y, px - x) - theta)
        if abs(phi) >= a.field_of_view:
            continue
        if a.cone_margin >= 0.0:
            cone = collision_cone(ob, x, y, params.robot.radius + a.cone_margin)
            phi = steering_bearing(phi, cone, person_side, a.tie_band)
        total += angular_acceleration(phi, rho_ob, a)
    return total


def collision_cone(obstacle: Obstacle, x: float, y: float, inflate: float) -> float:
    """Half-angle (rad) of the headings from (x, y) whose straight path comes within
    ``inflate`` of the obstacle (pi/2 when already that close)."""
    px, py = nearest_point(obstacle, x, y)
    dist = math.hypot(px - x, py - y)
    if isinstance(obstacle, Circle):
        dist += obstacle.radius  # distance to the centre
        reach = obstacle.radius + inflate
    else:
        reach = inflate
    return math.asin(min(1.0, reach / dist)) if dist > 0.0 else 0.5 * math.pi


class AvoidingController:
    """Wraps any :class:`~companion.control.base.Controller` with behavioural-dynamics
    avoidance of ``obs.obstacles`` (see the module docstring), moving ones on a collision
    course where they will be when closest to the robot (:func:`companion.geometry.predicted`,
    within ``avoidance.prediction_horizon_s``); the command's ``u_ob`` field is the avoidance
    part of omega."""

    def __init__(self, inner: Controller, params: Params):
        self.inner = inner
        self.params = params
        a = params.avoidance
        self._decay = math.exp(-params.dt / a.decay_time)
        self.reset()

    def reset(self) -> None:
        self.inner.reset()
        self.u_ob = 0.0

    def step(self, obs: Observation) -> Command:
        cmd = self.inner.step(obs)
        r, h = obs.robot, obs.person
        # +1 when the person is on the robot's left
        side = math.copysign(1.0, math.cos(r.theta) * (h.y - r.y)
                             - math.sin(r.theta) * (h.x - r.x))
        v = 0.0 if obs.robot_velocity is None else obs.robot_velocity[0]
        a = self.params.avoidance
        ahead = predicted(obs.obstacles, r.x, r.y, v * math.cos(r.theta), v * math.sin(r.theta),
                          a.prediction_horizon_s, self.params.robot.radius + a.cone_margin)
        acc = total_acceleration(r.x, r.y, r.theta, ahead, self.params, side)
        tau = self.params.avoidance.decay_time
        u_ob = self.u_ob * self._decay + acc * tau * (1.0 - self._decay)
        w_max = self.params.robot.omega_max
        self.u_ob = min(max(u_ob, -w_max - cmd.omega), w_max - cmd.omega)
        return Command(cmd.v, cmd.omega + self.u_ob, self.u_ob)

    def applied(self, cmd: Command) -> None:
        """Pass the command finally sent on to the wrapped controller."""
        self.inner.applied(cmd)
