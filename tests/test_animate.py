"""Animations: `companion run --animate FILE` and the helpers behind fig4.gif."""

import dataclasses
import json

import numpy as np
import pytest
from PIL import Image, ImageChops

from companion.apps import animate, movie
from companion.apps.cli import main
from companion.io import leftovers
from companion.sim.scenario import load_scenario, run_scenario
from companion.types import Circle


def frames(path):
    """The frames of a GIF as RGB arrays, and its frame duration (ms)."""
    with Image.open(path) as im:
        out = []
        for i in range(im.n_frames):
            im.seek(i)
            out.append(np.asarray(im.convert("RGB")))
        return out, im.info["duration"]


@pytest.fixture(scope="module")
def animated(tmp_path_factory):
    """A 6 s run of fig4 written with and without --animate (inside --out)."""
    base = tmp_path_factory.mktemp("animate")
    plain, anim = base / "plain", base / "anim"
    args = ["run", "fig4", "--duration", "6", "--out"]
    assert main([*args, str(plain)]) == 0
    assert main([*args, str(anim), "--animate", str(anim / "run.gif")]) == 0
    return plain, anim


def test_the_gif_has_a_frame_per_tenth_of_a_second_that_change_over_time(animated):
    _, out = animated
    images, duration = frames(out / "run.gif")
    assert len(images) == 60                         # 6 s at 10 fps, real time
    assert duration == 100
    height, width, _ = images[0].shape
    assert height == 480 and width % 2 == 0 and 400 <= width <= 1200
    assert 10_000 < (out / "run.gif").stat().st_size < 2_000_000
    changed = [np.any(a != b) for a, b in zip(images, images[1:])]
    assert all(changed)                              # the robot and the clock move
    # the background is exactly white (a tinted palette would show as grey)
    assert tuple(images[0][2, 2]) == (255, 255, 255)


def test_the_other_outputs_are_unaffected_and_the_gif_is_an_output_of_the_run(animated):
    plain, anim = animated
    for name in ("log.csv", "metrics.json"):
        assert (plain / name).read_bytes() == (anim / name).read_bytes(), name
    assert json.loads((anim / ".run.outputs").read_text()) == [
        "log.csv", "metrics.json", "run.gif"]
    assert not any(p.is_symlink() for p in anim.iterdir())
    assert leftovers(anim) == []


def test_an_animation_outside_the_output_folder_is_written_there(tmp_path, capsys):
    target = tmp_path / "movies" / "fig4.gif"
    assert main(["run", "fig4", "--duration", "2", "--out", str(tmp_path / "o"),
                 "--animate", str(target)]) == 0
    assert Image.open(target).n_frames == 20
    assert str(target) in capsys.readouterr().out
    assert [p.name for p in target.parent.iterdir()] == ["fig4.gif"]
    assert "fig4.gif" not in json.loads((tmp_path / "o" / ".run.outputs").read_text())
    assert not (tmp_path / "o" / "fig4.gif").exists()


