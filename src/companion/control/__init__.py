"""Companion controllers behind one interface (:mod:`companion.control.base`).

``CONTROLLERS`` maps the names accepted by ``companion run --controller`` to factories.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

from companion.control.base import Command, Controller, Observation, PersonState, Pose, saturate
from companion.control.lqr import LqrController
from companion.errors import ConfigError
from companion.config import hint
from companion.params import Params


def paper_lqr(params: Params) -> LqrController:
    """The LQR as printed: linearised at the desired state, u_d = u_h, no error clipping and
    no keep-out barrier."""
    lqr = dataclasses.replace(params.lqr, linearize_at="desired", feedforward="person",
                              error_clip=(math.inf, math.inf, math.inf))
    safety = dataclasses.replace(params.safety, person_clearance=0.0)
    return LqrController(dataclasses.replace(params, lqr=lqr, safety=safety))


CONTROLLERS: dict[str, Callable[[Params], Controller]] = {
    "lqr": LqrController,
    "lqr-paper": paper_lqr,
}


def make_controller(name: str, params: Params) -> Controller:
    """Construct the registered controller ``name``; unknown names raise ConfigError."""
    if name not in CONTROLLERS:
        raise ConfigError(f"controller: unknown controller {name!r}{hint(name, CONTROLLERS)} "
                          f"(known: {', '.join(CONTROLLERS)})")
    return CONTROLLERS[name](params)


__all__ = ["CONTROLLERS", "Command", "Controller", "LqrController", "Observation",
           "PersonState", "Pose", "make_controller", "paper_lqr", "saturate"]
