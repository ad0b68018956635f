"""Is the person tracker's uncertainty honest? Its innovations and errors against the
chi-square bands an honest filter keeps, and its position error against its own standard
deviation in closed loop, on real walkers and on the closed-loop fuzz's walker
(docs/sensing.md).

    python bench/tracker_consistency.py [--every N] [--episodes N] [--params FILE]
                                        [--open-loop-only]

First, open loop: the sensor of ``params`` (``realistic`` unless the file gives a [sensing]
table) detects the person of every ``--every``-th ETH/UCY walking track and the tracker
follows it alone. Each accepted detection's NIS (its position's squared Mahalanobis distance
from the prediction, chi-square with 2 degrees of freedom for an honest filter, and white, so
a track's mean over N detections lies in the chi-square band of 2N degrees of freedom 95 % of
the time) and the position NEES at every control instant (the true position's, against the
reported covariance: chi-square with 2 degrees of freedom per step) are compared with their
95 % bands. Then, closed loop:
Runs the default LQR with ``realistic`` sensing beside every ``--every``-th ETH/UCY walking
track (robot on the left and on the right) and beside the first ``--episodes`` walkers of
``companion fuzz`` (seed 0; up to 2 m/s, turnarounds, sharp turns), and prints for each the
percentiles of the estimate's position error at the control instant, of its standard
deviation (``person_est_std``: the larger axis), and the share of steps whose error exceeds 2
and 3 of them. For an error that is Gaussian with the reported covariance those shares are at
most 13.5 % and 1.1 % (the Rayleigh tails; at most, because the larger axis is used), so a
larger share means the tracker is overconfident on that kind of walker.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

import numpy as np
from scipy.stats import chi2

from companion.data import pedestrians
from companion.errors import CompanionError
from companion.evaluate import fuzz_runs, walkers
from companion.evaluate.generators import suite_of
from companion.evaluate.run import run_results
from companion.params import IDEAL, REALISTIC, Params, load_params
from companion.sim.recorded import RecordedPerson
from companion.sim.runner import EpisodeSpec, run_one
from companion.sim.sensing import PersonSensor, streams
from companion.tracking import PersonTracker

#: Rayleigh tails: P(|e| > k sigma) for a 2D Gaussian of per-axis std sigma.
RAYLEIGH = {2: float(np.exp(-2.0)), 3: float(np.exp(-4.5))}


def errors(log) -> np.ndarray:
    """(error, std) per step with an estimate."""
    e = np.hypot(log["person_est_x"] - log["person_x"], log["person_est_y"] - log["person_y"])
    s = log["person_est_std"]
    ok = np.isfinite(e) & np.isfinite(s) & (s > 0.0)
    return np.stack([e[ok], s[ok]])


def closed_loop(spec: EpisodeSpec) -> np.ndarray:
    """Run one episode of the engine: its :func:`errors`."""
    return errors(run_one(spec))


def report(name: str, parts: list[np.ndarray]) -> None:
    e, s = np.concatenate(parts, axis=1)
    r = e / s
    print(f"{name}: {len(e):,} steps; error p50/p90/p99 {np.percentile(e, 50):.3f}/"
          f"{np.percentile(e, 90):.3f}/{np.percentile(e, 99):.3f} m; std p50/p99 "
          f"{np.percentile(s, 50):.3f}/{np.percentile(s, 99):.3f} m; error/std p99 "
          f"{np.percentile(r, 99):.2f}; beyond 2 std {np.mean(r > 2):.1%} "
          f"(Gaussian <= {RAYLEIGH[2]:.1%}), beyond 3 std {np.mean(r > 3):.2%} "
          f"(<= {RAYLEIGH[3]:.2%})")


def open_loop(track: pedestrians.Track, params: Params, seed: int
              ) -> tuple[np.ndarray, np.ndarray]:
    """The NIS of every accepted detection and the position NEES at every control instant
    of the tracker alone following ``track``'s person through ``params``' sensor."""
    person = RecordedPerson(track.t, track.x, track.y)
    rng = streams(seed)
    sensor = PersonSensor(params, person, rng["person_sensor"], rng["person_dropout"])
    tracker = PersonTracker(params.tracker, params.sensing)
    nis, nees = [], []
    for k in range(int(person.duration / params.dt) + 1):
        t = k * params.dt
        tracker.add(sensor.detections(t), t)
        nis += tracker.innovations
        est = tracker.estimate(t)
        if est is None or not person.observed(t):
            continue
        truth = person.state(t)
        e = np.array((truth.x - est.state.x, truth.y - est.state.y))
        nees.append(float(e @ np.linalg.solve(est.covariance[:2, :2], e)))
    return np.array(nis), np.array(nees)


def report_bands(name: str, runs: list[tuple[np.ndarray, np.ndarray]]) -> None:
    """Print the NIS and NEES against their 95 % chi-square bands."""
    inside = below = 0
    for nis, _ in runs:
        n = len(nis)
        low, high = chi2.ppf(0.025, 2 * n) / n, chi2.ppf(0.975, 2 * n) / n
        below += nis.mean() < low
        inside += low <= nis.mean() <= high
    nis = np.concatenate([r[0] for r in runs])
    nees = np.concatenate([r[1] for r in runs])
    n = len(nis)
    low, high = chi2.ppf(0.025, 2 * n) / n, chi2.ppf(0.975, 2 * n) / n
    print(f"{name}: NIS over {n:,} detections: mean {nis.mean():.2f} (band {low:.2f}-"
          f"{high:.2f}), beyond its 95 % point {np.mean(nis > chi2.ppf(0.95, 2)):.1%} (5 %); "
          f"tracks whose mean NIS is inside its band {inside}/{len(runs)} "
          f"({below} below, {len(runs) - inside - below} above)")
    lo1, hi1 = chi2.ppf(0.025, 2), chi2.ppf(0.975, 2)
    print(f"{name}: NEES over {len(nees):,} steps: mean {nees.mean():.2f} (2), median "
          f"{np.median(nees):.2f} ({chi2.ppf(0.5, 2):.2f}), below {lo1:.3f} "
          f"{np.mean(nees < lo1):.1%} (2.5 %), above {hi1:.2f} {np.mean(nees > hi1):.1%} "
          f"(2.5 %)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=3, help="every N-th walking track (3)")
    ap.add_argument("--episodes", type=int, default=60, help="fuzz walkers (60)")
    ap.add_argument("--params", help="TOML file of parameter overrides")
    ap.add_argument("--open-loop-only", action="store_true", help="skip the closed loop")
    args = ap.parse_args()
    try:
        base = load_params(args.params) if args.params else Params()
    except CompanionError as exc:
        sys.exit(f"tracker_consistency: {exc}")
    params = base.replace(sensing=REALISTIC) if base.sensing == IDEAL else base
    tracks = pedestrians.select_tracks(pedestrians.load_scenes())[::args.every]
    report_bands(f"ETH/UCY walkers, open loop ({len(tracks)} tracks)",
                 [open_loop(t, params, seed) for seed, t in enumerate(tracks)])
    if args.open_loop_only:
        return
    suite = walkers.tracks_suite(["lqr"], ["realistic"], every=args.every)
    tracks = suite_of("tracker-tracks", (dataclasses.replace(e, spec=dataclasses.replace(
        e.spec, params=params.replace(formation=e.spec.params.formation)))
        for e in suite.episodes), closed_loop)
    report(f"ETH/UCY walkers ({len(tracks.episodes)} runs)", run_results(tracks))
    drawn, _ = fuzz_runs.fuzz_suite([(seed, "lqr", "realistic") for seed in range(args.episodes)],
                                    base)
    report(f"fuzz walkers ({args.episodes} episodes)",
           run_results(dataclasses.replace(drawn, row=closed_loop)))
    print(f"\nData: {pedestrians.CREDIT}")


if __name__ == "__main__":
    main()
