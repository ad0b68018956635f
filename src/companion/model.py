"""Human-robot companion model (paper Sec. 2, Eq. 4-8).

State ``chi = [rho, alpha, beta]``: distance from the person to the robot's reference point R
(Eq. 2), bearing of R seen from the person in [0, 2*pi) (left pi/2, behind pi, right 3*pi/2,
front 0) and heading difference ``theta_h - theta_r`` in (-pi, pi]. Input ``u = [v, omega]``
(robot), exogenous input ``w = [v_h, omega_h]`` (person). The dynamics are Eq. (7) with
``gamma = alpha + beta`` at the current state, and the Jacobians are their exact derivatives
(docs/model.md, sections 1-3).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.linalg import expm

from companion._jit import jitable
from companion.geometry import offset_point, wrap_2pi, wrap_pi


@jitable
def relative_state(robot_x: float, robot_y: float, robot_theta: float,
                   person_x: float, person_y: float, person_theta: float,
                   d: float) -> tuple[float, float, float]:
    """``chi = (rho, alpha, beta)`` from the robot and person poses (Eq. 4-6, with atan2)."""
    rx, ry = offset_point(robot_x, robot_y, robot_theta, d)
    dx, dy = rx - person_x, ry - person_y
    rho = math.hypot(dx, dy)
    alpha = wrap_2pi(math.atan2(dy, dx) - person_theta)
    beta = wrap_pi(person_theta - robot_theta)
    return rho, alpha, beta


def robot_pose_at(rho: float, alpha: float, beta: float,
                  person_x: float, person_y: float, person_theta: float,
                  d: float) -> tuple[float, float, float]:
    """Inverse of :func:`relative_state`: the robot pose (axle centre) that has state chi."""
    theta = person_theta - beta
    rx = person_x + rho * math.cos(person_theta + alpha)
    ry = person_y + rho * math.sin(person_theta + alpha)
    return rx - d * math.cos(theta), ry - d * math.sin(theta), theta


def dynamics(chi, u, w, d: float) -> np.ndarray:
    """Continuous-time dynamics ``chi_dot = f(chi, u, w)`` (Eq. 7, corrected); rho > 0."""
    rho, alpha, beta = chi
    v, om = u
    vh, omh = w
    sg, cg = math.sin(alpha + beta), math.cos(alpha + beta)
    return np.array([
        v * cg + d * om * sg - vh * math.cos(alpha),
        (vh * math.sin(alpha) - v * sg + d * om * cg) / rho - omh,
        omh - om,
    ])


@jitable
def jacobians(chi, u, w, d: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact Jacobians ``(df/dchi, df/du)`` of :func:`dynamics`, shapes (3, 3) and (3, 2).

    ``chi``, ``u`` and ``w`` are sequences (tuples or arrays) of 3, 2 and 2 numbers.
    """
    rho, alpha, beta = chi[0], chi[1], chi[2]
    v, om, vh = u[0], u[1], w[0]
    g = alpha + beta
    sg, cg = math.sin(g), math.cos(g)
    dr_dg = -v * sg + d * om * cg          # d(rho_dot)/d(gamma)
    num = vh * math.sin(alpha) - v * sg + d * om * cg   # rho * (alpha_dot + omega_h)
    dnum_dg = -v * cg - d * om * sg
    jx = np.zeros((3, 3))
    jx[0, 1] = dr_dg + vh * math.sin(alpha)
    jx[0, 2] = dr_dg
    jx[1, 0] = -num / (rho * rho)
    jx[1, 1] = (vh * math.cos(alpha) + dnum_dg) / rho
    jx[1, 2] = dnum_dg / rho
    ju = np.zeros((3, 2))
    ju[0, 0] = cg
    ju[0, 1] = d * sg
    ju[1, 0] = -sg / rho
    ju[1, 1] = d * cg / rho
    ju[2, 1] = -1.0
    return jx, ju


@jitable
def euler(jx: np.ndarray, ju: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Forward-Euler discretisation ``(I + dt jx, dt ju)`` (the paper's)."""
    n, m = ju.shape
    a = np.empty((n, n))
    b = np.empty((n, m))
    for i in range(n):
        for j in range(n):
            a[i, j] = dt * jx[i, j] + (1.0 if i == j else 0.0)
        for j in range(m):
            b[i, j] = dt * ju[i, j]
    return a, b


def zoh(jx: np.ndarray, ju: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation, read off ``expm(dt [[jx, ju], [0, 0]])``."""
    n, m = ju.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n] = jx
    block[:n, n:] = ju
    e = expm(block * dt)
    return e[:n, :n], e[:n, n:]


def discretize(jx: np.ndarray, ju: np.ndarray, dt: float, method: str = "euler"
               ) -> tuple[np.ndarray, np.ndarray]:
    """Discretise ``dx/dt = jx x + ju u`` with sample time ``dt``: ``method`` is "euler"
    (:func:`euler`) or "zoh" (:func:`zoh`)."""
    if method == "euler":
        return euler(np.asarray(jx, float), np.asarray(ju, float), dt)
    if method == "zoh":
        return zoh(jx, ju, dt)
    raise ValueError(f"discretize: method must be 'euler' or 'zoh', got {method!r}")


class SlotReference(NamedTuple):
    """Equilibrium of the companion model for a person moving with constant ``(v_h, omega_h)``:
    the heading difference ``beta`` and robot input ``(v, omega)`` that hold the slot.
    ``feasible`` is False when no equilibrium exists (the slot moves slower than
    ``d |omega_h|``); the values are then the closest compromise."""

    beta: float
    v: float
    omega: float
    feasible: bool


@jitable
def slot_reference(v_h: float, omega_h: float, rho_d: float, alpha_d: float, d: float
                   ) -> SlotReference:
    """Geometry-consistent feedforward: the input and heading that hold the desired slot
    (docs/model.md, section 5).

    The slot ``R_d = h + rho_d e(theta_h + alpha_d)`` moves with ``V = v_h e(theta_h) +
    rho_d omega_h e_perp(theta_h + alpha_d)``; the robot holds it when ``v e(theta_r) +
    d omega_h e_perp(theta_r) = V``. Of the two headings that solve this (forward or reverse),
    the one closer to the person's heading is taken. Computed in the person's frame.
    """
    vx = v_h - rho_d * omega_h * math.sin(alpha_d)
    vy = rho_d * omega_h * math.cos(alpha_d)
    speed = math.hypot(vx, vy)
    lateral = d * omega_h
    feasible = speed >= abs(lateral)
    if speed < 1e-9:
        return SlotReference(0.0, 0.0, omega_h, feasible)
    psi = math.atan2(vy, vx)
    delta = math.asin(max(-1.0, min(1.0, lateral / speed)))
    along = math.sqrt(max(speed * speed - lateral * lateral, 0.0))
    theta_fwd = psi - delta             # forward: theta_r = psi - delta, v = +along
    theta_rev = psi + math.pi + delta   # reverse: theta_r = psi + pi + delta, v = -along
    if abs(wrap_pi(theta_fwd)) <= abs(wrap_pi(theta_rev)):
        return SlotReference(wrap_pi(-theta_fwd), along, omega_h, feasible)
    return SlotReference(wrap_pi(-theta_rev), -along, omega_h, feasible)
