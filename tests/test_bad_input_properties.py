"""Property tests of the validation boundary (issue 21): for any generated bad value in a
parameter file, a scenario file, a person CSV or a command-line flag, the command exits with
code 2 and one line on stderr that names the place (file and key or line, or the flag) and the
value, prints nothing on stdout and leaves the output folder as it was.

The commands run in-process (``companion.apps.cli.main``) with their work (simulation, tuning,
benchmark, data loading) replaced by a function that fails the case: a bad value must be
rejected before any work starts. Families and counts: tests/sweeps.py.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import os
import signal
import tempfile
import types
import typing
from pathlib import Path

import pytest
from hypothesis import strategies as st

from companion.apps import benchmark, commands, evaluation, reproduce, suites
from companion.apps.cli import main
from companion.data import pedestrians
from companion.params import Params
from companion.sim import soak
from sweeps import QUICK, SLOW, assert_none_failed, sweep


class WorkStarted(Exception):
    """The command started its work: the bad value was not rejected at the boundary."""


def _work(*args, **kwargs):
    raise WorkStarted


@pytest.fixture
def no_work(monkeypatch):
    for owner, name in [(commands, "stream_one"), (commands, "run_results"), (soak, "run_soak"),
                        (evaluation, "load_suite"), (benchmark, "run"),
                        (suites, "suite_from_mapping"), (suites, "evaluate"),
                        (reproduce, "reproduce"), (pedestrians, "load_scenes")]:
        monkeypatch.setattr(owner, name, _work)


# -- TOML and the check of one case ---------------------------------------------------------

def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) \
            else repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return '"' + v + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + "}"


def toml(mapping: dict, prefix: str = "") -> str:
    """TOML text of ``mapping``: scalars first, then one [table] per nested dict."""
    lines = [f"{k} = {toml_value(v)}" for k, v in mapping.items() if not isinstance(v, dict)]
    for k, v in mapping.items():
        if isinstance(v, dict):
            lines.append(f"\n[{prefix}{k}]")
            lines.append(toml(v, f"{prefix}{k}."))
    return "\n".join(lines) + "\n"


def put(mapping: dict, path: str, value) -> dict:
    """A copy of ``mapping`` with the dotted ``path`` set to ``value``."""
    head, _, rest = path.partition(".")
    out = dict(mapping)
    out[head] = put(dict(out.get(head, {})), rest, value) if rest else value
    return out


def renderings(v) -> list[str]:
    """How an error line may show the value ``v``."""
    out = [repr(v), str(v)]
    if isinstance(v, list):
        out += [r for x in v for r in renderings(x)]
    if isinstance(v, float) and not isinstance(v, bool):
        out += [f"{v:g}", toml_value(v)]
    return [r for r in out if r]


def snapshot(folder: Path) -> list:
    return sorted((p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in folder.iterdir())


class TooSlow(BaseException):
    """A case ran for longer than :data:`CASE_LIMIT_S` (work that was not replaced, such as
    loading a recording of 1e6 s): the value was not rejected early. The limit is generous,
    for a loaded machine."""


CASE_LIMIT_S = float(os.environ.get("COMPANION_CASE_LIMIT_S", "60"))


def _too_slow(signum, frame):
    raise TooSlow


def call(argv: list[str]) -> tuple[object, str, str]:
    out, err = io.StringIO(), io.StringIO()
    before = signal.signal(signal.SIGALRM, _too_slow)
    signal.setitimer(signal.ITIMER_REAL, CASE_LIMIT_S)
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
        except WorkStarted:
            code = "work started"
        except TooSlow:
            code = f"still running after {CASE_LIMIT_S:g} s"
        except Exception as exc:               # a crash: exit code 1 and a traceback
            code = f"raised {type(exc).__name__}: {str(exc)[:100]}"
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, before)
    return code, out.getvalue(), err.getvalue()


def expect_rejected(argv: list[str], out: Path, names: list[str], values: list[str],
                    any_name: bool = False) -> None:
    """Exit 2, one line naming every one of ``names`` (any one if ``any_name``) and one of
    ``values``, nothing on stdout, ``out`` untouched."""
    before = snapshot(out)
    code, stdout, err = call(argv)
    assert code == 2, f"exit {code}: {err.strip()[-200:]!r}"
    assert err.count("\n") == 1 and err.startswith("companion: error: "), f"not one line: {err!r}"
    found = [n in err for n in names]
    assert (any(found) if any_name else all(found)), f"does not name {names}: {err!r}"
    assert any(v in err for v in values), f"does not name the value {values}: {err!r}"
    assert stdout == "", f"printed before the error: {stdout!r}"
    assert snapshot(out) == before, "the output folder changed"


@contextlib.contextmanager
def workdir():
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "o").mkdir()
        (tmp / "o" / "old.txt").write_text("an earlier run\n")
        yield tmp


# -- bad values ------------------------------------------------------------------------------

HUGE = st.floats(min_value=1.0000001e6, max_value=1e308) | st.floats(min_value=-1e308,
                                                                      max_value=-1.0000001e6)
NONFINITE = st.sampled_from([math.nan, math.inf, -math.inf])
WORDS = st.text("abcdefghijklmnopqrstuvwxyz_ -", min_size=0, max_size=8)
WRONG_TYPE = WORDS | st.booleans() | st.just([1.0, 2.0]) | st.just({"a": 1})
ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True) | st.floats(-2.0, 10.0)


def bad_float(check, allows_inf: bool):
    """Floats the field must reject: not finite (inf where not allowed), beyond 1e6, outside
    its check, or not a number at all."""
    out_of_range = ANY_FLOAT.filter(
        lambda x: math.isnan(x) or (abs(x) > 1e6 and not (allows_inf and x == math.inf))
        or (check is not None and check(x) is not None))
    return out_of_range | WRONG_TYPE


def fields(cls, prefix=""):
    """(dotted key, field, type) of every leaf field of a config dataclass."""
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        if dataclasses.is_dataclass(default):
            yield from fields(type(default), f"{prefix}{f.name}.")
        else:
            yield f"{prefix}{f.name}", f, hints[f.name]


def bad_value(f: dataclasses.Field, tp):
    check, choices = f.metadata.get("check"), f.metadata.get("choices")
    allows_inf = getattr(check, "allows_inf", False)
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        tp = args[0]
    if tp is float:
        return bad_float(check, allows_inf)
    if tp is int:
        return (st.integers(-10**6, 0).filter(lambda n: check(n) is not None)
                | st.floats(0.5, 3.5) | WORDS | st.booleans())
    if tp is str:
        words = WORDS.filter(lambda w: w not in choices) if choices else st.just("")
        return words | st.booleans() | st.floats(0, 5) | st.just([1])
    n = len(typing.get_args(tp))
    good = [1.0] * n
    element = bad_float(lambda x: check((x,)), allows_inf)
    return (st.integers(0, n - 1).flatmap(lambda i: element.map(
        lambda x: good[:i] + [x] + good[i + 1:]))
            | st.lists(st.floats(0.5, 2.0), max_size=6).filter(lambda v: len(v) != n)
            | st.floats(0.5, 2.0))


PARAM_FIELDS = [(k, f, tp) for k, f, tp in fields(Params) if not k.startswith("sensing.")]
SENSING_FIELDS = [(k, f, tp) for k, f, tp in fields(Params) if k.startswith("sensing.")]


def one_bad_param(table):
    return st.sampled_from(table).flatmap(
        lambda item: bad_value(item[1], item[2]).map(lambda v: (item[0], v)))


def _contradictions():
    """Parameter combinations each valid alone, contradictory together: (mapping, names,
    values)."""
    pos = st.floats(0.01, 10.0)
    return st.one_of(
        st.tuples(pos, pos).filter(lambda ab: ab[0] < ab[1]).map(lambda ab: (
            {"tracker": {"lost_after_s": ab[0], "coast_after_s": ab[1]}},
            ["tracker.lost_after_s"], renderings(ab[0]))),
        st.tuples(pos, pos).filter(lambda ab: ab[0] > ab[1]).map(lambda ab: (
            {"extractor": {"min_radius": ab[0], "max_radius": ab[1]}},
            ["extractor.min_radius"], renderings(ab[0]))),
        st.floats(0.05, 0.5).map(lambda d: (
            {"formation": {"distance": d, "bearing": "front"}}, ["formation.distance"],
            renderings(d))),
        st.floats(0.51, 10.0).map(lambda lat: (
            {"sensing": {"person_latency_s": lat}, "tracker": {"max_delay_s": 0.5}},
            ["sensing.person_latency_s", "tracker.max_delay_s"], renderings(lat))),
        st.floats(0.01, 1.0).map(lambda hz: (
            {"sensing": {"person_rate_hz": hz}}, ["sensing.person_rate_hz"], renderings(hz))),
        WORDS.map(lambda w: ({"tracker": {"world_frame": w or "x", "robot_frame": w or "x"}},
                             ["tracker.robot_frame"], [repr(w or "x")])),
        st.just(({"lqr": {"q": [0.0] * 5}}, ["lqr.q"], ["[0.0, 0.0, 0.0, 0.0, 0.0]",
                                                        "(0.0, 0.0, 0.0, 0.0, 0.0)"])),
    )


def params_case():
    single = one_bad_param(PARAM_FIELDS + SENSING_FIELDS).map(
        lambda kv: (put({}, kv[0], kv[1]), [kv[0]], renderings(kv[1])))
    return single | _contradictions()


def check_params_file(case, command=("run", "line", "--duration", "1")):
    mapping, names, values = case
    with workdir() as tmp:
        (tmp / "p.toml").write_text(toml(mapping))
        argv = [*command, "--params", str(tmp / "p.toml"), "--out", str(tmp / "o")]
        expect_rejected(argv, tmp / "o", names, values, any_name=True)
        assert "p.toml" in call(argv)[2], "does not name the file"


# -- scenario files --------------------------------------------------------------------------

BASE = {"duration": 1.0, "person": {"kind": "line"}}


def scenario_case():
    def at(path, values, base=BASE):
        return values.map(lambda v: (put(base, path, v), [path], renderings(v)))

    number = bad_float(None, False)
    circle = put(BASE, "person", {"kind": "circle"})
    fig8 = put(BASE, "person", {"kind": "figure8"})
    segs = put(BASE, "person", {"kind": "segments", "segments": [{"duration": 1.0}]})
    obstacle = put(BASE, "obstacles", [{"kind": "circle", "x": 3.0, "y": 3.0}])
    fault = {"kind": "stall", "start": 1.0, "end": 2.0}

    def listed(key, item, field, values, base=BASE):
        return values.map(lambda v: (put(base, key, [dict(item, **{field: v})]),
                                     [f"{key}[0].{field}" if field else key], renderings(v)))

    return st.one_of(
        at("duration", st.floats(-1e12, 0.0) | st.floats(86400.001, 1e12) | st.floats(0, 0.049)
           | NONFINITE | WRONG_TYPE),
        at("seed", st.integers(-2**63, -1) | st.floats(0.5, 9.5) | WORDS | st.booleans()),
        at("name", st.floats(0, 1) | st.booleans()),
        at("controller", WORDS.filter(lambda w: w not in ("lqr", "pid", "vsm", "ic"))
           | st.floats(0, 1)),
        at("obstacle_source", WORDS | st.integers(0, 3)),
        at("sensing", WORDS.filter(lambda w: w not in ("ideal", "realistic"))),
        at("person.speed", number | st.floats(3.001, 1e6) | st.floats(-1e6, 0.0099)),
        at("person.start", st.just([1.0, 2.0]) | number.map(lambda x: [0.0, x, 0.0])),
        at("person.radius", st.floats(-1e6, 0.199) | number, circle),
        at("person.lap_time", st.floats(-1e6, 20.0) | number, fig8),
        at("person.phase", NONFINITE | HUGE, fig8),
        st.tuples(st.floats(0.2, 1.0), st.floats(2.0, 3.0)).filter(
            lambda rv: rv[1] / rv[0] > 2.0 * math.pi).map(lambda rv: (
            put(put(circle, "person.radius", rv[0]), "person.speed", rv[1]),
            ["person.radius", "person.speed"], renderings(rv[0]) + renderings(rv[1]))),
        st.tuples(st.floats(4.0, 10.0), st.floats(2.0, 3.0)).map(lambda kv: (
            put(segs, "person.segments", [{"duration": 1.0, "curvature": kv[0],
                                           "v_start": kv[1], "v_end": kv[1]}]),
            ["person.segments[0]"], renderings(kv[0]) + renderings(kv[1]))),
        listed("person.segments", {"duration": 1.0}, "curvature",
               st.floats(10.001, 1e6) | number, segs),
        listed("person.segments", {"duration": 1.0}, "v_end", st.floats(3.001, 1e6) | number,
               segs),
        listed("person.segments", {"duration": 1.0}, "duration", st.floats(-1e6, 0.0) | number,
               segs),
        at("robot.start", number.map(lambda x: [x, 0.0, 0.0]) | st.just([0.0, 0.0])),
        listed("obstacles", {"kind": "circle", "x": 3.0, "y": 3.0}, "radius",
               st.floats(-1e6, 0.0) | number, obstacle),
        listed("obstacles", {"kind": "circle", "x": 3.0, "y": 3.0}, "x", number, obstacle),
        listed("faults", fault, "start", st.floats(-1e6, -1e-9) | number),
        listed("faults", fault, "end", st.floats(-1e6, 1.0) | number),
        listed("faults", dict(fault, kind="person_jump"), "dx", number),
        one_bad_param(PARAM_FIELDS).map(lambda kv: (put(BASE, f"params.{kv[0]}", kv[1]),
                                                    [f"params.{kv[0]}"], renderings(kv[1]))),
    )


def check_scenario_file(case):
    mapping, names, values = case
    with workdir() as tmp:
        (tmp / "s.toml").write_text(toml(mapping))
        argv = ["run", str(tmp / "s.toml"), "--out", str(tmp / "o")]
        expect_rejected(argv, tmp / "o", [f"s.toml: {n}" for n in names], values,
                        any_name=True)


# -- person CSV ------------------------------------------------------------------------------

GOOD_ROWS = [[f"{0.1 * i:.1f}", f"{0.1 * i:.2f}", "0"] for i in range(20)]
BAD_CELLS = (st.sampled_from(["nan", "inf", "-inf", "1e309", "abc", "", "1e6.5", "0x10"])
             | HUGE.map(repr))


def csv_case():
    cell = st.tuples(st.integers(0, 19), st.integers(0, 2), BAD_CELLS).map(
        lambda c: (c[0], c[1], c[2], ["t", "x", "y"][c[1]]))
    span = st.floats(86400.01, 1e6).map(lambda t: (19, 0, repr(t), "t"))
    return cell | span


def check_person_csv(case):
    row, col, text, name = case
    rows = [list(r) for r in GOOD_ROWS]
    rows[row][col] = text
    with workdir() as tmp:
        lines = ["t,x,y"] + [",".join(r) for r in rows]
        (tmp / "walk.csv").write_text("\n".join(lines) + "\n")
        argv = ["run", "line", "--person-csv", str(tmp / "walk.csv"), "--out", str(tmp / "o")]
        expect_rejected(argv, tmp / "o", [f"walk.csv:{row + 2}", f"'{name}'"],
                        [repr(text.strip()), text.strip() or "''"])


# -- flags -----------------------------------------------------------------------------------

def texts(floats):
    return floats.map(repr)


SPECIAL = st.sampled_from(["nan", "inf", "-inf", "1e309", "-1e309", "abc", "", "1e7",
                           "-1e7"])
SETTLE = texts(st.floats(-1e6, 0.0) | st.floats(86400.01, 1e6)) | SPECIAL
DURATION = SETTLE | texts(st.floats(1e-9, 0.049))      # shorter than dt: no sample
COUNT = st.integers(-10**6, 0).map(str) | st.integers(10**6 + 1, 10**30).map(str) \
    | st.sampled_from(["1.5", "abc", "nan", ""])
WORKERS = st.integers(-10**6, 0).map(str) | st.integers(257, 10**30).map(str) \
    | st.sampled_from(["1.5", "abc", ""])
SEED = st.integers(-10**30, -1).map(str) | st.integers(2**63, 10**30).map(str) \
    | st.sampled_from(["1.5", "abc", ""])
SPEED = texts(st.floats(-1e6, -1e-9) | st.floats(3.001, 1e6)) | SPECIAL

FLAGS = [
    (["run", "line"], "--duration", DURATION),
    (["run", "line"], "--distance", texts(st.floats(-1e6, 0.0)) | SPECIAL),
    (["run", "line"], "--bearing", SPECIAL | texts(HUGE)),
    (["run", "line"], "--start", SPECIAL.map(lambda s: f"0,{s},0") | st.just("1,2")),
    (["convergence"], "--duration", DURATION),
    (["convergence"], "--speeds", SPEED | SPEED.map(lambda s: f"0.5,{s}")),
    (["convergence"], "--settle-limit", SETTLE),
    (["convergence"], "--workers", WORKERS),
    (["pedestrians"], "--min-speed", SPEED),
    (["pedestrians"], "--min-duration", texts(st.floats(-1e6, -1e-9) | st.floats(86400.01, 1e6))
     | SPECIAL),
    (["pedestrians"], "--workers", WORKERS),
    (["soak"], "--duration", DURATION),
    (["soak", "--duration", "1"], "--seed", SEED),
    (["tune", "lqr"], "--trials", COUNT),
    (["tune", "lqr"], "--seed", SEED),
    (["tune", "lqr"], "--workers", WORKERS),
    (["bench"], "--episodes", COUNT),
    (["bench"], "--duration", DURATION),
    (["bench"], "--workers", WORKERS),
    (["reproduce"], "--workers", WORKERS),
]


def flag_case():
    return st.sampled_from(range(len(FLAGS))).flatmap(
        lambda i: FLAGS[i][2].map(lambda v: (FLAGS[i][0], FLAGS[i][1], v)))


def check_flag(case):
    command, flag, value = case
    with workdir() as tmp:
        out = ["--out", str(tmp / "o" / "bench.json")] if command[0] == "bench" else \
            [] if command[0] == "tune" else ["--out", str(tmp / "o")]
        argv = [*command, f"{flag}={value}", *out]
        expect_rejected(argv, tmp / "o", [flag], [repr(value), value or "''"])


# -- the sweeps ------------------------------------------------------------------------------

FAMILIES = {"params_file": (params_case(), check_params_file),
            "scenario_file": (scenario_case(), check_scenario_file),
            "person_csv": (csv_case(), check_person_csv),
            "flags": (flag_case(), check_flag)}


@pytest.mark.parametrize("family", FAMILIES)
def test_any_bad_input_is_one_line_naming_it_and_nothing_is_touched(family, no_work):
    strategy, check = FAMILIES[family]
    assert_none_failed(family, *sweep(family, strategy, check, QUICK))


@pytest.mark.slow
@pytest.mark.parametrize("family", FAMILIES)
def test_sweep_bad_inputs(family, no_work):
    strategy, check = FAMILIES[family]
    assert_none_failed(family, *sweep(family, strategy, check, SLOW))
