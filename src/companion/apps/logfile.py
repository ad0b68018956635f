"""An episode's log on its way to disk: ``log.csv`` written block by block as the episode runs
(:func:`companion.sim.runner.stream_one`), and a thinned copy of the log for the plots, so
that a long run needs memory for a block and the plotted points, not for its whole log."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from companion.io import CsvWriter
from companion.types import LOG_COLUMNS, TEXT_COLUMNS, Log

#: Most rows of a log kept for plotting (:class:`Thinned`).
PLOT_ROWS = 50_000


class LogCsv(CsvWriter):
    """``log.csv``: the columns of :data:`LOG_COLUMNS` and :data:`TEXT_COLUMNS`, one row per
    sample, written whole or not at all: ``with LogCsv(path) as out: out.log(block)`` for each
    block in order."""

    def __init__(self, path: str | Path):
        super().__init__(path, (*LOG_COLUMNS, *TEXT_COLUMNS))

    def log(self, block: Log) -> None:
        numbers = np.column_stack([block[c] for c in LOG_COLUMNS]).tolist()
        texts = zip(*(block[c].tolist() for c in TEXT_COLUMNS))
        self.add(row + list(text) for row, text in zip(numbers, texts))


def write_log(path: str | Path, log: Log) -> None:
    """Write a whole log as ``log.csv`` (see :class:`LogCsv`)."""
    with LogCsv(path) as out:
        out.log(log)


class Thinned:
    """Every ``step``-th row of a log fed block by block, ``step`` chosen so that at most
    ``limit`` (default :data:`PLOT_ROWS`) of ``steps`` rows are kept (all of a short
    run's)."""

    def __init__(self, steps: int, limit: int | None = None):
        self.step = max(1, math.ceil(steps / (limit or PLOT_ROWS)))
        self._seen = 0
        self._parts: list[Log] = []

    def add(self, block: Log) -> None:
        first = -self._seen % self.step        # the block's first row on the stride
        self._parts.append(Log({name: a[first::self.step].copy()   # not a view: the block
                                for name, a in block.columns.items()}))  # can go
        self._seen += len(block)
        if len(self._parts) >= 16:               # a long run's many small parts in one
            self._parts = [Log.concat(self._parts)]

    def log(self) -> Log:
        return Log.concat(self._parts)
