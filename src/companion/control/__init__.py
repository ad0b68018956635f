"""Companion controllers behind one interface (:mod:`companion.control.base`).

``CONTROLLERS`` maps the names accepted by ``companion run --controller`` to factories.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

from companion.control.avoidance import AvoidingController
from companion.control.base import Command, Controller, Observation, PersonState, Pose, saturate
from companion.control.impedance import ImpedanceController
from companion.control.lqr import LqrController
from companion.control.pid import PidController
from companion.control.supervisor import SafetySupervisor
from companion.control.vsm import VsmController
from companion.errors import ConfigError
from companion.config import hint
from companion.params import Params


def paper_params(params: Params) -> Params:
    """The paper's design: LQR linearised at the desired state, u_d = u_h, no error clipping,
    no keep-out barriers, the paper's phi in Eq. 17 (no collision cone)."""
    lqr = dataclasses.replace(params.lqr, linearize_at="desired", feedforward="person",
                              error_clip=(math.inf, math.inf, math.inf))
    safety = dataclasses.replace(params.safety, person_clearance=0.0, obstacle_clearance=0.0)
    avoidance = dataclasses.replace(params.avoidance, cone_margin=-1.0)
    return dataclasses.replace(params, lqr=lqr, safety=safety, avoidance=avoidance)


def paper_lqr(params: Params) -> LqrController:
    """The LQR as printed (see :func:`paper_params`), without the avoidance layer."""
    return LqrController(paper_params(params))


#: Q and R of our LQR after the same tuning procedure and budget as the baselines
#: (``companion tune lqr``, docs/baselines.md).
TUNED_LQR_Q = (109.1, 10.69, 113.6, 1.058, 8.022)
TUNED_LQR_R = (1.566, 41.36)


def tuned_lqr_params(params: Params) -> Params:
    """Our LQR with Q and R from ``companion tune lqr`` instead of Table 1."""
    lqr = dataclasses.replace(params.lqr, q=TUNED_LQR_Q, r=TUNED_LQR_R)
    return dataclasses.replace(params, lqr=lqr)


@dataclass(frozen=True)
class Entry:
    """A registered controller: its factory and how it adjusts the parameters."""

    factory: Callable[[Params], Controller]
    adjust: Callable[[Params], Params] = lambda p: p


CONTROLLERS: dict[str, Entry] = {
    "lqr": Entry(LqrController),
    "lqr-paper": Entry(LqrController, paper_params),
    "lqr-tuned": Entry(LqrController, tuned_lqr_params),
    "pid": Entry(PidController),
    "vsm": Entry(VsmController),
    "ic": Entry(ImpedanceController),
}


def make_controller(name: str, params: Params) -> SafetySupervisor:
    """Construct the registered controller ``name`` inside the avoidance layer (the same
    module for every controller, as in the paper's Fig. 4) and the safety supervisor (the
    standard stack); unknown names raise ConfigError."""
    if name not in CONTROLLERS:
        raise ConfigError(f"controller: unknown controller {name!r}{hint(name, CONTROLLERS)} "
                          f"(known: {', '.join(CONTROLLERS)})")
    entry = CONTROLLERS[name]
    params = entry.adjust(params)
    return SafetySupervisor(AvoidingController(entry.factory(params), params), params)


__all__ = ["AvoidingController", "CONTROLLERS", "Command", "Controller", "ImpedanceController",
           "LqrController", "Observation", "PersonState", "PidController", "Pose", "SafetySupervisor",
           "VsmController", "make_controller", "paper_lqr", "paper_params", "saturate"]
