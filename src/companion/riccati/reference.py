"""Reference solution of the LQR problem by scipy (``solve_discrete_are``), with input checks
that name the offending matrix, and the augmentation of Eq. (12)."""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_discrete_are

from companion._jit import jitable

#: Closed-loop spectral radius must be below 1 - RADIUS_MARGIN (both solvers).
RADIUS_MARGIN = 1e-9


def augment(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(A_bar, B_bar)`` of Eq. (12), ``[[A, B], [0, I]]`` and ``[[B], [I]]``, from the
    discrete model ``a`` (n, n), ``b`` (n, m): the state is augmented with the last input."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    n, m = _shape_of_b(b, "augment")
    if a.shape != (n, n):
        raise ValueError(f"augment: A must be ({n}, {n}) to match B {b.shape}, got {a.shape}")
    return augmented(a, b)


@jitable
def augmented(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`augment` without the input checks (also called from compiled kernels)."""
    n, m = b.shape
    a_bar = np.zeros((n + m, n + m))
    b_bar = np.zeros((n + m, m))
    for i in range(n):
        for j in range(n):
            a_bar[i, j] = a[i, j]
        for j in range(m):
            a_bar[i, n + j] = b[i, j]
            b_bar[i, j] = b[i, j]
    for i in range(m):
        a_bar[n + i, n + i] = 1.0
        b_bar[n + i, i] = 1.0
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
    """Discrete LQR gain ``K`` (Eq. 14) and Riccati solution ``P`` (Eq. 15) by scipy.

    Parameters
    ----------
    a : ndarray, shape (n, n)
    b : ndarray, shape (n, m)
    q : ndarray, shape (n, n), symmetric positive semi-definite
    r : ndarray, shape (m, m), symmetric positive definite
    check : bool
        Validate shapes and weights (skip only where the inputs were checked once).

    Returns
    -------
    k : ndarray, shape (m, n)
        Optimal gain; the control law is ``u = -K x``.
    p : ndarray, shape (n, n)
        Stabilising solution of the Riccati equation.

    Raises
    ------
    ValueError
        If a matrix has the wrong shape or sign; the message names it.
    numpy.linalg.LinAlgError
        If no stabilising solution exists (the closed loop ``A - BK`` is checked, since the
        Riccati solver does not always detect this).
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
    if not radius < 1.0 - RADIUS_MARGIN:
        raise np.linalg.LinAlgError(
            f"dlqr: no stabilising solution (closed-loop spectral radius {radius:.12g})")
    return k, p


def riccati_residual(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray,
                     p: np.ndarray) -> float:
    """Largest absolute entry of the Eq. (15) residual ``A'PA - A'PB(R+B'PB)^-1 B'PA + Q - P``."""
    bt_p_a = b.T @ p @ a
    res = a.T @ p @ a - bt_p_a.T @ np.linalg.solve(r + b.T @ p @ b, bt_p_a) + q - p
    return float(np.max(np.abs(res)))
