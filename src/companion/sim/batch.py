"""Many independent episodes, metrics only (Monte-Carlo evaluation and tuning).

Each :class:`EpisodeSpec` names everything one episode needs (controller, whether the
standard stack wraps it, person, parameters, start, seed, sensor noise, obstacles).
:func:`run_batch` returns one metrics dict (:func:`companion.metrics.compute`) per episode, in
the order of the specs, from one of two back ends:

* compiled (:mod:`companion.sim.fast_batch`): every registered controller, bare (without the
  avoidance layer and the supervisor), without obstacles, all episodes as lanes of one
  vectorised simulation;
* processes: anything, with the single-episode simulator
  (:func:`companion.sim.episode.run_episode`) in worker processes.

Both keep only running sums or one episode's log at a time, so memory does not grow with the
number of episodes. Both agree with :func:`run_one` in this process to 1e-9
(``tests/sim/test_batch.py``, ``tests/sim/test_fast_batch.py``). docs/performance.md has the
throughput.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Callable, Sequence

from companion import metrics
from companion.control import CONTROLLERS, make_controller
from companion.control.base import Controller, Pose
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
    stack: bool = True
    """True: the standard stack (avoidance layer and safety supervisor around the controller,
    :func:`companion.control.make_controller`); False: the controller alone."""


def controller_of(spec: EpisodeSpec) -> Controller:
    """The spec's controller: the standard stack, or the registered controller alone."""
    if spec.stack:
        return make_controller(spec.controller, spec.params)
    if spec.controller not in CONTROLLERS:
        make_controller(spec.controller, spec.params)   # raises ConfigError with a hint
    entry = CONTROLLERS[spec.controller]
    return entry.factory(entry.adjust(spec.params))


def run_one(spec: EpisodeSpec) -> dict:
    """Simulate one episode with the single-episode simulator and return its metrics
    (:func:`companion.metrics.compute`)."""
    log = run_episode(controller_of(spec), spec.person, spec.params, spec.duration,
                      start=spec.start, seed=spec.seed, noise=spec.noise,
                      obstacles=spec.obstacles)
    return metrics.compute(log)


def default_workers() -> int:
    """One worker per CPU this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else \
        (os.cpu_count() or 1)


BACKENDS = ("auto", "compiled", "processes")


def run_batch(specs: Sequence[EpisodeSpec], workers: int | None = None,
              progress: Callable[[int], None] | None = None, backend: str = "auto"
              ) -> list[dict]:
    """Metrics of every episode in ``specs``, in order.

    Parameters
    ----------
    specs : sequence of EpisodeSpec
    workers : int, optional
        Threads (compiled backend) or worker processes (default: one per CPU); with
        processes, 1 runs in this process.
    progress : callable, optional
        Called with the number of episodes finished so far.
    backend : {"auto", "compiled", "processes"}
        "compiled": :func:`companion.sim.fast_batch.run_fast_batch` (bare controllers
        without obstacles; for the LQR about 30x the processes back end's throughput,
        docs/performance.md); "processes": the single-episode
        simulator in worker processes (anything); "auto": compiled when every spec allows it.

    Raises
    ------
    ConfigError
        If ``workers`` is not a positive integer, ``backend`` is unknown, or "compiled" is
        asked for a spec it cannot run.
    """
    from companion.sim import fast_batch

    workers = default_workers() if workers is None else workers
    if not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers: expected a positive integer, got {workers!r}")
    if backend not in BACKENDS:
        raise ConfigError(f"backend: expected one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "compiled" or (backend == "auto" and specs
                                 and not any(fast_batch.unsupported(s) for s in specs)):
        results = fast_batch.run_fast_batch(specs, threads=workers)
        if progress:
            progress(len(results))
        return results
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
