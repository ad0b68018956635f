"""One runner for many episodes of the full stack: safety supervisor, avoidance layer,
controller and sensing, in parallel worker processes.

An :class:`EpisodeSpec` says everything one episode needs; :func:`run_one` simulates it in this
process and :func:`run_many` many of them in worker processes, returning the same logs (or
what ``summarize`` makes of each log, in the worker) in the order of the specs. Each episode
draws its noise from its own seed, so the results do not depend on the number of workers.
"""

from __future__ import annotations

import ctypes
import math
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from functools import partial
from typing import Any

from companion import _jit
from companion.control import make_controller
from companion.errors import ConfigError
from companion.params import Params
from companion.sim.episode import BLOCK_ROWS, episode_blocks
from companion.sim.faults import Fault
from companion.sim.person import PersonMotion
from companion.sim.sensing import make_perception
from companion.types import Log, Obstacle, Pose


@dataclass(frozen=True)
class EpisodeSpec:
    """One episode (see :func:`companion.sim.episode.run_episode` for the fields)."""

    controller: str
    person: PersonMotion
    params: Params
    duration: float
    start: Pose | None = None
    seed: int = 0
    obstacles: tuple[Obstacle, ...] = field(default_factory=tuple)
    obstacle_source: str = "truth"
    """"truth": the controller knows the obstacles exactly; "lidar": it sees what the
    simulated LiDAR detects."""
    faults: tuple[Fault, ...] = field(default_factory=tuple)
    start_velocity: tuple[float, float] | None = None


def run_one(spec: EpisodeSpec) -> Log:
    """Simulate one episode of the standard stack of ``spec.controller``."""
    return Log.concat(stream_one(spec))


#: The callback of :func:`reporting` in this context (None: nobody is watching).
_watcher: ContextVar[Callable[[float], None] | None] = ContextVar("watcher", default=None)


@contextmanager
def reporting(callback: Callable[[float], None]) -> Iterator[None]:
    """Inside, every episode streamed in this process (:func:`stream_one`, so also
    :func:`run_one` and a suite run with one worker) calls ``callback(t)`` with the simulated
    time it reached after each block: a command's progress bar. Worker processes do not
    report."""
    token = _watcher.set(callback)
    try:
        yield
    finally:
        _watcher.reset(token)


def stream_one(spec: EpisodeSpec, rows: int = BLOCK_ROWS) -> Iterator[Log]:
    """:func:`run_one`'s log in blocks of ``rows`` rows, yielded as the episode runs
    (:func:`companion.sim.episode.episode_blocks`): a long episode in bounded memory."""
    blocks = episode_blocks(make_controller(spec.controller, spec.params), spec.person,
                            spec.params, spec.duration, start=spec.start, seed=spec.seed,
                            obstacles=spec.obstacles,
                            perception=make_perception(spec.obstacle_source, spec.params),
                            faults=spec.faults, start_velocity=spec.start_velocity, rows=rows)
    watcher = _watcher.get()
    return blocks if watcher is None else _watched(blocks, watcher, spec.duration)


def _watched(blocks: Iterator[Log], watcher: Callable[[float], None], duration: float
             ) -> Iterator[Log]:
    for block in blocks:
        if len(block["t"]):
            watcher(float(block["t"][-1]))
        yield block
    watcher(duration)                   # the episode is over


