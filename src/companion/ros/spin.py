"""The node's loop: a tick every period on its clock (the system clock, or /clock with
``use_sim_time``), a zero velocity at the end (docs/ros2.md)."""

from __future__ import annotations

import math
import threading

from companion.ros.node import CompanionNode

#: A period is due this much before its time: /clock carries nanoseconds and the schedule
#: sums ``dt``, so a clock of exactly ``k * dt`` can read a hair before the summed time.
_CLOCK_SLACK_S = 1e-6


def spin(node: CompanionNode, stop: threading.Event, limit_s: float | None = None) -> int:
    """Tick ``node`` every period until ``stop`` is set (or ``limit_s`` s of the node's time
    have passed), then publish a zero velocity; returns the number of ticks."""
    dt, sim = node.config.params.dt, node.config.ros.use_sim_time
    ticks, start, next_t = 0, None, None
    while not stop.is_set():
        due = -math.inf if next_t is None else next_t - _CLOCK_SLACK_S
        now = node.wait_clock(due, 0.1) if sim else node.now()
        if now is None or now < due:
            if not sim:
                stop.wait(min(due - now, dt))
            continue
        start = now if start is None else start
        if limit_s is not None and now - start >= limit_s:
            break
        node.tick(now)
        ticks += 1
        next_t = (next_t if next_t is not None else now) + dt
        if next_t < now - dt:           # fell behind by more than a period: do not burst
            next_t = now + dt
    node.stop(node.now() or 0.0)
    return ticks
