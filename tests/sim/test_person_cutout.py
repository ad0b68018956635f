"""The LiDAR's returns are left out as the person only near the tracker's confirmed estimate:
detections that a fault drops, or that the tracker refuses, hide nothing (the robot's own
perception front end decides, the same in the simulator and the node)."""

import numpy as np
import pytest

from companion.control import CONTROLLERS, make_controller
from companion.params import REALISTIC, Params
from companion.sim.episode import run_episode
from companion.sim.faults import Fault
from companion.sim.person import Segment, SegmentPath
from companion.sim.sensing import make_perception
from companion.types import Pose

P = Params(sensing=REALISTIC)
#: Centre distance at which the robot's footprint touches the person's body (m).
CONTACT = P.robot.radius + P.lidar.person_radius


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_a_person_whose_detections_drop_out_is_still_an_obstacle(name):
    """The person stands 1 m ahead and the detector goes silent after 0.5 s (a
    ``person_dropout`` fault): the tracker loses them and the search begins, but the LiDAR
    still sees the person's body, so no controller drives into them (the simulated world
    used to leave out the returns at the detections it made before the fault dropped them,
    and every controller hit the person at 0.28 m)."""
    person = SegmentPath((1.0, 0.0, 0.0), [Segment(1.0, 0.0, 0.0)])
    log = run_episode(make_controller(name, P), person, P, 8.0, start=Pose(0.0, 0.0, 0.0),
                      perception=make_perception("lidar", P),
                      faults=(Fault("person_dropout", 0.5, 8.0),))
    gap = np.hypot(log["robot_x"] - log["person_x"], log["robot_y"] - log["person_y"])
    assert any("person_lost" in r for r in log["reason"])
    assert gap.min() > CONTACT + 0.02
    assert "obstacle_in_footprint" not in set(log["reason"])
