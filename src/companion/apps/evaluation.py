"""``companion evaluate SUITE``: run a suite (:mod:`companion.evaluate`) and write
episodes.csv, summary.json, summary.md and the figures; print the summary. The experiment
commands that are suites (``pedestrians``, ``convergence``) run through :func:`evaluate`."""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from companion.apps.args import (
    UsageError,
    int_arg,
    output_dir,
    seed_arg,
    shown,
    workers_arg,
    wrote,
)
from companion.apps.progress import progress_bar, resumable
from companion.evaluate import companions
from companion.evaluate.report import write_episodes, write_summary
from companion.evaluate.rows import failed
from companion.evaluate.run import PARTIAL, finish, kept_count, run_suite
from companion.evaluate.stats import summarize
from companion.evaluate.suite import Suite, load_suite
from companion.evaluate.tuning import as_toml, open_storage, tune_on_suite
from companion.io import CsvWriter, Outputs, atomic_write, save_figure


def cmd_evaluate(args: argparse.Namespace) -> int:
    suite = load_suite(args.suite)
    name = re.sub(r"[^A-Za-z0-9_.-]+", "-", suite.name).strip(".-") or "suite"
    out = output_dir(Path(args.out or Path("out") / f"evaluate-{name}"))
    rows = evaluate(suite, out, workers_arg(args), args.dask)
    print((out / "summary.md").read_text(encoding="utf-8"))
    pairs = [out / "pairs.md", out / "pairs.csv"] if companions.beside_pairs(rows) else []
    if pairs:
        print(companions.short(rows))
    print(wrote(suite_outputs(out) + pairs, f"and the figures in {shown(out)}"))
    return 1 if failures(suite, rows) else 0


def suite_outputs(out: Path) -> list[Path]:
    """The files every suite command writes in ``out`` besides its figures."""
    return [out / name for name in ("episodes.csv", "summary.json", "summary.md")]


def evaluate(suite: Suite, out: Path, workers: int | None, dask: str | None = None,
             rows: list[dict] | None = None,
             extra: Callable[[Path], None] | None = None) -> list[dict]:
    """Run ``suite`` into ``out`` (resumable) with a progress bar, write its files and
    return its rows; ``rows`` already computed (with logs kept for figures) are written
    as they are; ``extra(folder)`` writes a command's own files with them."""
    controllers = list(dict.fromkeys(e.controller for e in suite.episodes))
    print(f"{suite.name}: {len(suite.episodes)} episodes ({', '.join(controllers)}; "
          f"reference {suite.reference}) on "
          f"{'local worker processes' if dask is None else 'Dask ' + dask}")
    if rows is None:
        total, partial, kept = len(suite.episodes), out / PARTIAL, kept_count(suite, out)
        if kept:
            print(f"resuming: {kept} of {total} episodes kept in {partial}", flush=True)
        with resumable(suite.name, out, total), progress_bar(total, "episode") as bar:
            rows = run_suite(suite, out, workers, dask, lambda done, total: bar(done))
    summary = summarize(rows, suite.reference)
    with Outputs(out, "evaluate") as stage:
        write_episodes(stage / "episodes.csv", rows)
        write_summary(stage, suite.name, suite.reference, summary, failures(suite, rows),
                      [str(c) for c in suite.criteria])
        for name, fig in figures(rows, suite.reference):
            save_figure(fig, stage / name)
            plt.close(fig)
        if companions.beside_pairs(rows):
            companions.write(stage, rows)
        if extra is not None:
            extra(stage)
    finish(out)
    return rows


def failures(suite: Suite, rows: list[dict]) -> list[tuple[str, list[str]]]:
    """``(episode, missed criteria)`` of every episode that misses the suite's criteria."""
    out = []
    for r in rows:
        missed = failed(r, suite.criteria)
        if missed:
            out.append((r["episode"], missed))
    return out


def cmd_tune(args: argparse.Namespace) -> int:
    """``companion tune CONTROLLER [--suite SUITE]``: Optuna on the suite's episodes."""
    trials = int_arg(args.trials, "--trials")
    seed, workers = seed_arg(args.seed), workers_arg(args)
    out = output_dir(Path(args.out or Path("out") / f"tune-{args.controller}"))
    suite = load_suite(args.suite)
    n = sum(e.controller == args.controller for e in suite.episodes)
    if not n:
        raise UsageError(f"{args.suite}: controllers: expected {args.controller!r} among them")
    storage = open_storage(args.storage)        # before the progress bar: errors on one line
    print(f"tuning {args.controller} on {suite.name}: {trials} trials of {n} episodes, "
          f"storage {args.storage or 'in memory'}")
    with resumable("tune", out, kept=f"the finished trials are kept in {args.storage}"
                   if args.storage else None), progress_bar(trials, "trial") as bar:
        def progress(number: int, value: float) -> None:
            bar(min(number + 1, trials))
        tuned = tune_on_suite(suite, args.controller, trials, storage,
                              workers=workers, dask=args.dask, seed=seed,
                              progress=progress)
    with Outputs(out, "tune") as stage:
        atomic_write(stage / "best.toml", lambda p: p.write_text(
            f"# companion tune {args.controller} --suite {args.suite}: J {tuned.best_value:.4f} "
            f"(current parameters {tuned.start_value:.4f})\n"
            + as_toml(tuned.params, tuned.dims), encoding="utf-8"))
        with CsvWriter(stage / "trials.csv", ["trial", "objective"]) as csv:
            csv.add(tuned.history)
    print(f"J: current parameters {tuned.start_value:.4f}, best {tuned.best_value:.4f} "
          f"({tuned.trials} trials)")
    for dim, value in zip(tuned.dims, tuned.best):
        print(f"  {dim.name} = {value:.4g}")
    print(wrote([out / "best.toml", out / "trials.csv"]))
    return 0


def figures(rows: list[dict], reference: str) -> list[tuple[str, plt.Figure]]:
    """Per condition: the slot error of every controller (box plots over episodes), and
    each controller's paired difference from ``reference``."""
    out = []
    conditions = sorted({(r["sensing"], r["group"]) for r in rows})
    for sensing, group in conditions:
        here = [r for r in rows if r["sensing"] == sensing and r["group"] == group]
        names = list(dict.fromkeys(r["controller"] for r in here))
        fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
        data = [[100 * r["rms_slot_error_m"] for r in here if r["controller"] == c]
                for c in names]
        ax.boxplot(data, tick_labels=names)
        ax.set_ylabel("slot error RMS (cm)")
        ax.set_title(f"{sensing} / {group}: per episode")
        ref = {r["pair"]: r["rms_slot_error_m"] for r in here if r["controller"] == reference}
        others = [c for c in names if c != reference]
        diffs = [[100 * (r["rms_slot_error_m"] - ref[r["pair"]]) for r in here
                  if r["controller"] == c and r["pair"] in ref] for c in others]
        if others:
            bx.boxplot(diffs, tick_labels=others)
            bx.axhline(0.0, color="0.5", lw=0.8)
        bx.set_ylabel(f"slot error minus {reference}'s (cm)")
        bx.set_title("paired with the reference (below 0: better)")
        for axis in (ax, bx):
            axis.grid(alpha=0.3)
        fig.tight_layout()
        safe = re.sub(r"[^A-Za-z0-9_.-]+", "-", f"{sensing}_{group}")
        out.append((f"slot_{safe}.png", fig))
    return out
