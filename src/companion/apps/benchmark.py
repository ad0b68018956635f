"""``companion bench``: what users feel, measured on the figure-8 scenario (60 s, 1,200 steps).

* ``step_us``: wall time of one ``step`` per registered controller, alone and in the standard
  stack (supervisor with the person tracker, avoidance, controller) with ideal sensing, and
  for the stack also with ``realistic`` sensing: median and 99th percentile over every step
  of :data:`LATENCY_ROUNDS` episodes after a warm-up episode, all round-robin (so a passing
  load on the machine does not fall on one of them); ``scipy`` is the LQR step with scipy's
  Riccati solver;
* ``dare_us``: the reference unit, one scipy ``solve_discrete_are`` and gain on the 5x5
  augmented model (median and p99 over operating points of the figure-8), measured in the
  same run, and ``stack_per_dare``: each stack median over it;
* ``throughput``: full-stack episodes through the runner (:func:`companion.sim.runner.run_many`),
  controller steps per second with one worker process and with one per CPU;
* ``first_step_s``: a fresh process's first full-stack step (import included, an evasive check
  forced so that every kernel is needed), with an empty numba cache (compilation) and with the
  cache that run left (loading);
* ``peak_rss_mb``: the largest peak resident memory of this process and its children.
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
from collections.abc import Callable

import numpy as np

from companion.control import CONTROLLERS, Controller, make_bare, make_controller
from companion.control.lqr import augmented_model
from companion.model import slot_reference
from companion.params import Params
from companion.params.sensing import REALISTIC
from companion.riccati.reference import dlqr
from companion.sim.episode import run_episode
from companion.sim.runner import EpisodeSpec, default_workers, run_many
from companion.sim.scenario import Scenario, load_scenario
from companion.types import Command, Observation, Pose

#: Timed episodes per controller.
LATENCY_ROUNDS = 3


def timed(controller: Controller, seconds: list[float]) -> Controller:
    """``controller`` with its ``step`` timed: the wall time of every call goes to
    ``seconds`` (the instance keeps its class, so the episode sees the same stack)."""
    step = controller.step

    def timed_step(obs: Observation) -> Command:
        t = time.perf_counter()
        cmd = step(obs)
        seconds.append(time.perf_counter() - t)
        return cmd

    controller.step = timed_step
    return controller


def latencies_us(makers: dict[str, tuple[Callable[[], Controller], Params]], sc: Scenario,
                 duration: float, rounds: int = LATENCY_ROUNDS,
                 progress: Callable[[str], None] = lambda s: None) -> dict[str, dict]:
    """Median and p99 (us) of the step time of each controller of ``makers`` (a factory and
    the parameters of its episodes) over ``rounds`` episodes of ``sc``'s person (``duration``
    s) after a warm-up episode each, the controllers visited in turn; ``progress`` after the
    warm-up and each round."""
    seconds: dict[str, list[float]] = {name: [] for name in makers}
    runs = {name: (timed(make(), seconds[name]), params)
            for name, (make, params) in makers.items()}
    for name, (c, params) in runs.items():
        run_episode(c, sc.person, params, duration)
        seconds[name].clear()
    progress("  warm-up done")
    for k in range(rounds):
        for c, params in runs.values():
            run_episode(c, sc.person, params, duration)
        progress(f"  round {k + 1} of {rounds} done")
    return {name: {"median": float(np.median(np.asarray(s) * 1e6)),
                   "p99": float(np.percentile(np.asarray(s) * 1e6, 99))}
            for name, s in seconds.items()}


def dare_us(sc: Scenario, points: int = 200, repeats: int = 5) -> dict[str, float]:
    """Median and p99 (us) of one scipy ``solve_discrete_are`` plus gain (``dlqr`` without
    its input checks) on the LQR's 5x5 augmented model, at ``points`` operating points (the
    person on the figure-8 with the robot in its slot), each solved ``repeats`` times."""
    p = sc.params
    f, d = p.formation, p.robot.d
    q, r = np.diag(p.lqr.q), np.diag(p.lqr.r)
    seconds = []
    for t in np.linspace(0.0, 60.0, points, endpoint=False):
        h = sc.person.state(float(t))
        ref = slot_reference(h.v, h.omega, f.distance, f.bearing, d)
        a, b = augmented_model((f.distance, f.bearing, ref.beta), (ref.v, ref.omega),
                               (h.v, h.omega), p)
        for _ in range(repeats):
            t0 = time.perf_counter()
            dlqr(a, b, q, r, check=False)
            seconds.append(time.perf_counter() - t0)
    us = np.asarray(seconds) * 1e6
    return {"median": float(np.median(us)), "p99": float(np.percentile(us, 99))}


def episodes(sc: Scenario, n: int, duration: float, controller: str = "lqr"
             ) -> list[EpisodeSpec]:
    """``n`` full-stack episodes of ``sc`` (``duration`` s) from starts up to 0.5 m and
    0.5 rad off the slot."""
    rng = np.random.default_rng(0)
    h0 = sc.person.state(0.0)
    specs = []
    for i in range(n):
        dx, dy, dth = rng.uniform(-0.5, 0.5, 3)
        start = Pose(h0.x + 0.75 + dx, h0.y - 1.0 + dy, h0.theta + dth)
        specs.append(EpisodeSpec(controller, sc.person, sc.params, duration, start=start,
                                 seed=i))
    return specs


def steps_per_s(specs: list[EpisodeSpec], workers: int) -> float:
    """Controller steps per second of the runner over ``specs`` with ``workers`` processes."""
    t = time.perf_counter()
    logs = run_many(specs, workers, summarize=len)
    return sum(logs) / (time.perf_counter() - t)


_FIRST_STEP = """
import time
t = time.perf_counter()
from companion.control import make_controller
from companion.params import Params
from companion.types import Observation, PersonState, Pose
make_controller("lqr", Params()).step(Observation(0.0, Pose(0.0, -0.7, 0.5),
                                      PersonState(0.0, 0.0, 0.0, 1.0, 0.0)))
