"""``companion bench``: controller step latency, the scipy reference, batch throughput, memory.

Everything is measured in one run on the figure-8 scenario (Table 2, 60 s, 1,200 steps):

* ``step_us``: wall time of ``controller.step`` for each registered controller alone (no
  avoidance layer, no supervisor): median and 99th percentile over every step of
  ``LATENCY_ROUNDS`` episodes, after a warm-up episode. The episodes of all controllers
  (alone, stacked and the scipy reference) run round-robin, so that a passing load on the
  machine does not fall on one controller's measurement only;
* ``stack_step_us``: the same for the standard stack (:func:`companion.control.make_controller`:
  avoidance layer and safety supervisor around the controller);
* ``scipy_step_us``: the LQR step with ``lqr.solver = "scipy"`` (scipy's
  ``solve_discrete_are``), and ``speedup_vs_scipy`` = its median over the compiled one;
* ``batch_steps_per_s``: controller steps per second of the compiled batch
  (:mod:`companion.sim.fast_batch`) over N figure-8 episodes of the LQR (the scenario as
  defined: exact person observations) from different starts: the median of
  ``BATCH_ROUNDS`` runs, made round-robin with the other batches (all runs in
  ``batch.steps_per_s_runs``);
  ``batch_steps_per_s_by_controller``: the same for lqr, pid, vsm and ic;
  ``batch_noisy_steps_per_s``: the LQR with sensor noise and a different seed per episode; ``stack_batch_steps_per_s``: the standard
  stack in worker processes (:func:`companion.sim.batch.run_batch`, backend "processes") over
  N / 10 noisy episodes;
* ``compile_s`` / ``warmup_s``: first LQR step in a fresh process with an empty numba cache
  (compilation) and with the cache filled (loading); ``batch_compile_s`` /
  ``batch_warmup_s``: the same for a first small batch;
* ``peak_rss_mb``: the larger of this process's peak resident memory and that of its
  largest child process (stack workers, compile-time processes).
"""

from __future__ import annotations

import dataclasses
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from typing import Callable

import numpy as np

from companion.control import CONTROLLERS, make_controller
from companion.control.base import Command, Controller, Observation, Pose
from companion.params import Params
from companion.sim.batch import EpisodeSpec, default_workers, run_batch
from companion.sim.episode import SensorNoise, run_episode
from companion.sim.scenario import Scenario, load_scenario


class Timed:
    """A controller wrapper that records the wall time of every ``step``."""

    def __init__(self, inner: Controller):
        self.inner = inner
        self.seconds: list[float] = []

    def reset(self) -> None:
        self.inner.reset()

    def step(self, obs: Observation) -> Command:
        t = time.perf_counter()
        cmd = self.inner.step(obs)
        self.seconds.append(time.perf_counter() - t)
        return cmd

    def applied(self, cmd: Command) -> None:
        self.inner.applied(cmd)


#: Timed episodes per controller in :func:`latencies_us`.
LATENCY_ROUNDS = 3
#: Runs of each compiled batch in :func:`run` (round-robin; the median is reported).
BATCH_ROUNDS = 3


def latencies_us(makers: dict[str, tuple[Callable[[], Controller], Params]], sc: Scenario,
                 duration: float, rounds: int = LATENCY_ROUNDS) -> dict[str, dict]:
    """Median and 99th percentile (us) of the step time of each controller of ``makers``
    (name -> (factory, params)) over every step of ``rounds`` episodes, after a warm-up
    episode each; the rounds visit the controllers in turn."""
    timed = {name: Timed(make()) for name, (make, _) in makers.items()}
    for name, (_, params) in makers.items():
        run_episode(timed[name], sc.person, params, duration)
        timed[name].seconds.clear()
    for _ in range(rounds):
        for name, (_, params) in makers.items():
            run_episode(timed[name], sc.person, params, duration)
    out = {}
    for name, t in timed.items():
        us = np.asarray(t.seconds) * 1e6
        out[name] = {"median": float(np.median(us)), "p99": float(np.percentile(us, 99))}
    return out


