"""Runs drawn as animations (``companion run --animate FILE``, ``fig4.gif`` of ``companion
reproduce``): the person (true, and the tracker's estimate where it differs), each robot's
footprint and heading, its desired slot, the obstacles with their influence ranges, a
crowd's walkers, LiDAR returns, the recent paths, the time and the supervisor's status when
it is not ok.

Frames are taken every ``speed / fps`` simulated seconds: real time (``speed`` 1) for runs up
to :data:`MAX_PLAYBACK_S`, longer runs faster, so an animation never has more than
``MAX_PLAYBACK_S * fps`` frames. GIFs are written with Pillow, MP4s with ffmpeg where it is
on PATH (:mod:`companion.apps.movie`). docs/animations.md: what a frame holds, what it costs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.patches import Circle as Circle2D

from companion.apps import movie, plots
from companion.control.slot import slot_point
from companion.params import Params
from companion.sim.crowd import WALKER_RADIUS
from companion.sim.lidar import cast, scan_points
from companion.sim.scenario import Scenario
from companion.sim.sensing import LidarPerception
from companion.types import Circle, Log, PersonState, Pose, Wall

FPS = 10
"""Frames per second of playback."""

MAX_PLAYBACK_S = 30.0
"""Longest playback (s): longer runs play faster than real time."""

TRAIL_S = 10.0
"""Simulated seconds of path drawn behind the person and each robot."""

FOLLOW_SPAN = 25.0
"""Runs spreading wider than this (m) are shown in a window that follows the person."""

WINDOW = 12.0
"""Width and height (m) of that window."""

HEADING = 0.5
"""Length (m) of the person's heading tick."""

LIDAR = "tab:cyan"
"""Colour of the LiDAR returns of a single run (several runs: each in its robot's)."""

WALKER = "tab:gray"
"""Colour of a crowd's walkers (those of the first run where several are drawn)."""

LATE_LABELS = ("desired slot of R", "walkers", "LiDAR returns")
"""Legend entries listed after the robots."""

DPI = 80
"""Pixels per inch of the frames."""

HEIGHT = 6.0
"""Height of the frames (in): 480 pixels."""

#: Margins (in) around the scene: left (y label), bottom (x label), top (title); the legend
#: goes in a strip at the right as wide as it needs.
LEFT, BOTTOM, TOP = 0.75, 0.55, 0.4


def scene_box(xlim: tuple[float, float], ylim: tuple[float, float]
              ) -> tuple[float, tuple[float, float], tuple[float, float]]:
    """Width (in) of the scene's axes (:data:`HEIGHT` less the margins high) and x and y
    limits widened so that a metre is as long on both axes, for a scene spanning ``xlim``
    and ``ylim`` (m); the scene is between a third and three times as wide as high."""
    axes_h = HEIGHT - BOTTOM - TOP
    sx, sy = xlim[1] - xlim[0], ylim[1] - ylim[0]
    axes_w = axes_h * min(max(sx / sy, 1 / 3), 3.0)
    scale = max(sx / axes_w, sy / axes_h)               # m per inch
    cx, cy = sum(xlim) / 2, sum(ylim) / 2
    hx, hy = 0.5 * scale * axes_w, 0.5 * scale * axes_h
    return axes_w, (cx - hx, cx + hx), (cy - hy, cy + hy)


def playback(duration: float, fps: int = FPS, max_s: float = MAX_PLAYBACK_S) -> float:
    """Playback speed (x real time): 1 up to ``max_s`` of run, else the whole number that
    keeps the playback within ``max_s``."""
    return float(max(1, math.ceil(duration / max_s - 1e-9)))


def frame_indices(t: np.ndarray, fps: int = FPS, speed: float = 1.0) -> np.ndarray:
    """Log rows shown as frames: the row nearest each frame time ``i * speed / fps`` (``t``
    evenly sampled from 0)."""
    if len(t) < 2:
        return np.zeros(len(t), dtype=int)
    dt = float(t[1] - t[0])
    step = speed / fps
    times = np.arange(0.0, float(t[-1]) + 0.5 * dt, step)
    return np.unique(np.minimum(np.round(times / dt).astype(int), len(t) - 1))


