"""Closed-loop episode: person motion, sensing, controller and the robot's base (its plant).

:class:`Simulator` is the world of one episode, steppable from outside: ``reset(seed)`` gives
the first observation, ``step(command)`` applies a command for one period and gives the next.
At each sample ``k`` (time ``t_k = k * dt``) the robot observes its pose and velocity (the
plant's odometry, :mod:`companion.sim.plant`), the person detections that have arrived
(:class:`~companion.sim.sensing.PersonSensor`) and the obstacles it knows, as the active faults
corrupt them; the command is held for one period while the plant moves: the kinematic
unicycle's actual velocities follow it through the first-order lag ``sensing.actuator_tau_s``
along the arc of the period's mean velocity (exact without lag,
:func:`companion.geometry.base_step`); the MuJoCo base turns its wheels. What the robot senses
is seen from its true pose and handed over in its odometry frame. Row ``k`` of the log holds
the true state at ``t_k``, the command applied from ``t_k`` on and the tracker's estimate.
:func:`episode_blocks` drives a simulator with a controller. The episode is deterministic for a
given seed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence

import numpy as np

from companion.control.base import Controller
from companion.control.supervisor import SafetySupervisor
from companion.errors import ConfigError
from companion.geometry import clearance
from companion.model import robot_pose_at, slot_reference
from companion.params import IDEAL, Params
from companion.sim.crowd import WALKER_RADIUS, Crowd
from companion.sim.faults import Fault, stalled
from companion.sim.faults import apply as apply_faults
from companion.sim.person import PersonMotion
from companion.sim.plant import FrameShift, make_plant
from companion.sim.recorder import Recorder, Sample
from companion.sim.sensing import GroundTruth, Perception, PersonSensor, in_view, streams
from companion.types import Command, Log, Observation, Obstacle, PersonState, Pose, StepReport

#: Closing speed (m/s) of the robot's own motion above which a step inside the protective
#: distance, or into a contact, is robot-caused.
TOLERANCE = 0.01


def start_in_slot(person: PersonState, params: Params) -> Pose:
    """Robot pose in its desired slot, heading aligned with the person's (beta = 0)."""
    f = params.formation
    return Pose(*robot_pose_at(f.distance, f.bearing, 0.0, person.x, person.y, person.theta,
                               params.robot.d))


def nearest_clearance(x: float, y: float, obstacles: Sequence[Obstacle], footprint: float
                      ) -> float:
    """Smallest clearance from a footprint at (x, y) to any obstacle (NaN if none)."""
    if not obstacles:
        return math.nan
    return min(clearance(ob, x, y, footprint) for ob in obstacles)


def timed_out(command: tuple[float, float], params: Params) -> tuple[float, float]:
    """One period of a base whose commands stopped coming: ``command`` brought towards a stop
    at the supervisor's deceleration limits."""
    s, dt = params.supervisor, params.dt

    def towards_zero(x: float, rate: float) -> float:
        return math.copysign(max(abs(x) - rate * dt, 0.0), x)

    return towards_zero(command[0], s.decel_max), towards_zero(command[1], s.angular_accel_max)


#: Rows per block of :func:`episode_blocks` (about 0.9 MB of numbers).
BLOCK_ROWS = 4096


def run_episode(controller: Controller, person: PersonMotion, params: Params,
                duration: float, start: Pose | None = None, seed: int = 0,
                obstacles: Sequence[Obstacle] = (), perception: Perception | None = None,
                faults: Sequence[Fault] = (),
                start_velocity: tuple[float, float] | None = None) -> Log:
    """Simulate ``duration`` seconds and return the whole log: the blocks of
    :func:`episode_blocks` (same parameters) joined."""
    return Log.concat(episode_blocks(controller, person, params, duration, start, seed,
                                     obstacles, perception, faults, start_velocity))


