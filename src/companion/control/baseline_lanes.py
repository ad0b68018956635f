"""The PID, VSM and impedance baselines for many lanes at once, compiled (batch simulation).

Each kernel is the ``step`` of :class:`~companion.control.pid.PidController`,
:class:`~companion.control.vsm.VsmController` or
:class:`~companion.control.impedance.ImpedanceController` for every lane, written with the same
floating-point operations in the same order; ``tests/sim/test_fast_batch.py`` checks whole
episodes against the classes. The slot geometry (:mod:`companion.control.slot`) is compiled
from the same source. A lane's state is a row of ``state``; its parameters a row of
``config`` (:func:`baseline_config`). As in a bare episode of
:func:`companion.sim.episode.run_episode`, the controllers are told nothing after a step:
the PID's keep-out memory stays 0, and VSM and IC use their own last output as the command in
force.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from companion.control import slot
from companion.fastlqr import slot_reference_nb, wrap_pi_nb
from companion.params import Params

_NB = {"cache": True, "nogil": True, "error_model": "numpy", "no_cfunc_wrapper": True}

_to_frame = njit(**_NB)(slot.to_frame)
_from_frame = njit(**_NB)(slot.from_frame)
_to_inputs = njit(**_NB)(slot.to_inputs)
_point_velocity = njit(**_NB)(slot.point_velocity)

#: Baselines with a compiled lane kernel, and their index in ``config[:, 0]``.
KINDS = {"pid": 0, "vsm": 1, "ic": 2}
#: Columns of a lane's state row.
STATE_SIZE = 8


def baseline_config(name: str, params: Params) -> np.ndarray:
    """The parameters of baseline ``name`` as one float row: kind, d, dt, rho_d, alpha_d,
    v_max, omega_max, then the controller's gains."""
    r, f = params.robot, params.formation
    head = [KINDS[name], r.d, params.dt, f.distance, f.bearing, r.v_max, r.omega_max]
    if name == "pid":
        g = params.pid
        gains = [g.kp_x, g.ki_x, g.kd_x, g.kp_y, g.ki_y, g.kd_y, g.kp_theta,
                 params.dt / (g.derivative_tau + params.dt), g.i_limit_v, g.i_limit_omega]
    elif name == "vsm":
        g = params.vsm
        gains = [g.stiffness, g.damping, g.mass]
    else:
        g = params.impedance
        gains = [*g.mass, *g.damping, *g.stiffness]
    row = np.zeros(17)
    row[:len(head) + len(gains)] = head + gains
    return row


@njit(**_NB)
def _slot(hx, hy, hth, hv, hw, rho_d, alpha_d):
    """Slot point S and its velocity S_dot (:func:`companion.control.slot.slot_point` and
    :func:`~companion.control.slot.slot_velocity`)."""
    a = hth + alpha_d
    w = rho_d * hw
    return (hx + rho_d * math.cos(a), hy + rho_d * math.sin(a),
            hv * math.cos(hth) - w * math.sin(a), hv * math.sin(hth) + w * math.cos(a))


@njit(**_NB)
def _saturate(v, om, v_max, w_max):
    return min(max(v, -v_max), v_max), min(max(om, -w_max), w_max)


@njit(**_NB)
def _pid(c, s, x, y, th, hx, hy, hth, hv, hw):
    """:meth:`PidController.step` for one lane; ``s`` = [i_v, i_w, e_x(k-1), e_y(k-1),
    has_previous, D_x, D_y, -]."""
    d, dt, rho_d, alpha_d = c[1], c[2], c[3], c[4]
    rx, ry = x + d * math.cos(th), y + d * math.sin(th)
    sx, sy, sdx, sdy = _slot(hx, hy, hth, hv, hw, rho_d, alpha_d)
    e_x, e_y = _to_frame(th, sx - rx, sy - ry)
    beta, _, _ = slot_reference_nb(hv, hw, rho_d, alpha_d, d)
    e_th = wrap_pi_nb(hth - beta - th)
    alpha = c[14]
    if s[4] != 0.0:
        s[5] += alpha * ((e_x - s[2]) / dt - s[5])
        s[6] += alpha * ((e_y - s[3]) / dt - s[6])
    s[2], s[3], s[4] = e_x, e_y, 1.0
    v_ff = math.cos(th) * sdx + math.sin(th) * sdy
    base = (v_ff + c[7] * e_x + c[9] * s[5],
            hw + c[10] * e_y + c[12] * s[6] + c[13] * e_th)
    steps = (c[8] * e_x * dt, c[11] * e_y * dt)
    for i in range(2):
        bound = c[15 + i]
        limit = c[5 + i]
        trial = min(max(s[i] + steps[i], -bound), bound)
        u = base[i] + trial
        pushes = math.copysign(1.0, steps[i]) if steps[i] != 0.0 else 0.0
        if not ((u > limit and pushes > 0) or (u < -limit and pushes < 0)):
            s[i] = trial
    return _saturate(base[0] + s[0], base[1] + s[1], c[5], c[6])


