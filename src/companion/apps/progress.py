"""The progress bar of the commands that run many episodes."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from tqdm import tqdm

tqdm.monitor_interval = 0   # no monitor thread: the runner forks worker processes


@contextmanager
def progress_bar(total: int, unit: str) -> Iterator[Callable[[int], None]]:
    """A progress bar on stderr, advanced by calling the yielded function with the number of
    items done so far."""
    with tqdm(total=total, unit=unit, file=sys.stderr) as bar:
        yield lambda done: bar.update(done - bar.n)
