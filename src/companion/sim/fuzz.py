"""Closed-loop fuzz: many short random episodes of the full stack, counted for safety
(docs/safety.md, "Closed-loop fuzzing").

Every episode is drawn from its own seed (:func:`draw`): a walled arena with up to
``MAX_PILLARS`` round pillars, a person who walks a random script of the soak's kinds of phase
but faster (up to 2 m/s, stops, sharp turns, turnarounds on the spot; :data:`WALKER`), a
formation 0.3-3 m away at any bearing, and a robot that starts at rest in its slot, or nearby
at rest or already moving. The controller and the sensing profile come with the episode's
index (:func:`plan`), so every pair gets the same share of the steps.
:func:`episode_counts` reduces an episode's log to counts; the definitions are in its
docstring and in docs/safety.md.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from companion.params import PROFILES, Params, SensingParams
from companion.sim.episode import TOLERANCE, start_in_slot
from companion.sim.escape import escapable
from companion.sim.runner import EpisodeSpec
from companion.sim.soak import PILLAR_RADIUS, Walker, arena_walls, pillars, random_walk
from companion.types import Log, Obstacle, PersonState, Pose

#: The fuzz walker: the soak's phases, up to 2 m/s, shorter walks and sharper turns.
WALKER = Walker(walk_time=(1.0, 6.0), walk_speed=(0.3, 2.0), sharp_speed=(0.3, 1.2),
                sharp_rate=(1.0, 2.5), turnaround_speed=(0.5, 2.0))
#: Half the side of the arena (m), the most pillars and their smallest spacing (m).
ARENA = 10.0
MAX_PILLARS = 16
SPACING = 2.5
#: Episode length (s), formation distance (m) and the person's margin to obstacles (m).
DURATION = (15.0, 60.0)
DISTANCE = (0.3, 3.0)
PERSON_MARGIN = (0.6, 1.5)
#: Robot starts away from the slot: within this distance of the person (m); velocity ranges.
START_RANGE = 4.0
START_V = (-0.5, 1.5)
START_OMEGA = (-1.0, 1.0)
#: Room (m) kept beyond the protective distance and obstacles at the start.
START_ROOM = 0.15
#: Episode seeds: run ``seed`` uses ``seed * SEED_STRIDE + i`` for its i-th episode.
SEED_STRIDE = 10_000_000
START_KINDS = ("slot", "rest", "moving")

#: The sensing profiles the fuzz runs unless told otherwise: the paper's setting and a leg
#: tracker (docs/safety.md).
FUZZ_PROFILES = {name: PROFILES[name] for name in ("ideal", "realistic")}


@dataclass(frozen=True)
class Case:
    """What an episode's seed drew (one row of fuzz.csv with its counts)."""

    seed: int
    controller: str
    sensing: str
    duration: float
    distance_drawn: float
    distance: float
    bearing: float
    start: str
    pillars: int
    person_margin: float


def feasible_distance(distance: float, bearing: float, params: Params, room: float = 0.01
                      ) -> float:
    """``distance`` or, if the slot at ``bearing`` would put the robot centre closer to the
    person than the protective distance or the comfort clearance (which :class:`Params`
    refuses), the smallest distance along that bearing that keeps ``room`` m beyond both."""
    need = max(params.keepout.protective_distance, params.keepout.person_clearance) + room
    d = params.robot.d
    # |R - d e| = need for R = D e(bearing): D^2 - 2 D d cos(b) + d^2 = need^2
    smallest = d * math.cos(bearing) + math.sqrt(need ** 2 - (d * math.sin(bearing)) ** 2)
    return max(distance, smallest)


def stopping_room(v: float, params: Params) -> float:
    """Distance (m) a robot at speed ``v`` covers before it stands: the reaction delay at
    ``v``, then braking at the deceleration limit."""
    delay = params.dt + params.sensing.actuator_tau_s + params.sensing.person_latency_s
    return abs(v) * delay + v * v / (2.0 * params.supervisor.decel_max)


