"""Obstacle extraction from a 2D LiDAR scan: clusters of returns -> covering circles.

:func:`extract_obstacles` clusters the returns (fixed gap or the adaptive Borges-Aldon
breakpoint; the full-circle seam joined), fits one algebraic (Kasa) circle per cluster when it
is a convex arc, splits other clusters (walls, corners, merged objects) into pieces of at most
``max_segment``, enlarges every circle to cover its returns, and drops circles centred near the
tracked person. Every reported circle contains the returns it was fitted to, so the union
covers the seen surface. docs/model.md, section 9, describes the steps and their limits.
"""

from __future__ import annotations

import math

import numpy as np

from companion.params import ExtractorParams
from companion.types import Circle, Scan

_COVER_EPS = 1e-9  # m added to covering radii so that round-off never leaves a point outside
# m: no planar LiDAR measures farther (long-range ones reach a few hundred metres); a range
# beyond it is a driver's "no return" (FLT_MAX, 1e20), whatever the scan's range_max says
PHYSICAL_RANGE_MAX = 1000.0


def _clusters(scan: Scan, gap: float, breakpoint_angle: float
              ) -> tuple[np.ndarray, list[np.ndarray]]:
    """World points of all beams (NaN where no return) and the index arrays of the clusters."""
    ranges = np.asarray(scan.ranges, float)
    angles = np.asarray(scan.angles, float) + scan.theta
    n = len(ranges)
    valid = np.isfinite(ranges)
    with np.errstate(invalid="ignore"):            # inf * 0 -> NaN for beams without return
        pts = np.column_stack((scan.x + ranges * np.cos(angles),
                               scan.y + ranges * np.sin(angles)))
    if n == 0 or not valid.any():
        return pts, []
    link = valid[:-1] & valid[1:]                  # link[i]: beam i and i+1 in one cluster
    threshold = np.full(n - 1, gap)
    if breakpoint_angle > 0.0 and n >= 2:
        dphi = np.abs(np.diff(angles))
        with np.errstate(invalid="ignore"):
            adaptive = (np.fmax(ranges[:-1], ranges[1:]) * np.sin(dphi)
                        / np.sin(np.maximum(breakpoint_angle - dphi, 1e-12)))
        threshold = np.where(link & (dphi < breakpoint_angle), np.fmax(threshold, adaptive),
                             threshold)
    with np.errstate(invalid="ignore"):
        link &= np.hypot(*(pts[1:] - pts[:-1]).T) <= threshold
    starts = np.flatnonzero(valid & np.concatenate(([True], ~link)))
    ends = np.flatnonzero(valid & np.concatenate((~link, [True])))
    clusters = [np.arange(a, b + 1) for a, b in zip(starts, ends)]
    # full circle: join up the cluster that crosses the seam between the last and first beam
    if n >= 3 and valid[0] and valid[-1]:
        step = angles[1] - angles[0]
        seam = angles[0] + 2.0 * math.pi - angles[-1]
        if seam <= 1.5 * step and math.hypot(*(pts[0] - pts[-1])) <= gap:
            if len(clusters) >= 2:
                clusters[0] = np.concatenate((clusters.pop(), clusters[0]))
            else:                                  # a closed ring: close the polyline too
                clusters[0] = np.concatenate((clusters[0], [0]))
    return pts, clusters


