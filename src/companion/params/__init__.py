"""Every parameter of companion, the paper's Table 1 values as defaults.

One frozen, typed tree (:class:`Params`) validated in one place (:mod:`companion.config`),
its sections in :mod:`.control` and :mod:`.sensing`. docs/parameters.md documents every
field; a test keeps the two in step.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from companion.config import Validated, build, hint, load_toml, param, ranged, validate
from companion.errors import ConfigError
from companion.params.control import (
    BEHIND,
    FRONT,
    LEFT,
    RIGHT,
    SIDES,
    AvoidanceParams,
    Formation,
    ImpedanceParams,
    KeepOutParams,
    LqrParams,
    PidParams,
    RobotParams,
    SearchParams,
    SupervisorParams,
    VsmParams,
)
from companion.params.plant import PLANTS, PlantParams
from companion.params.sensing import (
    IDEAL,
    PROFILES,
    REALISTIC,
    ExtractorParams,
    LidarParams,
    MoverParams,
    SensingParams,
    TrackerParams,
)

__all__ = ["BEHIND", "FRONT", "IDEAL", "LEFT", "PLANTS", "PROFILES", "REALISTIC", "RIGHT",
           "SIDES", "PlantParams",
           "AvoidanceParams", "ExtractorParams", "Formation", "ImpedanceParams", "SearchParams",
           "KeepOutParams", "LidarParams", "MoverParams", "LqrParams", "Params", "PidParams",
           "RobotParams", "SensingParams", "SupervisorParams", "TrackerParams", "VsmParams",
           "load_params", "load_sensing", "params_from_mapping", "sensing_params",
           "side_to_bearing"]


@ranged("[0.001, 1]")
def _sample_period(x: float) -> str | None:
    return None if 1e-3 <= x <= 1.0 else "a sample period in [0.001, 1] s"


@dataclasses.dataclass(frozen=True)
class Params(Validated):
    """Everything that tunes a run; defaults are the paper's Table 1."""

    dt: float = param(0.05, "s", "sample period T of controller and simulator, in [0.001, 1]",
                      _sample_period)
    robot: RobotParams = param(RobotParams(), "", "")
    formation: Formation = param(Formation(), "", "")
    lqr: LqrParams = param(LqrParams(), "", "")
    keepout: KeepOutParams = param(KeepOutParams(), "", "")
    supervisor: SupervisorParams = param(SupervisorParams(), "", "")
    search: SearchParams = param(SearchParams(), "", "")
    sensing: SensingParams = param(IDEAL, "", "")
    tracker: TrackerParams = param(TrackerParams(), "", "")
    avoidance: AvoidanceParams = param(AvoidanceParams(), "", "")
    lidar: LidarParams = param(LidarParams(), "", "")
    extractor: ExtractorParams = param(ExtractorParams(), "", "")
    movers: MoverParams = param(MoverParams(), "", "")
    pid: PidParams = param(PidParams(), "", "")
    vsm: VsmParams = param(VsmParams(), "", "")
    impedance: ImpedanceParams = param(ImpedanceParams(), "", "")
    plant: PlantParams = param(PlantParams(), "", "")

    def __post_init__(self) -> None:
        super().__post_init__()
        f, k = self.formation, self.keepout
        # robot centre (axle) in the slot, heading with the person: R - d e(theta_h)
        centre = math.hypot(f.distance * math.cos(f.bearing) - self.robot.d,
                            f.distance * math.sin(f.bearing))
        for name, keep in (("keepout.person_clearance", k.person_clearance),
                           ("keepout.protective_distance", k.protective_distance)):
            if centre < keep:
                raise ConfigError(
                    f"formation.distance: the slot at {f.distance:g} m, bearing "
                    f"{f.bearing:.3f} rad puts the robot centre {centre:.2f} m from the person, "
                    f"inside {name} ({keep:g} m); expected a larger distance or a smaller "
                    f"{name.split('.')[1]}")

        s, tr = self.sensing, self.tracker
        if s.person_latency_s >= tr.max_delay_s:
            raise ConfigError(
                f"sensing.person_latency_s: expected less than tracker.max_delay_s "
                f"({tr.max_delay_s:g} s; every detection would arrive stale), got "
                f"{s.person_latency_s!r}")
        if 1.0 / s.person_rate_hz > tr.lost_after_s:
            raise ConfigError(
                f"sensing.person_rate_hz: expected at least 1 / tracker.lost_after_s "
                f"({1.0 / tr.lost_after_s:g} Hz; the person would be lost between "
                f"detections), got {s.person_rate_hz!r}")
        if 1.0 / s.lidar_rate_hz >= self.lidar.timeout_s:
            raise ConfigError(
                f"sensing.lidar_rate_hz: expected more than 1 / lidar.timeout_s "
                f"({1.0 / self.lidar.timeout_s:g} Hz; the obstacles would be dropped between "
                f"scans), got {s.lidar_rate_hz!r}")

    def replace(self, **changes: Any) -> Params:
        """A copy with top-level fields replaced, validated."""
        out = dataclasses.replace(self, **changes)
        validate(out)
        return out


