"""Command-line arguments turned into validated inputs: numbers, seeds, durations, parameter
files, scenarios with their flag overrides, output folders. Every error is a one-line
:class:`UsageError` (or the file's own ConfigError) naming the flag, file or key, raised
before any work."""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path

from companion.apps.flags import FLAGS
from companion.config import MAX_MAGNITUDE, load_toml
from companion.control import make_controller
from companion.errors import CompanionError, ConfigError
from companion.geometry import wrap_2pi
from companion.params import Params, SensingParams, load_sensing, params_from_mapping
from companion.sim.recorded import load_person_csv
from companion.sim.scenario import Scenario, load_scenario
from companion.swap import unswitchable
from companion.types import Pose


class UsageError(CompanionError):
    """Bad command-line usage."""


def floats_arg(text: str, n: int, what: str) -> tuple[float, ...]:
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        count = "a number" if n == 1 else f"{n} comma-separated numbers"
        raise UsageError(f"{what}: expected {count}, got {text!r}") from None
    if len(values) != n or not all(abs(v) <= MAX_MAGNITUDE for v in values):
        count = "a finite number" if n == 1 else f"{n} comma-separated finite numbers"
        raise UsageError(f"{what}: expected {count} of magnitude at most {MAX_MAGNITUDE:g}, "
                         f"got {text!r}")
    return values


def ranged(values: tuple[float, ...], text: str, flag: str, metavar: str) -> tuple[float, ...]:
    """``values`` if each is in the range of ``flag`` (:data:`companion.apps.flags.FLAGS`)."""
    bound = FLAGS[flag]
    if not all(bound.contains(v) for v in values):
        each = "each " if len(values) > 1 else ""
        raise UsageError(f"{flag}: expected {each}{bound.text(metavar)}, got {text!r}")
    return values


def number_arg(text: str, flag: str, metavar: str) -> float:
    """One number in the range of ``flag``."""
    return ranged(floats_arg(text, 1, flag), text, flag, metavar)[0]


def positive_arg(text: str, what: str) -> float:
    return number_arg(text, what, "M")


def duration_arg(text: str, what: str = "--duration", dt: float | None = None) -> float:
    """A simulated duration in (0, MAX_DURATION] s, at least one period ``dt``."""
    value = number_arg(text, what, "S")
    if dt is not None and value < dt:
        raise UsageError(f"{what}: expected at least one sample period (dt = {dt:g} s), "
                         f"got {text!r}")
    return value


def int_arg(value: int | None, flag: str, metavar: str = "N") -> int | None:
    """A whole-number flag in its range (None: not given)."""
    if value is not None:
        ranged((value,), str(value), flag, metavar)
    return value


def seed_arg(seed: int) -> int:
    return int_arg(seed, "--seed")


def checked_controllers(names: Sequence[str], params: Params, where: str | None) -> None:
    """Build each controller once, so that weights without a stabilising gain are a one-line
    error naming the file ``where`` they came from, before any work."""
    for name in names:
        try:
            make_controller(name, params)
        except CompanionError as exc:
            raise UsageError(f"{where}: {exc}" if where else str(exc)) from None


def file_params(args: argparse.Namespace) -> Params:
    """Table 1 defaults, or the ``--params FILE`` given, validated with the file's name."""
    return Params() if not args.params else params_from_mapping(
        load_toml(args.params), prefix=f"{args.params}: ")


def params_arg(args: argparse.Namespace) -> Params:
    """:func:`file_params` with the ``--sensing`` given."""
    return with_sensing(file_params(args), args)


def with_sensing(params: Params, args: argparse.Namespace) -> Params:
    """``params`` with the ``--sensing`` and ``--plant`` given (each if given)."""
    sensing, plant = getattr(args, "sensing", None), getattr(args, "plant", None)
    if sensing is not None:
        params = params.replace(sensing=sensing_arg(sensing))
    if plant is not None:
        params = params.replace(plant=dataclasses.replace(params.plant, kind=plant))
    return params


def sensing_arg(name: str) -> SensingParams:
    """The sensing of a ``--sensing`` profile name or TOML file; an error names the flag
    and the name, or the file and its key."""
    try:
        return load_sensing(name)
    except ConfigError as exc:
        raise UsageError(f"--sensing: {exc}") from None