def lidar_returns(log: Log, k: int, sc: Scenario) -> np.ndarray:
    """World points (k, 2) of the scan the controller held at row ``k``: re-cast without
    noise from the logged robot pose and person of the row the scan was taken at (every
    ``LidarPerception.every`` rows, :class:`companion.sim.sensing.LidarPerception`) against
    the scenario's obstacles."""
    p = sc.params
    every = LidarPerception(p).every
    j = k - k % every
    circles = [ob for ob in sc.obstacles if isinstance(ob, Circle)] + walkers_at(log, j)
    walls = [ob for ob in sc.obstacles if isinstance(ob, Wall)]
    pose = Pose(log["robot_x"][j], log["robot_y"][j], log["robot_theta"][j])
    scan = cast(pose, circles, walls, (log["person_x"][j], log["person_y"][j]), p.lidar)
    return scan_points(scan)


def walkers_at(log: Log, k: int) -> list[Circle]:
    """The bodies of a crowd's walkers at row ``k`` (none without a crowd)."""
    if "walkers_xy" not in log.columns:
        return []
    xy = log["walkers_xy"][k]
    return [Circle(float(x), float(y), WALKER_RADIUS) for x, y in zip(xy[0::2], xy[1::2])]


def _has_estimate(log: Log) -> bool:
    """The tracker's estimate is in the log and is not just the true person (ideal sensing)."""
    gap = np.hypot(log["person_est_x"] - log["person_x"], log["person_est_y"] - log["person_y"])
    return bool(np.isfinite(gap).any() and np.nanmax(gap) > 1e-3)


def _slot(log: Log, k: int, params: Params) -> tuple[float, float]:
    """The slot the controller aims R at: from its estimate of the person when it has one."""
    pre = "person_est_" if math.isfinite(log["person_est_x"][k]) else "person_"
    person = PersonState(log[pre + "x"][k], log[pre + "y"][k], log[pre + "theta"][k], 0.0, 0.0)
    return slot_point(person, params)


def _heading(x: float, y: float, theta: float, length: float) -> tuple[list, list]:
    return [x, x + length * math.cos(theta)], [y, y + length * math.sin(theta)]


@dataclass
class _Body:
    """A round body with a heading tick (robot footprint, person)."""

    disc: Circle2D
    tick: object

    def move(self, x: float, y: float, theta: float, length: float) -> None:
        visible = math.isfinite(x) and math.isfinite(y)
        self.disc.set_visible(visible)
        self.tick.set_visible(visible)
        if visible:
            self.disc.set_center((x, y))
            self.tick.set_data(*_heading(x, y, theta, length))


def _body(ax, radius: float, color: str, label: str | None, fill: bool = True,
          ls: str = "-") -> _Body:
    disc = Circle2D((0.0, 0.0), radius, facecolor=color if fill else "none", edgecolor=color,
                    alpha=0.85, ls=ls, lw=1.5, zorder=4, label=label)
    ax.add_patch(disc)
    (tick,) = ax.plot([], [], color="k" if fill else color, lw=1.5, ls=ls, zorder=5)
    return _Body(disc, tick)


def _extent(runs: Mapping[str, Log]) -> tuple[float, float, float, float]:
    xs = np.concatenate([np.r_[log["robot_x"], log["person_x"]] for log in runs.values()])
    ys = np.concatenate([np.r_[log["robot_y"], log["person_y"]] for log in runs.values()])
    return float(np.nanmin(xs)), float(np.nanmax(xs)), float(np.nanmin(ys)), float(np.nanmax(ys))


