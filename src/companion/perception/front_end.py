"""The robot-side perception front end: the same code whether the inputs come from the
simulator or from the ROS 2 node (docs/sensing.md, "The front end").

It takes stamped raw inputs, one :class:`Source` per sensor, each with its own stamp
handling and timeout, as Nav2's collision monitor has one source per sensor:

- :class:`OdometrySource`: the robot poses of the last seconds; :func:`pose_at` places
  anything stamped (a detection in the robot's frame, a scan) at its stamp, interpolated
  between the poses around it (one rule, the node's placement uses it too);
- :class:`ScanSource`: a LiDAR scan is used once, when its stamp is newer than the last
  one; its obstacles (:func:`~companion.perception.extract_obstacles`, moving ones tracked
  by :class:`~companion.perception.MovingTracker`) are held until the next scan, at most
  ``lidar.timeout_s``. The returns near the person are left out only while the tracker has
  a confirmed estimate (:func:`person_cutout`): a lost person, or detections the tracker
  refused, hide nothing;
- :class:`PeopleSource`: other people's detections (the person tracker's gate kept them
  out) as moving obstacles.

A new sensor is one more source.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from typing import NamedTuple

from companion.geometry import unicycle_step, wrap_pi
from companion.params import Params
from companion.perception.extract import extract_obstacles
from companion.perception.movers import MovingTracker
from companion.types import Circle, Obstacle, PersonDetection, PersonEstimate, Pose, Scan


class OdometrySample(NamedTuple):
    """One odometry sample: time (s), the robot pose in the tracking frame, its velocity
    ``(v, omega)`` in the robot frame."""

    t: float
    pose: Pose
    velocity: tuple[float, float]


#: How far (s) :func:`pose_at` moves a pose on with its velocity beyond the samples.
EXTRAPOLATE_S = 0.5


def pose_at(samples: Sequence[OdometrySample], t: float) -> Pose | None:
    """The robot pose at time ``t``: interpolated between the samples around it (in time
    order), or moved on from the nearest end with its velocity (at most
    :data:`EXTRAPOLATE_S`); None without samples."""
    if not samples:
        return None
    if t <= samples[0].t or t >= samples[-1].t:
        s = samples[0] if t <= samples[0].t else samples[-1]
        x, y, th = unicycle_step(s.pose.x, s.pose.y, s.pose.theta, *s.velocity,
                                 max(-EXTRAPOLATE_S, min(t - s.t, EXTRAPOLATE_S)))
        return Pose(x, y, wrap_pi(th))
    lo, hi = 0, len(samples) - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if samples[mid].t <= t else (lo, mid)
    a, b = samples[lo], samples[hi]
    w = (t - a.t) / (b.t - a.t) if b.t > a.t else 0.0
    dth = wrap_pi(b.pose.theta - a.pose.theta)
    return Pose(a.pose.x + w * (b.pose.x - a.pose.x), a.pose.y + w * (b.pose.y - a.pose.y),
                wrap_pi(a.pose.theta + w * dth))


def person_cutout(estimate: PersonEstimate | None) -> tuple[float, float] | None:
    """Where the LiDAR's returns belong to the person: the tracker's estimate, which exists
    only for a confirmed track seen within ``tracker.lost_after_s``; None (nothing left out)
    while the person is lost or being re-acquired."""
    if estimate is None:
        return None
    return estimate.state.x, estimate.state.y


class Source:
    """Stamp handling shared by the sources: an input is new when its stamp is later than the
    last one taken; the source is stale once ``timeout_s`` has passed since then."""

    def __init__(self, timeout_s: float = math.inf):
        self.timeout_s = timeout_s
        self.reset()

    def reset(self) -> None:
        self.stamp = -math.inf

    def take(self, t: float) -> bool:
        """Whether an input stamped ``t`` is new (and remember it)."""
        if not t > self.stamp:
            return False
        self.stamp = t
        return True

    def stale(self, now: float) -> bool:
        return now - self.stamp > self.timeout_s


class OdometrySource(Source):
    """The valid robot poses of the last ``horizon_s`` seconds, for :func:`pose_at`."""

    def __init__(self, horizon_s: float):
        self.horizon_s = horizon_s
        super().__init__()

    def reset(self) -> None:
        super().reset()
        self.samples: deque[OdometrySample] = deque()

    def add(self, t: float, pose: Pose, velocity: tuple[float, float] | None) -> None:
        samples = self.samples
        if math.isfinite(pose.x) and math.isfinite(pose.y) and math.isfinite(pose.theta) \
                and self.take(t):
            v = velocity if velocity is not None and math.isfinite(velocity[0]) \
                and math.isfinite(velocity[1]) else (0.0, 0.0)
            samples.append(OdometrySample(t, pose, v))
        oldest = t - self.horizon_s
        while samples and samples[0].t < oldest:
            samples.popleft()

    def pose_at(self, t: float) -> Pose:
        """The robot pose at ``t`` (NaN without a valid one: what is placed by it is
        refused)."""
        return pose_at(self.samples, t) or Pose(math.nan, math.nan, math.nan)


class ScanSource(Source):
    """LiDAR scans -> the obstacles of the newest one, held until the next, at most
    ``timeout_s`` (see the module docstring)."""

    def __init__(self, params: Params):
        self.params = params
        self.movers = MovingTracker(params.movers)
        super().__init__(params.lidar.timeout_s)

    def reset(self) -> None:
        super().reset()
        self.movers.reset()
        self.held: tuple[Circle, ...] = ()
        self._last: Scan | None = None

    def update(self, scan: Scan | None, estimate: PersonEstimate | None, now: float
               ) -> tuple[Circle, ...]:
        """The obstacles known from the scans at ``now``; ``scan`` is used if it is new (by
        its stamp, or a scan without one by identity)."""
        if scan is not None and scan is not self._last:
            t = now if math.isnan(scan.t) else scan.t
            self._last = scan
            if self.take(t):
                found = extract_obstacles(scan, person_cutout(estimate), self.params.extractor)
                self.held = self.movers.update(found, t)
        if self.stale(now):
            self.held = ()
        return self.held


class PeopleSource(Source):
    """Other people's detections (in the tracking frame) as moving circles."""

    def __init__(self, params: Params):
        self.radius = params.movers.person_radius
        self.movers = MovingTracker(params.movers)
        super().__init__()

    def reset(self) -> None:
        super().reset()
        self.movers.reset()

    def update(self, detections: Sequence[PersonDetection]) -> None:
        if not detections:
            return
        for t in sorted({d.t for d in detections}):
            if self.take(t):
                self.movers.update([Circle(d.x, d.y, self.radius)
                                    for d in detections if d.t == t], t)

    def circles(self, now: float) -> tuple[Circle, ...]:
        return self.movers.circles(now)


class FrontEnd:
    """The sources of one robot (see the module docstring)."""

    def __init__(self, params: Params):
        self.odometry = OdometrySource(params.tracker.max_delay_s + 1.0)
        self.scans = ScanSource(params)
        self.people = PeopleSource(params)

    def reset(self) -> None:
        self.odometry.reset()
        self.scans.reset()
        self.people.reset()

    def obstacles(self, known: Sequence[Obstacle], scan: Scan | None,
                  estimate: PersonEstimate | None, now: float) -> tuple[Obstacle, ...]:
        """The obstacles at ``now``: ``known`` ones (a map, the simulator's exact ones), the
        LiDAR's, then the other people."""
        return (*known, *self.scans.update(scan, estimate, now), *self.people.circles(now))
