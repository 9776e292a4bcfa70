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

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from pinobs.errors import (
    ConfigurationError,
    ContactWarning,
    DimensionError,
    GainError,
    NotResetError,
    ObserverDiverged,
)
from pinobs.model import Robot
from pinobs.model.robot import read_only
from pinobs.observers.base import Vector
from pinobs.observers.inekf import (
    GRAVITY,
    ContactKinematics,
    InEKFEstimate,
    InEKFGains,
    InEKFPrior,
    check_contacts,
    check_time,
    contact_kinematics,
    gammas,
    propagate_mean,
    rotation_to_quaternion,
    skew,
)
from pinobs.observers.linalg import cholesky_solve
from pinobs.tolerances import NO_CONTACT_WARN_TIME, QUATERNION_NORM_TOL

__all__ = ["QEKFState", "QuaternionEKF", "error_dynamics"]

_I3 = np.eye(3)


@dataclass(frozen=True)
class QEKFState:
    """The filter's state (immutable).

    Attributes:
        t: time [s].
        R: world from IMU rotation.
        x: rows ``v, p, d_1 … d_K`` (world frame) [m/s, m], shape ``(2 + K, 3)``.
        feet: index (into the kinematics' feet) of each ``d_j``, in state order.
        bias: ``(b_g, b_a)`` [rad/s, m/s²].
        P: covariance of ``(δθ, δv, δp, δd_1 … δd_K, δb_g, δb_a)``.
        imu: the held reading ``(ω̃, ã)``, or ``None`` before the first one.
        last_contact: time a foot was last in contact [s].
    """

    t: float
    R: Vector
    x: Vector
    feet: tuple[int, ...]
    bias: Vector
    P: Vector
    imu: Vector | None
    last_contact: float


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


