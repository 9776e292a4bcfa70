"""Contact-aided quaternion (multiplicative) EKF: the baseline for :mod:`pinobs.observers.inekf`.

The filter most lab code runs (Bloesch et al., *State estimation for legged
robots: consistent fusion of leg kinematics and IMU*, RSS 2012; the quaternion EKF that
Hartley et al., IJRR 2020, compare with), written from the equations as an error-state
EKF in the form of Solà, *Quaternion kinematics for the error-state Kalman
filter* (arXiv:1711.02508, §5 and §7: the local angular error).  Same state,
inputs, measurements and noise parameters (:class:`InEKFGains`) as the
invariant EKF; only the error differs.  Numbers (1)-(5) are this docstring's.

State: ``R`` (world from IMU frame), ``v``, ``p`` (IMU's world velocity and
position), ``d_j`` (world position of foot j in contact), ``b = (b_g, b_a)``.
Error (true = estimate ⊕ error, "multiplicative" on the rotation)::

    R = R̂ Exp(δθ),  v = v̂ + δv,  p = p̂ + δp,  d_j = d̂_j + δd_j,  b = b̂ + δb       (1)

``e = (δθ, δv, δp, δd_1 … δd_K, δb_g, δb_a)``, ``9 + 3K + 6`` entries (the
order of the invariant EKF's error).  The mean propagates by the exact flow
of the IMU model for held readings (:func:`pinobs.observers.inekf.propagate_mean`,
shared).  Error dynamics (Solà §5.3.3, the error-state kinematics, with the local angular error;
``ω = ω̃ − b̂_g``, ``a = ã − b̂_a``)::

    δθ̇ = −ω^ δθ − δb_g − w_g,   δv̇ = −R̂ a^ δθ − R̂ δb_a − R̂ w_a,   δṗ = δv,
    δḋ_j = w_c,   δḃ_g = w_bg,   δḃ_a = w_ba                                        (2)

``F`` depends on the estimate (``R̂``, ``a``): the difference from the invariant
error, whose ``A`` does not.  ``Φ = I + F h + (F h)²/2 + (F h)³/6`` (``F`` at the
start of the step; the series' error is O((‖F‖ h)⁴)), and
``Q = ½ (Φ Q_c Φᵀ + Q_c) h``, ``Q_c = diag(σ_g², σ_a², 0, σ_c² …, σ_bg², σ_ba²)``
(``R̂ σ_a² I R̂ᵀ = σ_a² I``).

Measurement, each foot j in contact (``h_j(q̃)`` its position in the IMU frame
from the measured joint angles; Bloesch et al.'s kinematic measurement)::

    y_j = h_j(q̃) = Rᵀ (d_j − p) + J_j w_q + n_k,     ŷ_j = R̂ᵀ (d̂_j − p̂)
    H_j = [ŷ_j^, 0, −R̂ᵀ, 0 … R̂ᵀ (at δd_j) … 0, 0, 0],   N_j = J_j Σ_q J_jᵀ + σ_k² I   (3)

(from ``Rᵀ ≈ (I − δθ^) R̂ᵀ``).  Update::

    S = H P Hᵀ + N,  K = P Hᵀ S⁻¹,  e = K (y − ŷ),  state ⊕ e (eq. 1),
    P⁺ = (I − K H) P (I − K H)ᵀ + K N Kᵀ                                            (4)

(no covariance reset Jacobian for the rotation, as in most lab code).
A foot that lands is added from the updated estimate, ``d̂_j = p̂ + R̂ h_j``,
``δd_j = δp − R̂ h_j^ δθ + R̂ J_j w_q``::

    P ← F P Fᵀ + G R̂ N_j R̂ᵀ Gᵀ                                                     (5)

and a foot that lifts off is marginalised (rows and columns deleted).  The
sampled-data convention (the reading held from ``t_k`` to ``t_{k+1}``,
``imu_hold``) and the outputs (:class:`InEKFEstimate`, converted from the IMU
frame to the root joint) are the invariant EKF's; ``covariance`` is that of
``e`` above.
"""

from __future__ import annotations

import numpy as np

from pinobs.observers.base import Vector
from pinobs.observers.inekf import gammas, imu_step, skew
from pinobs.observers.legged_filter import LeggedFilter
from pinobs.observers.legs import (
    LegState,
    ResetInputs,
    foot_noise,
    noise_densities,
    replace_state,
)
from pinobs.observers.linalg import cholesky_solve

__all__ = ["QEKFState", "QuaternionEKF", "error_dynamics"]

_I3 = np.eye(3)
#: The quaternion EKF's state (:class:`pinobs.observers.legs.LegState`; ``P`` is the
#: covariance of ``(δθ, δv, δp, δd_1 … δd_K, δb_g, δb_a)``).
QEKFState = LegState


