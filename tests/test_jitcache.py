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


def test_lane_kernels_compile_and_the_solver_is_marked(monkeypatch, tmp_path):
    """compile_solve_lanes and compile_sda run their kernels and mark them (a marked kernel
    starts no helper); lqr_lanes.compile_kernels runs the other lane kernels."""
    from companion import fastlqr
    from companion.control import lqr_lanes

    monkeypatch.setattr(_jitcache, "cache_dir", lambda: tmp_path)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    for name, function, kernel in ((fastlqr.SOLVE_LANES_KERNELS, "compile_solve_lanes",
                                    fastlqr.solve_lanes),
                                   (fastlqr.SDA_KERNELS, "compile_sda", fastlqr.sda_nb)):
        assert _jitcache.active() and not _jitcache.is_compiled(name)
        getattr(fastlqr, function)()
        assert kernel.signatures and _jitcache.is_compiled(name)
        assert _jitcache.compile_in_helper(name, "companion.fastlqr", function) is None
    lqr_lanes.compile_kernels()
    for kernel in (lqr_lanes._prepare, lqr_lanes._check, lqr_lanes._control):
        assert kernel.signatures, kernel
    _jitcache.wait_helper(None)


def test_a_helper_process_marks_its_kernels(monkeypatch, tmp_path):
    """The helper runs in a fresh interpreter that caches in the same directory."""
    cache = tmp_path / _jitcache.source_digest()
    cache.mkdir()
    monkeypatch.setattr(_jitcache, "cache_dir", lambda: cache)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    helper = _jitcache.compile_in_helper("probe", "companion._jitcache", "_probe")
    assert helper is not None
    _jitcache.wait_helper(helper)
    assert helper.returncode == 0 and _jitcache.is_compiled("probe")


def test_no_helper_where_this_process_does_not_cache_there(monkeypatch, tmp_path):
    monkeypatch.setattr(_jitcache, "cache_dir", lambda: tmp_path / "elsewhere")
    assert _jitcache.compile_in_helper("probe", "companion._jitcache", "_probe") is None


def test_step_kernels_compile_and_are_marked(monkeypatch, tmp_path):
    from companion.control import lqr

    monkeypatch.setattr(_jitcache, "cache_dir", lambda: tmp_path)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    lqr.compile_step_kernels()
    assert _jitcache.is_compiled(lqr.STEP_KERNELS)
    assert lqr.lqr_prepare_nb.signatures and lqr.lqr_output_nb.signatures


def test_a_helper_that_takes_too_long_is_stopped():
    import subprocess
    import sys

    slow = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    _jitcache.wait_helper(slow, timeout=0.5)
    assert slow.returncode is not None and slow.returncode != 0
    _jitcache.stop_helper(slow)            # already ended: nothing to do
    _jitcache.stop_helper(None)
