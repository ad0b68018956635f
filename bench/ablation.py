"""Measure the effect of each deviation from the printed LQR design (docs/model.md).

    python bench/ablation.py

Prints, for each variant: how many of the 48 Fig. 3 runs settle within 20 s while staying
>= 0.5 m from the person, the worst settling time, the closest approach, and RMSE of rho and
alpha on the figure-8 (60 s lap, right side) and the circle (3 m, 1 m/s, left side).
"""

from __future__ import annotations

import dataclasses
import math

from threadpoolctl import threadpool_limits

from companion import metrics
from companion.params import Params
from companion.sim import convergence
from companion.sim.runner import EpisodeSpec, run_many
from companion.sim.scenario import load_scenario

INF = (math.inf, math.inf, math.inf)
PAPER = dict(linearize_at="desired", feedforward="person", error_clip=INF, clearance=0.0)
VARIANTS = {
    "paper (lqr-paper)": PAPER,
    "+ measured linearisation": dict(PAPER, linearize_at="measured"),
    "+ geometric feedforward": dict(PAPER, linearize_at="measured", feedforward="geometric"),
    "+ error clip": dict(linearize_at="measured", feedforward="geometric", clearance=0.0),
    "+ keep-out barrier = ours (lqr)": dict(),
    "ours without geometric ff": dict(feedforward="person"),
    "ours with desired linearisation": dict(linearize_at="desired"),
    "ours with zoh discretisation": dict(discretization="zoh"),
}


def with_lqr(params: Params, clearance: float | None = None, **lqr) -> Params:
    """``params`` with LQR fields replaced and, if given, the barrier's person_clearance."""
    keepout = params.keepout if clearance is None else dataclasses.replace(
        params.keepout, person_clearance=clearance)
    return dataclasses.replace(params, lqr=dataclasses.replace(params.lqr, **lqr),
                               keepout=keepout)


def fig3(lqr: dict) -> tuple[int, float, float]:
    specs = [convergence.episode(case, "lqr", with_lqr(Params(), **lqr))
             for case in convergence.cases()]
    ok, worst, closest = 0, 0.0, math.inf
    for m in run_many(specs, summarize=metrics.compute):
        s = m["settling_time_s"]
        closest = min(closest, m["min_person_distance_m"])
        ok += s is not None and s <= 20.0 and m["min_person_distance_m"] >= 0.5
        worst = max(worst, s if s is not None else math.inf)
    return ok, worst, closest


def scenario(name: str, lqr: dict) -> dict:
    sc = load_scenario(name)
    spec = EpisodeSpec("lqr", sc.person, with_lqr(sc.params, **lqr), sc.duration)
    return metrics.compute(run_many([spec])[0])


def main() -> None:
    print(f"{'variant':34s} {'fig3 ok':>8s} {'worst settle':>12s} {'closest':>8s} "
          f"{'8: rho cm':>9s} {'8: alpha':>8s} {'circ: rho cm':>12s} {'circ: alpha':>11s}")
    for name, lqr in VARIANTS.items():
        ok, worst, closest = fig3(lqr)
        f8, ci = scenario("figure8", lqr), scenario("circle", lqr)
        print(f"{name:34s} {ok:>5d}/48 {worst:>11.2f}s {closest:>7.2f}m "
              f"{f8['rmse_rho_m'] * 100:>9.3f} {f8['rmse_alpha_rad']:>8.4f} "
              f"{ci['rmse_rho_m'] * 100:>12.3f} {ci['rmse_alpha_rad']:>11.4f}", flush=True)


if __name__ == "__main__":
    with threadpool_limits(limits=1):
        main()
