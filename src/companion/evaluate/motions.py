"""The person motions of a suite's ``[motions]`` table: built-in or file scenarios, recorded
``t,x,y`` tracks (the shipped ETH/UCY ones by name) and the paper's Fig. 3 convergence starts
(docs/evaluation.md gives the keys). Errors name the suite file and the key.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.config import reject_unknown
from companion.data import pedestrians
from companion.data.pairs import load_pairs
from companion.errors import CompanionError, ConfigError
from companion.params import SIDES, Params, params_from_mapping
from companion.sim import convergence
from companion.sim.pairs import pair_episode, pair_params, paired
from companion.sim.person import line
from companion.sim.recorded import RecordedPerson, load_person_csv
from companion.sim.runner import EpisodeSpec
from companion.sim.scenario import builtin_path, deep_merge, load_scenario
from companion.sim.sensing import OBSTACLE_SOURCES

KEYS = ("scenarios", "tracks", "pairs", "data", "every", "offset", "min_mean_speed",
        "min_duration", "convergence")
SCENARIO = ("name", "obstacles", "label")
CONVERGENCE = ("speeds", "duration")
#: The shipped walking tracks, by name.
SHIPPED_TRACKS = "eth_ucy"


@dataclass(frozen=True)
class Motion:
    """One person motion of a suite. ``base(label, overrides)``: the motion's parameters with
    a controller's overrides; ``build(label, overrides, controller)``: its episode;
    ``sides``: the sides it is run on when the motion fixes them (else the suite's)."""

    name: str
    group: str
    base: Callable[[str, dict], Params]
    build: Callable[[str, dict, str], EpisodeSpec]
    sides: tuple[str, ...] | None = None
    shared: bool = True
    """The motions of its group have the same parameters (False: its own, a pair's slot)."""


def motions(data: Any, path: Path, digest: Any, resolve: Callable[[Any, Path], str]
            ) -> list[Motion]:
    """Every motion of the ``[motions]`` table ``data`` of the suite at ``path`` (the files
    read added to ``digest``)."""
    where = f"{path}: motions"
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where}: expected a table with scenarios, tracks and/or "
                          f"convergence")
    reject_unknown(data, KEYS, f"{where}.")
    out: list[Motion] = []
    scenarios = data.get("scenarios", []) and _list(data["scenarios"], f"{where}.scenarios")
    for i, item in enumerate(scenarios):
        out.append(_scenario(item, f"{where}.scenarios[{i}]", path, digest, resolve))
    if "convergence" in data:
        out += _convergence(data["convergence"], f"{where}.convergence")
    every = _count(data.get("every", 1), f"{where}.every")
    offset = data.get("offset", 0)
    if isinstance(offset, bool) or not isinstance(offset, int) or not 0 <= offset < every:
        raise ConfigError(f"{where}.offset: expected an integer in [0, every), got {offset!r}")
    if "tracks" in data:
        def track_base(label: str, over: dict) -> Params:
            return params_from_mapping(over)

        for label, person in _tracks(data["tracks"], data, path, digest, resolve)[offset::every]:
            def track_build(label: str, over: dict, controller: str,
                            person=person) -> EpisodeSpec:
                return EpisodeSpec(controller, person, Params(), person.duration)
            out.append(Motion(label, "tracks", track_base, track_build))
    elif any(k in data for k in ("data", "min_mean_speed")):
        raise ConfigError(f"{where}: data and min_mean_speed select tracks: expected tracks "
                          f"too")
    if "pairs" in data:
        out += pair_motions(data["pairs"], data, path, digest, resolve)[offset::every]
    if not {"tracks", "pairs"} & set(data) and any(k in data for k in ("every", "offset",
                                                                       "min_duration")):
        raise ConfigError(f"{where}: every, offset and min_duration select tracks or pairs: "
                          f"expected tracks or pairs too")
    if not out:
        raise ConfigError(f"{where}: expected at least one scenario, track or convergence "
                          f"start")
    return out


