"""Typed, validated configuration from TOML: the one place where user-supplied keys are checked.

A config class is a frozen dataclass whose fields carry metadata:

* ``unit`` and ``doc`` (for docs/parameters.md),
* ``check``: a function ``value -> str | None`` returning what was expected when invalid,
* ``choices``: the allowed strings of a ``str`` field.

:func:`build` turns a mapping (parsed TOML) into such a dataclass, rejecting unknown keys with a
"did you mean" hint and naming the offending key, e.g. ``params.toml: lqr.q: expected 5 numbers``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import difflib
import functools
import math
import tomllib
import types
import typing
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar

from companion.errors import ConfigError

T = TypeVar("T")
Check = Callable[[Any], "str | None"]


def param(default: Any, unit: str, doc: str, check: Check | None = None,
          choices: tuple[str, ...] | None = None) -> Any:
    """Declare a documented configuration field with an optional validity check."""
    meta = {"unit": unit, "doc": doc, "check": check, "choices": choices}
    if isinstance(default, (list, dict)):
        raise TypeError("param: use a tuple for sequence defaults")
    if dataclasses.is_dataclass(default):
        return dataclasses.field(default_factory=lambda: default, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


#: Largest magnitude of any number in a configuration (m, s, rad, weights): beyond it a value
#: is a typo or an attack, and arithmetic on it overflows. A field that accepts ``inf`` says so.
MAX_MAGNITUDE = 1e6
#: The longest simulated time (s): a day (a log of about 400 MB). Scenario durations, every
#: ``--duration`` and the span of a recorded person are at most this.
MAX_DURATION = 86400.0


def ranged(text: str) -> Callable[[Check], Check]:
    """Decorate a check with its range as docs/parameters.md shows it (``check.range``)."""
    def mark(check: Check) -> Check:
        check.range = text  # type: ignore[attr-defined]
        return check
    return mark


@ranged("(0, 1e6]")
def positive(x: float) -> str | None:
    return None if 0.0 < x < math.inf else "a finite positive number"


@ranged("[0, 1e6]")
def non_negative(x: float) -> str | None:
    return None if 0.0 <= x < math.inf else "a finite number >= 0"


@ranged("(0, 1e6] or inf")
def positive_or_inf(x: float) -> str | None:
    return None if x > 0.0 else "a positive number (inf allowed)"


positive_or_inf.allows_inf = True  # type: ignore[attr-defined]


@ranged("[0, 1]")
def fraction(x: float) -> str | None:
    return None if 0.0 <= x <= 1.0 else "a fraction in [0, 1]"


@ranged("integer >= 1")
def at_least_one(n: int) -> str | None:
    return None if n >= 1 else "an integer >= 1"


@ranged("each (0, 1e6]")
def all_positive(xs: tuple[float, ...]) -> str | None:
    return None if all(0.0 < x < math.inf for x in xs) else "all entries finite and positive"


@ranged("each [0, 1e6]")
def all_non_negative(xs: tuple[float, ...]) -> str | None:
    return None if all(0.0 <= x < math.inf for x in xs) else "all entries finite and >= 0"


@ranged("each (0, 1e6] or inf")
def all_positive_or_inf(xs: tuple[float, ...]) -> str | None:
    return None if all(x > 0.0 for x in xs) else "all entries positive (inf allowed)"


all_positive_or_inf.allows_inf = True  # type: ignore[attr-defined]


def at_least(low: float, unit: str) -> Check:
    """A check: a finite number >= ``low`` (what a simulation can resolve)."""
    def check(x: float) -> str | None:
        return None if low <= x < math.inf else f"a number >= {low:g} {unit}"
    return ranged(f"[{low:g}, 1e6]")(check)


def between(low: float, high: float, unit: str) -> Check:
    """A check: a number in [``low``, ``high``]."""
    def check(x: float) -> str | None:
        return None if low <= x <= high else f"a number in [{low:g}, {high:g}] {unit}"
    return ranged(f"[{low:g}, {high:g}]")(check)


def hint(key: str, known: typing.Iterable[str]) -> str:
    """A "; did you mean 'x'?" suffix for a misspelt key, or an empty string."""
    close = difflib.get_close_matches(key, list(known), n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


def reject_unknown(mapping: Mapping[str, Any], known: typing.Iterable[str], where: str) -> None:
    """Raise :class:`ConfigError` naming the first key of ``mapping`` not in ``known``."""
    known = list(known)
    for key in mapping:
        if key not in known:
            raise ConfigError(f"{where}{key}: unknown key{hint(key, known)} "
                              f"(known: {', '.join(known)})")


def _as_float(value: Any, name: str, allow_inf: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{name}: expected a number, got {value!r}")
    x = float(value)
    if math.isnan(x):
        raise ConfigError(f"{name}: expected a number, got nan")
    if abs(x) > MAX_MAGNITUDE and not (allow_inf and math.isinf(x)):
        raise ConfigError(f"{name}: expected a finite number of magnitude at most "
                          f"{MAX_MAGNITUDE:g}{' (or inf)' if allow_inf else ''}, got {value!r}")
    return x


def convert(value: Any, tp: Any, name: str, allow_inf: bool = False) -> Any:
    """Convert a TOML value to the annotated type ``tp`` or raise naming ``name``. Numbers
    must be finite and at most :data:`MAX_MAGNITUDE` in magnitude (``inf`` where
    ``allow_inf``)."""
    origin = typing.get_origin(tp)
    if tp is float:
        return _as_float(value, name, allow_inf)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{name}: expected an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{name}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{name}: expected a string, got {value!r}")
        return value
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{name}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(convert(v, args[0], f"{name}[{i}]", allow_inf)
                         for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{name}: expected {len(args)} values, got {len(value)}: "
                              f"{list(value)!r}")
        return tuple(convert(v, a, f"{name}[{i}]", allow_inf)
                     for i, (v, a) in enumerate(zip(value, args)))
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return convert(value, args[0], name, allow_inf)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, Mapping):
            raise ConfigError(f"{name}: expected a table, got {value!r}")
        return build(tp, value, prefix=f"{name}.")
    raise TypeError(f"convert: unsupported field type {tp!r} for {name}")  # programming error


def _allows_inf(f: dataclasses.Field) -> bool:
    return getattr(f.metadata.get("check"), "allows_inf", False)


def _check_field(f: dataclasses.Field, value: Any, name: str) -> None:
    """Apply a field's ``choices`` and ``check`` metadata to an already converted value."""
    choices = f.metadata.get("choices")
    if choices and value not in choices:
        raise ConfigError(f"{name}: expected one of {', '.join(map(repr, choices))}, "
                          f"got {value!r}{hint(str(value), choices)}")
    check = f.metadata.get("check")
    if check is not None and value is not None:
        problem = check(value)
        if problem:
            raise ConfigError(f"{name}: expected {problem}, got {value!r}")


