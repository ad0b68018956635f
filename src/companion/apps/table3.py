"""The paper's Table 3 (its real-robot experiments), simulated under the ``em-tracker``
sensing profile (a sensor like the paper's electromagnetic tracker) and the ``realistic`` one
(a leg-tracker-like detector): the U-shape without obstacles (Fig. 6) and the figure-8 with
obstacles (Fig. 7, the obstacles seen by the simulated LiDAR), every controller, several
seeds (docs/sensing.md).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from companion import metrics
from companion.params import PROFILES
from companion.sim.runner import EpisodeSpec
from companion.sim.scenario import load_scenario
from companion.types import Log

#: Table 3 trajectory -> (built-in scenario, obstacle source).
EXPERIMENTS = {"U-shaped": ("ushape", "truth"), "8-shaped": ("fig7", "lidar")}

#: The paper's Table 3 (its LQR on the real robot): rho m, alpha rad, beta rad, v m/s,
#: omega rad/s.
PAPER_TABLE3 = {"U-shaped": (0.068, 0.094, 0.130, 0.245, 0.245),
                "8-shaped": (0.226, 0.324, 0.142, 0.285, 0.241)}

#: Seeds of the sensing noise; each row is the mean over them.
SEEDS = tuple(range(5))
#: The sensing profiles of the table: like the paper's sensor first.
SENSING = ("em-tracker", "realistic")

METRICS = ("rmse_rho_m", "rmse_alpha_rad", "rmse_beta_rad", "rmsv_v_mps", "rmsv_omega_radps")
COLUMNS = ("trajectory", "sensing", "controller", "runs", *METRICS, "rmse_rho_m_min",
           "rmse_rho_m_max", "min_person_distance_m", "obstacle_collisions", "stopped_s")


def jobs(names: Sequence[str]) -> list[tuple[str, str, str, EpisodeSpec]]:
    """``(trajectory, sensing, controller, spec)`` for every experiment, sensing profile,
    controller and seed."""
    out = []
    for trajectory, (scenario, source) in EXPERIMENTS.items():
        sc = load_scenario(scenario)
        for sensing in SENSING:
            for name in names:
                spec = sc.episode(name, source)
                params = spec.params.replace(sensing=PROFILES[sensing])
                out += [(trajectory, sensing, name,
                         dataclasses.replace(spec, params=params, seed=seed))
                        for seed in SEEDS]
    return out


def rows(done: Sequence[tuple[str, str, str, EpisodeSpec]], logs: Sequence[Log]
         ) -> list[list]:
    """One row per trajectory, sensing and controller (:data:`COLUMNS`): the mean of each
    metric over the seeds, the spread of rho, the closest approach to the person, the
    collisions and the time spent stopped over all of them."""
    groups: dict[tuple[str, str, str], list[tuple[dict, Log, EpisodeSpec]]] = {}
    for (trajectory, sensing, name, spec), log in zip(done, logs):
        groups.setdefault((trajectory, sensing, name), []).append(
            (metrics.compute(log), log, spec))
    out = []
    for (trajectory, sensing, name), runs in groups.items():
        ms = [m for m, _, _ in runs]
        rho = [m["rmse_rho_m"] for m in ms]
        stopped = sum(float(np.sum(log["status"] == "stopped")) * spec.params.dt
                      for _, log, spec in runs)
        out.append([trajectory, sensing, name, len(runs),
                    *(float(np.mean([m[k] for m in ms])) for k in METRICS),
                    min(rho), max(rho), min(m["min_person_distance_m"] for m in ms),
                    sum(m["obstacle_collisions"] for m in ms), stopped])
    return out


def markdown(table: Sequence[Sequence]) -> str:
    """Table 3 with the paper's values beside ours."""
    lines = [
        "# Table 3: the real-robot experiments, simulated with the robot's sensing",
        "",
        f"Ours: `companion reproduce`, mean over {len(SEEDS)} seeds (rho's range over the "
        "seeds in brackets), under the `em-tracker` sensing profile (like the paper's "
        "electromagnetic tracker: position and heading) and the `realistic` one (a leg "
        "tracker: positions only); the 8-shaped run sees its obstacles with the simulated "
        "LiDAR. Paper: Su et al., Table 3 (its LQR on the real robot), beside our `lqr` under "
        "`em-tracker`. Units: rho m, alpha and beta rad, v m/s, omega rad/s.",
        "",
        "| trajectory | sensing | controller | rho (m) | paper | alpha | paper | beta | paper "
        "| v | paper | omega | paper | closest to person (m) | collisions |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in table:
        trajectory, sensing, name, _, *values = row
        like = name == "lqr" and sensing == SENSING[0]
        paper = PAPER_TABLE3[trajectory] if like else None
        cells = [f"{values[0]:.3f} [{values[5]:.3f}, {values[6]:.3f}]",
                 "" if paper is None else f"{paper[0]:.3f}"]
        for i in range(1, 5):
            cells += [f"{values[i]:.3f}", "" if paper is None else f"{paper[i]:.3f}"]
        lines.append(f"| {trajectory} | {sensing} | {name} | " + " | ".join(cells)
                     + f" | {values[7]:.2f} | {values[8]} |")
    return "\n".join(lines) + "\n"


def text(table: Sequence[Sequence]) -> str:
    """Table 3 for the terminal."""
    out = [f"{'trajectory':10s} {'sensing':10s} {'controller':10s} {'rho m':>6s} {'alpha':>6s} "
           f"{'beta':>6s} {'v m/s':>6s} {'w rad/s':>7s} {'person m':>8s}   paper rho, alpha"]
    for trajectory, sensing, name, _, rho, alpha, beta, v, w, _, _, closest, _, _ in table:
        paper = PAPER_TABLE3[trajectory]
        like = name == "lqr" and sensing == SENSING[0]
        ref = f"   {paper[0]:.3f}, {paper[1]:.3f}" if like else ""
        out.append(f"{trajectory:10s} {sensing:10s} {name:10s} {rho:6.3f} {alpha:6.3f} "
                   f"{beta:6.3f} {v:6.3f} {w:7.3f} {closest:8.2f}{ref}")
    return "\n".join(out)
