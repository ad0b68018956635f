"""Figures in the spirit of the paper's Fig. 3 and Fig. 4 (matplotlib, Agg backend)."""

from __future__ import annotations

from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from matplotlib.patches import Circle as Circle2D  # noqa: E402

from companion.control.avoidance import influence_range  # noqa: E402
from companion.metrics import errors  # noqa: E402
from companion.obstacles import Circle, Obstacle  # noqa: E402
from companion.params import AvoidanceParams, Params  # noqa: E402
from companion.sim.episode import Log  # noqa: E402

PERSON = "tab:red"
ROBOT = "tab:purple"


def _headings(ax, x, y, th, every: int, color: str) -> None:
    idx = np.arange(0, len(x), max(every, 1))
    ax.quiver(x[idx], y[idx], np.cos(th[idx]), np.sin(th[idx]), color=color, angles="xy",
              scale_units="xy", scale=4.0, width=0.004, alpha=0.8)


def draw_obstacles(ax, obstacles: Sequence[Obstacle], avoidance: AvoidanceParams | None) -> None:
    """Obstacles in grey; their influence ranges dashed (when ``avoidance`` is given)."""
    for i, ob in enumerate(obstacles):
        label = "obstacle" if i == 0 else None
        if isinstance(ob, Circle):
            ax.add_patch(Circle2D((ob.x, ob.y), ob.radius, color="0.4", label=label))
            if avoidance is not None:
                reach = ob.radius + influence_range(ob, avoidance)
                ax.add_patch(Circle2D((ob.x, ob.y), reach, fill=False, ls="--", color="0.5",
                                      label="influence range (from the surface)"
                                      if i == 0 else None))
        else:
            ax.plot([ob.x0, ob.x1], [ob.y0, ob.y1], color="0.3", lw=3, label=label)


def trajectory(log: Log, title: str = "", marker_period_s: float = 2.0,
               obstacles: Sequence[Obstacle] = (), avoidance: AvoidanceParams | None = None
               ) -> Figure:
    """Person and robot paths with heading arrows every ``marker_period_s`` seconds, and the
    obstacles with their influence ranges."""
    fig, ax = plt.subplots(figsize=(7, 6), layout="constrained")
    draw_obstacles(ax, obstacles, avoidance)
    dt = float(log["t"][1] - log["t"][0]) if len(log) > 1 else 1.0
    every = int(round(marker_period_s / dt))
    ax.plot(log["person_x"], log["person_y"], color=PERSON, lw=2, label="person")
    ax.plot(log["robot_x"], log["robot_y"], color=ROBOT, lw=1.5, ls="--", label="robot")
    _headings(ax, log["person_x"], log["person_y"], log["person_theta"], every, PERSON)
    _headings(ax, log["robot_x"], log["robot_y"], log["robot_theta"], every, ROBOT)
    ax.plot(log["person_x"][0], log["person_y"][0], "o", color=PERSON, label="start")
    ax.plot(log["robot_x"][0], log["robot_y"][0], "o", color=ROBOT)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title or "Trajectories (arrows: heading)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best")
    return fig


def state_errors(log: Log, title: str = "") -> Figure:
    """rho, alpha and beta errors over time (beta also against the turn's beta_ref)."""
    e = errors(log)
    t = log["t"]
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True, layout="constrained")
    axes[0].plot(t, e["rho"], color=ROBOT)
    axes[0].set_ylabel("rho - rho_d (m)")
    axes[1].plot(t, e["alpha"], color=ROBOT)
    axes[1].set_ylabel("alpha - alpha_d (rad)")
    axes[2].plot(t, e["beta"], color=ROBOT, label="beta")
    axes[2].plot(t, log["beta_ref"], color="k", ls=":", lw=1,
                 label="beta_ref (heading offset a turn needs)")
    axes[2].set_ylabel("beta (rad)")
    axes[2].legend(loc="best", fontsize=8)
    axes[2].set_xlabel("t (s)")
    for ax in axes:
        ax.axhline(0.0, color="grey", lw=0.8)
        ax.grid(alpha=0.3)
    axes[0].set_title(title or "State errors")
    return fig


def inputs(log: Log, params: Params, title: str = "") -> Figure:
    """Robot inputs against the person's velocity, with the input limits dashed."""
    t = log["t"]
    fig, axes = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, layout="constrained")
    for ax, key, pkey, lim, unit in ((axes[0], "v", "person_v", params.robot.v_max, "m/s"),
                                    (axes[1], "omega", "person_omega", params.robot.omega_max,
                                     "rad/s")):
        ax.plot(t, log[pkey], color=PERSON, lw=1.5, label="person")
        ax.plot(t, log[key], color=ROBOT, lw=1.2, label="robot")
        for s in (-1, 1):
            ax.axhline(s * lim, color="k", ls="--", lw=0.8)
        ax.set_ylabel(f"{key} ({unit})")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    axes[1].set_xlabel("t (s)")
    axes[0].set_title(title or "Control inputs (dashed: limits)")
    return fig


def avoidance(log: Log, obstacles: Sequence[Obstacle], params: Params, title: str = ""
              ) -> Figure:
    """Fig. 4(d): the avoidance output u_ob and the clearance rho_ob to the nearest obstacle
    over time, with the influence range(s) dashed."""
    t = log["t"]
    fig, axes = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, layout="constrained")
    axes[0].plot(t, log["u_ob"], color=ROBOT)
    axes[0].set_ylabel("u_ob (rad/s)")
    axes[1].plot(t, log["rho_ob"], color=ROBOT, label="rho_ob (footprint to nearest surface)")
    for i, reach in enumerate(sorted({influence_range(ob, params.avoidance) for ob in obstacles})):
        axes[1].axhline(reach, color="tab:purple", ls="--", lw=1,
                        label="influence range" if i == 0 else None)
    axes[1].axhline(0.0, color="k", lw=0.8, label="contact")
    reaches = [influence_range(ob, params.avoidance) for ob in obstacles]
    if reaches:
        axes[1].set_ylim(-0.1, 4.0 * max(reaches))
    axes[1].set_ylabel("rho_ob (m)")
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
    colors = {label: plt.cm.tab10(i % 10) for i, label in enumerate(labels)}
    first = runs[0][2]
    ax_traj.plot(first["person_x"], first["person_y"], color=PERSON, lw=2.5, label="person")
    for label, side, log in runs:
        c = colors[label]
        ax_traj.plot(log["robot_x"], log["robot_y"], ls="--", lw=1, color=c)
        ax_traj.plot(log["robot_x"][0], log["robot_y"][0], "o", color=c, ms=4)
        e = errors(log)
        for ax, key in zip(err_axes[side], ("rho", "alpha", "beta_ref")):
            ax.plot(log["t"], e[key], color=c, lw=1)
    for label in labels:
        ax_traj.plot([], [], color=colors[label], ls="--", label=f"start {label}")
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
