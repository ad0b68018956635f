"""Tune the person tracker's process noises and switching rates with optuna (docs/sensing.md).

    pip install -e '.[tune]'
    python bench/tune_tracker.py [--trials N] [--every K] [--offset I]

Each trial runs the default LQR under the ``realistic`` sensing profile on every K-th
pedestrian track (from the I-th, both sides) with candidate ``tracker`` parameters, and scores
the closed loop: median RMSE rho (cm) + 20 x median RMSE alpha (rad) + 0.2 x p90 RMSE rho
(cm), plus 20 if any run came closer than 0.55 m to the person. Starts from the defaults;
prints every trial and the best one as a ``[tracker]`` TOML table.
"""

from __future__ import annotations

import argparse
import dataclasses

import optuna

from companion.data import pedestrians
from companion.evaluate import walkers
from companion.params import REALISTIC, Params, TrackerParams

#: Searched parameters: (low, high), on a log scale.
SPACE = {"accel_std": (0.1, 1.5), "turn_accel_std": (0.1, 3.0),
         "maneuver_accel_std": (0.5, 5.0), "maneuver_turn_accel_std": (0.3, 6.0),
         "maneuver_start_rate": (0.05, 5.0), "maneuver_end_rate": (0.2, 10.0)}


def score(table: dict) -> float:
    return (table["median_rho_m"] * 100 + 20 * table["median_alpha_rad"]
            + 0.2 * table["p90_rho_m"] * 100 + (20 if table["min_distance_m"] < 0.55 else 0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--every", type=int, default=6)
    ap.add_argument("--offset", type=int, default=1)
    args = ap.parse_args()
    tracks = pedestrians.select_tracks(pedestrians.load_scenes())[args.offset::args.every]

    def objective(trial: optuna.Trial) -> float:
        tracker = TrackerParams(**{k: trial.suggest_float(k, lo, hi, log=True)
                                   for k, (lo, hi) in SPACE.items()})
        rows = walkers.evaluate(tracks, Params(sensing=REALISTIC, tracker=tracker), ["lqr"])
        t = walkers.table(rows)["lqr"]
        print(f"{trial.number:3d} rho {t['median_rho_m'] * 100:.2f} cm, p90 "
              f"{t['p90_rho_m'] * 100:.2f} cm, alpha {t['median_alpha_rad']:.3f} rad, closest "
              f"{t['min_distance_m']:.3f} m", flush=True)
        return score(t)

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=0))
    defaults = dataclasses.asdict(TrackerParams())
    study.enqueue_trial({k: defaults[k] for k in SPACE})
    study.optimize(objective, n_trials=args.trials)
    print("[tracker]")
    for key, value in study.best_params.items():
        print(f"{key} = {value:.4g}")
    print(f"\nData: {pedestrians.CREDIT}")


if __name__ == "__main__":
    main()
