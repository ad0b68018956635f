"""A Foxglove 3D scene of a run, as ``foxglove_msgs/msg/SceneUpdate`` messages in the bag.

Foxglove's SceneUpdate schema exists in several encodings; foxglove-sdk's Python package ships
the protobuf one, but a rosbag2 bag holds CDR messages with ``ros2msg`` schemas only (rosbags
writes no other schema encoding), so the scene is written in the schema's ROS 2 edition,
the ``foxglove_msgs`` package, which Foxglove draws without set-up. The definitions below
declare the fields of that package (tests check every field name against foxglove-sdk's
schema). docs/recording.md.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from typing import Any

from rosbags.typesys import get_types_from_msg

from companion.ros.convert import ABSOLUTE, TimeBase, point, pose_msg
from companion.ros.messages import make, typestore
from companion.types import Circle, Obstacle, PersonEstimate, PersonState, Pose

_COLOR = "float64 r\nfloat64 g\nfloat64 b\nfloat64 a"
_POSED = "geometry_msgs/Pose pose\n"
#: The foxglove_msgs definitions companion writes (field names as in Foxglove's schemas).
DEFINITIONS = {
    "Color": _COLOR,
    "KeyValuePair": "string key\nstring value",
    "ArrowPrimitive": _POSED + "float64 shaft_length\nfloat64 shaft_diameter\n"
                      "float64 head_length\nfloat64 head_diameter\nfoxglove_msgs/Color color",
    "CubePrimitive": _POSED + "geometry_msgs/Vector3 size\nfoxglove_msgs/Color color",
    "SpherePrimitive": _POSED + "geometry_msgs/Vector3 size\nfoxglove_msgs/Color color",
    "CylinderPrimitive": _POSED + "geometry_msgs/Vector3 size\nfloat64 bottom_scale\n"
                         "float64 top_scale\nfoxglove_msgs/Color color",
    "LinePrimitive": "uint8 LINE_STRIP=0\nuint8 LINE_LOOP=1\nuint8 LINE_LIST=2\nuint8 type\n"
                     + _POSED + "float64 thickness\nbool scale_invariant\n"
                     "geometry_msgs/Point[] points\nfoxglove_msgs/Color color\n"
                     "foxglove_msgs/Color[] colors\nuint32[] indices",
    "TriangleListPrimitive": _POSED + "geometry_msgs/Point[] points\n"
                             "foxglove_msgs/Color color\nfoxglove_msgs/Color[] colors\n"
                             "uint32[] indices",
    "TextPrimitive": _POSED + "bool billboard\nfloat64 font_size\nbool scale_invariant\n"
                     "foxglove_msgs/Color color\nstring text",
    "ModelPrimitive": _POSED + "geometry_msgs/Vector3 scale\nfoxglove_msgs/Color color\n"
                      "bool override_color\nstring url\nstring media_type\nuint8[] data",
    "SceneEntityDeletion": "uint8 MATCHING_ID=0\nuint8 ALL=1\n"
                           "builtin_interfaces/Time timestamp\nuint8 type\nstring id",
    "SceneEntity": "builtin_interfaces/Time timestamp\nstring frame_id\nstring id\n"
                   "builtin_interfaces/Duration lifetime\nbool frame_locked\n"
                   "foxglove_msgs/KeyValuePair[] metadata\n"
                   "foxglove_msgs/ArrowPrimitive[] arrows\nfoxglove_msgs/CubePrimitive[] cubes\n"
                   "foxglove_msgs/SpherePrimitive[] spheres\n"
                   "foxglove_msgs/CylinderPrimitive[] cylinders\n"
                   "foxglove_msgs/LinePrimitive[] lines\n"
                   "foxglove_msgs/TriangleListPrimitive[] triangles\n"
                   "foxglove_msgs/TextPrimitive[] texts\nfoxglove_msgs/ModelPrimitive[] models",
    "SceneUpdate": "foxglove_msgs/SceneEntityDeletion[] deletions\n"
                   "foxglove_msgs/SceneEntity[] entities",
}
SCENE_TYPE = "foxglove_msgs/msg/SceneUpdate"
SCENE_TOPIC = "/companion/scene"


def scene_types(distro: str) -> Any:
    """The typestore of ``distro`` with the foxglove_msgs types added (once)."""
    ts = typestore(distro)
    if SCENE_TYPE not in ts.fielddefs:
        types = {}
        for name, text in DEFINITIONS.items():
            types.update(get_types_from_msg(text, f"foxglove_msgs/msg/{name}"))
        ts.register(types)
    return ts


_RGBA = {"robot": (0.55, 0.55, 0.6, 0.9), "heading": (0.1, 0.1, 0.1, 1.0),
         "person": (0.1, 0.4, 1.0, 0.9), "estimate": (1.0, 0.55, 0.0, 0.9),
         "slot": (0.1, 0.8, 0.2, 0.8), "obstacle": (0.9, 0.2, 0.1, 0.9),
         "influence": (0.9, 0.6, 0.1, 0.2), "robot_path": (0.3, 0.3, 0.35, 1.0),
         "person_path": (0.1, 0.4, 1.0, 1.0)}


def _color(name: str) -> Any:
    r, g, b, a = _RGBA[name]
    return make("foxglove_msgs/msg/Color", r=r, g=g, b=b, a=a)


def _vec(x: float, y: float, z: float) -> Any:
    return make("geometry_msgs/msg/Vector3", x=x, y=y, z=z)


def _cylinder(x: float, y: float, diameter: float, height: float, color: str) -> Any:
    return make("foxglove_msgs/msg/CylinderPrimitive", pose=pose_msg(x, y, 0.0, 0.5 * height),
                size=_vec(diameter, diameter, height), bottom_scale=1.0, top_scale=1.0,
                color=_color(color))


def _arrow(pose: Pose, length: float, color: str, z: float = 0.3) -> Any:
    return make("foxglove_msgs/msg/ArrowPrimitive", pose=pose_msg(pose.x, pose.y, pose.theta, z),
                shaft_length=0.7 * length, shaft_diameter=0.05, head_length=0.3 * length,
                head_diameter=0.12, color=_color(color))


def _line(points: Sequence[tuple[float, float]], color: str, width: float = 0.03) -> Any:
    return make("foxglove_msgs/msg/LinePrimitive", type=0, pose=pose_msg(0.0, 0.0, 0.0),
                thickness=width, points=[point(x, y, 0.01) for x, y in points],
                color=_color(color))


def _entity(t: float, frame: str, name: str, tb: TimeBase = ABSOLUTE, **primitives: Any) -> Any:
    return make("foxglove_msgs/msg/SceneEntity", timestamp=tb.stamp(t), frame_id=frame,
                id=name, **primitives)


class Scene:
    """The scene of one run: call :meth:`update` every period; it gives a SceneUpdate every
    ``period`` s (None in between): the robot's footprint (radius ``radius``, m) and heading,
    the true person and the estimate (arrows along their headings), the desired slot, the
    obstacles with their influence range (pairs of obstacle and range, m) and the paths of
    the last ``history`` s (points every ``spacing`` s)."""

    def __init__(self, frame: str, radius: float, period: float = 0.1, history: float = 30.0,
                 spacing: float = 0.2):
        self.frame, self.radius, self.period = frame, radius, period
        self.spacing = spacing
        keep = max(2, int(history / spacing) + 1)
        self.paths: dict[str, deque[tuple[float, float]]] = {
            name: deque(maxlen=keep) for name in ("robot_path", "person_path")}
        self._next = -math.inf
        self._next_point = -math.inf

    def update(self, t: float, robot: Pose, person: PersonState | None,
               estimate: PersonEstimate | None, slot: tuple[float, float] | None,
               obstacles: Sequence[tuple[Obstacle, float]], tb: TimeBase = ABSOLUTE
               ) -> Any | None:
        """The update at ``t`` (s since ``tb``'s origin), or None between updates."""
        if t >= self._next_point - 1e-9 and math.isfinite(robot.x):
            self._next_point = t + self.spacing
            self.paths["robot_path"].append((robot.x, robot.y))
            truth = person or (estimate.walker if estimate is not None else None)
            if truth is not None:
                self.paths["person_path"].append((truth.x, truth.y))
        if t < self._next - 1e-9:
            return None
        self._next = t + self.period
        f = self.frame
        entities = []
        if math.isfinite(robot.x):
            entities.append(_entity(t, f, "robot", tb, cylinders=[
                _cylinder(robot.x, robot.y, 2 * self.radius, 0.3, "robot")],
                arrows=[_arrow(robot, 1.2 * self.radius + 0.2, "heading", 0.35)]))
        if person is not None:
            entities.append(_entity(t, f, "person", tb, cylinders=[
                _cylinder(person.x, person.y, 0.4, 1.7, "person")],
                arrows=[_arrow(Pose(person.x, person.y, person.theta), 0.6, "person", 1.8)]))
        if estimate is not None:
            w = estimate.walker
            entities.append(_entity(t, f, "person_estimate", tb, arrows=[
                _arrow(Pose(w.x, w.y, w.theta), 0.6, "estimate", 0.05)]))
        if slot is not None:
            entities.append(_entity(t, f, "slot", tb, cylinders=[
                _cylinder(*slot, 0.3, 0.05, "slot")]))
        prims: dict[str, list] = {"cylinders": [], "lines": []}
        for ob, reach in obstacles:
            if isinstance(ob, Circle):
                prims["cylinders"] += [_cylinder(ob.x, ob.y, 2 * ob.radius, 1.0, "obstacle"),
                                       _cylinder(ob.x, ob.y, 2 * (ob.radius + reach), 0.02,
                                                 "influence")]
            else:
                prims["lines"] += [_line([(ob.x0, ob.y0), (ob.x1, ob.y1)], "obstacle", 0.1),
                                   _line([(ob.x0, ob.y0), (ob.x1, ob.y1)], "influence",
                                         2 * reach)]
        entities.append(_entity(t, f, "obstacles", tb, **prims))
        entities.append(_entity(t, f, "paths", tb, lines=[
            _line(list(p), name) for name, p in self.paths.items() if len(p) > 1]))
        return make(SCENE_TYPE, entities=entities)


