"""The person tracker: timestamped detections -> the person's state at the control instant.

Detections are checked (finite, known frame, not from the future, not stale), gated by the
Mahalanobis distance of their position (another person, or an identity switch, falls
outside), and merged in time order into the walker filter (:mod:`.walker`): a late
detection re-filters the detections after it. Between detections the track is predicted;
after ``lost_after_s`` s without one, or when its position grows too uncertain, the person is
lost, and a new track needs ``reacquire_time_s`` s of consistent detections where the lost
track may have gone (or that a re-identification hook accepts). Detections that
give no covariance take the declared sensing's noise; the position variance is then scaled,
within bounds, by how far the detections fall from the prediction on average (a detector
noisier than it declares). While detections fall farther from the prediction than
the filter expects (a manoeuvre its models did not foresee), the reported position covariance
is widened to match. An exact full-state detection
(all stds 0, an ideal sensor) sets the state exactly. docs/sensing.md explains the choices.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from companion.geometry import major_std, segment_point, wrap_pi
from companion.params import SensingParams, TrackerParams
from companion.tracking.motion import (
    MAX_DETECTIONS,
    Motion,
    motion_nis,
    motion_of,
    without_motion,
)
from companion.tracking.walker import (
    Belief,
    WalkerFilter,
    formation_person,
    position_cov,
    position_nis,
    predict,
    widened,
)
from companion.types import PersonDetection, PersonEstimate, PersonState, Pose

#: Largest plausible coordinate (m) and standard deviation (m, rad, m/s) of a detection.
MAX_COORDINATE = 1e6

#: The re-identification hook: given a detection after a loss and the person as last
#: tracked, True (it is the person), False (it is not) or None (let the prediction decide).
Reidentify = Callable[[PersonDetection, PersonState], "bool | None"]


def _plausible(d: PersonDetection) -> bool:
    """Finite, with coordinates and uncertainties a person detector could give."""
    values = [d.t, *(d.covariance or ()), *(d.velocity_std or ())]
    values += [v for v in (d.heading, d.heading_std, d.speed, d.turn_rate) if v is not None]
    return (all(math.isfinite(v) for v in values)
            and abs(d.x) <= MAX_COORDINATE and abs(d.y) <= MAX_COORDINATE
            and all(abs(v) <= MAX_COORDINATE for v in (*(d.covariance or ()), d.heading_std or 0.0,
                                                       *(d.velocity_std or ()))))


@dataclass(frozen=True)
class _Posterior:
    """The filter after applying ``detection`` (kept for re-filtering late detections)."""

    t: float
    detection: PersonDetection
    belief: Belief
    inflation: float = 1.0     # the widening of the reported position covariance
    noise_scale: float = 1.0   # the learned factor on the detections' position variance
    trusted: bool = True               # the detection's reported motion was used
    motion: Motion | None = None       # what it brings to the motion check (.motion)


class PersonTracker:
    """See the module docstring. Drive it with :meth:`add` and :meth:`estimate` once per
    control step; ``reacquired`` is True after a step that ended an outage, and
    ``innovations`` holds the position NIS of each detection the last :meth:`add` applied
    (its squared Mahalanobis distance from the prediction: chi-square with 2 degrees of
    freedom for an honest filter), ``others`` the detections it took for other people (seen
    together with the person, outside the gate). ``sensing`` is what the detector declares (default
    ``realistic``); ``reidentify`` (:data:`Reidentify`) decides, where it returns a bool,
    whether a detection after a loss is the person."""

    def __init__(self, params: TrackerParams, sensing: SensingParams | None = None,
                 reidentify: Reidentify | None = None):
        self._filter = WalkerFilter(params, sensing)
        self.params = self._filter.params
        self.reidentify = reidentify
        self.reset()

    def reset(self) -> None:
        self._history: list[_Posterior] = []   # posteriors within max_delay_s, in time order
        self._candidate: list[PersonDetection] = []   # consistent detections while lost
        self._walking: float | None = None            # heading of the last walking estimate
        self.lost = False
        self.reacquired = False
        self.innovations: list[float] = []
        self.others: list[PersonDetection] = []

    @property
    def noise_scale(self) -> float:
        """The factor on the detections' position variance learned so far (1 unless
        ``adapt_noise_max`` > 1)."""
        return self._history[-1].noise_scale if self._history else 1.0

    @property
    def reacquiring(self) -> bool:
        return self.lost and bool(self._candidate)

    # -- detections -------------------------------------------------------------------------

    def add(self, detections: Sequence[PersonDetection], now: float,
            pose_at: Callable[[float], Pose] | None = None,
            reasons: list[str] | None = None) -> None:
        """Take the detections that arrived by ``now`` (s, the sensor clock). ``pose_at(t)``
        gives the robot pose at time ``t`` for detections in the robot frame. What was wrong
        with a detection is appended to ``reasons``."""
        reasons = [] if reasons is None else reasons
        self.reacquired = False
        self.innovations = []
        self.others = []
        good = [d for d in (self._checked(d, now, pose_at, reasons) for d in detections)
                if d is not None]
        for t in sorted({d.t for d in good}):
            self._add_group([d for d in good if d.t == t], reasons)

    def _checked(self, d: PersonDetection, now: float,
                 pose_at: Callable[[float], Pose] | None,
                 reasons: list[str]) -> PersonDetection | None:
        """The detection in the world frame with plausible rates, or None (reason given)."""
        p = self.params
        if not _plausible(d):
            reasons.append("person_invalid")
            return None
        if d.t > now + p.future_tolerance_s:
            reasons.append("detection_future")
            return None
        if d.t < now - p.max_delay_s:
            reasons.append("detection_stale")
            return None
        if d.frame == p.robot_frame and pose_at is not None:
            r = pose_at(d.t)
            c, s = math.cos(r.theta), math.sin(r.theta)
            cov = d.covariance
            if cov is not None:   # rotate the covariance with the frame: R C R'
                rot = np.array(((c, -s), (s, c)))
                cov = tuple((rot @ np.reshape(cov, (2, 2)) @ rot.T).ravel())
            d = dataclasses.replace(
                d, x=r.x + c * d.x - s * d.y, y=r.y + s * d.x + c * d.y, frame=p.world_frame,
                covariance=cov, heading=None if d.heading is None else d.heading + r.theta)
            if not _plausible(d):             # no valid robot pose at the detection's time
                reasons.append("person_invalid")
                return None
        elif d.frame != p.world_frame:
            reasons.append("detection_frame")
            return None
        clipped = {}
        if d.speed is not None and abs(d.speed) > p.max_person_speed:
            clipped["speed"] = math.copysign(p.max_person_speed, d.speed)
        if d.turn_rate is not None and abs(d.turn_rate) > p.max_person_turn_rate:
            clipped["turn_rate"] = math.copysign(p.max_person_turn_rate, d.turn_rate)
        if clipped:
            reasons.append("person_rate_clipped")
            d = dataclasses.replace(d, **clipped)
        return d

    def _add_group(self, group: list[PersonDetection], reasons: list[str]) -> None:
        """Detections taken at one time: the best gated one updates the track."""
        t = group[0].t
        if self._history and not self.lost and t - self._history[-1].t > self.params.lost_after_s:
            self.lost, self._candidate = True, []     # too long since the last one
        if not self._history or self.lost:
            self._reacquire(group, reasons)
            return
        before = [h for h in self._history if h.t < t]
        if not before:                        # older than everything kept: too late to use
            reasons.append("detection_stale")
            return
        later = [h for h in self._history if h.t >= t]
        self._history = before
        prior = self._predicted(before[-1], t)
        best = self._best(before[-1], prior, group)
        if best is None:                      # did a wrong velocity carry the prior off?
            nearest = min(group, key=lambda d: math.hypot(d.x - prior.x[0], d.y - prior.x[1]))
            if not self._motion_agrees(motion_of(nearest, self.params)):
                self._without_motion()
                prior = self._predicted(self._history[-1], t)
                best = self._best(self._history[-1], prior, group)
        if best is None:                      # a lone jump: a glitch as likely as someone
            reasons.append("person_outlier")
            self._history += later
            return
        self.others += [d for d in group if d is not best]
        motion = motion_of(best, self.params)
        trusted = self._motion_agrees(motion)
        if not trusted:
            reasons.append("person_motion_inconsistent")
            self._without_motion()
            prior = self._predicted(self._history[-1], t)
        self._apply(best, prior, trusted=trusted, motion=motion)
        for h in later:                       # re-filter what came after a late detection
            self._apply(h.detection, self._predicted(self._history[-1], h.t), again=True,
                        trusted=h.trusted and trusted, motion=h.motion)
        horizon = self._history[-1].t - self.params.max_delay_s
        self._history = [h for h in self._history if h.t >= horizon] or self._history[-1:]

    def _best(self, base: _Posterior, prior: Belief,
              group: list[PersonDetection]) -> PersonDetection | None:
        """The detection of ``group`` nearest to the track's ``prior`` (``base`` predicted to
        the group's time), if it is inside the gate."""
        p = self.params
        x, cov = prior.x, prior.p
        dt = group[0].t - base.t
        best, best_d2 = None, p.gate_chi2
        for d in group:
            if math.hypot(d.x - x[0], d.y - x[1]) \
                    > p.max_person_speed * dt + p.gate_floor_m + 3 * _std(d, p):
                continue
            d2 = position_nis(x, cov, d, p, floor=p.gate_floor_m, scale=base.noise_scale)
            if d2 <= best_d2:
                best, best_d2 = d, d2
        return best

    def _predicted(self, base: _Posterior, t: float) -> Belief:
        """``base`` predicted to time ``t``."""
        return self._filter.predict(base.belief, t - base.t)

    def _apply(self, d: PersonDetection, prior: Belief, again: bool = False,
               trusted: bool = True, motion: Motion | None = None) -> None:
        """Append the ``prior`` updated with ``d`` (not ``trusted``: its position only;
        ``again``: re-filtered after a late detection, its NIS already reported)."""
        last = self._history[-1]
        scale = last.noise_scale
        nis = position_nis(prior.x, prior.p, d, self.params, scale=scale)
        if math.isfinite(nis) and not again:
            self.innovations.append(nis)
        used = d if trusted else without_motion(d)
        self._history.append(_Posterior(d.t, d, self._filter.update(prior, used, scale),
                                        self._inflation(last, d, nis),
                                        self._adapted(last, prior, d), trusted,
                                        motion or motion_of(d, self.params)))

    def _motion_agrees(self, m: Motion) -> bool:
        """The reports of the kept detections and ``m`` agree with their positions (.motion)."""
        p = self.params
        window = [h.motion for h in self._history[1 - MAX_DETECTIONS:]] + [m]
        return not m.reported \
            or motion_nis(window, p.motion_floor_mps, self.noise_scale) <= p.motion_gate_chi2

    def _without_motion(self) -> None:
        """Re-filter the kept detections for their positions alone (their reports are wrong)."""
        if not any(h.trusted and h.motion.reported for h in self._history):
            return
        kept = self._history
        self._history = [dataclasses.replace(self._start(without_motion(kept[0].detection)),
                                             detection=kept[0].detection, trusted=False,
                                             motion=kept[0].motion)]
        for h in kept[1:]:
            self._apply(h.detection, self._predicted(self._history[-1], h.t), again=True,
                        trusted=False, motion=h.motion)

    def _inflation(self, last: _Posterior, d: PersonDetection, nis: float) -> float:
        """How much wider than the filter's the reported position covariance is after ``d``:
        ``d``'s NIS over ``inflate_nis`` if that is more than the ``last`` detection's
        widening, decayed over the time between them, else the latter (at least 1). The
        filter itself is not widened: its mean stays as smooth as on an ordinary walk, only
        the keep-out rules see the doubt."""
        p = self.params
        held = 1.0 + (last.inflation - 1.0) * math.exp(-(d.t - last.t) / p.inflate_time_s)
        return max(held, nis / p.inflate_nis) if math.isfinite(nis) else held

    def _adapted(self, last: _Posterior, prior: Belief, d: PersonDetection) -> float:
        """The factor on the detections' position variance after ``d``: ``last``'s, moved
        towards what ``d``'s innovation says (``(|e|^2 - tr P) / tr R``, whose mean is the
        true factor while the filter's prediction is honest), averaged over
        ``adapt_time_s`` and kept in [1, ``adapt_noise_max``]. One
        sample moves it at most as far as ``adapt_noise_max`` times its value, so a
        manoeuvre or an outlier cannot make the detections look noisier at once."""
        p = self.params
        k = p.adapt_noise_max
        if k == 1.0 or d.covariance is not None and not any(d.covariance):
            return last.noise_scale
        e2 = (d.x - prior.x[0]) ** 2 + (d.y - prior.x[1]) ** 2
        r = float(np.trace(position_cov(d, p)))
        sample = (e2 - float(prior.p[0, 0] + prior.p[1, 1])) / r if r > 0.0 else 1.0
        if not math.isfinite(sample):
            return last.noise_scale
        sample = min(max(sample, 0.0), k * last.noise_scale)
        w = 1.0 - math.exp(-(d.t - last.t) / p.adapt_time_s)
        return min(max(last.noise_scale + w * (sample - last.noise_scale), 1.0), k)

    def _start(self, d: PersonDetection) -> _Posterior:
        """A new track at ``d``, keeping what was learned of the detector's noise."""
        scale = self._history[-1].noise_scale if self._history else 1.0
        return _Posterior(d.t, d, self._filter.start(d), noise_scale=scale,
                          motion=motion_of(d, self.params))

    def _reacquire(self, group: list[PersonDetection], reasons: list[str]) -> None:
        """No track (or lost): the first detection starts one; after a loss, detections must
        be where the person may have gone (:meth:`_refound`) and agree with each other for
        ``reacquire_time_s`` first."""
        p = self.params
        if not self._history and not self.lost:        # the first detection of an episode
            self._history = [self._start(group[0])]
            return
        group = [d for d in group if self._refound(d, reasons)]
        if not group:
            return
        last = self._candidate[-1] if self._candidate else None
        d = group[0]
        if last is not None:
            near = min(group, key=lambda g: math.hypot(g.x - last.x, g.y - last.y))
            dt = near.t - last.t
            if dt > 0.0 and math.hypot(near.x - last.x, near.y - last.y) \
                    <= p.max_person_speed * dt + p.gate_floor_m and dt <= p.lost_after_s:
                self._candidate.append(near)
                if near.t - self._candidate[0].t >= p.reacquire_time_s - 1e-9:
                    self._history = [self._start(self._candidate[0])]
                    for c in self._candidate[1:]:
                        self._apply(c, self._predicted(self._history[-1], c.t))
                    self._candidate, self.lost, self.reacquired = [], False, True
                return
        self._candidate = [d]

    def _refound(self, d: PersonDetection, reasons: list[str]) -> bool:
        """Whether ``d`` may be the lost person: what the re-identification hook says if it
        says so, else whether ``d`` is within the re-find gate of the way the lost track
        predicted the person to go, from where it was last seen to where its velocity takes
        it (``refind_spread_mps``, ``refind_horizon_s``)."""
        if not self._history:
            return True
        p, last = self.params, self._history[-1]
        x = last.belief.x
        if self.reidentify is not None:
            try:
                verdict = self.reidentify(d, PersonState(float(x[0]), float(x[1]),
                                                         math.atan2(x[3], x[2]),
                                                         math.hypot(x[2], x[3]), float(x[4])))
            except Exception:                 # a user's hook must not stop the robot
                verdict = None
                reasons.append("reidentify_failed")
            if verdict is not None:
                return bool(verdict)
        dt = max(d.t - last.t, 0.0)
        ahead = min(dt, p.refind_horizon_s)
        gx, gy = segment_point(d.x, d.y, x[0], x[1], x[0] + x[2] * ahead, x[1] + x[3] * ahead)
        return math.hypot(d.x - gx, d.y - gy) <= p.gate_floor_m + p.refind_spread_mps * dt

    # -- the estimate --------------------------------------------------------------------------

    def estimate(self, now: float, reasons: list[str] | None = None) -> PersonEstimate | None:
        """The person at ``now`` (s, the sensor clock), or None when there is no track or the
        person is lost (then :attr:`lost` is set)."""
        p = self.params
        reasons = [] if reasons is None else reasons
        if not self._history or self.lost:
            if self._candidate and now - self._candidate[-1].t > p.lost_after_s:
                self._candidate = []   # the detections of a re-find stopped: lost again
            return None
        last = self._history[-1]
        age = now - last.t
        if age < -p.future_tolerance_s:       # the clock went back past the track: start over
            self.reset()
            self.lost = True
            return None
        if age > p.lost_after_s:
            self.lost, self._candidate = True, []
            return None
        belief = self._predicted(last, now)
        x, cov = belief.x, belief.p
        std = major_std(cov)
        if std > p.max_position_std_m:
            self.lost, self._candidate = True, []
            return None
        status = "seen" if age <= p.coast_after_s else "predicted"
        if status == "predicted":
            reasons.append("person_predicted")
        k = last.inflation
        if std * math.sqrt(k) > p.uncertain_std_m:
            reasons.append("person_uncertain")
        if last.belief.exact:                 # an ideal sensor: exactly as detected
            d = last.detection
            heading, v = (d.heading, d.speed) if d.speed >= 0.0 else (d.heading + math.pi,
                                                                       -d.speed)
            state = predict(PersonState(d.x, d.y, wrap_pi(heading), v, d.turn_rate), age)
            return PersonEstimate(state, std, cov, age, status, state)
        state = PersonState(float(x[0]), float(x[1]), math.atan2(x[3], x[2]),
                            math.hypot(x[2], x[3]), float(x[4]))
        walker, self._walking = formation_person(state, cov, self._walking, p)
        return PersonEstimate(state, std * math.sqrt(k), widened(cov, k), age, status, walker)


def _std(d: PersonDetection, p: TrackerParams) -> float:
    if d.covariance is None:
        return p.position_std_m
    return math.sqrt(max(d.covariance[0], d.covariance[3], 0.0))
