"""The paper's Table 3 (its real-robot experiments) from the rows of the shipped ``table3``
suite: the U-shape without obstacles (Fig. 6) and the figure-8 with obstacles (Fig. 7, seen
by the simulated LiDAR) under the ``em-tracker`` sensing profile (a sensor like the paper's
electromagnetic tracker) and the ``realistic`` one (a leg-tracker-like detector), every
controller, several seeds (docs/sensing.md).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: The paper's Table 3 (its LQR on the real robot): rho m, alpha rad, beta rad, v m/s,
#: omega rad/s.
PAPER_TABLE3 = {"U-shaped": (0.068, 0.094, 0.130, 0.245, 0.245),
                "8-shaped": (0.226, 0.324, 0.142, 0.285, 0.241)}

#: The sensing profile like the paper's sensor: our lqr under it sits beside the paper's.
PAPER_LIKE = "em-tracker"

METRICS = ("rmse_rho_m", "rmse_alpha_rad", "rmse_beta_rad", "rmsv_v_mps", "rmsv_omega_radps")
COLUMNS = ("trajectory", "sensing", "controller", "runs", *METRICS, "rmse_rho_m_min",
           "rmse_rho_m_max", "min_person_distance_m", "obstacle_collisions", "stopped_s")


def rows(episodes: Sequence[dict]) -> list[list]:
    """One row per trajectory, sensing and controller (:data:`COLUMNS`) from the rows of the
    ``table3`` suite: the mean of each metric over the seeds, the spread of rho, the closest
    approach to the person, the collisions and the time spent stopped over all of them."""
    groups: dict[tuple[str, str, str], list[dict]] = {}
    for r in episodes:
        groups.setdefault((r["motion"], r["sensing"], r["controller"]), []).append(r)
    out = []
    for (trajectory, sensing, name), ms in groups.items():
        rho = [m["rmse_rho_m"] for m in ms]
        stopped = sum(m["share_stopped"] * m["duration_s"] for m in ms)
        out.append([trajectory, sensing, name, len(ms),
                    *(float(np.mean([m[k] for m in ms])) for k in METRICS),
                    min(rho), max(rho), min(m["min_person_distance_m"] for m in ms),
                    int(sum(m["obstacle_collisions"] for m in ms)), stopped])
    return out


def markdown(table: Sequence[Sequence]) -> str:
    """Table 3 with the paper's values beside ours."""
    lines = [
        "# Table 3: the real-robot experiments, simulated with the robot's sensing",
        "",
        f"Ours: `companion reproduce` (the `table3` suite), mean over {table[0][3]} seeds "
        "(rho's range over the "
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
        like = name == "lqr" and sensing == PAPER_LIKE
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
        like = name == "lqr" and sensing == PAPER_LIKE
        ref = f"   {paper[0]:.3f}, {paper[1]:.3f}" if like else ""
        out.append(f"{trajectory:10s} {sensing:10s} {name:10s} {rho:6.3f} {alpha:6.3f} "
                   f"{beta:6.3f} {v:6.3f} {w:7.3f} {closest:8.2f}{ref}")
    return "\n".join(out)