class QuaternionEKF:
    """Contact-aided quaternion EKF (multiplicative attitude error; module docstring).

    Takes the arguments of :class:`pinobs.observers.inekf.InvariantEKF` and has its
    ``reset``/``update`` interface and :class:`InEKFEstimate` output.

    Raises:
        GainError: an ``imu_hold`` that is neither ``"previous"`` nor ``"average"``.
        UnknownNameError: a foot frame that is not in the model (names the frames).
        UnsupportedRobotError: a robot without a free-flyer root joint.
    """

    def __init__(
        self,
        robot: Robot | ContactKinematics,
        feet: Sequence[str] | None = None,
        *,
        gains: InEKFGains | None = None,
        gravity: ArrayLike = GRAVITY,
        imu_hold: str = "previous",
        imu_frame: str | None = None,
    ) -> None:
        if imu_hold not in ("previous", "average"):
            raise GainError(f"imu_hold must be 'previous' or 'average', got {imu_hold!r}")
        self.imu_hold = imu_hold
        self.kinematics = contact_kinematics(robot, feet, imu_frame)
        if gains is not None and not isinstance(gains, InEKFGains):
            raise GainError(f"gains must be an InEKFGains, got {type(gains).__name__}")
        self.gains = gains if gains is not None else InEKFGains()
        self.gravity = Robot.check_vector(gravity, 3, what="gravity")
        self.feet: tuple[str, ...] = tuple(self.kinematics.feet)
        self._nq_j = int(self.kinematics.nq_joints)
        self._nv_j = int(self.kinematics.nv_joints)
        placement = getattr(self.kinematics, "imu_placement", None)
        self.imu_placement: tuple[Vector, Vector] = (
            (np.eye(3), np.zeros(3))
            if placement is None
            else (np.asarray(placement[0], dtype=float), np.asarray(placement[1], dtype=float))
        )
        self._state: QEKFState | None = None
        self._estimate: InEKFEstimate | None = None
        self._warned = False

    def __repr__(self) -> str:
        return f"QuaternionEKF(feet={self.feet})"

    @property
    def state(self) -> QEKFState:
        """The current state (raises before ``reset``)."""
        if self._state is None:
            raise NotResetError("QuaternionEKF: call reset(t, q, ...) before update")
        return self._state

    @property
    def estimate(self) -> InEKFEstimate:
        """The last estimate (raises before ``reset``)."""
        if self._estimate is None:
            raise NotResetError("QuaternionEKF: call reset(t, q, ...) before update")
        return self._estimate

    def reset(
        self,
        t: float,
        q: ArrayLike,
        v: ArrayLike | None = None,
        *,
        gyro: ArrayLike | None = None,
        acc: ArrayLike | None = None,
        contacts: Mapping[str, bool] | Sequence[bool] | None = None,
        prior: InEKFPrior | None = None,
        bias: ArrayLike | None = None,
    ) -> InEKFEstimate:
        """Start at ``t`` [s] from the free-flyer ``q`` and ``v`` (as
        :meth:`pinobs.observers.inekf.InvariantEKF.reset`; same arguments and errors)."""
        from scipy.spatial.transform import Rotation

        t = check_time(t, None)
        nq, nv = 7 + self._nq_j, 6 + self._nv_j
        q = Robot.check_vector(q, nq, what="q")
        quat_norm = float(np.linalg.norm(q[3:7]))
        if abs(quat_norm - 1.0) > QUATERNION_NORM_TOL:
            raise ConfigurationError(
                f"q[3:7] = {q[3:7].tolist()} is not a unit quaternion (x, y, z, w) "
                f"(norm {quat_norm:.6g}); its norm must be 1 within {QUATERNION_NORM_TOL:g}"
            )
        v = np.zeros(nv) if v is None else Robot.check_vector(v, nv, what="v")
        if (gyro is None) != (acc is None):
            raise DimensionError("give both gyro and acc to reset, or neither")
        imu = None
        if gyro is not None and acc is not None:
            imu = np.concatenate(
                [Robot.check_vector(gyro, 3, what="gyro"), Robot.check_vector(acc, 3, what="acc")]
            )
        flags = (
            check_contacts(self.feet, contacts)
            if contacts is not None
            else [False] * len(self.feet)
        )
        prior = prior if prior is not None else InEKFPrior()
        if not isinstance(prior, InEKFPrior):
            raise GainError(f"prior must be an InEKFPrior, got {type(prior).__name__}")
        theta = np.zeros(6) if bias is None else Robot.check_vector(bias, 6, what="bias")
        R_bi, r_bi = self.imu_placement
        R_b = np.asarray(Rotation.from_quat(q[3:7]).as_matrix())
        x = np.array([R_b @ (v[:3] + np.cross(v[3:6], r_bi)), q[:3] + R_b @ r_bi])
        P = np.diag(
            np.repeat(
                [prior.attitude, prior.velocity, prior.position, prior.gyro_bias, prior.accel_bias],
                3,
            )
            ** 2
        )
        state = QEKFState(t, R_b @ R_bi, x, (), theta, P, imu, t)
        h, jac = self.kinematics.positions_and_jacobians(q[7:])
        state = self._add_feet(state, [j for j, f in enumerate(flags) if f], h, jac)
        self._commit(state, q[7:], None, None, t if state.feet else None)
        self._warned = False
        return self.estimate

    def update(
        self,
        t: float,
        q: ArrayLike,
        gyro: ArrayLike,
        acc: ArrayLike,
        contacts: Mapping[str, bool] | Sequence[bool],
        *,
        joint_velocities: ArrayLike | None = None,
    ) -> InEKFEstimate:
        """One sample (as :meth:`pinobs.observers.inekf.InvariantEKF.update`: same arguments,
        conventions and errors): propagate with the held reading, correct, store the reading."""
        state = self.state
        t = check_time(t, state.t)
        q = np.asarray(q, dtype=float)
        if q.shape == (7 + self._nq_j,):
            q = q[7:]
        q_joints = Robot.check_vector(q, self._nq_j, what="q")
        reading = np.concatenate(
            [Robot.check_vector(gyro, 3, what="gyro"), Robot.check_vector(acc, 3, what="acc")]
        )
        flags = check_contacts(self.feet, contacts)
        dq = (
            None
            if joint_velocities is None
            else Robot.check_vector(joint_velocities, self._nv_j, what="joint_velocities")
        )
        held = state.imu if state.imu is not None else reading
        if self.imu_hold == "average":
            held = 0.5 * (held + reading)
        new = self._propagate(state, held, t - state.t, t)
        h, jac = self.kinematics.positions_and_jacobians(q_joints)
        h, jac = np.asarray(h, dtype=float), np.asarray(jac, dtype=float)
        ended = [s for s, j in enumerate(new.feet) if not flags[j]]
        if ended:
            new = self._remove_feet(new, ended)
        nis = None
        if new.feet:
            new, nis = self._update(new, h, jac)
        landed = [j for j, f in enumerate(flags) if f and j not in new.feet]
        if landed:
            new = self._add_feet(new, landed, h, jac)
        new = replace(new, imu=reading)
        if not any(flags) and not self._warned and t - new.last_contact >= NO_CONTACT_WARN_TIME:
            self._warned = True
            warnings.warn(
                f"QuaternionEKF: no foot in contact for {t - new.last_contact:.3g} s: the "
                f"velocity is the IMU's open-loop integral and drifts; contacts must set each "
                f"of {', '.join(self.feet)} to True while it is on the ground",
                ContactWarning,
                stacklevel=2,
            )
        self._commit(new, q_joints, dq, nis, t if any(flags) else None)
        return self.estimate

    # ------------------------------------------------------------- the steps
    def _propagate(self, state: QEKFState, imu: Vector, dt: float, t: float) -> QEKFState:
        """Mean by the exact flow, covariance by eq. (2) discretised (module docstring)."""
        w = imu[:3] - state.bias[:3]
        a = imu[3:] - state.bias[3:]
        K = state.x.shape[0] - 2
        R1, v1, p1 = propagate_mean(state.R, state.x[0], state.x[1], w, a, dt, self.gravity)
        R1 = R1 @ (1.5 * _I3 - 0.5 * (R1.T @ R1))
        x1 = state.x.copy()
        x1[0], x1[1] = v1, p1
        Fh = error_dynamics(state.R, w, a, K) * dt
        Fh2 = Fh @ Fh
        Phi = np.eye(Fh.shape[0]) + Fh + 0.5 * Fh2 + Fh2 @ Fh / 6.0
        g = self.gains
        qc = np.concatenate(
            [
                np.full(3, g.gyro**2),
                np.full(3, g.accel**2),
                np.zeros(3),
                np.full(3 * K, g.contact**2),
                np.full(3, g.gyro_bias**2),
                np.full(3, g.accel_bias**2),
            ]
        )
        Q = (Phi * qc) @ Phi.T
        Q.flat[:: Q.shape[0] + 1] += qc
        P = Phi @ state.P @ Phi.T + 0.5 * dt * Q
        return replace(state, t=t, R=R1, x=x1, P=0.5 * (P + P.T))

    def _noise(self, jac: Vector) -> Vector:
        """``N_j = J_j Σ_q J_jᵀ + σ_k² I`` (eq. 3), for a stack of ``J`` (m, 3, n)."""
        g = self.gains
        return (g.joint**2) * (jac @ np.swapaxes(jac, -1, -2)) + (g.kinematics**2) * _I3

    def _update(self, state: QEKFState, h: Vector, jac: Vector) -> tuple[QEKFState, float]:
        """Eqs. (3)-(4) for every foot in the state."""
        R, x, P = state.R, state.x, state.P
        n = P.shape[0]
        k = len(state.feet)
        H = np.zeros((3 * k, n))
        N = np.zeros((3 * k, 3 * k))
        r = np.empty(3 * k)
        blocks = self._noise(jac[list(state.feet)])
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
        return replace(state, R=R1, x=x1, bias=bias, P=0.5 * (P1 + P1.T)), nis

    def _add_feet(self, state: QEKFState, new: list[int], h: Vector, jac: Vector) -> QEKFState:
        """Eq. (5): each new foot at ``p̂ + R̂ h_j``."""
        R, x, P = state.R, state.x, state.P
        for j in new:
            n = P.shape[0]
            at = n - 6
            F = np.zeros((n + 3, n))
            F[:at, :at] = np.eye(at)
            F[at : at + 3, 0:3] = -R @ skew(h[j])
            F[at : at + 3, 6:9] = _I3
            F[at + 3 :, at:] = np.eye(6)
            P = F @ P @ F.T
            P[at : at + 3, at : at + 3] += R @ self._noise(jac[j][None])[0] @ R.T
            x = np.vstack([x, x[1] + R @ h[j]])
        return replace(state, x=x, P=P, feet=state.feet + tuple(new))

    @staticmethod
    def _remove_feet(state: QEKFState, slots: list[int]) -> QEKFState:
        n = state.P.shape[0]
        drop = np.concatenate([np.arange(9 + 3 * s, 12 + 3 * s) for s in slots])
        keep = np.setdiff1d(np.arange(n), drop)
        rows = np.setdiff1d(np.arange(state.x.shape[0]), [2 + s for s in slots])
        feet = tuple(f for s, f in enumerate(state.feet) if s not in slots)
        return replace(state, x=state.x[rows], P=state.P[np.ix_(keep, keep)], feet=feet)

    def _commit(
        self,
        state: QEKFState,
        q_joints: Vector,
        dq: Vector | None,
        nis: float | None,
        contact_time: float | None,
    ) -> None:
        if contact_time is not None:
            state = replace(state, last_contact=contact_time)
        total = float(state.R.sum() + state.x.sum() + state.P.sum() + state.bias.sum())
        if not math.isfinite(total):
            raise ObserverDiverged(
                f"QuaternionEKF: non-finite estimate at t = {state.t!r}",
                t=state.t,
                last_estimate=self._estimate,
            )
        R, x = state.R, state.x
        omega = (state.imu[:3] if state.imu is not None else np.zeros(3)) - state.bias[:3]
        R_bi, r_bi = self.imu_placement
        R_b = R @ R_bi.T
        p_b = x[1] - R_b @ r_bi
        w_b = R_bi @ omega
        v_b = R_b.T @ x[0] - np.cross(w_b, r_bi)
        q = np.concatenate([p_b, rotation_to_quaternion(R_b), q_joints])
        v = np.concatenate([v_b, w_b, np.full(self._nv_j, np.nan) if dq is None else dq])
        self._state = state
        self._estimate = InEKFEstimate(
            t=state.t,
            q=read_only(q),
            v=read_only(v),
            rotation=read_only(R_b),
            velocity_world=read_only(R_b @ v_b),
            bias=read_only(state.bias),
            covariance=read_only(state.P),
            contacts=tuple(self.feet[j] for j in state.feet),
            foot_positions=read_only(x[2:]),
            nis=nis,
        )
