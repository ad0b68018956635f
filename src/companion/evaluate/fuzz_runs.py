"""The closed-loop fuzz over many episodes (:mod:`companion.sim.fuzz` draws and counts one):
a plan of episodes as a suite whose results are their counts (:func:`fuzz_suite`, run by
the engine of :mod:`companion.evaluate.run`), replaying one, and the totals, failure rates,
CSV rows and table that ``companion fuzz`` writes and prints (docs/safety.md)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from pathlib import Path

from companion import metrics
from companion.evaluate.generators import suite_of
from companion.evaluate.run import run_results
from companion.evaluate.suite import Episode, Suite
from companion.params import PROFILES, Params, SensingParams
from companion.sim import fuzz
from companion.sim.runner import EpisodeSpec, run_one
from companion.types import Log

COLUMNS = (*(f.name for f in dataclasses.fields(fuzz.Case)), *fuzz.COUNTS, "failed")


def fuzz_suite(episodes: Sequence[tuple[int, str, str]], base: Params | None = None,
               profiles: Mapping[str, SensingParams] = PROFILES
               ) -> tuple[Suite, list[fuzz.Case]]:
    """The ``episodes`` of :func:`~companion.sim.fuzz.plan` drawn (on the parameters
    ``base``, default Table 1's, and the sensing ``profiles`` by name) as a suite whose
    results are their counts (:func:`counts`; motion ``fuzz``, side ``drawn``, the episode's
    seed as its seed), and their cases, in order."""
    base = base or Params()
    drawn = [fuzz.draw(*episode, base=base, profiles=profiles) for episode in episodes]
    suite = suite_of("fuzz", (Episode("fuzz", "fuzz", "drawn", c.sensing, c.controller, c.seed,
                                      spec) for c, spec in drawn),
                     partial(counts, params=base), parts=(base, dict(profiles)))
    return suite, [case for case, _ in drawn]


def counts(spec: EpisodeSpec, params: Params) -> dict:
    """Run one fuzz episode: its counts (:func:`companion.sim.fuzz.spec_counts`, the
    thresholds of ``params``)."""
    return fuzz.spec_counts(run_one(spec), spec, params)


def run(episodes: Sequence[tuple[int, str, str]], workers: int | None,
        progress: Callable[[int], None] | None = None, base: Params | None = None,
        profiles: Mapping[str, SensingParams] = PROFILES, out: Path | None = None,
        dask: str | None = None) -> tuple[list[fuzz.Case], list[dict]]:
    """Run :func:`fuzz_suite` (``workers``, ``dask``: the backends of
    :func:`~companion.evaluate.run.run_results`; with ``out``, each episode's counts are kept
    there and a killed run resumes); its cases and counts, in order. ``progress(done)``."""
    suite, cases = fuzz_suite(episodes, base, profiles)
    results = run_results(suite, out, workers, dask,
                          progress and (lambda done, total: progress(done)))
    return cases, results


def replay(seed: int, controller: str, sensing: str, base: Params | None = None,
           profiles: Mapping[str, SensingParams] = PROFILES) -> tuple[fuzz.Case, dict, Log]:
    """One episode again: its case, counts and log."""
    base = base or Params()
    case, spec = fuzz.draw(seed, controller, sensing, base, profiles)
    log = run_one(spec)
    return case, fuzz.episode_counts(log, base, spec.obstacles), log


def csv_rows(cases: Sequence[fuzz.Case], counts: Sequence[dict]) -> list[tuple]:
    return [(*dataclasses.astuple(c), *(n[k] for k in fuzz.COUNTS), int(fuzz.failed(n)))
            for c, n in zip(cases, counts)]


def grouped(cases: Sequence[fuzz.Case], counts: Sequence[dict],
            key: Callable[[fuzz.Case], str]) -> dict[str, dict]:
    """:func:`companion.sim.fuzz.totals` per ``key`` of the case, in order of appearance."""
    groups: dict[str, list[dict]] = {}
    for c, n in zip(cases, counts):
        groups.setdefault(key(c), []).append(n)
    return {name: fuzz.totals(rows) for name, rows in groups.items()}


def by_pair(cases: Sequence[fuzz.Case], counts: Sequence[dict]) -> tuple[dict[str, dict], dict]:
    """Totals per "controller/sensing", in the order the pairs first appear, and of all."""
    return (grouped(cases, counts, lambda c: f"{c.controller}/{c.sensing}"),
            fuzz.totals(counts))


def failure_rates(cases: Sequence[fuzz.Case], counts: Sequence[dict]) -> dict[str, dict]:
    """Per sensing profile: the share of episodes the robot failed by its own doing
    (:func:`companion.sim.fuzz.robot_failed`) with its exact 95 % interval. Failures are
    rare and clumped in a few episodes, so a difference between two runs means something only
    where these intervals part."""
    out = {}
    for sensing, t in grouped(cases, counts, lambda c: c.sensing).items():
        k, n = t["robot_failed_episodes"], t["episodes"]
        lo, hi = metrics.binomial_interval(k, n)
        out[sensing] = {"episodes": n, "robot_failed_episodes": k, "rate": k / n,
                        "ci95": [lo, hi]}
    return out


#: The fuzz's walker is blind (docs/safety.md, "Which walker is which"): it turns or sets off
#: into the robot within tenths of a second. Against it under any sensing but ``ideal`` the
#: exact 95 % upper bound of the robot-caused failure rate must be at most this.
BLIND_WALKER_BOUND = 0.01


def missed_criteria(rates: dict[str, dict]) -> list[str]:
    """The fuzz's criteria each sensing profile misses, one line each: with ``ideal`` sensing
    no robot-caused failure at all; with any other, the upper end of the 95 % interval of the
    robot-caused failure rate at most :data:`BLIND_WALKER_BOUND` (which needs at least 299
    episodes without one). Contacts the walker caused count for neither."""
    out = []
    for sensing, r in rates.items():
        k, n, hi = r["robot_failed_episodes"], r["episodes"], r["ci95"][1]
        if sensing == "ideal":
            if k:
                out.append(f"ideal: the robot failed by its own doing in {k} of {n} episodes "
                           f"(criterion: none)")
        elif hi > BLIND_WALKER_BOUND:
            out.append(f"{sensing}: the robot-caused failure rate's 95 % upper bound is "
                       f"{hi:.1%} over {n} episodes (criterion: at most "
                       f"{BLIND_WALKER_BOUND:.0%}; {k} failed)")
    return out


def rates_text(rates: dict[str, dict]) -> str:
    """The lines :func:`failure_rates` prints, one per sensing profile."""
    return "\n".join(
        f"{sensing}: the robot failed by its own doing in {r['robot_failed_episodes']} of "
        f"{r['episodes']} episodes ({r['rate']:.1%}, 95 % interval {r['ci95'][0]:.1%} to "
        f"{r['ci95'][1]:.1%})" for sensing, r in rates.items())


def failures(cases: Sequence[fuzz.Case], counts: Sequence[dict]) -> list[dict]:
    return [{"seed": c.seed, "controller": c.controller, "sensing": c.sensing,
             **{k: n[k] for k in ("person_collisions", "person_collisions_robot",
                                  "person_collisions_unescapable", "obstacle_collisions",
                                  "violations", "violations_estimate",
                                  "violations_walkthrough", "nonfinite_steps",
                                  "min_person_distance_m", "min_obstacle_clearance_m")}}
            for c, n in zip(cases, counts) if fuzz.failed(n)]


def table(pairs: dict[str, dict], total: dict) -> str:
    """The printed table: per pair and in all, collisions (robot-caused, and of the person's
    those no command could escape), protective steps (robot-caused outside walk-throughs,
    of them from the estimate, and during walk-throughs), statuses and the closest approach."""
    w = max([22, *map(len, pairs)])   # a sensing file's path can be long
    head = (f"{'controller/sensing':{w}s} {'episodes':>8s} {'steps':>9s} {'person':>6s} "
            f"{'(rob.)':>6s} {'(unesc.)':>8s} {'obstacle':>8s} {'inside':>6s} {'robot':>5s} "
            f"{'(est.)':>6s} {'(walk)':>6s} {'nonfin':>6s} {'ok':>6s} {'degr.':>6s} "
            f"{'stop':>6s} {'closest':>7s}")
    lines = [f"{'':{w}s} {'':>8s} {'':>9s} {'collisions':>31s} {'protective steps':>28s}", head]
    for name, t in [*pairs.items(), ("all", total)]:
        n = max(t["steps"], 1)
        lines.append(
            f"{name:{w}s} {t['episodes']:8d} {t['steps']:9d} {t['person_collisions']:6d} "
            f"{t['person_collisions_robot']:6d} {t['person_collisions_unescapable']:8d} "
            f"{t['obstacle_collisions']:8d} {t['protective_steps']:6d} {t['violations']:5d} "
            f"{t['violations_estimate']:6d} {t['violations_walkthrough']:6d} "
            f"{t['nonfinite_steps']:6d} {t['ok_steps'] / n:6.1%} {t['degraded_steps'] / n:6.1%} "
            f"{t['stopped_steps'] / n:6.1%} {t['min_person_distance_m']:7.3f}")
    return "\n".join(lines)
