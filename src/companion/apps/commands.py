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
from pathlib import Path

from companion import metrics
from companion.apps import animate, benchmark, fuzz, movie, plots, reproduce, table3
from companion.apps.args import (
    UsageError,
    build_scenario,
    checked_controllers,
    duration_arg,
    file_params,
    int_arg,
    output_dir,
    output_file,
    params_arg,
    seed_arg,
    shown,
    with_sensing,
    workers_arg,
    wrote,
)
from companion.apps.logfile import LogCsv, Thinned, write_log
from companion.apps.progress import progress_bar, resumable, seconds_bar
from companion.control import lookup
from companion.evaluate import fuzz_runs
from companion.evaluate.generators import soak_suite
from companion.evaluate.run import finish, run_results
from companion.io import Outputs, save_figure, write_csv, write_json
from companion.params import Params
from companion.sim import fuzz as sim_fuzz
from companion.sim import soak
from companion.sim.runner import reporting, stream_one
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
    elsewhere: list[Path] = []
    with seconds_bar(sc.duration) as reached, reporting(reached):
        if args.bag:                        # the episode runs over the recorded graph
            from companion.apps.bags import bag_arg, run_recorded

            bag = bag_arg(args.bag)
            blocks = iter([run_recorded(sc, bag, reached)])
            elsewhere.append(bag)
        else:
            blocks = started(stream_one(sc.episode()))
        with Outputs(out, "run") as stage:  # the log goes to disk as the episode runs
            if target is None:
                m, written = _write_run(stage, sc, args.plot, blocks)
            else:                           # an animation needs the whole log at the end
                log = Log.concat(blocks)
                m, written = _write_run(stage, sc, args.plot, [log])
                if animate.save_run(target, out, stage, sc, log):
                    written.append(target.name)
                else:
                    elsewhere.append(target)
    # Everything is written before anything is printed: a reader that goes away early
    # (| head) cannot cut the outputs short.
    print(f"{sc.name}: {sc.description}")
    print(f"controller {sc.controller}, {sc.duration:g} s, seed {sc.seed}, side bearing "
          f"{sc.params.formation.bearing:.4f} rad, distance {sc.params.formation.distance:g} m")
    print("\n".join(summary_lines(m)))
    print(wrote([*(out / name for name in written), *elsewhere]))
    return 0


def cmd_scenarios(args: argparse.Namespace) -> int:
    for name in builtin_names():
        sc = load_scenario(name)
        print(f"{name:10s} {sc.description}")
    return 0


#: Simulated seconds of the soak per second of wall time on the 2-core machine of
#: docs/performance.md (600 s took 7.2 s, 2 s of it starting up).
SOAK_PACE = 115.0


def cmd_soak(args: argparse.Namespace) -> int:
    params = params_arg(args)
    checked_controllers([args.controller], params, args.params)
    duration = duration_arg(args.duration, dt=params.dt)
    seed = seed_arg(args.seed)
    out = output_dir(Path(args.out or Path("out") / "soak"))
    print(f"soak: {duration:g} s of a random walker among pillars (seed {seed}), "
          f"controller {args.controller}; about {2 + duration / SOAK_PACE:.0f} s on a 2-core "
          f"machine", flush=True)
    suite = soak_suite(duration, seed, args.controller, params)
    # with --log the episode runs here, its log going to disk as it runs; else through the
    # engine, kept in --out once run (as evaluate keeps its episodes)
    with resumable("soak", out, 1), seconds_bar(duration) as reached, reporting(reached), \
            Outputs(out, "soak") as stage:
        if args.log:
            blocks = started(stream_one(suite.episodes[0].spec))
            with LogCsv(stage / "log.csv") as csv:
                result = soak.summarize_blocks(blocks, params, csv.log)
        else:
            result = run_results(suite, out, 1)[0]
        write_json(stage / "soak.json", result)
    finish(out)
    written = ["soak.json"] + ["log.csv"] * bool(args.log)
    for key, value in result.items():
        print(f"  {key:26s} {value:.4g}" if isinstance(value, float) else f"  {key:26s} {value}")
    ok = result["finite"] and result["person_collisions"] == 0 \
        and result["obstacle_collisions"] == 0
    print("PASS: no collision with the person or an obstacle, all values finite" if ok
          else "FAIL: a collision or a non-finite value")
    print(wrote(out / name for name in written))
    return 0 if ok else 1