def default_workers() -> int:
    """One worker per CPU this process may use."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def warm_up() -> None:
    """Load (or compile) the compiled kernels of the stack in this process
    (:func:`companion._jit.warm_up`), so that worker processes forked from it inherit them
    instead of each loading them."""
    _jit.warm_up()


def _run(spec: EpisodeSpec, summarize: Callable[[Log], Any] | None) -> Any:
    log = run_one(spec)
    return log if summarize is None else summarize(log)


def run_many(specs: Sequence[EpisodeSpec], workers: int | None = None,
             summarize: Callable[[Log], Any] | None = None,
             progress: Callable[[int], None] | None = None) -> list:
    """The log of every episode of ``specs`` (or ``summarize(log)``), in order.

    Parameters
    ----------
    specs : sequence of EpisodeSpec
    workers : int, optional
        Worker processes (default: one per CPU); 1 runs everything in this process.
    summarize : callable, optional
        A module-level function applied to each log in the worker (keeps only what is needed,
        e.g. :func:`companion.metrics.compute`).
    progress : callable, optional
        Called with the number of episodes finished so far.

    Raises
    ------
    ConfigError
        If ``workers`` is not a positive integer.
    """
    workers = default_workers() if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers: expected a positive integer, got {workers!r}")
    job = partial(_run, summarize=summarize)
    results: list = []
    if workers == 1 or len(specs) <= 1:
        for spec in specs:
            results.append(job(spec))
            if progress:
                progress(len(results))
        return results
    warm_up()
    # Several chunks per worker keep every worker busy to the end.
    chunk = max(1, math.ceil(len(specs) / (4 * workers)))
    # fork (Linux) hands the workers the loaded kernels; elsewhere the platform's default
    context = multiprocessing.get_context("fork") if sys.platform.startswith("linux") else None
    pool = ProcessPoolExecutor(max_workers=min(workers, len(specs)), mp_context=context,
                               initializer=_worker_init, initargs=(os.getpid(),))
    try:
        for result in pool.map(job, specs, chunksize=chunk):
            results.append(result)
            if progress:
                progress(len(results))
    except BaseException:
        _stop(pool)       # an error, Ctrl-C or SIGTERM: do not wait for the remaining episodes
        raise
    pool.shutdown()
    return results


def run_unordered(specs: Sequence[EpisodeSpec], workers: int | None,
                  func: Callable[[EpisodeSpec], Any]) -> Iterator[tuple[int, Any]]:
    """``(index, func(spec))`` for every spec, as each finishes (in worker processes unless
    ``workers`` is 1): a caller can keep each result before the others are done. ``func`` is
    a module-level function of the spec (it runs the episode itself)."""
    workers = default_workers() if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers: expected a positive integer, got {workers!r}")
    if workers == 1 or len(specs) <= 1:
        for i, spec in enumerate(specs):
            yield i, func(spec)
        return
    warm_up()
    context = multiprocessing.get_context("fork") if sys.platform.startswith("linux") else None
    pool = ProcessPoolExecutor(max_workers=min(workers, len(specs)), mp_context=context,
                               initializer=_worker_init, initargs=(os.getpid(),))
    try:
        futures = {pool.submit(func, spec): i for i, spec in enumerate(specs)}
        for future in as_completed(futures):
            yield futures[future], future.result()
    except BaseException:
        _stop(pool)
        raise
    pool.shutdown()


def _worker_init(parent: int) -> None:
    """Workers leave Ctrl-C to the parent, die on SIGTERM (the parent stops them) and die
    with the parent process ``parent`` (a SIGKILLed parent cannot stop them)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    die_with_parent(parent)


#: prctl option: the signal this process gets when its parent dies (linux/prctl.h).
_PR_SET_PDEATHSIG = 1
#: How often (s) a worker without PR_SET_PDEATHSIG checks that its parent lives.
PARENT_POLL = 1.0


def die_with_parent(parent: int) -> None:
    """Make this process die when its parent process ``parent`` dies.

    Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)``, at once. Elsewhere (or if prctl fails): a
    daemon thread that checks every :data:`PARENT_POLL` s whether the parent changed
    (``os.getppid()``: an orphan is adopted by another process) and then ends the process
    (``os._exit(1)``). On Linux the signal comes
    when the *thread* that started this process ends, so a pool must be made, and used up,
    by one thread, as :func:`run_many` and :func:`run_unordered` do."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            if libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0:
                if os.getppid() != parent:          # it died before prctl was set
                    os.kill(os.getpid(), signal.SIGKILL)
                return
        except (OSError, AttributeError):           # no libc or no prctl: poll instead
            pass

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_POLL)
        os._exit(1)

    threading.Thread(target=watch, name="die-with-parent", daemon=True).start()


def _stop(pool: ProcessPoolExecutor) -> None:
    """Cancel what is queued and terminate the workers (concurrent.futures has no public way
    to stop running work before Python 3.14)."""
    processes = list(getattr(pool, "_processes", {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
