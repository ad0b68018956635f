"""The progress bars of the commands (on stderr, so that their printed results stay clean)."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import TypeVar

from tqdm import tqdm

tqdm.monitor_interval = 0   # no monitor thread: the runner forks worker processes

#: Wall seconds before the bars of work that is often quick appear (a quick command prints
#: nothing but its result).
QUIET_S = 1.0

T = TypeVar("T")


@contextmanager
def progress_bar(total: int, unit: str) -> Iterator[Callable[[int], None]]:
    """A progress bar on stderr, advanced by calling the yielded function with the number of
    items done so far."""
    with tqdm(total=total, unit=unit, file=sys.stderr) as bar:
        yield lambda done: bar.update(done - bar.n)


@contextmanager
def seconds_bar(duration: float, what: str = "simulated") -> Iterator[Callable[[float], None]]:
    """A bar over ``duration`` s of simulated (or recorded) time, advanced by calling the
    yielded function with the time reached; its rate is in those seconds per wall second and
    its estimate of the time left is measured. Shown only after :data:`QUIET_S`."""
    total = round(duration, 1)
    with tqdm(total=total, unit="s", desc=what, file=sys.stderr, delay=QUIET_S,
              bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:g} s "
                         "[{elapsed}<{remaining}, {rate_fmt}]") as bar:
        def reached(t: float) -> None:
            bar.update(min(round(t, 1), total) - bar.n)
            if t >= duration:           # done: off the screen before what comes next
                bar.close()
        yield reached


@contextmanager
def sized_bar(unit: str, what: str) -> Iterator[Callable[[int, int], None]]:
    """A bar of work whose size is known once it has started, advanced by calling the yielded
    function with (done, total); shown only after :data:`QUIET_S`."""
    with tqdm(unit=unit, desc=what, file=sys.stderr, delay=QUIET_S) as bar:
        def update(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)
        yield update


def counted(items: Iterable[T], total: int, unit: str, what: str) -> Iterator[T]:
    """``items`` with a bar of ``total`` ``unit`` s named ``what``, shown only after
    :data:`QUIET_S` (an animation's frames)."""
    yield from tqdm(items, total=total, unit=unit, desc=what, file=sys.stderr, delay=QUIET_S)
