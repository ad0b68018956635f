"""``companion fuzz``'s flags: the controllers and sensing profiles to fuzz and the bounds of
--steps and --seed (the runs and their tables: :mod:`companion.evaluate.fuzz_runs`)."""

from __future__ import annotations

from collections.abc import Sequence

from companion.apps.args import UsageError, sensing_arg
from companion.apps.flags import FLAGS
from companion.control import CONTROLLERS
from companion.params import SensingParams
from companion.sim import fuzz

#: Bounds of --steps and --seed (the episode seeds stay below 2**63).
MAX_STEPS = FLAGS["--steps"].high
MAX_SEED = FLAGS["--seed"].high
MAX_EPISODE_SEED = (MAX_SEED + 1) * fuzz.SEED_STRIDE - 1


def names_arg(text: str | None, known: Sequence[str], flag: str) -> tuple[str, ...]:
    """A comma-separated list of names from ``known`` (all of them when ``text`` is None)."""
    if text is None:
        return tuple(known)
    names = tuple(n.strip() for n in text.split(","))
    bad = [n for n in names if n not in known]
    if bad or not names or len(set(names)) != len(names):
        raise UsageError(f"{flag}: expected distinct names from {', '.join(known)} separated "
                         f"by commas, got {text!r}")
    return names


def bounded_arg(value: int, low: int, high: int, flag: str) -> int:
    if not low <= value <= high:
        raise UsageError(f"{flag}: expected a whole number in [{low}, {high:,}], got {value}")
    return value


def selection(args) -> tuple[tuple[str, ...], dict[str, SensingParams]]:
    """The controllers of --controllers, and the sensing of --sensing by name: profile
    names or TOML files of sensing keys (docs/sensing.md), separated by commas."""
    controllers = names_arg(args.controllers, tuple(CONTROLLERS), "--controllers")
    if args.sensing is None:
        return controllers, dict(fuzz.FUZZ_PROFILES)
    names = tuple(n.strip() for n in args.sensing.split(","))
    if not all(names) or len(set(names)) != len(names):
        raise UsageError(f"--sensing: expected distinct profile names or .toml files "
                         f"separated by commas, got {args.sensing!r}")
    return controllers, {name: sensing_arg(name) for name in names}
