"""Real walking pairs (ETH "hotel", UCY "zara01" and "students03"): two people the data sets'
authors annotated as walking together, the reference a robot companion is measured against.

The files ship inside the package, in ``companion/data/walking_pairs`` (its README.md gives
their format and credit): per scene ``obsmat.txt`` (``frame ped_id pos_x pos_z pos_y v_x v_z
v_y``, one row per person every 0.4 s) and ``groups.txt`` (the ids of each group, one group per
line). A pair is a group of exactly two people, over the frames both are annotated in, both
walking (:data:`MIN_SPEED`). Every scene has its own frame.

Any result computed on these data must carry the credit in :data:`CREDIT`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.errors import DataError
from companion.io import parse_number

#: The copy of the data shipped with the package, with its README and credit.
PACKAGED_DIR = Path(__file__).with_name("walking_pairs")
#: Scene -> frames per second of its annotation (time = frame / rate).
SCENES = {"hotel": 15.0, "zara01": 25.0, "students03": 25.0}
#: A pair walks when both of its people's mean speeds over their shared frames exceed this
#: (m/s), as in the data's README.
MIN_SPEED = 0.5
#: The columns of obsmat.txt.
OBSMAT_COLUMNS = ("frame", "ped_id", "pos_x", "pos_z", "pos_y", "v_x", "v_z", "v_y")
#: Fewest shared samples of a pair (the smoothing of a track needs 5).
MIN_SAMPLES = 5

CREDIT = """\
Walking pairs from the ETH and UCY data sets, as distributed by the crowdbotp/OpenTraj \
repository (commit 97ec1d5e):
- ETH BIWI Walking Pedestrians: S. Pellegrini, A. Ess, K. Schindler, L. Van Gool, "You'll \
never walk alone: modeling social behavior for multi-target tracking", ICCV 2009.
- UCY Crowds by Example: A. Lerner, Y. Chrysanthou, D. Lischinski, "Crowds by example", \
Computer Graphics Forum 2007.
For research use; cite them.
"""


@dataclass(frozen=True, eq=False)
class Pair:
    """Two people walking together over the frames they share: times (s, as in the file)
    and positions (m) of ``a`` and of ``b``."""

    scene: str
    a: int
    b: int
    t: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    bx: np.ndarray
    by: np.ndarray

    @property
    def name(self) -> str:
        return f"{self.scene}/{self.a}+{self.b}"

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def speeds(self) -> tuple[float, float]:
        """The mean speeds (m/s) of ``a`` and ``b``: path length over duration."""
        def speed(x: np.ndarray, y: np.ndarray) -> float:
            return float(np.sum(np.hypot(np.diff(x), np.diff(y)))) / self.duration
        return speed(self.ax, self.ay), speed(self.bx, self.by)


def read_positions(path: Path) -> dict[int, dict[int, tuple[float, float]]]:
    """``obsmat.txt``: person id -> frame -> (x, y).

    Raises
    ------
    DataError
        Naming the file and line of a row that is not 8 finite numbers, or of a person
        annotated twice in one frame.
    """
    out: dict[int, dict[int, tuple[float, float]]] = {}
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read: {exc}") from None
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        cells = line.split()
        if len(cells) != 8:
            raise DataError(f"{path}:{n}: expected 8 numbers (frame ped_id pos_x pos_z pos_y "
                            f"v_x v_z v_y), got {len(cells)}")
        frame, ped, x, _, y = (parse_number(f"{path}:{n}", col, c) for col, c
                               in zip(OBSMAT_COLUMNS, cells[:5]))
        if frame != int(frame) or ped != int(ped):
            raise DataError(f"{path}:{n}: frame and ped_id must be whole numbers")
        track = out.setdefault(int(ped), {})
        if int(frame) in track:
            raise DataError(f"{path}:{n}: person {int(ped)} twice in frame {int(frame)}")
        track[int(frame)] = (x, y)
    return out


def read_groups(path: Path) -> list[tuple[int, ...]]:
    """``groups.txt``: the ids of each group.

    Raises
    ------
    DataError
        Naming the file and line of an id that is not a whole number.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read: {exc}") from None
    groups = []
    for n, line in enumerate(text.splitlines(), 1):
        ids = []
        for cell in line.split():
            value = parse_number(f"{path}:{n}", "ped_id", cell)
            if value != int(value):
                raise DataError(f"{path}:{n}: expected whole ped_ids, got {cell!r}")
            ids.append(int(value))
        if ids:
            groups.append(tuple(ids))
    return groups


def scene_pairs(folder: Path, scene: str, rate: float) -> list[Pair]:
    """The walking pairs of ``scene`` in ``folder``, in the order of its groups file."""
    positions = read_positions(folder / scene / "obsmat.txt")
    pairs = []
    for group in read_groups(folder / scene / "groups.txt"):
        if len(group) != 2 or not all(p in positions for p in group):
            continue
        a, b = group
        frames = sorted(set(positions[a]) & set(positions[b]))
        if len(frames) < MIN_SAMPLES:
            continue
        pa = np.array([positions[a][f] for f in frames])
        pb = np.array([positions[b][f] for f in frames])
        pair = Pair(scene, a, b, np.array(frames, dtype=float) / rate,
                    pa[:, 0], pa[:, 1], pb[:, 0], pb[:, 1])
        if min(pair.speeds()) > MIN_SPEED:
            pairs.append(pair)
    return pairs


def load_pairs(folder: Path | None = None) -> list[Pair]:
    """Every walking pair of the shipped scenes (or of a copy of the files in ``folder``).

    Raises
    ------
    DataError
        If a file is missing or malformed (naming it and the line).
    """
    folder = PACKAGED_DIR if folder is None else Path(folder)
    out = []
    for scene, rate in SCENES.items():
        for name in ("obsmat.txt", "groups.txt"):
            if not (folder / scene / name).is_file():
                raise DataError(f"{folder / scene / name}: no such file (the walking pairs' "
                                f"{name})")
        out += scene_pairs(folder, scene, rate)
    return out