class _Scene:
    """The artists of one animation and how a frame moves them."""

    def __init__(self, runs: Mapping[str, Log], sc: Scenario, title: str, speed: float,
                 trail_rows: int):
        import matplotlib.pyplot as plt

        self.runs, self.sc, self.speed, self.trail = runs, sc, speed, trail_rows
        p = sc.params
        x0, x1, y0, y1 = _extent(runs)
        self.follow = max(x1 - x0, y1 - y0) > FOLLOW_SPAN
        if self.follow:
            xlim, ylim = (-0.5 * WINDOW, 0.5 * WINDOW), (-0.5 * WINDOW, 0.5 * WINDOW)
        else:
            margin = 1.0 + p.robot.radius
            xlim, ylim = (x0 - margin, x1 + margin), (y0 - margin, y1 + margin)
        axes_w, xlim, ylim = scene_box(xlim, ylim)
        self.fig = plt.figure(figsize=(LEFT + axes_w, HEIGHT), dpi=DPI)
        ax = self.fig.add_axes((0, 0, 1, 1))
        ax.set_xlim(*xlim)
        ax.set_ylim(*ylim)
        self.ax = ax
        plots.draw_obstacles(ax, sc.obstacles, p.avoidance, p.robot.radius)
        first = next(iter(runs.values()))
        (self.person_trail,) = ax.plot([], [], color=plots.PERSON, lw=1.2, alpha=0.6)
        self.walkers = [ax.add_patch(Circle2D((0.0, 0.0), c.radius, color=WALKER, alpha=0.7,
                                              zorder=4, label=None if i else "walkers"))
                        for i, c in enumerate(walkers_at(first, 0))]
        self.person = _body(ax, p.lidar.person_radius, plots.PERSON, "person")
        self.robots, self.trails, self.slots, self.estimates, self.scans = {}, {}, {}, {}, {}
        for name, color in plots.colors(runs).items():
            log = runs[name]
            (self.trails[name],) = ax.plot([], [], color=color, lw=1.2, ls="--", alpha=0.7)
            self.robots[name] = _body(ax, p.robot.radius, color, name)
            (self.slots[name],) = ax.plot([], [], "x", color=color, ms=8, mew=2, zorder=6,
                                          label="desired slot of R" if not self.slots else None)
            if _has_estimate(log):
                self.estimates[name] = _body(ax, p.lidar.person_radius, color,
                                             "person estimate" if not self.estimates else None,
                                             fill=False, ls=":")
            if sc.obstacle_source == "lidar":
                (self.scans[name],) = ax.plot(
                    [], [], ".", color=LIDAR if len(runs) == 1 else color, ms=4, zorder=3,
                    label="LiDAR returns" if not self.scans else None)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        inches = self.fig.dpi_scale_trans
        self.fig.text(LEFT, HEIGHT - 0.28, title, fontsize=10, transform=inches)
        ax.grid(alpha=0.3)
        self.clock = ax.text(0.01, 0.99, "", transform=ax.transAxes, va="top", fontsize=9,
                             family="monospace", zorder=7,
                             bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "none"})
        self.status = ax.text(0.01, 0.01, "", transform=ax.transAxes, va="bottom", fontsize=8,
                              color="tab:red", zorder=7,
                              bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "none"})
        handles, labels = ax.get_legend_handles_labels()
        order = sorted(range(len(labels)), key=lambda i: labels[i] in LATE_LABELS)
        legend = self.fig.legend([handles[i] for i in order], [labels[i] for i in order],
                                 loc="upper left", fontsize=8, bbox_transform=inches,
                                 bbox_to_anchor=(LEFT + axes_w + 0.1, HEIGHT - TOP))
        wide = legend.get_window_extent(self.fig.canvas.get_renderer()).width / DPI
        width = movie.even_inches(LEFT + axes_w + 0.2 + wide, DPI)
        self.fig.set_size_inches(width, HEIGHT)
        ax.set_position((LEFT / width, BOTTOM / HEIGHT, axes_w / width,
                         (HEIGHT - BOTTOM - TOP) / HEIGHT))
        self.t = first["t"]
        self.dynamic = sorted(
            [self.person.disc, self.person.tick, self.person_trail, self.clock, self.status,
             *self.walkers,
             *self.trails.values(), *self.slots.values(), *self.scans.values(),
             *(a for b in (*self.robots.values(), *self.estimates.values())
               for a in (b.disc, b.tick))], key=lambda a: a.get_zorder())
        self.background = None
        if not self.follow:                     # a still scene: draw it once
            for artist in self.dynamic:
                artist.set_animated(True)
            self.fig.canvas.draw()
            self.background = self.fig.canvas.copy_from_bbox(self.fig.bbox)

    def render(self, k: int) -> None:
        """Draw the frame of row ``k`` on the canvas: the still scene once drawn, and the
        moving artists over it (all of it when the view follows the person)."""
        self.draw(k)
        canvas = self.fig.canvas
        if self.background is None:
            canvas.draw()
            return
        canvas.restore_region(self.background)
        for artist in self.dynamic:
            self.fig.draw_artist(artist)

    def draw(self, k: int) -> None:
        """Move every artist to row ``k`` of the logs."""
        p, sc = self.sc.params, self.sc
        lo = max(0, k - self.trail)
        first = next(iter(self.runs.values()))
        px, py, pth = (first[c][k] for c in ("person_x", "person_y", "person_theta"))
        self.person.move(px, py, pth, HEADING)
        for patch, c in zip(self.walkers, walkers_at(first, k)):
            patch.set_center((c.x, c.y))
        self.person_trail.set_data(first["person_x"][lo:k + 1], first["person_y"][lo:k + 1])
        stopped = []
        for name, log in self.runs.items():
            self.robots[name].move(log["robot_x"][k], log["robot_y"][k], log["robot_theta"][k],
                                   p.robot.d)
            self.trails[name].set_data(log["robot_x"][lo:k + 1], log["robot_y"][lo:k + 1])
            self.slots[name].set_data(*([v] for v in _slot(log, k, p)))
            if name in self.estimates:
                self.estimates[name].move(log["person_est_x"][k], log["person_est_y"][k],
                                          log["person_est_theta"][k], HEADING)
            if name in self.scans:
                pts = lidar_returns(log, k, sc)
                self.scans[name].set_data(pts[:, 0], pts[:, 1])
            if log["status"][k] != "ok":
                reason = log["reason"][k]
                stopped.append(f"{name}: {log['status'][k]}" + (f" ({reason})" if reason else ""))
        self.clock.set_text(f"t = {self.t[k]:5.1f} s  ({self.speed:g}x)")
        self.status.set_text("\n".join(stopped))
        if self.follow:
            h = 0.5 * WINDOW
            self.ax.set_xlim(px - h, px + h)
            self.ax.set_ylim(py - h, py + h)