def error_dynamics(R: Vector, omega: Vector, acc: Vector, n_contacts: int) -> Vector:
    """Eq. (2): ``F`` of ``ė = F e`` (noise-free), ``(15 + 3K)`` square, at the estimate ``R̂``
    with the bias-corrected readings ``ω`` [rad/s] and ``a`` [m/s²]."""
    n = 15 + 3 * n_contacts
    F = np.zeros((n, n))
    F[0:3, 0:3] = -skew(omega)  # Solà §5.3.3: δθ̇ = −[ω]× δθ − δω_b
    F[0:3, n - 6 : n - 3] = -_I3
    F[3:6, 0:3] = -R @ skew(acc)  # δv̇ = −R [a]× δθ − R δa_b
    F[3:6, n - 3 :] = -R
    F[6:9, 3:6] = _I3  # δṗ = δv
    return F


class QuaternionEKF(LeggedFilter):
    """Contact-aided quaternion EKF (multiplicative attitude error; module docstring).

    Takes the arguments of :class:`pinobs.observers.inekf.InvariantEKF` that both take
    (:class:`~pinobs.observers.legged_filter.LeggedFilter`: not ``foot_gate``, ``joint_std``,
    ``slip_speed``, ``slip_gyro``) and has its ``reset``/``update`` interface and
    :class:`InEKFEstimate` output; ``InEKFGains.landing`` raises a foot's contact density
    over its first ``landing_time`` of contact as the invariant EKF's eq. (11) does.

    Raises:
        GainError: an ``imu_hold`` that is neither ``"previous"`` nor ``"average"``.
        UnknownNameError: a foot frame that is not in the model (names the frames).
        UnsupportedRobotError: a robot without a free-flyer root joint.
    """

    # ------------------------------------------------------------- the steps
    def _initial_covariance(self, a: ResetInputs) -> Vector:
        """The prior's velocity is the IMU frame's (as the invariant EKF's, its eq. 7):
        ``v = R v_b``, so ``δv = R̂ δv_b + v̂^ R̂ δθ`` to first order."""
        T = np.eye(15)
        T[3:6, 0:3] = skew(a.x[0]) @ a.R
        return T @ a.prior.covariance() @ T.T

    def _propagate(self, state: QEKFState, imu: Vector, dt: float, t: float) -> QEKFState:
        """Mean by the exact flow, covariance by eq. (2) discretised (module docstring)."""
        w = imu[:3] - state.bias[:3]
        a = imu[3:] - state.bias[3:]
        K = state.x.shape[0] - 2
        R1, x1 = imu_step(state.R, state.x, w, a, dt, self.gravity)
        Fh = error_dynamics(state.R, w, a, K) * dt
        Fh2 = Fh @ Fh
        Phi = np.eye(Fh.shape[0]) + Fh + 0.5 * Fh2 + Fh2 @ Fh / 6.0
        qc = self._landing(noise_densities(self.gains, K), state, dt)
        Q = (Phi * qc) @ Phi.T
        Q.flat[:: Q.shape[0] + 1] += qc
        P = Phi @ state.P @ Phi.T + 0.5 * dt * Q
        return replace_state(state, t=t, R=R1, x=x1, P=0.5 * (P + P.T))

    def _foot_noise(self, R: Vector, jac: Vector) -> Vector:
        """``R N_j Rᵀ``, ``N_j = J_j Σ_q J_jᵀ + σ_k² I`` (eq. 3), for one ``J`` (3, n)."""
        return R @ foot_noise(self.gains, jac[None])[0] @ R.T

    def _landing_attitude(self, R: Vector, h: Vector) -> Vector:
        """Eq. (5): ``δd_j = δp − R̂ h_j^ δθ + …``."""
        return -R @ skew(h)

    def _update(
        self, state: QEKFState, measured: list[int], h: Vector, jac: Vector
    ) -> tuple[QEKFState, float]:
        """Eqs. (3)-(4) for every foot in the state (``measured``, in state order)."""
        R, x, P = state.R, state.x, state.P
        n = P.shape[0]
        k = len(state.feet)
        H = np.zeros((3 * k, n))
        N = np.zeros((3 * k, 3 * k))
        r = np.empty(3 * k)
        blocks = foot_noise(self.gains, jac[list(state.feet)])  # eq. (3)'s N_j
        for s, j in enumerate(state.feet):
            rows = slice(3 * s, 3 * s + 3)
            y_hat = R.T @ (x[2 + s] - x[1])  # Bloesch et al.: s_i = Cᵀ (p_i − r)
            r[rows] = h[j] - y_hat
            H[rows, 0:3] = skew(y_hat)
            H[rows, 6:9] = -R.T
            H[rows, 9 + 3 * s : 12 + 3 * s] = R.T
            N[rows, rows] = blocks[s]
        HP = H @ P
        S = HP @ H.T + N
        rhs = np.column_stack([HP, r])
        sol, _ = cholesky_solve(S, rhs)
        Kt = sol[:, :n]
        nis = float(r @ sol[:, n])
        e = HP.T @ sol[:, n]  # K r
        R1 = R @ gammas(e[0:3])[0]  # eq. (1): R = R̂ Exp(δθ)
        x1 = x + e[3 : n - 6].reshape(-1, 3)
        bias = state.bias + e[n - 6 :]
        IKH = np.eye(n) - Kt.T @ H
        P1 = IKH @ P @ IKH.T + Kt.T @ N @ Kt
        return replace_state(state, R=R1, x=x1, bias=bias, P=0.5 * (P1 + P1.T)), nis
