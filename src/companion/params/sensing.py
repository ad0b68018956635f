"""Parameters of sensing and perception (sections of :class:`Params`): the sensing profile,
the person tracker, the simulated LiDAR and the obstacle extractor (docs/sensing.md)."""

from __future__ import annotations

import dataclasses
import math

from companion.config import (
    Validated,
    at_least,
    at_least_one,
    non_negative,
    param,
    positive,
    positive_or_inf,
    ranged,
)
from companion.errors import ConfigError
from companion.geometry import TWO_PI


@ranged("(0, 2*pi]")
def _fov(x: float) -> str | None:
    return None if 0.0 < x <= TWO_PI + 1e-9 else "an angle in (0, 2*pi] rad"


@ranged("[0.0001, pi]")
def _resolution(x: float) -> str | None:
    return None if 1e-4 <= x <= math.pi else "an angle in [0.0001, pi] rad"


@ranged("[0, pi/2)")
def _breakpoint_angle(x: float) -> str | None:
    return None if 0.0 <= x < 0.5 * math.pi else "an angle in [0, pi/2) rad"


@ranged("[0, 1)")
def _dropout(x: float) -> str | None:
    return None if 0.0 <= x < 1.0 else "a probability in [0, 1)"


@ranged("(0, 1)")
def _probability(x: float) -> str | None:
    return None if 0.0 < x < 1.0 else "a probability in (0, 1)"


@dataclasses.dataclass(frozen=True)
class SensingParams(Validated):
    """What the robot senses and how its base answers (docs/sensing.md). The defaults are the
    ``realistic`` profile; :data:`IDEAL` is the perfect person state at every step."""

    person_rate_hz: float = param(10.0, "Hz", "person detections per second; inf: one at "
                                  "every control step", positive_or_inf)
    person_position_noise_m: float = param(0.05, "m", "standard deviation of the Gaussian "
                                           "noise on each detected coordinate", non_negative)
    person_declared_noise_m: float | None = param(None, "m", "the standard deviation the "
                                                  "detections' covariance states; absent: "
                                                  "person_position_noise_m (an honest "
                                                  "detector)", non_negative)
    person_heading_noise_rad: float | None = param(None, "rad", "standard deviation of the "
                                                   "noise on a detected heading; absent: no "
                                                   "heading is measured", non_negative)
    person_velocity_noise: float | None = param(None, "m/s, rad/s", "standard deviation of the "
                                                "noise on a detected speed and turn rate (a "
                                                "tracker or tag upstream); absent: not "
                                                "measured", non_negative)
    person_latency_s: float = param(0.1, "s", "a detection arrives this long after the moment "
                                    "it shows", non_negative)
    person_dropout: float = param(0.02, "-", "probability that a detection is lost", _dropout)
    actuator_tau_s: float = param(0.2, "s", "time constant of the first-order lag of the "
                                  "robot's actual v and omega behind the command; 0: none",
                                  non_negative)
    lidar_rate_hz: float = param(10.0, "Hz", "LiDAR scans per second (held between scans)",
                                 positive)
    person_range_m: float = param(math.inf, "m", "the simulated person detector sees the "
                                  "person only within this distance of the robot; inf: at any "
                                  "distance", positive_or_inf)
    person_occlusion: bool = param(False, "-", "the simulated person detector does not see "
                                   "the person behind a walker or an obstacle (the line from "
                                   "the robot to the person's centre blocked)")

    @property
    def declared_noise_m(self) -> float:
        """The position noise the detector declares (m)."""
        declared = self.person_declared_noise_m
        return self.person_position_noise_m if declared is None else declared


#: Today's simulation: the exact person state at every control step, no lag.
IDEAL = SensingParams(person_rate_hz=math.inf, person_position_noise_m=0.0,
                      person_heading_noise_rad=0.0, person_velocity_noise=0.0,
                      person_latency_s=0.0, person_dropout=0.0, actuator_tau_s=0.0)
#: A person detector like a LiDAR leg tracker or UWB tag, and a base with lag.
REALISTIC = SensingParams()
#: A sensor like the paper's: an electromagnetic tracker (transmitter on the robot, receiver
#: worn by the person, pose sent by Bluetooth) measuring position and heading; values from
#: what such trackers specify, degraded for a body-worn receiver about 1 m from a
#: robot-mounted source (docs/sensing.md). The base is ``realistic``'s.
EM_TRACKER = SensingParams(person_rate_hz=50.0, person_position_noise_m=0.01,
                           person_heading_noise_rad=math.radians(1.0),
                           person_latency_s=0.03, person_dropout=0.01)
