"""An evaluation suite: a TOML file naming the factors of a set of episodes, and the episodes
it expands to (docs/evaluation.md gives the format).

Every combination of person motion, side, sensing profile, controller and seed is one
:class:`Episode`. Episodes that differ only in the controller share their seed, so their
person detections and LiDAR noise are the same (:func:`companion.sim.sensing.streams`) and
they can be compared in pairs. Errors name the suite file and the key.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.config import load_toml, reject_unknown
from companion.control import CONTROLLERS
from companion.data import pedestrians
from companion.errors import ConfigError
from companion.params import SIDES, Params, load_sensing, params_from_mapping
from companion.sim.faults import faults_from_list
from companion.sim.recorded import RecordedPerson, load_person_csv
from companion.sim.runner import EpisodeSpec
from companion.sim.scenario import builtin_path, load_scenario
from companion.sim.sensing import OBSTACLE_SOURCES

TOP = ("name", "description", "reference", "seeds", "controllers", "sensing", "sides",
       "obstacles", "duration", "motions", "faults")
MOTIONS = ("scenarios", "tracks", "every", "offset", "min_mean_speed", "min_duration")
CONTROLLER = ("name", "params", "label")
#: The shipped walking tracks, by name.
SHIPPED_TRACKS = "eth_ucy"


@dataclass(frozen=True)
class Episode:
    """One episode of a suite: its factors (``motion``, ``group``: the scenario's name or
    ``tracks``, ``side``, ``sensing``, ``controller``, ``seed``) and its spec."""

    motion: str
    group: str
    side: str
    sensing: str
    controller: str
    seed: int
    spec: EpisodeSpec

    @property
    def key(self) -> str:
        """Unique within the suite; the same for every controller of a pair but the name."""
        return ":".join((self.motion, self.side, self.sensing, self.controller, str(self.seed)))

    @property
    def pair(self) -> str:
        """What the controllers of a paired comparison share."""
        return ":".join((self.motion, self.side, self.sensing, str(self.seed)))

    @property
    def factors(self) -> dict[str, Any]:
        return {"motion": self.motion, "group": self.group, "side": self.side,
                "sensing": self.sensing, "controller": self.controller, "seed": self.seed}


@dataclass(frozen=True)
class Suite:
    """A parsed suite file: its name, reference controller, episodes and a digest of every
    file it read, scenarios and tracks included (a changed file invalidates kept results; a
    changed companion does not: give an updated companion a new output folder)."""

    name: str
    description: str
    reference: str
    episodes: tuple[Episode, ...]
    digest: str


def load_suite(path: str | Path) -> Suite:
    """Parse and expand the suite file at ``path``."""
    path = Path(path)
    data = load_toml(path)
    where = f"{path}: "
    reject_unknown(data, TOP, where)
    digest = hashlib.sha256(path.read_bytes())
    controllers = _controllers(data.get("controllers", ["lqr"]), path, digest)
    labels = [c[0] for c in controllers]
    reference = data.get("reference", labels[0])
    if reference not in labels:
        raise ConfigError(f"{where}reference: expected one of the controllers "
                          f"({', '.join(labels)}), got {reference!r}")
    sensing = []
    for i, s in enumerate(_list(data.get("sensing", ["realistic"]), f"{where}sensing")):
        name = _sensing_name(s, path, i)
        try:
            sensing.append((Path(name).stem, load_sensing(_resolve(name, path))))
        except ConfigError as exc:
            raise ConfigError(f"{where}sensing[{i}]: {exc}") from None
        if name.endswith(".toml"):
            digest.update(Path(_resolve(name, path)).read_bytes())
    sides = [_side(s, f"{where}sides[{i}]")
             for i, s in enumerate(_list(data.get("sides", ["left"]), f"{where}sides"))]
    seeds = _seeds(data.get("seeds", 1), f"{where}seeds")
    obstacles = data.get("obstacles")
    if obstacles is not None and obstacles not in OBSTACLE_SOURCES:
        raise ConfigError(f"{where}obstacles: expected one of {', '.join(OBSTACLE_SOURCES)}, "
                          f"got {obstacles!r}")
    duration = data.get("duration")
    if duration is not None and (isinstance(duration, bool)
                                 or not isinstance(duration, (int, float)) or duration <= 0):
        raise ConfigError(f"{where}duration: expected a positive number of seconds, got "
                          f"{duration!r}")
    faults = faults_from_list(data["faults"], f"{where}faults") if "faults" in data else ()
    motions = _motions(data.get("motions", {"scenarios": ["figure8"]}), path, digest)
    episodes = []
    final: dict[tuple, Params] = {}     # validated once per group, controller, side, sensing
    for m, (motion, group, base, build) in enumerate(motions):
        for side_name, bearing in sides:
            for sensing_name, sensing_params in sensing:
                for seed in seeds:
                    episode_seed = _episode_seed(seed, m)
                    for label, name, overrides in controllers:
                        key = (group, label, side_name, sensing_name)
                        if key not in final:
                            p = base(label, overrides)
                            final[key] = p.replace(
                                sensing=sensing_params,
                                formation=dataclasses.replace(p.formation, bearing=bearing))
                        spec = build(label, overrides, name)
                        spec = dataclasses.replace(
                            spec, params=final[key], seed=episode_seed,
                            duration=min(spec.duration, duration or math.inf),
                            obstacle_source=obstacles or spec.obstacle_source,
                            faults=spec.faults + tuple(faults))
                        episodes.append(Episode(motion, group, side_name, sensing_name, label,
                                                seed, spec))
    keys = [e.key for e in episodes]
    if len(set(keys)) != len(keys):
        twice = next(k for k in keys if keys.count(k) > 1)
        raise ConfigError(f"{where}two episodes would be {twice!r}: a motion, side or sensing "
                          f"named twice, or two files of one name")
    return Suite(str(data.get("name", path.stem)), str(data.get("description", "")), reference,
                 tuple(episodes), digest.hexdigest())


def track_episode(person: RecordedPerson, params: Params, controller: str = "lqr",
                  side: str = "left", seed: int = 0) -> EpisodeSpec:
    """A recorded walker (not observed in its holes) with the robot starting in its slot on
    ``side``, for the recording's duration."""
    params = params.replace(formation=dataclasses.replace(params.formation,
                                                          bearing=SIDES[side]))
    return EpisodeSpec(controller, person, params, person.duration, seed=seed)


