"""The social-navigation measures of a logged episode among people (docs/crowds.md, "What is
measured"), kept over consecutive blocks of the log as :mod:`companion.metrics` keeps the
others: contacts with walkers by who moved into whom, proxemic zones, path, jerk, stops, and
losing and finding the person.
"""

from __future__ import annotations

import math

import numpy as np

from companion.types import Log


class Runs:
    """The longest run of True samples of a boolean series given in consecutive blocks."""

    def __init__(self) -> None:
        self.now, self.longest = 0, 0       # samples: the run at the end so far, the longest

    def add(self, mask: np.ndarray) -> None:
        false = np.flatnonzero(~mask)
        if len(false) == 0:                 # true through the block
            self.now += len(mask)
        else:                               # the runs of true samples in it
            runs = np.diff(np.concatenate(([-1], false))) - 1
            runs[0] += self.now             # carried over from the blocks before
            self.longest = max(self.longest, int(runs.max()))
            self.now = len(mask) - 1 - int(false[-1])
        self.longest = max(self.longest, self.now)


#: Proxemic zones (m of gap between bodies): intimate below the first, personal up to the
#: second (Hall's distances, as the social-navigation literature uses them).
INTIMATE_M, PERSONAL_M = 0.45, 1.2
#: Below this speed (m/s) the robot is standing (for the longest stop); from this one (m/s)
#: the person walks.
STANDING_MPS, WALKING_MPS = 0.05, 0.3
#: Time (s) in the detector's view while lost that counts as a chance to re-find the person
#: (the tracker needs ``tracker.reacquire_time_s``, 0.3 s, of consistent detections).
REFIND_VIEW_S = 0.5


class Social:
    """The social-navigation measures (docs/crowds.md) over consecutive blocks: contacts with
    other walkers by who moved into whom, the closest gap to a walker and the time inside a
    walker's intimate zone, the time the gap to the person lies in the intimate and in the
    personal zone, the robot's path length, the RMS of its jerk and its longest stop; and
    of finding the person: the share of samples with the person in the detector's view, the
    times the person was lost and re-found (the tracker's decisions, from the status reasons),
    the losses during which the person was in view for at least :data:`REFIND_VIEW_S` (the
    chances to re-find them) and the time spent searching."""

    def __init__(self) -> None:
        self._contacts = {1.0: 0, 2.0: 0}
        self._min_gap: float | None = None
        self._walker_intimate = self._intimate = self._personal = 0   # samples
        self._length, self._jerk_sq, self._jerks = 0.0, 0.0, 0
        self._prev: np.ndarray | None = None     # the last two rows' t, x, y, v
        self._stops, self._stops_walking = Runs(), Runs()   # standing; while the person walks
        self._dt = 0.0                            # the sample period, once two samples came
        self._samples = self._in_view = self._searching = 0
        self._losses = self._refinds = self._chances = 0
        self._was_lost = False                    # the last sample of the blocks before
        self._lost_seen = 0                       # samples in view during that loss so far

    def add(self, log: Log) -> None:
        code, gap = log["walker_contact"], log["walker_gap_m"]
        for c in self._contacts:
            self._contacts[c] += int(np.count_nonzero(code == c))
        if np.any(np.isfinite(gap)):
            low = float(np.nanmin(gap))
            self._min_gap = low if self._min_gap is None else min(self._min_gap, low)
        self._walker_intimate += int(np.count_nonzero(gap < INTIMATE_M))
        person = log["person_gap_m"]
        self._intimate += int(np.count_nonzero(person < INTIMATE_M))
        self._personal += int(np.count_nonzero((person >= INTIMATE_M) & (person < PERSONAL_M)))
        rows = np.vstack((log["t"], log["robot_x"], log["robot_y"], log["robot_v"]))
        path = rows
        if self._prev is not None:             # the last two rows of the blocks before
            rows = np.hstack((self._prev, rows))
            path = rows[:, len(self._prev[0]) - 1:]
        if rows.shape[1] >= 2 and not self._dt:
            self._dt = float(rows[0, 1] - rows[0, 0])
        self._length += float(np.sum(np.hypot(np.diff(path[1]), np.diff(path[2]))))
        if rows.shape[1] >= 3 and self._dt > 0:    # every window of three rows is a new one
            jerk = np.diff(rows[3], 2) / self._dt ** 2
            self._jerk_sq += float(np.sum(jerk * jerk))
            self._jerks += len(jerk)
        self._prev = rows[:, -2:]
        standing = np.abs(log["robot_v"]) < STANDING_MPS
        self._stops.add(standing)
        self._stops_walking.add(standing & (np.abs(log["person_v"]) >= WALKING_MPS))
        self._finding(log)

    def _finding(self, log: Log) -> None:
        if "reason" not in log.columns or "person_in_view" not in log.columns:
            return                                # a hand-made log without them
        reason = np.asarray(log["reason"], dtype=str)
        lost = (np.char.find(reason, "person_lost") >= 0) \
            | (np.char.find(reason, "reacquiring") >= 0)
        before = np.concatenate(([self._was_lost], lost[:-1]))
        start = lost & ~before
        self._losses += int(np.count_nonzero(start))
        self._refinds += int(np.count_nonzero(~lost & before))
        # a chance to re-find: a loss during which the person was in view for REFIND_VIEW_S
        run = np.cumsum(start)                     # 0: the loss carried from before
        seen = np.bincount(run[lost & (log["person_in_view"] > 0.5)],
                           minlength=int(run[-1]) + 1 if len(run) else 1)
        carried = self._lost_seen if self._was_lost else 0
        seen[0] += carried
        need = (REFIND_VIEW_S / self._dt if self._dt else math.inf) - 1e-9
        chance = seen >= need
        chance[0] &= self._was_lost and carried < need   # a carried loss counts once
        self._chances += int(np.count_nonzero(chance))
        if len(lost):
            self._was_lost = bool(lost[-1])
            self._lost_seen = int(seen[int(run[-1])]) if self._was_lost else 0
        self._searching += int(np.count_nonzero(np.char.find(reason, "search_") >= 0))
        self._in_view += int(np.count_nonzero(log["person_in_view"] > 0.5))
        self._samples += len(reason)

    def value(self) -> dict:
        dt = self._dt
        return {"walker_contacts_robot": self._contacts[1.0],
                "walker_contacts_walker": self._contacts[2.0],
                "min_walker_gap_m": self._min_gap,
                "walker_intimate_s": self._walker_intimate * dt,
                "person_intimate_s": self._intimate * dt,
                "person_personal_s": self._personal * dt,
                "path_length_m": self._length,
                "jerk_rms_mps3": math.sqrt(self._jerk_sq / self._jerks) if self._jerks
                else 0.0,
                "longest_stop_s": self._stops.longest * dt,
                "longest_stop_person_walking_s": self._stops_walking.longest * dt,
                "person_in_view_share": self._in_view / self._samples if self._samples
                else None,
                "person_losses": self._losses,
                "person_refinds": self._refinds,
                "person_refind_chances": self._chances,
                "search_time_s": self._searching * dt}
