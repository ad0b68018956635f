"""Closed-loop episode: person motion, controller and exactly integrated unicycle plant.

At each sample ``k`` (time ``t_k = k * dt``) the runner reads the person's true state, the
controller observes it (optionally with Gaussian sensor noise) together with the robot pose,
and the command is held for one period while the unicycle is integrated exactly
(:func:`companion.geometry.unicycle_step`). Row ``k`` of the log holds the state at ``t_k``
and the command applied from ``t_k`` on. The run is deterministic for a given seed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from companion.control.base import Controller
from companion.errors import ConfigError
from companion.geometry import clearance, unicycle_step, wrap_pi
from companion.model import relative_state, robot_pose_at, slot_reference
from companion.params import Params
from companion.sim.faults import Fault, stalled
from companion.sim.faults import apply as apply_faults
from companion.sim.person import PersonMotion
from companion.sim.sensing import GroundTruth, Perception
from companion.types import LOG_COLUMNS, Command, Log, Observation, Obstacle, PersonState, Pose


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of zero-mean Gaussian noise on the person observation."""

    position: float = 0.0   # m, on x and y
    heading: float = 0.0    # rad
    speed: float = 0.0      # m/s
    turn_rate: float = 0.0  # rad/s


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
                perception: Perception | None = None, faults: Sequence[Fault] = (),
                start_velocity: tuple[float, float] | None = None) -> Log:
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
    start_velocity : (v, omega), optional
        The robot's velocity at the start, told to the controller as the command being
        applied (``controller.applied``) so that its acceleration limits start from it.
        Default: with ``start`` None, the slot velocity (already walking with the person);
        with a ``start``, at rest.
    seed : int
        Seed of the sensor-noise generator.
    noise : SensorNoise
    obstacles : sequence of Circle or Wall
        The world's static obstacles.
    perception : Perception, optional
        How the controller learns about obstacles; default: it sees ``obstacles`` exactly.
    faults : sequence of Fault
        Faults injected into what the controller observes (:mod:`companion.sim.faults`).
    """
    dt, d = params.dt, params.robot.d
    f = params.formation
    n = int(round(duration / dt))
    if n < 1:
        raise ConfigError(f"duration: expected at least one sample period ({dt:g} s), "
                          f"got {duration:g} s")
    rng = np.random.default_rng(seed)
    out = np.empty((n, len(LOG_COLUMNS)))
    status: list[str] = []
    reason: list[str] = []
    obstacles = tuple(obstacles)
    perception = perception or GroundTruth()
    perception.reset()
    controller.reset()
    if start is None:
        h0 = person.state(0.0)
        pose = start_in_slot(h0, params)
        ref = slot_reference(h0.v, h0.omega, f.distance, f.bearing, d)
        start_velocity = start_velocity or (ref.v, ref.omega)
    else:
        pose = start
    if start_velocity is not None:
        controller.applied(Command(*start_velocity))
    x, y, th = pose.x, pose.y, pose.theta
    cmd = Command(0.0, 0.0)
    for k in range(n):
        t = k * dt
        h = person.state(t)
        seen = _observe(h, noise, rng)
        known = perception.obstacles(k, Pose(x, y, th), obstacles, (h.x, h.y),
                                     (seen.x, seen.y), rng)
        if not stalled(faults, t):  # a stalled controller leaves the last command in force
            obs = Observation(t, Pose(x, y, th), seen, known, perception.scan())
            cmd = controller.step(apply_faults(obs, faults))
        rho, alpha, beta = relative_state(x, y, th, h.x, h.y, h.theta, d)
        beta_ref = slot_reference(h.v, h.omega, f.distance, f.bearing, d).beta
        out[k] = (t, x, y, th, h.x, h.y, h.theta, h.v, h.omega, rho, alpha, beta,
                  f.distance, f.bearing, beta_ref, cmd.v, cmd.omega, cmd.u_ob,
                  nearest_clearance(x, y, obstacles, params.robot.radius))
        status.append(cmd.status)
        reason.append(cmd.reason)
        x, y, th = unicycle_step(x, y, th, cmd.v, cmd.omega, dt)
        th = wrap_pi(th)
    columns: dict[str, np.ndarray] = {name: out[:, i] for i, name in enumerate(LOG_COLUMNS)}
    columns["status"] = np.array(status, dtype=str)
    columns["reason"] = np.array(reason, dtype=str)
    return Log(columns)
