"""A real walking pair as an episode: the robot in the human companion's place.

One way round, one person of a :class:`~companion.data.pairs.Pair` is the person the robot
accompanies (a :class:`~companion.sim.recorded.RecordedPerson`, its heading from the same
smoothing as the walking tracks) and the other is the human companion. The slot is where
the companion walked on average in the person's frame (the mean of their offsets, as
distance and bearing); the companion's own RMS deviation about it is the human reference
for the robot's slot error (docs/companions.md).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from companion.data.pairs import Pair
from companion.model import robot_pose_at, slot_reference
from companion.params import Params
from companion.sim.recorded import RecordedPerson
from companion.sim.runner import EpisodeSpec
from companion.types import Log, Pose

#: How far outside the keep-out's person clearance (m) a slot that was inside it is put.
CLEARANCE_MARGIN = 0.01


@dataclass(frozen=True, eq=False)
class Companion:
    """The human companion of a pair, one way round: sample times (s, from the person's
    first sample) and positions (m); the slot (m, rad in [0, 2 pi)) and their RMS deviation
    about it (m); the pair's mean speed (m/s)."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    distance: float
    bearing: float
    deviation: float
    speed: float

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The companion's position at times ``t`` (linear between samples, held outside)."""
        return np.interp(t, self.t, self.x), np.interp(t, self.t, self.y)


class PairedPerson(RecordedPerson):
    """A recorded person walking with a human :attr:`companion` (:func:`paired`)."""

    companion: Companion


def offsets(person: RecordedPerson, t: np.ndarray, x: np.ndarray, y: np.ndarray
            ) -> np.ndarray:
    """The points ``(x, y)`` at times ``t`` in the person's frame (forward, left), one row
    each."""
    states = [person.state(float(ti)) for ti in t]
    th = np.array([s.theta for s in states])
    dx = x - np.array([s.x for s in states])
    dy = y - np.array([s.y for s in states])
    c, s = np.cos(th), np.sin(th)
    return np.column_stack((c * dx + s * dy, -s * dx + c * dy))


def paired(pair: Pair, flipped: bool = False) -> PairedPerson:
    """``pair``'s ``a`` as the person and ``b`` as the companion (``flipped``: the other way
    round)."""
    px, py, cx, cy = (pair.bx, pair.by, pair.ax, pair.ay) if flipped else \
        (pair.ax, pair.ay, pair.bx, pair.by)
    person = PairedPerson(pair.t, px, py)
    t = pair.t - pair.t[0]
    rel = offsets(person, t, cx, cy)
    mean = rel.mean(axis=0)
    deviation = float(np.sqrt(np.mean(np.sum((rel - mean) ** 2, axis=1))))
    person.companion = Companion(t, np.asarray(cx, float), np.asarray(cy, float),
                                 float(np.hypot(*mean)),
                                 math.atan2(mean[1], mean[0]) % (2.0 * math.pi), deviation,
                                 float(np.mean(pair.speeds())))
    return person


def closest_distance(bearing: float, clearance: float, d: float) -> float:
    """The smallest slot distance at ``bearing`` that keeps the robot centre (``d`` behind
    the reference point, heading with the person) ``clearance`` from the person."""
    return d * math.cos(bearing) + math.sqrt(max(clearance ** 2 - (d * math.sin(bearing)) ** 2,
                                                 0.0))


def nearest_slot(distance: float, bearing: float, params: Params) -> float:
    """``distance`` at ``bearing``, or the closest distance the keep-out lets the robot hold
    there (its person clearance and protective distance, plus :data:`CLEARANCE_MARGIN`)."""
    k = params.keepout
    keep = max(k.person_clearance, k.protective_distance) + CLEARANCE_MARGIN
    return max(distance, closest_distance(bearing, keep, params.robot.d))


def pair_params(person: PairedPerson, params: Params) -> Params:
    """``params`` with the formation at the companion's slot (moved out where the keep-out
    would not let the robot hold it: :func:`nearest_slot`)."""
    c = person.companion
    return params.replace(formation=dataclasses.replace(
        params.formation, distance=nearest_slot(c.distance, c.bearing, params),
        bearing=c.bearing))


def pair_episode(person: PairedPerson, params: Params, controller: str = "lqr",
                 seed: int = 0) -> EpisodeSpec:
    """The robot in the companion's place: ``params`` as :func:`pair_params` makes them, the
    robot starting where the companion was (no nearer the person than the slot's distance
    allows), heading and moving with the person, for the pair's duration."""
    params = pair_params(person, params)
    c, h0 = person.companion, person.state(0.0)
    rel = offsets(person, c.t[:1], c.x[:1], c.y[:1])[0]
    bearing = math.atan2(rel[1], rel[0]) % (2.0 * math.pi)
    rho = nearest_slot(float(np.hypot(*rel)), bearing, params)
    pose = Pose(*robot_pose_at(rho, bearing, 0.0, h0.x, h0.y, h0.theta, params.robot.d))
    f = params.formation
    ref = slot_reference(h0.v, h0.omega, f.distance, f.bearing, params.robot.d)
    return EpisodeSpec(controller, person, params, person.duration, start=pose, seed=seed,
                       start_velocity=(ref.v, ref.omega))


def pair_row(person: PairedPerson, params: Params, log: Log) -> dict[str, float]:
    """The numbers of an episode beside a walking pair: the human companion's own RMS
    deviation about the slot, the robot's RMS distance from where the companion walked
    (reference point against the companion, over the steps of the recording), the slot
    held, how far it was moved out (:func:`nearest_slot`) and the pair's mean speed."""
    c = person.companion
    t = log["t"]
    inside = t <= c.t[-1]
    th = log["robot_theta"][inside]
    rx = log["robot_x"][inside] + params.robot.d * np.cos(th)
    ry = log["robot_y"][inside] + params.robot.d * np.sin(th)
    cx, cy = c.at(t[inside])
    gap = np.hypot(rx - cx, ry - cy)
    return {"human_deviation_m": c.deviation,
            "companion_distance_m": float(np.sqrt(np.mean(gap ** 2))) if len(gap) else math.nan,
            "slot_distance_m": params.formation.distance,
            "slot_bearing_rad": params.formation.bearing,
            "slot_moved_m": params.formation.distance - c.distance,
            "pair_speed_mps": c.speed}
