"""The companion beside real walkers: one episode per ETH/UCY track, side and controller
(``companion pedestrians``, docs/sensing.md).

Any result on these tracks carries :data:`companion.data.pedestrians.CREDIT`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from companion.data.pedestrians import Track
from companion.evaluate.suite import track_episode
from companion.metrics import compute
from companion.params import Params
from companion.sim.recorded import DEFAULT_SMOOTHING, RecordedPerson
from companion.sim.runner import EpisodeSpec, run_many
from companion.types import Log

#: Per-run columns of ``pedestrians.csv``.
COLUMNS = ("scene", "ped_id", "side", "controller", "duration_s", "mean_speed_mps",
           "rmse_rho_m", "rmse_alpha_rad", "min_person_distance_m", "share_stopped", "finite",
           "rms_slot_error_m", "rms_estimate_error_m", "rms_tracking_error_m",
           "safety_shift_m", "safety_share")


def episode(track: Track, params: Params, controller: str = "lqr", side: str = "left",
            smoothing: float = DEFAULT_SMOOTHING, seed: int = 0) -> EpisodeSpec:
    """The track's person (:class:`~companion.sim.recorded.RecordedPerson`, not observed in
    its holes), the robot starting in its slot on ``side``, for the track's duration."""
    person = RecordedPerson(track.t, track.x, track.y, smoothing=smoothing)
    return track_episode(person, params, controller, side, seed)


def summary(log: Log) -> dict:
    """The metrics of one run that ``companion pedestrians`` reports."""
    m = compute(log)
    return {k: m[k] for k in COLUMNS[6:]}


def evaluate(tracks: Sequence[Track], params: Params, controllers: Sequence[str] = ("lqr",),
             sides: Sequence[str] = ("left", "right"), workers: int | None = None,
             progress: Callable[[int], None] | None = None) -> list[dict]:
    """One row (:data:`COLUMNS`) per track, side and controller; every controller runs the
    same episodes (seed = the track's index), so rows can be compared in pairs."""
    jobs = [(i, t, s, c) for i, t in enumerate(tracks) for s in sides for c in controllers]
    specs = [episode(t, params, c, s, seed=i) for i, t, s, c in jobs]
    results = run_many(specs, workers, summarize=summary, progress=progress)
    return [{"scene": t.scene, "ped_id": t.ped_id, "side": s, "controller": c,
             "duration_s": t.duration, "mean_speed_mps": t.mean_speed, **r}
            for (_, t, s, c), r in zip(jobs, results)]


def table(rows: Sequence[dict]) -> dict[str, dict]:
    """Per controller: runs, median and 90th percentile of RMSE rho, median RMSE alpha, the
    closest approach to the true person, whether every run stayed finite, and the medians of
    the slot error's split (:class:`companion.metrics.Split`)."""
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


def _median(values: Sequence[float | None]) -> float | None:
    """The median of the values that are not None (None if none is)."""
    known = [v for v in values if v is not None]
    return float(np.median(known)) if known else None


def paired(rows: Sequence[dict], reference: str = "lqr") -> dict[str, dict]:
    """``reference`` against every other controller on the same runs: the share of runs in
    which it has the lower RMSE rho (alpha), and the median of its RMSE minus the other's."""
    key = {(r["scene"], r["ped_id"], r["side"], r["controller"]): r for r in rows}
    out = {}
    for name in dict.fromkeys(r["controller"] for r in rows):
        if name == reference:
            continue
        pairs = [(key[(s, p, d, reference)], r) for (s, p, d, c), r in key.items()
                 if c == name and (s, p, d, reference) in key]
        entry = {"runs": len(pairs)}
        for metric, short in (("rmse_rho_m", "rho"), ("rmse_alpha_rad", "alpha")):
            diff = np.array([a[metric] - b[metric] for a, b in pairs])
            entry[f"better_{short}"] = float(np.mean(diff < 0.0)) if len(diff) else np.nan
            entry[f"median_diff_{short}"] = float(np.median(diff)) if len(diff) else np.nan
        out[name] = entry
    return out
