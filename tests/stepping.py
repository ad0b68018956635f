"""One step of the standard stack seen whole: its command and its step report."""

from __future__ import annotations

from typing import NamedTuple

from companion.types import PersonEstimate


class Stepped(NamedTuple):
    """The command's ``v``, ``omega``, ``u_ob`` and ``status`` with the report's ``reason``,
    ``estimate``, ``requested`` and ``bearing``."""

    v: float
    omega: float
    u_ob: float
    status: str
    reason: str
    estimate: PersonEstimate | None
    requested: tuple[float, float] | None
    bearing: float | None


def step(stack, obs) -> Stepped:
    """``stack.step(obs)`` with ``stack.report``."""
    cmd = stack.step(obs)
    r = stack.report
    return Stepped(cmd.v, cmd.omega, cmd.u_ob, cmd.status, r.reason, r.estimate, r.requested,
                   r.bearing)


def tick(node, t: float) -> Stepped:
    """``node.tick(t)`` with the node's step report."""
    cmd = node.tick(t)
    r = node.report
    return Stepped(cmd.v, cmd.omega, cmd.u_ob, cmd.status, r.reason, r.estimate, r.requested,
                   r.bearing)
