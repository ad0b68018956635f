"""A transform tree from /tf and /tf_static, looked up at a stamp as tf2 does.

Each frame has one parent (the last transform received for it says which). Static transforms
hold at every time; dynamic ones are kept for ``cache_s`` and interpolated between the two
samples around the stamp (translation linearly, rotation by slerp, scipy's ``Slerp``); a stamp
after the newest sample of an edge is not yet known (``future``: the caller may wait for it),
one before the oldest is lost (``past``), and frames without a chain between them are
``unconnected``. Transforms are 3D (a camera's optical frame is tilted); the node uses the
planar part of what they give. Pure data, no transport.
"""

from __future__ import annotations

import bisect
import threading
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

#: A chain deeper than this is a loop in the tree (a frame that is its own ancestor).
MAX_DEPTH = 64


@dataclass(frozen=True)
class Transform:
    """A rigid transform: ``p_parent = rotation.apply(p_child) + translation`` (m)."""

    rotation: Rotation
    translation: np.ndarray

    def apply(self, points: np.ndarray) -> np.ndarray:
        return self.rotation.apply(points) + self.translation

    def then(self, inner: Transform) -> Transform:
        """``self`` after ``inner``: points of ``inner``'s child into ``self``'s parent."""
        return Transform(self.rotation * inner.rotation,
                         self.rotation.apply(inner.translation) + self.translation)

    def inverse(self) -> Transform:
        inv = self.rotation.inv()
        return Transform(inv, -inv.apply(self.translation))

    @property
    def yaw(self) -> float:
        """The heading of the child's x axis in the parent's xy plane (rad)."""
        x = self.rotation.apply([1.0, 0.0, 0.0])
        return float(np.arctan2(x[1], x[0]))


IDENTITY = Transform(Rotation.identity(), np.zeros(3))


class Lookup(Exception):
    """Why a transform is not available: ``reason`` is ``unconnected``, ``future`` or
    ``past``."""

    def __init__(self, reason: str, detail: str):
        super().__init__(detail)
        self.reason = reason


class _Edge:
    """The samples of one child frame's transform to its parent, in time order."""

    def __init__(self, parent: str, static: bool):
        self.parent, self.static = parent, static
        self.times: list[float] = []
        self.samples: list[Transform] = []

    def add(self, t: float, transform: Transform, keep_from: float) -> None:
        if self.static:
            self.times, self.samples = [t], [transform]
            return
        i = bisect.bisect_right(self.times, t)
        if i and self.times[i - 1] == t:
            self.samples[i - 1] = transform          # the same stamp again: the newer wins
        else:
            self.times.insert(i, t)
            self.samples.insert(i, transform)
        while len(self.times) > 2 and self.times[1] < keep_from:
            del self.times[0], self.samples[0]

    def at(self, t: float, child: str) -> Transform:
        if self.static:
            return self.samples[0]
        times = self.times
        if t > times[-1]:
            raise Lookup("future", f"{self.parent} -> {child} is known up to {times[-1]:.6f} s, "
                                   f"not yet at {t:.6f} s")
        if t < times[0]:
            raise Lookup("past", f"{self.parent} -> {child} is kept from {times[0]:.6f} s, "
                                 f"not at {t:.6f} s")
        i = bisect.bisect_left(times, t)
        if times[i] == t:
            return self.samples[i]
        a, b = self.samples[i - 1], self.samples[i]
        w = (t - times[i - 1]) / (times[i] - times[i - 1])
        slerp = Slerp([0.0, 1.0], Rotation.concatenate([a.rotation, b.rotation]))
        return Transform(slerp([w])[0], (1.0 - w) * a.translation + w * b.translation)


class TransformBuffer:
    """The tree of every transform received; thread-safe (transports call back on their own
    threads)."""

    def __init__(self, cache_s: float = 10.0):
        self.cache_s = cache_s
        self._edges: dict[str, _Edge] = {}
        self._lock = threading.Lock()

    def add(self, parent: str, child: str, t: float, transform: Transform,
            static: bool = False) -> None:
        """A transform of ``child`` in ``parent`` at ``t`` (s); a new parent replaces the old
        one (as tf2 does). Leading slashes of frame names are ignored."""
        parent, child = parent.lstrip("/"), child.lstrip("/")
        if not parent or not child or parent == child:
            return
        with self._lock:
            edge = self._edges.get(child)
            if edge is None or edge.parent != parent or edge.static != static:
                edge = self._edges[child] = _Edge(parent, static)
            edge.add(t, transform, t - self.cache_s)

    def frames(self) -> set[str]:
        with self._lock:
            return set(self._edges) | {e.parent for e in self._edges.values()}

    def lookup(self, target: str, source: str, t: float) -> Transform:
        """The transform taking points of ``source`` into ``target`` at ``t``; raises
        :class:`Lookup` saying why it is not available."""
        target, source = target.lstrip("/"), source.lstrip("/")
        if target == source:
            return IDENTITY
        with self._lock:
            up_source, up_target = self._chain(source), self._chain(target)
            common = next((f for f in up_source if f in up_target), None)
            if common is None:
                raise Lookup("unconnected", f"no chain of transforms between {target} and "
                                            f"{source}")
            to_common = self._compose(up_source[:up_source.index(common)], t)
            from_target = self._compose(up_target[:up_target.index(common)], t)
        return from_target.inverse().then(to_common)

    def _chain(self, frame: str) -> list[str]:
        """``frame`` and its ancestors, root last."""
        out = [frame]
        while out[-1] in self._edges and len(out) <= MAX_DEPTH:
            parent = self._edges[out[-1]].parent
            if parent in out:
                break
            out.append(parent)
        return out

    def _compose(self, frames: list[str], t: float) -> Transform:
        """The transform from the first of ``frames`` to the parent of the last."""
        total = IDENTITY
        for frame in frames:
            total = self._edges[frame].at(t, frame).then(total)
        return total


def from_message(transform_msg) -> Transform:
    """A geometry_msgs/Transform as a :class:`Transform` (a zero quaternion: no rotation)."""
    q = transform_msg.rotation
    quat = np.array([q.x, q.y, q.z, q.w], dtype=float)
    norm = float(np.linalg.norm(quat))
    rotation = Rotation.from_quat(quat / norm) if np.isfinite(norm) and norm > 0.0 \
        else Rotation.identity()
    v = transform_msg.translation
    return Transform(rotation, np.array([v.x, v.y, v.z], dtype=float))