print(time.perf_counter() - t)
"""


def first_step_seconds() -> dict[str, float]:
    """Seconds to a fresh process's first full-stack step: with an empty numba cache, then
    with the cache it left."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        runs = [float(subprocess.run([sys.executable, "-c", _FIRST_STEP], env=env,
                                     check=True, capture_output=True, text=True).stdout)
                for _ in range(2)]
    return {"empty_cache": runs[0], "warm_cache": runs[1]}


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


def run(n_episodes: int = 48, duration: float = 60.0, workers: int | None = None,
        first_step: bool = True, progress: Callable[[str], None] = lambda s: None) -> dict:
    """All figures of ``companion bench`` as a JSON-ready dict (module docstring); episodes
    last ``duration`` s."""
    sc = load_scenario("figure8")
    workers = workers or default_workers()
    result: dict = {"machine": {"cpu": cpu_name(), "cpus": os.cpu_count(),
                                "python": platform.python_version()},
                    "scenario": sc.name, "episode_steps": int(round(duration / sc.params.dt))}
    if first_step:
        progress("first full-stack step in a fresh process (numba compile, then cached)")
        result["first_step_s"] = first_step_seconds()
    progress(f"step latency: every controller alone and stacked (ideal and realistic "
             f"sensing), and the lqr with scipy's solver, {LATENCY_ROUNDS} episodes each, "
             f"round-robin")
    ideal, realistic = sc.params, sc.params.replace(sensing=REALISTIC)
    makers: dict[str, tuple[Callable[[], Controller], Params]] = {}
    for name in CONTROLLERS:
        makers[name] = (lambda n=name: make_bare(n, ideal)), ideal
        makers["stack " + name] = (lambda n=name: make_controller(n, ideal)), ideal
        makers["realistic " + name] = (lambda n=name: make_controller(n, realistic)), realistic
    scipy = ideal.replace(lqr=dataclasses.replace(ideal.lqr, solver="scipy"))
    makers["scipy"] = (lambda: make_bare("lqr", scipy)), scipy
    latency = latencies_us(makers, sc, duration, progress=progress)
    result["step_us"] = {name: {"alone": latency[name], "stack": latency["stack " + name],
                                "stack_realistic": latency["realistic " + name]}
                         for name in CONTROLLERS}
    result["step_us"]["lqr with scipy"] = {"alone": latency["scipy"]}
    progress("the reference unit: scipy's solve_discrete_are and gain on the 5x5 model")
    dare = result["dare_us"] = dare_us(sc)
    result["stack_per_dare"] = {
        name: {where: s[where]["median"] / dare["median"]
               for where in ("stack", "stack_realistic")}
        for name, s in result["step_us"].items() if "stack" in s}
    specs = episodes(sc, n_episodes, duration)
    progress(f"full-stack throughput: {n_episodes} episodes with 1 worker, then {workers}")
    one = steps_per_s(specs, 1)
    progress(f"  1 worker: {one:,.0f} steps/s")
    many = steps_per_s(specs, workers)
    result["throughput"] = {"episodes": n_episodes, "workers": workers,
                            "steps_per_s_one_worker": one, "steps_per_s_all_workers": many}
    result["peak_rss_mb"] = peak_rss_mb()
    return result


def text(result: dict) -> str:
    """Human-readable table of :func:`run`'s result."""
    m = result["machine"]
    lines = [f"companion bench on {m['cpu']} ({m['cpus']} CPUs, Python {m['python']}), "
             f"{result['scenario']} scenario, {result['episode_steps']} steps per episode",
             f"  {'step (us)':22s} {'alone median':>12s} {'p99':>8s} {'stack median':>13s} "
             f"{'p99':>8s} {'realistic median':>17s} {'p99':>8s}"]
    for name, s in result["step_us"].items():
        tail = "".join(f" {s[k]['median']:{w}.1f} {s[k]['p99']:8.1f}"
                       for k, w in (("stack", 13), ("stack_realistic", 17)) if k in s)
        lines.append(f"  {name:22s} {s['alone']['median']:12.1f} {s['alone']['p99']:8.1f}{tail}")
    dare, ratio = result["dare_us"], result["stack_per_dare"]["lqr"]
    lines.append(f"  scipy solve_discrete_are + gain (5x5): {dare['median']:.1f} us median, "
                 f"{dare['p99']:.1f} p99; the lqr stack costs {ratio['stack']:.2f} of it "
                 f"(ideal sensing), {ratio['stack_realistic']:.2f} (realistic)")
    tp = result["throughput"]
    lines.append(f"  full stack, {tp['episodes']} episodes: "
                 f"{tp['steps_per_s_one_worker']:,.0f} steps/s with 1 worker, "
                 f"{tp['steps_per_s_all_workers']:,.0f} with {tp['workers']}")
    if "first_step_s" in result:
        fs = result["first_step_s"]
        lines.append(f"  first full-stack step in a fresh process: {fs['empty_cache']:.1f} s "
                     f"with an empty numba cache, {fs['warm_cache']:.2f} s with a warm one")
    lines.append(f"  peak memory: {result['peak_rss_mb']:.0f} MB")
    return "\n".join(lines)
