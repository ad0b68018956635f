"""The contract every companion controller follows.

A controller is built from :class:`~companion.params.Params`, reset before an episode, and maps
one :class:`~companion.types.Observation` per sample period to one
:class:`~companion.types.Command`::

    controller.reset()
    command = controller.step(observation)
    controller.applied(final_command)   # what was actually sent, after the outer layers

``applied`` is called once per step, by the outermost layer (the safety supervisor in the
standard stack); a layer that wraps another passes it on. ``step`` returns finite inputs
within ``robot.v_max`` and ``robot.omega_max``; tests/control/test_contract.py checks every
registered controller.
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

from companion.params import Params, RobotParams
from companion.types import Command, Observation


class Controller(Protocol):
    """A companion controller (see the module docstring)."""

    def reset(self) -> None:
        """Forget all internal state before a new episode."""

    def step(self, obs: Observation) -> Command:
        """Return the input to apply for the next sample period."""

    def applied(self, cmd: Command) -> None:
        """Told the command actually sent; controllers that remember their input store it."""


def saturate(v: float, omega: float, robot: RobotParams) -> tuple[float, float]:
    """Clip each input to its limit (|v| <= v_max, |omega| <= omega_max), componentwise."""
    return (min(max(v, -robot.v_max), robot.v_max),
            min(max(omega, -robot.omega_max), robot.omega_max))


def in_force(params: Params, obs: Observation) -> Params:
    """``params`` with the formation in force that ``obs`` carries (``Observation.formation``,
    set by a formation policy while walking); ``params`` itself where it is the configured
    one. The formation is an input of every step, so a change of side makes no controller
    anew."""
    f, given = params.formation, obs.formation
    if given is None or given == (f.distance, f.bearing):
        return params
    return dataclasses.replace(params, formation=dataclasses.replace(
        f, distance=given[0], bearing=given[1]))
