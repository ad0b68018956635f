"""Long commands show progress: simulated time as an episode streams, frames as an
animation is drawn, ticks as a bag is replayed (on stderr, after a quiet second)."""

import dataclasses

import pytest

from companion.apps import progress
from companion.apps.args import shown
from companion.apps.cli import main
from companion.params import Params
from companion.sim.runner import reporting, run_one, stream_one
from companion.sim.scenario import load_scenario


def test_a_watched_episode_reports_its_time_up_to_its_duration():
    spec = dataclasses.replace(load_scenario("line").episode(), duration=30.0)
    seen: list[float] = []
    with reporting(seen.append):
        blocks = list(stream_one(spec, rows=100))
    assert len(seen) == len(blocks) + 1
    assert seen == sorted(seen) and seen[-1] == 30.0
    assert seen[0] == pytest.approx(100 * spec.params.dt, abs=spec.params.dt)
    reported = len(seen)
    run_one(spec)                           # outside the block: nobody is told
    assert len(seen) == reported


def test_the_soak_through_the_engine_reports_in_this_process(tmp_path):
    from companion.evaluate.generators import soak_suite
    from companion.evaluate.run import run_results

    seen: list[float] = []
    with reporting(seen.append):
        run_results(soak_suite(20.0, seed=1, params=Params()), tmp_path, 1)
    assert seen[-1] == 20.0 and seen[0] == pytest.approx(20.0, abs=0.06)


@pytest.fixture
def loud(monkeypatch):
    monkeypatch.setattr(progress, "QUIET_S", 0.0)


def test_run_and_soak_show_simulated_time(tmp_path, capsys, loud):
    assert main(["run", "line", "--duration", "4", "--out", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    assert "simulated: 100%" in err and "4.0/4 s" in err
    assert main(["soak", "--duration", "10", "--out", str(tmp_path / "s")]) == 0
    err = capsys.readouterr().err
    assert "simulated: 100%" in err and "10.0/10 s" in err


def test_an_animation_shows_its_frames(tmp_path, capsys, loud):
    assert main(["run", "line", "--duration", "2", "--out", str(tmp_path),
                 "--animate", str(tmp_path / "a.gif")]) == 0
    err = capsys.readouterr().err
    assert "drawing a.gif: 100%" in err and "frame" in err


def test_a_replay_shows_its_ticks(tmp_path, capsys, loud):
    assert main(["run", "line", "--duration", "2", "--bag", str(tmp_path / "bag"),
                 "--out", str(tmp_path / "run")]) == 0
    assert "simulated: 100%" in capsys.readouterr().err
    assert main(["replay", str(tmp_path / "bag"), "--out", str(tmp_path / "replay")]) == 0
    assert "replaying: 100%" in capsys.readouterr().err


def test_quick_commands_print_no_bar(tmp_path, capsys):
    assert main(["run", "line", "--duration", "1", "--out", str(tmp_path)]) == 0
    assert "simulated" not in capsys.readouterr().err


def _interrupt_after(monkeypatch, count):
    """The engine stops with Ctrl-C after ``count`` episodes."""
    from companion.evaluate import run as engine

    real = engine._backend

    def interrupted(dask, workers, specs, reduce):
        for n, item in enumerate(real(dask, workers, specs, reduce)):
            if n == count:
                raise KeyboardInterrupt
            yield item
    monkeypatch.setattr(engine, "_backend", interrupted)


def test_an_interrupted_fuzz_says_what_it_kept(tmp_path, capsys, monkeypatch):
    _interrupt_after(monkeypatch, 2)
    out = tmp_path / "fuzz"
    assert main(["fuzz", "--steps", "3000", "--controllers", "pid", "--sensing", "ideal",
                 "--workers", "1", "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert f"fuzz: stopped; 2 of 5 episodes kept in {shown(out / '.evaluate.partial')}: " \
           "the same command continues from them" in err
    assert err.rstrip().endswith("companion: interrupted; no output was changed")
    assert not (out / "fuzz.json").exists()


def test_an_interrupted_soak_says_nothing_was_kept(tmp_path, capsys, monkeypatch):
    _interrupt_after(monkeypatch, 0)
    assert main(["soak", "--duration", "5", "--out", str(tmp_path)]) == 130
    assert "soak: stopped; nothing kept" in capsys.readouterr().err
