"""Closed-loop episode: person motion, controller and exactly integrated unicycle plant.

At each sample ``k`` (time ``t_k = k * dt``) the runner reads the person's true state, the
controller observes it (optionally with Gaussian sensor noise) together with the robot pose,
and the command is held for one period while the unicycle is integrated exactly
(:func:`companion.kinematics.unicycle_step`). Row ``k`` of the log holds the state at ``t_k``
and the command applied from ``t_k`` on. The run is deterministic for a given seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from companion.control.avoidance import clearance
from companion.control.base import Controller, Observation, PersonState, Pose
from companion.kinematics import unicycle_step
from companion.errors import ConfigError
from companion.model import relative_state, robot_pose_at, slot_reference
from companion.obstacles import Obstacle
from companion.params import Params
from companion.sim.sensing import GroundTruth, Perception
from companion.sim.person import PersonMotion

LOG_COLUMNS = ("t", "robot_x", "robot_y", "robot_theta", "person_x", "person_y",
               "person_theta", "person_v", "person_omega", "rho", "alpha", "beta",
               "rho_d", "alpha_d", "beta_ref", "v", "omega", "u_ob", "rho_ob")
"""``u_ob``: the avoidance part of omega (rad/s); ``rho_ob``: clearance (m) from the robot's
footprint to the nearest true obstacle surface (NaN without obstacles)."""


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of zero-mean Gaussian noise on the person observation."""

    position: float = 0.0   # m, on x and y
    heading: float = 0.0    # rad
    speed: float = 0.0      # m/s
    turn_rate: float = 0.0  # rad/s


@dataclass(frozen=True)
class Log:
    """Columns of one episode (names in :data:`LOG_COLUMNS`), each an array of length N."""

    columns: dict[str, np.ndarray]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __len__(self) -> int:
        return len(self.columns["t"])


def start_in_slot(person: PersonState, params: Params) -> Pose:
    """Robot pose in its desired slot, heading aligned with the person's (beta = 0)."""
    f = params.formation
    return Pose(*robot_pose_at(f.distance, f.bearing, 0.0, person.x, person.y, person.theta,
                               params.robot.d))


def _observe(person: PersonState, noise: SensorNoise, rng: np.random.Generator) -> PersonState:
    if noise == SensorNoise():
        return person
    e = rng.normal(size=5)
    return PersonState(person.x + noise.position * e[0], person.y + noise.position * e[1],
                       person.theta + noise.heading * e[2], person.v + noise.speed * e[3],
                       person.omega + noise.turn_rate * e[4])


def nearest_clearance(x: float, y: float, obstacles: Sequence[Obstacle], footprint: float
                      ) -> float:
    """Smallest clearance from a footprint at (x, y) to any obstacle (NaN if none)."""
    if not obstacles:
        return math.nan
    return min(clearance(ob, x, y, footprint) for ob in obstacles)


def run_episode(controller: Controller, person: PersonMotion, params: Params,
                duration: float, start: Pose | None = None, seed: int = 0,
                noise: SensorNoise = SensorNoise(), obstacles: Sequence[Obstacle] = (),
                perception: Perception | None = None) -> Log:
    """Simulate ``duration`` seconds and return the log.

    Parameters
    ----------
    controller : Controller
        Reset before the first step.
    person : PersonMotion
    params : Params
    duration : float
        Simulated time (s); ``round(duration / dt)`` steps are run.
    start : Pose, optional
        Robot start; default: in the desired slot, aligned with the person.
    seed : int
        Seed of the sensor-noise generator.
    noise : SensorNoise
    obstacles : sequence of Circle or Wall
        The world's static obstacles.
    perception : Perception, optional
        How the controller learns about obstacles; default: it sees ``obstacles`` exactly.
    """
    dt, d = params.dt, params.robot.d
    f = params.formation
    n = int(round(duration / dt))
    if n < 1:
        raise ConfigError(f"duration: expected at least one sample period ({dt:g} s), "
                          f"got {duration:g} s")
    rng = np.random.default_rng(seed)
    out = np.empty((n, len(LOG_COLUMNS)))
    obstacles = tuple(obstacles)
    perception = perception or GroundTruth()
    perception.reset()
    controller.reset()
    pose = start or start_in_slot(person.state(0.0), params)
    x, y, th = pose.x, pose.y, pose.theta
    for k in range(n):
        t = k * dt
        h = person.state(t)
        seen = _observe(h, noise, rng)
        known = perception.obstacles(k, Pose(x, y, th), obstacles, (h.x, h.y),
                                     (seen.x, seen.y), rng)
        obs = Observation(t, Pose(x, y, th), seen, known)
        cmd = controller.step(obs)
        rho, alpha, beta = relative_state(x, y, th, h.x, h.y, h.theta, d)
        beta_ref = slot_reference(h.v, h.omega, f.distance, f.bearing, d).beta
        out[k] = (t, x, y, th, h.x, h.y, h.theta, h.v, h.omega, rho, alpha, beta,
                  f.distance, f.bearing, beta_ref, cmd.v, cmd.omega, cmd.u_ob,
                  nearest_clearance(x, y, obstacles, params.robot.radius))
        x, y, th = unicycle_step(x, y, th, cmd.v, cmd.omega, dt)
        th = math.remainder(th, 2.0 * math.pi)
    return Log({name: out[:, i] for i, name in enumerate(LOG_COLUMNS)})