@njit(**_NB)
def _vsm(c, s, x, y, th, hx, hy, hth, hv, hw):
    """:meth:`VsmController.step` for one lane; ``s`` = [v, omega, has_last, ...]."""
    d, dt = c[1], c[2]
    rx, ry = x + d * math.cos(th), y + d * math.sin(th)
    sx, sy, sdx, sdy = _slot(hx, hy, hth, hv, hw, c[3], c[4])
    rdx, rdy = _point_velocity(th, s[0], s[1], d) if s[2] != 0.0 else (sdx, sdy)
    k, damping, mass = c[7], c[8], c[9]
    fx = k * (sx - rx) - damping * (rdx - sdx)
    fy = k * (sy - ry) - damping * (rdy - sdy)
    vx, vy = rdx + dt * fx / mass, rdy + dt * fy / mass
    u_v, u_w = _to_inputs(th, vx, vy, d)
    return _saturate(u_v, u_w, c[5], c[6])


@njit(**_NB)
def _ic(c, s, x, y, th, hx, hy, hth, hv, hw):
    """:meth:`ImpedanceController.step` for one lane; ``s`` = [v, omega, has_last, ...]."""
    d, dt, w = c[1], c[2], hw
    rx, ry = x + d * math.cos(th), y + d * math.sin(th)
    sx, sy, sdx, sdy = _slot(hx, hy, hth, hv, hw, c[3], c[4])
    rdx, rdy = _point_velocity(th, s[0], s[1], d) if s[2] != 0.0 else (sdx, sdy)
    e0, e1 = _to_frame(hth, rx - sx, ry - sy)
    w0, w1 = _to_frame(hth, rdx - sdx, rdy - sdy)
    ed0, ed1 = w0 + w * e1, w1 - w * e0
    t0 = ed0 - dt * (c[9] * ed0 + c[11] * e0) / c[7]
    t1 = ed1 - dt * (c[10] * ed1 + c[12] * e1) / c[8]
    cx, cy = _from_frame(hth, t0 - w * e1, t1 + w * e0)
    u_v, u_w = _to_inputs(th, sdx + cx, sdy + cy, d)
    return _saturate(u_v, u_w, c[5], c[6])


@njit(**_NB)
def baseline_lanes(idx, observed, pose, config, state, vw):
    """One period of every lane's baseline: from ``observed`` (person x, y, theta, v, omega)
    and ``pose`` (robot x, y, theta) to ``vw``; ``state`` rows are updated."""
    for lane in range(idx.size):
        g = idx[lane]
        if g < 0:
            continue
        c = config[g]
        s = state[lane]
        o = observed[lane]
        x, y, th = pose[lane, 0], pose[lane, 1], pose[lane, 2]
        kind = int(c[0])
        if kind == 0:
            v, om = _pid(c, s, x, y, th, o[0], o[1], o[2], o[3], o[4])
        elif kind == 1:
            v, om = _vsm(c, s, x, y, th, o[0], o[1], o[2], o[3], o[4])
        else:
            v, om = _ic(c, s, x, y, th, o[0], o[1], o[2], o[3], o[4])
        if kind != 0:
            s[0], s[1], s[2] = v, om, 1.0
        vw[lane, 0] = v
        vw[lane, 1] = om


class BaselineLanes:
    """The arrays of a set of baseline lanes (``idx``: row in ``config`` per lane, -1 for
    padding); ``observed`` and ``pose`` are inputs, ``vw`` the output."""

    def __init__(self, idx: np.ndarray):
        n = idx.size
        self.idx = idx
        self.state = np.zeros((n, STATE_SIZE))
        self.observed = np.zeros((n, 5))
        self.pose = np.zeros((n, 3))
        self.vw = np.zeros((n, 2))

    def step(self, config: np.ndarray) -> None:
        baseline_lanes(self.idx, self.observed, self.pose, config, self.state, self.vw)
