"""Obstacle scenarios side by side (docs/model.md section 8).

    python bench/obstacles.py

For fig4, fig7 and corridor, with ground-truth and LiDAR obstacles, for `lqr` and
`lqr-paper`: collisions, closest clearance (footprint to obstacle surface), closest approach
to the person, and RMSE of rho and alpha over the whole run.
"""

from __future__ import annotations

from threadpoolctl import threadpool_limits

from companion.evaluate.generators import scenario_episodes, suite_of
from companion.evaluate.run import run_all


def main() -> None:
    suite = suite_of("obstacles", (e for name in ("fig4", "fig7", "corridor")
                                   for source in ("truth", "lidar")
                                   for e in scenario_episodes(name, ["lqr", "lqr-paper"], source)))
    print(f"{'scenario':9s} {'obstacles':9s} {'controller':10s} {'collisions':>10s} "
          f"{'clearance':>9s} {'person':>7s} {'rmse rho':>9s} {'rmse alpha':>10s}")
    for e, m in zip(suite.episodes, run_all(suite)):
        name, source = e.motion.split("+")
        print(f"{name:9s} {source:9s} {e.controller:10s} {int(m['obstacle_collisions']):>10d} "
              f"{m['min_obstacle_clearance_m']:>8.3f}m "
              f"{m['min_person_distance_m']:>6.2f}m {m['rmse_rho_m'] * 100:>7.1f}cm "
              f"{m['rmse_alpha_rad']:>10.3f}")


if __name__ == "__main__":
    with threadpool_limits(limits=1):
        main()
