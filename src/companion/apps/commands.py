"""The commands of the ``companion`` command line (:mod:`companion.apps.cli` parses them).

Bad usage or bad input files raise :class:`~companion.errors.CompanionError` with one line naming
the file, line or key. Output files are written whole or not at all.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from collections.abc import Iterable, Iterator
from contextlib import nullcontext
from pathlib import Path

from companion import metrics
from companion.apps import animate, benchmark, fuzz, movie, plots, reproduce, table3, tune
from companion.apps.args import (
    UsageError,
    build_scenario,
    checked_controllers,
    duration_arg,
    file_params,
    floats_arg,
    int_arg,
    number_arg,
    output_dir,
    output_file,
    params_arg,
    ranged,
    seed_arg,
    workers_arg,
)
from companion.apps.logfile import LogCsv, Thinned, write_log
from companion.apps.progress import progress_bar
from companion.control import CONTROLLERS, lookup
from companion.data import pedestrians
from companion.evaluate import fuzz_runs, walkers
from companion.io import Outputs, save_figure, write_csv, write_json
from companion.params import Params
from companion.sim import convergence, soak
from companion.sim import fuzz as sim_fuzz
from companion.sim.runner import run_many, stream_one
from companion.sim.scenario import builtin_names, load_scenario
from companion.types import Log


def summary_lines(m: dict) -> list[str]:
    settle = m["settling_time_s"]
    return [
        f"  RMSE rho   {m['rmse_rho_m']:.4f} m ({m['rmse_rho_m'] * 100:.3f} cm)",
        f"  RMSE alpha {m['rmse_alpha_rad']:.4f} rad",
        f"  RMSE beta  {m['rmse_beta_rad']:.4f} rad (against beta_d = 0; turns need an offset)",
        f"  RMSV v     {m['rmsv_v_mps']:.4f} m/s,  RMSV omega {m['rmsv_omega_radps']:.4f} rad/s "
        f"({m['rmsv_omega_radps'] * 1000:.2f} mrad/s)",
        f"  min distance robot centre to person {m['min_person_distance_m']:.3f} m",
        f"  settling time {'never' if settle is None else f'{settle:.2f} s'}",
        f"  supervisor: ok {m['share_ok']:.1%}, degraded {m['share_degraded']:.1%}, "
        f"stopped {m['share_stopped']:.1%} of the time (reasons in log.csv)",
    ] + split_lines(m) + ([] if m.get("min_obstacle_clearance_m") is None else [
        f"  min obstacle clearance {m['min_obstacle_clearance_m']:.3f} m, "
        f"collisions {m['obstacle_collisions']}"])


def split_lines(m: dict) -> list[str]:
    """Where the slot error comes from (docs/sensing.md), when the run had an estimate."""
    if m.get("rms_estimate_error_m") is None:
        return []
    return [f"  slot error {m['rms_slot_error_m']:.4f} m RMS: the estimate's own "
            f"{m['rms_estimate_error_m']:.4f} m, tracking the estimated slot "
            f"{m['rms_tracking_error_m']:.4f} m; the keep-out moved the robot "
            f"{m['safety_shift_m']:.3f} m in all, on {m['safety_share']:.1%} of the steps"]




def started(blocks: Iterator[Log]) -> Iterator[Log]:
    """An episode's blocks with the first one already simulated, so that bad input is an
    error before any output is staged."""
    first = next(blocks)
    return itertools.chain((first,), blocks)


def _write_run(out: Path, sc, plot: bool, blocks: Iterable[Log], extra: dict | None = None
               ) -> tuple[dict, list[str]]:
    """Write ``companion run``'s files into ``out`` as the episode's blocks come (``extra``
    goes into metrics.json too); returns the metrics and the names of the files."""
    running = metrics.Running()
    thinned = Thinned(round(sc.duration / sc.params.dt))
    with LogCsv(out / "log.csv") as csv:
        for block in blocks:
            csv.log(block)
            running.add(block)
            if plot:
                thinned.add(block)
    m = {**running.value(), "scenario": sc.name, "controller": sc.controller, **(extra or {})}
    write_json(out / "metrics.json", m)
    written = ["log.csv", "metrics.json"]
    if plot:
        title = f"{sc.name} / {sc.controller}"
        runs = {sc.controller: thinned.log()}
        figures = [("trajectory.png", plots.trajectories(runs, title, obstacles=sc.obstacles,
                                                         avoidance=sc.params.avoidance,
                                                         footprint=sc.params.robot.radius)),
                   ("errors.png", plots.errors_over_time(runs, title)),
                   ("inputs.png", plots.inputs_over_time(runs, sc.params, title))]
        if sc.obstacles:
            figures.append(("avoidance.png", plots.avoidance_over_time(runs, sc.obstacles,
                                                                       sc.params, title)))
        for name, fig in figures:
            save_figure(fig, out / name)
            plots.close(fig)
            written.append(name)
    return m, written


def cmd_run(args: argparse.Namespace) -> int:
    sc = build_scenario(args)
    lookup(sc.controller)  # unknown names: ConfigError with a hint
    checked_controllers([sc.controller], sc.params, args.params or sc.source)
    out = output_dir(Path(args.out or Path("out") / sc.name))
    target = movie.target_arg(args.animate) if args.animate else None
    if args.bag:                            # the episode runs over the recorded graph
        from companion.apps.bags import bag_arg, run_recorded

        blocks = iter([run_recorded(sc, bag_arg(args.bag))])
    else:
        blocks = started(stream_one(sc.episode()))
    with Outputs(out, "run") as stage:      # the log goes to disk as the episode runs
        if target is None:
            m, written = _write_run(stage, sc, args.plot, blocks)
        else:                               # an animation needs the whole log at the end
            log = Log.concat(blocks)
            m, written = _write_run(stage, sc, args.plot, [log])
            written.append(animate.save_run(target, out, stage, sc, log))
    # Everything is written before anything is printed: a reader that goes away early
    # (| head) cannot cut the outputs short.
    print(f"{sc.name}: {sc.description}")
    print(f"controller {sc.controller}, {sc.duration:g} s, seed {sc.seed}, side bearing "
          f"{sc.params.formation.bearing:.4f} rad, distance {sc.params.formation.distance:g} m")
    print("\n".join(summary_lines(m)))
    print(f"wrote {', '.join(written)} in {out}")
    return 0


def cmd_scenarios(args: argparse.Namespace) -> int:
    for name in builtin_names():
        sc = load_scenario(name)
        print(f"{name:10s} {sc.description}")
    return 0


def cmd_convergence(args: argparse.Namespace) -> int:
    params = params_arg(args)
    checked_controllers([args.controller], params, args.params)
    speeds = ranged(floats_arg(args.speeds, len(args.speeds.split(",")), "--speeds"),
                    args.speeds, "--speeds", "V")
    duration = duration_arg(args.duration, dt=params.dt)
    settle_limit = number_arg(args.settle_limit, "--settle-limit", "S")
    workers = workers_arg(args)
    out = output_dir(Path(args.out or Path("out") / "convergence"))
    cases = list(convergence.cases(speeds))
    logs = run_many([convergence.episode(c, args.controller, params, duration) for c in cases],
                    workers)
    rows, runs, lines, failures = [], {}, [], 0
    for case, log in zip(cases, logs):
        m = metrics.compute(log)
        settle = m["settling_time_s"]
        ok = settle is not None and settle <= settle_limit \
            and m["min_person_distance_m"] >= 0.5
        failures += not ok
        rows.append((*convergence.csv_row(case, m), int(ok)))
        runs.setdefault(case.speed, []).append((case.label, case.side, log))
        lines.append(f"{case.speed:5.2f} {case.label:>10} {case.start.theta:8.3f} "
                     f"{case.side:>5} {'never' if settle is None else f'{settle:.2f}':>9} "
                     f"{m['min_person_distance_m']:10.3f}{'' if ok else '  FAIL'}")
    with Outputs(out, "convergence") as stage:
        write_csv(stage / "convergence.csv", (*convergence.CSV_COLUMNS, "ok"), rows)
        written = ["convergence.csv"]
        if args.plot:
            for speed, speed_runs in runs.items():
                fig = plots.convergence(speed_runs, f"Fig. 3: person at {speed:g} m/s, "
                                                    f"controller {args.controller}")
                name = f"fig3_{speed:g}mps.png"
                save_figure(fig, stage / name)
                plots.close(fig)
                written.append(name)
    print(f"{'speed':>5} {'start':>10} {'heading':>8} {'side':>5} {'settle_s':>9} "
          f"{'min_dist_m':>10}")
    print("\n".join(lines))
    print(f"{len(rows) - failures}/{len(rows)} runs settled within {settle_limit:g} s "
          f"and kept >= 0.5 m from the person")
    print(f"wrote {', '.join(written)} in {out}")
    return 0 if failures == 0 else 1


def cmd_pedestrians(args: argparse.Namespace) -> int:
    params = params_arg(args)
    controllers = list(CONTROLLERS) if args.controller == "all" else [args.controller]
    checked_controllers(controllers, params, args.params)
    sides = ("left", "right") if args.side == "both" else (args.side,)
    min_speed = number_arg(args.min_speed, "--min-speed", "MPS")
    min_duration = number_arg(args.min_duration, "--min-duration", "S")
    workers = workers_arg(args)
    tracks = pedestrians.select_tracks(pedestrians.load_scenes(args.data),
                                       min_mean_speed=min_speed, min_duration=min_duration)
    if not tracks:
        raise UsageError("no track is fast and long enough; lower --min-speed or --min-duration")
    out = output_dir(Path(args.out or Path("out") / "pedestrians"))
    print(f"{len(tracks)} tracks (mean speed > {min_speed:g} m/s, >= "
          f"{min_duration:g} s) x {len(sides)} side(s) x {len(controllers)} "
          f"controller(s), {args.sensing or 'ideal'} sensing")
    with progress_bar(len(tracks) * len(sides) * len(controllers), "episode") as progress:
        rows = walkers.evaluate(tracks, params, controllers, sides, workers, progress)
    with Outputs(out, "pedestrians") as stage:
        write_csv(stage / "pedestrians.csv", walkers.COLUMNS,
                  ([r[k] for k in walkers.COLUMNS] for r in rows))
    print(walkers_text(walkers.table(rows), walkers.paired(rows, controllers[0])))
    print(f"wrote pedestrians.csv in {out}\n")
    print(pedestrians.CREDIT)
    return 0


def walkers_text(table: dict, paired: dict) -> str:
    """The per-controller table and the paired comparison of ``companion pedestrians``."""
    lines = [f"{'controller':10s} {'runs':>5s} {'median rho cm':>13s} {'p90 rho cm':>10s} "
             f"{'median alpha':>12s} {'closest m':>9s}"]
    for name, r in table.items():
        lines.append(f"{name:10s} {r['runs']:5d} {r['median_rho_m'] * 100:13.2f} "
                     f"{r['p90_rho_m'] * 100:10.2f} {r['median_alpha_rad']:12.3f} "
                     f"{r['min_distance_m']:9.3f}")
    lines.append("where the slot error comes from (medians over runs of each run's RMS, cm; "
                 "the keep-out's displacement in m and the share of steps it acted)")
    lines.append(f"{'controller':10s} {'slot':>7s} {'estimate':>9s} {'tracking':>9s} "
                 f"{'keep-out m':>10s} {'acting':>7s}")
    for name, r in table.items():
        cells = [r[f"median_rms_{k}_error_m"] for k in ("slot", "estimate", "tracking")]
        lines.append(f"{name:10s} " + " ".join(
            f"{'-' if v is None else f'{v * 100:.2f}':>{w}s}" for v, w in zip(cells, (7, 9, 9)))
            + f" {r['median_safety_shift_m']:10.3f} {r['median_safety_share']:7.1%}")
    for name, r in paired.items():
        lines.append(f"paired with {name}: better rho in {r['better_rho']:.0%} of runs (median "
                     f"difference {r['median_diff_rho'] * 100:+.2f} cm), better alpha in "
                     f"{r['better_alpha']:.0%} ({r['median_diff_alpha']:+.3f} rad)")
    return "\n".join(lines)


def cmd_soak(args: argparse.Namespace) -> int:
    params = params_arg(args)
    checked_controllers([args.controller], params, args.params)
    duration = duration_arg(args.duration, dt=params.dt)
    seed = seed_arg(args.seed)
    out = output_dir(Path(args.out or Path("out") / "soak"))
    print(f"soak: {duration:g} s of a random walker among pillars (seed {seed}), "
          f"controller {args.controller}; about {duration / 25:.0f} s")
    spec = soak.soak_episode(duration, seed, args.controller, params)
    blocks = started(stream_one(spec))
    summary = soak.Summary(params)
    with Outputs(out, "soak") as stage:
        with LogCsv(stage / "log.csv") if args.log else nullcontext() as csv:
            for block in blocks:        # the log goes to disk as the episode runs
                summary.add(block)
                if csv:
                    csv.log(block)
        result = summary.value()
        write_json(stage / "soak.json", result)
    written = ["soak.json"] + ["log.csv"] * bool(args.log)
    for key, value in result.items():
        print(f"  {key:26s} {value:.4g}" if isinstance(value, float) else f"  {key:26s} {value}")
    ok = result["finite"] and result["person_collisions"] == 0 \
        and result["obstacle_collisions"] == 0
    print("PASS: no collision with the person or an obstacle, all values finite" if ok
          else "FAIL: a collision or a non-finite value")
    print(f"wrote {', '.join(written)} in {out}")
    return 0 if ok else 1


def cmd_fuzz(args: argparse.Namespace) -> int:
    controllers, profiles = fuzz.selection(args)
    sensings = tuple(profiles)
    base = file_params(args)
    out = output_dir(Path(args.out or Path("out") / "fuzz"))
    if args.replay is not None:
        if len(controllers) != 1 or len(sensings) != 1:
            raise UsageError("--replay: give the episode's controller and sensing as one "
                             "--controllers NAME and one --sensing NAME (fuzz.csv has them)")
        seed = int_arg(args.replay, "--replay", "SEED")
        case, counts, log = fuzz_runs.replay(seed, controllers[0], sensings[0], base, profiles)
        with Outputs(out, "fuzz-replay") as stage:
            write_log(stage / "log.csv", log)
            write_json(stage / "episode.json", {"case": vars(case), "counts": counts})
        print(json.dumps({"case": vars(case), "counts": counts}, indent=1))
        print(f"wrote log.csv, episode.json in {out}")
        return 1 if sim_fuzz.failed(counts) else 0
    steps = int_arg(args.steps, "--steps", "N")
    seed = seed_arg(args.seed)
    workers = workers_arg(args)
    start = time.monotonic()
    print(f"fuzz: >= {steps:,} steps, seed {seed}, {', '.join(controllers)} x "
          f"{', '.join(sensings)} sensing")
    episodes = sim_fuzz.plan(steps, seed, controllers, sensings)
    with progress_bar(len(episodes), "episode") as progress:
        cases, counts = fuzz_runs.run(episodes, workers, progress, base, profiles)
    pairs, total = fuzz_runs.by_pair(cases, counts)
    failed = fuzz_runs.failures(cases, counts)
    rates = fuzz_runs.failure_rates(cases, counts)
    report = {"steps_requested": steps, "seed": seed, "params": args.params,
              "controllers": list(controllers),
              "sensing": list(sensings), "wall_time_s": round(time.monotonic() - start, 1),
              "total": total, "by_pair": pairs, "robot_failure_rate": rates, "failed": failed}
    with Outputs(out, "fuzz") as stage:
        write_json(stage / "fuzz.json", report)
        write_csv(stage / "fuzz.csv", fuzz_runs.COLUMNS, fuzz_runs.csv_rows(cases, counts))
    print(fuzz_runs.table(pairs, total))
    for f in failed[:20]:
        print(f"FAIL seed {f['seed']} {f['controller']}/{f['sensing']}: replay with companion "
              f"fuzz --replay {f['seed']} --controllers {f['controller']} --sensing "
              f"{f['sensing']}")
    print(f"{len(failed)} of {len(cases)} episodes failed (a collision, a robot-caused "
          f"protective violation or a non-finite value); {report['wall_time_s']:g} s")
    print(fuzz_runs.rates_text(rates))
    print(f"wrote fuzz.json, fuzz.csv in {out}")
    return 1 if failed else 0


def cmd_reproduce(args: argparse.Namespace) -> int:
    workers = workers_arg(args)
    out = output_dir(Path(args.out or Path("out") / "reproduce"))
    names = reproduce.controllers()
    print(f"Reproducing Fig. 3, Table 2, Fig. 4, Fig. 7 and Table 3 with {', '.join(names)} "
          f"into {out}")
    with progress_bar(reproduce.episode_count(), "episode") as progress, \
            Outputs(out, "reproduce") as stage:
        result = reproduce.reproduce(stage, workers, progress)
    print(reproduce.fig3_summary(result.fig3))
    print("Table 2 (ours; paper's LQR/PID/VSM/IC rho and alpha at the right):")
    print(reproduce.table2_text(result.table2))
    print("Fig. 4 (figure-8 with the obstacle, every controller):")
    print(reproduce.fig4_text(result.fig4))
    print("Table 3 (em-tracker and realistic sensing, mean over seeds; the paper's LQR on the "
          "real robot at the right of ours under em-tracker):")
    print(table3.text(result.table3))
    print(f"wrote table2.csv, table2.md, table3.csv, table3.md, fig3.csv, fig4.csv, the "
          f"Fig. 3, 4, 7 PNGs and fig4.gif in {out}")
    return 0


def cmd_tune(args: argparse.Namespace) -> int:
    if args.suite:
        from companion.apps.evaluation import cmd_tune_suite
        return cmd_tune_suite(args)
    params = params_arg(args)
    checked_controllers([args.controller], params, args.params)
    budget, seed = int_arg(args.budget, "--budget"), seed_arg(args.seed)
    workers = workers_arg(args)
    print(f"tuning {args.controller}: {budget} candidates, seed {seed}, "
          f"scenarios {', '.join(c.name for c in tune.tuning_scenarios())}")
    cases = len(tune.tuning_scenarios())
    with progress_bar(budget * cases, "episode") as progress:
        result = tune.tune(args.controller, params, budget, seed, workers, progress)
    print(f"J: current gains {result.start_score:.4f}, best {result.best_score:.4f}")
    for dim, value in zip(result.dims, result.best):
        print(f"  {dim.name} = {value:.4g}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    out = output_file(args.out) if args.out else None
    episodes = int_arg(args.episodes, "--episodes")
    duration = duration_arg(args.duration, dt=Params().dt)
    workers = workers_arg(args)
    result = benchmark.run(episodes, duration, workers, not args.no_first_step,
                           progress=lambda msg: print(f"bench: {msg}", file=sys.stderr))
    if out is not None:
        write_json(out, result)
    print(json.dumps(result, indent=2, allow_nan=False) if args.json else benchmark.text(result))
    return 0


