"""Real walking pairs (companion.data.pairs, credit: its CREDIT) and the robot in the human
companion's place (companion.sim.pairs, companion.evaluate.companions)."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from companion.data.pairs import CREDIT, PACKAGED_DIR, SCENES, Pair, load_pairs
from companion.errors import ConfigError, DataError
from companion.evaluate import companions
from companion.evaluate.suite import load_suite, suite_from_mapping
from companion.params import Params
from companion.sim.pairs import closest_distance, nearest_slot, pair_episode, pair_row, paired
from companion.sim.runner import run_one


def _straight_pair(offset=(0.0, 0.8), speed=1.0, duration=12.0, wobble=0.0) -> Pair:
    """a walks along +x; b at ``offset`` (forward, left) from a, swaying sideways by
    ``wobble`` m."""
    t = np.arange(0.0, duration + 1e-9, 0.4)
    ax, ay = speed * t, np.zeros_like(t)
    sway = wobble * np.sin(2 * math.pi * t / 4.0)
    return Pair("synthetic", 1, 2, t, ax, ay, ax + offset[0], ay + offset[1] + sway)


def test_the_shipped_pairs_are_the_walking_pairs_of_the_three_scenes():
    pairs = load_pairs()
    counts = {s: sum(p.scene == s for p in pairs) for s in SCENES}
    assert counts == {"hotel": 34, "zara01": 36, "students03": 71}
    assert all(min(p.speeds()) > 0.5 for p in pairs)
    gaps = np.array([np.median(np.hypot(p.ax - p.bx, p.ay - p.by)) for p in pairs])
    assert 0.65 < float(np.median(gaps)) < 0.8         # the data's README: 0.70-0.92 m
    assert (PACKAGED_DIR / "README.md").read_text().count("Pellegrini") == 1
    assert "Lerner" in CREDIT


def test_a_malformed_line_or_a_missing_file_is_one_error_naming_it(tmp_path):
    shutil.copytree(PACKAGED_DIR, tmp_path / "p")
    obsmat = tmp_path / "p" / "zara01" / "obsmat.txt"
    lines = obsmat.read_text().splitlines()
    lines[6] = lines[6].replace(lines[6].split()[2], "x1", 1)
    obsmat.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=rf"{obsmat}:7: column 'pos_x': expected a number"):
        load_pairs(tmp_path / "p")
    (tmp_path / "p" / "hotel" / "groups.txt").unlink()
    with pytest.raises(DataError, match="hotel/groups.txt: no such file"):
        load_pairs(tmp_path / "p")


def test_the_slot_is_where_the_companion_walked_in_the_persons_frame():
    person = paired(_straight_pair((0.1, 0.8)))
    c = person.companion
    assert c.distance == pytest.approx(math.hypot(0.1, 0.8), abs=1e-3)
    assert c.bearing == pytest.approx(math.atan2(0.8, 0.1), abs=1e-3)
    assert c.deviation == pytest.approx(0.0, abs=1e-3) and c.speed == pytest.approx(1.0)
    other = paired(_straight_pair((0.1, 0.8)), flipped=True).companion   # b leads: a right
    assert other.bearing == pytest.approx(2 * math.pi - math.atan2(0.8, -0.1), abs=1e-3)
    swaying = paired(_straight_pair((0.0, 0.8), wobble=0.2)).companion
    assert swaying.deviation == pytest.approx(0.2 / math.sqrt(2), rel=0.05)


@given(st.floats(0.0, 2 * math.pi), st.floats(0.3, 1.0), st.floats(0.0, 0.3))
def test_the_nearest_slot_puts_the_robot_centre_at_the_clearance(bearing, clearance, d):
    D = closest_distance(bearing, clearance, d)
    centre = math.hypot(D * math.cos(bearing) - d, D * math.sin(bearing))
    assert centre == pytest.approx(clearance, abs=1e-9)


def test_a_slot_inside_the_keepout_is_moved_out_and_the_row_says_by_how_much():
    p = Params()
    near = paired(_straight_pair((0.0, 0.45)))
    spec = pair_episode(near, p)
    held = spec.params.formation.distance
    assert held == pytest.approx(nearest_slot(0.45, math.pi / 2, p), abs=1e-3) and held > 0.55
    row = pair_row(near, spec.params, run_one(spec))
    assert row["slot_moved_m"] == pytest.approx(spec.params.formation.distance - 0.45, abs=1e-3)


def test_beside_a_steady_companion_with_ideal_sensing_the_robot_walks_where_they_did():
    """The companion 0.8 m to the left of a person walking straight at 1 m/s: the robot
    starts where they were and stays within a few centimetres of their path."""
    person = paired(_straight_pair((0.0, 0.8)))
    spec = pair_episode(person, Params(), "lqr")
    x0 = spec.start.x + spec.params.robot.d * math.cos(spec.start.theta)
    y0 = spec.start.y + spec.params.robot.d * math.sin(spec.start.theta)
    assert (x0, y0) == pytest.approx((0.0, 0.8), abs=0.02)
    row = pair_row(person, spec.params, run_one(spec))
    assert row["companion_distance_m"] < 0.03 and row["human_deviation_m"] < 0.01
    assert row["slot_moved_m"] == 0.0 and row["pair_speed_mps"] == pytest.approx(1.0)


def test_the_pairs_motion_runs_each_pair_both_ways_at_its_own_slot():
    suite = suite_from_mapping({"controllers": ["lqr", "pid"], "sensing": ["ideal"],
                                "motions": {"pairs": "eth_ucy", "every": 40}}, _where())
    motions = {e.motion for e in suite.episodes}
    assert len(suite.episodes) == 2 * len(motions) and {e.side for e in suite.episodes} == \
        {"companion"}
    slots = {e.motion: e.spec.params.formation for e in suite.episodes}
    assert len({(f.distance, f.bearing) for f in slots.values()}) == len(motions)
    assert all(e.spec.duration >= 5.0 for e in suite.episodes)
    shipped = load_suite("pairs")
    assert {e.sensing for e in shipped.episodes} == {"ideal", "em-tracker", "realistic"}
    assert len({e.controller for e in shipped.episodes}) == 6


@pytest.mark.parametrize("motions, message", [
    ({"pairs": 3}, "motions.pairs: expected 'eth_ucy' or a folder"),
    ({"pairs": "eth_ucy", "min_duration": 1e6}, "no pair walks 1e\\+06 s or longer"),
    ({"scenarios": ["line"], "every": 2}, "every, offset and min_duration select tracks or "
                                          "pairs"),
])
def test_bad_pairs_keys_name_the_key(motions, message):
    with pytest.raises(ConfigError, match=message):
        suite_from_mapping({"motions": motions}, _where())


def test_the_report_puts_each_walk_in_its_speed_band_against_the_human():
    rows = [{"motion": f"m{i}", "sensing": "ideal", "controller": "lqr",
             "pair_speed_mps": speed, "rms_slot_error_m": robot, "human_deviation_m": 0.2,
             "companion_distance_m": 0.3, "min_person_distance_m": 0.7, "safety_share": 0.1,
             "slot_moved_m": moved, "slot_distance_m": held}
            for i, (speed, robot, moved, held) in enumerate([
                (0.8, 0.1, 0.0, 0.65), (0.9, 0.3, 0.05, 0.8), (1.2, 0.1, 0.0, 1.0),
                (1.5, 0.5, 0.0, 0.75)])]
    lines = {d["band"]: d for d in companions.table(rows + [{"motion": "track"}])}
    assert lines["0-1"]["walks"] == 2 and lines["0-1"]["robot_steadier"] == 0.5
    assert lines["1-1.3"]["robot_median_cm"] == pytest.approx(10.0)
    assert lines["> 1.45"]["walks"] == 1 and "1.3-1.45" not in lines
    assert lines["<= 1.3"]["walks"] == 3 and lines["all"]["slots_moved"] == 1
    near = {d["band"]: d["walks"] for d in companions.table(rows, "distance")}
    assert near == {"0-0.7": 1, "0.7-0.9": 2, "> 0.9": 1, "all": 4}
    text = companions.markdown(list(lines.values()), rows)
    assert "1 of 4 walks had their slot inside the keep-out" in text and "Pellegrini" in text
    printed = companions.short(rows)
    assert "| <= 1.3 | 3 |" in printed and "| all | 4 |" in printed and "| 0-1 |" not in printed


def _where():
    return Path("<test>")


def test_no_step_whose_command_the_keepout_changed_reports_ok():
    """Beside a real pair under realistic sensing the keep-out changes the command on many
    steps (the braking bound, the evasive check): each of them says so in its status."""
    from companion.params import load_sensing

    person = paired(next(p for p in load_pairs() if p.name == "hotel/90+89"))
    spec = pair_episode(person, Params().replace(sensing=load_sensing("realistic")))
    log = run_one(spec)
    changed = log["safety_shift_m"] > 1e-9
    assert changed.sum() > 10
    assert all(status != "ok" for status in np.asarray(log["status"])[changed])
    reasons = {str(r) for r in np.asarray(log["reason"])[changed]}
    assert any("braking" in r or "evasive" in r for r in reasons), reasons


def test_the_robustness_suite_crosses_shapes_tracks_and_pairs_with_five_detectors():
    suite = load_suite("robustness")
    assert {e.sensing for e in suite.episodes} == {"ideal", "em-tracker", "clean", "realistic",
                                                  "all worse"}
    assert {e.group for e in suite.episodes} == {"line", "circle", "figure8", "ushape",
                                                 "tracks", "pairs"}
    clean = next(e.spec.params.sensing for e in suite.episodes if e.sensing == "clean")
    assert (clean.person_position_noise_m, clean.person_rate_hz, clean.person_latency_s,
            clean.actuator_tau_s) == (0.03, 10.0, 0.0, 0.0)
    assert len({e.controller for e in suite.episodes}) == 6
