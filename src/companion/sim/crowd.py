"""Other people walking: pedestrians who avoid each other, the companion person and the robot
with ORCA (optimal reciprocal collision avoidance, through pyrvo, the bindings of the RVO2
library), for the crowd scenes of docs/crowds.md.

A :class:`Crowd` holds the walkers of one episode in a ``pyrvo.RVOSimulator``. Each walker
follows its route (waypoints, looping or not) at its preferred speed; ORCA picks the velocity
closest to the preferred one that keeps clear of the others for ``time_horizon`` seconds.
The companion person is one of them, walking its own route and seeing the robot and the
walkers: the crowd is then also the episode's person motion (``state(t)`` reads the person's
recorded states). The robot is an agent moved by the episode (its velocity set each period),
so the walkers see it and give way. Walls are ORCA line obstacles. Preferred speeds are drawn
from the episode's ``walkers`` random stream, so a crowd is deterministic for the episode
seed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pyrvo

from companion.geometry import wrap_pi
from companion.types import Circle, PersonState, Wall

#: Body radius of a walker (m): the circle the LiDAR sees and contacts are measured against.
WALKER_RADIUS = 0.25


@dataclass(frozen=True)
class Walker:
    """A pedestrian: ``route`` (waypoints, m; it starts at the first), preferred ``speed``
    (m/s, before the episode's draw), and whether it starts the route over at its end."""

    route: tuple[tuple[float, float], ...]
    speed: float = 1.2
    loop: bool = False


@dataclass(frozen=True)
class Scene:
    """A crowd scene: the companion person's route, the walls, and ``draw(rng, n)``: the
    ``n`` other walkers of one episode."""

    name: str
    description: str
    person: Walker
    walls: tuple[Wall, ...]
    draw: Callable[[np.random.Generator, int], tuple[Walker, ...]]


@dataclass(frozen=True)
class CrowdParams:
    """ORCA's settings for the walkers (RVO2's names)."""

    comfort: float = 0.1          # m added to the body radius in ORCA (personal space)
    neighbor_dist: float = 5.0    # m: agents farther away are ignored
    max_neighbors: int = 10
    time_horizon: float = 2.0     # s: look-ahead against other agents
    time_horizon_obst: float = 1.0  # s: look-ahead against walls
    max_speed: float = 1.8        # m/s
    speed_spread: float = 0.1     # preferred speeds drawn within +-10 %
    goal_tolerance: float = 0.3   # m: a waypoint closer than this is reached


class Crowd:
    """The walkers of one episode of a crowd ``scene`` (:mod:`companion.sim.crowd_scenes`)
    with ``walkers`` others than the person, stepped once per control period ``dt`` (s).

    It is the episode's person motion too: ``state(t)`` is the person's recorded state.
    Before :meth:`reset` there are no walkers and the person stands at its start, facing its
    first waypoint. The episode works on its own copy (:meth:`fresh`)."""

    def __init__(self, scene: Scene, walkers: int, params: CrowdParams = CrowdParams(),
                 dt: float = 0.05):
        self.scene, self.count, self.params, self.dt = scene, walkers, params, dt
        self.person, self.walls = scene.person, tuple(scene.walls)
        self.walkers: tuple[Walker, ...] = ()
        self.n = 0
        (x0, y0), (x1, y1) = self.person.route[:2]
        self._history = [(x0, y0, math.atan2(y1 - y0, x1 - x0), self.person.speed, 0.0)]
        self.positions = np.array([[x0, y0]])
        self.velocities = np.zeros((1, 2))

    def fresh(self) -> Crowd:
        """A copy not yet reset (what a new episode steps)."""
        return Crowd(self.scene, self.count, self.params, self.dt)

    def reset(self, rng: np.random.Generator, robot_radius: float) -> None:
        """Draw the walkers of this episode from ``rng``; every one of them and the person at
        their route's start, walking towards the next waypoint. The robot joins at the first
        :meth:`step`."""
        p = self.params
        self.walkers = tuple(self.scene.draw(rng, self.count))
        self.n = len(self.walkers)
        self._sim = pyrvo.RVOSimulator(self.dt, p.neighbor_dist, p.max_neighbors,
                                       p.time_horizon, p.time_horizon_obst,
                                       WALKER_RADIUS + p.comfort, p.max_speed)
        everyone = (*self.walkers, self.person)
        for w in everyone:
            self._sim.add_agent(tuple(map(float, w.route[0])))
        self._robot = self._sim.add_agent((1e6, 1e6))
        self._sim.set_agent_radius(self._robot, robot_radius)
        for wall in self.walls:
            self._sim.add_obstacle([(wall.x0, wall.y0), (wall.x1, wall.y1)])
        if self.walls:
            self._sim.process_obstacles()
        self._speed = np.array([w.speed for w in everyone]) * (
            1.0 + rng.uniform(-p.speed_spread, p.speed_spread, len(everyone)))
        self._next = np.ones(len(everyone), dtype=int)   # index of the waypoint walked to
        self.positions = np.array([w.route[0] for w in everyone], dtype=float)
        self.velocities = np.array([self._preferred(i, w) for i, w in enumerate(everyone)])
        for i, v in enumerate(self.velocities):
            self._sim.set_agent_velocity(i, tuple(v))
        x, y = self.positions[-1]
        vx, vy = self.velocities[-1]
        self._history = [(x, y, math.atan2(vy, vx) if vx or vy else self._history[0][2],
                          math.hypot(vx, vy), 0.0)]

    def step(self, robot: tuple[float, float, float, float]) -> None:
        """Advance one period; ``robot``: (x, y, vx, vy) at its start."""
        x, y, vx, vy = robot
        self._sim.set_agent_position(self._robot, (x, y))
        self._sim.set_agent_velocity(self._robot, (vx, vy))
        self._sim.set_agent_pref_velocity(self._robot, (vx, vy))
        for i, w in enumerate((*self.walkers, self.person)):
            self._sim.set_agent_pref_velocity(i, self._preferred(i, w))
        self._sim.do_step()
        for i in range(self.n + 1):
            self.positions[i] = self._sim.get_agent_position(i).to_tuple()
            self.velocities[i] = self._sim.get_agent_velocity(i).to_tuple()
        px, py = self.positions[-1]
        pvx, pvy = self.velocities[-1]
        speed, last = math.hypot(pvx, pvy), self._history[-1]
        theta = math.atan2(pvy, pvx) if speed > 0.05 else last[2]
        omega = wrap_pi(theta - last[2]) / self.dt
        self._history.append((px, py, theta, speed, omega))

    def state(self, t: float) -> PersonState:
        """The companion person at ``t`` (s), between the recorded periods linearly; held at
        the last recorded one (the episode steps the crowd before it asks further)."""
        k = t / self.dt
        i = min(max(int(math.floor(k)), 0), len(self._history) - 1)
        a = self._history[i]
        if i + 1 >= len(self._history) or k <= i:
            return PersonState(*a)
        b, f = self._history[i + 1], k - i
        return PersonState(a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]),
                           wrap_pi(a[2] + f * wrap_pi(b[2] - a[2])), a[3] + f * (b[3] - a[3]),
                           b[4])

    def _preferred(self, i: int, w: Walker) -> tuple[float, float]:
        """Towards the walker's next waypoint at its speed (slowing into its last one)."""
        x, y = self.positions[i]
        while True:
            if self._next[i] >= len(w.route):
                if not w.loop:
                    return 0.0, 0.0
                self._next[i] = 0
            gx, gy = w.route[self._next[i]]
            dist = math.hypot(gx - x, gy - y)
            if dist > self.params.goal_tolerance:
                break
            self._next[i] += 1
        last = not w.loop and self._next[i] == len(w.route) - 1
        speed = min(self._speed[i], dist / self.dt) if last else self._speed[i]
        return speed * (gx - x) / dist, speed * (gy - y) / dist

    def circles(self) -> tuple[Circle, ...]:
        """The walkers' bodies (not the person's) where they are now, with their velocities,
        as obstacles."""
        return tuple(Circle(float(x), float(y), WALKER_RADIUS, None, float(vx), float(vy))
                     for (x, y), (vx, vy) in zip(self.positions[:-1], self.velocities[:-1]))
