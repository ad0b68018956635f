"""The companion beside real walkers: one episode per ETH/UCY track (``companion pedestrians``).

Any result on these tracks carries :data:`companion.data.pedestrians.CREDIT`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from companion.data.pedestrians import Track
from companion.metrics import compute
from companion.params import Params
from companion.sim.recorded import DEFAULT_SMOOTHING, RecordedPerson, gap_faults
from companion.sim.runner import EpisodeSpec, run_many
from companion.types import Log


def episode(track: Track, params: Params, controller: str = "lqr",
            smoothing: float = DEFAULT_SMOOTHING) -> EpisodeSpec:
    """The track's person (:class:`~companion.sim.recorded.RecordedPerson`), the robot starting
    in its slot, for the track's duration; sample gaps longer than the person timeout are
    outages."""
    person = RecordedPerson(track.t, track.x, track.y, smoothing=smoothing)
    return EpisodeSpec(controller, person, params, person.duration,
                       faults=gap_faults(person, params.supervisor.person_timeout))


def summary(log: Log) -> dict:
    """The metrics of one track's episode that ``companion pedestrians`` reports."""
    m = compute(log)
    return {"max_person_speed_mps": float(np.max(log["person_v"])),
            **{k: m[k] for k in ("rmse_rho_m", "rmse_alpha_rad", "min_person_distance_m",
                                 "finite")}}


def evaluate_tracks(tracks: Sequence[Track], params: Params, controller: str = "lqr",
                    smoothing: float = DEFAULT_SMOOTHING, workers: int | None = None,
                    progress: Callable[[int], None] | None = None) -> list[dict]:
    """One row per track: ``scene``, ``ped_id``, ``duration_s``, ``mean_speed_mps`` (raw
    track) and :func:`summary` of its episode."""
    specs = [episode(track, params, controller, smoothing) for track in tracks]
    rows = run_many(specs, workers, summarize=summary, progress=progress)
    return [{"scene": t.scene, "ped_id": t.ped_id, "duration_s": t.duration,
             "mean_speed_mps": t.mean_speed, **row} for t, row in zip(tracks, rows)]