def episode_blocks(controller: Controller, person: PersonMotion, params: Params,
                   duration: float, start: Pose | None = None, seed: int = 0,
                   obstacles: Sequence[Obstacle] = (), perception: Perception | None = None,
                   faults: Sequence[Fault] = (),
                   start_velocity: tuple[float, float] | None = None,
                   rows: int = BLOCK_ROWS) -> Iterator[Log]:
    """Simulate ``duration`` seconds, yielding the log in consecutive blocks of ``rows`` rows
    (the last one shorter), so that a long episode can go to disk as it runs.

    Parameters
    ----------
    controller : Controller
        Reset before the first step. The standard stack (a
        :class:`~companion.control.supervisor.SafetySupervisor`) gets the person detections
        of ``params.sensing`` and its step reports go into the log; any other controller gets
        the true person state, which needs ideal sensing.
    person : PersonMotion
    params : Params
    duration : float
        Simulated time (s); ``round(duration / dt)`` steps are run.
    start : Pose, optional
        Robot start; default: in the desired slot, aligned with the person, already walking
        with it (its velocity the slot's, its tracker handed the person's state).
    start_velocity : (v, omega), optional
        The robot's velocity at the start, told to the controller (``controller.applied``) so
        that its acceleration limits start from it. Default: with ``start`` None, the slot
        velocity; with a ``start``, at rest.
    seed : int
        Seed of the sensing noise.
    obstacles : sequence of Circle or Wall
        The world's static obstacles.
    perception : Perception, optional
        How the controller learns about obstacles; default: it sees ``obstacles`` exactly.
    faults : sequence of Fault
        Faults injected into what the controller observes (:mod:`companion.sim.faults`).
    rows : int
        Rows per block (>= 1).

    Raises
    ------
    ConfigError
        For a duration shorter than one period or sensing the controller cannot use.
    """
    stack = isinstance(controller, SafetySupervisor)
    sim = Simulator(person, params, duration, start, obstacles, perception, faults,
                    start_velocity, stack)
    if not stack and params.sensing != IDEAL:
        raise ConfigError("sensing: a controller without the standard stack sees the true "
                          "person state, which needs ideal sensing")
    if not stack and not isinstance(sim.perception, GroundTruth):
        raise ConfigError("obstacle_source: a controller without the standard stack has no "
                          "perception front end to read a LiDAR; it needs truth")

    def started(sim: Simulator) -> None:
        controller.reset()
        if sim.start_velocity is not None:
            controller.applied(Command(*sim.start_velocity))

    report = (lambda: controller.report) if stack else None
    return drive(sim, controller.step, seed, rows, started, report)


def drive(sim: Simulator, act: Callable[[Observation], Command | None], seed: int = 0,
          rows: int = BLOCK_ROWS, started: Callable[[Simulator], None] | None = None,
          report: Callable[[], StepReport] | None = None) -> Iterator[Log]:
    """Run ``sim`` from ``reset(seed)`` (then ``started(sim)``) to its end, asking ``act``
    for each sample's command (None: none came), except while a stall fault is active, and
    yield the log in blocks of ``rows`` rows; ``report()`` gives the step report of each new
    command (None: the command's status alone)."""
    if rows < 1:
        raise ConfigError(f"rows: expected a block of at least one row, got {rows}")
    return _drive(sim, act, seed, rows, started, report)


def _drive(sim: Simulator, act: Callable[[Observation], Command | None], seed: int,
           rows: int, started: Callable[[Simulator], None] | None,
           report: Callable[[], StepReport] | None) -> Iterator[Log]:
    obs = sim.reset(seed)
    if started is not None:
        started(sim)
    walkers = 0 if sim.crowd is None else sim.crowd.n
    recorder = Recorder(sim.params, min(rows, sim.steps), walkers)
    while obs is not None:
        cmd = None if sim.stalled else act(obs)
        obs = sim.step(cmd)
        recorder.add(sim.sample, None if cmd is None or report is None else report())
        if recorder.full() or obs is None:
            yield recorder.log()
            recorder.start(min(rows, sim.steps - sim.k), walkers)


