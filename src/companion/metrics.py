"""Evaluation metrics of a logged episode (paper Eq. 21-22 and more).

* RMSE (Eq. 21) of rho, alpha and beta against the nominal desired state (rho_d, alpha_d, 0),
  angle errors wrapped to (-pi, pi];
* RMSV (Eq. 22) of v and omega against the person's (v_h, omega_h). In a turn the robot must
  move at a different speed than the person (docs/model.md R7), so RMSV > 0
  there is geometry;
* minimum distance from the robot centre (wheel axle) to the person;
* settling time: the first time after which |rho_e| < tol_rho, |alpha_e| < tol_alpha and
  |beta - beta_ref| < tol_beta hold to the end of the run (None if they do not hold at the end).
  ``beta_ref`` is the heading offset that holding the slot needs (0 on straight walks);
* final absolute errors (last sample, beta against beta_ref);
* obstacle clearance (robot footprint to the nearest obstacle surface) and the number of
  separate collisions;
* the shares of the samples in which the safety supervisor was ok, degraded or stopped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.geometry import wrap_pi_array
from companion.types import Log


@dataclass(frozen=True)
class Tolerance:
    rho: float = 0.02    # m
    alpha: float = 0.02  # rad
    beta: float = 0.02   # rad


def errors(log: Log) -> dict[str, np.ndarray]:
    """Per-sample errors: rho_e, alpha_e, beta_e (vs 0) and beta_ref_e (vs beta_ref)."""
    return {
        "rho": log["rho"] - log["rho_d"],
        "alpha": wrap_pi_array(log["alpha"] - log["alpha_d"]),
        "beta": wrap_pi_array(log["beta"]),
        "beta_ref": wrap_pi_array(log["beta"] - log["beta_ref"]),
    }


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def settling_time(log: Log, tol: Tolerance = Tolerance()) -> float | None:
    """First time from which all errors stay inside ``tol`` to the end, or None."""
    e = errors(log)
    inside = ((np.abs(e["rho"]) < tol.rho) & (np.abs(e["alpha"]) < tol.alpha)
              & (np.abs(e["beta_ref"]) < tol.beta))
    if len(inside) == 0 or not inside[-1]:
        return None
    outside = np.flatnonzero(~inside)
    first = 0 if len(outside) == 0 else outside[-1] + 1
    return float(log["t"][first])


def obstacle_metrics(log: Log) -> dict:
    """``min_obstacle_clearance_m`` (footprint to surface; None without obstacles) and
    ``obstacle_collisions``: the number of separate contacts (entries into clearance <= 0)."""
    rho_ob = log["rho_ob"]
    if len(rho_ob) == 0 or np.all(np.isnan(rho_ob)):
        return {"min_obstacle_clearance_m": None, "obstacle_collisions": 0}
    contact = rho_ob <= 0.0
    entries = int(contact[0]) + int(np.count_nonzero(contact[1:] & ~contact[:-1]))
    return {"min_obstacle_clearance_m": float(np.nanmin(rho_ob)), "obstacle_collisions": entries}


def status_shares(log: Log) -> dict:
    """Shares of the samples in which the safety supervisor reported each status."""
    status = log.columns.get("status")
    if status is None or len(status) == 0:
        return {"share_ok": 1.0, "share_degraded": 0.0, "share_stopped": 0.0}
    return {f"share_{s}": float(np.mean(status == s)) for s in ("ok", "degraded", "stopped")}


def _duration(log: Log) -> float:
    """Simulated time covered by the log: the last sample plus one period."""
    t = log["t"]
    return float(t[-1] + (t[1] - t[0])) if len(t) > 1 else 0.0


def compute(log: Log, tol: Tolerance = Tolerance()) -> dict:
    """All metrics as a JSON-ready dict (SI units; key names carry the unit)."""
    e = errors(log)
    dist = np.hypot(log["robot_x"] - log["person_x"], log["robot_y"] - log["person_y"])
    settle = settling_time(log, tol)
    values = {
        "rmse_rho_m": _rms(e["rho"]),
        "rmse_alpha_rad": _rms(e["alpha"]),
        "rmse_beta_rad": _rms(e["beta"]),
        "rmsv_v_mps": _rms(log["v"] - log["person_v"]),
        "rmsv_omega_radps": _rms(log["omega"] - log["person_omega"]),
        "min_person_distance_m": float(np.min(dist)),
        "settling_time_s": settle,
        "final_abs_error": {
            "rho_m": float(abs(e["rho"][-1])),
            "alpha_rad": float(abs(e["alpha"][-1])),
            "beta_rad": float(abs(e["beta_ref"][-1])),
        },
        "duration_s": _duration(log),
        "steps": len(log),
    }
    values.update(obstacle_metrics(log))
    values.update(status_shares(log))
    finite = all(math.isfinite(v) for v in (values["rmse_rho_m"], values["rmse_alpha_rad"]))
    values["finite"] = bool(finite and np.all(np.isfinite(log["v"]))
                            and np.all(np.isfinite(log["omega"])))
    return values
