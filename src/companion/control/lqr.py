"""LQR companion controller (paper Sec. 3.2, Eq. 10-16) with our two corrections.

Per sample period:

1. measure ``chi`` from the robot and person poses;
2. feedforward ``u_d`` and heading target ``beta_d``: either the paper's ``u_d = u_h``,
   ``beta_d = 0`` or the geometry-consistent slot reference (:func:`companion.model.slot_reference`);
3. linearise Eq. (7) at the desired state (paper) or the measured one (ours), discretise, augment;
4. clip the state error to ``lqr.error_clip`` (ours; the quadratic model is local, so far from
   the slot the controller acts on a bounded error, like tracking a virtual slot that leads the
   robot towards the real one);
5. solve the Riccati equation for ``K`` (compiled by default, :mod:`companion.fastlqr`; scipy's
   ``solve_discrete_are`` with ``lqr.solver = "scipy"``) and apply ``u = u_d + u_e(k-1) - K xi`` (Eq. 16), clipped
   to the input limits; the stored ``u_e(k-1)`` is what was actually applied minus ``u_d``, so
   saturation cannot wind it up (the layers around the controller report the final command
   through :meth:`LqrController.applied`).

docs/model.md explains the choices and their measured effect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion import _jitcache
from companion.control.base import Command, Observation, saturate
from companion.fastlqr import (OP_FIELDS, lqr_gain, lqr_output_nb, lqr_prepare_nb,
                               lqr_step_config, model_zoh_nb, stabilising_gain)
from companion.kinematics import wrap_pi
from companion.lqr import augment, dlqr
from companion.model import discretize, jacobians, relative_state, slot_reference
from companion.params import Params


REST_SPEED = 0.5  # m/s, person speed assumed by the fallback gain
#: Name of the step's kernels in the compile cache (:func:`compile_step_kernels`).
STEP_KERNELS = "lqr_step"


def rest_operating_point(params: Params) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(chi, u, w)`` of the fallback gain: the desired slot for a person walking straight
    at ``REST_SPEED``."""
    f = params.formation
    ref = slot_reference(REST_SPEED, 0.0, f.distance, f.bearing, params.robot.d)
    return (np.array([f.distance, f.bearing, ref.beta]), np.array([ref.v, ref.omega]),
            np.array([REST_SPEED, 0.0]))


def reference_solution(chi, u, w, params: Params, check: bool = False
                       ) -> tuple[np.ndarray, np.ndarray]:
    """``(K, P)`` of the augmented model linearised at ``(chi, u, w)`` (rho floored at
    ``lqr.rho_min``) by the reference path: the model of :mod:`companion.model` and scipy's
    ``solve_discrete_are`` (:func:`companion.lqr.dlqr`, which raises
    ``numpy.linalg.LinAlgError`` where no stabilising gain exists)."""
    lqr = params.lqr
    lin = np.array([max(chi[0], lqr.rho_min), chi[1], chi[2]])
    jx, ju = jacobians(lin, np.asarray(u, dtype=float), np.asarray(w, dtype=float),
                       params.robot.d)
    a_bar, b_bar = augment(*discretize(jx, ju, params.dt, lqr.discretization))
    return dlqr(a_bar, b_bar, np.diag(lqr.q), np.diag(lqr.r), check=check)


@dataclass(frozen=True)
class LqrStep:
    """Diagnostics of one controller step (for logs, tests and plots)."""

    xi: np.ndarray      # augmented state [rho_e, alpha_e, beta_e, v_e(k-1), omega_e(k-1)]
    gain: np.ndarray    # K, shape (2, 5)
    u_d: tuple[float, float]
    beta_d: float


