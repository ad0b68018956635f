"""Suite generators: suites built in Python rather than read from a TOML file, run by the one
engine (:mod:`companion.evaluate.run`: local processes or Dask, resumable) like any suite.

A suite generator gives a :class:`~companion.evaluate.suite.Suite` of episodes and the
function that makes each episode's result (its row function, run in the worker):
:func:`suite_of` any episodes, :func:`scenario_episodes` the scenarios as ``companion run``
runs them, :func:`soak_suite` the soak's one long episode; the closed-loop fuzz's plan is
:func:`companion.evaluate.fuzz_runs.fuzz_suite`.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from companion.evaluate.rows import summary_row
from companion.evaluate.suite import OWN_SIDE, Episode, Suite
from companion.params import Params
from companion.sim import soak
from companion.sim.runner import EpisodeSpec
from companion.sim.scenario import load_scenario


def suite_of(name: str, episodes: Iterable[Episode],
             row: Callable[[EpisodeSpec], Any] = summary_row, parts: Sequence[Any] = (),
             description: str = "") -> Suite:
    """A suite of ``episodes`` (distinct keys), each giving ``row(spec)``: a module-level
    function of the spec or a partial of one. Its digest covers the episodes' keys and the
    reprs of ``parts``: whatever else the episodes and ``row``'s arguments depend on (their
    parameters, the digests of the suites they come from), so that results kept under an
    output folder are resumed only by the same suite. The reference is the first
    controller."""
    episodes = tuple(episodes)
    keys = [e.key for e in episodes]
    if len(set(keys)) != len(keys):
        raise ValueError(f"{name}: two episodes share a key")
    digest = hashlib.sha256(repr((name, keys, [repr(p) for p in parts])).encode())
    return Suite(name, description, episodes[0].controller if episodes else "", episodes,
                 digest.hexdigest(), row=row)


def scenario_episodes(name: str, controllers: Sequence[str], obstacles: str | None = None
                      ) -> list[Episode]:
    """The scenario ``name`` (built-in or a file) with each of ``controllers`` as ``companion
    run`` runs it: its own seed, sensing, side, start and duration. ``obstacles``: the
    source the robot sees them with (None: the scenario's); the motion is named as a suite
    names it (``fig7+lidar``), its side and sensing ``scenario``."""
    sc = load_scenario(name)
    label = Path(name).stem + ("" if obstacles is None else f"+{obstacles}")
    return [Episode(label, label, OWN_SIDE, OWN_SIDE, c, sc.seed, sc.episode(c, obstacles))
            for c in controllers]


def soak_suite(duration: float, seed: int = 0, controller: str = "lqr",
               params: Params | None = None) -> Suite:
    """The soak (:mod:`companion.sim.soak`) of ``duration`` s in the world of ``seed``: one
    episode whose result is its summary (:func:`companion.sim.soak.spec_summary`, the log
    kept in blocks only)."""
    params = params or Params()
    spec = soak.soak_episode(duration, seed, controller, params)
    episode = Episode("soak", "soak", "params", "params", controller, seed, spec)
    return suite_of("soak", [episode], soak.spec_summary, parts=(duration, params))
