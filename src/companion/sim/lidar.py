"""A simulated planar (2D) LiDAR: exact, vectorised ray casting against the world's obstacles.

One ray per beam from the robot's pose, intersected in closed form with every circle, wall
segment (zero thickness, its ends rounded off by circles of :data:`WALL_END` m: a real wall's
end face, which a zero-thickness end would hide from a robot in line with the wall) and the
person's body (a circle); the nearest hit is the range.
Beam angles are in the robot frame, increasing and centred on the heading (a full circle has
an even number of beams from -pi, none at +pi). Ranges are ``inf`` where nothing is hit within
``range_max`` and 0 for a ray starting inside a circle; NaN never comes out of :func:`cast`
(it marks invalid returns in fault tests).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np

from companion.geometry import TWO_PI, circle_clearance, wall_clearance
from companion.params import LidarParams
from companion.types import Circle, Pose, Scan, Wall

_FULL_CIRCLE_TOL = 1e-9
#: Radius (m) of the rounded end of every wall the LiDAR sees.
WALL_END = 0.05


@functools.lru_cache(maxsize=16)
def _beams(fov: float, resolution: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Beam angles (robot frame) and their cosines and sines, read-only and cached."""
    if fov >= TWO_PI - _FULL_CIRCLE_TOL:
        n = max(2, 2 * round(math.pi / resolution))
        angles = -math.pi + np.arange(n) * (TWO_PI / n)
    else:
        m = int(math.floor(0.5 * fov / resolution + 1e-9))
        angles = np.arange(-m, m + 1) * resolution
    out = (angles, np.cos(angles), np.sin(angles))
    for a in out:
        a.flags.writeable = False
    return out


def beam_angles(params: LidarParams) -> np.ndarray:
    """The beam angles of a scan with ``params`` (rad, robot frame; a new array)."""
    return _beams(params.fov, params.resolution)[0].copy()


