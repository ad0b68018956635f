"""The simulator as a Gymnasium environment, for learned followers (docs/evaluation.md).

A thin adapter over :class:`companion.sim.episode.Simulator`: the action is the velocity
command ``(v, omega)`` sent to the base (m/s, rad/s; no safety layer in between, wrap one if
the policy needs it; outside the action space it is clipped, and a wrong shape or a
non-finite entry raises ValueError); the observation is what a robot's detector and
odometry give, in the robot frame (:data:`OBSERVATION`); the reward is minus the slot error
of the step (m). An episode terminates on a contact with the person or an obstacle and is
truncated at the scenario's duration. ``info`` carries the step's log row (``info["row"]``, the
:data:`companion.types.LOG_COLUMNS` defined at that step: no estimate, as the action carries
none, nor obstacle clearance without obstacles) and the simulator's own observation
(``info["observation"]``), so a controller of :mod:`companion.control` can be run as a
policy for comparison. Importing this module registers ``companion/Follow-v0``.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from companion.geometry import wrap_pi
from companion.params import load_sensing
from companion.sim.episode import Simulator
from companion.sim.recorder import row as log_row
from companion.sim.scenario import load_scenario
from companion.sim.sensing import make_perception
from companion.types import LOG_COLUMNS, Command, Observation, PersonDetection, StepReport

#: The observation vector's entries, in order (SI units, robot frame: x ahead, y left).
OBSERVATION = ("person_x", "person_y", "person_heading", "person_speed", "heading_measured",
               "detection_age", "robot_v", "robot_omega", "distance_d", "bearing_d")

_SLOT, _CLEARANCE = LOG_COLUMNS.index("slot_error_m"), LOG_COLUMNS.index("rho_ob")


class FollowEnv(gym.Env):
    """Walk beside the person of a built-in ``scenario`` (or a scenario TOML file) under the
    ``sensing`` profile (a name of :data:`companion.params.PROFILES` or a sensing TOML
    file), on the scenario's plant or ``plant`` ("kinematic" or "mujoco", docs/plants.md),
    with the scenario's obstacles known exactly (``obstacles="truth"``) or as the simulated
    LiDAR sees them (the raw scan in ``info["observation"].scan``;
    :class:`companion.perception.front_end.FrontEnd` turns scans into obstacles as the
    standard stack does)."""

    metadata = {"render_modes": []}

    def __init__(self, scenario: str = "figure8", sensing: str = "ideal",
                 obstacles: str | None = None, duration: float | None = None,
                 plant: str | None = None):
        sc = load_scenario(scenario, None if plant is None else {"plant": {"kind": plant}})
        self.params = sc.params.replace(sensing=load_sensing(sensing))
        self.scenario = sc
        source = obstacles or sc.obstacle_source
        self._sim = Simulator(sc.person, self.params, duration or sc.duration, sc.start,
                              sc.obstacles, make_perception(source, self.params), sc.faults)
        limits = self.params.robot
        self.action_space = gym.spaces.Box(
            np.array((-limits.v_max, -limits.omega_max)),
            np.array((limits.v_max, limits.omega_max)), dtype=np.float64)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (len(OBSERVATION),),
                                                dtype=np.float64)
        self._last: PersonDetection | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        """A new episode; its sensing noise is drawn from the environment's generator, so a
        ``seed`` repeats it."""
        super().reset(seed=seed)
        self._last = None
        obs = self._sim.reset(int(self.np_random.integers(2 ** 63 - 1)))
        return self._vector(obs), {"observation": obs,
                                   "start_velocity": self._sim.start_velocity}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One sample under ``action``, an array of shape (2,) of finite numbers: a wrong shape
        or a NaN/inf entry raises ValueError (nothing is simulated); entries outside
        :attr:`action_space` are clipped to it, as the base's limits would."""
        a = np.asarray(action, dtype=float)
        if a.shape != self.action_space.shape:
            raise ValueError(f"action: expected shape {self.action_space.shape} (v, omega), "
                             f"got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action: (v, omega) must be finite, got {a.tolist()}")
        v, omega = np.clip(a, self.action_space.low, self.action_space.high)
        obs = self._sim.step(Command(float(v), float(omega)))
        numbers = log_row(self._sim.sample, StepReport(), self.params)
        row = {k: x for k, x in zip(LOG_COLUMNS, numbers) if not math.isnan(x)}
        contact = math.hypot(row["person_x"] - row["robot_x"], row["person_y"] - row["robot_y"]) \
            < self.params.robot.radius + self.params.lidar.person_radius
        terminated = bool(contact or numbers[_CLEARANCE] <= 0.0)
        truncated = obs is None
        info = {"row": row, "observation": obs}
        vector = self._vector(obs) if obs is not None else np.zeros(len(OBSERVATION))
        return vector, -float(numbers[_SLOT]), terminated, truncated and not terminated, info

    def _vector(self, obs: Observation) -> np.ndarray:
        """:data:`OBSERVATION` from the newest detection so far and the odometry."""
        if obs.detections:
            self._last = max(obs.detections, key=lambda d: d.t)
        d, r = self._last, obs.robot
        out = np.zeros(len(OBSERVATION))
        if d is not None:
            c, s = math.cos(r.theta), math.sin(r.theta)
            dx, dy = d.x - r.x, d.y - r.y
            out[0:2] = c * dx + s * dy, -s * dx + c * dy
            if d.heading is not None:
                out[2], out[4] = wrap_pi(d.heading - r.theta), 1.0
            out[3] = d.speed or 0.0
            out[5] = obs.t - d.t
        out[6:8] = obs.robot_velocity or (0.0, 0.0)
        out[8:10] = self.params.formation.distance, self.params.formation.bearing
        return np.nan_to_num(out)


gym.register("companion/Follow-v0", entry_point=FollowEnv)
