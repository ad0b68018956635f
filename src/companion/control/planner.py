"""A shortest way round walls on a small grid, for the rejoin and the search
(:mod:`companion.control.rejoin`, :mod:`companion.control.search`).

:func:`plan_way` lays a grid of ``cell`` m over the box round the start and the goal, marks
the cells whose clearance to the walls is below the footprint (or below the start's own,
where the robot already stands closer: it may stay that close, not come closer) and runs
Dijkstra (:func:`scipy.sparse.csgraph.dijkstra`) over the free cells, 8-connected, from the
goal. A step away from the person's own way (``along``, the points the rejoin keeps)
costs :data:`OFF_WAY_COST` times its length: a person walked there, while a LiDAR that saw
a wall only at a grazing angle may have missed it elsewhere. The way is the chain of cells
from the start down the distances; :func:`next_point` is where on it to drive now.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.ndimage import distance_transform_edt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from companion.geometry import obstacle_arrays, point_clearances, sweep_clear
from companion.types import Obstacle

#: Grid cell (m) and the room (m) round the start and the goal the grid covers.
CELL, BORDER = 0.1, 3.0
#: How far along the way (m) the point to drive to may lie.
LOOKAHEAD = 1.5
#: Within this (m) of the person's way a step costs its length; farther, this many times.
ALONG_M, OFF_WAY_COST = 0.6, 2.0
#: The 8 neighbours of a cell and their step lengths (in cells).
_STEPS = [(di, dj, math.hypot(di, dj)) for di in (-1, 0, 1) for dj in (-1, 0, 1)
          if (di, dj) != (0, 0)]


def plan_way(start: tuple[float, float], goal: tuple[float, float],
             obstacles: Sequence[Obstacle], footprint: float, cell: float = CELL,
             border: float = BORDER, along: Sequence[tuple[float, float]] = ()
             ) -> list[tuple[float, float]] | None:
    """The shortest 8-connected way of grid cells from ``start`` to ``goal`` that keeps
    ``footprint`` m from ``obstacles`` (module docstring; with ``along``, steps farther than
    :data:`ALONG_M` from those points cost :data:`OFF_WAY_COST` times), as cell centres from
    the start's to the goal's; None if the goal is in an obstacle's reach or cut off."""
    (sx, sy), (gx, gy) = start, goal
    x0, y0 = min(sx, gx) - border, min(sy, gy) - border
    nx = int(math.ceil((max(sx, gx) + border - x0) / cell)) + 1
    ny = int(math.ceil((max(sy, gy) + border - y0) / cell)) + 1
    xs, ys = np.meshgrid(x0 + cell * np.arange(nx), y0 + cell * np.arange(ny), indexing="ij")
    clear = point_clearances(xs.ravel(), ys.ravel(), obstacle_arrays(obstacles),
                             0.0).reshape(xs.shape)
    si, sj = round((sx - x0) / cell), round((sy - y0) / cell)
    gi, gj = round((gx - x0) / cell), round((gy - y0) / cell)
    free = clear >= min(footprint, clear[si, sj])
    if not free[gi, gj]:
        return None
    index = np.arange(nx * ny).reshape(nx, ny)
    weight = np.ones((nx, ny))
    if len(along):                   # cells within ALONG_M of a point of the person's way
        way = np.rint((np.asarray(along, float) - (x0, y0)) / cell).astype(int)
        way = way[(way[:, 0] >= 0) & (way[:, 0] < nx) & (way[:, 1] >= 0) & (way[:, 1] < ny)]
        walked = np.zeros((nx, ny), bool)
        walked[way[:, 0], way[:, 1]] = True
        if walked.any():
            weight[distance_transform_edt(~walked) * cell > ALONG_M] = OFF_WAY_COST
    rows, cols, costs = [], [], []
    for di, dj, length in _STEPS:                 # an edge wherever both cells are free
        src = (_part(di, nx, False), _part(dj, ny, False))
        dst = (_part(di, nx, True), _part(dj, ny, True))
        both = free[src] & free[dst]
        rows.append(index[src][both])
        cols.append(index[dst][both])
        costs.append(0.5 * length * (weight[src] + weight[dst])[both])
    graph = coo_matrix((np.concatenate(costs), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(nx * ny, nx * ny)).tocsr()
    dist, before = dijkstra(graph, indices=int(index[gi, gj]), return_predecessors=True)
    k = int(index[si, sj])
    if not math.isfinite(dist[k]):
        return None
    way = []
    while k >= 0:
        i, j = divmod(k, ny)
        way.append((x0 + cell * i, y0 + cell * j))
        k = int(before[k])
    return way


def next_point(start: tuple[float, float], goal: tuple[float, float],
               obstacles: Sequence[Obstacle], footprint: float,
               along: Sequence[tuple[float, float]] = ()) -> tuple[float, float] | None:
    """Where to drive now on the way to ``goal``: the goal if the footprint can move
    straight there (:func:`companion.geometry.sweep_clear`), else the farthest point of the
    way :func:`plan_way` plans (preferring ``along``) within :data:`LOOKAHEAD` m that it can
    reach straight; None if no way."""
    if sweep_clear(*start, *goal, obstacles, footprint):
        return goal
    way = plan_way(start, goal, obstacles, footprint, along=along)
    if way is None:
        return None
    ahead = min(len(way) - 1, int(LOOKAHEAD / CELL))
    while ahead > 1 and not sweep_clear(*start, *way[ahead], obstacles, footprint):
        ahead -= 1
    return way[ahead]


def _part(shift: int, n: int, moved: bool) -> slice:
    """The cells along one axis that have a neighbour ``shift`` away (``moved``: those
    neighbours)."""
    if moved:
        return slice(max(0, shift), n - max(0, -shift))
    return slice(max(0, -shift), n - max(0, shift))
