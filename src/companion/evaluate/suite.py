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
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from companion.config import MAX_DURATION, build, hint, load_toml, reject_unknown
from companion.control import CONTROLLERS, make_controller
from companion.errors import ConfigError
from companion.evaluate.motions import fixed_sides, motions
from companion.evaluate.rows import Criterion, criteria_from, summary_row
from companion.params import (
    PLANTS,
    SIDES,
    Formation,
    Params,
    SensingParams,
    load_sensing,
    params_from_mapping,
)
from companion.sim.faults import faults_from_list
from companion.sim.recorded import RecordedPerson
from companion.sim.runner import EpisodeSpec
from companion.sim.sensing import OBSTACLE_SOURCES

TOP = ("name", "description", "reference", "seeds", "controllers", "sensing", "plants",
       "sides", "obstacles", "duration", "motions", "faults", "criteria")
CONTROLLER = ("name", "params", "label")
#: The suites shipped with companion (``companion evaluate NAME``).
BUILTIN = Path(__file__).resolve().parent.parent / "suites"
#: The most episodes a suite may expand to (the largest shipped one has 5,832): beyond it a
#: number is a typo, and the expansion alone would fill the memory.
MAX_EPISODES = 100_000


@dataclass(frozen=True)
class Episode:
    """One episode of a suite: its factors (``motion``, ``group``: the scenario's name or
    ``tracks``, ``side``, ``sensing``: the profile's label, ``/PLANT`` added where the suite
    names ``plants``, ``controller``, ``seed``) and its spec (``plant``: its plant's kind)."""

    motion: str
    group: str
    side: str
    sensing: str
    controller: str
    seed: int
    spec: EpisodeSpec

    @property
    def plant(self) -> str:
        return self.spec.params.plant.kind

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
                "sensing": self.sensing, "controller": self.controller, "seed": self.seed,
                "plant": self.plant}


@dataclass(frozen=True)
class Suite:
    """A parsed suite file (or a suite generator's suite,
    :mod:`companion.evaluate.generators`): its name, reference controller, episodes and a
    digest of every file it read, scenarios and tracks included (a changed file invalidates
    kept results, as does a changed companion: :func:`companion.evaluate.run.code_digest`).
    ``row``: what an episode gives, a module-level function of its spec (or a partial of
    one, its arguments part of the digest) run in the worker; by default its row of
    numbers."""

    name: str
    description: str
    reference: str
    episodes: tuple[Episode, ...]
    digest: str
    criteria: tuple[Criterion, ...] = ()
    row: Callable[[EpisodeSpec], Any] = summary_row


def builtin_suites() -> list[str]:
    """The names of the shipped suites."""
    return sorted(p.stem for p in BUILTIN.glob("*.toml"))


def suite_path(name: str | Path) -> Path:
    """A suite file, or a shipped suite by name (``pedestrians``)."""
    if str(name) in builtin_suites():
        return BUILTIN / f"{name}.toml"
    path = Path(name)
    if not path.exists() and path.suffix != ".toml" and len(path.parts) == 1:
        raise ConfigError(f"{name}: no such suite file or shipped suite"
                          f"{hint(str(name), builtin_suites())} (shipped: "
                          f"{', '.join(builtin_suites())})")
    return path


def load_suite(name: str | Path) -> Suite:
    """Parse and expand the suite file at ``name`` (or the shipped suite of that name)."""
    path = suite_path(name)
    data = load_toml(path)
    return suite_from_mapping(data, path, hashlib.sha256(path.read_bytes()))


