"""Running a suite: every episode once, on local worker processes or a Dask cluster, each
result kept as soon as it is known so that a killed run resumes where it stopped. An
episode's result is what the suite's row function makes of it (:attr:`Suite.row
<companion.evaluate.suite.Suite>`: the row of numbers of a TOML suite, or what a suite
generator asks for, such as the fuzz's counts).

Results are kept in ``<out>/.evaluate.partial/episodes.jsonl``, one JSON line per finished
episode, appended and flushed to disk one at a time (a line cut short by a kill is ignored).
The file's first line holds the suite's digest, its row function's name and the code's
digest (every source file of companion, and the numpy and scipy versions); a changed suite
or an updated companion starts over. An episode's
result depends on its spec alone, so the same suite gives the same results whatever the
number or kind of workers (given the same companion and libraries on every worker).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import nullcontext
from pathlib import Path
from typing import Any

import numpy as np
import scipy

from companion.evaluate.suite import Suite
from companion.sim.runner import EpisodeSpec, run_unordered

PARTIAL = ".evaluate.partial"


def run_suite(suite: Suite, out: Path | None, workers: int | None = None,
              dask: str | None = None, progress: Callable[[int, int], None] | None = None
              ) -> list[dict]:
    """One row per episode of ``suite`` (its factors, ``episode``, ``pair`` and its
    numbers), in the suite's order; the episodes kept under ``out`` from an earlier call are
    not run again (None: nothing kept). ``dask``: None (local worker processes), ``"local"``
    (a Dask LocalCluster on 127.0.0.1) or a scheduler address. ``progress(done, total)``
    after each episode."""
    return suite_rows(suite, dict(zip((e.key for e in suite.episodes),
                                      run_results(suite, out, workers, dask, progress))))


def run_results(suite: Suite, out: Path | None = None, workers: int | None = None,
                dask: str | None = None, progress: Callable[[int, int], None] | None = None
                ) -> list:
    """What ``suite.row`` gives for every episode of ``suite``, in the suite's order, on the
    backends of :func:`run_suite`. With ``out`` each result is kept there as soon as it is
    known (it must then be JSON: a row, counts) and the results kept from an earlier call of
    the same suite, row function and companion are not run again; without, nothing is kept
    (a result may then be anything picklable: a row and its log)."""
    if dask is not None:
        from companion.evaluate.dask_backend import check_address
        check_address(dask)
    store = None if out is None else Path(out) / PARTIAL / "episodes.jsonl"
    digest = _digest(suite)
    kept, done = (False, {}) if store is None else _load(store, digest)
    todo = [e for e in suite.episodes if e.key not in done]
    total = len(suite.episodes)
    if progress:
        progress(total - len(todo), total)
    with nullcontext(lambda key, result: None) if store is None \
            else _Appender(store, digest, fresh=not kept) as keep:
        for n, (i, result) in enumerate(_backend(dask, workers, [e.spec for e in todo],
                                                 suite.row), 1):
            done[todo[i].key] = result
            keep(todo[i].key, result)
            if progress:
                progress(total - len(todo) + n, total)
    return [done[e.key] for e in suite.episodes]


def _name(func: Callable) -> str:
    """The module and name of a row function (of the function a partial wraps): what it
    computes is its code's, and a partial's arguments are the suite digest's."""
    func = getattr(func, "func", func)
    return f"{func.__module__}.{func.__qualname__}"


@functools.cache
def code_digest() -> str:
    """A digest of what computes an episode's numbers: every Python and TOML file of the
    companion package, and the numpy and scipy versions."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256(f"numpy {np.__version__} scipy {scipy.__version__}".encode())
    for f in sorted(p for ext in ("*.py", "*.toml") for p in root.rglob(ext)):
        h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def run_all(suite: Suite, workers: int | None = None, dask: str | None = None,
            progress: Callable[[int], None] | None = None) -> list[dict]:
    """The rows of :func:`run_suite` without keeping anything on disk (benches, tests);
    ``progress(done)``."""
    return run_suite(suite, None, workers, dask, progress and (lambda done, total: progress(done)))


def suite_rows(suite: Suite, results: dict[str, dict]) -> list[dict]:
    """One row per episode of ``suite``: its factors, ``episode``, ``pair`` and its numbers
    (``results`` by episode key)."""
    return [{**e.factors, "episode": e.key, "pair": e.pair, **results[e.key]}
            for e in suite.episodes]


def kept_count(suite: Suite, out: Path) -> int:
    """How many of ``suite``'s results an earlier, unfinished run kept in ``out``."""
    _, done = _load(Path(out) / PARTIAL / "episodes.jsonl", _digest(suite))
    return sum(e.key in done for e in suite.episodes)


def kept_results(out: Path) -> int:
    """How many results the store in ``out`` holds, whatever suite made them (what a run
    interrupted just now kept)."""
    return len(_read(Path(out) / PARTIAL / "episodes.jsonl")[1])


def _digest(suite: Suite) -> str:
    """What kept results must have been made with: the suite, its row function, the code."""
    return f"{suite.digest}:{_name(suite.row)}:{code_digest()}"


def finish(out: Path) -> None:
    """Forget the kept episodes once the outputs are written."""
    store = Path(out) / PARTIAL
    for f in store.glob("*"):
        f.unlink()
    if store.exists():
        store.rmdir()


def _backend(dask: str | None, workers: int | None, specs: Sequence[EpisodeSpec],
             reduce: Callable[[EpisodeSpec], Any]) -> Iterator[tuple[int, Any]]:
    if not specs:
        return iter(())
    if dask is None:
        return run_unordered(specs, workers, reduce)
    from companion.evaluate.dask_backend import run_dask
    return run_dask(specs, dask, workers, reduce)


def _load(store: Path, digest: str) -> tuple[bool, dict[str, dict]]:
    """Whether ``store`` belongs to the suite of ``digest``, and the results kept there."""
    header, results = _read(store)
    if header.get("digest") != digest:
        return False, {}
    return True, results


def _read(store: Path) -> tuple[dict, dict[str, Any]]:
    """The header of ``store`` and the results it keeps, by episode key (none without the
    file or a readable header; a line cut short by a kill is left out: it runs again)."""
    if not store.exists():
        return {}, {}
    lines = store.read_text(encoding="utf-8").splitlines()
    try:
        header = json.loads(lines[0]) if lines else {}
    except json.JSONDecodeError:
        return {}, {}
    out = {}
    for line in lines[1:]:
        try:
            item = json.loads(line)
        except json.JSONDecodeError:
            continue
        out[item["key"]] = item["result"]
    return header, out


class _Appender:
    """Appends one JSON line per result to the store, flushed and synced each time; a
    ``fresh`` store (none, or another suite's) is started over with the digest."""

    def __init__(self, store: Path, digest: str, fresh: bool):
        self.store, self.digest, self.fresh = store, digest, fresh

    def __enter__(self) -> Callable[[str, dict], None]:
        self.store.parent.mkdir(parents=True, exist_ok=True)
        fresh = self.fresh
        if not fresh:                       # drop a line a kill cut short
            data = self.store.read_bytes()
            if not data.endswith(b"\n"):
                with open(self.store, "r+b") as f:
                    f.truncate(data.rfind(b"\n") + 1)
        self._file = open(self.store, "w" if fresh else "a", encoding="utf-8")
        if fresh:
            self._write({"digest": self.digest})
        return lambda key, result: self._write({"key": key, "result": result})

    def _write(self, item: dict) -> None:
        self._file.write(json.dumps(item, allow_nan=True) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def __exit__(self, *exc: object) -> None:
        self._file.close()
