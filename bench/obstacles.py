"""Obstacle scenarios side by side (docs/model.md section 8).

    python bench/obstacles.py

For fig4, fig7 and corridor, with ground-truth and LiDAR obstacles, for `lqr` and
`lqr-paper`: collisions, closest clearance (footprint to obstacle surface), closest approach
to the person, and RMSE of rho and alpha over the whole run.
"""

from __future__ import annotations

from threadpoolctl import threadpool_limits

from companion import metrics
from companion.control import make_controller
from companion.sim.episode import run_episode
from companion.sim.scenario import load_scenario
from companion.sim.sensing import make_perception


def main() -> None:
    print(f"{'scenario':9s} {'obstacles':9s} {'controller':10s} {'collisions':>10s} "
          f"{'clearance':>9s} {'person':>7s} {'rmse rho':>9s} {'rmse alpha':>10s}")
    for name in ("fig4", "fig7", "corridor"):
        sc = load_scenario(name)
        for source in ("truth", "lidar"):
            for ctl in ("lqr", "lqr-paper"):
                log = run_episode(make_controller(ctl, sc.params), sc.person, sc.params,
                                  sc.duration, start=sc.start, seed=sc.seed,
                                  obstacles=sc.obstacles,
                                  perception=make_perception(source, sc.params))
                m = metrics.compute(log)
                print(f"{name:9s} {source:9s} {ctl:10s} {m['obstacle_collisions']:>10d} "
                      f"{m['min_obstacle_clearance_m']:>8.3f}m "
                      f"{m['min_person_distance_m']:>6.2f}m {m['rmse_rho_m'] * 100:>7.1f}cm "
                      f"{m['rmse_alpha_rad']:>10.3f}", flush=True)


if __name__ == "__main__":
    with threadpool_limits(limits=1):
        main()