def _ray_circles(ox: float, oy: float, dirs: np.ndarray,
                 cx: np.ndarray, cy: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Nearest hit distance of each ray with the circles (inf if none), shape (n,).

    ``dirs`` (n, 2) holds the rays' world-frame unit directions, all starting at (ox, oy).
    """
    fx, fy = ox - cx, oy - cy                       # (m,) circle centre -> ray origin
    c = fx * fx + fy * fy - r * r                   # (m,) > 0 iff the origin is outside
    if (c <= 0.0).any():                            # origin inside (or on) a circle:
        return np.zeros(len(dirs))                  # every ray hits it at once
    b = dirs @ np.stack((fx, fy))                   # (n, m) half the linear coefficient
    disc = b * b
    disc -= c                                       # roots t = -b +- sqrt(disc)
    hit = disc >= 0.0
    hit &= b < 0.0                                  # ahead of the origin, not behind
    np.sqrt(disc, out=disc, where=hit)
    disc -= b
    # near root in the cancellation-free form t = c / (-b + sqrt(disc))  (t1 * t2 = c)
    t = np.divide(np.broadcast_to(c, b.shape), disc, out=np.full(b.shape, np.inf), where=hit)
    return t.min(axis=1)


def _ray_segments(ox: float, oy: float, dirs: np.ndarray,
                  x0: np.ndarray, y0: np.ndarray, ex: np.ndarray, ey: np.ndarray) -> np.ndarray:
    """Nearest hit distance of each ray with the segments (inf if none), shape (n,).

    Solves ``o + t d = p0 + s e`` by cross products: ``t = (w x e) / (d x e)``,
    ``s = (w x d) / (d x e)`` with ``w = p0 - o``; a hit needs ``t >= 0`` and ``0 <= s <= 1``.
    """
    wx, wy = x0 - ox, y0 - oy                       # (k,) ray origin -> segment start
    denom = dirs @ np.stack((ey, -ex))              # (n, k) d x e
    w_x_d = dirs @ np.stack((-wy, wx))              # (n, k) w x d = distance of p0 to ray line
    w_x_e = wx * ey - wy * ex                       # (k,)
    length = np.hypot(ex, ey)
    parallel = np.abs(denom) <= 1e-12 * np.maximum(length, 1e-300)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = w_x_e / denom
        s = w_x_d / denom
    hit = ~parallel
    hit &= t >= 0.0
    hit &= s >= 0.0
    hit &= s <= 1.0
    t[~hit] = np.inf
    # a ray running along its own segment's line: the nearest end ahead, or 0 if on it
    collinear = parallel & (np.abs(w_x_d) <= 1e-9)
    if collinear.any():
        t0 = dirs @ np.stack((wx, wy))
        t1 = dirs @ np.stack((wx + ex, wy + ey))
        tc = np.where(t0 * t1 <= 0.0, 0.0,
                      np.where(np.minimum(t0, t1) > 0.0, np.minimum(t0, t1), np.inf))
        t = np.where(collinear, tc, t)
    return t.min(axis=1)


def wall_ends(walls: Sequence[Wall]) -> list[Circle]:
    """The rounded ends the LiDAR sees of ``walls``: a circle of :data:`WALL_END` m at each."""
    return [Circle(x, y, WALL_END) for w in walls for x, y in ((w.x0, w.y0), (w.x1, w.y1))]


def cast(pose: Pose, circles: Sequence[Circle], walls: Sequence[Wall],
         person: tuple[float, float] | None, params: LidarParams,
         rng: np.random.Generator | None = None) -> Scan:
    """Cast one scan from ``pose`` against the circles, walls and the person.

    Parameters
    ----------
    pose : Pose
        Sensor pose (anything with ``x``, ``y``, ``theta``); rays start at (x, y).
    circles, walls : sequence of Circle, sequence of Wall
        Static obstacles in world coordinates.
    person : (float, float) or None
        The person's position; seen as a circle of radius ``params.person_radius``.
    params : LidarParams
        Sensor geometry and noise.
    rng : numpy.random.Generator or None
        Source of the range noise; ``None`` (or ``noise_std == 0``) gives exact ranges.

    Returns
    -------
    Scan
        Nearest hit per beam (``inf`` beyond ``range_max``, 0 if the ray starts inside a
        circle), with Gaussian noise N(0, noise_std) added to finite ranges, clipped at 0.
    """
    angles, ca, sa = _beams(params.fov, params.resolution)
    ox, oy, th = float(pose.x), float(pose.y), float(pose.theta)
    ct, st = math.cos(th), math.sin(th)
    dirs = np.column_stack((ca * ct - sa * st, sa * ct + ca * st))  # world-frame unit vectors
    ranges = np.full(angles.shape, np.inf)

    circles = [*circles, *wall_ends(walls)]
    cx = [c.x for c in circles]
    cy = [c.y for c in circles]
    cr = [c.radius for c in circles]
    if person is not None:
        cx.append(person[0])
        cy.append(person[1])
        cr.append(params.person_radius)
    if cx:
        cx_, cy_, cr_ = (np.asarray(v, float) for v in (cx, cy, cr))
        near = np.array([circle_clearance(ox, oy, x, y, r) <= params.range_max  # cull
                         for x, y, r in zip(cx, cy, cr)])
        if near.any():
            ranges = np.minimum(ranges, _ray_circles(ox, oy, dirs, cx_[near], cy_[near],
                                                     cr_[near]))
    if walls:
        near = [w for w in walls
                if wall_clearance(ox, oy, w.x0, w.y0, w.x1, w.y1) <= params.range_max]
        if near:
            w = np.array([(s.x0, s.y0, s.x1 - s.x0, s.y1 - s.y0) for s in near], float)
            ranges = np.minimum(ranges, _ray_segments(ox, oy, dirs, w[:, 0], w[:, 1],
                                                      w[:, 2], w[:, 3]))

    ranges[ranges > params.range_max] = np.inf
    if rng is not None and params.noise_std > 0.0:   # one draw per beam, hit or not, so
        noise = rng.normal(0.0, params.noise_std, len(ranges))   # the noise is the beam's
        hit = np.isfinite(ranges)
        ranges[hit] = np.maximum(ranges[hit] + noise[hit], 0.0)
    return Scan(angles=angles.copy(), ranges=ranges, x=ox, y=oy, theta=th,
                range_max=params.range_max)


def scan_points(scan: Scan) -> np.ndarray:
    """World coordinates of the scan's finite returns, shape (k, 2), in beam order."""
    ranges = np.asarray(scan.ranges, float)
    ok = np.isfinite(ranges)
    r = ranges[ok]
    a = np.asarray(scan.angles, float)[ok] + scan.theta
    return np.column_stack((scan.x + r * np.cos(a), scan.y + r * np.sin(a)))
