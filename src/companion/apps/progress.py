"""The progress bars of the commands and what they say when interrupted (on stderr, so that
their printed results stay clean)."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TypeVar

from tqdm import tqdm

from companion import _jit
from companion.apps.args import shown
from companion.evaluate.run import PARTIAL, kept_results

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


@contextmanager
def resumable(command: str, out: Path, total: int | None = None, kept: str | None = ""
              ) -> Iterator[None]:
    """Inside, Ctrl-C or SIGTERM first says what was kept and that the same command
    continues from it: ``kept`` (None: nothing), by default the episodes (of ``total``) the
    engine kept in ``out``."""
    try:
        yield
    except BaseException as exc:
        if not isinstance(exc, (Exception, SystemExit, GeneratorExit)):
            if kept == "":
                n = kept_results(out)
                kept = (f"{n}{'' if total is None else f' of {total}'} episodes kept in "
                        f"{shown(out / PARTIAL)}") if n else None
            print(f"{command}: stopped; " + (f"{kept}: the same command continues from "
                  f"them" if kept else "nothing kept"), file=sys.stderr, flush=True)
        raise


def compile_kernels(signals: bool = True) -> None:
    """Compile the numerical kernels now, saying so (a cold cache: about half a minute).
    With ``signals`` (the main thread), Ctrl-C or SIGTERM meanwhile ends the process at
    once: raised inside numba's compiler an exception is swallowed by its C callbacks and
    surfaces later as a RuntimeError. Nothing is written yet, and the cache keeps only
    whole files."""
    print("companion: compiling the numerical kernels for these sources, once (about half a "
          "minute; later runs load them)", file=sys.stderr, flush=True)

    def stop(signum: int, frame) -> None:
        print("companion: stopped while compiling; no output was changed", file=sys.stderr,
              flush=True)
        os._exit(128 + signum)

    kinds = (signal.SIGINT, signal.SIGTERM) if signals else ()
    before = {kind: signal.signal(kind, stop) for kind in kinds}
    try:
        _jit.warm_up()
    finally:
        for kind, handler in before.items():
            signal.signal(kind, handler)
