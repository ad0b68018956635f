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
* the shares of the samples in which the safety supervisor was ok, degraded or stopped;
* the social-navigation measures of a robot among people (:mod:`companion.social`);
* the plant's: contacts the physics found and the odometry's largest drift (docs/plants.md);
* where the slot error comes from (docs/sensing.md): the RMS of the slot error, of the
  estimate's own error and of the tracking of the estimated slot (over the samples with an
  estimate), and the displacement the keep-out imposed, summed over the run, with the share
  of samples in which it acted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.geometry import wrap_pi_array
from companion.social import Social
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


def settling_time(log: Log, tol: Tolerance = Tolerance()) -> float | None:
    """First time from which all errors stay inside ``tol`` to the end, or None."""
    settle = Settling(tol)
    settle.add(log, errors(log))
    return settle.value()


def obstacle_metrics(log: Log) -> dict:
    """``min_obstacle_clearance_m`` (footprint to surface; None without obstacles) and
    ``obstacle_collisions``: the number of separate contacts (entries into clearance <= 0)."""
    ob = Obstacles()
    ob.add(log)
    return ob.value()


def status_shares(log: Log) -> dict:
    """Shares of the samples in which the safety supervisor reported each status."""
    shares = Statuses()
    shares.add(log)
    return shares.value()


def compute(log: Log, tol: Tolerance = Tolerance()) -> dict:
    """All metrics as a JSON-ready dict (SI units; key names carry the unit)."""
    running = Running(tol)
    running.add(log)
    return running.value()


# Each metric is kept by an accumulator fed the log block by block (one block: the whole log),
# so that a long episode streamed to disk (companion.sim.episode.episode_blocks) is measured
# in bounded memory by the same code as a log in memory.

class Entries:
    """The number of separate entries into a condition over consecutive blocks of samples:
    samples where it holds and did not hold at the sample before (the first sample counts
    when it holds)."""

    def __init__(self) -> None:
        self.count = 0
        self._last = False

    def add(self, holds: np.ndarray) -> None:
        if len(holds):
            self.count += int(holds[0] and not self._last) + int(np.count_nonzero(
                holds[1:] & ~holds[:-1]))
            self._last = bool(holds[-1])


class Settling:
    """Settling time (see :func:`settling_time`) over consecutive blocks."""

    def __init__(self, tol: Tolerance = Tolerance()):
        self.tol = tol
        self._time: float | None = None
        self._pending = True      # the settling sample is the next block's first
        self._inside_at_end = False

    def add(self, log: Log, e: dict[str, np.ndarray]) -> None:
        tol = self.tol
        inside = ((np.abs(e["rho"]) < tol.rho) & (np.abs(e["alpha"]) < tol.alpha)
                  & (np.abs(e["beta_ref"]) < tol.beta))
        if len(inside) == 0:
            return
        outside = np.flatnonzero(~inside)
        if len(outside):
            first = outside[-1] + 1
            self._pending = first == len(inside)
            self._time = None if self._pending else float(log["t"][first])
        elif self._pending:
            self._time, self._pending = float(log["t"][0]), False
        self._inside_at_end = bool(inside[-1])

    def value(self) -> float | None:
        return self._time if self._inside_at_end else None


class Obstacles:
    """Obstacle clearance and contacts (see :func:`obstacle_metrics`) over consecutive blocks."""

    def __init__(self) -> None:
        self._min: float | None = None
        self._contacts = Entries()

    def add(self, log: Log) -> None:
        rho_ob = log["rho_ob"]
        if len(rho_ob) and not np.all(np.isnan(rho_ob)):
            low = float(np.nanmin(rho_ob))
            self._min = low if self._min is None else min(self._min, low)
        self._contacts.add(rho_ob <= 0.0)

    def value(self) -> dict:
        if self._min is None:
            return {"min_obstacle_clearance_m": None, "obstacle_collisions": 0}
        return {"min_obstacle_clearance_m": self._min,
                "obstacle_collisions": self._contacts.count}


STATUSES = ("ok", "degraded", "stopped")


class Statuses:
    """Shares of the supervisor's statuses (see :func:`status_shares`) over consecutive
    blocks."""

    def __init__(self) -> None:
        self._n = 0
        self._counts = dict.fromkeys(STATUSES, 0)

    def add(self, log: Log) -> None:
        status = log.columns.get("status")
        if status is not None:
            self._n += len(status)
            for s in STATUSES:
                self._counts[s] += int(np.count_nonzero(status == s))

    def value(self) -> dict:
        if self._n == 0:
            return {"share_ok": 1.0, "share_degraded": 0.0, "share_stopped": 0.0}
        return {f"share_{s}": self._counts[s] / self._n for s in STATUSES}


#: The root-mean-square metrics: key and the per-sample error it is taken of.
RMS = {
    "rmse_rho_m": lambda log, e: e["rho"],
    "rmse_alpha_rad": lambda log, e: e["alpha"],
    "rmse_beta_rad": lambda log, e: e["beta"],
    "rmsv_v_mps": lambda log, e: log["v"] - log["person_v"],
    "rmsv_omega_radps": lambda log, e: log["omega"] - log["person_omega"],
}