#: Profiles by name (``companion run --sensing NAME``).
PROFILES = {"ideal": IDEAL, "realistic": REALISTIC, "em-tracker": EM_TRACKER}


@dataclasses.dataclass(frozen=True)
class TrackerParams(Validated):
    """The person tracker (:mod:`companion.tracking`): two coordinated-turn models of a walker
    (steady, manoeuvre) in an interacting multiple model of unscented Kalman filters, gated
    detections and the track's status."""

    world_frame: str = param("world", "-", "name of the frame of the robot pose; detections "
                             "in it are taken as they are")
    robot_frame: str = param("robot", "-", "name of the robot's own frame; detections in it "
                             "are moved to the world frame with the robot pose at their time")
    position_std_m: float | None = param(None, "m", "standard deviation of a detected "
                                         "coordinate when the detection gives no covariance; "
                                         "absent: the noise the sensing declares "
                                         "(person_declared_noise_m, else "
                                         "person_position_noise_m), or 0.05 where it "
                                         "declares 0", positive)
    heading_std_rad: float | None = param(None, "rad", "standard deviation of a detected "
                                          "heading when the detection gives none; absent: the "
                                          "declared sensing's person_heading_noise_rad, or "
                                          "0.1 where it declares none", positive)
    adapt_noise_max: float = param(1.0, "-", "the tracker scales the detections' position "
                                   "variance by a factor it learns from their innovations "
                                   "(how far they fall from the prediction), kept in [1, this]: "
                                   "a detector noisier than it declares (5 with adapt_time_s "
                                   "2 measured in docs/sensing.md); 1: the declared variance",
                                   at_least(1.0, ""))
    adapt_time_s: float = param(2.0, "s", "time constant of the innovation average that sets "
                                "that factor", positive)
    accel_std: float = param(0.3, "m/s^2", "steady walk model: white acceleration in x and "
                             "y (how fast a walker changes velocity)", positive)
    turn_accel_std: float = param(1.6, "rad/s^2", "steady walk model: white acceleration of "
                                  "the turn rate", positive)
    maneuver_accel_std: float = param(0.9, "m/s^2", "manoeuvre model (starting, stopping, "
                                      "turning sharply): white acceleration in x and y",
                                      positive)
    maneuver_turn_accel_std: float = param(3.5, "rad/s^2", "manoeuvre model: white "
                                           "acceleration of the turn rate", positive)
    inflate_nis: float = param(2.0, "-", "a detection whose squared Mahalanobis distance of "
                               "position from the prediction exceeds this widens the reported "
                               "position covariance by their ratio (the filter's own update is "
                               "unchanged): the estimate admits a manoeuvre its models did not "
                               "expect; inf: never", positive_or_inf)
    inflate_time_s: float = param(0.5, "s", "time constant with which that widening decays "
                                  "from one detection to the next", positive)
    maneuver_start_rate: float = param(0.15, "1/s", "how often a steady walk turns into a "
                                       "manoeuvre (the models' switching rate)", positive)
    maneuver_end_rate: float = param(5.0, "1/s", "how often a manoeuvre ends", positive)
    initial_maneuver: float = param(0.5, "-", "probability of the manoeuvre model when a "
                                    "track starts", _probability)
    gate_chi2: float = param(13.8, "-", "a detection whose squared Mahalanobis distance of "
                             "position exceeds this is another person (13.8: 99.9 % for 2 "
                             "degrees of freedom)", positive)
    gate_floor_m: float = param(0.2, "m", "position tolerance always allowed in the gate (an "
                                "exact sensor must not make the gate arbitrarily tight)",
                                non_negative)
    motion_gate_chi2: float = param(25.0, "-", "reported velocities whose mean over the "
                                    "newest detections (up to 6, within max_delay_s) differs "
                                    "from the slope of their positions by a squared "
                                    "Mahalanobis distance above this are wrong: the "
                                    "detections are used for their position only (25: about "
                                    "4e-6 for 2 degrees of freedom); inf: always trusted",
                                    positive_or_inf)
    motion_floor_mps: float = param(0.2, "m/s", "tolerance always allowed in that comparison "
                                    "(a walk that is not straight over the window)",
                                    non_negative)
    max_person_speed: float = param(3.0, "m/s", "a detection farther from the track than this "
                                    "speed allows (plus gate_floor_m) is rejected; estimated "
                                    "speeds are clipped to it", positive)
    max_person_turn_rate: float = param(TWO_PI, "rad/s", "estimated turn rates are clipped to "
                                        "this", positive)
    max_delay_s: float = param(0.5, "s", "a detection older than this when it arrives is "
                               "stale and rejected; later ones are merged in time order",
                               positive)
    future_tolerance_s: float = param(0.05, "s", "a detection from further in the future than "
                                      "this is rejected (clock skew)", non_negative)
    coast_after_s: float = param(0.3, "s", "no accepted detection for longer than this: the "
                                 "person is predicted (degraded)", positive)
    lost_after_s: float = param(0.5, "s", "no accepted detection for longer than this: the "
                                "person is lost (stop)", positive)
    uncertain_std_m: float = param(0.15, "m", "a position std above this is reported "
                                   "(degraded: person_uncertain)", positive)
    max_position_std_m: float = param(0.5, "m", "a position std above this loses the person",
                                      positive)
    reacquire_time_s: float = param(0.3, "s", "after the person was lost, detections must agree "
                                    "with each other for this long before the track resumes",
                                    non_negative)
    refind_spread_mps: float = param(1.5, "m/s", "after a loss, a detection re-finds the "
                                     "person only within gate_floor_m plus this times the time "
                                     "since the last one of the way the lost track predicted "
                                     "(from where the person was last seen to where the "
                                     "track's velocity takes them in at most "
                                     "refind_horizon_s), unless the re-identification hook "
                                     "decides; 1.5: a brisk walk in any direction; inf: "
                                     "anywhere", positive_or_inf)
    refind_horizon_s: float = param(5.0, "s", "how long the lost track's velocity is carried "
                                    "on in that prediction", non_negative)
    standing_speed: float = param(0.2, "m/s", "below this estimated speed the person stands: "
                                  "the heading is held at its last walking value and the turn "
                                  "rate is 0 (positions alone tell no heading then)",
                                  non_negative)
    walking_heading_std_rad: float = param(0.5, "rad", "the person also stands while the "
                                           "estimated heading is less certain than this",
                                           positive)
    initial_speed_std: float = param(0.7, "m/s", "std of the speed of a new track whose "
                                     "detections give none", positive)
    initial_turn_rate_std: float = param(0.5, "rad/s", "std of the turn rate of a new track",
                                         positive)

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("world_frame", "robot_frame"):
            if not getattr(self, name).strip():
                raise ConfigError(f"{name}: expected a frame name, got "
                                  f"{getattr(self, name)!r}")
        if self.robot_frame == self.world_frame:
            raise ConfigError(f"robot_frame: expected a frame other than "
                              f"world_frame, got {self.robot_frame!r}")
        if self.lost_after_s < self.coast_after_s:
            raise ConfigError(f"lost_after_s: expected at least coast_after_s "
                              f"({self.coast_after_s:g} s), got {self.lost_after_s:g}")

    def for_sensing(self, sensing: SensingParams) -> TrackerParams:
        """These settings with the noise of detections that give none taken from the declared
        ``sensing`` where they are absent."""
        pos, heading = self.position_std_m, self.heading_std_rad
        if pos is None:   # an exact (ideal) sensor gives whole states, not bare positions
            pos = sensing.declared_noise_m or 0.05
        if heading is None:
            declared = sensing.person_heading_noise_rad
            heading = declared if declared else 0.1
        return dataclasses.replace(self, position_std_m=pos, heading_std_rad=heading)


