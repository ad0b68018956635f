"""The built-in crowd scenes (docs/crowds.md): where the companion person walks, the walls,
and how the other walkers are drawn for an episode's seed; and a scenario's ``[crowd]``
table (:func:`crowd_from`).

In every scene the person starts at the origin walking along +x at about 1.1 m/s; the
walkers are drawn from the episode's ``walkers`` random stream, so each seed is another crowd.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from companion.config import reject_unknown
from companion.errors import ConfigError
from companion.sim.crowd import Crowd, Scene, Walker
from companion.types import Wall

PERSON_SPEED = 1.1      # m/s
LENGTH = 30.0           # m the person walks along +x


#: Closest start between two walkers, and from a walker to the person's and robot's starts (m).
SPACING, CLEAR_START = 0.8, 2.0


@dataclass(frozen=True)
class Spaced:
    """``draw(rng, n)`` from ``one(rng, i)`` (the i-th walker): a walker whose start is
    within :data:`SPACING` of another's, or within :data:`CLEAR_START` of where the person
    and the robot start, is drawn again (a picklable callable: episodes go to worker
    processes)."""

    one: Callable[[np.random.Generator, int], Walker]

    def __call__(self, rng: np.random.Generator, n: int) -> tuple[Walker, ...]:
        out: list[Walker] = []
        while len(out) < n:
            for _ in range(1000):
                w = self.one(rng, len(out))
                x, y = w.route[0]
                if math.hypot(x, y) >= CLEAR_START and all(
                        math.hypot(x - o.route[0][0], y - o.route[0][1]) >= SPACING
                        for o in out):
                    break
            out.append(w)
        return tuple(out)


def _lane(half_width: float, x0: float, x1: float, rng: np.random.Generator, i: int
          ) -> Walker:
    """Along +x (even i) or -x (odd i) from between ``x0`` and ``x1``, in
    ``|y| <= half_width``."""
    x, y = rng.uniform(x0, x1), rng.uniform(-half_width, half_width)
    end = x1 + 15.0 if i % 2 == 0 else x0 - 15.0
    return Walker(((float(x), float(y)), (end, float(y))), float(rng.uniform(0.9, 1.4)))


def _crossing(rng: np.random.Generator, i: int) -> Walker:
    """From either side of the person's way (alternating) to the other."""
    side = 1.0 if i % 2 == 0 else -1.0
    x, d = rng.uniform(3.0, LENGTH - 3.0), rng.uniform(2.0, 14.0)
    return Walker(((float(x), side * float(d)), (float(x), -side * 20.0)),
                  float(rng.uniform(0.9, 1.4)))


def _circular(rng: np.random.Generator, i: int) -> Walker:
    """Round a circle of 4-6 m about (15, 0), which the person's way crosses, either way."""
    turn = 1.0 if i % 2 == 0 else -1.0
    phase, r = rng.uniform(0.0, 2 * math.pi), rng.uniform(4.0, 6.0)
    route = tuple((15.0 + r * math.cos(phase + turn * k * math.pi / 8),
                   r * math.sin(phase + turn * k * math.pi / 8)) for k in range(16))
    return Walker(route, float(rng.uniform(0.9, 1.4)), loop=True)


DOOR_X, DOOR_HALF = 15.0, 0.8       # a 1.6 m door in a wall across the person's way


def _doorway(rng: np.random.Generator, i: int) -> Walker:
    """From beyond the door, through it, towards the person's side."""
    x, y = rng.uniform(DOOR_X + 3.0, DOOR_X + 25.0), rng.uniform(-4.0, 4.0)
    return Walker(((float(x), float(y)), (DOOR_X + 1.0, 0.0), (DOOR_X - 1.0, 0.0),
                   (-10.0, float(y))), float(rng.uniform(0.9, 1.4)))


CORRIDOR_HALF = 1.5                 # a 3 m wide corridor from x = 5 to x = 30


def _walls_doorway() -> tuple[Wall, ...]:
    return (Wall(DOOR_X, -6.0, DOOR_X, -DOOR_HALF), Wall(DOOR_X, DOOR_HALF, DOOR_X, 6.0))


def _walls_corridor() -> tuple[Wall, ...]:
    return (Wall(5.0, CORRIDOR_HALF, LENGTH, CORRIDOR_HALF),
            Wall(5.0, -CORRIDOR_HALF, LENGTH, -CORRIDOR_HALF))


_STRAIGHT = Walker(((0.0, 0.0), (LENGTH + 10.0, 0.0)), PERSON_SPEED)

SCENES = {s.name: s for s in (
    Scene("parallel", "walkers in both directions along the person's way, in 8 m of width",
          _STRAIGHT, (), Spaced(partial(_lane, 4.0, -5.0, LENGTH + 5.0))),
    Scene("crossing", "walkers crossing the person's way from both sides", _STRAIGHT, (),
          Spaced(_crossing)),
    Scene("circular", "walkers going round a 5 m circle, both ways, across the person's way",
          _STRAIGHT, (), Spaced(_circular)),
    Scene("doorway", "a 1.6 m door across the person's way, walkers coming through it",
          Walker(((0.0, 0.0), (DOOR_X - 1.0, 0.0), (DOOR_X + 1.0, 0.0), (LENGTH + 10.0, 0.0)),
                 PERSON_SPEED), _walls_doorway(), Spaced(_doorway)),
    Scene("corridor", "a 3 m wide, 25 m long corridor with walkers both ways", _STRAIGHT,
          _walls_corridor(), Spaced(partial(_lane, CORRIDOR_HALF - 0.5, 6.0, LENGTH))),
    Scene("turnaround", "the person walks 15 m, turns round and walks back, among walkers "
          "in both directions", Walker(((0.0, 0.0), (15.0, 0.0), (-15.0, 0.0)),
                                       PERSON_SPEED), (), Spaced(partial(_lane, 4.0, -10.0, 25.0))),
)}


CROWD_KEYS = ("scene", "walkers")


def crowd_from(data: Any, dt: float, where: str) -> Crowd:
    """The ``[crowd]`` table: a built-in crowd scene and how many walkers besides the person
    (docs/crowds.md)."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where}crowd: expected a table with scene and walkers")
    reject_unknown(data, CROWD_KEYS, f"{where}crowd.")
    scene = data.get("scene")
    if scene not in SCENES:
        raise ConfigError(f"{where}crowd.scene: expected one of {', '.join(SCENES)}, got "
                          f"{scene!r}")
    walkers = data.get("walkers", 10)
    if isinstance(walkers, bool) or not isinstance(walkers, int) or not 0 <= walkers <= 60:
        raise ConfigError(f"{where}crowd.walkers: expected an integer in [0, 60], got "
                          f"{walkers!r}")
    return Crowd(SCENES[scene], walkers, dt=dt)
