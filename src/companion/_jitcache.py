"""Where numba keeps the compiled code of this package, keyed by the package's sources.

numba checks a cached function against its own source file only. A compiled function that
calls compiled functions of another module (``companion.control.lqr_lanes`` calls
``companion.fastlqr``) would keep running the old callees after that other module changed
(a ``git pull`` that touches only ``fastlqr.py``), which can crash. So the cache lives in a
directory named after a hash of every source file of the package: any change starts a fresh
cache. The base directory is ``NUMBA_CACHE_DIR`` if set, else the user's cache directory
(``$XDG_CACHE_HOME`` or ``~/.cache``) under ``companion/numba``. If it cannot be created,
numba's default (``__pycache__`` beside the sources) is left in place.

numba has one cache setting per process: importing companion sets ``NUMBA_CACHE_DIR`` (and
numba's config) for the whole process and its children, so other numba code in the same
process caches there too.
"""

from __future__ import annotations

import functools
import hashlib
import os
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent


def source_digest(root: Path = PACKAGE) -> str:
    """SHA-1 (12 hex digits) of the paths and contents of every ``.py`` file under ``root``."""
    h = hashlib.sha1()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:12]


@functools.lru_cache(maxsize=1)
def _package_digest() -> str:
    """:func:`source_digest` of the package, once per process (the code a process runs is
    the code it imported)."""
    return source_digest()


def cache_dir() -> Path:
    """The cache directory for the current sources (see the module docstring). A
    ``NUMBA_CACHE_DIR`` that already ends in the digest (set by :func:`install` in a parent
    process) is used as it is."""
    digest = _package_digest()
    base = Path(os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "companion", "numba"))
    return base if base.name == digest else base / digest


def install() -> None:
    """Point numba's cache at :func:`cache_dir` (before any compiled function is defined)."""
    path = cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError:
        return
    os.environ["NUMBA_CACHE_DIR"] = str(path)
    import numba.core.config

    numba.core.config.CACHE_DIR = str(path)


# -- compiling in a helper process -----------------------------------------------------------
# numba compiles in one thread. On a first call with an empty cache, a second process can
# compile one set of kernels into the shared cache while this one compiles another; this
# process then loads the helper's kernels from the cache instead of compiling them.


def active() -> bool:
    """Whether this process caches in :func:`cache_dir` (:func:`install` succeeded)."""
    return os.environ.get("NUMBA_CACHE_DIR") == str(cache_dir())


def _marker(name: str) -> Path:
    return cache_dir() / f"{name}.compiled"


def is_compiled(name: str) -> bool:
    """Whether the kernels called ``name`` are in the cache (see :func:`mark_compiled`)."""
    return _marker(name).exists()


def mark_compiled(name: str) -> None:
    """Record that the kernels called ``name`` are in the cache."""
    try:
        _marker(name).write_bytes(b"")
    except OSError:
        pass


def compile_in_helper(name: str, module: str, function: str, nice: int = 0
                      ) -> subprocess.Popen | None:
    """Start ``module.function()`` in a helper Python process, which compiles the kernels
    called ``name`` into the cache while this process goes on; :func:`wait_helper` before the
    first call of any of them, so that this process loads them instead of compiling them too.

    ``nice`` > 0 lowers the helper's scheduling priority (``os.nice``, where the system has
    it), so that it takes the CPU time the other compilations leave.

    Returns None (nothing to wait for) where that would not help: this process does not cache
    in :func:`cache_dir`, the kernels are already cached, or the process cannot start.
    """
    if not active() or is_compiled(name):
        return None
    try:
        lower = f"import os; hasattr(os, 'nice') and os.nice({int(nice)}); " if nice > 0 else ""
        return subprocess.Popen([sys.executable, "-c",
                                 f"{lower}import {module}; {module}.{function}()"],
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
    except OSError:
        return None


#: Longest wait for a helper (s); a helper that takes longer is stopped (compiling all the
#: package's kernels takes ~20 s on the project's machine).
HELPER_TIMEOUT = 120.0


def wait_helper(helper: subprocess.Popen | None, timeout: float = HELPER_TIMEOUT) -> None:
    """Wait for a process of :func:`compile_in_helper`, at most ``timeout`` seconds (a helper
    that failed or was stopped costs nothing but time: the kernels are then compiled here at
    their first call)."""
    if helper is None:
        return
    try:
        helper.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        stop_helper(helper)


def stop_helper(helper: subprocess.Popen | None) -> None:
    """Stop a process of :func:`compile_in_helper` if it still runs (when the work that
    needed its kernels was abandoned)."""
    if helper is not None and helper.poll() is None:
        helper.kill()
        helper.wait()


def _probe() -> None:
    """A helper's job that compiles nothing: marks ``probe`` (tests/test_jitcache.py)."""
    mark_compiled("probe")
