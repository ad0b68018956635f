import math
from pathlib import Path

import pytest

from companion.config import field_docs
from companion.errors import ConfigError
from companion.params import Params, load_params, params_from_mapping

DOCS = Path(__file__).resolve().parents[1] / "docs" / "parameters.md"


def test_defaults_are_table_1():
    p = Params()
    assert p.dt == 0.05
    assert p.lqr.q == (25.0, 10.0, 25.0, 30.0, 30.0)
    assert p.lqr.r == (20.0, 20.0)
    assert p.formation.distance == 1.0
    assert p.robot.d == 0.25
    assert p.robot.v_max == 1.5
    assert p.robot.omega_max == pytest.approx(math.pi / 2)


def test_load_from_toml(tmp_path):
    f = tmp_path / "p.toml"
    f.write_text('dt = 0.1\n[formation]\nbearing = "right"\ndistance = 1.5\n'
                 '[lqr]\nq = [1, 2, 3, 4, 5]\nlinearize_at = "desired"\n')
    p = load_params(f)
    assert p.dt == 0.1
    assert p.formation.bearing == pytest.approx(1.5 * math.pi)
    assert p.formation.distance == 1.5
    assert p.lqr.q == (1.0, 2.0, 3.0, 4.0, 5.0)
    assert p.lqr.linearize_at == "desired"


@pytest.mark.parametrize("text, expected", [
    ("dtt = 0.1", r"p\.toml: dtt: unknown key; did you mean 'dt'\?"),
    ("[lqr]\nqq = [1,2,3,4,5]", r"lqr\.qq: unknown key; did you mean 'q'\?"),
    ("dt = -1", r"p\.toml: dt: expected a sample period in \[0.001, 1\] s"),
    ("dt = 'fast'", r"dt: expected a number"),
    ("dt = true", r"dt: expected a number"),
    ("dt = nan", r"dt: expected a number, got nan"),
    ("[lqr]\nq = [1, 2, 3]", r"lqr\.q: expected 5 values, got 3"),
    ("[lqr]\nr = [1, -2]", r"lqr\.r: expected all entries finite and positive"),
    ("[lqr]\nlinearize_at = 'measure'",
     r"lqr\.linearize_at: expected one of .*did you mean 'measured'"),
    ("[formation]\nbearing = 7.0", r"formation\.bearing: expected an angle in \[0, 2\*pi\)"),
    ("[formation]\nbearing = 'up'", r"formation\.bearing: expected a bearing in rad or one of"),
    ("robot = 3", r"robot: expected a table"),
    ("dt = ", r"p\.toml: invalid TOML: .*line 1"),
])
def test_bad_values_name_file_and_key(tmp_path, text, expected):
    f = tmp_path / "p.toml"
    f.write_text(text + "\n")
    with pytest.raises(ConfigError, match=expected) as info:
        load_params(f)
    assert "\n" not in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_params(tmp_path / "nope.toml")


def test_error_clip_accepts_inf():
    p = params_from_mapping({"lqr": {"error_clip": [math.inf, 1.0, 1.0]}})
    assert p.lqr.error_clip[0] == math.inf


def test_every_parameter_is_documented():
    text = DOCS.read_text()
    for key, *_ in field_docs(Params):
        assert f"`{key}`" in text, f"{key} missing from docs/parameters.md"


@pytest.mark.parametrize("bearing, distance", [("front", 0.5), ("left", 0.5)])
def test_slot_inside_the_keep_out_is_rejected(tmp_path, bearing, distance):
    f = tmp_path / "p.toml"
    f.write_text(f'[formation]\nbearing = "{bearing}"\ndistance = {distance}\n')
    with pytest.raises(ConfigError, match="formation.distance: the slot .* inside "
                                          "keepout.person_clearance"):
        load_params(f)
    f.write_text(f'[formation]\nbearing = "{bearing}"\ndistance = {distance}\n'
                 '[keepout]\nperson_clearance = 0.2\nprotective_distance = 0.2\n')
    assert load_params(f).formation.distance == distance


def test_slot_inside_the_protective_distance_is_rejected(tmp_path):
    f = tmp_path / "p.toml"
    f.write_text('[formation]\nbearing = "front"\ndistance = 0.7\n'
                 '[keepout]\nperson_clearance = 0.2\n')
    with pytest.raises(ConfigError, match="robot centre 0.45 m from the person, inside "
                                          "keepout.protective_distance"):
        load_params(f)
    f.write_text('[formation]\nbearing = "front"\ndistance = 0.7\n'
                 '[keepout]\nperson_clearance = 0.2\nprotective_distance = 0.4\n')
    assert load_params(f).formation.distance == 0.7


def test_config_built_in_python_is_validated():
    from companion.params import Formation
    with pytest.raises(ConfigError, match="distance: expected a finite positive"):
        Formation(distance=-1.0)
    with pytest.raises(ConfigError, match="dt: expected a sample period"):
        Params(dt=0.0)
