"""Files in and out: input cells parsed with one-line errors, outputs written whole or not at
all (to a temporary file, then renamed), and a command's outputs switched together in one
rename (:class:`Outputs`)."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from companion.errors import DataError

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
    """The outputs of one run of ``command`` in ``folder``, all or nothing, switched in one step.

    ``with Outputs(folder, "run") as stage:`` gives a new hidden folder inside ``folder`` (a
    generation, ``.run@<pid>-<n>``) to write into. When the block ends normally every output
    name appears in ``folder`` as a symbolic link through ``.run@current`` (``log.csv ->
    .run@current/log.csv``), and ``.run@current`` is re-pointed from the previous generation
    to the new one by a single rename: a reader sees the previous run's set or the new one,
    never a mix, whenever the process is killed. Names the previous run wrote and this one did
    not are removed, and so is the previous generation. When the block ends with an exception
    (an error, Ctrl-C, SIGTERM) the generation is removed and ``folder`` is left as it was.
    What a killed process left behind (a generation that never became current, links to
    names the current run lacks) is removed on the next entry.
    """

    _count = 0

    def __init__(self, folder: str | Path, command: str):
        self.folder, self.command = Path(folder), command
        self._pid = os.getpid()
        Outputs._count += 1
        self.stage = self.folder / f".{command}{MARK}{self._pid}-{Outputs._count}"

    def __enter__(self) -> Path:
        self.folder.mkdir(parents=True, exist_ok=True)
        remove_stale(self.folder)
        shutil.rmtree(self.stage, ignore_errors=True)
        self.stage.mkdir()
        return self.stage

    def __exit__(self, kind, value, trace) -> None:
        if os.getpid() != self._pid:        # a forked worker leaving: not its outputs
            return
        if kind is not None:
            shutil.rmtree(self.stage, ignore_errors=True)
            return
        switch(self.folder, self.command, self.stage)


#: Separates a command's name from its generation in the hidden folders of :class:`Outputs`.
MARK = "@"
CURRENT = "current"
_OUR_LINK = re.compile(rf"\.[^/]+{MARK}{CURRENT}/[^/]+")


def current_link(folder: Path, command: str) -> Path:
    """The link that names the current generation of ``command``'s outputs in ``folder``."""
    return folder / f".{command}{MARK}{CURRENT}"


def switch(folder: Path, command: str, generation: Path) -> None:
    """Make ``generation`` (a folder inside ``folder``) the current outputs of ``command``: link
    each of its names, re-point the current link by one rename, then remove what the previous
    generation had alone (see :class:`Outputs`)."""
    link = current_link(folder, command)
    previous = _generation(link)
    old = set() if previous is None else {p.name for p in previous.iterdir()}
    old |= _legacy_names(folder, command)
    new = sorted(p.name for p in generation.iterdir())
    for name in new:
        _place_link(folder / name, f"{link.name}/{name}", folder, command)
    tmp = folder / f".{command}{MARK}{os.getpid()}.link.tmp"
    tmp.unlink(missing_ok=True)
    os.symlink(generation.name, tmp)
    os.replace(tmp, link)                    # the one step from the old set to the new one
    for name in sorted(old - set(new)):
        if _links_into(folder / name, link.name) or name in _legacy_names(folder, command):
            _remove(folder / name)
    (folder / f".{command}.outputs").unlink(missing_ok=True)
    if previous is not None and previous.resolve() != generation.resolve():
        shutil.rmtree(previous, ignore_errors=True)


def _generation(link: Path) -> Path | None:
    """The generation folder ``link`` points to, or None."""
    if not link.is_symlink():
        return None
    target = link.parent / os.readlink(link)
    return target if target.is_dir() else None


def _links_into(path: Path, link_name: str) -> bool:
    return path.is_symlink() and os.readlink(path).startswith(f"{link_name}/")


def _legacy_names(folder: Path, command: str) -> set[str]:
    """Names listed by the manifest of earlier versions (``.<command>.outputs``), whose
    outputs were plain files."""
    try:
        names = json.loads((folder / f".{command}.outputs").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return set()
    return {n for n in names if isinstance(n, str) and "/" not in n and n not in ("", ".", "..")}


def _place_link(path: Path, target: str, folder: Path, command: str) -> None:
    """``path`` as a link to ``target`` (nothing to do if it is one already); a plain file or
    folder in its place (an earlier version's output, or another command's) is replaced."""
    if path.is_symlink() and os.readlink(path) == target:
        return
    if path.is_dir() and not path.is_symlink():
        aside = folder / f".{command}{MARK}{os.getpid()}.old.tmp"
        shutil.rmtree(aside, ignore_errors=True)
        os.replace(path, aside)
        shutil.rmtree(aside, ignore_errors=True)
    tmp = folder / f".{path.name}.{os.getpid()}.link.tmp"
    tmp.unlink(missing_ok=True)
    os.symlink(target, tmp)
    os.replace(tmp, path)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def remove_stale(folder: Path) -> None:
    """Remove what processes that no longer exist left in ``folder``: generations that never
    became current, links to names their current generation lacks, temporary files, and the
    staging folders of earlier versions."""
    current = {p.resolve() for p in folder.glob(f".*{MARK}{CURRENT}") if p.is_symlink()}
    for path in folder.glob(f".*{MARK}*"):
        owner = path.name.rsplit(MARK, 1)[-1].split("-", 1)[0].split(".", 1)[0]
        if path.name.endswith(f"{MARK}{CURRENT}") or not owner.isdigit():
            continue
        if not _alive(int(owner)) and path.resolve() not in current:
            _remove(path)
    for path in folder.iterdir():
        if path.is_symlink() and not path.exists() and _OUR_LINK.fullmatch(os.readlink(path)):
            path.unlink(missing_ok=True)      # into a current generation that lacks it
    for path in [*folder.glob(".staging-*"), *folder.glob(".*.tmp")]:
        _remove(path)


def leftovers(folder: Path) -> list[str]:
    """Hidden entries of ``folder`` other than the current links of :class:`Outputs` and their
    generations (what an interrupted write leaves; none after a finished or failed one)."""
    if not folder.is_dir():
        return []
    links = [p for p in folder.glob(f".*{MARK}{CURRENT}") if p.is_symlink()]
    keep = {p.name for p in links} | {os.readlink(p) for p in links}
    return sorted(p.name for p in folder.iterdir()
                  if p.name.startswith(".") and p.name not in keep)


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return False                          # an earlier run of this very process
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
