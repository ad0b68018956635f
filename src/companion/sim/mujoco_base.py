"""A differential-drive base with mass in MuJoCo: the ``mujoco`` plant (docs/plants.md).

The model (:func:`model_xml`, built from ``params.plant`` and ``params.robot``): a cylindrical
body of the footprint's radius on two driven wheels at the robot centre, a frictionless caster
behind them and an anti-tip caster in front, each wheel turned by a velocity servo with a
torque limit, the wheels gripping the floor with Coulomb friction. A command ``(v, omega)``,
after the base's command lag ``sensing.actuator_tau_s``, becomes the two wheel speed set-
points. Odometry integrates the wheel angles as a base's encoders do, so it drifts from the
true pose (the free joint's) when a wheel slips. The scenario's obstacles are static bodies and
the person a moving one: ``contact`` says whether the robot's body touches either, as the
physics finds it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco

from companion.geometry import unicycle_step, wrap_pi
from companion.params import Params
from companion.types import Circle, Obstacle, Pose

#: Height (m) of the body's underside above the floor, and radius (m) of the casters.
CLEARANCE, CASTER = 0.03, 0.03
#: The body's centre of mass this far (m) behind the axle (its shape stays the footprint's
#: circle), so that the wheels carry most of the weight and the rear caster the rest; the
#: front caster rides this far (m) above the floor and stops the base tipping forward when
#: it brakes (three-point support).
COM_BACK, ANTI_TIP = 0.05, 0.005
#: Height (m) of the obstacles' and the person's bodies.
TALL = 1.8


def model_xml(params: Params, obstacles: Sequence[Obstacle] = ()) -> str:
    """The MJCF of the base on a floor, with ``obstacles`` as static bodies and the person as
    a capsule moved from outside (a mocap body)."""
    pl, r = params.plant, params.robot
    wheel, half = pl.wheel_radius, 0.5 * pl.track_width
    caster_mass = 0.5
    body_mass = pl.mass - 2.0 * pl.wheel_mass - 2.0 * caster_mass
    if body_mass <= 0.0:
        raise ValueError("plant.mass: expected more than the wheels' and casters' mass")
    body_z = CLEARANCE + 0.5 * pl.body_height - wheel   # body frame at the axle
    mass = body_mass + 2.0 * caster_mass                 # a solid cylinder's inertia
    spin = 0.5 * mass * r.radius ** 2
    tilt = mass * (3.0 * r.radius ** 2 + pl.body_height ** 2) / 12.0
    caster_x, caster_z = r.radius - CASTER - 0.02, CASTER - wheel
    walls = []
    for i, ob in enumerate(obstacles):
        if isinstance(ob, Circle):
            walls.append(f'<geom name="ob{i}" type="cylinder" size="{ob.radius} {TALL / 2}" '
                         f'pos="{ob.x} {ob.y} {TALL / 2}" contype="2" conaffinity="1"/>')
        else:
            length = math.hypot(ob.x1 - ob.x0, ob.y1 - ob.y0)
            yaw = math.degrees(math.atan2(ob.y1 - ob.y0, ob.x1 - ob.x0))
            walls.append(f'<geom name="ob{i}" type="box" size="{max(length / 2, 1e-3)} 0.01 '
                         f'{TALL / 2}" pos="{(ob.x0 + ob.x1) / 2} {(ob.y0 + ob.y1) / 2} '
                         f'{TALL / 2}" euler="0 0 {yaw}" contype="2" conaffinity="1"/>')
    person = params.lidar.person_radius
    return f"""
<mujoco model="companion-base">
  <compiler angle="degree"/>
  <option timestep="{pl.physics_step}" integrator="implicitfast"/>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 0.1" friction="{pl.friction} 0.005 0.0001"
          contype="1" conaffinity="1"/>
    {''.join(walls)}
    <body name="person" mocap="true" pos="0 0 {TALL / 2}">
      <geom name="person" type="capsule" size="{person} {TALL / 2 - person}"
            contype="2" conaffinity="1"/>
    </body>
    <body name="base" pos="0 0 {wheel}">
      <freejoint name="base"/>
      <inertial pos="{-COM_BACK} 0 {body_z}" mass="{body_mass + 2 * caster_mass}"
                diaginertia="{tilt} {tilt} {spin}"/>
      <geom name="body" type="cylinder" size="{r.radius} {pl.body_height / 2}"
            pos="0 0 {body_z}" contype="1" conaffinity="2"/>
      <geom name="caster_front" type="sphere" size="{CASTER}"
            pos="{caster_x} 0 {caster_z + ANTI_TIP}"
            condim="1" priority="1" contype="1" conaffinity="1"/>
      <geom name="caster_back" type="sphere" size="{CASTER}" pos="{-caster_x} 0 {caster_z}"
            condim="1" priority="1" contype="1" conaffinity="1"/>
      <body name="left" pos="0 {half} 0">
        <joint name="left" type="hinge" axis="0 1 0"/>
        <geom type="sphere" size="{wheel}" mass="{pl.wheel_mass}"
              friction="{pl.friction} 0.005 0.0001" contype="1" conaffinity="1"/>
      </body>
      <body name="right" pos="0 {-half} 0">
        <joint name="right" type="hinge" axis="0 1 0"/>
        <geom type="sphere" size="{wheel}" mass="{pl.wheel_mass}"
              friction="{pl.friction} 0.005 0.0001" contype="1" conaffinity="1"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <velocity name="left" joint="left" kv="{pl.motor_gain}"
              forcerange="{-pl.torque_max} {pl.torque_max}" forcelimited="true"/>
    <velocity name="right" joint="right" kv="{pl.motor_gain}"
              forcerange="{-pl.torque_max} {pl.torque_max}" forcelimited="true"/>
  </actuator>
