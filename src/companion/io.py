"""Files in and out: input cells parsed with one-line errors, outputs written whole or not at
all (to a temporary file, then renamed), and a command's outputs switched together in one
step (:class:`Outputs`: a new folder built beside the output folder, then renamed into
place)."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from companion.errors import CompanionError, DataError
from companion.swap import ACTIVE, leftovers, locked, remove_stale, sibling, switch, unswitchable

__all__ = ["leftovers"]

#: Largest magnitude of a number in a data file (m, s): beyond it a cell is corrupt.
MAX_CELL = 1e6


def parse_number(where: str, col: str, cell: str) -> float:
    """A finite float from a data-file cell, or a one-line DataError naming ``where`` (file
    and line) and the column ``col``."""
    text = cell.strip()
    try:
        value = float(text)
    except ValueError:
        raise DataError(f"{where}: column '{col}': expected a number, got {text!r}") from None
    if not abs(value) <= MAX_CELL:
        raise DataError(f"{where}: column '{col}': expected a finite number of magnitude at "
                        f"most {MAX_CELL:g}, got {text!r}")
    return value


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _umask()


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` to write to, renamed to ``path`` when the block ends
    normally; on any error the temporary file is removed and ``path`` is left untouched."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_UMASK)      # mkstemp makes it 0600: follow the umask
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp_path)`` and atomically rename the result to ``path``.

    On any error the temporary file is removed and ``path`` is left untouched.
    """
    with atomic_path(path) as tmp:
        write(tmp)
    return Path(path)


def write_text(path: str | Path, text: str) -> Path:
    return atomic_write(path, lambda p: p.write_text(text, encoding="utf-8"))


def write_json(path: str | Path, data: Any) -> Path:
    return write_text(path, json.dumps(data, indent=2, allow_nan=False) + "\n")


def write_csv(path: str | Path, header: Sequence[str], rows: Iterable[Sequence[Any]]) -> Path:
    """Write a CSV; floats with 10 significant digits."""
    with CsvWriter(path, header) as out:
        out.add(rows)
    return Path(path)


def _cell(value: Any) -> Any:
    return f"{value:.10g}" if isinstance(value, float) else value


class CsvWriter:
    """A CSV file written as its rows come, whole or not at all: ``with CsvWriter(path,
    header) as out: out.add(rows)`` as often as needed; the file appears at ``path`` when
    the block ends normally (:func:`atomic_path`). Floats get 10 significant digits."""

    def __init__(self, path: str | Path, header: Sequence[str]):
        self.path, self.header = Path(path), header
        self._stack = ExitStack()

    def __enter__(self) -> CsvWriter:
        with ExitStack() as stack:
            tmp = stack.enter_context(atomic_path(self.path))
            self._file = stack.enter_context(open(tmp, "w", encoding="utf-8", newline=""))
            self._csv = csv.writer(self._file, lineterminator="\n")
            self._csv.writerow(self.header)
            self._stack = stack.pop_all()
        return self

    def add(self, rows: Iterable[Sequence[Any]]) -> None:
        self._csv.writerows([_cell(v) for v in row] for row in rows)

    def __exit__(self, kind, value, trace) -> bool | None:
        return self._stack.__exit__(kind, value, trace)


def save_figure(fig: Any, path: str | Path, dpi: int = 120) -> Path:
    """Save a matplotlib figure atomically as PNG."""
    return atomic_write(path, lambda p: fig.savefig(p, dpi=dpi, format="png"))


class Outputs:
    """The outputs of one run of ``command`` in ``folder``: plain files and folders, all or
    nothing, switched in one step.

    ``with Outputs(folder, "run") as stage:`` gives a new hidden folder beside ``folder`` (in
    its parent: ``.<folder name>.companion-<pid>-<n>.tmp``) to write the outputs into. When
    the block ends normally the rest of ``folder`` (what is not this command's previous
    output: other commands' files, ``.evaluate.partial``) is carried into it as hard links,
    with ``.<command>.outputs`` listing the command's names; it is renamed
    ``.<...>.new`` (from then on it is complete), and that folder and ``folder`` are swapped
    in one rename (``renameat2`` with ``RENAME_EXCHANGE``; where the system has none: ``folder``
    renamed to ``.<...>.old``, then the new one to ``folder``); the old set is then removed. A
    reader sees the previous set or the new one, never a mix, whenever the process is
    killed. When the block ends with an exception (an error, Ctrl-C, SIGTERM) the temporary
    folder is removed and ``folder`` is left as it was.

    Recovery, on the next entry for ``folder``, of what processes that no longer exist left:
    a ``.new`` folder is moved to ``folder`` if ``folder`` is missing or empty (the switch was
    killed between its two renames: the set is complete; ``--out`` checks may have made an
    empty folder since, and a switched folder always holds its manifest), else removed; an
    ``.old`` one likewise after it; ``.tmp`` folders are removed. The layout of earlier versions
    is converted by the first switch: plain files listed in ``.<command>.outputs`` are
    replaced, and the symbolic links through ``.<command>@current`` into hidden generation
    folders become plain files (the generations and links go). Switches beside each other
    take turns (a lock on the parent folder); a command writing into ``folder`` itself (its
    resumable store) while another switches it may lose what it writes in that moment.
    """

    _count = 0

    def __init__(self, folder: str | Path, command: str):
        self.folder, self.command = Path(folder), command
        self._pid = os.getpid()
        Outputs._count += 1
        self._tag = f"{self._pid}-{Outputs._count}"
        self.stage = sibling(self.folder.absolute(), self._tag, "tmp")   # resolved on entry

    def __enter__(self) -> Path:
        self.folder.absolute().parent.mkdir(parents=True, exist_ok=True)
        self.folder = self.folder.resolve()
        self.stage = sibling(self.folder, self._tag, "tmp")
        with locked(self.folder.parent):
            remove_stale(self.folder)      # first: a vacant folder may get a complete set
            self.folder.mkdir(exist_ok=True)
            reason = unswitchable(self.folder)
            if reason:
                raise CompanionError(f"{self.folder}: {reason}")
            self.stage.mkdir(mode=0o777)
        ACTIVE.add(self._tag)
        return self.stage

    def __exit__(self, kind, value, trace) -> None:
        if os.getpid() != self._pid:        # a forked worker leaving: not its outputs
            return
        try:
            if kind is not None:
                shutil.rmtree(self.stage, ignore_errors=True)
                return
            with locked(self.folder.parent):
                try:
                    _complete(self.folder, self.command, self.stage)
                except BaseException:
                    shutil.rmtree(self.stage, ignore_errors=True)
                    raise
                switch(self.folder, self.stage, self._tag)
        finally:
            ACTIVE.discard(self._tag)


