"""Parameters of the robot's base as the simulator moves it (the ``plant`` section).

``kind = "kinematic"`` is the unicycle with a first-order lag of every published figure;
``"mujoco"`` a differential-drive base with mass in MuJoCo (docs/plants.md). The defaults
describe a 40 kg base; docs/plants.md gives the source of each.
"""

from __future__ import annotations

import dataclasses

from companion.config import Validated, param, positive, ranged

#: The plants a scenario, suite or flag may name.
PLANTS = ("kinematic", "mujoco")


@ranged("(0, 0.01]")
def _physics_step(x: float) -> str | None:
    return None if 0.0 < x <= 0.01 else "a physics time step in (0, 0.01] s"


@ranged("[0, 2]")
def _friction(x: float) -> str | None:
    return None if 0.0 <= x <= 2.0 else "a friction coefficient in [0, 2]"


@dataclasses.dataclass(frozen=True)
class PlantParams(Validated):
    """The base the simulator moves: a kinematic unicycle or a MuJoCo model (docs/plants.md)."""

    kind: str = param("kinematic", "-", "the robot's base: 'kinematic' (unicycle with the "
                      "first-order lag sensing.actuator_tau_s) or 'mujoco' (a base with mass, "
                      "wheels, motors and friction; docs/plants.md)", choices=PLANTS)
    mass: float = param(40.0, "kg", "MuJoCo base: total mass (body, wheels and caster)",
                        positive)
    body_height: float = param(0.3, "m", "MuJoCo base: height of the cylindrical body (its "
                               "radius is robot.radius); sets the yaw inertia with the mass",
                               positive)
    wheel_radius: float = param(0.1, "m", "MuJoCo base: radius of the two driven wheels",
                                positive)
    track_width: float = param(0.4, "m", "MuJoCo base: distance between the driven wheels' "
                               "contact points", positive)
    wheel_mass: float = param(2.0, "kg", "MuJoCo base: mass of each driven wheel (part of "
                              "mass)", positive)
    friction: float = param(0.8, "-", "MuJoCo base: sliding friction coefficient between the "
                            "driven wheels and the floor", _friction)
    motor_gain: float = param(5.0, "N m s/rad", "MuJoCo base: gain of each wheel's velocity "
                              "servo (torque per rad/s of wheel speed error)", positive)
    torque_max: float = param(10.0, "N m", "MuJoCo base: torque limit of each wheel motor",
                              positive)
    physics_step: float = param(0.002, "s", "MuJoCo base: physics time step (dt is divided "
                                "into whole steps of at most this)", _physics_step)