def _start(rng: np.random.Generator, kind: str, params: Params
           ) -> tuple[Pose | None, tuple[float, float] | None, float]:
    """Robot start pose, velocity and the room (m) it needs to stop, for a person standing
    at the origin."""
    if kind == "slot":      # at rest: the slot's own velocity can exceed the robot's limits
        return None, (0.0, 0.0), 0.0
    v = float(rng.uniform(*START_V)) if kind == "moving" else 0.0
    w = float(rng.uniform(*START_OMEGA)) if kind == "moving" else 0.0
    room = stopping_room(v, params) + START_ROOM
    near = params.keepout.protective_distance + room
    r = float(rng.uniform(near, max(near, START_RANGE)))
    phi, heading = rng.uniform(-math.pi, math.pi, 2)
    return Pose(r * math.cos(phi), r * math.sin(phi), float(heading)), (v, w), room


def draw(seed: int, controller: str, sensing: str, base: Params | None = None,
         profiles: Mapping[str, SensingParams] = PROFILES) -> tuple[Case, EpisodeSpec]:
    """The episode of ``seed`` for ``controller`` and ``sensing`` (a name of ``profiles``):
    the world and the walk depend on the seed alone, so a seed can be replayed with any
    pair."""
    base = base or Params()
    rng = np.random.default_rng(seed)
    duration = _steps(rng, base.dt) * base.dt
    drawn = float(rng.uniform(*DISTANCE))
    bearing = float(rng.uniform(0.0, 2.0 * math.pi))
    distance = feasible_distance(drawn, bearing, base)
    params = base.replace(formation=dataclasses.replace(base.formation, distance=distance,
                                                        bearing=bearing),
                          sensing=profiles[sensing])   # the base's formation policy stays
    heading = float(rng.uniform(-math.pi, math.pi))
    kind = START_KINDS[int(rng.integers(len(START_KINDS)))]
    start, velocity, room = _start(rng, kind, params)
    margin = float(rng.uniform(*PERSON_MARGIN))
    robot = start or start_in_slot(PersonState(0.0, 0.0, heading, 0.0, 0.0), params)
    keep = max(PILLAR_RADIUS)
    clear = ((0.0, 0.0, margin + keep + 0.3),
             (robot.x, robot.y, params.robot.radius + keep + room + START_ROOM))
    obstacles = (*arena_walls(ARENA),
                 *pillars(rng, keep_free=0.0, count=int(rng.integers(MAX_PILLARS + 1)),
                          half=ARENA, spacing=SPACING, keep_clear=clear))
    person = random_walk(rng, duration, obstacles, margin, WALKER, start=(0.0, 0.0, heading))
    case = Case(seed, controller, sensing, duration, drawn, distance, bearing, kind,
                len(obstacles) - 4, margin)
    spec = EpisodeSpec(controller, person, params, duration, start=start, seed=seed,
                       obstacles=obstacles, start_velocity=velocity)
    return case, spec


def _steps(rng: np.random.Generator, dt: float) -> int:
    """The episode's length in steps: the first draw of its seed."""
    return round(float(rng.uniform(*DURATION)) / dt)


def plan(steps: int, seed: int, controllers: Sequence[str], sensings: Sequence[str],
         dt: float = Params().dt) -> list[tuple[int, str, str]]:
    """(seed, controller, sensing) of the episodes of a run: episode ``i`` has seed
    ``seed * SEED_STRIDE + i`` and the ``i``-th pair in turn, until at least ``steps``
    steps."""
    pairs = [(c, s) for s in sensings for c in controllers]
    out, total, i = [], 0, 0
    while total < steps:
        s = seed * SEED_STRIDE + i
        total += _steps(np.random.default_rng(s), dt)
        out.append((s, *pairs[i % len(pairs)]))
        i += 1
    return out