def suite_from_mapping(data: Mapping[str, Any], path: Path, digest: Any = None) -> Suite:
    """Expand a parsed suite; ``path`` names it in errors and anchors its relative files
    (a command line's suite: a name whose folder is the working one). ``digest``: a
    hashlib object already fed with the file, else one fed with ``data``."""
    where = f"{path}: "
    reject_unknown(data, TOP, where)
    for key in ("name", "description"):
        if not isinstance(data.get(key, ""), str):
            raise ConfigError(f"{where}{key}: expected a string, got {data[key]!r}")
    if digest is None:
        digest = hashlib.sha256(repr(sorted(data.items())).encode())
    controllers = _controllers(data.get("controllers", ["lqr"]), path, digest)
    labels = [c[0] for c in controllers]
    reference = data.get("reference", labels[0])
    if reference not in labels:
        raise ConfigError(f"{where}reference: expected one of the controllers "
                          f"({', '.join(labels)}), got {reference!r}")
    sensing = [_sensing(s, path, i, digest) for i, s
               in enumerate(_list(data.get("sensing", ["realistic"]), f"{where}sensing"))]
    sides = [_side(s, f"{where}sides[{i}]")
             for i, s in enumerate(_list(data.get("sides", ["left"]), f"{where}sides"))]
    plants = _plants(data.get("plants"), f"{where}plants")
    seeds = _seeds(data.get("seeds", 1), f"{where}seeds")
    obstacles = data.get("obstacles")
    if obstacles is not None and obstacles not in OBSTACLE_SOURCES:
        raise ConfigError(f"{where}obstacles: expected one of {', '.join(OBSTACLE_SOURCES)}, "
                          f"got {obstacles!r}")
    duration = data.get("duration")
    if duration is not None and (isinstance(duration, bool)
                                 or not isinstance(duration, (int, float))
                                 or not 0.0 < duration <= MAX_DURATION):
        raise ConfigError(f"{where}duration: expected a number of seconds in (0, "
                          f"{MAX_DURATION:g}], got {duration!r}")
    faults = faults_from_list(data["faults"], f"{where}faults") if "faults" in data else ()
    criteria = criteria_from(data["criteria"], f"{where}criteria") if "criteria" in data else ()
    moves = motions(data.get("motions", {"scenarios": ["figure8"]}), path, digest, _resolve)
    total = sum(len(fixed_sides(m, sides)) for m in moves) * len(sensing) * len(plants) \
        * len(seeds) * len(controllers)
    if total > MAX_EPISODES:
        raise ConfigError(f"{where}expected at most {MAX_EPISODES} episodes, got {total} "
                          f"(motions x sides x sensing x plants x seeds x controllers)")
    episodes = []
    final: dict[tuple, Params] = {}     # validated once per group, controller, side, sensing
    for m, motion in enumerate(moves):
        group, base, build = motion.group, motion.base, motion.build
        for side_name, bearing in fixed_sides(motion, sides):
            for (sensing_name, sensing_params), plant in itertools.product(sensing, plants):
                label_s = sensing_name if plant is None else f"{sensing_name}/{plant}"
                for seed in seeds:
                    episode_seed = _episode_seed(seed, m)
                    for label, name, overrides in controllers:
                        key = (group if motion.shared else motion.name, label, side_name,
                               label_s)
                        if key not in final:
                            final[key] = _final(partial(base, label, overrides), name, bearing,
                                                sensing_params, plant,
                                                _factors(where, sides, side_name, sensing,
                                                         sensing_name, controllers, label))
                        if duration is not None and duration < final[key].dt:
                            raise ConfigError(f"{where}duration: expected at least one sample "
                                              f"period (params.dt = {final[key].dt:g} s), got "
                                              f"{duration!r}")
                        spec = build(label, overrides, name)
                        spec = dataclasses.replace(
                            spec, params=final[key], seed=episode_seed,
                            duration=min(spec.duration, duration or math.inf),
                            obstacle_source=obstacles or spec.obstacle_source,
                            faults=spec.faults + tuple(faults))
                        episodes.append(Episode(motion.name, group, side_name, label_s, label,
                                                seed, spec))
    keys = [e.key for e in episodes]
    if len(set(keys)) != len(keys):
        twice = next(k for k in keys if keys.count(k) > 1)
        raise ConfigError(f"{where}two episodes would be {twice!r}: a motion, side or sensing "
                          f"named twice, or two files of one name")
    return Suite(str(data.get("name", path.stem)), str(data.get("description", "")), reference,
                 tuple(episodes), digest.hexdigest(), criteria)


def _final(base: Callable[[], Params], controller: str, bearing: float | None,
           sensing: SensingParams, plant: str | None, where: str) -> Params:
    """An episode's parameters: the motion's with a controller's overrides (``base()``) and
    the suite's sensing, plant (None: the parameters' own) and side (``bearing``; None: the
    motion's own). A combination that
    the checks across sections refuse, or whose ``controller`` cannot be made (LQR weights
    without a stabilising gain), raises naming ``where``."""
    try:
        p = base()
        p = p.replace(sensing=sensing, formation=dataclasses.replace(
            p.formation, bearing=p.formation.bearing if bearing is None else bearing))
        if plant is not None:
            p = p.replace(plant=dataclasses.replace(p.plant, kind=plant))
        make_controller(controller, p)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    return p


def _factors(where: str, sides: list, side: str, sensing: list, sensing_name: str,
             controllers: list, label: str) -> str:
    """``file: sides[i], sensing[j], controllers[k]``: the keys that make one combination (a
    side the motion fixes itself is named as it)."""
    names = [s[0] for s in sides]
    at = f"sides[{names.index(side)}]" if side in names else f"side {side!r}"
    return (f"{where}{at}, sensing[{[s[0] for s in sensing].index(sensing_name)}], "
            f"controllers[{[c[0] for c in controllers].index(label)}]")


def track_episode(person: RecordedPerson, params: Params, controller: str = "lqr",
                  side: str = "left", seed: int = 0) -> EpisodeSpec:
    """A recorded walker (not observed in its holes) with the robot starting in its slot on
    ``side``, for the recording's duration."""
    params = params.replace(formation=dataclasses.replace(params.formation,
                                                          bearing=SIDES[side]))
    return EpisodeSpec(controller, person, params, person.duration, seed=seed)


