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


def test_every_kernel_python_calls_is_registered_with_its_example():
    """Every compiled function of the package that Python can call is in _jit.KERNELS
    (kernels only called from compiled code have no Python entry)."""
    import sys

    from numba.core.registry import CPUDispatcher

    import companion.control  # the stack: control, tracking, riccati, geometry
    import companion.perception
    import companion.sim.runner  # noqa: F401
    found = {}
    for name, module in list(sys.modules.items()):
        if name == "companion" or name.startswith("companion."):
            for value in vars(module).values():
                if isinstance(value, CPUDispatcher) \
                        and not value.targetoptions.get("no_cpython_wrapper"):
                    func = value.py_func
                    found[f"{func.__module__}.{func.__name__}"] = value
    assert len(found) >= 11
    assert {n: d for n, (d, _) in _jit.KERNELS.items()} == found


_AFTER_WARM_UP = """
import dataclasses, json, sys
import numpy as np
import companion.control
from companion import _jit
_jit.warm_up()
signatures = lambda: {n: {str(s) for s in d.signatures} for n, (d, _) in _jit.KERNELS.items()}
warm = signatures()
loaded = sorted(m for m in sys.modules if m.startswith("companion.sim") or "rvo" in m)
# the stack as an episode and the node run it, and every kernel's other callers
from companion.control.keepout import risk_of
from companion.control.planner import plan_way
from companion.control.stopping import stop_path_target
from companion.geometry import obstacle_arrays, path_clearance
from companion.params import REALISTIC, Params
from companion.riccati import spectral_radius_below
from companion.sim.scenario import load_scenario, run_scenario
from companion.types import Circle, Pose, Wall
sc = load_scenario("fig7")
p = sc.params.replace(sensing=REALISTIC,
                      keepout=dataclasses.replace(sc.params.keepout, collision_risk=0.1))
run_scenario(dataclasses.replace(sc, duration=12.0, params=p), "lqr", "lidar")
obstacles = [Circle(0.6, 0.0, 0.2), Wall(-1.0, 1.0, 3.0, 1.0)]
stop_path_target((1.0, 0.0), Pose(0.0, 0.0, 0.0), (1.0, 0.0), (1.0, 0.0), obstacles, Params())
plan_way((0.0, 0.0), (2.0, 0.0), obstacles, 0.3)
path_clearance(np.array([0.0, 0.1]), np.array([0.0, 0.0]), obstacle_arrays(obstacles), 0.0)
spectral_radius_below(np.array([[0.5, 2.0], [0.0, 0.99995]]), 1.0 - 1e-6)
after = signatures()
print(json.dumps({"cold": sorted(n for n, s in warm.items() if not s), "loaded": loaded,
                  "new": sorted(n for n in after if after[n] - warm[n])}))
"""


def test_warm_up_loads_every_kernel_without_the_simulator_and_nothing_compiles_after():
    """In a new process: after _jit.warm_up() every kernel is loaded, neither the simulator
    nor pyrvo was imported, and an episode with LiDAR obstacles and realistic sensing (the
    stack the node steps), the planner, the stop check, the risk and the clearance of a path
    compile nothing more (each of them compiles at least one kernel in a cold process)."""
    import json
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _AFTER_WARM_UP], capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result == {"cold": [], "loaded": [], "new": []}


def test_a_cache_without_kernels_is_cold(tmp_path, monkeypatch):
    """The CLI says it compiles (about half a minute) exactly when no kernel of these sources
    is cached yet."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert _jit.cold()
    kernel = _jit.cache_dir() / "control_0123" / "lqr.step-1.py311.nbi"
    kernel.parent.mkdir(parents=True)
    kernel.write_bytes(b"")
    assert not _jit.cold()