def save(path: str | Path, runs: Mapping[str, Log], sc: Scenario, title: str = "",
         fps: int = FPS, max_playback_s: float = MAX_PLAYBACK_S) -> int:
    """Write the animation of ``runs`` (logs of scenario ``sc`` by controller name, sharing
    the person) to ``path`` (.gif or .mp4) atomically; returns the number of frames."""
    path = Path(path)
    first = next(iter(runs.values()))
    t = first["t"]
    duration = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    speed = playback(duration, fps, max_playback_s)
    rows = frame_indices(t, fps, speed)
    dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
    scene = _Scene(runs, sc, title or f"{sc.name}: {', '.join(runs)}", speed,
                   int(round(TRAIL_S / dt)))
    try:
        movie.write(path, scene.fig, scene.render, rows, fps)
    finally:
        plots.close(scene.fig)
    return len(rows)


def save_run(target: Path, out: Path, stage: Path, sc: Scenario, log: Log) -> bool:
    """``companion run --animate``: into the staging folder ``stage`` (so it is replaced with
    the other outputs) when ``target`` is directly in the output folder ``out``, else
    straight to ``target``; returns whether it is one of the outputs in ``out``."""
    inside = target.absolute().parent.resolve() == out.absolute().resolve()
    save(stage / target.name if inside else target, {sc.controller: log}, sc,
         f"{sc.name} / {sc.controller}")
    return inside