#: Keys of :func:`episode_counts`, in the order of fuzz.csv.
COUNTS = ("steps", "person_collisions", "person_collisions_robot",
          "person_collisions_unescapable", "obstacle_collisions", "protective_steps",
          "violations", "violations_estimate", "violations_walkthrough", "nonfinite_steps",
          "ok_steps", "degraded_steps", "stopped_steps", "min_person_distance_m",
          "min_obstacle_clearance_m")
_STATE = ("t", "robot_x", "robot_y", "robot_theta", "person_x", "person_y", "v", "omega",
          "robot_v", "robot_omega")


def own_closing(x: np.ndarray, y: np.ndarray, px: np.ndarray, py: np.ndarray,
                dt: float) -> np.ndarray:
    """Speed (m/s) at which the robot's own motion over each step, from (x[k], y[k]) to
    (x[k+1], y[k+1]), brings it closer to the point (px[k], py[k]) held still; the last step
    has none (0). Positive: closer."""
    out = np.zeros(len(x))
    before = np.hypot(px[:-1] - x[:-1], py[:-1] - y[:-1])
    after = np.hypot(px[:-1] - x[1:], py[:-1] - y[1:])
    out[:-1] = (before - after) / dt
    return out


def _entries(flag: np.ndarray) -> np.ndarray:
    """Where ``flag`` becomes true (its first element: if it starts true)."""
    return flag & ~np.concatenate(([False], flag[:-1]))


def robot_caused(entries: np.ndarray, own: np.ndarray) -> np.ndarray:
    """Which of the ``entries`` (into contact) came with the robot's own motion over the
    step that ended in them closing on the person faster than :data:`TOLERANCE` m/s
    (``own``: :func:`own_closing` per step); an entry at the first sample has no such step
    and counts as the person's."""
    into = np.zeros(len(own), dtype=bool)
    into[1:] = own[:-1] > TOLERANCE
    return entries & into


def walkthroughs(entries: np.ndarray, dist: np.ndarray, zone: float) -> np.ndarray:
    """Steps from each of the ``entries`` (contacts the person caused) until the person is
    again ``zone`` or more away (``dist``: robot centre to person per step)."""
    out = np.zeros(len(dist), dtype=bool)
    outside = np.flatnonzero(dist >= zone)
    for k in np.flatnonzero(entries):
        later = outside[outside > k]
        out[k:later[0] if len(later) else len(dist)] = True
    return out


