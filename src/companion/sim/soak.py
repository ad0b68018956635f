"""Soak test: a long episode of a randomly walking person among obstacles (docs/safety.md).

The person walks a random, seeded script of :class:`~companion.sim.person.Move` phases in a
walled square arena with scattered round pillars: straight walks and gentle curves at
0.5-1.5 m/s, stops of 0.5-3 s, sharp walking turns and turnarounds on the spot. The person
keeps ``person_margin`` from pillars and walls (a person walks around things too), which is
less than the robot needs on that side at 1 m, so the robot has to avoid pillars as well. The
robot runs the standard stack (supervisor, avoidance, controller) and is judged on collisions
with the person and the obstacles, non-finite values and its statuses.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from companion.geometry import obstacle_arrays, path_clearance
from companion.metrics import Entries, Running
from companion.params import Params
from companion.sim.person import Move, Row, ScriptedWalk, integrate_move
from companion.sim.runner import EpisodeSpec, run_one, stream_one
from companion.types import Circle, Log, Obstacle, Wall

#: Half the side of the square arena (m), centred on the origin.
ARENA = 15.0
#: Number of pillars and their radius range (m).
PILLARS = 14
PILLAR_RADIUS = (0.15, 0.5)
#: Walker's acceleration limit (m/s^2) and the grid its path is integrated on (s).
WALKER_ACCEL = 1.5
GRID = 0.02


@dataclass(frozen=True)
class SoakWorld:
    """The arena's obstacles and the person's script."""

    obstacles: tuple[Obstacle, ...]
    person: ScriptedWalk


@dataclass(frozen=True)
class Walker:
    """The mix of a random walker's phases: the share of each kind and the ranges (lo, hi)
    their durations (s), speeds (m/s) and turn rates (rad/s) are drawn from (a range with
    lo == hi is that value, drawing nothing). The defaults are the soak's walker; the
    closed-loop fuzz (:mod:`companion.sim.fuzz`) walks faster."""

    walk_share: float = 0.45
    stop_share: float = 0.2
    sharp_share: float = 0.2          # the rest: turnarounds on the spot
    walk_time: tuple[float, float] = (2.0, 8.0)
    walk_speed: tuple[float, float] = (0.5, 1.5)
    straight_share: float = 0.6       # of the walks; the others curve gently
    curve_rate: float = 0.4
    stop_time: tuple[float, float] = (0.5, 3.0)
    sharp_time: tuple[float, float] = (0.6, 1.2)
    sharp_speed: tuple[float, float] = (0.6, 0.6)
    sharp_rate: tuple[float, float] = (1.0, 2.0)
    turnaround_speed: tuple[float, float] = (1.0, 1.0)


def _draw(rng: np.random.Generator, span: tuple[float, float]) -> float:
    lo, hi = span
    return lo if lo == hi else float(rng.uniform(lo, hi))


def arena_walls(half: float = ARENA) -> tuple[Wall, ...]:
    a = half
    return (Wall(-a, -a, a, -a), Wall(a, -a, a, a), Wall(a, a, -a, a), Wall(-a, a, -a, -a))


def pillars(rng: np.random.Generator, keep_free: float = 3.0, count: int = PILLARS,
            half: float = ARENA, spacing: float = 3.0,
            keep_clear: tuple[tuple[float, float, float], ...] = ()) -> tuple[Circle, ...]:
    """``count`` round pillars at least ``spacing`` m apart and 2.5 m inside the walls, none
    centred within ``keep_free`` m of the origin (the start) or within ``r`` m of any (x, y, r)
    of ``keep_clear``; fewer if 100 draws per pillar find no room."""
    out: list[Circle] = []
    for _ in range(100 * count):
        if len(out) == count:
            break
        x, y = rng.uniform(-half + 2.5, half - 2.5, 2)
        r = float(rng.uniform(*PILLAR_RADIUS))
        if math.hypot(x, y) < keep_free or any(math.hypot(x - c.x, y - c.y) < spacing
                                               for c in out) \
                or any(math.hypot(x - px, y - py) < d for px, py, d in keep_clear):
            continue
        out.append(Circle(float(x), float(y), r))
    return tuple(out)


def _random_move(rng: np.random.Generator, w: Walker) -> list[Move]:
    r = rng.random()
    if r < w.walk_share:      # walk straight or along a gentle curve
        turn = 0.0 if rng.random() < w.straight_share else \
            float(rng.uniform(-w.curve_rate, w.curve_rate))
        return [Move(_draw(rng, w.walk_time), _draw(rng, w.walk_speed), turn)]
    if r < w.walk_share + w.stop_share:      # stop
        return [Move(_draw(rng, w.stop_time), 0.0)]
    if r < w.walk_share + w.stop_share + w.sharp_share:      # sharp walking turn
        sign = 1.0 if rng.random() < 0.5 else -1.0
        return [Move(_draw(rng, w.sharp_time), _draw(rng, w.sharp_speed),
                     sign * _draw(rng, w.sharp_rate))]
    sign = 1.0 if rng.random() < 0.5 else -1.0   # turnaround on the spot
    return [Move(1.0, 0.0), Move(1.0, 0.0, sign * math.pi),
            Move(3.0, _draw(rng, w.turnaround_speed))]


def _clear(rows: list[Row], obstacles: tuple[Obstacle, ...], margin: float) -> bool:
    x = np.array([r[0] for r in rows])
    y = np.array([r[1] for r in rows])
    return path_clearance(x, y, obstacle_arrays(obstacles), 0.0) >= margin


def random_walk(rng: np.random.Generator, duration: float, obstacles: tuple[Obstacle, ...],
                person_margin: float, walker: Walker = Walker(),
                start: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> ScriptedWalk:
    """A seeded random script of ``walker`` phases from ``start``, at least ``duration`` s
    long, whose path keeps ``person_margin`` from every obstacle: each drawn phase is tried
    out, together with stopping after it, and redrawn if it comes too close; when 50 draws
    fail the person stops and turns on the spot (safe: the last phase was checked with its
    stop)."""
    row: Row = (*start, 0.0, 0.0)
    moves: list[Move] = []
    t = 0.0
    while t < duration:
        for _ in range(50):
            cand = _random_move(rng, walker)
            rows, r = [], row
            for m in cand:
                rows += integrate_move(r, m, WALKER_ACCEL, GRID)
                r = rows[-1]
            stop = integrate_move(rows[-1], Move(1.5, 0.0), WALKER_ACCEL, GRID)
            if _clear(rows + stop, obstacles, person_margin):   # and it can still stop
                break
        else:
            cand = [Move(1.0, 0.0), Move(1.0, 0.0, float(rng.choice((-1.0, 1.0))) * 0.5 * math.pi)]
            rows, r = [], row
            for m in cand:
                rows += integrate_move(r, m, WALKER_ACCEL, GRID)
                r = rows[-1]
        moves += cand
        row = rows[-1]
        t += sum(m.duration for m in cand)
    return ScriptedWalk(start, moves, accel=WALKER_ACCEL, grid_step=GRID)


def make_world(seed: int, duration: float, person_margin: float = 1.2) -> SoakWorld:
    rng = np.random.default_rng(seed)
    obstacles = (*arena_walls(), *pillars(rng))
    return SoakWorld(obstacles, random_walk(rng, duration, obstacles, person_margin))


class Summary:
    """The soak's summary over consecutive blocks of its log (one block: the whole log):
    collisions, closest approaches, finiteness and time shares per status."""

    def __init__(self, params: Params):
        self.params = params
        self._metrics = Running()
        self._person_contacts = Entries()
        self._finite = True

    def add(self, log: Log) -> None:
        self._metrics.add(log)
        dist = np.hypot(log["robot_x"] - log["person_x"], log["robot_y"] - log["person_y"])
        self._person_contacts.add(dist < self.params.robot.radius
                                  + self.params.lidar.person_radius)
        self._finite = self._finite and all(
            bool(np.all(np.isfinite(a))) for c, a in log.columns.items()
            if c not in ("status", "reason", "rho_ob", "walker_gap_m", "plant_contact"))

    def value(self) -> dict:
        m = self._metrics.value()
        return {
            "duration_s": float(m["steps"] * self.params.dt),
            "steps": m["steps"],
            "finite": self._finite,
            "person_collisions": self._person_contacts.count,
            "min_person_distance_m": m["min_person_distance_m"],
            "obstacle_collisions": m["obstacle_collisions"],
            "min_obstacle_clearance_m": m["min_obstacle_clearance_m"],
            **{k: m[k] for k in ("share_ok", "share_degraded", "share_stopped")},
            "rmse_rho_m": m["rmse_rho_m"],
        }


def summarize(log: Log, params: Params) -> dict:
    """Collisions, closest approaches, finiteness and time shares per status."""
    return summarize_blocks([log], params)


def summarize_blocks(blocks: Iterable[Log], params: Params,
                     each: Callable[[Log], None] | None = None) -> dict:
    """:func:`summarize` over an episode's consecutive log blocks, as they come;
    ``each(block)`` too (to write the log as the episode runs)."""
    summary = Summary(params)
    for block in blocks:
        summary.add(block)
        if each is not None:
            each(block)
    return summary.value()


def spec_summary(spec: EpisodeSpec) -> dict:
    """Run the soak episode ``spec`` and summarise it block by block (bounded memory)."""
    return summarize_blocks(stream_one(spec), spec.params)


def soak_episode(duration: float, seed: int = 0, controller: str = "lqr",
                 params: Params | None = None) -> EpisodeSpec:
    """The episode of ``duration`` s in the soak world of ``seed``."""
    params = params or Params()
    world = make_world(seed, duration)
    return EpisodeSpec(controller, world.person, params, duration, seed=seed,
                       obstacles=world.obstacles)


def run_soak(duration: float, seed: int = 0, controller: str = "lqr",
             params: Params | None = None) -> tuple[dict, Log]:
    """Simulate ``duration`` s of the soak world of ``seed``; returns (summary, log)."""
    spec = soak_episode(duration, seed, controller, params)
    log = run_one(spec)
    return summarize(log, spec.params), log