def _plants(value: Any, where: str) -> list[str | None]:
    """The suite's ``plants`` (each of :data:`~companion.params.PLANTS`), or ``[None]``: the
    parameters' own plant, no factor."""
    if value is None:
        return [None]
    names = _list(value, where)
    for i, name in enumerate(names):
        if name not in PLANTS:
            raise ConfigError(f"{where}[{i}]: expected one of {', '.join(map(repr, PLANTS))}, "
                              f"got {name!r}{hint(str(name), PLANTS)}")
    return list(dict.fromkeys(names))


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
        given = item.get("params")
        if isinstance(given, Mapping):                 # a table of overrides in the suite
            try:
                params_from_mapping(given, prefix=f"{at}.params.")
            except ConfigError as exc:
                raise ConfigError(str(exc)) from None
            overrides = dict(given)
            digest.update(repr(sorted(overrides.items())).encode())
        elif given is not None:
            file = _resolve(given, path)
            try:
                overrides = load_toml(file)
                params_from_mapping(overrides, prefix=f"{file}: ")   # errors name the file
            except ConfigError as exc:
                raise ConfigError(f"{at}.params: {exc}") from None
            digest.update(Path(file).read_bytes())
        if "label" not in item and isinstance(given, Mapping):
            raise ConfigError(f"{at}.label: expected a label for a controller with a table of "
                              f"params")
        label = str(item["label"] if "label" in item
                    else name if given is None else f"{name}+{Path(given).stem}")
        out.append((label, name, overrides))
    labels = [c[0] for c in out]
    if len(set(labels)) != len(labels):
        raise ConfigError(f"{where}: expected distinct labels, got {', '.join(labels)}")
    if not out:
        raise ConfigError(f"{where}: expected at least one controller")
    return out


def _resolve(name: Any, path: Path) -> str:
    """A file named in the suite, relative to the suite's folder; other values as given."""
    name = str(name)
    if name.endswith(".toml") or "/" in name:
        candidate = path.parent / name
        return str(candidate) if candidate.exists() or not Path(name).exists() else name
    return name


def _sensing(value: Any, path: Path, i: int, digest: Any) -> tuple[str, SensingParams]:
    """``(label, sensing)`` of a profile name, a .toml file or a table ``{label, base,
    <sensing keys>}``: the profile ``base`` (default realistic) with those keys changed."""
    where = f"{path}: sensing[{i}]"
    if isinstance(value, Mapping):
        label, base = value.get("label"), value.get("base", "realistic")
        if not isinstance(label, str) or not label:
            raise ConfigError(f"{where}.label: expected a name for this sensing, got {label!r}")
        if not isinstance(base, str):
            raise ConfigError(f"{where}.base: expected a profile name or a .toml file, got "
                              f"{base!r}")
        keys = {k: v for k, v in value.items() if k not in ("label", "base")}
        try:
            profile = load_sensing(_resolve(base, path))
            merged = {**dataclasses.asdict(profile), **keys}
            return label, build(SensingParams, merged, prefix=f"{where}.")
        except ConfigError as exc:
            raise ConfigError(exc if str(exc).startswith(where) else f"{where}: {exc}") \
                from None
    if not isinstance(value, str):
        raise ConfigError(f"{where}: expected a profile name, a .toml file or a table with "
                          f"label and base, got {value!r}")
    try:
        profile = load_sensing(_resolve(value, path))
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    if value.endswith(".toml"):
        digest.update(Path(_resolve(value, path)).read_bytes())
    return Path(value).stem, profile


#: A side meaning: the one the scenario (or parameter file) gives.
OWN_SIDE = "scenario"


def _side(value: Any, where: str) -> tuple[str, float | None]:
    if isinstance(value, str):
        if value not in SIDES and value != OWN_SIDE:
            raise ConfigError(f"{where}: expected one of {', '.join(SIDES)}, {OWN_SIDE!r} or a "
                              f"bearing in rad, got {value!r}")
        return value, SIDES.get(value)
    bearing = _number(value, where)
    check = {f.name: f for f in dataclasses.fields(Formation)}["bearing"].metadata["check"]
    problem = check(bearing)
    if problem:
        raise ConfigError(f"{where}: expected {problem}, got {value!r}")
    return f"{bearing:.4f}", bearing


def _seeds(value: Any, where: str) -> list[int]:
    if not isinstance(value, (list, tuple)):
        if isinstance(value, bool) or not isinstance(value, int) \
                or not 1 <= value <= MAX_EPISODES:
            raise ConfigError(f"{where}: expected an integer in [1, {MAX_EPISODES}] or a list "
                              f"of seeds, got {value!r}")
        return list(range(value))
    seeds = _list(value, where)
    for i, s in enumerate(seeds):
        if isinstance(s, bool) or not isinstance(s, int) or s < 0:
            raise ConfigError(f"{where}[{i}]: expected a seed >= 0, got {s!r}")
    return list(dict.fromkeys(seeds))


def _list(value: Any, where: str) -> Sequence:
    if isinstance(value, (str, Mapping)) or not isinstance(value, (list, tuple)) or not value:
        raise ConfigError(f"{where}: expected a non-empty list, got {value!r}")
    return value


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    return float(value)