def build(cls: type[T], mapping: Mapping[str, Any], prefix: str = "") -> T:
    """Build the config dataclass ``cls`` from ``mapping``, validating every key and value.

    Keys missing from ``mapping`` take their defaults. ``prefix`` is prepended to key names in
    error messages (for example ``"scenario.toml: params."``).
    """
    hints = _hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    reject_unknown(mapping, fields, prefix)
    kwargs: dict[str, Any] = {}
    for key, value in mapping.items():
        f = fields[key]
        name = f"{prefix}{key}"
        converted = convert(value, hints[key], name, _allows_inf(f))
        _check_field(f, converted, name)
        kwargs[key] = converted
    try:
        return cls(**kwargs)
    except ConfigError as exc:  # a check across fields (__post_init__): add the location
        raise ConfigError(f"{prefix}{exc}") from None


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    """``typing.get_type_hints(cls)``, once per class: it evaluates every annotation string,
    and a config is validated whenever one is made (the adaptive formation makes one each
    period while the bearing moves)."""
    return typing.get_type_hints(cls)


def validate(obj: Any, prefix: str = "") -> None:
    """Re-check every field of an already built config object (for objects made in Python)."""
    hints = _hints(type(obj))
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(value):
            if not isinstance(value, Validated):   # a Validated one checked itself when made
                validate(value, prefix=f"{name}.")
            continue
        convert(list(value) if isinstance(value, tuple) else value, hints[f.name], name,
                _allows_inf(f))
        _check_field(f, value, name)


class Validated:
    """Mixin for config dataclasses: every field is checked when the object is made, so a
    config built in Python is as safe as one loaded from TOML."""

    def __post_init__(self) -> None:
        validate(self)


@contextlib.contextmanager
def reading(path: str | Path, kind: str) -> Iterator[None]:
    """Turn the errors of opening and decoding the ``kind`` file ``path`` (a missing file, a
    folder, bytes that are not UTF-8) into one-line ConfigErrors naming it."""
    try:
        yield
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a directory, expected a {kind}") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text ({exc.reason})") from None


def load_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; a missing file or a syntax error raises a one-line ConfigError."""
    path = Path(path)
    with reading(path, "TOML file"):
        try:
            with path.open("rb") as fh:
                return tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{path}: invalid TOML: {exc}") from None


def range_text(f: dataclasses.Field) -> str:
    """The allowed values of a field as docs/parameters.md gives them: its check's range,
    its choices, or any number of magnitude at most 1e6."""
    choices, check = f.metadata.get("choices"), f.metadata.get("check")
    if choices:
        return "one of " + ", ".join(f"'{c}'" for c in choices)
    if check is not None:
        return check.range
    if f.type in (bool, "bool"):
        return "true or false"
    return "a name" if f.type in (str, "str") else "[-1e6, 1e6]"


def field_docs(cls: type, prefix: str = "", instance: Any = None
               ) -> list[tuple[str, str, str, str, str]]:
    """Rows ``(key, unit, default, meaning, range)`` for every field of ``cls``, nested tables
    flattened; the defaults are ``instance``'s where given (a nested table's default)."""
    rows = []
    for f in dataclasses.fields(cls):
        if instance is not None:
            default = getattr(instance, f.name)
        else:
            default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        if dataclasses.is_dataclass(default):
            rows.extend(field_docs(type(default), f"{prefix}{f.name}.", default))
            continue
        rows.append((f"{prefix}{f.name}", f.metadata.get("unit", ""), repr(default),
                     f.metadata.get("doc", ""), range_text(f)))
    return rows
