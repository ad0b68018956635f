"""``--bag DIR`` of ``companion run``, ``sim-robot`` and ``node``: the folder checked first, the
bag built beside it and put into place whole (docs/recording.md)."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import nullcontext
from pathlib import Path

from companion.apps.args import UsageError, output_dir
from companion.io import atomic_folder, unswitchable


def bag_arg(value: str | None) -> Path | None:
    """The ``--bag DIR`` folder, checked before any work: a new folder or an earlier bag
    (replaced whole at the end)."""
    if not value:
        return None
    path = Path(value)
    if path.exists() and not (path.is_dir() and (path / "metadata.yaml").exists()):
        raise UsageError(f"--bag {path}: exists and is not a rosbag2 bag (no metadata.yaml); "
                         f"give a new folder")
    output_dir(path.parent if str(path.parent) else Path("."), replaced=False)
    reason = unswitchable(path) if path.exists() else None
    if reason:
        raise UsageError(f"--bag {path}: {reason}")
    return path


def bag_outputs(path: Path | None):
    """A context giving the path beside ``path`` to write the bag at (None without
    ``--bag``); the bag, a plain folder, appears at ``path`` only when the block ends
    normally (:func:`~companion.io.atomic_folder`)."""
    return nullcontext(None) if path is None else atomic_folder(path)


def run_recorded(sc, bag: Path, reached: Callable[[float], None] | None = None):
    """``companion run --bag``: the scenario's run recorded as a bag (docs/recording.md);
    ``reached(t)`` as the run goes."""
    from companion.ros.record import record_run, run_config

    spec = sc.episode()
    if spec.obstacles and spec.obstacle_source != "lidar":
        print("note: with --bag the controller sees the obstacles through the simulated LiDAR "
              "(as the ROS 2 node does)", flush=True)
    with bag_outputs(bag) as staged:
        log = record_run(spec, run_config(spec, sc.controller), staged, reached)
    if reached is not None:
        reached(spec.duration)
    return log