def side_to_bearing(value: Any, name: str) -> Any:
    """Map a side name to its bearing; other values pass through unchanged for validation."""
    if isinstance(value, str):
        if value not in SIDES:
            raise ConfigError(f"{name}: expected a bearing in rad or one of "
                              f"{', '.join(map(repr, SIDES))}, got {value!r}")
        return SIDES[value]
    return value


#: Keys that moved to another section: old name -> new name (named in the error).
MOVED = {"safety": "keepout", "supervisor.protective_distance": "keepout.protective_distance",
         "supervisor.person_accel": "keepout.person_accel",
         "supervisor.person_timeout": "tracker.lost_after_s",
         "supervisor.max_person_speed": "tracker.max_person_speed",
         "supervisor.max_person_turn_rate": "tracker.max_person_turn_rate",
         "supervisor.jump_tolerance": "tracker.gate_floor_m",
         "supervisor.reacquire_time": "tracker.reacquire_time_s",
         "lidar.rate": "sensing.lidar_rate_hz"}


def _reject_moved(mapping: Mapping[str, Any], prefix: str) -> None:
    for old, new in MOVED.items():
        section, _, key = old.partition(".")
        table = mapping.get(section)
        if table is not None and (not key or (isinstance(table, Mapping) and key in table)):
            raise ConfigError(f"{prefix}{old}: moved to {new} (docs/parameters.md)")


def sensing_from(value: Any, name: str) -> Any:
    """A profile name (``"ideal"``, ``"realistic"``) becomes its table; tables pass through."""
    if isinstance(value, str):
        if value not in PROFILES:
            raise ConfigError(f"{name}: expected a table or one of "
                              f"{', '.join(map(repr, PROFILES))}, got {value!r}")
        return {k: v for k, v in dataclasses.asdict(PROFILES[value]).items() if v is not None}
    return value


def sensing_params(value: Any, name: str) -> SensingParams:
    """The sensing of a profile name or a table (missing keys: the realistic profile's);
    errors name ``name`` and the key."""
    return build(SensingParams, sensing_from(value, name), prefix=f"{name}.")


def load_sensing(name_or_path: str) -> SensingParams:
    """A profile by name (``ideal``, ``realistic``) or a TOML file of sensing keys; errors
    name the file and key."""
    if name_or_path in PROFILES:
        return PROFILES[name_or_path]
    if not name_or_path.endswith(".toml"):
        raise ConfigError(f"expected {' or '.join(PROFILES)} or a .toml file, got "
                          f"{name_or_path!r}{hint(name_or_path, PROFILES)}")
    return build(SensingParams, load_toml(name_or_path), prefix=f"{name_or_path}: ")


def params_from_mapping(mapping: Mapping[str, Any], prefix: str = "") -> Params:
    """Build validated :class:`Params` from a parsed TOML mapping. Missing keys of ``sensing``
    take the ``realistic`` profile's values (a sensing table describes a real sensor); without
    a ``sensing`` table the sensing is ideal."""
    _reject_moved(mapping, prefix)
    mapping = dict(mapping)
    if "sensing" in mapping:
        mapping["sensing"] = sensing_from(mapping["sensing"], f"{prefix}sensing")
    formation = mapping.get("formation")
    if isinstance(formation, Mapping) and "bearing" in formation:
        formation = dict(formation)
        formation["bearing"] = side_to_bearing(formation["bearing"],
                                               f"{prefix}formation.bearing")
        mapping["formation"] = formation
    return build(Params, mapping, prefix=prefix)


def load_params(path: str | Path) -> Params:
    """Load :class:`Params` from a TOML file; errors name the file and key."""
    return params_from_mapping(load_toml(path), prefix=f"{path}: ")
