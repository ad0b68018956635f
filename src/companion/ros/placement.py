"""Where an input measured in some frame at some stamp lies in the odometry frame.

A detection or a scan in frame F at stamp t is placed, in this order (docs/ros2.md):

1. F is ``ros.odom_frame``: as it is; F is ``ros.base_frame``: the odometry pose at t (the
   node's robot pose comes from /odom, even where /tf carries it too);
2. the transform tree (/tf, /tf_static) links F to ``ros.base_frame`` at t: that transform
   after the odometry pose at t;
3. the tree links F to ``ros.odom_frame`` at t (a camera fixed in the world);
4. F is ``ros.lidar_frame``: the odometry pose after ``ros.lidar_mount`` (for robots
   without tf);
5. else it cannot be placed (the tracker's reason ``detection_frame``).

A transform the tree knows, but not yet at t (it arrives later than the input), makes the
input wait (:data:`WAIT`), at most ``ros.tf_wait_s``. The odometry pose at t is interpolated
between the samples around t (or moved on from the nearest with its velocity, at most
0.5 s: :func:`companion.perception.front_end.pose_at`, the rule the whole stack uses).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from companion.perception.front_end import OdometrySample, pose_at
from companion.ros.settings import RosParams
from companion.ros.tf import Lookup, Transform, TransformBuffer
from companion.types import PersonDetection, Pose

#: The input's transform is known, but not yet at its stamp: try again at the next period.
WAIT = "wait"


def planar(pose: Pose) -> Transform:
    """A planar pose as a 3D transform (rotation about z)."""
    return Transform(Rotation.from_euler("z", pose.theta),
                     np.array([pose.x, pose.y, 0.0]))


def flat(transform: Transform) -> Pose:
    """The planar part of a transform: its origin's x, y and its x axis' heading."""
    return Pose(float(transform.translation[0]), float(transform.translation[1]),
                transform.yaw)


class Placer:
    """Places inputs in ``ros.odom_frame`` (see the module docstring); ``tf`` None: without a
    transform tree (steps 1, 4, 5)."""

    def __init__(self, ros: RosParams, tf: TransformBuffer | None):
        self.ros, self.tf = ros, tf

    def frame(self, frame: str, t: float, samples: deque[OdometrySample]
              ) -> Transform | str | None:
        """The transform of ``frame`` into the odometry frame at ``t``; :data:`WAIT` while the
        tree does not know it at ``t`` yet; None if it cannot be placed."""
        r = self.ros
        frame = frame.lstrip("/")
        if frame == r.odom_frame:
            return planar(Pose(0.0, 0.0, 0.0))
        robot = pose_at(samples, t)
        if frame == r.base_frame:           # the odometry's own frame: its pose, not /tf's
            return None if robot is None else planar(robot)
        waiting = False
        if self.tf is not None:
            for target, before in ((r.base_frame, robot), (r.odom_frame, Pose(0.0, 0.0, 0.0))):
                if before is None:
                    continue
                try:
                    return planar(before).then(self.tf.lookup(target, frame, t))
                except Lookup as exc:
                    waiting |= exc.reason == "future"
        if waiting:
            return WAIT
        if robot is None:
            return None
        if frame == r.lidar_frame:
            return planar(robot).then(planar(Pose(*r.lidar_mount)))
        return None

    def odometry(self, sample: OdometrySample, frame: str, child: str
                 ) -> OdometrySample | str:
        """An odometry sample of ``child`` in ``frame`` as the pose of ``ros.base_frame`` in
        ``ros.odom_frame``, through the tree where the frames differ (the twist is taken as
        the base's); a line saying what is missing if it cannot be placed."""
        r = self.ros
        frame, child = frame.lstrip("/") or r.odom_frame, child.lstrip("/") or r.base_frame
        if frame == r.odom_frame and child == r.base_frame:
            return sample
        if self.tf is None:
            return (f"odometry of {child} in {frame}, and ros.use_tf is off; expected "
                    f"{r.base_frame} in {r.odom_frame}")
        try:
            pose = planar(sample.pose)
            if frame != r.odom_frame:
                pose = self.tf.lookup(r.odom_frame, frame, sample.t).then(pose)
            if child != r.base_frame:
                pose = pose.then(self.tf.lookup(child, r.base_frame, sample.t))
        except Lookup as exc:
            return f"odometry of {child} in {frame}: {exc}"
        return OdometrySample(sample.t, flat(pose), sample.velocity)

    def detection(self, s: PersonDetection, samples: deque[OdometrySample], world: str
                  ) -> PersonDetection | str:
        """``s`` as the tracker takes it, in its ``world`` frame: position, covariance and
        heading rotated into the odometry frame; a detection that cannot be placed keeps its
        frame's name (the tracker rejects it as ``detection_frame``); :data:`WAIT`."""
        where = self.frame(s.frame, s.t, samples)
        if where == WAIT:
            return WAIT
        if where is None:
            return replace(s, frame=s.frame or "(no frame)")
        m = where.rotation.as_matrix()
        x, y, _ = where.apply(np.array([s.x, s.y, s.z]))
        cov = s.covariance
        if cov is not None:        # R C R^T of the xy block (no uncertainty along z)
            c3 = np.zeros((3, 3))
            c3[:2, :2] = np.reshape(cov, (2, 2))
            cov = tuple((m @ c3 @ m.T)[:2, :2].ravel().tolist())
        heading = s.heading
        if heading is not None:
            d = m @ np.array([math.cos(heading), math.sin(heading), 0.0])
            heading = math.atan2(d[1], d[0])
        return replace(s, x=float(x), y=float(y), z=0.0, frame=world, covariance=cov,
                       heading=heading)
