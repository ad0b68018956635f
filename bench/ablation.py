"""Measure the effect of each deviation from the printed LQR design (docs/model.md).

    python bench/ablation.py

Prints, for each variant: how many of the 48 Fig. 3 runs settle within 20 s while staying
>= 0.5 m from the person, the worst settling time, the closest approach, and RMSE of rho and
alpha on the figure-8 (60 s lap, right side) and the circle (3 m, 1 m/s, left side). The
variants are the controllers of one suite (the shipped convergence suite and its criteria,
with the two scenarios), run by the evaluate engine.
"""

from __future__ import annotations

import math
from pathlib import Path

from threadpoolctl import threadpool_limits

from companion.config import load_toml
from companion.evaluate.rows import failed
from companion.evaluate.run import run_all
from companion.evaluate.suite import suite_from_mapping, suite_path

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


def overrides(lqr: dict) -> dict:
    """A variant as parameter overrides: LQR fields and, as ``clearance``, the barrier's
    person_clearance."""
    lqr = dict(lqr)
    clearance = lqr.pop("clearance", None)
    return {"lqr": lqr, **({} if clearance is None else
                           {"keepout": {"person_clearance": clearance}})}


def main() -> None:
    # The convergence suite (Fig. 3 and its criteria) with a controller per variant, and the
    # figure-8 (60 s lap, right side) and the circle (3 m, 1 m/s, left side) beside it.
    data = load_toml(suite_path("convergence"))
    data.update(controllers=[{"name": "lqr", "label": name, "params": overrides(lqr)}
                             for name, lqr in VARIANTS.items()], sides=["scenario"])
    data["motions"]["scenarios"] = ["figure8", "circle"]
    suite = suite_from_mapping(data, Path("<ablation>"))
    rows = run_all(suite)
    print(f"{'variant':34s} {'fig3 ok':>8s} {'worst settle':>12s} {'closest':>8s} "
          f"{'8: rho cm':>9s} {'8: alpha':>8s} {'circ: rho cm':>12s} {'circ: alpha':>11s}")
    for name in VARIANTS:
        mine = [r for r in rows if r["controller"] == name]
        fig3 = [r for r in mine if r["group"].startswith("fig3")]
        ok = sum(not failed(r, suite.criteria) for r in fig3)
        worst = max(r["settling_time_s"] if math.isfinite(r["settling_time_s"]) else math.inf
                    for r in fig3)
        closest = min(r["min_person_distance_m"] for r in fig3)
        f8, ci = (next(r for r in mine if r["motion"] == m) for m in ("figure8", "circle"))
        print(f"{name:34s} {ok:>5d}/48 {worst:>11.2f}s {closest:>7.2f}m "
              f"{f8['rmse_rho_m'] * 100:>9.3f} {f8['rmse_alpha_rad']:>8.4f} "
              f"{ci['rmse_rho_m'] * 100:>12.3f} {ci['rmse_alpha_rad']:>11.4f}", flush=True)


if __name__ == "__main__":
    with threadpool_limits(limits=1):
        main()
