"""Files in and out: input cells parsed with one-line errors, outputs written whole or not at
all (to a temporary file, then renamed), and a command's outputs replaced together
(:class:`Outputs`)."""

from __future__ import annotations

import csv
import json
import os
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


STAGING = ".staging-"


class Outputs:
    """The outputs of one run of ``command`` in ``folder``, all or nothing.

    ``with Outputs(folder, "run") as stage:`` gives a hidden staging folder inside ``folder``
    to write into. When the block ends normally the staged files replace every file the
    previous run of ``command`` wrote there (a manifest, ``.<command>.outputs``, lists
    them), so the folder never mixes two runs; when it ends with an exception (an error,
    Ctrl-C, SIGTERM) the staging folder is removed and ``folder`` is left as it was.
    Staging folders of processes that no longer exist (killed) are removed on entry.
    """

    def __init__(self, folder: str | Path, command: str):
        self.folder, self.command = Path(folder), command
        self.stage = self.folder / f"{STAGING}{command}-{os.getpid()}"
        self._pid = os.getpid()

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
        manifest = self.folder / f".{self.command}.outputs"
        try:
            old = json.loads(manifest.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            old = []
        new = sorted(p.name for p in self.stage.iterdir())
        for name in old:
            if name not in new and isinstance(name, str) and "/" not in name:
                _remove(self.folder / name)
        for name in new:
            target = self.folder / name
            if target.is_dir() and not target.is_symlink():   # a folder output (a bag)
                old_dir = self.stage.with_name(f"{self.stage.name}-old")
                os.replace(target, old_dir)
                os.replace(self.stage / name, target)
                shutil.rmtree(old_dir, ignore_errors=True)
            else:
                os.replace(self.stage / name, target)
        write_text(manifest, json.dumps(new) + "\n")
        shutil.rmtree(self.stage, ignore_errors=True)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def remove_stale(folder: Path) -> None:
    """Remove the staging folders and temporary files in ``folder`` that processes which no
    longer exist left behind."""
    for path in folder.glob(f"{STAGING}*"):
        pid = path.name.rsplit("-", 1)[-1]
        if not (pid.isdigit() and _alive(int(pid))):
            shutil.rmtree(path, ignore_errors=True)
    for path in folder.glob(".*.tmp"):
        path.unlink(missing_ok=True)


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
