"""Tuning a controller's parameters with Optuna on a suite (``companion tune CONTROLLER
--suite SUITE.toml``; docs/evaluation.md).

Each trial runs the suite's episodes of the controller with candidate parameters (on the
same backends as ``companion evaluate``) and scores them with :func:`objective`. Trials are
kept in an Optuna storage when one is given, so a stopped study resumes; the first trial is
the controller's current parameters. The search spaces are :data:`SPACES`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.errors import ConfigError
from companion.evaluate.run import run_results
from companion.evaluate.suite import Suite
from companion.params import Params


@dataclass(frozen=True)
class Dim:
    """One tuned value: ``section.field`` (``index`` for tuple fields), searched log-uniformly
    in [low, high]."""

    section: str
    field: str
    low: float
    high: float
    index: int | None = None

    @property
    def name(self) -> str:
        return f"{self.section}.{self.field}" + ("" if self.index is None else f"[{self.index}]")


SPACES: dict[str, tuple[Dim, ...]] = {
    "lqr": tuple(Dim("lqr", "q", 1.0, 300.0, i) for i in range(5))
    + tuple(Dim("lqr", "r", 1.0, 300.0, i) for i in range(2)),
    "pid": (Dim("pid", "kp_x", 0.2, 5.0), Dim("pid", "ki_x", 0.01, 2.0),
            Dim("pid", "kd_x", 0.01, 1.0), Dim("pid", "kp_y", 0.2, 8.0),
            Dim("pid", "ki_y", 0.01, 2.0), Dim("pid", "kd_y", 0.01, 1.0),
            Dim("pid", "kp_theta", 0.2, 6.0)),
    "vsm": (Dim("vsm", "stiffness", 0.2, 20.0), Dim("vsm", "damping", 0.1, 20.0),
            Dim("vsm", "mass", 0.1, 5.0)),
    "ic": tuple(Dim("impedance", f, lo, hi, i) for f, lo, hi in
                (("mass", 0.1, 5.0), ("damping", 0.1, 20.0), ("stiffness", 0.2, 20.0))
                for i in range(2)),
}

#: The person tracker's process noises and switching rates (``bench/tune_tracker.py`` tunes
#: them on a suite's episodes of the default LQR).
TRACKER_SPACE: tuple[Dim, ...] = (
    Dim("tracker", "accel_std", 0.1, 1.5), Dim("tracker", "turn_accel_std", 0.1, 3.0),
    Dim("tracker", "maneuver_accel_std", 0.5, 5.0),
    Dim("tracker", "maneuver_turn_accel_std", 0.3, 6.0),
    Dim("tracker", "maneuver_start_rate", 0.05, 5.0),
    Dim("tracker", "maneuver_end_rate", 0.2, 10.0))

#: The objective's weights: metres of slot error per radian of bearing error, and the metres
#: added per unsafe episode.
ALPHA_WEIGHT = 0.25
UNSAFE_PENALTY = 0.1


def apply(params: Params, dims: Sequence[Dim], values: Sequence[float]) -> Params:
    """``params`` with each ``dims[i]`` set to ``values[i]``."""
    for dim, value in zip(dims, values):
        section = getattr(params, dim.section)
        current = getattr(section, dim.field)
        if dim.index is not None:
            current = tuple(value if i == dim.index else c for i, c in enumerate(current))
        else:
            current = float(value)
        params = dataclasses.replace(
            params, **{dim.section: dataclasses.replace(section, **{dim.field: current})})
    return params


def current(params: Params, dims: Sequence[Dim]) -> list[float]:
    """The values of ``dims`` in ``params``."""
    out = []
    for dim in dims:
        value = getattr(getattr(params, dim.section), dim.field)
        out.append(float(value if dim.index is None else value[dim.index]))
    return out


def as_toml(params: Params, dims: Sequence[Dim]) -> str:
    """The tuned sections of ``params`` as a TOML file for ``--params`` or a suite."""
    lines = []
    for section in dict.fromkeys(d.section for d in dims):
        lines.append(f"[{section}]")
        for field in dict.fromkeys(d.field for d in dims if d.section == section):
            value = getattr(getattr(params, section), field)
            text = (f"[{', '.join(f'{v:.6g}' for v in value)}]" if isinstance(value, tuple)
                    else f"{value:.6g}")
            lines.append(f"{field} = {text}")
        lines.append("")
    return "\n".join(lines)


def objective(rows: Sequence[dict]) -> float:
    """J = median slot error (m) + :data:`ALPHA_WEIGHT` x median RMSE alpha (rad) +
    :data:`UNSAFE_PENALTY` per unsafe episode (a robot-caused contact or protective
    violation, an obstacle contact, or a non-finite value)."""
    slot = np.median([r["rms_slot_error_m"] for r in rows])
    alpha = np.median([r["rmse_alpha_rad"] for r in rows])
    unsafe = sum(not r["safe"] or not r["finite"] for r in rows)
    j = float(slot + ALPHA_WEIGHT * alpha) + UNSAFE_PENALTY * unsafe
    return j if math.isfinite(j) else 1e6


@dataclass(frozen=True)
class Tuned:
    controller: str
    dims: tuple[Dim, ...]
    best: tuple[float, ...]
    best_value: float
    start_value: float
    trials: int
    params: Params
    history: tuple[tuple[int, float], ...]   # (trial number, J) of every finished trial


def _optuna() -> Any:
    try:
        import optuna
    except ImportError:
        raise ConfigError("--suite: tuning needs optuna (pip install -e '.[tune]')") from None
    return optuna


def _reason(exc: BaseException) -> str:
    """The first line of what went wrong (SQLAlchemy: its driver's error, without the
    'Background on this error' line)."""
    orig = getattr(exc, "orig", None)
    text = str(orig if isinstance(orig, BaseException) else exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def open_storage(storage: Any) -> Any:
    """The Optuna storage of the URL ``storage`` (``sqlite:///study.db``), opened now; None
    (in memory) and storage objects as given. A URL that cannot be opened (a bad URL, a
    folder that does not exist, a database that is a folder) raises a one-line ConfigError
    naming it."""
    if not isinstance(storage, str):
        return storage
    optuna = _optuna()
    try:
        return optuna.storages.RDBStorage(storage)
    except Exception as exc:        # optuna and SQLAlchemy raise many kinds for a bad URL
        raise ConfigError(f"--storage {storage}: cannot open it ({_reason(exc)})") from None


def tune_on_suite(suite: Suite, controller: str, trials: int, storage: Any = None,
                  study_name: str | None = None, workers: int | None = None,
                  dask: str | None = None, seed: int = 0,
                  progress: Callable[[int, float], None] | None = None,
                  dims: Sequence[Dim] | None = None) -> Tuned:
    """Optuna's TPE sampler (seeded) over ``dims`` (default: :data:`SPACES` of
    ``controller``), each trial the suite's episodes of that controller (its other
    controllers are ignored), until the study holds ``trials`` finished trials.
    ``storage``: a URL or a storage of :func:`open_storage` (None: in memory).
    ``progress(trial number, its J)`` after each."""
    optuna = _optuna()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    dims = tuple(dims or SPACES[controller])
    episodes = [e for e in suite.episodes if e.controller == controller]
    if not episodes:
        raise ValueError(f"the suite has no episodes of {controller!r}")
    base = episodes[0].spec.params
    space = "-".join(dict.fromkeys(d.section for d in dims))
    name = study_name or f"companion-{controller}-{space}-{suite.digest[:16]}"  # per suite
    url = storage
    storage = open_storage(storage)
    try:
        study = optuna.create_study(study_name=name, storage=storage, load_if_exists=True,
                                    direction="minimize",
                                    sampler=optuna.samplers.TPESampler(seed=seed))
    except Exception as exc:        # optuna raises many kinds for a storage it cannot use
        raise ConfigError(f"--storage {url}: {_reason(exc)}") from None
    # A resumed study draws on from a seed of its own: the seed alone would repeat the
    # first session's draws.
    study.sampler = optuna.samplers.TPESampler(seed=seed + len(study.trials))
    complete = optuna.trial.TrialState.COMPLETE
    if not any(t.state == complete for t in study.trials):   # the current gains first
        study.enqueue_trial({d.name: v for d, v in zip(dims, current(base, dims))})

    def run(trial: Any) -> float:
        values = [trial.suggest_float(d.name, d.low, d.high, log=True) for d in dims]
        cache: dict[int, Params] = {}
        candidates = []
        for e in episodes:
            if id(e.spec.params) not in cache:
                cache[id(e.spec.params)] = apply(e.spec.params, dims, values)
            candidates.append(dataclasses.replace(e, spec=dataclasses.replace(
                e.spec, params=cache[id(e.spec.params)])))
        trial_suite = dataclasses.replace(suite, episodes=tuple(candidates))
        value = objective(run_results(trial_suite, None, workers, dask))
        if progress:
            progress(trial.number, value)
        return value

    done = sum(t.state == complete for t in study.trials)
    if done < trials:
        study.optimize(run, n_trials=trials - done)
    finished = [t for t in study.trials if t.state == complete]
    best = study.best_trial
    values = tuple(best.params[d.name] for d in dims)
    history = tuple((t.number, float(t.value)) for t in finished)
    return Tuned(controller, dims, values, float(best.value), float(finished[0].value),
                 len(finished), apply(base, dims, values), history)
