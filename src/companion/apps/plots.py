"""Figures in the spirit of the paper's Fig. 3 and Fig. 4 (matplotlib, Agg backend)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle as Circle2D

from companion.control.avoidance import influence_range
from companion.metrics import errors
from companion.params import AvoidanceParams, Params
from companion.types import Circle, Log, Obstacle

PERSON = "tab:red"
ROBOT = "tab:purple"
#: Most heading arrows drawn along one path (:func:`trajectories`).
MAX_ARROWS = 400
#: Points of a line that Agg rasterizes at a time (matplotlib's ``agg.path.chunksize``).
#: Agg's memory for a line grows with its length on the canvas, not with its points: the
#: 50,000 plotted rows of a day-long figure-8 run retrace the figure over 1,440 laps, and
#: with each line drawn in one piece, saving the trajectories took 155 MB more than for a
#: lap. In pieces, each piece's memory is freed before the next one is drawn (matplotlib
#: leaves out the two segments around one point at each joint, which the line's width
#: covers at this many points).
AGG_CHUNK = 1000

matplotlib.rcParams["agg.path.chunksize"] = AGG_CHUNK


def _headings(ax, x, y, th, every: int, color: str) -> None:
    idx = np.arange(0, len(x), max(every, 1))
    ax.quiver(x[idx], y[idx], np.cos(th[idx]), np.sin(th[idx]), color=color, angles="xy",
              scale_units="xy", scale=4.0, width=0.004, alpha=0.8)


def draw_obstacles(ax, obstacles: Sequence[Obstacle], avoidance: AvoidanceParams | None,
                   footprint: float = 0.0) -> None:
    """Obstacles in grey; dashed, where the robot centre enters their influence range
    (surface + rho_o + footprint radius), when ``avoidance`` is given."""
    for i, ob in enumerate(obstacles):
        label = "obstacle" if i == 0 else None
        if isinstance(ob, Circle):
            ax.add_patch(Circle2D((ob.x, ob.y), ob.radius, color="0.4", label=label))
            if avoidance is not None:
                reach = ob.radius + influence_range(ob, avoidance) + footprint
                ax.add_patch(Circle2D((ob.x, ob.y), reach, fill=False, ls="--", color="0.5",
                                      label="influence range (robot centre)"
                                      if i == 0 else None))
        else:
            ax.plot([ob.x0, ob.x1], [ob.y0, ob.y1], color="0.3", lw=3, label=label)


Runs = Mapping[str, Log]
"""Logs of the same scenario by controller name (they share the person)."""


def colors(runs: Runs) -> dict[str, str]:
    """A colour per run: purple for one, else the Fig. 4 palette in order."""
    if len(runs) == 1:
        return {name: ROBOT for name in runs}
    palette = ["tab:purple", "tab:green", "tab:orange", "tab:pink", "tab:blue", "tab:brown"]
    return {name: palette[i % len(palette)] for i, name in enumerate(runs)}


def trajectories(runs: Runs, title: str = "", marker_period_s: float = 2.0,
                 obstacles: Sequence[Obstacle] = (), avoidance: AvoidanceParams | None = None,
                 footprint: float = 0.0) -> Figure:
    """Person and robot paths (one per run) with heading arrows every ``marker_period_s``
    seconds (at most :data:`MAX_ARROWS` a path), the obstacles with their influence ranges
    (Fig. 3(a), Fig. 4(a)) and a crowd's walkers' paths."""
    fig, ax = plt.subplots(figsize=(7, 6), layout="constrained")
    draw_obstacles(ax, obstacles, avoidance, footprint)
    first = next(iter(runs.values()))
    if "walkers_xy" in first.columns:          # a crowd's walkers (the first run's)
        xy = first["walkers_xy"]
        ax.plot(xy[:, 0::2], xy[:, 1::2], color="tab:gray", lw=0.8, alpha=0.4)
        ax.plot([], [], color="tab:gray", lw=0.8, alpha=0.4, label="walkers")
    dt = float(first["t"][1] - first["t"][0]) if len(first) > 1 else 1.0
    # at most MAX_ARROWS arrows a path: a day-long run's would hide it
    every = max(int(round(marker_period_s / dt)), math.ceil(len(first) / MAX_ARROWS))
    ax.plot(first["person_x"], first["person_y"], color=PERSON, lw=2, label="person")
    _headings(ax, first["person_x"], first["person_y"], first["person_theta"], every, PERSON)
    ax.plot(first["person_x"][0], first["person_y"][0], "o", color=PERSON, label="start")
    for (name, log), color in zip(runs.items(), colors(runs).values()):
        ax.plot(log["robot_x"], log["robot_y"], color=color, lw=1.5, ls="--", label=name)
        _headings(ax, log["robot_x"], log["robot_y"], log["robot_theta"], every, color)
        ax.plot(log["robot_x"][0], log["robot_y"][0], "o", color=color)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title or "Trajectories (arrows: heading)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return fig


def errors_over_time(runs: Runs, title: str = "") -> Figure:
    """rho, alpha and beta errors over time (Fig. 4(b)); with one run, beta_ref dotted."""
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True, layout="constrained")
    for (name, log), color in zip(runs.items(), colors(runs).values()):
        e = errors(log)
        axes[0].plot(log["t"], e["rho"], color=color, label=name)
        axes[1].plot(log["t"], e["alpha"], color=color)
        axes[2].plot(log["t"], e["beta"], color=color)
    if len(runs) == 1:
        log = next(iter(runs.values()))
        axes[2].plot(log["t"], log["beta_ref"], color="k", ls=":", lw=1,
                     label="beta_ref (heading offset a turn needs)")
        axes[2].legend(loc="best", fontsize=8)
    else:
        axes[0].legend(loc="best", fontsize=8)
    axes[0].set_ylabel("rho - rho_d (m)")
    axes[1].set_ylabel("alpha - alpha_d (rad)")
    axes[2].set_ylabel("beta (rad)")
    axes[2].set_xlabel("t (s)")
    for ax in axes:
        ax.axhline(0.0, color="grey", lw=0.8)
        ax.grid(alpha=0.3)
    axes[0].set_title(title or "State errors")
    return fig


def inputs_over_time(runs: Runs, params: Params, title: str = "") -> Figure:
    """Robot inputs against the person's velocity, input limits dashed (Fig. 4(c))."""
    fig, axes = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, layout="constrained")
    first = next(iter(runs.values()))
    for ax, key, pkey, lim, unit in ((axes[0], "v", "person_v", params.robot.v_max, "m/s"),
                                    (axes[1], "omega", "person_omega", params.robot.omega_max,
                                     "rad/s")):
        ax.plot(first["t"], first[pkey], color=PERSON, lw=1.5, label="person")
        for (name, log), color in zip(runs.items(), colors(runs).values()):
            ax.plot(log["t"], log[key], color=color, lw=1.2, label=name)
        for s in (-1, 1):
            ax.axhline(s * lim, color="k", ls="--", lw=0.8)
        ax.set_ylabel(f"{key} ({unit})")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    axes[1].set_xlabel("t (s)")
    axes[0].set_title(title or "Control inputs (dashed: limits)")
    return fig