class Split:
    """Where the slot error comes from (the log's ``slot_error_m``, ``estimate_error_m``,
    ``tracking_error_m`` and ``safety_shift_m``) over consecutive blocks."""

    def __init__(self) -> None:
        self._squares = {"slot": 0.0, "estimate": 0.0, "tracking": 0.0}
        self._n = {"slot": 0, "estimate": 0, "tracking": 0}
        self._shift, self._acted = 0.0, 0
        self._final = math.nan

    def add(self, log: Log) -> None:
        self._final = float(log["slot_error_m"][-1])
        for key in self._squares:
            e = log[f"{key}_error_m"]
            e = e[np.isfinite(e)]
            self._squares[key] += float(np.sum(e * e))
            self._n[key] += len(e)
        shift = log["safety_shift_m"]
        self._shift += float(np.sum(shift))
        self._acted += int(np.count_nonzero(shift > 1e-9))

    def value(self, steps: int) -> dict:
        out = {f"rms_{key}_error_m": math.sqrt(sq / self._n[key]) if self._n[key] else None
               for key, sq in self._squares.items()}
        out["final_slot_error_m"] = self._final
        out["safety_shift_m"] = self._shift
        out["safety_share"] = self._acted / steps if steps else 0.0
        return out


class PlantMeasures:
    """The plant's own measures over consecutive blocks: the contacts the physics found (the
    number of times the robot's body began to touch the person or an obstacle; None on a
    plant without bodies) and the odometry's largest distance from the true pose (m)."""

    def __init__(self) -> None:
        self._contacts: int | None = None
        self._touching = False
        self._drift = 0.0

    def add(self, log: Log) -> None:
        c = log["plant_contact"]
        if np.all(np.isnan(c)):
            return
        touching = np.concatenate(([self._touching], c > 0.5))
        self._contacts = (self._contacts or 0) + int(np.count_nonzero(touching[1:]
                                                                        & ~touching[:-1]))
        self._touching = bool(touching[-1])
        drift = np.hypot(log["odom_x"] - log["robot_x"], log["odom_y"] - log["robot_y"])
        self._drift = max(self._drift, float(np.max(drift)))

    def value(self) -> dict:
        return {"plant_contacts": self._contacts, "odometry_drift_m": self._drift}


class Running:
    """All the metrics of :func:`compute` over consecutive blocks of one episode's log:
    ``add`` each block in order, then ``value()``. Sums of squares, minima and counts are
    kept, not the samples."""

    def __init__(self, tol: Tolerance = Tolerance()):
        self.steps = 0
        self._squares = dict.fromkeys(RMS, 0.0)
        self._min_distance = math.inf
        self._settling = Settling(tol)
        self._obstacles = Obstacles()
        self._statuses = Statuses()
        self._split = Split()
        self._social = Social()
        self._plant = PlantMeasures()
        self._finite = True
        self._times: list[float] = []          # the first two sample times
        self._last: tuple[float, dict] = (math.nan, {})

    def add(self, log: Log) -> None:
        n = len(log)
        if n == 0:
            return
        e = errors(log)
        for key, error in RMS.items():
            self._squares[key] += float(np.sum(np.square(error(log, e))))
        dist = np.hypot(log["robot_x"] - log["person_x"], log["robot_y"] - log["person_y"])
        self._min_distance = float(np.minimum(self._min_distance, np.min(dist)))  # NaN stays
        self._settling.add(log, e)
        self._obstacles.add(log)
        self._statuses.add(log)
        self._split.add(log)
        self._social.add(log)
        self._plant.add(log)
        self._finite = self._finite and bool(np.all(np.isfinite(log["v"]))
                                             and np.all(np.isfinite(log["omega"])))
        t = log["t"]
        self._times = (self._times + [float(x) for x in t[:2]])[:2]
        self._last = (float(t[-1]), {"rho_m": float(abs(e["rho"][-1])),
                                     "alpha_rad": float(abs(e["alpha"][-1])),
                                     "beta_rad": float(abs(e["beta_ref"][-1]))})
        self.steps += n

    def value(self) -> dict:
        """The metrics as a JSON-ready dict (SI units; key names carry the unit)."""
        rms = {k: math.sqrt(s / self.steps) if self.steps else math.nan
               for k, s in self._squares.items()}
        t_last, final = self._last
        times = self._times
        values = {
            **rms,
            "min_person_distance_m": self._min_distance,
            "settling_time_s": self._settling.value(),
            "final_abs_error": final,
            # the simulated time covered: the last sample plus one period
            "duration_s": t_last + (times[1] - times[0]) if len(times) > 1 else 0.0,
            "steps": self.steps,
        }
        values.update(self._obstacles.value())
        values.update(self._statuses.value())
        values.update(self._split.value(self.steps))
        values.update(self._social.value())
        values.update(self._plant.value())
        values["finite"] = bool(self._finite and math.isfinite(rms["rmse_rho_m"])
                                and math.isfinite(rms["rmse_alpha_rad"]))
        return values


def binomial_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper-Pearson) interval of a proportion seen as ``k`` of ``n``: the rate of
    rare failures from a sample of episodes, conservative at the small counts they give.
    ``(0, 1)`` for ``n = 0``."""
    if not 0 <= k <= n:
        raise ValueError(f"binomial_interval: expected 0 <= k <= n, got k={k}, n={n}")
    if n == 0:
        return 0.0, 1.0
    from scipy.stats import binomtest  # scipy only where it is used
    ci = binomtest(k, n).proportion_ci(confidence_level=level, method="exact")
    return float(ci.low), float(ci.high)
