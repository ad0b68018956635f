"""The way round walls (rejoin, search): a swept footprint's clearance and the grid plan."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from companion.control.planner import CELL, next_point, plan_way
from companion.geometry import clearance, obstacle_arrays, point_clearances, sweep_clear
from companion.types import Circle, Wall

DOOR = (Wall(15.0, -6.0, 15.0, -0.8), Wall(15.0, 0.8, 15.0, 6.0))
FOOTPRINT = 0.35


def test_a_sweep_through_a_wall_or_grazing_it_is_not_clear():
    assert not sweep_clear(14.0, 2.0, 16.0, 2.0, DOOR, FOOTPRINT)         # through the wall
    assert not sweep_clear(14.0, 0.7, 16.0, 0.7, DOOR, FOOTPRINT)         # past the edge, 0.1 m
    assert sweep_clear(14.0, 0.0, 16.0, 0.0, DOOR, FOOTPRINT)             # through the door
    assert not sweep_clear(0.0, 0.0, 2.0, 0.0, [Circle(1.0, 0.3, 0.2)], FOOTPRINT)
    assert sweep_clear(0.0, 0.0, 2.0, 0.0, [Circle(1.0, 0.6, 0.2)], FOOTPRINT)


def test_a_footprint_already_too_close_may_move_away_not_closer():
    wall = [Wall(0.0, 1.0, 10.0, 1.0)]
    assert sweep_clear(5.0, 0.8, 5.0, 0.0, wall, FOOTPRINT)              # away
    assert sweep_clear(5.0, 0.8, 7.0, 0.8, wall, FOOTPRINT)              # along, as close
    assert not sweep_clear(5.0, 0.8, 6.0, 0.9, wall, FOOTPRINT)          # closer


@given(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0))
def test_a_clear_sweep_keeps_the_footprint_off_every_obstacle(ax, ay, bx, by):
    obstacles = [Circle(0.5, 0.5, 0.4), Wall(-2.0, -1.0, 2.0, -1.2)]
    start = min(clearance(o, ax, ay) for o in obstacles)
    if start < FOOTPRINT or not sweep_clear(ax, ay, bx, by, obstacles, FOOTPRINT):
        return
    for k in range(101):
        x, y = ax + (bx - ax) * k / 100, ay + (by - ay) * k / 100
        assert min(clearance(o, x, y) for o in obstacles) >= FOOTPRINT - 1e-9


def test_the_way_through_a_door_keeps_the_footprint_and_ends_at_the_goal():
    way = plan_way((14.5, 1.6), (17.0, 1.0), DOOR, FOOTPRINT)
    assert way is not None
    assert math.dist(way[0], (14.5, 1.6)) <= CELL and math.dist(way[-1], (17.0, 1.0)) <= CELL
    xs, ys = np.array(way[1:]).T
    assert point_clearances(xs, ys, obstacle_arrays(DOOR), 0.0).min() >= FOOTPRINT - 1e-9
    crossing = [y for (x0, y), (x1, _) in zip(way, way[1:]) if x0 <= 15.0 < x1]
    assert len(crossing) == 1 and abs(crossing[0]) <= 0.8 - FOOTPRINT + CELL
    steps = [math.dist(a, b) for a, b in zip(way, way[1:])]
    assert max(steps) == pytest.approx(CELL * math.sqrt(2.0))
    assert sum(steps) < 1.1 * (math.dist((14.5, 1.6), (15.0, 0.45))
                               + math.dist((15.0, 0.45), (17.0, 1.0))) + 2 * CELL


def test_no_way_to_a_walled_in_goal_and_next_point_goes_straight_where_it_can():
    box = (Wall(20.0, -1.0, 22.0, -1.0), Wall(22.0, -1.0, 22.0, 1.0),
           Wall(22.0, 1.0, 20.0, 1.0), Wall(20.0, 1.0, 20.0, -1.0))
    assert plan_way((17.0, 0.0), (21.0, 0.0), box, FOOTPRINT) is None
    assert next_point((17.0, 0.0), (21.0, 0.0), box, FOOTPRINT) is None
    assert next_point((14.0, 0.0), (16.0, 0.0), DOOR, FOOTPRINT) == (16.0, 0.0)
    x, y = next_point((14.5, 1.6), (17.0, 1.0), DOOR, FOOTPRINT)
    assert sweep_clear(14.5, 1.6, x, y, DOOR, FOOTPRINT) and x <= 15.0 and y < 1.6


def test_the_way_keeps_to_where_the_person_walked_where_a_wall_may_be_unseen():
    # a robot pushed out past a corridor's mouth (wall y = 1.5 from x = 5 on): its LiDAR
    # shows the wall's end and a walker by the wall, not the wall itself
    seen = [Circle(5.0, 1.5, 0.07, piece=True), Circle(5.6, 1.2, 0.45, piece=True)]
    start, slot = (4.57, 1.62), (7.5, 1.0)
    walked = [(0.25 * k, 0.1) for k in range(40)]           # the person's way, y = 0.1
    shortest = plan_way(start, slot, seen, 0.45)
    assert any(y > 1.9 for x, y in shortest if 5.0 < x < 6.5)   # over the unseen wall
    kept = plan_way(start, slot, seen, 0.45, along=walked)
    assert all(y < 1.5 for x, y in kept if 5.0 < x < 7.0)       # into the mouth
    assert next_point(start, slot, seen, 0.45, walked)[1] < start[1]   # it heads down
    assert next_point(start, slot, seen, 0.45)[1] > start[1]           # it heads up
