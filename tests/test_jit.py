"""Compiled code comes from the plain Python source, cached by the package's sources
(companion._jit)."""

import os
import shutil
import time

import numba.core.config

from companion import _jit
from companion.geometry import unicycle_step, wrap_pi


def test_cache_is_in_a_directory_named_after_the_sources():
    assert os.environ["NUMBA_CACHE_DIR"] == str(_jit.cache_dir())
    assert numba.core.config.CACHE_DIR == os.environ["NUMBA_CACHE_DIR"]
    assert _jit.cache_dir().name == _jit.source_digest()


def test_any_source_change_gives_a_new_digest(tmp_path):
    copy = tmp_path / "companion"
    shutil.copytree(_jit.PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    before = _jit.source_digest(copy)
    assert before == _jit.source_digest(_jit.PACKAGE)
    source = copy / "geometry.py"
    source.write_text(source.read_text() + "\n# changed\n")
    assert _jit.source_digest(copy) != before


def test_default_cache_stays_inside_the_package(monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    assert _jit.cache_dir().parent == _jit.PACKAGE / "__pycache__" / "numba"


def test_prune_removes_only_stale_caches_of_the_package(tmp_path):
    base = _jit.PACKAGE / "__pycache__" / "numba"
    stale, recent = base / "000000000000", base / "000000000001"
    for path in (stale, recent):
        path.mkdir(parents=True, exist_ok=True)
    long_ago = time.time() - 2 * _jit.STALE_AFTER
    os.utime(stale, (long_ago, long_ago))
    _jit.prune(base / _jit.source_digest())
    assert not stale.exists() and recent.exists()   # recent: perhaps still in use
    shutil.rmtree(recent)
    outside = tmp_path / "000000000000"
    outside.mkdir()
    os.utime(outside, (long_ago, long_ago))
    _jit.prune(tmp_path / _jit.source_digest())     # not the package's folder: left alone
    assert outside.exists()


def test_jitable_functions_stay_plain_python_and_compile_the_same():
    assert type(wrap_pi).__name__ == "function"     # no dispatcher in Python callers

    @numba.njit
    def both(a, x, y, th, v, w, dt):
        return wrap_pi(a), unicycle_step(x, y, th, v, w, dt)

    args = (7.5, 1.0, 2.0, 0.3, 1.2, 0.4, 0.05)
    assert both(*args) == (wrap_pi(7.5), unicycle_step(*args[1:]))