def test_the_last_line_names_every_file_by_a_path_from_the_current_folder(tmp_path, capsys,
                                                                           monkeypatch):
    """Not "x.gif in o" when x.gif is elsewhere: each path opens from where the command ran."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "here").mkdir()
    monkeypatch.chdir(tmp_path / "here")
    assert main(["run", "fig4", "--duration", "1", "--out", "o",
                 "--animate", "../movies/x.gif"]) == 0
    last = capsys.readouterr().out.splitlines()[-1]
    assert last == "wrote o/log.csv, o/metrics.json, ../movies/x.gif"
    assert (tmp_path / "movies" / "x.gif").is_file() and (tmp_path / "here" / "o" / "log.csv"
                                                            ).is_file()
    assert main(["run", "fig4", "--duration", "1", "--out", "o", "--animate", "o/y.gif"]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == \
        "wrote o/log.csv, o/metrics.json, o/y.gif"


@pytest.mark.parametrize("name, message", [
    ("run.png", "--animate {}: expected a file name ending in .gif or .mp4, got '.png'"),
    ("run", "--animate {}: expected a file name ending in .gif or .mp4, got 'no extension'"),
    ("run.mp4", "--animate {}: .mp4 needs ffmpeg on PATH, which is not there; write a .gif "
                "instead"),
])
def test_a_bad_animation_name_is_one_line_and_exit_2_before_the_run(
        name, message, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))        # no ffmpeg, whatever the machine has
    target = tmp_path / name
    code = main(["run", "fig4", "--out", str(tmp_path / "o"), "--animate", str(target)])
    err = capsys.readouterr().err
    assert code == 2
    assert err == f"companion: error: {message.format(target)}\n"
    assert not (tmp_path / "o" / "log.csv").exists()


def test_an_animation_into_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "f").write_text("")
    assert main(["run", "fig4", "--out", str(tmp_path / "o"),
                 "--animate", str(tmp_path / "f" / "x.gif")]) == 2
    assert "--animate" in capsys.readouterr().err


@pytest.mark.parametrize("inside", [True, False])
def test_an_interrupted_animation_leaves_nothing(tmp_path, monkeypatch, inside):
    out = tmp_path / "o"
    target = (out if inside else tmp_path / "m") / "x.gif"

    def interrupted(self):
        raise KeyboardInterrupt

    monkeypatch.setattr(movie._GifWriter, "finish", interrupted)
    assert main(["run", "fig4", "--duration", "1", "--out", str(out),
                 "--animate", str(target)]) == 130
    assert not target.exists()
    assert not [p for p in tmp_path.rglob("*") if p.is_file()]     # no log, no temp file


def test_playback_speed_keeps_animations_short():
    assert animate.playback(6.0) == 1.0
    assert animate.playback(30.0) == 1.0
    assert animate.playback(60.0) == 2.0
    assert animate.playback(3600.0) == 120.0
    t = np.arange(0, 3600.0, 0.02)
    rows = animate.frame_indices(t, 10, animate.playback(3600.0))
    assert len(rows) == 300
    assert np.allclose(np.diff(t[rows]), 12.0)       # a frame every 12 simulated seconds


def test_lidar_returns_lie_on_the_obstacles_and_the_person():
    sc = load_scenario("fig4")
    sc = dataclasses.replace(sc, duration=1.0, obstacle_source="lidar",
                             obstacles=(Circle(1.5, -3.0, 0.3),))
    log = run_scenario(sc)
    pts = animate.lidar_returns(log, 0, sc)
    assert len(pts) > 10
    ob = sc.obstacles[0]
    person = np.array([log["person_x"][0], log["person_y"][0]])   # the scan of row 0
    on_obstacle = np.abs(np.hypot(*(pts - [ob.x, ob.y]).T) - ob.radius) < 1e-6
    on_person = np.abs(np.hypot(*(pts - person).T) - sc.params.lidar.person_radius) < 1e-6
    assert np.all(on_obstacle | on_person) and on_obstacle.any() and on_person.any()
    # between scans the controller holds the last one
    every = round(1.0 / (sc.params.sensing.lidar_rate_hz * sc.params.dt))
    assert every > 1
    assert all(np.array_equal(animate.lidar_returns(log, k, sc), pts) for k in range(every))
    assert not np.array_equal(animate.lidar_returns(log, every, sc), pts)


def test_several_controllers_in_one_animation(tmp_path):
    sc = dataclasses.replace(load_scenario("fig4"), duration=1.5)
    runs = {name: run_scenario(sc, name) for name in ("lqr", "pid")}
    path = tmp_path / "two.gif"
    assert animate.save(path, runs, sc) == 15
    images, _ = frames(path)
    # each robot shows in its Fig. 4 colour (tab:purple, tab:green) on the last frame
    last = images[-1].reshape(-1, 3).astype(int)
    for rgb in ((148, 103, 189), (44, 160, 44)):
        assert (np.abs(last - rgb).max(axis=1) <= 12).sum() > 50, rgb
    assert ImageChops.difference(Image.fromarray(images[0]), Image.fromarray(images[-1])
                                 ).getbbox() is not None


def test_mp4_frames_go_to_ffmpeg_as_raw_rgba(tmp_path, monkeypatch):
    """ffmpeg is not needed to test the MP4 path: a stand-in records its arguments and the
    frames it is sent, which must be whole RGBA frames of the size it is told."""
    fake = tmp_path / "bin" / "ffmpeg"
    fake.parent.mkdir()
    fake.write_text('#!/bin/sh\necho "$@" > "$(dirname "$0")/args"\n'
                    'for last; do :; done\ncat > "$last"\n')
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", f"{fake.parent}:/usr/bin:/bin")
    target = tmp_path / "run.mp4"
    assert main(["run", "fig4", "--duration", "1", "--out", str(tmp_path / "o"),
                 "--animate", str(target)]) == 0
    args = (fake.parent / "args").read_text().split()
    width, height = map(int, args[args.index("-s") + 1].split("x"))
    assert args[args.index("-f", args.index("-i")) + 1] == "mp4"
    assert height == 480 and width % 2 == 0
    assert target.stat().st_size == 10 * width * height * 4
