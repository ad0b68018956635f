"""``companion reproduce``: the paper's Fig. 3, Table 2, Fig. 4 (also as an animation,
fig4.gif), Fig. 7 and Table 3 (with realistic sensing, :mod:`companion.apps.table3`), side by
side.

Every number comes from a simulation run here, as two suites of the evaluate engine
(:func:`runs`); the paper's published Table 2 is kept beside ours for comparison
(:data:`PAPER_TABLE2`, in the paper's units).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from companion import metrics
from companion.apps import animate, plots, table3
from companion.control import CONTROLLERS
from companion.evaluate.generators import scenario_episodes, suite_of
from companion.evaluate.rows import row_and_log
from companion.evaluate.run import run_results, suite_rows
from companion.evaluate.suite import Suite, load_suite
from companion.io import save_figure, write_csv, write_text
from companion.sim import convergence
from companion.sim.scenario import load_scenario

#: Table 2 trajectory name -> built-in scenario.
TRAJECTORIES = {"Linear": "line", "8-shaped": "figure8", "Circle": "circle"}

#: The paper's Table 2: (trajectory, method) -> (rho cm, alpha rad, beta rad, v m/s,
#: omega mrad/s).
PAPER_TABLE2 = {
    ("Linear", "LQR"): (0.001, 0.005, 0.000, 0.001, 0.016),
    ("Linear", "PID"): (0.281, 0.075, 0.000, 0.009, 0.028),
    ("Linear", "VSM"): (3.743, 0.269, 0.000, 0.097, 0.036),
    ("Linear", "IC"): (4.371, 0.094, 0.000, 0.184, 0.020),
    ("8-shaped", "LQR"): (5.123, 0.012, 0.021, 0.072, 5.539),
    ("8-shaped", "PID"): (5.579, 0.068, 0.031, 0.175, 5.555),
    ("8-shaped", "VSM"): (13.873, 0.380, 0.135, 0.077, 35.750),
    ("8-shaped", "IC"): (7.801, 0.093, 0.051, 0.08, 7.910),
    ("Circle", "LQR"): (0.038, 0.006, 0.003, 0.050, 0.773),
    ("Circle", "PID"): (2.411, 0.076, 0.023, 0.100, 8.541),
    ("Circle", "VSM"): (1.612, 0.215, 0.068, 0.098, 9.795),
    ("Circle", "IC"): (3.410, 0.096, 0.021, 0.087, 6.541),
}

#: Our controller name -> the paper's method name (lqr-paper has no row of its own there).
PAPER_METHOD = {"lqr": "LQR", "pid": "PID", "vsm": "VSM", "ic": "IC"}

TABLE2_COLUMNS = ("trajectory", "controller", "rmse_rho_m", "rmse_alpha_rad", "rmse_beta_rad",
                  "rmsv_v_mps", "rmsv_omega_radps")


@dataclass(frozen=True)
class Table2Row:
    trajectory: str
    controller: str
    metrics: dict

    def values(self) -> tuple[float, float, float, float, float]:
        m = self.metrics
        return (m["rmse_rho_m"], m["rmse_alpha_rad"], m["rmse_beta_rad"], m["rmsv_v_mps"],
                m["rmsv_omega_radps"])


def controllers() -> list[str]:
    """Every registered controller, ours first."""
    return list(CONTROLLERS)


def table2_markdown(rows: Sequence[Table2Row]) -> str:
    """Table 2 in the paper's units, with the paper's published values beside ours."""
    lines = [
        "# Table 2: companion accuracy without obstacles (robot starting in its slot)",
        "",
        "Ours: measured by `companion reproduce`. Paper: Su et al., Table 2. Units as in the "
        "paper: rho in cm, alpha and beta in rad, v in m/s, omega in mrad/s.",
        "",
        "| trajectory | controller | rho (cm) | paper | alpha (rad) | paper | beta (rad) | paper "
        "| v (m/s) | paper | omega (mrad/s) | paper |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        rho, alpha, beta, v, om = row.values()
        ours = (rho * 100.0, alpha, beta, v, om * 1000.0)
        paper = PAPER_TABLE2.get((row.trajectory, PAPER_METHOD.get(row.controller, "")))
        cells = []
        for i, value in enumerate(ours):
            cells.append(f"{value:.3f}")
            cells.append("" if paper is None else f"{paper[i]:.3f}")
        lines.append(f"| {row.trajectory} | {row.controller} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def table2_text(rows: Sequence[Table2Row]) -> str:
    """A plain-text Table 2 for the terminal (paper's units)."""
    head = (f"{'trajectory':10s} {'controller':10s} {'rho cm':>8s} {'alpha':>7s} {'beta':>7s} "
            f"{'v m/s':>7s} {'w mrad/s':>9s}   paper rho, alpha")
    out = [head]
    for row in rows:
        rho, alpha, beta, v, om = row.values()
        paper = PAPER_TABLE2.get((row.trajectory, PAPER_METHOD.get(row.controller, "")))
        ref = "" if paper is None else f"   {paper[0]:.3f}, {paper[1]:.3f}"
        out.append(f"{row.trajectory:10s} {row.controller:10s} {rho * 100:8.3f} {alpha:7.4f} "
                   f"{beta:7.4f} {v:7.3f} {om * 1000:9.2f}{ref}")
    return "\n".join(out)


Progress = Callable[[int], None]


@dataclass(frozen=True)
class Reproduction:
    """What :func:`reproduce` measured: the rows of table2.csv, fig3.csv and fig4.csv."""

    table2: list[Table2Row]
    fig3: list[tuple]
    fig4: list[list]
    table3: list[list]


def suites() -> dict[str, Suite]:
    """The shipped suites :func:`reproduce` runs: Fig. 3, Table 2 and Table 3."""
    return {name: load_suite(name) for name in ("convergence", "table2", "table3")}


def runs(shipped: dict[str, Suite] | None = None) -> tuple[Suite, Suite]:
    """What :func:`reproduce` runs, as two suites: the tables' (Table 2 and Table 3, their
    rows) and the figures' (Fig. 3's suite, Fig. 4 with every controller, Fig. 7 with lqr,
    as ``companion run`` runs them; their rows and logs). ``shipped``: :func:`suites`."""
    shipped = shipped or suites()
    tables = suite_of("reproduce-tables", (*shipped["table2"].episodes,
                                           *shipped["table3"].episodes),
                      parts=(shipped["table2"].digest, shipped["table3"].digest))
    figures = suite_of("reproduce-figures", (*shipped["convergence"].episodes,
                                             *scenario_episodes("fig4", controllers()),
                                             *scenario_episodes("fig7", ["lqr"])), row_and_log)
    return tables, figures


def episode_count() -> int:
    """Episodes :func:`reproduce` runs: Fig. 3, Table 2, Fig. 4, Fig. 7 and Table 3."""
    return sum(len(s.episodes) for s in runs())


def reproduce(out: Path, workers: int | None = None, progress: Progress | None = None,
              keep: Path | None = None, dask: str | None = None) -> Reproduction:
    """Run the suites of :func:`runs` through the engine (``workers`` processes or ``dask``,
    :func:`~companion.evaluate.run.run_results`; the tables' episodes kept in ``keep`` as
    they finish, the figures' logs in memory) and write their files into ``out``."""
    shipped = suites()
    tables, figures = runs(shipped)
    done = dict(zip((e.key for e in tables.episodes),
                    run_results(tables, keep, workers, dask, progress and (
                        lambda n, total: progress(n)))))
    results = run_results(figures, None, workers, dask, progress and (
        lambda n, total: progress(len(tables.episodes) + n)))
    fig3_runs: dict[float, list] = {}
    fig3_rows = []
    logs: dict[str, dict] = {}                       # by scenario, the logs per controller
    for e, (row, log) in zip(figures.episodes, results):
        if e.group in ("fig4", "fig7"):
            logs.setdefault(e.group, {})[e.controller] = log
            continue
        case = convergence.Case(e.spec.person.state(0.0).v, e.spec.start, e.side)
        fig3_runs.setdefault(case.speed, []).append((case.label, case.side, log))
        fig3_rows.append(convergence.csv_row(case, _metrics(row)))
    fig4_runs = logs["fig4"]
    trajectory = {v: k for k, v in TRAJECTORIES.items()}
    rows = [Table2Row(trajectory[r["motion"]], r["controller"], r)
            for r in suite_rows(shipped["table2"], done)]
    table3_rows = table3.rows(suite_rows(shipped["table3"], done))
    write_csv(out / "fig3.csv", convergence.CSV_COLUMNS, fig3_rows)
    for speed, speed_runs in fig3_runs.items():
        _save(plots.convergence(speed_runs, f"Fig. 3: person at {speed:g} m/s (lqr)"),
              out / f"fig3_{speed:g}mps.png")
    write_csv(out / "table2.csv", TABLE2_COLUMNS,
              ([r.trajectory, r.controller, *r.values()] for r in rows))
    write_text(out / "table2.md", table2_markdown(rows))
    fig4_table = fig4_rows(fig4_runs)
    write_csv(out / "fig4.csv", FIG4_COLUMNS, fig4_table)
    _scenario_figures(out, "fig4", fig4_runs)
    animate.save(out / "fig4.gif", fig4_runs, load_scenario("fig4"), "Fig. 4: figure-8 with an "
                 "obstacle, every controller")
    _scenario_figures(out, "fig7", logs["fig7"])
    write_csv(out / "table3.csv", table3.COLUMNS, table3_rows)
    write_text(out / "table3.md", table3.markdown(table3_rows))
    return Reproduction(rows, fig3_rows, fig4_table, table3_rows)


def _metrics(row: dict) -> dict:
    """A row's metrics as :func:`companion.metrics.compute` gives them (None for NaN)."""
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()}


