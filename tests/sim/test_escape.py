"""Could a robot that knew the person's path have escaped a contact (companion.sim.escape)?"""

import numpy as np

from companion.params import Params
from companion.sim.escape import escapable
from companion.types import LOG_COLUMNS, Log, Wall

P = Params()


def _crossing(n=61, speed=2.0):
    """A robot at rest at the origin, facing +x; the person walks along +y at ``speed`` and
    reaches the robot's centre at row 40."""
    c = {k: np.zeros(n) for k in LOG_COLUMNS}
    c["t"] = np.arange(n) * P.dt
    c["person_y"] = (np.arange(n) - 40) * speed * P.dt
    c["status"], c["reason"] = np.array(["ok"] * n), np.array([""] * n)
    return Log(c)


def contact_row(log):
    d = np.hypot(log["person_x"] - log["robot_x"], log["person_y"] - log["robot_y"])
    return int(np.flatnonzero(d < P.robot.radius + P.lidar.person_radius)[0])


def test_a_robot_with_room_to_drive_off_could_have_escaped():
    log = _crossing()
    assert escapable(log, contact_row(log), P)


def test_a_robot_boxed_in_across_the_persons_path_could_not():
    # walls 5 cm beyond the footprint ahead and behind: it can only turn on the spot
    box = (Wall(0.3, -5.0, 0.3, 5.0), Wall(-0.3, -5.0, -0.3, 5.0))
    log = _crossing()
    assert not escapable(log, contact_row(log), P, box)


def test_without_foresight_the_robot_cannot_escape_a_fast_person():
    # 0.1 s of warning: the person at 2 m/s closes 0.45 m in 0.23 s, too fast to drive off
    log = _crossing()
    assert not escapable(log, contact_row(log), P, lead=0.1)
