"""A folder replaced whole by another built beside it: the hidden folders of the switch, the
swap itself (one exchange, or two renames), and the recovery of what a killed process left
(the rule is :class:`companion.io.Outputs`')."""

from __future__ import annotations

import errno
import os
import re
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

#: The tags (pid-count) of the switches this process is at work on.
ACTIVE: set[str] = set()

#: The hidden folders of :class:`~companion.io.Outputs` beside an output folder.
_SIBLING = re.compile(r"\.(?P<name>.+)\.companion-(?P<pid>\d+)-\d+\.(?P<kind>tmp|new|old)")


def sibling(folder: Path, tag: str, kind: str) -> Path:
    """The hidden folder beside ``folder`` of the switch ``tag`` (pid-count) in state
    ``kind``: ``tmp`` (being written), ``new`` (complete), ``old`` (the set replaced)."""
    return folder.parent / f".{folder.name}.companion-{tag}.{kind}"


def unswitchable(folder: Path) -> str | None:
    """Why ``folder`` cannot be replaced by a rename (None if it can): the root, a mount
    point, the current folder or one holding it, or a parent that cannot be written."""
    folder = Path(folder).resolve()
    if folder == folder.parent or os.path.ismount(folder):
        return "is a mount point; give a folder inside it"
    cwd = Path.cwd().resolve()
    if cwd == folder or folder in cwd.parents:
        return ("is the current folder or holds it, and the outputs replace the folder whole; "
                "give a folder inside it")
    if not os.access(folder.parent, os.W_OK | os.X_OK):
        return f"cannot write in its parent {folder.parent} (where the new set is built)"
    return None


def switch(folder: Path, stage: Path, tag: str) -> None:
    """Put the complete ``stage`` at ``folder`` (see :class:`~companion.io.Outputs`): renamed
    ``.new``, then swapped with ``folder`` in one step (or two renames), then the old set
    removed."""
    new, old = sibling(folder, tag, "new"), sibling(folder, tag, "old")
    os.replace(stage, new)                 # from here on the new set is complete
    if not folder.exists():
        os.replace(new, folder)
    elif exchange(new, folder):            # the one step from the old set to the new one
        shutil.rmtree(new, ignore_errors=True)
    else:
        os.replace(folder, old)
        os.replace(new, folder)
        shutil.rmtree(old, ignore_errors=True)


def _renameat2() -> Any:
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError, ImportError):
        return None


_RENAMEAT2 = _renameat2()


def exchange(a: Path, b: Path) -> bool:
    """Swap the paths ``a`` and ``b`` atomically (Linux's ``RENAME_EXCHANGE``); False if the
    system or file system cannot (nothing is changed then)."""
    if _RENAMEAT2 is None:
        return False
    at_fdcwd, rename_exchange = -100, 2
    if _RENAMEAT2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    import ctypes
    code = ctypes.get_errno()
    if code in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EPERM):
        return False
    raise OSError(code, os.strerror(code), str(a))


@contextmanager
def locked(folder: Path) -> Iterator[None]:
    """Switches beside each other one at a time (a lock on the parent folder, where the
    system has ``flock``)."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def remove_stale(folder: Path) -> None:
    """Finish or undo what processes that no longer exist left beside ``folder`` (the rule in
    :class:`~companion.io.Outputs`)."""
    found: dict[str, list[Path]] = {"new": [], "old": [], "tmp": []}
    for path in folder.parent.iterdir():
        match = _SIBLING.fullmatch(path.name)
        if match and match["name"] == folder.name and not _alive(path.name):
            found[match["kind"]].append(path)
    for path in [*sorted(found["new"]), *sorted(found["old"])]:
        if _vacant(folder):                # killed between the two renames: finish
            if folder.is_dir():
                folder.rmdir()
            os.replace(path, folder)
        else:
            shutil.rmtree(path, ignore_errors=True)
    for path in found["tmp"]:
        shutil.rmtree(path, ignore_errors=True)


def _vacant(folder: Path) -> bool:
    """No ``folder``, or an empty one (as ``--out`` checks make it before a run)."""
    if not os.path.lexists(folder):
        return True
    return folder.is_dir() and not folder.is_symlink() and not any(folder.iterdir())


def leftovers(folder: Path) -> list[str]:
    """What an interrupted write left: the hidden entries of ``folder`` other than the
    commands' manifests (``.<command>.outputs``), and the hidden folders of a switch beside
    it; none after a finished or failed one."""
    inside = [p.name for p in folder.iterdir() if p.name.startswith(".")
              and not (p.name.endswith(".outputs") and p.is_file())] if folder.is_dir() else []
    beside = [p.name for p in folder.parent.iterdir()
              if (m := _SIBLING.fullmatch(p.name)) and m["name"] == folder.name] \
        if folder.parent.is_dir() else []
    return sorted(inside + beside)


def _alive(name: str) -> bool:
    """Whether the process that made the hidden folder ``name`` is still at work on it."""
    tag = name.split(".companion-")[-1].rsplit(".", 1)[0]
    pid = int(tag.split("-")[0])
    if pid == os.getpid():
        return tag in ACTIVE         # else an earlier run of this very process
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
