"""Real pedestrian walking tracks (ETH and UCY data sets) as target persons.

The files ship inside the package, in ``companion/data/eth_ucy`` (its README.md gives their
format and credit; :func:`default_data_dir`). Each scene file has one observation per line,
tab separated: ``frame ped_id x y`` (frames and ids written as floats, x and y in metres); time is
``frame / 25`` s and each pedestrian has one row every 0.4 s. Every scene has its own frame.

Typical use: ``tracks = select_tracks(load_scenes())``;
:func:`companion.evaluate.walkers.evaluate` runs the companion beside them.

Any result computed on these data must carry the credit in :data:`CREDIT`.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.errors import DataError
from companion.io import parse_number

#: Frames per second of the ETH/UCY annotations: time = frame / FRAME_RATE.
FRAME_RATE = 25.0
#: Environment variable that overrides :func:`default_data_dir`.
ENV_VAR = "COMPANION_PEDESTRIANS"
#: The copy of the data shipped with the package (about 1.1 MB, with its README and credit).
PACKAGED_DIR = Path(__file__).with_name("eth_ucy")
#: Scene name -> file inside the data directory.
SCENES = {
    "hotel": Path("hotel", "biwi_hotel.txt"),
    "zara1": Path("zara1", "crowds_zara01.txt"),
    "students003": Path("students003", "students003.txt"),
}

CREDIT = """\
Pedestrian tracks from the ETH and UCY data sets:
- ETH: S. Pellegrini, A. Ess, K. Schindler, L. Van Gool, "You'll never walk alone: modeling \
social behavior for multi-target tracking", ICCV 2009. No license is stated with this data set.
- UCY: A. Lerner, Y. Chrysanthou, D. Lischinski, "Crowds by example", Computer Graphics Forum \
2007. The authors state the data are free for use as long as credit is given to the original \
uploaders.
- The metre-unit text files are the versions distributed with the public Trajectron++ \
repository (StanfordASL/Trajectron-plus-plus, folder experiments/pedestrians/raw/raw/all_data), \
identical to the Social-GAN splits.
"""


@dataclass(frozen=True, eq=False)
class Track:
    """One pedestrian's track: times (s, as in the file) and positions (m), read-only arrays."""

    scene: str
    ped_id: int
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray

    @property
    def duration(self) -> float:
        """Time (s) from the first to the last sample."""
        return float(self.t[-1] - self.t[0])

    @property
    def mean_speed(self) -> float:
        """Length of the sampled path divided by its duration (m/s); 0 for a single sample."""
        if self.duration <= 0.0:
            return 0.0
        return float(np.sum(np.hypot(np.diff(self.x), np.diff(self.y)))) / self.duration


def default_data_dir() -> Path:
    """The pedestrian data directory: ``$COMPANION_PEDESTRIANS`` if set and not empty (a copy
    of the files elsewhere), else the copy shipped with the package (:data:`PACKAGED_DIR`).

    Raises
    ------
    DataError
        If ``COMPANION_PEDESTRIANS`` is set but is not a directory.
    """
    override = os.environ.get(ENV_VAR)
    if override:
        path = Path(override)
        if not path.is_dir():
            raise DataError(f"{ENV_VAR}={override}: not a directory")
        return path
    return PACKAGED_DIR