def _scenario(item: Any, where: str, path: Path, digest: Any,
              resolve: Callable[[Any, Path], str]) -> Motion:
    """A scenario named by its built-in name or file, or a table ``{name, obstacles,
    label}`` (``obstacles``: the source the robot sees them with)."""
    if isinstance(item, Mapping):
        reject_unknown(item, SCENARIO, f"{where}.")
        name, source, label = item.get("name"), item.get("obstacles"), item.get("label")
        if source is not None and source not in OBSTACLE_SOURCES:
            raise ConfigError(f"{where}.obstacles: expected one of "
                              f"{', '.join(OBSTACLE_SOURCES)}, got {source!r}")
        if label is not None and not isinstance(label, str):
            raise ConfigError(f"{where}.label: expected a string, got {label!r}")
    else:
        name, source, label = item, None, None
    if not isinstance(name, str):
        raise ConfigError(f"{where}: expected a scenario name, a .toml file or a table with "
                          f"name, obstacles and label, got {name!r}")
    scenario = resolve(name, path) if name.endswith(".toml") else name
    try:
        load_scenario(scenario)                       # its errors name the scenario
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    file = Path(scenario) if scenario.endswith(".toml") else builtin_path(scenario)
    digest.update(file.read_bytes())
    cache: dict[str, Any] = {}     # the scenario with a controller's overrides, by label

    def loaded(label: str, over: dict) -> Any:
        if label not in cache:
            cache[label] = load_scenario(scenario, params_override=over or None)
        return cache[label]

    def base(label: str, over: dict) -> Params:
        return loaded(label, over).params

    def build(label: str, over: dict, controller: str) -> EpisodeSpec:
        return loaded(label, over).episode(controller, source)

    label = label or Path(name).stem + ("" if source is None else f"+{source}")
    return Motion(label, label, base, build)