@contextmanager
def atomic_folder(path: str | Path) -> Iterator[Path]:
    """A path to build a folder at (not made yet, of the same name as ``path``, in a hidden
    folder beside it: a rosbag2 writer names its files after it), put at ``path`` whole when
    the block ends normally, replacing what was there (:class:`Outputs`' switch); on an
    exception it is removed and ``path`` left as it was."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path = path.parent.resolve() / path.name
    Outputs._count += 1
    tag = f"{os.getpid()}-{Outputs._count}"
    tmp = sibling(path, tag, "tmp")
    with locked(path.parent):
        remove_stale(path)
    ACTIVE.add(tag)
    try:
        tmp.mkdir()
        yield tmp / path.name
        (tmp / path.name).mkdir(exist_ok=True)
        with locked(path.parent):
            switch(path, tmp / path.name, tag)
        os.rmdir(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        ACTIVE.discard(tag)


def _complete(folder: Path, command: str, stage: Path) -> None:
    """Make ``stage`` the whole new ``folder``: this command's manifest, and what of
    ``folder`` is not its previous output carried over as hard links."""
    manifest = f".{command}.outputs"
    names = sorted(p.name for p in stage.iterdir() if p.name != manifest)
    if folder.is_dir():
        os.chmod(stage, stat.S_IMODE(folder.stat().st_mode))
        old = _layout(folder)
        previous = old.outputs.get(command, set()) | _manifest(folder / manifest)
        for name, source in old.entries.items():
            if name not in previous and name not in names and name != manifest:
                _carry(source, stage / name)
        for other, outputs in old.outputs.items():
            if other != command and not (stage / f".{other}.outputs").exists():
                write_text(stage / f".{other}.outputs", json.dumps(sorted(outputs)) + "\n")
    write_text(stage / manifest, json.dumps(names) + "\n")


class _Layout:
    """What of a folder carries over (``entries``: name -> source) and the outputs of each
    command that used the links of earlier versions (``outputs``)."""

    def __init__(self) -> None:
        self.entries: dict[str, Path] = {}
        self.outputs: dict[str, set[str]] = {}


_OUR_LINK = re.compile(r"\.(?P<command>[^/]+)@current/[^/]+")
#: What earlier versions kept in an output folder besides the outputs (generations, current
#: links, staging folders) and the temporary files of interrupted writes: not carried over.
_EARLIER = re.compile(r"\..+@(current|\d+-\d+)|\.staging-.*|\..*\.tmp")


def _layout(folder: Path) -> _Layout:
    layout = _Layout()
    for path in sorted(folder.iterdir()):
        name = path.name
        if _EARLIER.fullmatch(name):
            continue               # earlier versions' generations and links; temporaries
        if path.is_symlink():
            match = _OUR_LINK.fullmatch(os.readlink(path))
            if match:              # an output of an earlier version: a plain file now
                if path.exists():
                    layout.entries[name] = path.resolve()
                    layout.outputs.setdefault(match["command"], set()).add(name)
                continue
        layout.entries[name] = path
    return layout


def _manifest(path: Path) -> set[str]:
    """The names listed by a command's manifest (``.<command>.outputs``), if any."""
    try:
        names = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return set()
    if not isinstance(names, list):
        return set()
    return {n for n in names if isinstance(n, str) and "/" not in n and n not in ("", ".", "..")}


def _link(source: str | Path, target: str | Path) -> None:
    """``target`` as a hard link of ``source``; a copy where the file system has none."""
    try:
        os.link(source, target)
    except OSError:
        shutil.copy2(source, target)


def _carry(source: Path, target: Path) -> None:
    """``source`` (a file, folder or symbolic link) at ``target`` without copying data."""
    if source.is_symlink():
        os.symlink(os.readlink(source), target)
    elif source.is_dir():
        shutil.copytree(source, target, symlinks=True, copy_function=_link)
    elif source.is_file():
        _link(source, target)