def load_tracks(path: str | Path, scene: str | None = None) -> dict[int, Track]:
    """Read one ETH/UCY scene file.

    Parameters
    ----------
    path : str or Path
        Tab- (or space-) separated ``frame ped_id x y`` lines; blank lines are skipped. The
        rows of one pedestrian must have strictly increasing frames; gaps are allowed.
    scene : str, optional
        Name stored in each :class:`Track`; default: the file name without extension.

    Returns
    -------
    dict
        Pedestrian id -> :class:`Track`, in order of first appearance.

    Raises
    ------
    DataError
        With a one-line message naming the file and line, e.g.
        ``zara.txt:12: column 'x': expected a number, got 'abc'``.
    """
    name = str(path)
    rows: dict[int, list[tuple[float, float, float]]] = {}
    last_line: dict[int, int] = {}
    try:
        with open(path, encoding="utf-8") as f:
            for line_no, line in enumerate(f, start=1):
                if not line.strip():
                    continue
                frame, ped, x, y = _parse_line(name, line_no, line)
                _check_order(name, line_no, ped, frame, rows.get(ped), last_line.get(ped))
                rows.setdefault(ped, []).append((frame / FRAME_RATE, x, y))
                last_line[ped] = line_no
    except OSError as e:
        raise DataError(f"{name}: cannot read file: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise DataError(f"{name}: not a UTF-8 text file ({e.reason})") from None
    if not rows:
        raise DataError(f"{name}:1: expected lines 'frame ped_id x y', the file is empty")
    scene = Path(path).stem if scene is None else scene
    return {ped: _make_track(scene, ped, samples) for ped, samples in rows.items()}


_COLUMNS = ("frame", "ped_id", "x", "y")


def _parse_line(name: str, line_no: int, line: str) -> tuple[float, int, float, float]:
    cells = line.split()
    if len(cells) != len(_COLUMNS):
        raise DataError(f"{name}:{line_no}: expected 4 values (frame ped_id x y), "
                        f"got {len(cells)}")
    frame, ped, x, y = (parse_number(f"{name}:{line_no}", col, cell)
                        for col, cell in zip(_COLUMNS, cells))
    for col, value in (("frame", frame), ("ped_id", ped)):
        if value != int(value) or value < 0:
            raise DataError(f"{name}:{line_no}: column '{col}': expected a whole number >= 0, "
                            f"got {value:g}")
    return frame, int(ped), x, y


def _check_order(name: str, line_no: int, ped: int, frame: float,
                 previous: list[tuple[float, float, float]] | None,
                 previous_line: int | None) -> None:
    if not previous:
        return
    prev_frame = previous[-1][0] * FRAME_RATE
    if frame <= prev_frame:
        kind = "duplicate" if frame == prev_frame else "unsorted"
        raise DataError(f"{name}:{line_no}: column 'frame': {kind} frame {frame:g} for "
                        f"pedestrian {ped}, expected a frame after {prev_frame:g} "
                        f"(line {previous_line})")


def _make_track(scene: str, ped: int, samples: list[tuple[float, float, float]]) -> Track:
    table = np.array(samples, dtype=float)
    t, x, y = (np.ascontiguousarray(table[:, k]) for k in range(3))
    for a in (t, x, y):
        a.setflags(write=False)
    return Track(scene, ped, t, x, y)


def load_scene(scene: str, data_dir: str | Path | None = None) -> dict[int, Track]:
    """Load the tracks of one scene of :data:`SCENES` from ``data_dir``.

    ``data_dir`` defaults to :func:`default_data_dir`; DataError if it is not found or the
    scene is unknown.
    """
    if scene not in SCENES:
        raise DataError(f"scene: unknown scene {scene!r} (known: {', '.join(SCENES)})")
    return load_tracks(_resolve_dir(data_dir) / SCENES[scene], scene=scene)


def load_scenes(data_dir: str | Path | None = None,
                scenes: Iterable[str] = tuple(SCENES)) -> list[Track]:
    """All tracks of ``scenes`` (default: all of :data:`SCENES`), scene by scene."""
    root = _resolve_dir(data_dir)
    return [track for scene in scenes for track in load_scene(scene, root).values()]


def _resolve_dir(data_dir: str | Path | None) -> Path:
    return Path(data_dir) if data_dir is not None else default_data_dir()


def select_tracks(tracks: Mapping[int, Track] | Iterable[Track], min_mean_speed: float = 0.6,
                  min_duration: float = 15.0) -> list[Track]:
    """Tracks of walking people: ``mean_speed > min_mean_speed`` (m/s) and
    ``duration >= min_duration`` (s), in their original order."""
    items = tracks.values() if isinstance(tracks, Mapping) else tracks
    return [tr for tr in items
            if tr.mean_speed > min_mean_speed and tr.duration >= min_duration]