def _convergence(data: Any, where: str) -> list[Motion]:
    """The paper's Fig. 3 (:mod:`companion.sim.convergence`): per person speed, the robot
    starting at 5 points with 4 headings on the side it starts on (both from behind)."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where}: expected a table with speeds and duration")
    reject_unknown(data, CONVERGENCE, f"{where}.")
    speeds = [_number(s, f"{where}.speeds[{i}]", positive=True)
              for i, s in enumerate(_list(data.get("speeds", list(convergence.SPEEDS)),
                                          f"{where}.speeds"))]
    duration = _number(data.get("duration", 30.0), f"{where}.duration", positive=True)
    out: list[Motion] = []
    seen: dict[tuple, list[str]] = {}
    for case in convergence.cases(speeds):
        seen.setdefault((case.speed, case.start), []).append(case.side)
    for (speed, start), sides in seen.items():
        def base(label: str, over: dict) -> Params:
            return params_from_mapping(deep_merge(convergence.PAPER, over))

        def build(label: str, over: dict, controller: str, speed=speed, start=start
                  ) -> EpisodeSpec:
            return EpisodeSpec(controller, line(convergence.PERSON_START, speed), Params(),
                               duration, start=start)
        name = f"fig3-{speed:g}mps({start.x:g},{start.y:g},{start.theta:.3f})"
        out.append(Motion(name, f"fig3-{speed:g}mps", base, build, tuple(sides)))
    return out


def _tracks(tracks: Any, data: Mapping, path: Path, digest: Any,
            resolve: Callable[[Any, Path], str]) -> list[tuple[str, RecordedPerson]]:
    """The named tracks (their data added to ``digest``)."""
    where = f"{path}: motions.tracks"
    if tracks == SHIPPED_TRACKS:
        folder = data.get("data")
        if folder is not None and not isinstance(folder, str):
            raise ConfigError(f"{path}: motions.data: expected a folder of the ETH/UCY files, "
                              f"got {folder!r}")
        try:
            scenes = pedestrians.load_scenes(None if folder is None else resolve(folder, path))
        except ConfigError as exc:
            raise ConfigError(f"{path}: motions.data: {exc}") from None
        chosen = pedestrians.select_tracks(
            scenes, _number(data.get("min_mean_speed", 0.6), f"{path}: motions.min_mean_speed"),
            _number(data.get("min_duration", 15.0), f"{path}: motions.min_duration"))
        if not chosen:
            raise ConfigError(f"{where}: no track is fast and long enough; lower "
                              f"min_mean_speed or min_duration")
        for tr in chosen:
            digest.update(np.asarray((tr.t, tr.x, tr.y), dtype=float).tobytes())
        return [(f"{tr.scene}/{tr.ped_id}", RecordedPerson(tr.t, tr.x, tr.y)) for tr in chosen]
    if "data" in data:
        raise ConfigError(f"{path}: motions.data: the folder of the {SHIPPED_TRACKS!r} files; "
                          f"expected tracks = {SHIPPED_TRACKS!r}")
    if not isinstance(tracks, str):
        raise ConfigError(f"{where}: expected {SHIPPED_TRACKS!r} or a folder of t,x,y CSV "
                          f"files, got {tracks!r}")
    folder = Path(resolve(tracks, path))
    files = sorted(folder.glob("*.csv")) if folder.is_dir() else []
    if not files:
        raise ConfigError(f"{where}: expected {SHIPPED_TRACKS!r} or a folder of t,x,y CSV "
                          f"files, got {tracks!r} (no CSV files there)")
    for f in files:
        digest.update(f.read_bytes())
    return [(f.stem, load_person_csv(f)) for f in files]


#: The side name of a motion that brings its own slot (a walking pair's).
OWN_SLOT = "companion"
#: Shortest pair (s) a suite takes by default: a shorter walk says little about steadiness.
PAIR_MIN_DURATION = 5.0


def pair_motions(pairs: Any, data: Mapping, path: Path, digest: Any,
                 resolve: Callable[[Any, Path], str]) -> list[Motion]:
    """Every walking pair (:mod:`companion.data.pairs`; the shipped ones by name, or a
    folder of the same layout) at least ``min_duration`` long, each both ways round: the
    robot in the companion's place (:func:`companion.sim.pairs.pair_episode`)."""
    where = f"{path}: motions.pairs"
    if not isinstance(pairs, str):
        raise ConfigError(f"{where}: expected {SHIPPED_TRACKS!r} or a folder of the walking "
                          f"pairs' files, got {pairs!r}")
    shortest = _number(data.get("min_duration", PAIR_MIN_DURATION),
                       f"{path}: motions.min_duration")
    try:
        found = load_pairs(None if pairs == SHIPPED_TRACKS else resolve(pairs, path))
    except CompanionError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    out = []
    for pair in found:
        if pair.duration < shortest:
            continue
        digest.update(np.asarray((pair.t, pair.ax, pair.ay, pair.bx, pair.by)).tobytes())
        for flipped in (False, True):
            person = paired(pair, flipped)

            def base(label: str, over: dict, person=person) -> Params:
                return pair_params(person, params_from_mapping(over))

            def build(label: str, over: dict, controller: str, person=person) -> EpisodeSpec:
                return pair_episode(person, base(label, over), controller)
            a, b = (pair.b, pair.a) if flipped else (pair.a, pair.b)
            out.append(Motion(f"{pair.scene}/{a}+{b}", "pairs", base, build, (OWN_SLOT,),
                              shared=False))
    if not out:
        raise ConfigError(f"{where}: no pair walks {shortest:g} s or longer; lower "
                          f"min_duration")
    return out


def fixed_sides(motion: Motion, sides: list[tuple[str, float]]
                ) -> list[tuple[str, float | None]]:
    """The (name, bearing) sides ``motion`` runs on (None: the motion's own bearing)."""
    return sides if motion.sides is None else [(s, SIDES.get(s)) for s in motion.sides]


def _list(value: Any, where: str) -> list:
    if isinstance(value, (str, Mapping)) or not isinstance(value, (list, tuple)) or not value:
        raise ConfigError(f"{where}: expected a non-empty list, got {value!r}")
    return list(value)


def _count(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(f"{where}: expected an integer >= 1, got {value!r}")
    return value


def _number(value: Any, where: str, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not np.isfinite(value) or (positive and value <= 0):
        raise ConfigError(f"{where}: expected a {'positive ' if positive else ''}number, got "
                          f"{value!r}")
    return float(value)

