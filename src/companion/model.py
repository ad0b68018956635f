"""Human-robot companion model (paper Sec. 2, Eq. 4-8).

State ``chi = [rho, alpha, beta]``:

* ``rho``: distance from the person to the robot's reference point R (Eq. 2);
* ``alpha`` in [0, 2*pi): bearing of R seen from the person, measured from the person's
  heading (left = pi/2, behind = pi, right = 3*pi/2, in front = 0);
* ``beta`` in (-pi, pi]: heading difference ``theta_h - theta_r``.

Input ``u = [v, omega]`` (robot), exogenous input ``w = [v_h, omega_h]`` (person).

The dynamics are Eq. (7) with ``gamma = alpha + beta`` evaluated at the current state (see
NOTES.md point 2 and docs/model.md). Jacobians are exact derivatives of those dynamics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from companion.kinematics import offset_point, wrap_2pi, wrap_pi

LEFT = 0.5 * math.pi
BEHIND = math.pi
RIGHT = 1.5 * math.pi
FRONT = 0.0
SIDES = {"left": LEFT, "right": RIGHT, "behind": BEHIND, "front": FRONT}


def relative_state(robot_x: float, robot_y: float, robot_theta: float,
                   person_x: float, person_y: float, person_theta: float,
                   d: float) -> tuple[float, float, float]:
    """Measure ``chi = (rho, alpha, beta)`` from the robot and person poses (Eq. 4-6).

    ``alpha`` uses ``atan2`` (NOTES.md point 1) and is wrapped to [0, 2*pi);
    ``beta`` is wrapped to (-pi, pi].
    """
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


def dynamics(chi: np.ndarray, u: np.ndarray, w: np.ndarray, d: float) -> np.ndarray:
    """Continuous-time companion dynamics ``chi_dot = f(chi, u, w)`` (Eq. 7, corrected).

    Parameters
    ----------
    chi : array_like, shape (3,)
        ``[rho, alpha, beta]``; rho must be positive.
    u : array_like, shape (2,)
        Robot input ``[v, omega]``.
    w : array_like, shape (2,)
        Person velocity ``[v_h, omega_h]``.
    d : float
        Offset of the reference point ahead of the axle (m).
    """
    rho, alpha, beta = chi
    v, om = u
    vh, omh = w
    g = alpha + beta
    sg, cg = math.sin(g), math.cos(g)
    return np.array([
        v * cg + d * om * sg - vh * math.cos(alpha),
        (vh * math.sin(alpha) - v * sg + d * om * cg) / rho - omh,
        omh - om,
    ])


def jacobians(chi: np.ndarray, u: np.ndarray, w: np.ndarray, d: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """Exact Jacobians ``(df/dchi, df/du)`` of :func:`dynamics`, shapes (3, 3) and (3, 2)."""
    rho, alpha, beta = chi
    v, om = u
    vh, _ = w
    g = alpha + beta
    sg, cg = math.sin(g), math.cos(g)
    sa, ca = math.sin(alpha), math.cos(alpha)
    dr_dg = -v * sg + d * om * cg          # d(rho_dot)/d(gamma)
    num = vh * sa - v * sg + d * om * cg   # rho * (alpha_dot + omega_h)
    dnum_dg = -v * cg - d * om * sg
    jx = np.array([
        [0.0, dr_dg + vh * sa, dr_dg],
        [-num / (rho * rho), (vh * ca + dnum_dg) / rho, dnum_dg / rho],
        [0.0, 0.0, 0.0],
    ])
    ju = np.array([
        [cg, d * sg],
        [-sg / rho, d * cg / rho],
        [0.0, -1.0],
    ])
    return jx, ju


def discretize(jx: np.ndarray, ju: np.ndarray, dt: float, method: str = "euler"
               ) -> tuple[np.ndarray, np.ndarray]:
    """Discretise the linearisation ``dx/dt = jx x + ju u`` with sample time ``dt``.

    ``method="euler"`` is the paper's forward Euler (``A = I + dt*jx``, ``B = dt*ju``);
    ``method="zoh"`` is the exact zero-order-hold discretisation via the matrix exponential.
    """
    n, m = ju.shape
    if method == "euler":
        return np.eye(n) + dt * jx, dt * ju
    if method == "zoh":
        block = np.zeros((n + m, n + m))
        block[:n, :n] = jx
        block[:n, n:] = ju
        e = expm(block * dt)
        return e[:n, :n], e[:n, n:]
    raise ValueError(f"discretize: method must be 'euler' or 'zoh', got {method!r}")


@dataclass(frozen=True)
class SlotReference:
    """Equilibrium of the companion model for a person moving with constant ``(v_h, omega_h)``.

    Attributes
    ----------
    beta : float
        Heading difference the robot must have to hold ``(rho_d, alpha_d)`` (rad).
    v, omega : float
        Robot input that holds the slot (m/s, rad/s).
    feasible : bool
        False when no equilibrium exists: the slot moves slower than ``d * |omega_h|``
        (the person turns about a point near the slot). The values are then the closest
        compromise (heading across the slot velocity, or at rest: beta = 0, v = 0).
    """

    beta: float
    v: float
    omega: float
    feasible: bool = True


def slot_reference(v_h: float, omega_h: float, rho_d: float, alpha_d: float, d: float
                   ) -> SlotReference:
    """Geometry-consistent feedforward: the input and heading that hold the desired slot.

    The desired reference point ``R_d = h + rho_d * e(theta_h + alpha_d)`` moves with velocity
    ``V = v_h e(theta_h) + rho_d omega_h e_perp(theta_h + alpha_d)``. The robot holds it when
    its heading turns at ``omega_h`` and its reference point moves with ``V``:
    ``v e(theta_r) + d omega_h e_perp(theta_r) = V``. Of the two headings that solve this
    (forward or reverse driving), the one closer to the person's heading is taken.
    This is an exact equilibrium of :func:`dynamics` (NOTES.md point 6) whenever one exists,
    i.e. when ``|V| >= d |omega_h|``; otherwise ``feasible`` is False.

    Everything is expressed in the person's frame, so the result does not depend on
    ``theta_h``.
    """
    # V in the person's frame (x along the person's heading).
    vx = v_h - rho_d * omega_h * math.sin(alpha_d)
    vy = rho_d * omega_h * math.cos(alpha_d)
    speed = math.hypot(vx, vy)
    lateral = d * omega_h
    feasible = speed >= abs(lateral)
    if speed < 1e-9:
        return SlotReference(beta=0.0, v=0.0, omega=omega_h, feasible=feasible)
    psi = math.atan2(vy, vx)
    ratio = max(-1.0, min(1.0, lateral / speed))
    delta = math.asin(ratio)
    along = math.sqrt(max(speed * speed - lateral * lateral, 0.0))
    # Forward solution: theta_r = psi - delta, v = +along; reverse: theta_r = psi + pi + delta.
    theta_fwd = psi - delta
    theta_rev = psi + math.pi + delta
    if abs(wrap_pi(theta_fwd)) <= abs(wrap_pi(theta_rev)):
        return SlotReference(wrap_pi(-theta_fwd), along, omega_h, feasible)
    return SlotReference(wrap_pi(-theta_rev), -along, omega_h, feasible)
