"""numba in one place: the two decorators the package uses and where compiled code is cached.

* :func:`jitable`: a plain Python function that compiled kernels may call; Python callers
  get the plain function (``numba.extending.register_jitable``).
* :func:`kernel`: the compiled version of a plain function, ``njit(cache=True)`` with
  ``error_model="numpy"`` (a division by zero gives inf/nan instead of raising).

So every compiled kernel is compiled from the same Python source that tests run directly.

Every kernel that Python calls is registered (:data:`KERNELS`) with an example call: small
arguments of the types the package passes. :func:`warm_up` loads (or compiles) them all, so
that a process can compile before its first control period (``companion node``) or before
forking workers that inherit the kernels. Kernels register themselves when their module is
imported (this module imports nothing of the package): importing :mod:`companion.control`
registers every kernel of the stack (control, tracking, riccati, geometry).

numba checks a cached kernel against its own source file only, and a kernel inlines the
jitable functions of other modules, so a change to those would leave a stale kernel. The
cache therefore lives in a directory named after a hash of every source file of the package
(docs/performance.md): ``$NUMBA_CACHE_DIR`` if set, else ``__pycache__/numba/<hash>`` inside
the package (caches of other sources untouched for an hour are removed), else (package not
writable) the system's temporary directory. Importing companion sets numba's cache directory
for the whole process and its children.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import hashlib
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

PACKAGE = Path(__file__).resolve().parent
_JIT_OPTIONS = {"cache": True, "error_model": "numpy"}


def jitable(func):
    """Mark a plain function as callable from compiled kernels; returns it unchanged."""
    from numba.extending import register_jitable  # numba only where kernels are defined

    return register_jitable(**_JIT_OPTIONS)(func)


#: Every compiled kernel that Python calls, by ``module.function``: the dispatcher and a
#: function giving the arguments of an example call (:func:`register`).
KERNELS: dict[str, tuple[Any, Callable[[], tuple]]] = {}


def kernel(func, example: Callable[[], tuple]):
    """``func`` compiled with numba (cached, numpy error model), registered with ``example``
    (:func:`register`); ``func`` stays as it is."""
    from numba import njit

    return register(njit(**_JIT_OPTIONS)(func), example)


def register(dispatcher, example: Callable[[], tuple]):
    """Register the compiled ``dispatcher`` for :func:`warm_up`; ``example()`` gives the
    arguments of one call, small and of the types the package calls it with (an argument of
    another type would compile another version). Returns ``dispatcher``."""
    func = dispatcher.py_func
    KERNELS[f"{func.__module__}.{func.__name__}"] = (dispatcher, example)
    return dispatcher


def warm_up() -> None:
    """Load (or compile) every registered kernel now, under :func:`compile_lock`: each is
    called once with its example. Only the kernels of modules imported so far are registered
    (import :mod:`companion.control` first for the whole stack)."""
    with compile_lock():
        for dispatcher, example in list(KERNELS.values()):
            dispatcher(*example())


def cold() -> bool:
    """No kernel of these sources is in the cache yet: the first run compiles them all."""
    return not any(cache_dir().rglob("*.nbi"))


def source_digest(root: Path = PACKAGE) -> str:
    """SHA-1 (12 hex digits) of the paths and contents of every ``.py`` file under ``root``."""
    h = hashlib.sha1()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:12]


@functools.lru_cache(maxsize=1)
def _package_digest() -> str:
    return source_digest()


def _writable(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".write-test"
        probe.write_bytes(b"")
        probe.unlink()
        return True
    except OSError:
        return False


def cache_dir() -> Path:
    """The cache directory for the current sources (see the module docstring); a
    ``NUMBA_CACHE_DIR`` that already ends in the digest (set by a parent process) is kept."""
    digest = _package_digest()
    base = os.environ.get("NUMBA_CACHE_DIR")
    if base:
        return Path(base) if Path(base).name == digest else Path(base) / digest
    local = PACKAGE / "__pycache__" / "numba"
    if _writable(local):
        return local / digest
    return Path(tempfile.gettempdir()) / f"companion-numba-{os.getuid()}" / digest


#: Caches of other sources untouched for this long (s) are removed (a process still running
#: older sources keeps its cache meanwhile).
STALE_AFTER = 3600.0


def prune(path: Path) -> None:
    """Remove stale caches of other sources beside ``path`` in the package's own folder."""
    if path.parent != PACKAGE / "__pycache__" / "numba":
        return
    for old in path.parent.iterdir():
        if old != path and old.is_dir() and time.time() - old.stat().st_mtime > STALE_AFTER:
            shutil.rmtree(old, ignore_errors=True)


def install() -> None:
    """Point numba's cache at :func:`cache_dir` (before any kernel is defined)."""
    path = cache_dir()
    if not _writable(path):
        return
    prune(path)
    os.environ["NUMBA_CACHE_DIR"] = str(path)   # numba reads it when it is imported
    if "numba" in sys.modules:
        import numba.core.config

        numba.core.config.CACHE_DIR = str(path)


@contextlib.contextmanager
def compile_lock() -> Iterator[None]:
    """Hold an exclusive lock on the cache directory while the kernels are first loaded or
    compiled: two processes started together (``companion node`` and ``companion sim-robot``)
    would otherwise compile the same kernel at once, and numba can fail saving it ("no
    compiled object yet"). The second process then loads what the first saved."""
    path = Path(os.environ.get("NUMBA_CACHE_DIR") or cache_dir())
    try:
        path.mkdir(parents=True, exist_ok=True)
        fh = open(path / ".compile.lock", "a+b")
    except OSError:              # an unwritable cache: numba does not save, nothing to guard
        yield
        return
    with fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)
