"""The way back to the slot round the walls: when it acts, where it leads, the person's way."""

import dataclasses
import math

from companion.control.rejoin import RELEASE, SPACING, Rejoin
from companion.params import Params
from companion.types import Circle, PersonState, Pose, Wall

DOOR = (Wall(15.0, -6.0, 15.0, -0.8), Wall(15.0, 0.8, 15.0, 6.0))
PERSON = PersonState(18.0, 0.0, 0.0, 1.0, 0.0)


def _rejoin(walked=()):
    rejoin = Rejoin(Params())
    for x in walked:
        rejoin.record(dataclasses.replace(PERSON, x=x))
    return rejoin


def test_no_rejoin_without_walls_or_where_the_slot_is_in_straight_reach():
    rejoin = _rejoin()
    assert rejoin.target(Pose(10.0, 3.0, 0.0), PERSON, (17.0, 0.0), (), 0.0) is None
    assert rejoin.target(Pose(10.0, 3.0, 0.0), PERSON, (17.0, 0.0),
                         (Circle(12.0, -2.0, 0.3),), 0.0) is None        # a pillar is no wall
    assert rejoin.target(Pose(16.0, 1.0, 0.0), PERSON, (17.0, 1.0), DOOR, 0.0) is None
    assert not rejoin.active


def test_behind_the_wall_it_turns_towards_the_opening_then_drives_through():
    rejoin = _rejoin()
    v, omega = rejoin.target(Pose(14.4, 1.6, 0.0), PERSON, (18.0, 1.0), DOOR, 0.0)
    assert rejoin.active and v == 0.0 and omega < 0.0                   # turn right, on the spot
    v, omega = rejoin.target(Pose(14.4, 1.6, -1.2), PERSON, (18.0, 1.0), DOOR, 0.0)
    assert v > 0.0                                                      # facing the opening
    # once through, it ends only when the straight way has RELEASE m to spare
    assert rejoin.target(Pose(15.6, 0.0, 0.0), PERSON, (18.0, 1.0), DOOR, 0.0) is None
    assert not rejoin.active and RELEASE > 0.0


def test_a_walled_in_slot_leads_along_the_persons_way():
    box = (Wall(16.5, -1.0, 19.5, -1.0), Wall(19.5, -1.0, 19.5, 1.0),
           Wall(19.5, 1.0, 16.5, 1.0))                      # open towards -x, slot in a wall
    slot, robot = (18.0, 1.0), Pose(15.0, 3.0, -math.pi / 2)
    alone = _rejoin()
    assert alone.target(robot, PERSON, slot, box, 0.0) is None and not alone.active
    rejoin = _rejoin([x * 0.1 for x in range(0, 171)])      # walked 0 .. 17 m along y = 0
    v, omega = rejoin.target(robot, PERSON, slot, box, 0.0)
    assert rejoin.active and (v > 0.0 or omega != 0.0)


def test_the_persons_way_is_kept_every_spacing():
    rejoin = _rejoin([0.0, 0.1, 0.2, SPACING, 0.3, 1.0, math.nan])
    assert list(rejoin._trail) == [(0.0, 0.0), (SPACING, 0.0), (1.0, 0.0)]
    rejoin.reset()
    assert not rejoin._trail and not rejoin.active


def test_outside_a_corridor_wall_it_goes_back_the_persons_way_not_over_the_unseen_wall():
    # pushed out past the corridor's mouth (wall y = 1.5 from x = 5 on), the LiDAR shows the
    # wall's end and a walker by it; the person walked in along y = 0.1
    seen = (Circle(5.0, 1.5, 0.07, piece=True), Circle(5.6, 1.2, 0.45, piece=True))
    robot, slot = Pose(4.57, 1.62, 0.0), (7.5, 1.0)
    person = dataclasses.replace(PERSON, x=8.5, y=0.1)
    walked = _rejoin()
    for k in range(35):
        walked.record(dataclasses.replace(PERSON, x=0.25 * k, y=0.1))
    _, omega = walked.target(robot, person, slot, seen, 0.0)
    assert walked.active and omega < 0.0                   # right, down into the mouth
    _, omega = _rejoin().target(robot, person, slot, seen, 0.0)
    assert omega > 0.0                                     # without it: left, over the top


def test_a_walker_standing_in_the_opening_is_passed_on_the_free_side():
    # on its way round the door's edge, the robot is in the door's lower half and a walker
    # stopped face to face with it beyond the door (the crowds-robot doorway, seed 14):
    # planned round like a pillar, the robot turns to the upper half; a walker who walks is
    # the keep-out's to give way to, not planned round
    robot, slot = Pose(14.78, -0.31, 0.0), (19.5, 0.9)
    person = dataclasses.replace(PERSON, x=19.5, y=-0.1)
    standing = Circle(15.3, -0.6, 0.25)
    turns = []
    for seen in (DOOR, (*DOOR, standing), (*DOOR, dataclasses.replace(standing, vx=-1.0))):
        rejoin = _rejoin()
        rejoin.active = True
        turns.append(rejoin.target(robot, person, slot, seen, 0.0))
    (_, free), (v, round_it), (_, passing) = turns
    assert v == 0.0 and round_it > free + 0.5        # turns left on the spot, to the free half
    assert passing == free
