"""Many independent episodes, metrics only (Monte-Carlo evaluation and tuning).

Each :class:`EpisodeSpec` names everything one episode needs (controller, person, parameters,
start, seed, noise, obstacles). :func:`run_batch` runs the episodes in worker processes with
the single-episode simulator (:func:`companion.sim.episode.run_episode` and the standard
controller stack of :func:`companion.control.make_controller`) and returns one metrics dict
per episode, in the order of the specs. A worker keeps one episode's log at a time and
returns only its metrics (about 1 kB), so memory does not grow with the number of episodes.

Because the workers run the single-episode code, the results are those of
:func:`run_one` in this process (``tests/sim/test_batch.py``). Throughput and how it scales
with the number of workers are measured by ``companion bench`` (docs/performance.md).
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Callable, Sequence

from companion import metrics
from companion.control import make_controller
from companion.control.base import Pose
from companion.errors import ConfigError
from companion.obstacles import Obstacle
from companion.params import Params
from companion.sim.episode import SensorNoise, run_episode
from companion.sim.person import PersonMotion


@dataclass(frozen=True)
class EpisodeSpec:
    """One episode of a batch (see :func:`companion.sim.episode.run_episode`)."""

    controller: str
    person: PersonMotion
    params: Params
    duration: float
    start: Pose | None = None
    seed: int = 0
    noise: SensorNoise = SensorNoise()
    obstacles: tuple[Obstacle, ...] = field(default_factory=tuple)


def run_one(spec: EpisodeSpec) -> dict:
    """Simulate one episode with the standard stack and return its metrics
    (:func:`companion.metrics.compute`)."""
    log = run_episode(make_controller(spec.controller, spec.params), spec.person, spec.params,
                      spec.duration, start=spec.start, seed=spec.seed, noise=spec.noise,
                      obstacles=spec.obstacles)
    return metrics.compute(log)


def default_workers() -> int:
    """One worker per CPU this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else \
        (os.cpu_count() or 1)


def run_batch(specs: Sequence[EpisodeSpec], workers: int | None = None,
              progress: Callable[[int], None] | None = None) -> list[dict]:
    """Metrics of every episode in ``specs``, in order.

    Parameters
    ----------
    specs : sequence of EpisodeSpec
    workers : int, optional
        Worker processes (default: :func:`default_workers`); 1 runs in this process.
    progress : callable, optional
        Called with the number of episodes finished so far, after each one.

    Raises
    ------
    ConfigError
        If ``workers`` is not a positive integer.
    """
    workers = default_workers() if workers is None else workers
    if not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers: expected a positive integer, got {workers!r}")
    results: list[dict] = []
    if workers == 1 or len(specs) <= 1:
        for spec in specs:
            results.append(run_one(spec))
            if progress:
                progress(len(results))
        return results
    # Chunks of a few episodes amortise the inter-process traffic; several chunks per
    # worker keep the workers busy to the end.
    chunk = max(1, math.ceil(len(specs) / (8 * workers)))
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for result in pool.map(run_one, specs, chunksize=chunk):
            results.append(result)
            if progress:
                progress(len(results))
    return results