class LqrController:
    """Augmented-state LQR companion controller; see the module docstring.

    With ``lqr.solver = "compiled"`` (default) a step is
    :func:`companion.fastlqr.lqr_prepare_nb` (relative state, feedforward, forward-Euler model;
    a zero-order-hold controller then calls :func:`companion.fastlqr.model_zoh_nb`),
    :func:`companion.fastlqr.stabilising_gain` (:func:`companion.fastlqr.dare_gain_nb`, and
    numpy's eigenvalues where its stability test cannot decide) and
    :func:`companion.fastlqr.lqr_output_nb`; with ``"scipy"`` the same step runs in Python with
    scipy's Riccati solver (the reference; tests/test_fastlqr.py checks they agree).
    """

    def __init__(self, params: Params):
        self.params = params
        lqr = params.lqr
        self._q_diag = np.array(lqr.q, dtype=float)
        self._r_diag = np.array(lqr.r, dtype=float)
        self._compiled = lqr.solver == "compiled"
        self._zoh = lqr.discretization == "zoh"
        self._config = lqr_step_config(params)
        helper = None
        if self._compiled and not lqr_prepare_nb.signatures:
            # First compiled LQR of this process: if the step's kernels are not in the cache
            # yet, a helper process compiles them while this one compiles the gain below.
            helper = _jitcache.compile_in_helper(STEP_KERNELS, "companion.control.lqr",
                                                 "compile_step_kernels")
        # Fallback gain for operating points without a stabilising Riccati solution (robot and
        # person at rest: the heading mode is then uncontrollable in the linearisation).
        try:
            self._rest_gain = self.gain(*rest_operating_point(params), check=True)
        except BaseException:
            _jitcache.stop_helper(helper)
            raise
        _jitcache.wait_helper(helper)
        self._memory = np.zeros(3)    # [v_e(k-1), omega_e(k-1), 1 once a gain is known]
        self._gain = np.zeros((2, 5))
        self._xi = np.zeros(5)
        # Buffers of the compiled step (operating point, model, Riccati solution, gain).
        self._op = np.zeros(len(OP_FIELDS))
        self._a, self._b = np.zeros((5, 5)), np.zeros((5, 2))
        self._p, self._k = np.zeros((5, 5)), np.zeros((2, 5))
        self.reset()

    def reset(self) -> None:
        self._memory[:] = 0.0
        self._ref: tuple[float, float, float] | None = None   # (v_d, omega_d, beta_d)

    @property
    def rest_gain(self) -> np.ndarray:
        """Fallback gain while no stabilising gain has been found (a copy)."""
        return self._rest_gain.copy()

    @property
    def u_e_prev(self) -> tuple[float, float]:
        """``u_e(k-1)``: the last applied input minus its feedforward."""
        return float(self._memory[0]), float(self._memory[1])

    @property
    def last(self) -> LqrStep | None:
        """Diagnostics of the last step (None before the first)."""
        if self._ref is None:
            return None
        v_d, omega_d, beta_d = self._ref
        return LqrStep(xi=self._xi.copy(), gain=self._gain.copy(), u_d=(v_d, omega_d),
                       beta_d=beta_d)

    def reference(self, v_h: float, omega_h: float) -> tuple[float, float, float]:
        """``(beta_d, v_d, omega_d)`` of the configured feedforward for a person velocity."""
        p = self.params
        if p.lqr.feedforward == "person":
            return 0.0, v_h, omega_h
        ref = slot_reference(v_h, omega_h, p.formation.distance, p.formation.bearing, p.robot.d)
        return ref.beta, ref.v, ref.omega

    def gain(self, chi, u, w, check: bool = False) -> np.ndarray:
        """LQR gain ``K`` (shape (2, 5)) of the augmented model linearised at ``(chi, u, w)``,
        with the configured ``lqr.solver``.

        Raises ``numpy.linalg.LinAlgError`` where no stabilising gain exists.
        """
        if self._compiled:
            return lqr_gain(chi, u, w, self.params)
        k, _ = reference_solution(chi, u, w, self.params, check=check)
        return k

    def step(self, obs: Observation) -> Command:
        r, h = obs.robot, obs.person
        if not self._compiled:
            return self._step_reference(r, h)
        op, a, b = self._op, self._a, self._b
        lqr_prepare_nb(r.x, r.y, r.theta, h.x, h.y, h.theta, h.v, h.omega, self._config,
                       self._memory, op, self._xi, a, b)
        if self._zoh:
            model_zoh_nb(op[0], op[1], op[2], op[3], op[4], op[5], op[6], self._config[0],
                         self._config[1], a, b)
        found = stabilising_gain(a, b, self._q_diag, self._r_diag, self._p, self._k)
        v, om = lqr_output_nb(found, self._k, self._gain, self._rest_gain, self._memory,
                              self._xi, op, self._config)
        self._ref = (float(op[7]), float(op[8]), float(op[9]))
        return Command(v, om)

    def _step_reference(self, r, h) -> Command:
        """The step in Python with the configured (scipy) gain: what the compiled step does."""
        p = self.params
        rho, alpha, beta = relative_state(r.x, r.y, r.theta, h.x, h.y, h.theta, p.robot.d)
        beta_d, v_d, omega_d = self.reference(h.v, h.omega)
        rho_d, alpha_d = p.formation.distance, p.formation.bearing
        e_v, e_w = self.u_e_prev
        if p.lqr.linearize_at == "desired":
            chi_lin, u_lin = (rho_d, alpha_d, beta_d), (v_d, omega_d)
        else:
            chi_lin, u_lin = (rho, alpha, beta), (v_d + e_v, omega_d + e_w)
        try:
            self._gain[:, :] = self.gain(chi_lin, u_lin, (h.v, h.omega))
            self._memory[2] = 1.0
        except (np.linalg.LinAlgError, ValueError):
            # No stabilising Riccati solution here: keep the last good gain, or use the
            # fallback computed at construction.
            if self._memory[2] == 0.0:
                self._gain[:, :] = self._rest_gain
                self._memory[2] = 1.0
        c_rho, c_alpha, c_beta = p.lqr.error_clip
        self._xi[:] = (min(max(rho - rho_d, -c_rho), c_rho),
                       min(max(wrap_pi(alpha - alpha_d), -c_alpha), c_alpha),
                       min(max(wrap_pi(beta - beta_d), -c_beta), c_beta), e_v, e_w)
        du_v, du_w = (self._gain @ self._xi).tolist()
        v, om = saturate(v_d + e_v - du_v, omega_d + e_w - du_w, p.robot)
        self._memory[:2] = (v - v_d, om - omega_d)
        self._ref = (v_d, omega_d, beta_d)
        return Command(v, om)

    def applied(self, cmd: Command) -> None:
        """Store ``u_e(k-1)`` from the command actually sent (after the safety and avoidance
        layers), without the avoidance part ``u_ob`` (Eq. 20 adds it outside the LQR)."""
        if self._ref is not None:
            self._memory[0] = cmd.v - self._ref[0]
            self._memory[1] = cmd.omega - cmd.u_ob - self._ref[1]


def compile_step_kernels() -> None:
    """Compile (or load from the cache) ``lqr_prepare_nb`` and ``lqr_output_nb`` by running
    them on dummy buffers, then mark them compiled. :class:`LqrController` runs this in a
    helper process when it is first built with an empty cache, while it compiles the gain."""
    config = lqr_step_config(Params())
    memory, op, xi = np.zeros(3), np.zeros(len(OP_FIELDS)), np.zeros(5)
    k, gain = np.zeros((2, 5)), np.zeros((2, 5))
    lqr_prepare_nb(0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, config, memory, op, xi,
                   np.zeros((5, 5)), np.zeros((5, 2)))
    lqr_output_nb(True, k, gain, k, memory, xi, op, config)
    _jitcache.mark_compiled(STEP_KERNELS)