def overrides(args: argparse.Namespace) -> dict:
    """Parameter overrides from --params, --side, --bearing and --distance."""
    over: dict = {}
    if args.params:
        over = load_toml(args.params)
        params_from_mapping(over, prefix=f"{args.params}: ")  # validate with the file's name
    formation = dict(over.get("formation", {}))
    if args.side and args.bearing is not None:
        raise UsageError("--side and --bearing: give one, not both")
    if args.side:
        formation["bearing"] = args.side
    if args.bearing is not None:
        bearing = number_arg(args.bearing, "--bearing", "RAD")
        formation["bearing"] = wrap_2pi(bearing)
    if args.distance is not None:
        formation["distance"] = positive_arg(args.distance, "--distance")
    if formation:
        over = dict(over, formation=formation)
    return over


def build_scenario(args: argparse.Namespace) -> Scenario:
    sc = load_scenario(args.scenario)           # the file's own errors name the file
    over = overrides(args)
    if over:
        try:
            sc = load_scenario(args.scenario, params_override=over)
        except ConfigError as exc:              # the flags' errors name the flags
            given = [f"--params {args.params}" if args.params else "",
                     "--side" if args.side else "", "--bearing" if args.bearing else "",
                     "--distance" if args.distance else ""]
            detail = str(exc).split(": ", 1)[-1]
            raise UsageError(f"{', '.join(g for g in given if g)}: {detail}") from None
    changes: dict = {}
    if args.controller:
        changes["controller"] = args.controller
    if args.start is not None:
        changes["start"] = Pose(*ranged(floats_arg(args.start, 3, "--start"), args.start,
                                        "--start", "X"))
    if args.person_csv:
        person = load_person_csv(args.person_csv)
        changes["person"] = person
        changes["duration"] = person.duration
        if person.duration < sc.params.dt:
            raise UsageError(f"{args.person_csv}: expected a recording of at least one sample "
                             f"period (dt = {sc.params.dt:g} s), got {person.duration:g} s")
    if args.duration is not None:
        changes["duration"] = duration_arg(args.duration, dt=sc.params.dt)
    if args.obstacles:
        changes["obstacle_source"] = args.obstacles
    if getattr(args, "seed", None) is not None:
        changes["seed"] = seed_arg(args.seed)
    changes["params"] = with_sensing(sc.params, args)
    return dataclasses.replace(sc, **changes)


def output_dir(path: Path, replaced: bool = True) -> Path:
    """Check (before any work) that ``path`` can be an output folder; the outputs go into it
    all together at the end, by replacing it (:class:`~companion.io.Outputs`; ``replaced``
    False: a folder that only gets new entries)."""
    if path.exists() and not path.is_dir():
        raise UsageError(f"--out {path}: exists and is not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--out {path}: cannot write there ({exc.strerror})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise UsageError(f"--out {path}: cannot write there (permission denied)")
    reason = unswitchable(path) if replaced else None
    if reason:
        raise UsageError(f"--out {path}: {reason}")
    return path


def shown(path: str | Path) -> str:
    """``path`` as the user can open it from the current folder: relative to it, or absolute
    where that would climb out more than one level; a folder ends with ``/``."""
    full = Path(path).absolute()
    try:
        text = os.path.relpath(full)
    except ValueError:                          # another drive
        text = str(full)
    if Path(text).parts.count("..") > 1:
        text = str(full)
    return text + os.sep if full.is_dir() else text


def wrote(paths: Iterable[str | Path], rest: str = "") -> str:
    """A command's last line: every file or folder it wrote, by :func:`shown`, then
    ``rest`` (for example ``"and the figures in out/x"``)."""
    return f"wrote {', '.join(shown(p) for p in paths)}{' ' + rest if rest else ''}"


def output_file(text: str, flag: str = "--out") -> Path:
    """Check (before any work) that ``text`` can be written as a file: not a folder, in a
    folder that exists (or can be made) and can be written (the file is written atomically
    at the end)."""
    path = Path(text)
    if path.is_dir():
        raise UsageError(f"{flag} {text}: is a folder, expected a file name")
    try:                                        # made and tried now, not after the run
        path.absolute().parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path.absolute().parent):
            pass
    except OSError as exc:
        raise UsageError(f"{flag} {text}: cannot write there ({exc.strerror})") from None
    return path


def workers_arg(args: argparse.Namespace) -> int | None:
    return int_arg(args.workers, "--workers")