def avoidance_over_time(runs: Runs, obstacles: Sequence[Obstacle], params: Params,
                        title: str = "") -> Figure:
    """Fig. 4(d): the avoidance output u_ob and the clearance rho_ob to the nearest obstacle
    over time, with the influence range(s) dashed."""
    fig, axes = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, layout="constrained")
    for (name, log), color in zip(runs.items(), colors(runs).values()):
        axes[0].plot(log["t"], log["u_ob"], color=color, label=name)
        axes[1].plot(log["t"], log["rho_ob"], color=color)
    axes[0].set_ylabel("u_ob (rad/s)")
    axes[0].legend(loc="best", fontsize=8)
    reaches = sorted({influence_range(ob, params.avoidance) for ob in obstacles})
    for i, reach in enumerate(reaches):
        axes[1].axhline(reach, color="tab:purple", ls="--", lw=1,
                        label="influence range" if i == 0 else None)
    axes[1].axhline(0.0, color="k", lw=0.8, label="contact")
    if reaches:
        axes[1].set_ylim(-0.1, 4.0 * max(reaches))
    axes[1].set_ylabel("rho_ob (m), footprint to nearest surface")
    axes[1].set_xlabel("t (s)")
    axes[1].legend(loc="best", fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].set_title(title or "Obstacle avoidance (Fig. 4(d))")
    return fig


def convergence(runs: Sequence[tuple[str, str, Log]], title: str = "") -> Figure:
    """Fig. 3 layout: (a) trajectories of all starts, (b) right-side and (c) left-side errors.

    ``runs`` holds ``(start_label, side, log)``; runs with the same start share a colour.
    """
    fig = plt.figure(figsize=(12, 11), layout="constrained")
    grid = fig.add_gridspec(4, 2, height_ratios=(1.3, 1, 1, 1))
    ax_traj = fig.add_subplot(grid[0, :])
    err_axes = {side: [fig.add_subplot(grid[i + 1, col]) for i in range(3)]
                for side, col in (("right", 0), ("left", 1))}
    labels = list(dict.fromkeys(label for label, _, _ in runs))
    shades = {label: plt.cm.tab10(i % 10) for i, label in enumerate(labels)}
    first = runs[0][2]
    ax_traj.plot(first["person_x"], first["person_y"], color=PERSON, lw=2.5, label="person")
    for label, side, log in runs:
        c = shades[label]
        ax_traj.plot(log["robot_x"], log["robot_y"], ls="--", lw=1, color=c)
        ax_traj.plot(log["robot_x"][0], log["robot_y"][0], "o", color=c, ms=4)
        e = errors(log)
        for ax, key in zip(err_axes[side], ("rho", "alpha", "beta_ref")):
            ax.plot(log["t"], e[key], color=c, lw=1)
    for label in labels:
        ax_traj.plot([], [], color=shades[label], ls="--", label=f"start {label}")
    ax_traj.set_aspect("equal", adjustable="box")
    ax_traj.set_xlabel("x (m)")
    ax_traj.set_ylabel("y (m)")
    ax_traj.set_title("(a) trajectories (dots: robot starts)")
    ax_traj.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax_traj.grid(alpha=0.3)
    for side, axes in err_axes.items():
        tag = "(b)" if side == "right" else "(c)"
        for ax, name in zip(axes, ("rho_e (m)", "alpha_e (rad)", "beta_e (rad)")):
            ax.set_ylabel(name)
            ax.axhline(0.0, color="grey", lw=0.8)
            ax.grid(alpha=0.3)
        axes[0].set_title(f"{tag} {side}-side state errors")
        axes[-1].set_xlabel("t (s)")
    if title:
        fig.suptitle(title)
    return fig


def close(fig: Figure) -> None:
    plt.close(fig)
