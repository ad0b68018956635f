"""Fault injection: make what the controller observes go wrong on purpose, for a while.

A :class:`Fault` is active for ``start <= t < end`` (simulated time, s) and changes the
:class:`~companion.control.base.Observation` handed to the controller; the simulated world
itself is unchanged. Kinds (:data:`KINDS`):

========================  ==========================================================
``person_dropout``        no person detection (the detector lost the person)
``person_nan``            person detections with NaN positions
``person_jump``           person detections offset by ``(dx, dy)`` m (identity switch)
``robot_nan``             robot pose NaN (localisation failure)
``obstacle_nan``          an extra obstacle with NaN centre in the obstacle list
``scan_blackout``         every LiDAR return NaN, so nothing is detected either
``clock_freeze``          the observation time stays at ``start`` (zero time steps)
``clock_backward``        the observation time runs backwards from ``start``
``stall``                 the controller is not called; the last command is held
========================  ==========================================================

Scenario files list faults as ``[[faults]]`` tables with these keys.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.config import Validated, build, non_negative, param, positive
from companion.errors import ConfigError
from companion.types import Circle, Observation, Pose

KINDS = ("person_dropout", "person_nan", "person_jump", "robot_nan", "obstacle_nan",
         "scan_blackout", "clock_freeze", "clock_backward", "stall")

_NAN = math.nan


def finite(x: float) -> str | None:
    return None if math.isfinite(x) else "a finite number"


@dataclass(frozen=True)
class Fault(Validated):
    """One injected fault (see the module docstring); ``dx``, ``dy`` only for person_jump."""

    kind: str = param("person_dropout", "-", "what goes wrong", choices=KINDS)
    start: float = param(0.0, "s", "time the fault begins", non_negative)
    end: float = param(1.0, "s", "time the fault ends (exclusive), > start", positive)
    dx: float = param(0.0, "m", "person_jump: offset of the observed person along x", finite)
    dy: float = param(0.0, "m", "person_jump: offset of the observed person along y", finite)

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.start < self.end:
            raise ConfigError(f"end: expected a time after start ({self.start:g} s), "
                              f"got {self.end:g}")

    def active(self, t: float) -> bool:
        return self.start <= t < self.end


def faults_from_list(items: Any, where: str) -> tuple[Fault, ...]:
    """Faults from a parsed TOML array of tables (``[[faults]]``); errors name ``where``, the
    index and the key, e.g. ``s.toml: faults[1].kind: expected one of ...``."""
    if not isinstance(items, list):
        raise ConfigError(f"{where}: expected an array of tables ([[faults]])")
    out = []
    for i, item in enumerate(items):
        at = f"{where}[{i}]"
        if not isinstance(item, Mapping):
            raise ConfigError(f"{at}: expected a table with kind, start and end")
        for key in ("kind", "start", "end"):
            if key not in item:
                raise ConfigError(f"{at}.{key}: missing; a fault needs kind, start and end")
        out.append(build(Fault, item, prefix=f"{at}."))
    return tuple(out)


def stalled(faults: Sequence[Fault], t: float) -> bool:
    """True if a ``stall`` fault is active at ``t``."""
    return any(f.kind == "stall" and f.active(t) for f in faults)


def _person(obs: Observation, change) -> Observation:
    """``obs`` with ``change`` applied to its person and to each of its detections."""
    return dataclasses.replace(
        obs, person=None if obs.person is None else change(obs.person),
        detections=tuple(change(d) for d in obs.detections))


def apply(obs: Observation, faults: Sequence[Fault]) -> Observation:
    """The observation as corrupted by the faults active at ``obs.t``."""
    t = obs.t
    for f in faults:
        if not f.active(t):
            continue
        if f.kind == "person_dropout":
            obs = dataclasses.replace(obs, person=None, detections=())
        elif f.kind == "person_nan":
            obs = _person(obs, lambda p: dataclasses.replace(p, x=_NAN, y=_NAN))
        elif f.kind == "person_jump":
            obs = _person(obs, lambda p, f=f: dataclasses.replace(p, x=p.x + f.dx,
                                                                  y=p.y + f.dy))
        elif f.kind == "robot_nan":
            obs = dataclasses.replace(obs, robot=Pose(_NAN, _NAN, _NAN))
        elif f.kind == "obstacle_nan":
            obs = dataclasses.replace(obs, obstacles=(*obs.obstacles, Circle(_NAN, _NAN, 0.3)))
        elif f.kind == "scan_blackout" and obs.scan is not None:
            dark = dataclasses.replace(obs.scan, ranges=np.full_like(obs.scan.ranges, np.nan))
            obs = dataclasses.replace(obs, scan=dark, obstacles=())
        elif f.kind == "clock_freeze":
            obs = dataclasses.replace(obs, t=f.start)
        elif f.kind == "clock_backward":
            obs = dataclasses.replace(obs, t=f.start - (t - f.start))
    return obs
