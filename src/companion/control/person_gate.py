"""The person estimate the controllers get: gated, predicted over short gaps, lost after a
timeout and reacquired only when consistent again (docs/safety.md, faults 1-3).

:class:`PersonGate` is a small state machine driven by the safety supervisor once per step:
``advance(elapsed)``, then ``update(estimate, reasons)`` with the new estimate (if the data
of this step count), then ``now(reasons)`` for the person to control against.
"""

from __future__ import annotations

import math

from companion.control.checks import finite
from companion.geometry import unicycle_step, wrap_pi
from companion.params import SupervisorParams
from companion.types import PersonState


def predict(person: PersonState, tau: float) -> PersonState:
    """The person ``tau`` seconds on at constant speed and turn rate (exact unicycle arc)."""
    x, y, th = unicycle_step(person.x, person.y, person.theta, person.v, person.omega, tau)
    return PersonState(x, y, wrap_pi(th), person.v, person.omega)


class PersonGate:
    """See the module docstring. ``reacquired`` is True after an :meth:`update` that ended an
    outage (the controller must then be reset)."""

    def __init__(self, params: SupervisorParams):
        self.params = params
        self.reset()

    def reset(self) -> None:
        self._track: PersonState | None = None
        self._age = math.inf          # s since the track was last confirmed
        self.lost = False             # the person was lost: reacquisition needed
        self._candidate: PersonState | None = None
        self._candidate_age = 0.0     # s since the last candidate estimate
        self._candidate_span = 0.0    # s over which the candidates agreed
        self.reacquired = False

    @property
    def reacquiring(self) -> bool:
        """Lost, with a candidate being checked for consistency."""
        return self.lost and self._candidate is not None

    def advance(self, elapsed: float) -> None:
        """Let ``elapsed`` seconds pass."""
        self._age += elapsed
        self._candidate_age += elapsed
        self.reacquired = False

    def _plausible(self, ref: PersonState, new: PersonState, elapsed: float) -> bool:
        s = self.params
        jump = math.hypot(new.x - ref.x, new.y - ref.y)
        return jump <= s.max_person_speed * elapsed + s.jump_tolerance

    def update(self, h: PersonState | None, reasons: list[str]) -> None:
        """Take a new estimate (None: missing), appending what was wrong with it to
        ``reasons``."""
        s = self.params
        if h is None:
            reasons.append("person_missing")
            return
        if not finite(h.x, h.y, h.theta, h.v, h.omega):
            reasons.append("person_invalid")
            return
        v = min(max(h.v, -s.max_person_speed), s.max_person_speed)
        w = min(max(h.omega, -s.max_person_turn_rate), s.max_person_turn_rate)
        if (v, w) != (h.v, h.omega):
            reasons.append("person_rate_clipped")
            h = PersonState(h.x, h.y, h.theta, v, w)
        if self._track is None and not self.lost:   # first estimate of the episode
            self._accept(h)
        elif self.lost:
            if self._candidate is not None and self._candidate_age <= s.person_timeout \
                    and self._plausible(self._candidate, h, self._candidate_age):
                self._candidate_span += self._candidate_age
            else:
                self._candidate_span = 0.0
            self._candidate, self._candidate_age = h, 0.0
            if self._candidate_span >= s.reacquire_time:
                self._accept(h)
        elif self._plausible(self._track, h, self._age):
            self._accept(h)
        else:
            reasons.append("person_outlier")

    def _accept(self, h: PersonState) -> None:
        self.reacquired = self.lost
        self._track, self._age, self.lost = h, 0.0, False
        self._candidate, self._candidate_span = None, 0.0

    def now(self, reasons: list[str]) -> PersonState | None:
        """The person to control against: the track, predicted if it is older than 0; None if
        there is none or it is older than the timeout (then the person is lost)."""
        if self._track is None or self.lost:
            return None
        if self._age > self.params.person_timeout:
            self.lost = True
            return None
        if self._age > 0.0:
            if not any(r.startswith("person_") for r in reasons):
                reasons.append("person_predicted")
            return predict(self._track, self._age)
        return self._track