FIG4_COLUMNS = ("controller", "obstacle_collisions", "min_obstacle_clearance_m",
                "min_person_distance_m", "rmse_rho_m", "rmse_alpha_rad", "rmse_beta_rad")


def fig4_rows(runs: dict) -> list[list]:
    """Per controller: collisions, clearances and RMSE over the Fig. 4 run."""
    rows = []
    for name, log in runs.items():
        m = metrics.compute(log)
        rows.append([name] + [m[k] for k in FIG4_COLUMNS[1:]])
    return rows


def fig4_text(rows: Sequence[Sequence]) -> str:
    """The Fig. 4 rows (:func:`fig4_rows`) as a table for the terminal."""
    out = [f"{'controller':10s} {'collisions':>10s} {'clearance m':>11s} {'person m':>8s} "
           f"{'rho cm':>7s} {'alpha':>6s}"]
    for name, collisions, clearance, person, rho, alpha, _ in rows:
        out.append(f"{name:10s} {collisions:>10d} {clearance:>11.3f} {person:>8.2f} "
                   f"{rho * 100:>7.1f} {alpha:>6.3f}")
    return "\n".join(out)


def _scenario_figures(out: Path, name: str, runs: dict) -> None:
    sc = load_scenario(name)
    title = f"{name}: {', '.join(runs)}"
    _save(plots.trajectories(runs, title, obstacles=sc.obstacles, avoidance=sc.params.avoidance,
                             footprint=sc.params.robot.radius),
          out / f"{name}a_trajectories.png")
    _save(plots.errors_over_time(runs, title), out / f"{name}b_errors.png")
    _save(plots.inputs_over_time(runs, sc.params, title), out / f"{name}c_inputs.png")
    _save(plots.avoidance_over_time(runs, sc.obstacles, sc.params, title),
          out / f"{name}d_avoidance.png")


def _save(fig, path: Path) -> None:
    save_figure(fig, path)
    plots.close(fig)


def fig3_summary(rows: Sequence[Sequence]) -> str:
    """One line on the Fig. 3 rows (:func:`companion.sim.convergence.csv_row`)."""
    settled = [r[5] for r in rows if r[5] != ""]
    closest = min(r[6] for r in rows)
    worst = max(settled) if settled else math.nan
    return (f"Fig. 3: {len(settled)}/{len(rows)} runs settled (worst {worst:.2f} s), "
            f"closest approach {closest:.2f} m")
