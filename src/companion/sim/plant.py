"""The robot's base as the simulator moves it: what it does with a velocity command and what
its odometry reports (docs/plants.md).

A plant takes the command ``(v, omega)`` the base executes for one period and gives the true
pose and velocity (what the log records) and the odometry pose and velocity (what the robot
observes). :class:`KinematicPlant`, the unicycle with a first-order lag, reports its true
motion; the MuJoCo base (:mod:`companion.sim.mujoco_base`) integrates its wheels, which drift
from the truth when a wheel slips. :class:`FrameShift` carries what the robot senses into
its odometry frame, as a real robot's sensors see the world from where it really is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Protocol

from companion.geometry import base_step, wrap_pi
from companion.params import Params
from companion.types import Circle, Obstacle, PersonDetection, PersonState, Pose, Scan


class Plant(Protocol):
    """A robot base: ``reset`` at a pose and velocity, then ``step`` one period at a time."""

    pose: Pose                          # true pose
    velocity: tuple[float, float]       # true (v, omega)
    odometry: Pose                      # where the wheels say the robot is
    odometry_velocity: tuple[float, float]
    contact: float                      # 1: the body touches the person or an obstacle now

    def reset(self, pose: Pose, velocity: tuple[float, float]) -> None: ...

    def step(self, command: tuple[float, float], t: float,
             person: tuple[float, float] | None) -> None: ...


class KinematicPlant:
    """A unicycle whose velocity follows the command through the first-order lag
    ``sensing.actuator_tau_s`` (:func:`companion.geometry.base_step`); its odometry is the
    truth, and it has no bodies to touch (``contact`` NaN)."""

    contact = math.nan

    def __init__(self, params: Params):
        self.tau, self.dt = params.sensing.actuator_tau_s, params.dt

    def reset(self, pose: Pose, velocity: tuple[float, float]) -> None:
        self.pose, self.velocity = pose, velocity

    def step(self, command: tuple[float, float], t: float = 0.0,
             person: tuple[float, float] | None = None) -> None:
        p, (va, wa) = self.pose, self.velocity
        x, y, th, va, wa = base_step(p.x, p.y, p.theta, va, wa, *command, self.tau, self.dt)
        self.pose, self.velocity = Pose(x, y, wrap_pi(th)), (va, wa)

    @property
    def odometry(self) -> Pose:
        return self.pose

    @property
    def odometry_velocity(self) -> tuple[float, float]:
        return self.velocity


def make_plant(params: Params, obstacles: Sequence[Obstacle] = ()) -> Plant:
    """The plant ``params.plant.kind`` names, with ``obstacles`` as bodies where it has
    bodies."""
    if params.plant.kind == "mujoco":
        from companion.sim.mujoco_base import MujocoPlant  # MuJoCo loads only when asked
        return MujocoPlant(params, obstacles)
    return KinematicPlant(params)


class FrameShift:
    """The map from the world frame to the robot's odometry frame at one instant: a point
    the robot sees at some place relative to its true pose lies at the same place relative
    to its odometry pose. ``identity`` when odometry is the truth (then nothing is copied)."""

    def __init__(self, truth: Pose, odometry: Pose):
        self.identity, self.odometry = truth == odometry, odometry
        self.rot = wrap_pi(odometry.theta - truth.theta)
        c, s = math.cos(self.rot), math.sin(self.rot)
        self._c, self._s = c, s
        self._tx = odometry.x - (c * truth.x - s * truth.y)
        self._ty = odometry.y - (s * truth.x + c * truth.y)

    def point(self, x: float, y: float) -> tuple[float, float]:
        return (self._c * x - self._s * y + self._tx, self._s * x + self._c * y + self._ty)

    def person(self, p: PersonState) -> PersonState:
        x, y = self.point(p.x, p.y)
        return PersonState(x, y, wrap_pi(p.theta + self.rot), p.v, p.omega)

    def vector(self, x: float, y: float) -> tuple[float, float]:
        return self._c * x - self._s * y, self._s * x + self._c * y

    def obstacle(self, ob: Obstacle) -> Obstacle:
        if isinstance(ob, Circle):
            (x, y), (vx, vy) = self.point(ob.x, ob.y), self.vector(ob.vx, ob.vy)
            return replace(ob, x=x, y=y, vx=vx, vy=vy)
        (x0, y0), (x1, y1) = self.point(ob.x0, ob.y0), self.point(ob.x1, ob.y1)
        return replace(ob, x0=x0, y0=y0, x1=x1, y1=y1)

    def detection(self, d: PersonDetection) -> PersonDetection:
        if d.frame != "world":
            return d
        x, y = self.point(d.x, d.y)
        changes: dict = {"x": x, "y": y}
        if d.heading is not None:
            changes["heading"] = wrap_pi(d.heading + self.rot)
        if d.covariance is not None:
            c, s = self._c, self._s
            a, b, _, e = d.covariance
            # R C R^T for the 2x2 covariance (a, b; b, e)
            xx = c * c * a - 2 * c * s * b + s * s * e
            xy = c * s * (a - e) + (c * c - s * s) * b
            yy = s * s * a + 2 * c * s * b + c * c * e
            changes["covariance"] = (xx, xy, xy, yy)
        return replace(d, **changes)

    def scan(self, scan: Scan) -> Scan:
        """The scan, taken from the true pose, with its pose the odometry's."""
        o = self.odometry
        return replace(scan, x=o.x, y=o.y, theta=o.theta)
