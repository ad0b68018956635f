"""The perception front end the simulator and the node share: placement at a stamp, one
source per sensor with its own stamps and timeout, and the person left out of the LiDAR's
obstacles only near a confirmed estimate."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion.params import LidarParams, Params
from companion.perception.front_end import (
    FrontEnd,
    OdometrySource,
    ScanSource,
    Source,
    person_cutout,
)
from companion.sim.lidar import cast
from companion.types import Circle, PersonDetection, PersonEstimate, PersonState, Pose

P = Params()
PERSON = Circle(2.0, 0.0, 0.2)
POST = Circle(0.0, 2.0, 0.15)


def estimate(x: float, y: float) -> PersonEstimate:
    s = PersonState(x, y, 0.0, 0.0, 0.0)
    return PersonEstimate(s, 0.05, np.zeros((5, 5)), 0.0, "seen", s)


def scan_at(t: float):
    """A noiseless scan from the origin of the person at (2, 0) and a post at (0, 2)."""
    s = cast(Pose(0.0, 0.0, 0.0), [POST], [], (PERSON.x, PERSON.y), LidarParams(noise_std=0.0))
    return dataclasses.replace(s, t=t)


def near(obstacles, c: Circle) -> bool:
    return any(math.hypot(o.x - c.x, o.y - c.y) < 0.3 for o in obstacles)


def test_a_source_takes_each_stamp_once_and_goes_stale_after_its_timeout():
    s = Source(timeout_s=0.5)
    assert s.stale(0.0) and s.take(1.0) and not s.take(1.0) and not s.take(0.9)
    assert not s.stale(1.5) and s.stale(1.51)
    assert not s.take(math.nan)


def test_odometry_places_a_stamp_between_its_samples_and_drops_invalid_poses():
    odo = OdometrySource(horizon_s=1.0)
    odo.add(0.0, Pose(0.0, 0.0, 0.0), (1.0, 0.0))
    odo.add(0.1, Pose(math.nan, 0.0, 0.0), (1.0, 0.0))       # not kept
    odo.add(0.2, Pose(0.2, 0.0, 0.0), None)
    assert odo.pose_at(0.1).x == pytest.approx(0.1)
    assert odo.pose_at(0.3).x == pytest.approx(0.2)          # no velocity known: stands
    odo.add(2.0, Pose(2.0, 0.0, 0.0), (1.0, 0.0))
    assert len(odo.samples) == 1                             # older than the horizon: gone
    assert math.isnan(OdometrySource(1.0).pose_at(0.0).x)


def test_the_person_is_left_out_only_near_a_confirmed_estimate():
    assert person_cutout(None) is None
    assert person_cutout(estimate(1.0, 2.0)) == (1.0, 2.0)
    seen = ScanSource(P).update(scan_at(0.0), estimate(PERSON.x, PERSON.y), 0.0)
    assert near(seen, POST) and not near(seen, PERSON)
    lost = ScanSource(P).update(scan_at(0.0), None, 0.0)
    assert near(lost, POST) and near(lost, PERSON)


def test_a_scan_is_used_once_and_its_obstacles_held_until_the_timeout():
    src = ScanSource(P)
    first = src.update(scan_at(0.0), None, 0.0)
    assert src.update(scan_at(0.0), estimate(PERSON.x, PERSON.y), 0.05) == first   # same stamp
    assert src.update(None, None, 0.5) == first
    assert src.update(None, None, 0.0 + P.lidar.timeout_s + 0.01) == ()
    later = src.update(scan_at(1.5), estimate(PERSON.x, PERSON.y), 1.5)
    assert near(later, POST) and not near(later, PERSON)


def test_other_people_are_moving_obstacles_in_the_front_ends_list():
    front = FrontEnd(P)
    for k in range(10):
        t = 0.1 * k
        front.people.update([PersonDetection(t, 3.0 + 1.0 * t, 1.0)])
    obs = front.obstacles((POST,), None, None, 0.9)
    assert obs[0] == POST and len(obs) == 2
    assert obs[1].vx == pytest.approx(1.0, abs=0.2) and obs[1].moving
