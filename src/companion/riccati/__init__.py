"""The discrete algebraic Riccati equation of the augmented LQR (paper Sec. 3.2, Eq. 11-15).

Two solvers of one problem, ``P = A'PA - A'PB (R + B'PB)^-1 B'PA + Q`` with the gain
``K = (R + B'PB)^-1 B'PA``:

* the reference, :func:`dlqr` (:mod:`.reference`): scipy's ``solve_discrete_are`` with input
  checks and a closed-loop stability test (~0.6 ms);
* the compiled solver, :func:`dare_gain` (:mod:`.doubling`): structure-preserving doubling and
  a Newton polish for the 5x5 augmented model (~8 us), used at every controller step.

They agree to 1e-8 relative wherever scipy itself is accurate (tests/test_riccati.py).
"""

from __future__ import annotations

import numpy as np

from companion.riccati.doubling import (
    GAIN_FAILED,
    GAIN_STABLE,
    GAIN_UNDECIDED,
    NU,
    NX,
    dare_gain,
    spectral_radius_below,
    stabilising_gain,
)
from companion.riccati.reference import RADIUS_MARGIN, augment, augmented, dlqr, riccati_residual

__all__ = ["GAIN_FAILED", "GAIN_STABLE", "GAIN_UNDECIDED", "NU", "NX", "RADIUS_MARGIN",
           "augment", "augmented", "dare_gain", "dlqr", "riccati_residual", "solve_gain",
           "spectral_radius_below", "stabilising_gain"]


def solve_gain(a: np.ndarray, b: np.ndarray, q_diag: np.ndarray, r_diag: np.ndarray,
               solver: str = "compiled") -> np.ndarray | None:
    """The LQR gain ``K`` (2, 5) of the augmented model ``a`` (5, 5), ``b`` (5, 2) with the
    weights' diagonals, by ``solver`` ("compiled": :func:`dare_gain`; "scipy": :func:`dlqr`);
    None where no stabilising gain exists."""
    if solver == "scipy":
        try:
            return dlqr(a, b, np.diag(q_diag), np.diag(r_diag), check=False)[0]
        except (np.linalg.LinAlgError, ValueError):
            return None
    k, p = np.empty((NU, NX)), np.empty((NX, NX))
    return k if stabilising_gain(a, b, q_diag, r_diag, p, k) else None
