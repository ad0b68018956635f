"""The episode log: one row per sample from what the world was (the simulator's
:class:`Sample`) and what the robot's stack did (its :class:`~companion.types.StepReport`).

The metrics (:mod:`companion.metrics`) read the log; the simulator itself only moves the
world and says what is true. :data:`companion.types.LOG_COLUMNS` names the columns.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from companion.control.slot import reference_point, slot_point
from companion.geometry import offset_point, unicycle_step
from companion.model import relative_state, slot_reference
from companion.params import Params
from companion.sim.plant import FrameShift
from companion.types import (
    LOG_COLUMNS,
    Command,
    Log,
    PersonEstimate,
    PersonState,
    Pose,
    StepReport,
)

_NO_ESTIMATE = (math.nan,) * 6


@dataclass(frozen=True)
class Sample:
    """The true state of one sample ``t`` (s) and the command the base executes from it:
    the robot pose and its actual velocity ``(v, omega)``, the person, the clearance from
    the robot's footprint to the nearest true obstacle (m, NaN without obstacles), the gap
    to the nearest walker (m, NaN without walkers) and whether a contact with a walker
    begins (1: the robot's doing, 2: the walker's, 0: none), whether the person detector
    could see the person, how the command came (``"new"``, ``"held"``: the last one stays
    in force, ``"timeout"``: the base brakes on its own), the walkers' positions (x0,
    y0, x1, ...; crowds only), the pose the robot's odometry reports (None: the true one)
    and whether the plant's physics finds the robot's body touching the person or an
    obstacle (1 or 0; NaN for a plant without bodies)."""

    t: float
    robot: Pose
    velocity: tuple[float, float]
    person: PersonState
    command: Command
    clearance: float
    walker_gap: float
    walker_contact: float
    in_view: bool
    came: str = "new"
    walkers_xy: np.ndarray | None = None
    odometry: Pose | None = None
    plant_contact: float = math.nan


def error_split(robot: Pose, person: PersonState, cmd: Command, report: StepReport,
                params: Params) -> tuple[float, float, float, float]:
    """Where the slot error of one sample comes from (the log's ``slot_error_m`` to
    ``safety_shift_m``), in metres: from R (the reference point) to the true person's slot;
    from the slot the report's estimate implies to the true one; from R to that estimated
    slot; between the two places R reaches in one period under ``cmd`` and under the
    report's ``requested`` command (0 without a request)."""
    d, dt = params.robot.d, params.dt
    rx, ry = reference_point(robot, d)
    sx, sy = slot_point(person, params)
    est = report.estimate
    if est is None:
        estimate_error = tracking_error = math.nan
    else:
        ex, ey = slot_point(est.walker, params)
        estimate_error = math.hypot(ex - sx, ey - sy)
        tracking_error = math.hypot(rx - ex, ry - ey)
    shift = 0.0
    if report.requested is not None and report.requested != (cmd.v, cmd.omega):
        ends = [offset_point(*unicycle_step(robot.x, robot.y, robot.theta, v, w, dt), d)
                for v, w in ((cmd.v, cmd.omega), report.requested)]
        shift = math.hypot(ends[0][0] - ends[1][0], ends[0][1] - ends[1][1])
    return math.hypot(rx - sx, ry - sy), estimate_error, tracking_error, shift


def in_world(estimate: PersonEstimate, odometry: Pose, truth: Pose) -> PersonEstimate:
    """An estimate the robot holds in its odometry frame, in the world frame: the person
    where the robot believes them relative to where it really is."""
    shift = FrameShift(odometry, truth)
    return dataclasses.replace(estimate, state=shift.person(estimate.state),
                               walker=shift.person(estimate.walker))


def row(sample: Sample, report: StepReport, params: Params) -> tuple[float, ...]:
    """The numbers of one log row (:data:`~companion.types.LOG_COLUMNS`)."""
    p, f = params, params.formation
    if report.bearing is not None and report.bearing != f.bearing:   # a formation policy's
        p = p.replace(formation=dataclasses.replace(f, bearing=report.bearing))
        f = p.formation
    r, h, cmd, d = sample.robot, sample.person, sample.command, p.robot.d
    o = sample.odometry or r
    odo = (o.x, o.y, o.theta)
    if o != r and report.estimate is not None:   # the robot's belief, in the world frame
        report = report._replace(estimate=in_world(report.estimate, o, r))
    e = report.estimate
    est = _NO_ESTIMATE if e is None else (e.state.x, e.state.y, e.state.theta, e.state.v,
                                          e.state.omega, e.position_std)
    rho, alpha, beta = relative_state(r.x, r.y, r.theta, h.x, h.y, h.theta, d)
    beta_ref = slot_reference(h.v, h.omega, f.distance, f.bearing, d).beta
    return (sample.t, r.x, r.y, r.theta, h.x, h.y, h.theta, h.v, h.omega, rho, alpha, beta,
            f.distance, f.bearing, beta_ref, cmd.v, cmd.omega, cmd.u_ob, sample.clearance,
            *sample.velocity, *est, *error_split(r, h, cmd, report, p),
            math.hypot(h.x - r.x, h.y - r.y) - p.robot.radius - p.lidar.person_radius,
            sample.walker_gap, sample.walker_contact, float(sample.in_view), *odo,
            sample.plant_contact)


class Recorder:
    """Rows of a log being filled from samples and reports, numbers in one array, texts in
    lists, the walkers' positions in their own array (the log's ``walkers_xy``)."""

    def __init__(self, params: Params, rows: int, walkers: int = 0):
        self.params = params
        self.last = StepReport()          # the report of the command in force
        self.start(rows, walkers)

    def start(self, rows: int, walkers: int = 0) -> None:
        """Begin a new block of ``rows`` rows."""
        self.numbers = np.empty((rows, len(LOG_COLUMNS)))
        self.walkers = np.empty((rows, 2 * walkers)) if walkers else None
        self.status: list[str] = []
        self.reason: list[str] = []

    def add(self, sample: Sample, report: StepReport | None) -> None:
        """One row: ``report`` is the stack's for a new command (None: a controller without
        one; its command's status)."""
        if sample.came == "new":
            self.last = report or StepReport(sample.command.status)
        elif sample.came == "timeout":
            self.last = self.last._replace(status="stopped", reason="command_timeout",
                                           requested=None)
        n = len(self.status)
        if self.walkers is not None:
            self.walkers[n] = sample.walkers_xy
        self.numbers[n] = row(sample, self.last, self.params)
        self.status.append(self.last.status)
        self.reason.append(self.last.reason)

    def full(self) -> bool:
        return len(self.status) == len(self.numbers)

    def log(self) -> Log:
        columns = {name: self.numbers[:, i] for i, name in enumerate(LOG_COLUMNS)}
        columns["status"] = np.array(self.status, dtype=str)
        columns["reason"] = np.array(self.reason, dtype=str)
        if self.walkers is not None:
            columns["walkers_xy"] = self.walkers
        return Log(columns)