def batch_specs(sc: Scenario, n: int, duration: float, noisy: bool = False,
                stack: bool = False, controller: str = "lqr") -> list[EpisodeSpec]:
    """``n`` figure-8 episodes of the bare ``controller`` (or the standard stack) from starts
    up to 0.5 m and 0.5 rad off the slot; with ``noisy``, sensor noise (0.02 in SI units on
    every observed value) and seed i for episode i."""
    rng = np.random.default_rng(0)
    noise = SensorNoise(position=0.02, heading=0.02, speed=0.02, turn_rate=0.02) if noisy \
        else SensorNoise()
    h0 = sc.person.state(0.0)
    specs = []
    for i in range(n):
        dx, dy, dth = rng.uniform(-0.5, 0.5, 3)
        start = Pose(h0.x + 0.75 + dx, h0.y - 1.0 + dy, h0.theta + dth)
        specs.append(EpisodeSpec(controller, sc.person, sc.params, duration, start=start,
                                 seed=i, noise=noise, stack=stack))
    return specs


_FIRST_STEP = """
import time
t = time.perf_counter()
from companion.control import LqrController, Observation, PersonState, Pose
from companion.params import Params
LqrController(Params()).step(Observation(0.0, Pose(0.0, -1.0, 0.0),
                                         PersonState(0.0, 0.0, 0.0, 1.0, 0.0)))
print(time.perf_counter() - t)
"""

_FIRST_BATCH = """
import time
t = time.perf_counter()
from companion.benchmark import batch_specs
from companion.sim.fast_batch import run_fast_batch
from companion.sim.scenario import load_scenario
run_fast_batch(batch_specs(load_scenario("figure8"), 2, 1.0, noisy=True))
print(time.perf_counter() - t)
"""


