"""The experiment commands that are suites: ``companion pedestrians`` and ``companion
convergence`` build their suite from the shipped one and their flags, run it through
:func:`companion.apps.evaluation.evaluate` (the path of ``companion evaluate``) and print
their own table."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from companion.apps import plots
from companion.apps.args import (
    checked_controllers,
    duration_arg,
    floats_arg,
    number_arg,
    output_dir,
    params_arg,
    ranged,
    shown,
    workers_arg,
    wrote,
)
from companion.apps.evaluation import evaluate, failures, suite_outputs
from companion.config import load_toml
from companion.control import CONTROLLERS
from companion.data import pedestrians
from companion.evaluate import walkers
from companion.evaluate.rows import row_and_log
from companion.evaluate.run import run_results, suite_rows
from companion.evaluate.suite import suite_from_mapping, suite_path
from companion.io import save_figure


def controller_entry(name: str, args: argparse.Namespace) -> str | dict:
    """A suite's controller entry for ``name`` with the command's ``--params`` file."""
    if not args.params:
        return name
    return {"name": name, "params": str(Path(args.params).resolve()), "label": name}


def sensing_entry(args: argparse.Namespace, default: str) -> str | dict:
    """A suite's sensing entry for the command's ``--sensing``, else the ``--params``
    file's sensing table, else ``default``."""
    if args.sensing:
        return str(Path(args.sensing).resolve()) if args.sensing.endswith(".toml") \
            else args.sensing
    sensing = load_toml(args.params).get("sensing") if args.params else None
    if sensing is not None:
        return {"label": Path(args.params).stem, "base": "realistic", **sensing}
    return default


def plant_entry(args: argparse.Namespace) -> dict:
    """A suite's ``plants`` for the command's ``--plant`` (none given: the suite's own)."""
    return {"plants": [args.plant]} if args.plant else {}


def cmd_pedestrians(args: argparse.Namespace) -> int:
    params = params_arg(args)
    controllers = list(CONTROLLERS) if args.controller == "all" else [args.controller]
    checked_controllers(controllers, params, args.params)
    workers = workers_arg(args)
    data = load_toml(suite_path("pedestrians"))
    motions = dict(data["motions"],
                   min_mean_speed=number_arg(args.min_speed, "--min-speed", "MPS"),
                   min_duration=number_arg(args.min_duration, "--min-duration", "S"))
    if args.data:
        motions["data"] = str(Path(args.data).resolve())
    data.update(controllers=[controller_entry(c, args) for c in controllers],
                reference=controllers[0], sensing=[sensing_entry(args, "ideal")],
                sides=["left", "right"] if args.side == "both" else [args.side],
                motions=motions, **plant_entry(args))
    out = output_dir(Path(args.out or Path("out") / "pedestrians"))
    suite = suite_from_mapping(data, Path("<companion pedestrians>"))
    rows = evaluate(suite, out, workers, args.dask)
    print(walkers_text(walkers.table(rows), walkers.paired(rows, controllers[0])))
    print(wrote(suite_outputs(out), f"and the figures in {shown(out)}") + "\n")
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


def cmd_convergence(args: argparse.Namespace) -> int:
    params = params_arg(args)
    checked_controllers([args.controller], params, args.params)
    data = load_toml(suite_path("convergence"))
    speeds = ranged(floats_arg(args.speeds, len(args.speeds.split(",")), "--speeds"),
                    args.speeds, "--speeds", "V")
    data["motions"]["convergence"] = {
        "speeds": list(speeds), "duration": duration_arg(args.duration, dt=params.dt)}
    if args.settle_limit is not None:
        data["criteria"]["settling_time_s"] = {
            "max": number_arg(args.settle_limit, "--settle-limit", "S")}
    data.update(controllers=[controller_entry(args.controller, args)],
                sensing=[sensing_entry(args, "ideal")], **plant_entry(args))
    workers = workers_arg(args)
    out = output_dir(Path(args.out or Path("out") / "convergence"))
    suite = suite_from_mapping(data, Path("<companion convergence>"))
    if args.plot:       # the figures need the logs: the engine returns them, keeps nothing
        results = run_results(dataclasses.replace(suite, row=row_and_log), None, workers,
                              args.dask)
        rows = suite_rows(suite, {e.key: r for e, (r, _) in zip(suite.episodes, results)})
        logs = [log for _, log in results]

        def figures(folder: Path) -> None:
            runs: dict[str, list] = {}       # by group: one figure per person speed
            for e, log in zip(suite.episodes, logs):
                start = e.spec.start
                runs.setdefault(e.group, []).append((f"({start.x:g}, {start.y:g})", e.side, log))
            for group, group_runs in runs.items():
                fig = plots.convergence(group_runs, f"Fig. 3 ({group}), controller "
                                                    f"{args.controller}")
                save_figure(fig, folder / f"{group}.png")
                plots.close(fig)
        rows = evaluate(suite, out, workers, args.dask, rows=rows, extra=figures)
    else:
        rows = evaluate(suite, out, workers, args.dask)
    failed = dict(failures(suite, rows))
    print(f"{'start':>24} {'side':>5} {'settle_s':>9} {'min_dist_m':>10}")
    for r in rows:
        settle = r["settling_time_s"]
        print(f"{r['motion']:>24} {r['side']:>5} "
              f"{'never' if settle != settle else f'{settle:.2f}':>9} "
              f"{r['min_person_distance_m']:10.3f}"
              + (f"  FAIL: {', '.join(failed[r['episode']])}" if r["episode"] in failed else ""))
    met = " and ".join(map(str, suite.criteria))
    print(f"{len(rows) - len(failed)}/{len(rows)} runs meet {met}")
    print(wrote(suite_outputs(out), f"and the figures{' and the Fig. 3 PNGs' * args.plot} in "
                                    f"{shown(out)}"))
    return 0 if not failed else 1
