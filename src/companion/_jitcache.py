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

import hashlib
import os
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent


def source_digest(root: Path = PACKAGE) -> str:
    """SHA-1 (12 hex digits) of the paths and contents of every ``.py`` file under ``root``."""
    h = hashlib.sha1()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:12]


def cache_dir() -> Path:
    """The cache directory for the current sources (see the module docstring). A
    ``NUMBA_CACHE_DIR`` that already ends in the digest (set by :func:`install` in a parent
    process) is used as it is."""
    digest = source_digest()
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
