"""Tune the person tracker's process noises and switching rates with Optuna, the way
``companion tune --suite`` tunes a controller's gains (docs/evaluation.md, docs/sensing.md).

    pip install -e '.[tune]'
    python bench/tune_tracker.py [--suite suites/tune-tracks.toml] [--trials N]
                                 [--storage sqlite:///tracker.db] [--workers N]

Each trial runs the suite's episodes of the default LQR with candidate ``tracker`` settings
(:data:`companion.evaluate.tuning.TRACKER_SPACE`) and scores them with the same objective
as ``companion tune --suite`` (:func:`companion.evaluate.tuning.objective`); the first trial
is the current settings. Prints the best as a ``[tracker]`` TOML table for ``--params``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from companion.data import pedestrians
from companion.errors import CompanionError
from companion.evaluate.suite import load_suite
from companion.evaluate.tuning import TRACKER_SPACE, as_toml, tune_on_suite

SUITE = Path(__file__).resolve().parents[1] / "suites" / "tune-tracks.toml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", default=str(SUITE), help="suite TOML (its lqr episodes)")
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--storage", help="Optuna storage URL (a stopped study resumes)")
    ap.add_argument("--workers", type=int)
    args = ap.parse_args()
    try:
        suite = load_suite(args.suite)
        tuned = tune_on_suite(suite, "lqr", args.trials, args.storage, workers=args.workers,
                              dims=TRACKER_SPACE,
                              progress=lambda n, j: print(f"{n:3d} J {j:.4f}", flush=True))
    except (CompanionError, ValueError) as exc:
        sys.exit(f"tune_tracker: {exc}")
    print(f"J: current settings {tuned.start_value:.4f}, best {tuned.best_value:.4f}")
    print(as_toml(tuned.params, tuned.dims))
    print(f"Data: {pedestrians.CREDIT}")


if __name__ == "__main__":
    main()
