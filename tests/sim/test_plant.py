"""The robot's base as a plant (docs/plants.md): the kinematic unicycle unchanged, the MuJoCo
base reaching commanded velocities, slipping and drifting when friction cannot follow, and
braking as the supervisor assumes."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from companion.geometry import base_step
from companion.metrics import compute
from companion.params import Params, load_sensing, params_from_mapping
from companion.sim.mujoco_base import MujocoPlant
from companion.sim.plant import FrameShift, KinematicPlant
from companion.sim.scenario import load_scenario, run_scenario
from companion.types import Circle, PersonDetection, Pose, Wall

MUJOCO = params_from_mapping({"plant": {"kind": "mujoco"}})


def drive(plant, commands, dt):
    """Step ``plant`` through ``commands``; the true velocities after each period."""
    out = []
    for k, command in enumerate(commands):
        plant.step(command, k * dt)
        out.append(plant.velocity)
    return np.array(out)


def ramp(v0, v1, w0, w1, rate_v, rate_w, dt, hold):
    """Commands from (v0, w0) to (v1, w1) at the rate limits, then ``hold`` s at the end."""
    n = max(math.ceil(abs(v1 - v0) / rate_v / dt), math.ceil(abs(w1 - w0) / rate_w / dt), 1)
    steps = [(v0 + (v1 - v0) * min((k + 1) / n, 1.0), w0 + (w1 - w0) * min((k + 1) / n, 1.0))
             for k in range(n)]
    return steps + [(v1, w1)] * int(hold / dt)


def test_the_kinematic_plant_is_the_lagged_unicycle_and_its_odometry_the_truth():
    p = Params().replace(sensing=load_sensing("realistic"))
    plant = KinematicPlant(p)
    plant.reset(Pose(1.0, 2.0, 0.3), (0.5, 0.1))
    plant.step((1.0, -0.2))
    x, y, th, va, wa = base_step(1.0, 2.0, 0.3, 0.5, 0.1, 1.0, -0.2,
                                 p.sensing.actuator_tau_s, p.dt)
    assert plant.pose == Pose(x, y, th) and plant.velocity == (va, wa)
    assert plant.odometry == plant.pose and plant.odometry_velocity == plant.velocity
    assert math.isnan(plant.contact)


def test_a_kinematic_log_reports_the_true_pose_as_odometry():
    log = run_scenario(dataclasses.replace(load_scenario("figure8"), duration=5.0))
    for a, b in (("odom_x", "robot_x"), ("odom_y", "robot_y"), ("odom_theta", "robot_theta")):
        np.testing.assert_array_equal(log[a], log[b])
    assert np.all(np.isnan(log["plant_contact"]))


@pytest.mark.parametrize("v, w", [(1.0, 0.0), (0.5, 0.5), (0.0, 1.0), (-0.5, 0.0)])
def test_mujoco_reaches_the_commanded_velocity(v, w):
    """Straight, arc, spin in place and reverse, ramped at the supervisor's rate limits: at
    steady state within 0.02 m/s and 0.03 rad/s of the command."""
    s = MUJOCO.supervisor
    plant = MujocoPlant(MUJOCO)
    plant.reset(Pose(0.0, 0.0, 0.0), (0.0, 0.0))
    got = drive(plant, ramp(0.0, v, 0.0, w, s.accel_max, s.angular_accel_max, MUJOCO.dt, 3.0),
                MUJOCO.dt)
    assert got[-1][0] == pytest.approx(v, abs=0.02)
    assert got[-1][1] == pytest.approx(w, abs=0.03)


def test_within_the_rate_limits_odometry_drifts_little():
    """An arc of 10 m ramped at the supervisor's limits: the odometry ends 0.14 m and 0.017
    rad from the truth (the start's small slip); at most 2 % of the distance and 0.03 rad."""
    s = MUJOCO.supervisor
    plant = MujocoPlant(MUJOCO)
    plant.reset(Pose(0.0, 0.0, 0.0), (0.0, 0.0))
    got = drive(plant, ramp(0.0, 1.0, 0.0, 0.3, s.accel_max, s.angular_accel_max, MUJOCO.dt,
                            10.0), MUJOCO.dt)
    distance = float(np.sum(got[:, 0]) * MUJOCO.dt)
    drift = math.hypot(plant.odometry.x - plant.pose.x, plant.odometry.y - plant.pose.y)
    assert drift < 0.02 * distance and abs(plant.odometry.theta - plant.pose.theta) < 0.03


def test_a_wheel_slips_where_friction_cannot_give_the_acceleration_and_odometry_drifts():
    """A step to 1.5 m/s asks for more than a floor of friction 0.1 can give (about 0.8
    m/s^2 on the wheels' share of the weight): the wheels spin ahead of the base and the
    odometry runs ahead of the truth; on the default floor, ramped, it does not."""
    slippery = params_from_mapping({"plant": {"kind": "mujoco", "friction": 0.1}})
    plant = MujocoPlant(slippery)
    plant.reset(Pose(0.0, 0.0, 0.0), (0.0, 0.0))
    slip = []
    for k in range(40):
        plant.step((1.5, 0.0), k * slippery.dt)
        slip.append(plant.wheel_slip())
    assert max(slip) > 0.5
    assert plant.odometry.x - plant.pose.x > 0.3
    assert plant.pose.x < 0.5 * plant.odometry.x


def test_the_base_brakes_at_least_as_hard_as_the_supervisor_assumes():
    """From 1.5 m/s, commanded down at supervisor.decel_max: the base follows the ramp
    within 0.1 m/s and stops within the braking distance plus 10 cm."""
    s = MUJOCO.supervisor
    plant = MujocoPlant(MUJOCO)
    plant.reset(Pose(0.0, 0.0, 0.0), (1.5, 0.0))
    drive(plant, [(1.5, 0.0)] * 20, MUJOCO.dt)
    start = plant.pose.x
    down = ramp(1.5, 0.0, 0.0, 0.0, s.decel_max, 1.0, MUJOCO.dt, 1.0)
    got = drive(plant, down, MUJOCO.dt)
    assert np.max(np.abs(got[:, 0] - np.array(down)[:, 0])) < 0.1
    assert plant.pose.x - start < 1.5 ** 2 / (2 * s.decel_max) + 0.1


def test_the_physics_finds_the_body_touching_an_obstacle():
    plant = MujocoPlant(MUJOCO, (Circle(1.0, 0.0, 0.2),))
    plant.reset(Pose(0.0, 0.0, 0.0), (0.0, 0.0))
    touched = []
    for k in range(60):
        plant.step((0.5, 0.0), k * MUJOCO.dt)
        touched.append(plant.contact)
    assert touched[0] == 0.0 and max(touched) == 1.0
    assert plant.pose.x < 1.0 - 0.2 - 0.2     # it cannot pass through


def test_a_wall_and_the_person_are_bodies_too():
    plant = MujocoPlant(MUJOCO, (Wall(1.0, -1.0, 1.0, 1.0),))
    plant.reset(Pose(0.0, 0.0, 0.0), (0.0, 0.0))
    hit = [plant.step((0.5, 0.0), k * MUJOCO.dt) or plant.contact for k in range(60)]
    assert max(hit) == 1.0
    plant = MujocoPlant(MUJOCO)
    plant.reset(Pose(0.0, 0.0, 0.0), (0.0, 0.0))
    hit = [plant.step((0.0, 0.0), k * MUJOCO.dt, (0.3, 0.0)) or plant.contact
           for k in range(5)]
    assert max(hit) == 1.0


COORD = st.floats(-50.0, 50.0)
ANGLE = st.floats(-math.pi, math.pi)


@given(COORD, COORD, ANGLE, COORD, COORD, ANGLE, COORD, COORD)
def test_a_frame_shift_keeps_what_the_robot_sees_relative_to_itself(tx, ty, tth, ox, oy, oth,
                                                                   px, py):
    truth, odometry = Pose(tx, ty, tth), Pose(ox, oy, oth)
    shift = FrameShift(truth, odometry)
    qx, qy = shift.point(px, py)
    assert math.hypot(qx - ox, qy - oy) == pytest.approx(math.hypot(px - tx, py - ty),
                                                           abs=1e-6)
    bearing = math.atan2(py - ty, px - tx) - tth
    seen = math.atan2(qy - oy, qx - ox) - oth
    if math.hypot(px - tx, py - ty) > 1e-3:
        assert math.cos(bearing - seen) == pytest.approx(1.0, abs=1e-6)
    back = FrameShift(odometry, truth).point(qx, qy)
    assert back == pytest.approx((px, py), abs=1e-6)


def test_a_shifted_detection_keeps_its_covariance_shape():
    shift = FrameShift(Pose(0.0, 0.0, 0.0), Pose(1.0, 2.0, 0.5 * math.pi))
    d = shift.detection(PersonDetection(0.0, 1.0, 0.0, covariance=(0.04, 0.0, 0.0, 0.01),
                                        heading=0.0))
    assert (d.x, d.y) == pytest.approx((1.0, 3.0))
    assert d.heading == pytest.approx(0.5 * math.pi)
    assert d.covariance == pytest.approx((0.01, 0.0, 0.0, 0.04), abs=1e-12)
    assert shift.detection(dataclasses.replace(d, frame="robot")).x == d.x   # not moved


def test_the_figure8_on_mujoco_stays_within_1_3_times_the_kinematic_slot_error():
    """Default controller, realistic sensing, the same noise seed (docs/plants.md)."""
    sc = load_scenario("figure8", {"sensing": "realistic"})
    errors = {}
    for kind in ("kinematic", "mujoco"):
        p = sc.params.replace(plant=dataclasses.replace(sc.params.plant, kind=kind))
        errors[kind] = compute(run_scenario(dataclasses.replace(sc, params=p)))[
            "rms_slot_error_m"]
    assert errors["mujoco"] <= 1.3 * errors["kinematic"], errors


def test_plants_are_a_suite_factor_with_named_errors(tmp_path):
    from companion.errors import ConfigError
    from companion.evaluate.suite import suite_from_mapping

    data = {"controllers": ["lqr", "pid"], "sensing": ["ideal"],
            "plants": ["kinematic", "mujoco"], "motions": {"scenarios": ["line"]}}
    suite = suite_from_mapping(data, tmp_path / "s.toml")
    assert sorted({(e.sensing, e.plant) for e in suite.episodes}) == [
        ("ideal/kinematic", "kinematic"), ("ideal/mujoco", "mujoco")]
    assert len({e.pair for e in suite.episodes}) == 2          # paired within a plant
    with pytest.raises(ConfigError, match=r"s.toml: plants\[1\]: .* got 'mujo'; did you mean"):
        suite_from_mapping(dict(data, plants=["kinematic", "mujo"]), tmp_path / "s.toml")
