"""Companion controllers behind one interface (:mod:`companion.control.base`) and the standard
stack every one of them runs in: safety supervisor -> avoidance layer -> controller.

``CONTROLLERS`` maps the names accepted by ``companion run --controller`` to factories.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

from companion.config import hint
from companion.control.avoidance import AvoidingController
from companion.control.base import Controller, saturate
from companion.control.impedance import ImpedanceController
from companion.control.lqr import LqrController
from companion.control.pid import PidController
from companion.control.supervisor import SafetySupervisor
from companion.control.vsm import VsmController
from companion.errors import ConfigError
from companion.params import Params


def paper_params(params: Params) -> Params:
    """The paper's design: LQR linearised at the desired state, u_d = u_h always trusted, no
    error clipping, the paper's phi in Eq. 17 (no collision cone) and no comfort barriers
    (the supervisor's protective distance and braking bounds stay: they are not part of the
    compared design)."""
    lqr = dataclasses.replace(params.lqr, linearize_at="desired", feedforward="person",
                              error_clip=(math.inf, math.inf, math.inf),
                              feedforward_std=(math.inf, math.inf))
    keepout = dataclasses.replace(params.keepout, person_clearance=0.0, obstacle_clearance=0.0)
    avoidance = dataclasses.replace(params.avoidance, cone_margin=-1.0)
    return dataclasses.replace(params, lqr=lqr, keepout=keepout, avoidance=avoidance)


def paper_lqr(params: Params) -> LqrController:
    """The LQR as printed (see :func:`paper_params`), without the avoidance layer."""
    return LqrController(paper_params(params))


#: Q and R of our LQR after the same tuning as the baselines' default gains (the ideal-sensing
#: search of docs/baselines.md).
TUNED_LQR_Q = (109.1, 10.69, 113.6, 1.058, 8.022)
TUNED_LQR_R = (1.566, 41.36)


def tuned_lqr_params(params: Params) -> Params:
    """Our LQR with the tuned Q and R (:data:`TUNED_LQR_Q`) instead of Table 1's. They were
    tuned with the feedforward always trusted and already weigh ``u_e`` lightly, so it stays
    trusted (docs/model.md, section 4.6)."""
    lqr = dataclasses.replace(params.lqr, q=TUNED_LQR_Q, r=TUNED_LQR_R,
                              feedforward_std=(math.inf, math.inf))
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


def lookup(name: str) -> Entry:
    """The registered controller ``name``; an unknown name raises ConfigError with a hint."""
    if name not in CONTROLLERS:
        raise ConfigError(f"controller: unknown controller {name!r}{hint(name, CONTROLLERS)} "
                          f"(known: {', '.join(CONTROLLERS)})")
    return CONTROLLERS[name]


def make_bare(name: str, params: Params) -> Controller:
    """The registered controller ``name`` alone, without avoidance layer and supervisor."""
    entry = lookup(name)
    return entry.factory(entry.adjust(params))


def make_controller(name: str, params: Params) -> SafetySupervisor:
    """The standard stack of the registered controller ``name``: the safety supervisor around
    the avoidance layer (the same module for every controller, as in the paper's Fig. 4)
    around the controller."""
    return SafetySupervisor(avoiding(name, params), lookup(name).adjust(params))


def check_stack(name: str, params: Params, where: str = "") -> None:
    """Make the standard stack of ``name`` for ``params`` once, so that LQR weights without a
    stabilising gain are an error when a file is read; its message (``lqr.q: ...``, a key of
    the parameters) is prefixed with ``where`` (``file: params.``)."""
    try:
        make_controller(name, params)
    except ConfigError as exc:
        raise ConfigError(f"{where}{exc}") from None


def avoiding(name: str, params: Params) -> AvoidingController:
    """The avoidance layer around the registered controller ``name`` made for ``params``:
    what the safety supervisor wraps."""
    entry = lookup(name)
    params = entry.adjust(params)
    return AvoidingController(entry.factory(params), params)


def retune(stack: SafetySupervisor, name: str, params: Params) -> None:
    """Give the running stack of controller ``name`` new parameters (docs/ros2.md, "Parameters
    while running"): the controller and the avoidance layer are made anew with them, the
    supervisor keeps its tracker and its last command (:meth:`SafetySupervisor.retune`)."""
    stack.retune(avoiding(name, params), lookup(name).adjust(params))


__all__ = ["AvoidingController", "CONTROLLERS", "Controller", "ImpedanceController",
           "LqrController", "PidController", "SafetySupervisor", "VsmController",
           "check_stack", "lookup", "make_bare", "make_controller", "paper_lqr", "paper_params",
           "retune", "saturate", "tuned_lqr_params"]
