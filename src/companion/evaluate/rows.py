"""One episode as a row of numbers, and the pass criteria a suite may set on them.

A row holds every scalar metric of :func:`companion.metrics.compute`, the fuzz's safety
counts against the true person (:data:`COUNTS`) and ``safe``; beside a walking pair, the
human companion's numbers too (:func:`companion.sim.pairs.pair_row`). A suite's ``[criteria]`` table
bounds any of them (``settling_time_s = {max = 20.0}``); an episode passes when every bound
holds and the value is a number (a run that never settles has no settling time: it fails).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from companion.errors import ConfigError
from companion.metrics import Running, compute
from companion.sim.fuzz import episode_counts
from companion.sim.pairs import PairedPerson, pair_row
from companion.sim.runner import EpisodeSpec, run_one
from companion.types import Log

#: Safety counts kept per episode (companion.sim.fuzz.episode_counts).
COUNTS = ("person_collisions", "person_collisions_robot", "violations", "obstacle_collisions")
#: Every number of a row.
NUMBERS = tuple(k for k, v in Running().value().items() if not isinstance(v, dict)) \
    + COUNTS[:3] + ("safe",)


def summary_row(spec: EpisodeSpec) -> dict[str, Any]:
    """Run one episode and reduce it to its row (module docstring)."""
    return row_of(spec, run_one(spec))


def row_and_log(spec: EpisodeSpec) -> tuple[dict[str, Any], Log]:
    """Run one episode: its row and its log (for figures)."""
    log = run_one(spec)
    return row_of(spec, log), log


def row_of(spec: EpisodeSpec, log: Log) -> dict[str, Any]:
    """The row of an episode's log: ``safe`` means no robot-caused contact or protective
    violation and no obstacle contact."""
    m = compute(log)
    row = {k: (math.nan if v is None else float(v)) for k, v in m.items()
           if v is None or isinstance(v, (int, float))}
    counts = episode_counts(log, spec.params, spec.obstacles)
    row.update({k: int(counts[k]) for k in COUNTS})
    row["safe"] = (counts["person_collisions_robot"] == 0 and counts["violations"] == 0
                   and counts["obstacle_collisions"] == 0)
    if isinstance(spec.person, PairedPerson):       # the human companion's numbers beside
        row.update(pair_row(spec.person, spec.params, log))
    return row


@dataclass(frozen=True)
class Criterion:
    """``low <= row[metric] <= high`` (a missing bound is open)."""

    metric: str
    low: float | None = None
    high: float | None = None

    def holds(self, row: Mapping[str, Any]) -> bool:
        value = float(row[self.metric])
        return math.isfinite(value) and (self.low is None or value >= self.low) \
            and (self.high is None or value <= self.high)

    def __str__(self) -> str:
        parts = ([f"{self.metric} >= {self.low:g}"] if self.low is not None else []) \
            + ([f"{self.metric} <= {self.high:g}"] if self.high is not None else [])
        return " and ".join(parts)


def criteria_from(data: Any, where: str) -> tuple[Criterion, ...]:
    """The ``[criteria]`` table: metric -> ``{min = ..., max = ...}``."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where}: expected a table of metric = {{min = ..., max = ...}}")
    out = []
    for metric, bounds in data.items():
        at = f"{where}.{metric}"
        if metric not in NUMBERS:
            raise ConfigError(f"{at}: expected one of {', '.join(NUMBERS)}")
        if not isinstance(bounds, Mapping) or not bounds or set(bounds) - {"min", "max"}:
            raise ConfigError(f"{at}: expected a table with min and/or max, got {bounds!r}")
        for key, value in bounds.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value):
                raise ConfigError(f"{at}.{key}: expected a number, got {value!r}")
        out.append(Criterion(metric, bounds.get("min"), bounds.get("max")))
    return tuple(out)


def failed(row: Mapping[str, Any], criteria: Sequence[Criterion]) -> list[str]:
    """The criteria ``row`` misses, as text."""
    return [str(c) for c in criteria if not c.holds(row)]
