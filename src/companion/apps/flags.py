"""The flags several commands share, and the ranges of the numeric command-line flags: the
one place that the checks (:mod:`companion.apps.args`) and ``--help``
(:mod:`companion.apps.cli`) both read. Standard library only, so that ``--help`` loads no
numerics."""

from __future__ import annotations

import argparse
from dataclasses import dataclass

from companion.config import MAX_DURATION, MAX_MAGNITUDE


@dataclass(frozen=True)
class Bound:
    """``low <= x <= high`` (``low < x`` if ``low_open``), in ``unit``; ``high_text`` spells
    ``high`` where ``%g`` would round it."""

    low: float
    high: float
    low_open: bool = False
    unit: str = ""
    high_text: str = ""

    def contains(self, x: float) -> bool:
        return (self.low < x if self.low_open else self.low <= x) and x <= self.high

    def text(self, metavar: str) -> str:
        """The range as ``--help`` shows it, e.g. ``0 < S <= 86400 s``."""
        high = self.high_text or f"{self.high:g}"
        unit = f" {self.unit}" if self.unit else ""
        return f"{self.low:g} {'<' if self.low_open else '<='} {metavar} <= {high}{unit}"


DURATION = Bound(0.0, MAX_DURATION, True, "s")
COORDINATE = Bound(-MAX_MAGNITUDE, MAX_MAGNITUDE)
#: What a walking (or jogging) person can do (as sim.scenario.SPEED).
SPEED = Bound(0.0, 3.0, unit="m/s")
COUNT = Bound(1, int(MAX_MAGNITUDE))
WORKERS = Bound(1, 256)
SEED = Bound(0, 2**63 - 1, high_text="2**63-1")

#: Every numeric flag, by name (the same flag has the same range in every command).
FLAGS: dict[str, Bound] = {
    "--duration": DURATION,
    "--distance": Bound(0.0, MAX_MAGNITUDE, True, "m"),
    "--bearing": COORDINATE,
    "--start": COORDINATE,
    "--speeds": SPEED,
    "--settle-limit": DURATION,
    "--min-speed": SPEED,
    "--min-duration": Bound(0.0, MAX_DURATION, unit="s"),
    "--workers": WORKERS,
    "--trials": COUNT,
    "--episodes": COUNT,
    "--seed": SEED,
    "--wait": Bound(0.0, 3600.0, True, "s"),
    "--rate": Bound(0.0, 100.0, True),
    "--domain-id": Bound(0, 232),
    "--steps": Bound(1, 1_000_000_000, high_text="1e9"),
    #: fuzz episode seeds: run seed * 10**7 + episode index (companion.sim.fuzz.SEED_STRIDE)
    "--replay": Bound(0, (2**63) * 10**7 - 1, high_text="2**63*10**7-1"),
}


def help_range(flag: str, metavar: str) -> str:
    """The range of ``flag`` for its ``--help`` line."""
    return FLAGS[flag].text(metavar)


#: The plants ``--plant`` takes (:data:`companion.params.PLANTS`; tests/test_cli.py checks).
PLANTS = ("kinematic", "mujoco")


def plant_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plant", choices=PLANTS, help="the robot's base: kinematic (a unicycle "
                   "with lag) or mujoco (mass, wheels, motors, slip; docs/plants.md); default: "
                   "the scenario's or parameters', else kinematic")


def sensing_flags(p: argparse.ArgumentParser) -> None:
    """``--sensing`` and ``--plant``: the world an episode runs in."""
    p.add_argument("--sensing", metavar="PROFILE", help="ideal, realistic, em-tracker or a TOML "
                   "file of sensing keys (docs/sensing.md); default: the scenario's, else ideal")
    plant_flag(p)


def dask_flag(p: argparse.ArgumentParser, when: str = "") -> None:
    p.add_argument("--dask", metavar="ADDRESS", help=f"{when}run the episodes on Dask: 'local' "
                   "starts a LocalCluster on 127.0.0.1, tcp://HOST:PORT uses a running "
                   "scheduler (default: local worker processes)")


def workers_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=int, metavar="N",
                   help=f"worker processes for the episodes, {help_range('--workers', 'N')} "
                        "(default: one per CPU)")