class Simulator:
    """The world of one episode (person, sensing, obstacles, faults, the robot's base).

    ``detections``: the controller takes person detections (the standard stack); otherwise
    the observation carries the true person state. ``start``, ``start_velocity``: see
    :func:`companion.sim.episode.episode_blocks`.
    """

    def __init__(self, person: PersonMotion, params: Params, duration: float,
                 start: Pose | None = None, obstacles: Sequence[Obstacle] = (),
                 perception: Perception | None = None, faults: Sequence[Fault] = (),
                 start_velocity: tuple[float, float] | None = None, detections: bool = True):
        self.steps = int(round(duration / params.dt))
        if self.steps < 1:
            raise ConfigError(f"duration: expected at least one sample period "
                              f"({params.dt:g} s), got {duration:g} s")
        #: A crowd scene's walkers (the person motion is then the crowd), the episode's own.
        self.crowd = person.fresh() if isinstance(person, Crowd) else None
        self.person, self.params, self.start = self.crowd or person, params, start
        self.obstacles, self.faults = tuple(obstacles), tuple(faults)
        self.perception = perception or GroundTruth()
        self.detections = detections
        self._start_velocity = start_velocity
        self.plant = make_plant(params, self.obstacles)
        self.k = 0
        #: The true state of the last sample stepped and the command applied from it.
        self.sample: Sample | None = None

    def reset(self, seed: int = 0) -> Observation:
        """Start the episode over with the sensing noise of ``seed``; the first observation.
        :attr:`start_velocity` is then the velocity the robot starts with (None: at rest),
        which a controller should be told (``controller.applied``)."""
        p, f = self.params, self.params.formation
        self._rng = streams(seed)
        if self.crowd is not None:
            self.crowd.reset(self._rng["walkers"], p.robot.radius)
        self._walkers = _WalkerContacts(p)
        self._sensor = PersonSensor(p, self.person, self._rng["person_sensor"],
                                    self._rng["person_dropout"])
        self.perception.reset()
        self._handover: tuple = ()
        self.start_velocity = self._start_velocity
        if self.start is None:
            h0 = self.person.state(0.0)
            pose = start_in_slot(h0, p)
            ref = slot_reference(h0.v, h0.omega, f.distance, f.bearing, p.robot.d)
            self.start_velocity = self._start_velocity or (ref.v, ref.omega)
            self._handover = (self._sensor.handover(0.0),) if self.detections else ()
        else:
            pose = self.start
        self.plant.reset(pose, self.start_velocity or (0.0, 0.0))
        self._cmd = Command(0.0, 0.0)
        self._base = self.start_velocity or (0.0, 0.0)   # what the base executes
        self._last_command = 0.0
        self.k = 0
        self.sample = None
        return self._observe()

    @property
    def stalled(self) -> bool:
        """A ``stall`` fault is active now: the controller is not to be called."""
        return stalled(self.faults, self.k * self.params.dt)

    def _observe(self) -> Observation:
        """The observation of sample :attr:`k`, as the active faults corrupt it."""
        t = self.k * self.params.dt
        h = self.person.state(t)
        pose, odometry = self.plant.pose, self.plant.odometry
        world = self._blockers()
        self._in_view = in_view(pose, h, world, self.params.sensing)
        arrived = (*self._handover, *self._sensor.detections(t, self._in_view)) \
            if self.detections else ()
        self._handover = ()
        known, scan = self.perception.sense(self.k, pose, world, (h.x, h.y), self._rng["lidar"])
        shift = FrameShift(pose, odometry)
        if not shift.identity:       # seen from the true pose, told in the odometry frame
            known = tuple(shift.obstacle(o) for o in known)
            scan = None if scan is None else shift.scan(scan)
            arrived = tuple(shift.detection(d) for d in arrived)
            h = shift.person(h)
        obs = Observation(t, odometry, None if self.detections else h, known, scan,
                          self.plant.odometry_velocity, arrived)
        return apply_faults(obs, self.faults)

    def _blockers(self) -> tuple[Obstacle, ...]:
        """The world's obstacles now: the scenario's and the walkers'."""
        return self.obstacles if self.crowd is None else self.obstacles + self.crowd.circles()

    def step(self, command: Command | None) -> Observation | None:
        """Apply ``command`` from the current sample on (None: no new command, as from a
        stalled controller or a silent node: the last one stays in force until the base's
        command timeout, then the base brakes, logged as ``stopped: command_timeout``);
        the true state of this sample in :attr:`sample`; advance one period. The next
        observation, or None after the last sample."""
        if self.sample is not None and self.k >= self.steps:
            raise RuntimeError("step: the episode is over; reset() starts it again")
        p = self.params
        t = self.k * p.dt
        came = "new"
        if command is not None:
            self._cmd, self._base, self._last_command = command, (command.v, command.omega), t
        elif t - self._last_command >= p.robot.command_timeout_s - 1e-9:
            self._base = timed_out(self._base, p)
            self._cmd, came = Command(*self._base, 0.0, "stopped"), "timeout"
        else:
            came = "held"
        pose, (va, wa), h = self.plant.pose, self.plant.velocity, self.person.state(t)
        x, y, th = pose.x, pose.y, pose.theta
        walkers = None if self.crowd is None else self.crowd.positions[:-1].ravel().copy()
        self.sample = Sample(t, pose, (va, wa), h, self._cmd,
                             nearest_clearance(x, y, self.obstacles, p.robot.radius),
                             *self._walkers.sample(x, y, self.crowd), self._in_view, came,
                             walkers, self.plant.odometry, self.plant.contact)
        if self.crowd is not None:
            self.crowd.step((x, y, va * math.cos(th), va * math.sin(th)))
        self.plant.step(self._base, t, (h.x, h.y))
        self.k += 1
        return self._observe() if self.k < self.steps else None


class _WalkerContacts:
    """Per sample: the gap from the robot's footprint to the nearest walker's body (m, NaN
    without walkers) and whether a contact with a walker begins (1: the robot's own motion
    over the last period closed on that walker, as the fuzz counts robot-caused contacts;
    2: the walker's doing; 0: none)."""

    def __init__(self, params: Params):
        self.radius, self.dt = params.robot.radius, params.dt
        self._before: tuple[float, float, np.ndarray, np.ndarray] | None = None

    def sample(self, x: float, y: float, crowd: Crowd | None) -> tuple[float, float]:
        if crowd is None or crowd.n == 0:
            return math.nan, 0.0
        walkers = crowd.positions[:-1]
        gaps = np.hypot(walkers[:, 0] - x, walkers[:, 1] - y) - self.radius - WALKER_RADIUS
        code = 0.0
        if self._before is not None:
            bx, by, was, where = self._before
            entered = np.flatnonzero((gaps < 0.0) & (was >= 0.0))
            if len(entered):
                own = (np.hypot(where[entered, 0] - bx, where[entered, 1] - by)
                       - np.hypot(where[entered, 0] - x, where[entered, 1] - y)) / self.dt
                code = 1.0 if np.any(own > TOLERANCE) else 2.0
        self._before = (x, y, gaps, walkers.copy())
        return float(gaps.min()), code