@dataclasses.dataclass(frozen=True)
class LidarParams(Validated):
    """A simulated 2D LiDAR at the robot's pose (:mod:`companion.sim.lidar`)."""

    fov: float = param(TWO_PI, "rad", "field of view, centred on the robot's heading, in "
                       "(0, 2*pi]; 2*pi is a full 360 degree scan", _fov)
    range_max: float = param(10.0, "m", "maximum range; beams hitting nothing closer return "
                             "inf", positive)
    resolution: float = param(math.radians(0.5), "rad",
                              "angular step between beams (0.5 deg: 720 beams per revolution); "
                              "for a full circle it is rounded so that it divides 2*pi",
                              _resolution)
    noise_std: float = param(0.01, "m", "standard deviation of the Gaussian noise added to "
                             "every finite range (clipped at 0); 0 = exact", non_negative)
    person_radius: float = param(0.2, "m", "radius of the circle that stands for the person's "
                                 "body in the scan", positive)
    timeout_s: float = param(1.0, "s", "a scan's obstacles are held until the next scan, at "
                             "most this long (the perception front end)", positive)


@dataclasses.dataclass(frozen=True)
class ExtractorParams(Validated):
    """Turning a LiDAR scan into circular obstacles (:mod:`companion.perception.extract`)."""

    cluster_gap: float = param(0.15, "m", "consecutive returns farther apart than this (and "
                               "than the adaptive breakpoint distance) start a new cluster; so "
                               "does a beam without return", positive)
    breakpoint_angle: float = param(math.radians(10.0), "rad",
                                    "adaptive breakpoint (Borges & Aldon 2004): returns on a "
                                    "surface seen at least this angle away from grazing stay in "
                                    "one cluster, i.e. the gap threshold grows to r * sin(step) "
                                    "/ sin(breakpoint_angle - step) at range r; 0 = fixed "
                                    "cluster_gap only", _breakpoint_angle)
    min_points: int = param(3, "-", "clusters with fewer returns are dropped as noise",
                            at_least_one)
    max_segment: float = param(0.6, "m", "a cluster that is not one circle (a wall, a corner) "
                               "and is longer than this is split into pieces of at most this "
                               "length, each reported as its own circle", positive)
    person_exclusion: float = param(0.5, "m", "circles whose centre is within person_radius + "
                                    "this of the tracked person are the person and are not "
                                    "reported (absorbs tracking error)", non_negative)
    person_radius: float = param(0.2, "m", "radius of the person's body; should match "
                                 "lidar.person_radius", positive)
    piece_influence: float = param(0.5, "m", "avoidance influence range given to circles that "
                                   "stand for pieces of a wall or a large object (like "
                                   "avoidance.wall_influence for known walls)", positive)
    min_radius: float = param(0.05, "m", "smallest reported radius", positive)
    max_radius: float = param(1.0, "m", "largest fitted radius; a circle is only enlarged "
                              "beyond it to cover its cluster's returns", positive)
    fit_tolerance: float = param(0.04, "m", "largest RMS radial residual of an accepted "
                                 "circle fit; the returns must also bulge towards the sensor by "
                                 "twice this from their chord (about 2-4 x the range noise)",
                                 positive)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.min_radius > self.max_radius:
            raise ConfigError(f"min_radius: expected at most max_radius "
                              f"({self.max_radius:g} m), got {self.min_radius:g}")