</mujoco>"""


class MujocoPlant:
    """The ``mujoco`` plant: see the module docstring. One model per episode (its obstacles
    are bodies); :meth:`reset` puts the base at a pose and velocity on the floor."""

    def __init__(self, params: Params, obstacles: Sequence[Obstacle] = ()):
        pl = params.plant
        self.model = mujoco.MjModel.from_xml_string(model_xml(params, obstacles))
        self.substeps = max(1, math.ceil(params.dt / pl.physics_step - 1e-9))
        self.model.opt.timestep = params.dt / self.substeps
        self.data = mujoco.MjData(self.model)
        self.r, self.half, self.tau = pl.wheel_radius, 0.5 * pl.track_width, \
            params.sensing.actuator_tau_s
        self.dt = params.dt
        m = self.model
        self._wheels = [m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]
                        for n in ("left", "right")]
        self._wheel_vel = [m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]
                           for n in ("left", "right")]
        bodies = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n)
                  for n in ("base", "left", "right")}
        self._robot = {i for i in range(m.ngeom) if int(m.geom_bodyid[i]) in bodies}
        self._targets = {i for i in range(m.ngeom)
                         if (m.geom(i).name or "").startswith(("ob", "person"))}
        self._mocap = m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "person")]

    def reset(self, pose: Pose, velocity: tuple[float, float]) -> None:
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        v, w = velocity
        d.qpos[0:3] = (pose.x, pose.y, self.r)
        d.qpos[3:7] = (math.cos(pose.theta / 2), 0.0, 0.0, math.sin(pose.theta / 2))
        d.qvel[0:3] = (v * math.cos(pose.theta), v * math.sin(pose.theta), 0.0)
        d.qvel[5] = w
        left, right = self._wheel_speeds(v, w)
        d.qvel[self._wheel_vel[0]], d.qvel[self._wheel_vel[1]] = left, right
        d.ctrl[:] = (left, right)
        d.mocap_pos[self._mocap] = (1e3, 1e3, TALL / 2)   # far away until placed
        mujoco.mj_forward(m, d)
        self.setpoint = (v, w)
        self.odometry = pose
        self._angles = [float(d.qpos[i]) for i in self._wheels]
        self.contact = 0.0

    def _wheel_speeds(self, v: float, w: float) -> tuple[float, float]:
        return (v - w * self.half) / self.r, (v + w * self.half) / self.r

    def step(self, command: tuple[float, float], t: float = 0.0,
             person: tuple[float, float] | None = None) -> None:
        """One period under ``command``, the person's body at ``person`` (None: absent)."""
        m, d = self.model, self.data
        if person is not None:
            d.mocap_pos[self._mocap] = (person[0], person[1], TALL / 2)
        h = m.opt.timestep
        a = 0.0 if self.tau <= 0.0 else math.exp(-h / self.tau)
        sv, sw = self.setpoint
        touched = 0.0
        for _ in range(self.substeps):
            sv, sw = command[0] + (sv - command[0]) * a, command[1] + (sw - command[1]) * a
            d.ctrl[:] = self._wheel_speeds(sv, sw)
            mujoco.mj_step(m, d)
            if touched == 0.0 and self._touching():
                touched = 1.0
        self.setpoint, self.contact = (sv, sw), touched
        self._odometry_step()

    def _touching(self) -> bool:
        for i in range(self.data.ncon):
            c = self.data.contact[i]
            pair = {int(c.geom1), int(c.geom2)}
            if pair & self._robot and pair & self._targets:
                return True
        return False

    def _odometry_step(self) -> None:
        """The encoders' dead reckoning over the last period: the mean wheel speeds' arc."""
        angles = [float(self.data.qpos[i]) for i in self._wheels]
        dl, dr = (self.r * (a - b) for a, b in zip(angles, self._angles))
        self._angles = angles
        o = self.odometry
        x, y, th = unicycle_step(o.x, o.y, o.theta, (dl + dr) / (2 * self.dt),
                                 (dr - dl) / (2 * self.half * self.dt), self.dt)
        self.odometry = Pose(x, y, wrap_pi(th))

    @property
    def pose(self) -> Pose:
        q = self.data.qpos
        yaw = math.atan2(2.0 * (q[3] * q[6] + q[4] * q[5]), 1.0 - 2.0 * (q[5] ** 2 + q[6] ** 2))
        return Pose(float(q[0]), float(q[1]), yaw)

    @property
    def velocity(self) -> tuple[float, float]:
        q, th = self.data.qvel, self.pose.theta
        return float(q[0] * math.cos(th) + q[1] * math.sin(th)), float(q[5])

    @property
    def odometry_velocity(self) -> tuple[float, float]:
        left, right = (float(self.data.qvel[i]) * self.r for i in self._wheel_vel)
        return 0.5 * (left + right), (right - left) / (2.0 * self.half)

    def wheel_slip(self) -> float:
        """Speed (m/s) at which the wheels' rims move against the floor under them (0: pure
        rolling): the odometry's speed against the truth's, the larger of the two wheels'."""
        v, w = self.velocity
        ov, ow = self.odometry_velocity
        return max(abs((ov - ow * self.half) - (v - w * self.half)),
                   abs((ov + ow * self.half) - (v + w * self.half)))

