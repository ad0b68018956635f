"""Scenarios as TOML data files: the person's motion, the robot start, the controller and the
parameters of one episode. Built-in scenarios ship in ``companion/scenarios/``.

Example::

    name = "figure8"
    description = "8-shaped walk of Eq. (23), one lap in 60 s; robot on the right"
    duration = 60.0          # s
    controller = "lqr"
    seed = 0

    [person]                 # kind: line | circle | figure8 | ushape | segments | csv
    kind = "figure8"
    lap_time = 60.0

    [robot]
    start = [5.0, 2.0, 0.0]  # optional x (m), y (m), theta (rad); default: in the slot

    [params.formation]       # any Params field (docs/parameters.md)
    bearing = "right"        # or "auto": the side the robot starts on (needs robot.start)

    [[obstacles]]            # any number; kind: circle | wall
    kind = "circle"
    x = 5.1
    y = -1.8
    radius = 0.15
    influence = 0.4          # optional avoidance range (default radius / K_ob)

    [[obstacles]]
    kind = "wall"
    start = [0.0, 1.0]
    end = [10.0, 1.0]

    [[faults]]               # any number (companion.sim.faults): what goes wrong, when
    kind = "person_dropout"
    start = 12.0
    end = 13.5

``obstacle_source`` (top level) is "truth" (the controller knows the obstacles exactly) or
"lidar" (it sees what the simulated LiDAR detects). ``sensing`` (top level) is "ideal",
"realistic" or a ``[sensing]`` table (docs/sensing.md; missing keys: realistic; default ideal);
``plant`` is "kinematic" (default) or "mujoco" (the robot's base, docs/plants.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from companion.config import (
    MAX_DURATION,
    at_least,
    between,
    build,
    convert,
    hint,
    load_toml,
    param,
    positive,
    reject_unknown,
)
from companion.control import check_stack, lookup
from companion.errors import ConfigError
from companion.model import relative_state
from companion.params import LEFT, RIGHT, Params, params_from_mapping, sensing_params
from companion.sim.crowd import Crowd
from companion.sim.crowd_scenes import crowd_from
from companion.sim.faults import Fault, faults_from_list
from companion.sim.person import Figure8, PersonMotion, Segment, SegmentPath, circle, line, u_shape
from companion.sim.recorded import load_person_csv
from companion.sim.runner import EpisodeSpec, run_one
from companion.sim.sensing import check_source
from companion.types import Circle, Log, Obstacle, Pose, Wall

Triple = tuple[float, float, float]

#: What a walking (or jogging) person can do: speeds in m/s.
SPEED = between(0.0, 3.0, "m/s")
WALKING = between(0.01, 3.0, "m/s")
#: The largest seed: what a TOML integer holds.
MAX_SEED = 2**63 - 1
#: The shortest figure-8 lap (s): Eq. (23) moves 10 m per radian of phase at its fastest, so a
#: faster lap would make the person run beyond SPEED's 3 m/s.
FIGURE8_MIN_LAP = 2.0 * math.pi * 10.0 / 3.0


@dataclass(frozen=True)
class LineSpec:
    start: Triple = param((0.0, 0.0, 0.0), "m, m, rad", "start pose x, y, heading")
    speed: float = param(1.0, "m/s", "walking speed", WALKING)


@dataclass(frozen=True)
class CircleSpec:
    start: Triple = param((0.0, 0.0, 0.0), "m, m, rad", "start pose x, y, heading")
    radius: float = param(3.0, "m", "circle radius", at_least(0.2, "m"))
    speed: float = param(1.0, "m/s", "walking speed", WALKING)
    turn: str = param("left", "-", "turn direction", choices=("left", "right"))


@dataclass(frozen=True)
class Figure8Spec:
    lap_time: float = param(60.0, "s", "time for one lap of Eq. (23)",
                            at_least(FIGURE8_MIN_LAP, "s"))
    phase: float = param(0.0, "rad", "phase of Eq. (23) at t = 0 (0: at (5, 3) walking +x)")


@dataclass(frozen=True)
class UShapeSpec:
    start: Triple = param((0.0, 0.0, 0.0), "m, m, rad", "start pose x, y, heading")
    radius: float = param(2.0, "m", "radius of the half circle", at_least(0.2, "m"))
    turn: str = param("left", "-", "turn direction", choices=("left", "right"))


@dataclass(frozen=True)
class SegmentSpec:
    duration: float = param(1.0, "s", "segment duration", positive)
    v_start: float = param(1.0, "m/s", "speed at the segment start", SPEED)
    v_end: float = param(1.0, "m/s", "speed at the segment end", SPEED)
    curvature: float = param(0.0, "1/m", "signed curvature, positive turns left",
                             between(-10.0, 10.0, "1/m"))


@dataclass(frozen=True)
class SegmentsSpec:
    start: Triple = param((0.0, 0.0, 0.0), "m, m, rad", "start pose x, y, heading")
    segments: tuple[SegmentSpec, ...] = param((), "-", "the segments, in order")


@dataclass(frozen=True)
class CsvSpec:
    path: str = param("", "-", "CSV file with header t,x,y; relative to the scenario file")


@dataclass(frozen=True)
class CircleObstacleSpec:
    x: float = param(0.0, "m", "centre x")
    y: float = param(0.0, "m", "centre y")
    radius: float = param(0.15, "m", "radius", positive)
    influence: float | None = param(None, "m", "avoidance range rho_o (default r / K_ob)",
                                    positive)


@dataclass(frozen=True)
class WallSpec:
    start: tuple[float, float] = param((0.0, 0.0), "m", "one end (x, y)")
    end: tuple[float, float] = param((1.0, 0.0), "m", "other end (x, y)")
    influence: float | None = param(None, "m", "avoidance range rho_o (default "
                                    "avoidance.wall_influence)", positive)


OBSTACLE_KINDS: dict[str, type] = {"circle": CircleObstacleSpec, "wall": WallSpec}


def obstacles_from_list(items: Any, where: str) -> tuple[Obstacle, ...]:
    """Parse ``[[obstacles]]`` tables (``kind = "circle"`` or ``"wall"``)."""
    if not isinstance(items, list):
        raise ConfigError(f"{where}obstacles: expected a list of [[obstacles]] tables")
    out: list[Obstacle] = []
    for i, item in enumerate(items):
        name = f"{where}obstacles[{i}]"
        if not isinstance(item, Mapping):
            raise ConfigError(f"{name}: expected a table")
        kind = item.get("kind")
        if kind not in OBSTACLE_KINDS:
            raise ConfigError(f"{name}.kind: expected 'circle' or 'wall', got {kind!r}")
        spec = build(OBSTACLE_KINDS[kind], {k: v for k, v in item.items() if k != "kind"},
                     prefix=f"{name}.")
        if isinstance(spec, CircleObstacleSpec):
            out.append(Circle(spec.x, spec.y, spec.radius, spec.influence))
        else:
            if spec.start == spec.end:
                raise ConfigError(f"{name}: expected a wall of positive length")
            out.append(Wall(*spec.start, *spec.end, spec.influence))
    return tuple(out)


PERSON_KINDS: dict[str, type] = {"line": LineSpec, "circle": CircleSpec, "figure8": Figure8Spec,
                                 "ushape": UShapeSpec, "segments": SegmentsSpec, "csv": CsvSpec}


def make_person(spec: Any, base_dir: Path) -> PersonMotion:
    """The person motion described by a validated spec."""
    if isinstance(spec, LineSpec):
        return line(spec.start, spec.speed)
    if isinstance(spec, CircleSpec):
        return circle(spec.start, spec.radius, spec.speed, spec.turn)
    if isinstance(spec, Figure8Spec):
        return Figure8(spec.lap_time, spec.phase)
    if isinstance(spec, UShapeSpec):
        return u_shape(spec.start, spec.radius, spec.turn)
    if isinstance(spec, SegmentsSpec):
        return SegmentPath(spec.start, [Segment(s.duration, s.v_start, s.v_end, s.curvature)
                                        for s in spec.segments])
    if isinstance(spec, CsvSpec):
        return load_person_csv(base_dir / spec.path)
    raise TypeError(f"make_person: unknown spec {spec!r}")


def turn_rate(spec: Any) -> tuple[float, str]:
    """The fastest turn (rad/s) a person spec asks of the walker, and the keys and values that
    set it."""
    if isinstance(spec, CircleSpec):
        return spec.speed / spec.radius, (f"person.speed / person.radius: {spec.speed!r} m/s "
                                          f"on a radius of {spec.radius!r} m")
    if isinstance(spec, UShapeSpec):                      # u_shape turns at 0.6 m/s
        return 0.6 / spec.radius, f"person.radius: 0.6 m/s on a radius of {spec.radius!r} m"
    if isinstance(spec, SegmentsSpec):
        rates = [max(s.v_start, s.v_end) * abs(s.curvature) for s in spec.segments]
        i = max(range(len(rates)), key=rates.__getitem__)
        seg = spec.segments[i]
        return rates[i], (f"person.segments[{i}]: speed {max(seg.v_start, seg.v_end)!r} m/s "
                          f"at curvature {seg.curvature!r} 1/m")
    return 0.0, ""


def check_turn_rate(spec: Any, limit: float, where: str) -> None:
    """A walk that turns faster than ``tracker.max_person_turn_rate``: no person does, and
    the tracker would clip it."""
    rate, what = turn_rate(spec)
    if rate > limit:
        raise ConfigError(f"{where}{what} is a turn at {rate:.3g} rad/s, expected at most "
                          f"params.tracker.max_person_turn_rate ({limit:.3g} rad/s)")


def person_spec(mapping: Any, where: str) -> Any:
    """The validated spec of a ``[person]`` table."""
    if not isinstance(mapping, Mapping):
        raise ConfigError(f"{where}person: expected a table")
    kind = mapping.get("kind")
    if kind not in PERSON_KINDS:
        raise ConfigError(f"{where}person.kind: expected one of "
                          f"{', '.join(map(repr, PERSON_KINDS))}, got {kind!r}")
    rest = {k: v for k, v in mapping.items() if k != "kind"}
    spec = build(PERSON_KINDS[kind], rest, prefix=f"{where}person.")
    if isinstance(spec, SegmentsSpec) and not spec.segments:
        raise ConfigError(f"{where}person.segments: expected at least one [[person.segments]]")
    if isinstance(spec, CsvSpec) and not spec.path:
        raise ConfigError(f"{where}person.path: expected the path of a CSV file")
    return spec


@dataclass(frozen=True)
class Scenario:
    """One episode's set-up. ``start`` None means: start in the slot, aligned with the person."""

    name: str
    description: str
    duration: float
    seed: int
    controller: str
    person: PersonMotion
    start: Pose | None
    params: Params
    source: str
    obstacles: tuple[Obstacle, ...] = ()
    obstacle_source: str = "truth"
    faults: tuple[Fault, ...] = ()

    def episode(self, controller: str | None = None, obstacle_source: str | None = None
                ) -> EpisodeSpec:
        """This scenario as one episode of the runner, optionally with another controller or
        obstacle source."""
        return EpisodeSpec(controller or self.controller, self.person, self.params,
                           self.duration, start=self.start, seed=self.seed,
                           obstacles=self.obstacles,
                           obstacle_source=obstacle_source or self.obstacle_source,
                           faults=self.faults)