def _episode_seed(seed: int, motion: int) -> int:
    """The noise seed of every episode of ``seed`` on motion number ``motion``: the same for
    every controller and side, different for every motion."""
    state = np.random.SeedSequence((seed, motion)).generate_state(2, dtype=np.uint64)
    return int(state[0]) % 2 ** 63


def _controllers(items: Any, path: Path, digest: Any) -> list[tuple[str, str, dict]]:
    """(label, controller name, parameter overrides) per controller entry."""
    where = f"{path}: controllers"
    out = []
    for i, item in enumerate(_list(items, where)):
        at = f"{where}[{i}]"
        if isinstance(item, str):
            item = {"name": item}
        if not isinstance(item, Mapping):
            raise ConfigError(f"{at}: expected a controller name or a table with name, params "
                              f"and label")
        reject_unknown(item, CONTROLLER, f"{at}.")
        name = item.get("name")
        if name not in CONTROLLERS:
            raise ConfigError(f"{at}.name: expected one of {', '.join(CONTROLLERS)}, got "
                              f"{name!r}")
        overrides: dict = {}
        if "params" in item:
            file = _resolve(item["params"], path)
            try:
                overrides = load_toml(file)
                params_from_mapping(overrides, prefix=f"{file}: ")   # errors name the file
            except ConfigError as exc:
                raise ConfigError(f"{at}.params: {exc}") from None
            digest.update(Path(file).read_bytes())
        label = str(item.get("label", name if "params" not in item
                             else f"{name}+{Path(item['params']).stem}"))
        out.append((label, name, overrides))
    labels = [c[0] for c in out]
    if len(set(labels)) != len(labels):
        raise ConfigError(f"{where}: expected distinct labels, got {', '.join(labels)}")
    if not out:
        raise ConfigError(f"{where}: expected at least one controller")
    return out