def _fit(pts: np.ndarray, groups: list[np.ndarray], origin: np.ndarray, heading: np.ndarray,
         params: ExtractorParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fit one circle to each group of points, all groups at once (vectorised).

    Parameters
    ----------
    pts : ndarray, shape (n, 2)
        World points of the beams.
    groups : list of ndarray of int
        Indices into ``pts`` of each group (at least one point each).
    origin, heading : ndarray, shape (2,)
        Sensor position and unit heading (the bearing of a group lying on the sensor).
    params : ExtractorParams
        Radius limits and fit tolerance.

    Returns
    -------
    centres : ndarray, shape (g, 2)
    radii : ndarray, shape (g,)
        Covering radii: every point of a group lies inside its circle.
    kasa : ndarray of bool, shape (g,)
        Whether the group's algebraic (Kasa) fit was acceptable, i.e. the group is one circle;
        where it is not, the fallback (half the chord, pushed away from the sensor) is used.
    """
    counts = np.array([len(g) for g in groups])
    offsets = np.concatenate(([0], np.cumsum(counts)[:-1]))
    p = pts[np.concatenate(groups)]
    k = counts.astype(float)
    mean = np.add.reduceat(p, offsets, axis=0) / k[:, None]
    q = p - np.repeat(mean, counts, axis=0)        # centred per group, for conditioning
    qx, qy = q[:, 0], q[:, 1]
    z = qx * qx + qy * qy

    def total(v: np.ndarray) -> np.ndarray:
        return np.add.reduceat(v, offsets)

    # Kasa: minimise sum(|q - c|^2 - s)^2 over c = (a, b), s = r^2 - |c|^2; with centred
    # points the normal equations give s = mean(z) and a 2x2 system for c.
    sxx, sxy, syy = total(qx * qx), total(qx * qy), total(qy * qy)
    vx, vy = total(qx * z), total(qy * z)
    det = sxx * syy - sxy * sxy
    ok = (counts >= 3) & (det > 1e-12 * (sxx + syy) ** 2)  # not (nearly) collinear
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(ok, 0.5 * (syy * vx - sxy * vy) / det, 0.0)
        b = np.where(ok, 0.5 * (sxx * vy - sxy * vx) / det, 0.0)
    r2 = total(z) / k + a * a + b * b
    ok &= np.isfinite(r2) & (r2 > 0.0)
    r = np.sqrt(np.where(ok, r2, 1.0))
    resid = np.hypot(qx - np.repeat(a, counts), qy - np.repeat(b, counts)) - np.repeat(r, counts)
    rms = np.sqrt(total(resid * resid) / k)

    v = mean - origin                              # bearing of each group from the sensor
    dist = np.hypot(v[:, 0], v[:, 1])
    on_top = dist <= 1e-12
    u = np.where(on_top[:, None], heading, v / np.where(on_top, 1.0, dist)[:, None])
    # chord of each group and its normal pointing away from the sensor (bearing if degenerate)
    last = offsets + counts - 1
    chord = p[last] - p[offsets]
    length = np.hypot(chord[:, 0], chord[:, 1])
    degenerate = length <= 1e-9
    normal = np.column_stack((chord[:, 1], -chord[:, 0])) / np.where(degenerate, 1.0,
                                                                      length)[:, None]
    normal *= np.where((normal * u).sum(axis=1) < 0.0, -1.0, 1.0)[:, None]
    normal = np.where(degenerate[:, None], u, normal)
    # how far the group bulges from its chord towards the sensor: a convex arc does, a
    # straight (noisy) piece does not, and a Kasa circle through it would be arbitrary
    toward = -((p - np.repeat(p[offsets], counts, axis=0))
               * np.repeat(normal, counts, axis=0)).sum(axis=1)
    bulge = np.where(degenerate, np.inf, np.maximum.reduceat(toward, offsets))

    centre_k = mean + np.column_stack((a, b))
    kasa = (ok & (r <= params.max_radius) & (rms <= params.fit_tolerance)
            & (bulge >= 2.0 * params.fit_tolerance)                    # an arc, not a line
            & (a * u[:, 0] + b * u[:, 1] > 0.0)                        # far side of the points
            & (np.hypot(*(centre_k - origin).T) > r))                  # sensor outside it

    # fallback: radius half the chord; centre the mean pushed by the radius along the chord's
    # normal pointing away from the sensor
    r_fb = np.clip(0.5 * length, params.min_radius, params.max_radius)
    centres = np.where(kasa[:, None], centre_k, mean + r_fb[:, None] * normal)
    radii = np.where(kasa, np.maximum(r, params.min_radius), r_fb)

    # cover: enlarge to the farthest point of the group
    d = p - np.repeat(centres, counts, axis=0)
    r_cover = np.sqrt(np.maximum.reduceat((d * d).sum(axis=1), offsets))
    radii = np.maximum(radii, r_cover * (1.0 + 1e-12) + _COVER_EPS)
    return centres, radii, kasa


def _pieces(p: np.ndarray, max_segment: float) -> list[tuple[int, int]]:
    """Cut the polyline ``p`` into consecutive pieces of path length <= about max_segment.

    Returns inclusive index ranges ``(first, last)`` of about equal length; neighbouring
    pieces share their boundary point. The length is measured along the polyline smoothed
    with a 5-point moving average, so that range noise does not inflate it much. A single
    step longer than a piece is not cut further (a 2-point piece).
    """
    k = len(p)
    if k >= 5:
        cs = np.cumsum(np.concatenate((p[:1], p[:1], p[:1], p, p[-1:], p[-1:])), axis=0)
        p = (cs[5:] - cs[:-5]) * 0.2               # edge-padded moving average, k points
    cum = np.concatenate(([0.0], np.cumsum(np.hypot(*(p[1:] - p[:-1]).T))))
    n = max(1, math.ceil(cum[-1] / max_segment))
    if n == 1:
        return [(0, k - 1)]
    bounds = np.searchsorted(cum, np.arange(1, n) * (cum[-1] / n), side="right") - 1
    cuts = sorted({0, k - 1, *(int(x) for x in bounds)})
    return list(zip(cuts[:-1], cuts[1:]))


def checked_scan(scan: object, range_max: float = math.inf) -> Scan | None:
    """``scan`` read the way a LaserScan driver means it, or None if it is not a valid scan.

    Invalid: angles and ranges that are not 1-D arrays of numbers of the same length, an
    angle or the sensor pose not finite. Per beam: above the sensor's ``range_max`` (or
    ``range_max`` given here when the scan's is not finite), and always above
    :data:`PHYSICAL_RANGE_MAX` (1 km; FLT_MAX and 1e20 included), is ``inf``, "no return";
    NaN or a finite range below ``range_min`` is NaN, an invalid beam; ``-inf`` stays
    "closer than the sensor can measure" (ROS REP 117).
    """
    try:
        angles = np.asarray(scan.angles, dtype=float)
        ranges = np.array(scan.ranges, dtype=float)
        pose = (float(scan.x), float(scan.y), float(scan.theta))
        low = float(getattr(scan, "range_min", 0.0))
        high = float(getattr(scan, "range_max", math.inf))
    except (AttributeError, TypeError, ValueError):
        return None
    if angles.ndim != 1 or angles.shape != ranges.shape \
            or not all(math.isfinite(v) for v in pose) or not np.all(np.isfinite(angles)):
        return None
    high = min(high if math.isfinite(high) else range_max, PHYSICAL_RANGE_MAX)
    low = low if math.isfinite(low) and low >= 0.0 else 0.0
    with np.errstate(invalid="ignore"):
        ranges[ranges > high] = math.inf
        ranges[np.isfinite(ranges) & (ranges < low)] = math.nan
    return Scan(angles, ranges, *pose, low, high)


def extract_obstacles(scan: Scan, person: tuple[float, float] | None,
                      params: ExtractorParams) -> list[Circle]:
    """Circular obstacles (world frame) that cover the returns of ``scan``.

    Parameters
    ----------
    scan : Scan
        A LiDAR scan (:func:`companion.sim.lidar.cast` or hand-made), read by
        :func:`checked_scan` (an invalid scan gives no obstacles); ``inf`` and NaN ranges
        count as "no return", and so does any range beyond ``range_max`` or beyond
        :data:`PHYSICAL_RANGE_MAX` (1 km: FLT_MAX, 1e20) even when ``range_max`` is left
        infinite.
    person : (float, float) or None
        Tracked position of the person; circles centred near it are left out. ``None`` (or a
        position that is not finite) reports everything.
    params : ExtractorParams
        Clustering, fitting and exclusion settings.

    Returns
    -------
    list of Circle
        In beam order of their clusters. Each circle contains every return it was fitted to
        (see the module docstring for the guarantees). Circles that stand for a piece of a
        split cluster (a wall, a large object) are marked ``piece`` and carry ``influence =
        piece_influence``: their radius says nothing about the object's size, so r / K_ob
        would be meaningless.
    """
    checked = checked_scan(scan)
    if checked is None:
        return []
    scan = checked
    pts, clusters = _clusters(scan, params.cluster_gap, params.breakpoint_angle)
    origin = np.array((scan.x, scan.y), float)
    heading = np.array((math.cos(scan.theta), math.sin(scan.theta)))
    clusters = [c for c in clusters if len(c) >= params.min_points]
    if not clusters:
        return []
    centres, radii, whole = _fit(pts, clusters, origin, heading, params)
    out = [(i, c, r, None) for i, (c, r) in enumerate(zip(centres.tolist(), radii.tolist()))
           if whole[i]]
    pieces, owner = [], []                         # clusters that are not one circle: split
    for i in np.flatnonzero(~whole):
        idx = clusters[i]
        for a, b in _pieces(pts[idx], params.max_segment):
            pieces.append(idx[a:b + 1])
            owner.append(i)
    if pieces:
        centres, radii, _ = _fit(pts, pieces, origin, heading, params)
        out += [(i, c, r, params.piece_influence)
                for i, c, r in zip(owner, centres.tolist(), radii.tolist())]
    out.sort(key=lambda item: item[0])             # stable: pieces stay in beam order
    circles = [Circle(c[0], c[1], r, influence, piece=influence is not None)
               for _, c, r, influence in out]
    if person is not None and math.isfinite(person[0]) and math.isfinite(person[1]):
        keep_out = params.person_radius + params.person_exclusion
        circles = [c for c in circles if math.hypot(c.x - person[0], c.y - person[1]) > keep_out]
    return circles