TOP_KEYS = ("name", "description", "duration", "seed", "controller", "obstacle_source",
            "sensing", "plant", "person", "crowd", "robot", "obstacles", "params", "faults")
def _resolve_auto_side(params_map: dict, start: Pose | None, person: PersonMotion,
                       where: str) -> dict:
    formation = params_map.get("formation")
    if not (isinstance(formation, Mapping) and formation.get("bearing") == "auto"):
        return params_map
    if start is None:
        raise ConfigError(f"{where}params.formation.bearing: 'auto' needs robot.start")
    h = person.state(0.0)
    d = params_map.get("robot", {}).get("d", Params().robot.d)
    _, alpha, _ = relative_state(start.x, start.y, start.theta, h.x, h.y, h.theta, d)
    formation = dict(formation, bearing=LEFT if alpha < math.pi else RIGHT)
    return dict(params_map, formation=formation)


def deep_merge(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` updated by ``over``, recursing into tables."""
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = deep_merge(out[k], v)
        else:
            out[k] = v
    return out


def scenario_from_mapping(data: Mapping[str, Any], source: str, base_dir: Path,
                          params_override: Mapping[str, Any] | None = None) -> Scenario:
    """Build a validated :class:`Scenario`; errors are prefixed with ``source``."""
    where = f"{source}: "
    reject_unknown(data, TOP_KEYS, where)
    name, description = data.get("name", Path(source).stem), data.get("description", "")
    for key, value in (("name", name), ("description", description)):
        if not isinstance(value, str):
            raise ConfigError(f"{where}{key}: expected a string, got {value!r}")
    duration = data.get("duration", 60.0)
    if isinstance(duration, bool) or not isinstance(duration, (int, float)) \
            or not 0.0 < duration <= MAX_DURATION:
        raise ConfigError(f"{where}duration: expected a number of seconds in (0, "
                          f"{MAX_DURATION:g}], got {duration!r}")
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise ConfigError(f"{where}seed: expected an integer in [0, 2**63 - 1], got {seed!r}")
    controller = data.get("controller", "lqr")
    if not isinstance(controller, str):
        raise ConfigError(f"{where}controller: expected a controller name, got {controller!r}")
    try:
        lookup(controller)
    except ConfigError as exc:
        raise ConfigError(f"{where}{exc}") from None
    if "crowd" in data and "person" in data:
        raise ConfigError(f"{where}person: a crowd scene walks its own person; expected "
                          f"[person] or [crowd], not both")
    if "person" not in data and "crowd" not in data:
        raise ConfigError(f"{where}person: missing table [person] (or [crowd])")
    spec = person_spec(data["person"], where) if "person" in data else None
    person: PersonMotion = make_person(spec, base_dir) if spec is not None \
        else crowd_from(data["crowd"], Params().dt, where)
    robot = data.get("robot", {})
    if not isinstance(robot, Mapping):
        raise ConfigError(f"{where}robot: expected a table")
    reject_unknown(robot, ("start",), f"{where}robot.")
    start = None
    if "start" in robot:
        start = Pose(*convert(robot["start"], Triple, f"{where}robot.start"))
    params_map = data.get("params", {})
    if not isinstance(params_map, Mapping):
        raise ConfigError(f"{where}params: expected a table")
    if "plant" in data:                  # the top-level key is params.plant.kind
        params_map = deep_merge(params_map, {"plant": {"kind": data["plant"]}})
    if params_override:
        params_map = deep_merge(params_map, params_override)
    params_map = _resolve_auto_side(dict(params_map), start, person, where)
    params = params_from_mapping(params_map, prefix=f"{where}params.")
    if "sensing" in data:
        sensing = sensing_params(data["sensing"], f"{where}sensing")
        try:
            params = params.replace(sensing=sensing)
        except ConfigError as exc:        # a check across sections
            raise ConfigError(f"{where}{exc}") from None
    check_stack(controller, params, f"{where}params.")   # LQR weights without a gain
    if spec is not None:
        check_turn_rate(spec, params.tracker.max_person_turn_rate, where)
    else:
        person = crowd_from(data["crowd"], params.dt, where)
    if duration < params.dt:
        raise ConfigError(f"{where}duration: expected at least one sample period "
                          f"(params.dt = {params.dt:g} s), got {duration!r}")
    obstacles = obstacles_from_list(data.get("obstacles", []), where)
    if isinstance(person, Crowd):
        obstacles += person.walls
    obstacle_source = check_source(data.get("obstacle_source", "truth"), where)
    faults = faults_from_list(data.get("faults", []), f"{where}faults")
    return Scenario(name, description, float(duration), seed, controller, person, start,
                    params, source, obstacles, obstacle_source, faults)


def builtin_names() -> list[str]:
    """Names of the scenarios shipped with the package."""
    folder = resources.files("companion") / "scenarios"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def builtin_path(name: str) -> Path:
    return Path(str(resources.files("companion") / "scenarios" / f"{name}.toml"))


def load_scenario(name_or_path: str, params_override: Mapping[str, Any] | None = None
                  ) -> Scenario:
    """Load a built-in scenario by name, or a TOML file by path."""
    path = Path(name_or_path)
    if path.suffix != ".toml" and len(path.parts) == 1:  # a bare name: a built-in scenario
        names = builtin_names()
        if name_or_path not in names:
            raise ConfigError(f"{name_or_path}: no built-in scenario of that name"
                              f"{hint(name_or_path, names)} (built-in: {', '.join(names)}; "
                              f"a scenario file must end in .toml)")
        path = builtin_path(name_or_path)
    return scenario_from_mapping(load_toml(path), str(path), path.parent, params_override)


def run_scenario(sc: Scenario, controller: str | None = None,
                 obstacle_source: str | None = None) -> Log:
    """Simulate a scenario (optionally with another controller or obstacle source)."""
    return run_one(sc.episode(controller, obstacle_source))
