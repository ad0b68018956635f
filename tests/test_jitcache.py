"""The numba cache is keyed by the package's sources (companion._jitcache)."""

import os
import shutil

import numba.core.config

from companion import _jitcache


def test_cache_is_in_a_directory_named_after_the_sources():
    assert os.environ["NUMBA_CACHE_DIR"] == str(_jitcache.cache_dir())
    assert numba.core.config.CACHE_DIR == os.environ["NUMBA_CACHE_DIR"]
    assert _jitcache.cache_dir().name == _jitcache.source_digest()


def test_any_source_change_gives_a_new_digest(tmp_path):
    copy = tmp_path / "companion"
    shutil.copytree(_jitcache.PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    before = _jitcache.source_digest(copy)
    assert before == _jitcache.source_digest(_jitcache.PACKAGE)
    kernel = copy / "fastlqr.py"
    kernel.write_text(kernel.read_text() + "\n# changed\n")
    assert _jitcache.source_digest(copy) != before
