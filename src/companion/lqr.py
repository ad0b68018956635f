"""Augmented-state discrete LQR of the companion controller (paper Sec. 3.2, Eq. 11-15).

The augmented state is ``xi = [chi_e; u_e(k-1)]`` and the decision variable is the input
increment ``du = u_e(k) - u_e(k-1)``:

    xi(k+1) = A_bar xi(k) + B_bar du(k),   A_bar = [[A, B], [0, I]],   B_bar = [[B], [I]]

(NOTES.md point 4 for the printed dimension slips). The gain minimises
``sum xi' Q xi + du' R du`` and comes from the discrete algebraic Riccati equation (Eq. 15).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_discrete_are


def augment(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Build ``(A_bar, B_bar)`` of Eq. (12) from the discrete model ``(A, B)``.

    Parameters
    ----------
    a : ndarray, shape (n, n)
    b : ndarray, shape (n, m)
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    n, m = _shape_of_b(b, "augment")
    if a.shape != (n, n):
        raise ValueError(f"augment: A must be ({n}, {n}) to match B {b.shape}, got {a.shape}")
    a_bar = np.zeros((n + m, n + m))
    a_bar[:n, :n] = a
    a_bar[:n, n:] = b
    a_bar[n:, n:] = np.eye(m)
    b_bar = np.vstack([b, np.eye(m)])
    return a_bar, b_bar


def _shape_of_b(b: np.ndarray, where: str) -> tuple[int, int]:
    if b.ndim != 2:
        raise ValueError(f"{where}: B must be a 2-D (n, m) matrix, got shape {b.shape}")
    return b.shape


def _check_weights(q: np.ndarray, r: np.ndarray, nx: int, nu: int) -> None:
    if q.shape != (nx, nx):
        raise ValueError(f"dlqr: Q must be ({nx}, {nx}), got {q.shape}")
    if r.shape != (nu, nu):
        raise ValueError(f"dlqr: R must be ({nu}, {nu}), got {r.shape}")
    if not np.allclose(q, q.T):
        raise ValueError("dlqr: Q must be symmetric")
    if not np.allclose(r, r.T):
        raise ValueError("dlqr: R must be symmetric")
    if np.min(np.linalg.eigvalsh(r)) <= 0.0:
        raise ValueError("dlqr: R must be positive definite")
    if np.min(np.linalg.eigvalsh(q)) < -1e-12:
        raise ValueError("dlqr: Q must be positive semi-definite")


def dlqr(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray, check: bool = True
         ) -> tuple[np.ndarray, np.ndarray]:
    """Discrete LQR gain ``K = (R + B'PB)^-1 B'PA`` (Eq. 14) and Riccati solution ``P`` (Eq. 15).

    Parameters
    ----------
    a : ndarray, shape (n, n)
    b : ndarray, shape (n, m)
    q : ndarray, shape (n, n), symmetric positive semi-definite
    r : ndarray, shape (m, m), symmetric positive definite
    check : bool
        Validate shapes and weights (skip only in a hot loop whose inputs were checked once).

    Returns
    -------
    k : ndarray, shape (m, n)
        Optimal gain; the control law is ``u = -K x``.
    p : ndarray, shape (n, n)
        Stabilising solution of the discrete algebraic Riccati equation.

    Raises
    ------
    ValueError
        If a matrix has the wrong shape or sign.
    numpy.linalg.LinAlgError
        If no stabilising solution exists (for example an uncontrollable mode on or outside
        the unit circle): the closed loop ``A - BK`` is checked, since the Riccati solver does
        not always detect this.
    """
    if check:
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        q = np.asarray(q, dtype=float)
        r = np.asarray(r, dtype=float)
        n, m = _shape_of_b(b, "dlqr")
        if a.shape != (n, n):
            raise ValueError(f"dlqr: A must be ({n}, {n}) to match B {b.shape}, got {a.shape}")
        _check_weights(q, r, n, m)
    p = solve_discrete_are(a, b, q, r)
    bt_p = b.T @ p
    k = np.linalg.solve(r + bt_p @ b, bt_p @ a)
    radius = np.max(np.abs(np.linalg.eigvals(a - b @ k)))
    if not radius < 1.0 - 1e-9:
        raise np.linalg.LinAlgError(
            f"dlqr: no stabilising solution (closed-loop spectral radius {radius:.12g})")
    return k, p


def riccati_residual(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray,
                     p: np.ndarray) -> float:
    """Largest absolute entry of the Eq. (15) residual ``A'PA - A'PB(R+B'PB)^-1 B'PA + Q - P``."""
    bt_p_a = b.T @ p @ a
    res = a.T @ p @ a - bt_p_a.T @ np.linalg.solve(r + b.T @ p @ b, bt_p_a) + q - p
    return float(np.max(np.abs(res)))
