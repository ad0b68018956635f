"""Slot geometry shared by the baseline controllers (docs/baselines.md, "Common geometry").

R is the robot's reference point, S the desired slot ``h + rho_d e(theta_h + alpha_d)`` and
``S_dot`` its velocity from the person's ``(v_h, omega_h)``; the offset-point kinematics map a
desired velocity of R to ``(v, omega)`` and back. At the slot-holding equilibrium, mapping
``S_dot`` gives exactly the input that holds the slot.
"""

from __future__ import annotations

import math

from companion.geometry import offset_point
from companion.params import Params
from companion.types import Command, Observation, PersonState, Pose


def reference_point(robot: Pose, d: float) -> tuple[float, float]:
    """R, the point ``d`` ahead of the wheel axle."""
    return offset_point(robot.x, robot.y, robot.theta, d)


def slot_point(person: PersonState, params: Params, bearing: float | None = None
               ) -> tuple[float, float]:
    """S, the desired position of R (at ``bearing``, rad, instead of the formation's if
    given)."""
    f = params.formation
    a = person.theta + (f.bearing if bearing is None else bearing)
    return person.x + f.distance * math.cos(a), person.y + f.distance * math.sin(a)


def slot_velocity(person: PersonState, params: Params) -> tuple[float, float]:
    """S_dot, the velocity of the slot point given the person's ``(v_h, omega_h)``."""
    f = params.formation
    a = person.theta + f.bearing
    w = f.distance * person.omega
    return (person.v * math.cos(person.theta) - w * math.sin(a),
            person.v * math.sin(person.theta) + w * math.cos(a))


def point_velocity(theta: float, v: float, omega: float, d: float) -> tuple[float, float]:
    """R_dot for the input ``(v, omega)`` at heading ``theta``."""
    c, s = math.cos(theta), math.sin(theta)
    return v * c - d * omega * s, v * s + d * omega * c


def to_inputs(theta: float, vx: float, vy: float, d: float) -> tuple[float, float]:
    """Inverse offset-point kinematics: the ``(v, omega)`` that move R with ``(vx, vy)``."""
    c, s = math.cos(theta), math.sin(theta)
    return c * vx + s * vy, (-s * vx + c * vy) / d


def to_frame(angle: float, x: float, y: float) -> tuple[float, float]:
    """World vector ``(x, y)`` in a frame rotated by ``angle``."""
    c, s = math.cos(angle), math.sin(angle)
    return c * x + s * y, -s * x + c * y


def from_frame(angle: float, x: float, y: float) -> tuple[float, float]:
    """Vector ``(x, y)`` of a frame rotated by ``angle`` in the world frame."""
    c, s = math.cos(angle), math.sin(angle)
    return c * x - s * y, s * x + c * y


class ActualVelocity:
    """Base for controllers whose virtual state starts from the robot's actual velocity (VSM,
    IC): odometry (``obs.robot_velocity``) when the observation has it, else the last command
    actually sent (:meth:`applied`). So saturation, the outer layers and the base's lag cannot
    wind the virtual state up, and no command is taken for the robot's actual motion."""

    def reset(self) -> None:
        self._last: tuple[float, float] | None = None   # last applied (v, omega)

    def applied(self, cmd: Command) -> None:
        """Store the command actually sent (R_dot on the next step without odometry; a
        controller also stores its own output, for callers that never call this)."""
        self._last = (cmd.v, cmd.omega)

    def point_velocity(self, obs: Observation, d: float, fallback: tuple[float, float]
                       ) -> tuple[float, float]:
        """R_dot now; ``fallback`` (the slot velocity: a bumpless start) while neither
        odometry nor a command sent is known."""
        v = obs.robot_velocity
        if v is None or not (math.isfinite(v[0]) and math.isfinite(v[1])):
            v = self._last
        if v is None:
            return fallback
        return point_velocity(obs.robot.theta, v[0], v[1], d)