@dataclasses.dataclass(frozen=True)
class MoverParams(Validated):
    """Tracking moving things: LiDAR clusters and the other people detected on the person
    topic, each with a constant-velocity Kalman filter (:mod:`companion.perception.movers`,
    docs/crowds.md)."""

    max_radius: float = param(0.5, "m", "LiDAR circles larger than this (or standing for a "
                              "piece of a wall) are not tracked: they are not people",
                              positive)
    gate_m: float = param(0.4, "m", "a circle belongs to a track if it is within this of the "
                          "track's prediction, plus max_speed times the time since the "
                          "track's last circle", positive)
    max_speed: float = param(2.5, "m/s", "fastest a tracked thing moves", positive)
    accel_std: float = param(1.5, "m/s^2", "standard deviation of the white acceleration of "
                             "the filter's constant-velocity model", positive)
    position_std: float = param(0.08, "m", "standard deviation of a circle's centre (a "
                                "LiDAR fit moves with the side of the body it sees)", positive)
    confirm: int = param(3, "-", "a track is reported after this many circles", at_least_one)
    forget_s: float = param(0.5, "s", "a track without a circle for longer is dropped",
                            positive)
    min_speed: float = param(0.25, "m/s", "slower tracks, or whose speed is within 3 "
                             "standard deviations of 0, are reported standing", non_negative)
    person_radius: float = param(0.25, "m", "radius of the body of another person detected "
                                 "on the person topic, as an obstacle", positive)