def _motions(data: Any, path: Path, digest: Any) -> list[tuple[str, str, Any, Any]]:
    """Per person motion: its name, its group, ``base(label, overrides) -> Params`` (the
    motion's parameters with a controller's overrides) and ``build(label, overrides,
    controller) -> EpisodeSpec``."""
    where = f"{path}: motions"
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where}: expected a table with scenarios and/or tracks")
    reject_unknown(data, MOTIONS, f"{where}.")
    out: list[tuple[str, str, Any, Any]] = []
    scenarios = data.get("scenarios", []) and _list(data["scenarios"], f"{where}.scenarios")
    for i, name in enumerate(scenarios):
        scenario = _resolve(name, path) if str(name).endswith(".toml") else str(name)
        try:
            load_scenario(scenario)                       # its errors name the scenario
        except ConfigError as exc:
            raise ConfigError(f"{where}.scenarios[{i}]: {exc}") from None
        file = Path(scenario) if scenario.endswith(".toml") else builtin_path(scenario)
        digest.update(file.read_bytes())
        cache: dict[str, Any] = {}     # the scenario with a controller's overrides, by label

        def loaded(label: str, over: dict, scenario: str = scenario, cache: dict = cache):
            if label not in cache:
                cache[label] = load_scenario(scenario, params_override=over or None)
            return cache[label]

        def base(label: str, over: dict, loaded=loaded) -> Params:
            return loaded(label, over).params

        def build(label: str, over: dict, controller: str, loaded=loaded) -> EpisodeSpec:
            return loaded(label, over).episode(controller)

        out.append((Path(str(name)).stem, Path(str(name)).stem, base, build))
    tracks = data.get("tracks")
    if tracks is not None:
        every = _count(data.get("every", 1), f"{where}.every")
        offset = data.get("offset", 0)
        if isinstance(offset, bool) or not isinstance(offset, int) or not 0 <= offset < every:
            raise ConfigError(f"{where}.offset: expected an integer in [0, every), got "
                              f"{offset!r}")

        def track_base(label: str, over: dict) -> Params:
            return params_from_mapping(over)

        for label, person in _tracks(tracks, data, path, digest)[offset::every]:
            def track_build(label: str, over: dict, controller: str,
                            person=person) -> EpisodeSpec:
                return EpisodeSpec(controller, person, Params(), person.duration)
            out.append((label, "tracks", track_base, track_build))
    if not out:
        raise ConfigError(f"{where}: expected at least one scenario or track")
    return out


def _tracks(tracks: Any, data: Mapping, path: Path, digest: Any
            ) -> list[tuple[str, RecordedPerson]]:
    """The named tracks (their data added to ``digest``)."""
    where = f"{path}: motions.tracks"
    if tracks == SHIPPED_TRACKS:
        chosen = pedestrians.select_tracks(
            pedestrians.load_scenes(), _number(data.get("min_mean_speed", 0.6),
                                               f"{path}: motions.min_mean_speed"),
            _number(data.get("min_duration", 15.0), f"{path}: motions.min_duration"))
        for tr in chosen:
            digest.update(np.asarray((tr.t, tr.x, tr.y), dtype=float).tobytes())
        return [(f"{tr.scene}/{tr.ped_id}", RecordedPerson(tr.t, tr.x, tr.y)) for tr in chosen]
    if not isinstance(tracks, str):
        raise ConfigError(f"{where}: expected {SHIPPED_TRACKS!r} or a folder of t,x,y CSV "
                          f"files, got {tracks!r}")
    folder = Path(_resolve(tracks, path))
    files = sorted(folder.glob("*.csv")) if folder.is_dir() else []
    if not files:
        raise ConfigError(f"{where}: expected {SHIPPED_TRACKS!r} or a folder of t,x,y CSV "
                          f"files, got {tracks!r} (no CSV files there)")
    for f in files:
        digest.update(f.read_bytes())
    return [(f.stem, load_person_csv(f)) for f in files]


def _resolve(name: Any, path: Path) -> str:
    """A file named in the suite, relative to the suite's folder; other values as given."""
    name = str(name)
    if name.endswith(".toml") or "/" in name:
        candidate = path.parent / name
        return str(candidate) if candidate.exists() or not Path(name).exists() else name
    return name


def _sensing_name(value: Any, path: Path, i: int) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{path}: sensing[{i}]: expected a profile name or a .toml file, got "
                          f"{value!r}")
    return value


def _side(value: Any, where: str) -> tuple[str, float]:
    if isinstance(value, str):
        if value not in SIDES:
            raise ConfigError(f"{where}: expected one of {', '.join(SIDES)} or a bearing in "
                              f"rad, got {value!r}")
        return value, SIDES[value]
    return f"{_number(value, where):.4f}", float(value)


def _seeds(value: Any, where: str) -> list[int]:
    if isinstance(value, int) and not isinstance(value, bool):
        return list(range(_count(value, where)))
    seeds = _list(value, where)
    for i, s in enumerate(seeds):
        if isinstance(s, bool) or not isinstance(s, int) or s < 0:
            raise ConfigError(f"{where}[{i}]: expected a seed >= 0, got {s!r}")
    return list(dict.fromkeys(seeds))


def _list(value: Any, where: str) -> Sequence:
    if isinstance(value, (str, Mapping)) or not isinstance(value, (list, tuple)) or not value:
        raise ConfigError(f"{where}: expected a non-empty list, got {value!r}")
    return value


def _count(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(f"{where}: expected an integer >= 1, got {value!r}")
    return value


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    return float(value)