def first_call_seconds(script: str) -> tuple[float, float]:
    """Seconds ``script`` reports in a fresh process: with an empty numba cache
    (compilation), then with the cache it left (loading)."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        runs = [float(subprocess.run([sys.executable, "-c", script], env=env,
                                     check=True, capture_output=True, text=True).stdout)
                for _ in range(2)]
    return runs[0], runs[1]


def cpu_name() -> str:
    """The CPU model (from /proc/cpuinfo on Linux), else the machine type."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def peak_rss_mb() -> float:
    """Peak resident set size (MB) of this process and of its largest finished child."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return max(own, children) / 1024.0   # Linux reports kB


def run(episodes: int = 1000, duration: float = 60.0, workers: int | None = None,
        compile_time: bool = True, progress: Callable[[str], None] = lambda s: None) -> dict:
    """All figures of ``companion bench`` as a JSON-ready dict (see the module docstring)."""
    sc = load_scenario("figure8")
    result: dict = {"machine": {"cpu": cpu_name(),
                                "cpus": os.cpu_count(), "python": platform.python_version()},
                    "scenario": sc.name, "episode_steps": int(round(duration / sc.params.dt))}
    if compile_time:
        progress("first LQR step in a fresh process (numba compile, then cached)")
        result["compile_s"], result["warmup_s"] = first_call_seconds(_FIRST_STEP)
        progress("first batch in a fresh process (numba compile, then cached)")
        result["batch_compile_s"], result["batch_warmup_s"] = first_call_seconds(_FIRST_BATCH)
    progress(f"step latency: every controller alone and stacked, and the lqr with scipy's "
             f"solve_discrete_are, {LATENCY_ROUNDS} episodes each, round-robin")
    makers: dict[str, tuple[Callable[[], Controller], Params]] = {}
    for name, entry in CONTROLLERS.items():
        params = entry.adjust(sc.params)
        makers[name] = (lambda e=entry, p=params: e.factory(p), params)
        makers["stack " + name] = (lambda n=name: make_controller(n, sc.params), sc.params)
    scipy_params = sc.params.replace(lqr=dataclasses.replace(sc.params.lqr, solver="scipy"))
    makers["scipy"] = (lambda: CONTROLLERS["lqr"].factory(scipy_params), scipy_params)
    latency = latencies_us(makers, sc, duration)
    result["step_us"] = {name: latency[name] for name in CONTROLLERS}
    result["stack_step_us"] = {name: latency["stack " + name] for name in CONTROLLERS}
    result["scipy_step_us"] = latency["scipy"]
    result["speedup_vs_scipy"] = (result["scipy_step_us"]["median"]
                                  / result["step_us"]["lqr"]["median"])
    workers = workers or default_workers()
    run_batch(batch_specs(sc, 2, 1.0, noisy=True) + batch_specs(sc, 2, 1.0, controller="pid"),
              workers)                                                # load the kernels
    configs = (("lqr", False), ("lqr", True), ("pid", False), ("vsm", False), ("ic", False))
    rates: dict[tuple[str, bool], list[float]] = {c: [] for c in configs}
    seconds: list[float] = []
    finite = True
    for round_ in range(BATCH_ROUNDS):
        for name, noisy in configs:
            progress(f"compiled batch, round {round_ + 1} of {BATCH_ROUNDS}: {episodes} "
                     f"episodes of {result['episode_steps']} steps, {name}"
                     + (", sensor noise" if noisy else ""))
            specs = batch_specs(sc, episodes, duration, noisy=noisy, controller=name)
            t = time.perf_counter()
            metrics = run_batch(specs, workers, backend="compiled")
            elapsed = time.perf_counter() - t
            rates[(name, noisy)].append(sum(m["steps"] for m in metrics) / elapsed)
            if (name, noisy) == ("lqr", False):
                seconds.append(elapsed)
                finite = finite and all(m["finite"] for m in metrics)
    median = {c: float(np.median(r)) for c, r in rates.items()}
    result["batch_steps_per_s"] = median[("lqr", False)]
    result["batch_noisy_steps_per_s"] = median[("lqr", True)]
    result["batch_steps_per_s_by_controller"] = {name: median[(name, False)]
                                                 for name, noisy in configs if not noisy}
    result["batch"] = {"episodes": episodes, "workers": workers,
                       "seconds": float(np.median(seconds)), "all_finite": finite,
                       "steps_per_s_runs": rates[("lqr", False)]}
    stack_episodes = max(1, episodes // 10)
    progress(f"standard stack in worker processes: {stack_episodes} episodes")
    specs = batch_specs(sc, stack_episodes, duration, noisy=True, stack=True)
    t = time.perf_counter()
    metrics = run_batch(specs, workers, backend="processes")
    result["stack_batch_steps_per_s"] = sum(m["steps"] for m in metrics) / (
        time.perf_counter() - t)
    result["peak_rss_mb"] = peak_rss_mb()
    return result


def text(result: dict) -> str:
    """Human-readable table of :func:`run`'s result."""
    lines = [f"companion bench on {result['machine']['cpu']} ({result['machine']['cpus']} CPUs, "
             f"Python {result['machine']['python']}), {result['scenario']} scenario, "
             f"{result['episode_steps']} steps per episode"]
    lines.append(f"  {'controller step (us)':28s} {'median':>9s} {'p99':>9s}"
                 f" {'stack median':>13s} {'stack p99':>10s}")
    for name, s in result["step_us"].items():
        st = result["stack_step_us"][name]
        lines.append(f"  {name:28s} {s['median']:9.1f} {s['p99']:9.1f} {st['median']:13.1f}"
                     f" {st['p99']:10.1f}")
    sc = result["scipy_step_us"]
    lines.append(f"  {'lqr, scipy solve_discrete_are':28s} {sc['median']:9.1f} {sc['p99']:9.1f}")
    lines.append(f"  speed-up of the lqr step over scipy: {result['speedup_vs_scipy']:.0f}x")
    b = result["batch"]
    runs = b["steps_per_s_runs"]
    lines.append(f"  compiled batch, {b['episodes']} episodes, {b['workers']} threads, median of "
                 f"{len(runs)} runs: {result['batch_steps_per_s']:,.0f} lqr steps/s (exact "
                 f"observations; runs {min(runs):,.0f}-{max(runs):,.0f}), "
                 f"{result['batch_noisy_steps_per_s']:,.0f} with sensor noise; "
                 + ", ".join(f"{name} {rate:,.0f}" for name, rate
                             in result["batch_steps_per_s_by_controller"].items()
                             if name != "lqr"))
    lines.append(f"  standard stack in worker processes: {result['stack_batch_steps_per_s']:,.0f}"
                 f" controller steps/s")
    if "compile_s" in result:
        lines.append(f"  first lqr step in a fresh process: {result['compile_s']:.1f} s with an "
                     f"empty numba cache, {result['warmup_s']:.2f} s cached; first batch: "
                     f"{result['batch_compile_s']:.1f} s, {result['batch_warmup_s']:.2f} s cached")
    lines.append(f"  peak memory: {result['peak_rss_mb']:.0f} MB")
    return "\n".join(lines)
