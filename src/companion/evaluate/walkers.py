"""The companion beside real walkers: the suite of the shipped ETH/UCY tracks
(``companion pedestrians``, the benches of docs/sensing.md) and its per-controller table.

Any result on these tracks carries :data:`companion.data.pedestrians.CREDIT`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from companion.evaluate.suite import Suite, suite_from_mapping


def tracks_suite(controllers: Sequence[str | Mapping], sensing: Sequence[str | Mapping],
                 sides: Sequence[str] = ("left", "right"), every: int = 1, offset: int = 0,
                 name: str = "pedestrians", **motions: Any) -> Suite:
    """Every shipped track (``motions``: more keys of the suite's ``[motions]`` table, such
    as ``min_mean_speed``), robot in its slot on ``sides``, every controller and sensing
    (as in a suite file: names or tables), one seed."""
    data = {"name": name, "controllers": list(controllers), "sensing": list(sensing),
            "sides": list(sides), "reference": _label(controllers[0]),
            "motions": {"tracks": "eth_ucy", "every": every, "offset": offset, **motions}}
    return suite_from_mapping(data, Path(f"<{name}>"))


def _label(controller: str | Mapping) -> str:
    if isinstance(controller, str):
        return controller
    return str(controller.get("label", controller.get("name")))


def table(rows: Sequence[dict]) -> dict[str, dict]:
    """Per controller: runs, median and 90th percentile of RMSE rho, median RMSE alpha, the
    closest approach to the true person, whether every run stayed finite, and the medians of
    the slot error's split (:class:`companion.metrics.Split`; None without an estimate)."""
    out = {}
    for name in dict.fromkeys(r["controller"] for r in rows):
        mine = [r for r in rows if r["controller"] == name]
        rho = np.array([r["rmse_rho_m"] for r in mine])
        out[name] = {"runs": len(mine), "median_rho_m": float(np.median(rho)),
                     "p90_rho_m": float(np.percentile(rho, 90)),
                     "median_alpha_rad": float(np.median([r["rmse_alpha_rad"] for r in mine])),
                     "min_distance_m": float(min(r["min_person_distance_m"] for r in mine)),
                     "all_finite": all(r["finite"] for r in mine),
                     **{f"median_{k}": _median([r[k] for r in mine])
                        for k in ("rms_slot_error_m", "rms_estimate_error_m",
                                  "rms_tracking_error_m", "safety_shift_m", "safety_share")}}
    return out


def _median(values: Sequence[float]) -> float | None:
    """The median of the finite values (None if none is)."""
    known = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.median(known)) if known else None


def paired(rows: Sequence[dict], reference: str = "lqr") -> dict[str, dict]:
    """``reference`` against every other controller on the same runs: the share of runs in
    which it has the lower RMSE rho (alpha), and the median of its RMSE minus the other's."""
    ref = {r["pair"]: r for r in rows if r["controller"] == reference}
    out = {}
    for name in dict.fromkeys(r["controller"] for r in rows):
        if name == reference:
            continue
        pairs = [(ref[r["pair"]], r) for r in rows
                 if r["controller"] == name and r["pair"] in ref]
        entry: dict[str, Any] = {"runs": len(pairs)}
        for metric, short in (("rmse_rho_m", "rho"), ("rmse_alpha_rad", "alpha")):
            diff = np.array([a[metric] - b[metric] for a, b in pairs])
            entry[f"better_{short}"] = float(np.mean(diff < 0.0)) if len(diff) else np.nan
            entry[f"median_diff_{short}"] = float(np.median(diff)) if len(diff) else np.nan
        out[name] = entry
    return out
