"""What the node says in its log about itself (docs/ros2.md): status changes, and each new
problem with its inputs (a publisher of a type or QoS it cannot take, inputs it cannot place),
once, with the active ones kept for the status topic."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

from companion.types import StepReport

#: How often (s of node time) the node looks at the publishers on its input topics.
GRAPH_PERIOD_S = 1.0
#: A change between ok and degraded is logged at most this often (s); a stop, and the end of
#: one, at once.
STATUS_LOG_S = 5.0


class Watch:
    """The node's log of what changed: ``status`` each tick, ``problems`` every
    :data:`GRAPH_PERIOD_S`; :attr:`warnings` the active problems, one line each."""

    def __init__(self, log: logging.Logger):
        self.log = log
        self.warnings: list[str] = []
        self.placing: dict[str, str] = {}          # inputs that cannot be placed, by input
        self._said: set[str] = set()
        self._graph_t = -math.inf
        self._shown = ("", "", -math.inf)          # status, reason, when logged

    def status(self, now: float, report: StepReport) -> None:
        status, _, shown = self._shown
        stop = "stopped" in (report.status, status)
        if report.status != status and (stop or now - shown >= STATUS_LOG_S):
            level = logging.WARNING if report.status == "stopped" else logging.INFO
            self.log.log(level, "status %s%s", report.status,
                         f": {report.reason}" * bool(report.reason))
            self._shown = (report.status, report.reason, now)

    def problems(self, now: float, graph_problems: Callable[[], list[str]]) -> None:
        """Every :data:`GRAPH_PERIOD_S`: the graph's problems and the inputs that could not be
        placed since the last look; each new line logged once."""
        if now - self._graph_t < GRAPH_PERIOD_S:
            return
        self._graph_t = now
        lines = graph_problems() + list(self.placing.values())
        self.placing = {}
        for line in lines:
            if line not in self._said:
                self.log.warning("%s", line)
                self._said.add(line)
        self.warnings = lines
