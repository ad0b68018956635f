"""The delays the stack sees, measured: how old the person detections are when they arrive,
and how fast the base follows its commands (docs/sensing.md, "Delays measured").

The sensing profile declares both (``person_latency_s``, ``actuator_tau_s``); a robot's
transport and timers add what no profile knows. :class:`DelayMeter` measures them from what
the supervisor sees every step: a detection's age is its arrival time minus its stamp; the
base's lag is the first-order time constant that best explains each new odometry sample's
velocity moving towards the command sent last before the previous sample,
``u - v[k] = a (u - v[k-1])`` with ``a = exp(-dt / tau)`` (``dt`` the time between the two
samples), fitted by least squares with exponential forgetting; a command that reaches the
base late shows as a longer lag. Until enough has been seen (and without odometry) the
declared values stand; measured values are kept within bounds.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Sequence

from companion.params import Params
from companion.types import PersonDetection

#: Time constant (s) over which the running estimates forget.
MEMORY_S = 5.0
#: Largest actuator time constant (s) the meter reports.
MAX_TAU_S = 1.0
#: Smallest gap (m/s, rad/s) between command and velocity that tells anything of the lag.
MIN_GAP = (0.02, 0.02)
#: Detections and lag samples needed before a measured value replaces the declared one.
MIN_SAMPLES = 10
#: Measured values are rounded to this (s), so the parameters change only now and then.
QUANTUM_S = 0.005


class DelayMeter:
    """Running estimates of the detection latency and the actuator lag; :meth:`params`
    gives ``params`` with them in place of the declared ones."""

    def __init__(self, params: Params):
        self.declared = params
        self.reset()

    def reset(self) -> None:
        self._age = self._age_w = 0.0
        self._sxy = self._sxx = 0.0
        self._n_age = self._n_lag = 0
        self._last: tuple[float, float] | None = None   # the last odometry: stamp, velocity
        self._sent: deque[tuple[float, tuple[float, float]]] = deque()   # time sent, (v, w)
        self._cache: tuple[tuple[float, float], Params, Params] | None = None

    def detections(self, arrived: Sequence[PersonDetection], now: float) -> None:
        """Note the age of every detection that arrived by ``now`` (s)."""
        forget = math.exp(-self.declared.dt / MEMORY_S)
        for d in arrived:
            age = now - d.t
            if math.isfinite(age) and 0.0 <= age <= self.declared.tracker.max_delay_s:
                self._age = forget * self._age + age
                self._age_w = forget * self._age_w + 1.0
                self._n_age += 1

    def sent(self, t: float, command: tuple[float, float]) -> None:
        """Note the command ``(v, omega)`` sent at ``t`` (s)."""
        self._sent.append((t, command))
        while len(self._sent) > 2 and self._sent[1][0] < t - 1.0:
            self._sent.popleft()

    def motion(self, stamp: float, velocity: tuple[float, float] | None) -> None:
        """Note the measured velocity ``(v, omega)`` of the odometry sample of time ``stamp``
        (None: no odometry); a sample already seen is ignored."""
        if velocity is None or not all(map(math.isfinite, (*velocity, stamp))):
            self._last = None
            return
        last = self._last
        if last is not None and stamp <= last[0]:
            return
        self._last = (stamp, velocity)
        if last is None:
            return
        (t0, v0), dt = last, stamp - last[0]
        if not 0.5 * self.declared.dt <= dt <= 1.5 * self.declared.dt:
            return      # a sample missed: two commands acted in between
        command = next((u for t, u in reversed(self._sent) if t <= t0 + 1e-9), None)
        if command is None:
            return
        forget = math.exp(-dt / MEMORY_S)
        for u, a0, a1, gap in zip(command, v0, velocity, MIN_GAP):
            x, y = u - a0, u - a1
            if abs(x) < gap:
                continue
            decay = min(max(y / x, 0.0), 1.0) ** (self.declared.dt / dt)   # over one period
            self._sxy = forget * self._sxy + x * x * decay
            self._sxx = forget * self._sxx + x * x
            self._n_lag += 1

    @property
    def latency(self) -> float | None:
        """The measured age of the detections at arrival (s), or None."""
        if self._n_age < MIN_SAMPLES or self._age_w <= 0.0:
            return None
        top = self.declared.tracker.max_delay_s - QUANTUM_S   # the tracker's own bound
        return min(max(self._age / self._age_w, 0.0), top)

    @property
    def tau(self) -> float | None:
        """The measured actuator time constant (s), or None."""
        if self._n_lag < MIN_SAMPLES or self._sxx <= 0.0:
            return None
        a = self._sxy / self._sxx
        if a <= 0.0:
            return 0.0
        if a >= math.exp(-self.declared.dt / MAX_TAU_S):
            return MAX_TAU_S
        return -self.declared.dt / math.log(a)

    def params(self, params: Params) -> Params:
        """``params`` with the measured latency and lag in its sensing (the declared ones
        where nothing is measured yet), rounded to :data:`QUANTUM_S`."""
        s = params.sensing
        latency, tau = self.latency, self.tau
        values = (s.person_latency_s if latency is None else round(latency / QUANTUM_S)
                  * QUANTUM_S,
                  s.actuator_tau_s if tau is None else round(tau / QUANTUM_S) * QUANTUM_S)
        if values == (s.person_latency_s, s.actuator_tau_s):
            return params
        if self._cache is not None and self._cache[0] == values and self._cache[1] is params:
            return self._cache[2]
        measured = params.replace(sensing=dataclasses.replace(
            s, person_latency_s=values[0], actuator_tau_s=values[1]))
        self._cache = (values, params, measured)
        return measured
