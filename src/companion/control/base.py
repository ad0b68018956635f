"""The contract every companion controller follows.

A controller is constructed from :class:`~companion.params.Params`, is reset before an
episode, and maps one :class:`Observation` per sample period to one :class:`Command`:

    controller.reset()
    command = controller.step(observation)
    controller.applied(final_command)   # what was actually sent, after outer layers

``step`` must return finite inputs within ``robot.v_max`` and ``robot.omega_max``; the
contract tests in tests/control/test_contract.py run over every registered controller.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from companion.obstacles import Obstacle
from companion.params import RobotParams
from companion.perception import Scan


@dataclass(frozen=True)
class Pose:
    """Planar pose of the robot's wheel-axle centre: x, y (m) and heading theta (rad)."""

    x: float
    y: float
    theta: float


@dataclass(frozen=True)
class PersonState:
    """The person's pose and velocity (Eq. 3): x, y (m), theta (rad), v (m/s), omega (rad/s)."""

    x: float
    y: float
    theta: float
    v: float
    omega: float


@dataclass(frozen=True)
class Observation:
    """What a controller sees at one sample: time (s), robot pose, person state, the
    obstacles known at that time (world frame; ground truth or detected) and the latest LiDAR
    scan they came from (None without a LiDAR).

    Raw sensor data may be missing (``person`` None) or corrupt (NaN or Inf anywhere, time
    going backwards): only :class:`~companion.control.supervisor.SafetySupervisor` accepts
    such observations. It passes the controllers inside it a checked observation: a finite
    person state and robot pose, finite obstacles and a time that advances.
    """

    t: float
    robot: Pose
    person: PersonState | None
    obstacles: tuple[Obstacle, ...] = ()
    scan: Scan | None = None


@dataclass(frozen=True)
class Command:
    """Robot input: linear velocity v (m/s) and angular velocity omega (rad/s).

    ``u_ob`` (rad/s) is the part of omega that obstacle avoidance added, for logs and plots.
    ``status`` ("ok", "degraded" or "stopped") and ``reason`` (empty when ok) are set by the
    safety supervisor (docs/safety.md).
    """

    v: float
    omega: float
    u_ob: float = 0.0
    status: str = "ok"
    reason: str = ""


class Controller(Protocol):
    """A companion controller (see module docstring)."""

    def reset(self) -> None:
        """Forget all internal state before a new episode."""

    def step(self, obs: Observation) -> Command:
        """Return the input to apply for the next sample period."""

    def applied(self, cmd: Command) -> None:
        """Told the command actually sent after the layers around this controller (obstacle
        avoidance, keep-out barriers); controllers that remember their last input store it."""


def saturate(v: float, omega: float, robot: RobotParams) -> tuple[float, float]:
    """Clip each input to its limit (|v| <= v_max, |omega| <= omega_max), componentwise."""
    return (min(max(v, -robot.v_max), robot.v_max),
            min(max(omega, -robot.omega_max), robot.omega_max))