def episode_counts(log: Log, params: Params, obstacles: Sequence[Obstacle] = ()) -> dict:
    """Safety counts of one fuzz episode, against the TRUE person and obstacles.

    * ``person_collisions``: entries into contact, robot centre closer to the person than
      ``robot.radius + lidar.person_radius`` (whoever moved);
    * ``person_collisions_robot``: the robot-caused ones among them: the robot's own motion
      over the step into contact closed on the person (:func:`robot_caused`); the others are
      the person's doing (it walked into a robot that stood, moved away or sideways);
    * ``person_collisions_unescapable``: of the person's, those that no constant command
      could have escaped even knowing the person's path (:func:`companion.sim.escape.escapable`,
      with the episode's ``obstacles``);
    * ``obstacle_collisions``: entries into footprint-obstacle overlap (clearance <= 0);
    * ``protective_steps``: steps with the robot centre inside
      ``keepout.protective_distance`` of the person (whoever moved);
    * ``violations``: the robot-caused ones among them: the robot's own motion over the step
      (:func:`own_closing`, the person held where it is) brings it closer than
      :data:`TOLERANCE` m/s times dt, outside the walk-throughs below;
    * ``violations_estimate``: of those, the steps that are not violations against the
      tracker's estimate (outside the protective distance of the estimate, or not closing on
      it): the supervisor acted on a wrong estimate;
    * ``violations_walkthrough``: such steps during a contact the person caused, until the
      person is out of the protective distance again (:func:`walkthroughs`): the walker does
      not see the robot and walks through its body, so which way is "towards the person"
      turns over within a few steps; counted apart, not as violations;
    * ``nonfinite_steps``: steps with a non-finite state, command or velocity;
    * ``ok_steps``, ``degraded_steps``, ``stopped_steps``: the supervisor's status.
    """
    x, y, px, py = log["robot_x"], log["robot_y"], log["person_x"], log["person_y"]
    dist = np.hypot(px - x, py - y)
    zone = params.keepout.protective_distance
    own = own_closing(x, y, px, py, params.dt)
    contact = _entries(dist < params.robot.radius + params.lidar.person_radius)
    by_robot = robot_caused(contact, own)
    by_person = np.flatnonzero(contact & ~by_robot)
    through = walkthroughs(contact & ~by_robot, dist, zone)
    robot = (dist < zone) & (own > TOLERANCE)
    ex, ey = log["person_est_x"], log["person_est_y"]
    est_robot = (np.hypot(ex - x, ey - y) < zone) & \
        (own_closing(x, y, ex, ey, params.dt) > TOLERANCE)
    finite = np.ones(len(log), dtype=bool)
    for c in _STATE:
        finite &= np.isfinite(log[c])
    clearance = log["rho_ob"]
    status = log["status"]
    return {
        "steps": len(log),
        "person_collisions": int(np.count_nonzero(contact)),
        "person_collisions_robot": int(np.count_nonzero(by_robot)),
        "person_collisions_unescapable": sum(not escapable(log, int(k), params, obstacles)
                                             for k in by_person),
        "obstacle_collisions": int(np.count_nonzero(_entries(clearance <= 0.0))),
        "protective_steps": int(np.count_nonzero(dist < zone)),
        "violations": int(np.count_nonzero(robot & ~through)),
        "violations_estimate": int(np.count_nonzero(robot & ~through & ~est_robot)),
        "violations_walkthrough": int(np.count_nonzero(robot & through)),
        "nonfinite_steps": int(np.count_nonzero(~finite)),
        "ok_steps": int(np.count_nonzero(status == "ok")),
        "degraded_steps": int(np.count_nonzero(status == "degraded")),
        "stopped_steps": int(np.count_nonzero(status == "stopped")),
        "min_person_distance_m": float(np.nanmin(dist)) if len(dist) else math.nan,
        "min_obstacle_clearance_m": float(np.nanmin(clearance))
        if np.any(np.isfinite(clearance)) else math.nan,
    }


def spec_counts(log: Log, spec: EpisodeSpec, params: Params) -> dict:
    """:func:`episode_counts` of an episode with its obstacles (the fuzz's row function,
    :func:`companion.evaluate.fuzz_runs.counts`); ``params`` gives the thresholds."""
    return episode_counts(log, params, spec.obstacles)


def failed(counts: dict) -> bool:
    """True for an episode with a collision, a robot-caused violation or a non-finite value."""
    return bool(counts["person_collisions"] or counts["obstacle_collisions"]
                or counts["violations"] or counts["nonfinite_steps"])


def robot_failed(counts: dict) -> bool:
    """True for an episode in which the robot failed by its own doing: a robot-caused
    collision or protective violation, an obstacle collision or a non-finite value (contacts
    the person caused aside)."""
    return bool(counts["person_collisions_robot"] or counts["obstacle_collisions"]
                or counts["violations"] or counts["nonfinite_steps"])


def totals(rows: Sequence[dict]) -> dict:
    """Sums of the counts over ``rows`` (minima for the distances), the episode count and the
    numbers of :func:`failed` and :func:`robot_failed` episodes."""
    out: dict = {"episodes": len(rows)}
    for key in COUNTS:
        values = [r[key] for r in rows]
        out[key] = (min(values, default=math.nan) if key.startswith("min_")
                    else int(sum(values)))
    out["failed_episodes"] = sum(failed(r) for r in rows)
    out["robot_failed_episodes"] = sum(robot_failed(r) for r in rows)
    return out
