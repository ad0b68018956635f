"""Giving way to walkers: a robot that can move does not stand while a walker walks into it,
and its own motion never closes on one (companion.control.evasive.give_way_target)."""

import dataclasses
import math

import pytest

from companion.control import make_controller
from companion.geometry import unicycle_step
from companion.params import Params
from companion.types import Circle, Observation, PersonDetection, PersonState, Pose
from stepping import step

WALKER_SPEED = 1.2


def closest_gap(params: Params, walker_y: float = 1.0, duration: float = 5.0
                ) -> tuple[float, list[str]]:
    """A standing person at the origin facing +x, the robot in its left slot, and a blind
    walker (constant velocity) coming along y = ``walker_y`` from 4 m ahead: the closest gap
    between the footprint and the walker's body, and the reasons of the commands."""
    stack = make_controller("lqr", params)
    person = PersonState(0.0, 0.0, 0.0, 0.0, 0.0)
    x, y, th, v, w = -params.robot.d, 1.0, 0.0, 0.0, 0.0
    gap, reasons = math.inf, []
    for k in range(round(duration / params.dt)):
        t = k * params.dt
        walker = Circle(4.0 - WALKER_SPEED * t, walker_y, 0.25, vx=-WALKER_SPEED)
        gap = min(gap, math.hypot(walker.x - x, walker.y - y) - 0.25 - params.robot.radius)
        cmd = step(stack, Observation(t, Pose(x, y, th), person, (walker,), None, (v, w)))
        reasons.append(cmd.reason)
        v, w = cmd.v, cmd.omega
        x, y, th = unicycle_step(x, y, th, v, w, params.dt)
    return gap, reasons


def without(p: Params, give_way: bool = True, predict: bool = True) -> Params:
    """``p`` without giving way and/or without avoidance's prediction of walkers."""
    if not give_way:
        p = p.replace(keepout=dataclasses.replace(p.keepout, give_way_margin=0.0))
    if not predict:
        p = p.replace(avoidance=dataclasses.replace(p.avoidance, prediction_horizon_s=0.0))
    return p


def test_a_standing_robot_gives_way_to_a_walker_coming_at_it():
    held, _ = closest_gap(without(Params(), give_way=False, predict=False))
    assert held < 0.0                         # the walker walks into a robot that stands
    gap, reasons = closest_gap(without(Params(), predict=False))
    assert gap > 0.0
    assert any("give_way" in r for r in reasons)


def test_avoidance_steers_away_from_where_a_walker_will_be():
    gap, reasons = closest_gap(without(Params(), give_way=False))
    assert gap > 0.0
    assert not any("give_way" in r for r in reasons)
    both, _ = closest_gap(Params())
    assert both > 0.0


def test_a_walker_passing_clear_is_not_given_way_to():
    gap, reasons = closest_gap(Params(), walker_y=3.0)
    assert gap == pytest.approx(2.0 - 0.5, abs=0.05)
    assert not any("give_way" in r for r in reasons)


def test_another_person_on_the_person_topic_is_given_way_to():
    """Detections of the companion and of a bystander walking at the robot arrive together;
    the tracker keeps the companion and the bystander becomes a moving obstacle."""
    p = without(Params(), predict=False)
    stack = make_controller("lqr", p)
    x, y, th, v, w = -p.robot.d, 1.0, 0.0, 0.0, 0.0
    gap, reasons, estimates = math.inf, [], []
    for k in range(round(4.0 / p.dt)):
        t = k * p.dt
        bx = 4.0 - WALKER_SPEED * t
        seen = (PersonDetection(t, 0.0, 0.0, covariance=(1e-4, 0.0, 0.0, 1e-4)),
                PersonDetection(t, bx, 1.0, covariance=(1e-4, 0.0, 0.0, 1e-4)))
        cmd = step(stack, Observation(t, Pose(x, y, th), None, (), None, (v, w), seen))
        gap = min(gap, math.hypot(bx - x, 1.0 - y) - p.movers.person_radius - p.robot.radius)
        reasons.append(cmd.reason)
        if cmd.estimate is not None:
            estimates.append(math.hypot(cmd.estimate.state.x, cmd.estimate.state.y))
        v, w = cmd.v, cmd.omega
        x, y, th = unicycle_step(x, y, th, v, w, p.dt)
    assert max(estimates) < 0.1                  # the track stayed on the companion
    assert any("give_way" in r for r in reasons)
    assert gap > 0.0


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_a_walker_with_a_broken_velocity_is_dropped_and_reported(bad):
    stack = make_controller("lqr", Params())
    walker = Circle(2.0, 1.0, 0.25, vx=bad)
    cmd = step(stack, Observation(0.0, Pose(-0.25, 1.0, 0.0), PersonState(0.0, 0.0, 0.0, 1.0, 0.0),
                                 (walker,), None, (1.0, 0.0)))
    assert math.isfinite(cmd.v) and math.isfinite(cmd.omega)
    assert "obstacle_invalid" in cmd.reason.split("+")


def test_a_robot_searching_for_a_lost_person_gives_way_too():
    """The companion's detections stop at 1 s; the robot stops and searches (there is no
    person to keep out of) while a blind walker comes along its line from 7 m ahead."""

    def closest(p: Params) -> tuple[float, list[str]]:
        stack = make_controller("lqr", p)
        x, y, th, v, w = -p.robot.d, 1.0, 0.0, 0.0, 0.0
        gap, reasons = math.inf, []
        for k in range(round(7.0 / p.dt)):
            t = k * p.dt
            seen = (PersonDetection(t, 0.0, 0.0, covariance=(1e-4, 0.0, 0.0, 1e-4)),) \
                if t < 1.0 else ()
            walker = Circle(7.0 - WALKER_SPEED * t, 1.0, 0.25, vx=-WALKER_SPEED)
            gap = min(gap, math.hypot(walker.x - x, walker.y - y) - 0.25 - p.robot.radius)
            cmd = step(stack, Observation(t, Pose(x, y, th), None, (walker,), None, (v, w), seen))
            reasons.append(cmd.reason)
            v, w = cmd.v, cmd.omega
            x, y, th = unicycle_step(x, y, th, v, w, p.dt)
        return gap, reasons

    held, _ = closest(without(Params(), give_way=False, predict=False))
    assert held < 0.0                         # the walker walks into the searching robot
    gap, reasons = closest(without(Params(), predict=False))
    assert gap > 0.0
    assert any("search" in r and "give_way" in r for r in reasons)
