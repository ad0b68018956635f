"""Could the robot have escaped a contact the person caused, had it known the person's path?

The closed-loop fuzz's walker does not see the robot and walks at up to 2 m/s, faster than
the robot's 1.5 m/s; a differential drive cannot step aside. For a contact the person caused
(:mod:`companion.sim.fuzz`), :func:`escapable` replays the robot from its true state
``lead`` s before the contact with every command of a grid held (ramped at the rate limits,
through the actuator lag, as the simulated base moves), against the person's TRUE path, and
tells whether any of them stays out of contact with the person and the obstacles until
``lead`` s after it. None escaping means not even a robot that knew the person's next
``2 lead`` s could have avoided the contact with a constant command: the contact is the
walker's doing in the strongest sense this check can give.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from companion.control.limits import limit
from companion.geometry import base_step
from companion.params import Params
from companion.sim.episode import nearest_clearance
from companion.types import Log, Obstacle

#: Seconds of foresight before the contact and of escape after it.
LEAD = 1.0
#: Targets of the replay: fractions of (v_max, omega_max), 9 x 7.
GRID = [(v, w) for v in np.linspace(-1.0, 1.0, 9) for w in np.linspace(-1.0, 1.0, 7)]


def escapable(log: Log, k: int, params: Params, obstacles: Sequence[Obstacle] = (),
              lead: float = LEAD) -> bool:
    """True if, from the robot's true state at row ``k - lead / dt``, some command of
    :data:`GRID` held to the end keeps the robot centre at least ``robot.radius +
    lidar.person_radius`` from the true person and the footprint clear of the obstacles at
    every row up to ``k + lead / dt`` (the rows of ``log``; a window cut by the log's ends is
    shorter)."""
    dt, r = params.dt, params.robot
    n = int(round(lead / dt))
    k0, k1 = max(k - n, 0), min(k + n, len(log) - 1)
    contact = r.radius + params.lidar.person_radius
    tau = params.sensing.actuator_tau_s
    px, py = log["person_x"][k0:k1 + 1], log["person_y"][k0:k1 + 1]
    start = (float(log["robot_x"][k0]), float(log["robot_y"][k0]),
             float(log["robot_theta"][k0]))
    actual = (float(log["robot_v"][k0]), float(log["robot_omega"][k0]))
    last = (float(log["v"][k0 - 1]), float(log["omega"][k0 - 1])) if k0 > 0 else actual
    for fv, fw in GRID:
        target = (fv * r.v_max, fw * r.omega_max)
        x, y, th = start
        va, wa = actual
        command = last
        clear = True
        for j in range(1, k1 - k0 + 1):
            command = limit(target, command, params)
            x, y, th, va, wa = base_step(x, y, th, va, wa, *command, tau, dt)
            if np.hypot(px[j] - x, py[j] - y) < contact \
                    or (obstacles and nearest_clearance(x, y, obstacles, r.radius) <= 0.0):
                clear = False
                break
        if clear:
            return True
    return False
