"""Adversarial inputs never give a non-finite or out-of-limit command (docs/safety.md).

A seeded fuzzer drives the standard stack (supervisor, avoidance, controller) of every
registered controller with observation streams that are mostly plausible (a person walking
near the robot, which moves by the commands) and corrupted at random: missing or non-finite
person and pose fields, identity switches, huge values, time steps that repeat, go backwards,
jump or are not finite, obstacles inside the footprint or with NaN, and LiDAR scans with NaN,
-inf and 0 returns. 100,000 steps in all; hypothesis adds shrinkable short streams.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.control import CONTROLLERS, make_controller
from companion.geometry import unicycle_step
from companion.params import Params
from companion.types import Circle, Observation, PersonState, Pose, Scan, Wall

P = Params()
LIMIT_V = max(P.supervisor.accel_max, P.supervisor.decel_max) * P.dt + 1e-9
LIMIT_W = P.supervisor.angular_accel_max * P.dt + 1e-9
STEPS = 100_000
WEIRD = (math.nan, math.inf, -math.inf, 1e12, -1e12, 0.0)


class Fuzzer:
    """A random but seeded stream of observations, corrupted now and then."""

    def __init__(self, seed: int):
        self.rng = np.random.default_rng(seed)
        self.t = 0.0
        self.pose = Pose(0.0, 0.0, 0.0)
        self.person = PersonState(0.25, 1.0, 0.0, 1.0, 0.0)

    def weird(self, x: float) -> float:
        return float(self.rng.choice(WEIRD)) if self.rng.random() < 0.3 else x

    def time(self) -> float:
        r = self.rng.random()
        if r < 0.9:
            self.t += P.dt
        elif r < 0.93:
            pass                                    # repeated stamp
        elif r < 0.96:
            self.t -= self.rng.uniform(0, 1.0)      # backwards
        elif r < 0.98:
            self.t += self.rng.uniform(0.2, 30.0)   # long gap
        else:
            return float(self.rng.choice((math.nan, math.inf, -math.inf)))
        return self.t

    def walk_person(self) -> None:
        h = self.person
        v = float(np.clip(h.v + self.rng.normal(0, 0.2), 0.0, 2.5))
        w = float(np.clip(h.omega + self.rng.normal(0, 0.5), -3.0, 3.0))
        th = h.theta + w * P.dt
        self.person = PersonState(h.x + v * P.dt * math.cos(th), h.y + v * P.dt * math.sin(th),
                                  math.remainder(th, 2 * math.pi), v, w)
        if math.hypot(h.x - self.pose.x, h.y - self.pose.y) > 5.0:   # keep it near the robot
            self.person = PersonState(self.pose.x + self.rng.uniform(-2, 2),
                                      self.pose.y + self.rng.uniform(-2, 2),
                                      self.rng.uniform(-3, 3), self.rng.uniform(0, 1.5), 0.0)

    def observed_person(self) -> PersonState | None:
        r = self.rng.random()
        h = self.person
        if r < 0.05:
            return None
        if r < 0.10:
            return PersonState(*(self.weird(x) for x in (h.x, h.y, h.theta, h.v, h.omega)))
        if r < 0.13:
            return PersonState(h.x + self.rng.uniform(-5, 5), h.y + self.rng.uniform(-5, 5),
                               h.theta, h.v, h.omega)
        if r < 0.15:   # right at the robot (rho ~ 0) or inside it
            return PersonState(self.pose.x + self.rng.uniform(-0.3, 0.3),
                               self.pose.y + self.rng.uniform(-0.3, 0.3), h.theta, h.v, h.omega)
        return h

    def observed_pose(self) -> Pose:
        if self.rng.random() < 0.05:
            return Pose(*(self.weird(x) for x in (self.pose.x, self.pose.y, self.pose.theta)))
        return self.pose

    def obstacles(self) -> tuple:
        out = []
        for _ in range(int(self.rng.integers(0, 3))):
            x = self.pose.x + self.rng.uniform(-3, 3)
            y = self.pose.y + self.rng.uniform(-3, 3)
            if self.rng.random() < 0.7:
                out.append(Circle(self.weird(x), y, self.weird(self.rng.uniform(0.0, 0.8))))
            else:
                out.append(Wall(x, y, self.weird(x + 2.0), y + 1.0))
        return tuple(out)

    def scan(self) -> Scan | None:
        if self.rng.random() < 0.5:
            return None
        n = 72
        ranges = self.rng.uniform(0.0, 10.0, n)
        ranges[self.rng.random(n) < self.rng.random()] = np.nan
        ranges[self.rng.random(n) < 0.3] = np.inf
        ranges[self.rng.random(n) < 0.02] = -np.inf
        return Scan(np.linspace(-math.pi, math.pi, n, endpoint=False), ranges, 0.0, 0.0, 0.0)

    def observation(self) -> Observation:
        self.walk_person()
        return Observation(self.time(), self.observed_pose(), self.observed_person(),
                           self.obstacles(), self.scan())

    def move(self, v: float, w: float) -> None:
        x, y, th = unicycle_step(self.pose.x, self.pose.y, self.pose.theta, v, w, P.dt)
        self.pose = Pose(x, y, math.remainder(th, 2 * math.pi))


def check(cmd, prev) -> None:
    assert math.isfinite(cmd.v) and math.isfinite(cmd.omega) and math.isfinite(cmd.u_ob)
    assert abs(cmd.v) <= P.robot.v_max + 1e-12 and abs(cmd.omega) <= P.robot.omega_max + 1e-12
    assert abs(cmd.v - prev[0]) <= LIMIT_V and abs(cmd.omega - prev[1]) <= LIMIT_W
    assert cmd.status in ("ok", "degraded", "stopped")


@pytest.mark.parametrize("name", sorted(CONTROLLERS))
def test_fuzzed_streams_give_finite_commands_within_limits(name):
    steps = STEPS // len(CONTROLLERS) + 1
    fuzz = Fuzzer(seed=sorted(CONTROLLERS).index(name))
    ctl = make_controller(name, P)
    ctl.reset()
    prev = (0.0, 0.0)
    statuses = set()
    for k in range(steps):
        if k % 2000 == 0:   # a new episode now and then
            ctl.reset()
            prev = (0.0, 0.0)
        cmd = ctl.step(fuzz.observation())
        check(cmd, prev)
        statuses.add(cmd.status)
        prev = (cmd.v, cmd.omega)
        fuzz.move(cmd.v, cmd.omega)
    assert statuses == {"ok", "degraded", "stopped"}   # the stream reached every status


finite_or_not = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                          st.floats(-10, 10))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.floats(allow_nan=True, allow_infinity=True),
                          st.tuples(finite_or_not, finite_or_not, finite_or_not),
                          st.one_of(st.none(), st.tuples(*[finite_or_not] * 5)),
                          st.lists(st.tuples(finite_or_not, finite_or_not,
                                             st.floats(0, 2)), max_size=2)),
                min_size=1, max_size=30))
def test_any_short_stream_gives_finite_commands_within_limits(stream):
    ctl = make_controller("lqr", P)
    ctl.reset()
    prev = (0.0, 0.0)
    for t, pose, person, circles in stream:
        obs = Observation(t, Pose(*pose), None if person is None else PersonState(*person),
                          tuple(Circle(x, y, r) for x, y, r in circles))
        cmd = ctl.step(obs)
        check(cmd, prev)
        prev = (cmd.v, cmd.omega)