def cmd_fuzz(args: argparse.Namespace) -> int:
    controllers, profiles = fuzz.selection(args)
    sensings = tuple(profiles)
    base = with_sensing(file_params(args), argparse.Namespace(plant=args.plant))
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
        print(wrote([out / "log.csv", out / "episode.json"]))
        return 1 if sim_fuzz.robot_failed(counts) else 0
    steps = int_arg(args.steps, "--steps", "N")
    seed = seed_arg(args.seed)
    workers = workers_arg(args)
    start = time.monotonic()
    print(f"fuzz: >= {steps:,} steps, seed {seed}, {', '.join(controllers)} x "
          f"{', '.join(sensings)} sensing")
    episodes = sim_fuzz.plan(steps, seed, controllers, sensings)
    with resumable("fuzz", out, len(episodes)), progress_bar(len(episodes), "episode") as progress:
        cases, counts = fuzz_runs.run(episodes, workers, progress, base, profiles, out,
                                      args.dask)
    pairs, total = fuzz_runs.by_pair(cases, counts)
    failed = fuzz_runs.failures(cases, counts)
    rates = fuzz_runs.failure_rates(cases, counts)
    missed = fuzz_runs.missed_criteria(rates)
    report = {"steps_requested": steps, "seed": seed, "params": args.params,
              "controllers": list(controllers),
              "sensing": list(sensings), "wall_time_s": round(time.monotonic() - start, 1),
              "walker": "blind", "total": total, "by_pair": pairs,
              "robot_failure_rate": rates, "missed_criteria": missed, "failed": failed}
    with Outputs(out, "fuzz") as stage:
        write_json(stage / "fuzz.json", report)
        write_csv(stage / "fuzz.csv", fuzz_runs.COLUMNS, fuzz_runs.csv_rows(cases, counts))
    finish(out)
    print(fuzz_runs.table(pairs, total))
    for f in failed[:20]:
        print(f"FAIL seed {f['seed']} {f['controller']}/{f['sensing']}: replay with companion "
              f"fuzz --replay {f['seed']} --controllers {f['controller']} --sensing "
              f"{f['sensing']}")
    print(f"{len(failed)} of {len(cases)} episodes failed (a collision, a robot-caused "
          f"protective violation or a non-finite value); {report['wall_time_s']:g} s")
    print(fuzz_runs.rates_text(rates))
    for line in missed:
        print(f"criterion not met: {line}")
    robot = sum(r["robot_failed_episodes"] for r in rates.values())
    if missed and not robot:
        print("no failure found, but the run is too short to bound the rate: that needs 299 "
              "episodes per sensing profile without one (about 1,000,000 steps)")
    print(wrote([out / "fuzz.json", out / "fuzz.csv"]))
    return 1 if robot else 0


def cmd_reproduce(args: argparse.Namespace) -> int:
    workers = workers_arg(args)
    out = output_dir(Path(args.out or Path("out") / "reproduce"))
    names = reproduce.controllers()
    print(f"Reproducing Fig. 3, Table 2, Fig. 4, Fig. 7 and Table 3 with {', '.join(names)} "
          f"into {out}")
    with resumable("reproduce", out), progress_bar(reproduce.episode_count(), "episode") \
            as progress, Outputs(out, "reproduce") as stage:
        result = reproduce.reproduce(stage, workers, progress, keep=out, dask=args.dask)
    finish(out)
    print(reproduce.fig3_summary(result.fig3))
    print("Table 2 (ours; paper's LQR/PID/VSM/IC rho and alpha at the right):")
    print(reproduce.table2_text(result.table2))
    print("Fig. 4 (figure-8 with the obstacle, every controller):")
    print(reproduce.fig4_text(result.fig4))
    print("Table 3 (em-tracker and realistic sensing, mean over seeds; the paper's LQR on the "
          "real robot at the right of ours under em-tracker):")
    print(table3.text(result.table3))
    print(wrote([out / name for name in ("table2.csv", "table2.md", "table3.csv", "table3.md",
                                          "fig3.csv", "fig4.csv", "fig4.gif")],
                f"and the Fig. 3, 4, 7 PNGs in {shown(out)}"))
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


