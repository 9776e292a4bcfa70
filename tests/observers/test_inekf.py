"""The contact-aided invariant EKF (``pinobs.observers.inekf``): invariance, the autonomous
error dynamics, convergence, and the input checks.

The truths are made analytically, independently of the filter's closed forms: the IMU
readings (smooth functions of time, sampled) are held over each sample interval (the
filter's sampled-data convention), and the base moves by the exact flow of the IMU
model, ``s(h) = expm(L h) s(0)`` for ``s = (vec R, v, p, 1)`` (a generic 16 × 16
matrix exponential); the feet stay at fixed world points while in contact, and the
joint angles are the inverse kinematics of the feet's base-frame positions.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.spatial.transform import Rotation
from threadpoolctl import threadpool_limits

import pinobs
from pinobs.errors import (
    ConfigurationError,
    ContactWarning,
    DimensionError,
    GainError,
    NotResetError,
    ObserverDiverged,
    TimestampError,
    UnknownNameError,
    UnsupportedRobotError,
)
from pinobs.model import FootKinematics
from pinobs.observers.imu_link import LEVER_TAU
from pinobs.observers.inekf import (
    GRAVITY,
    InEKFGains,
    InEKFPrior,
    InvariantEKF,
    error_transition,
    gammas,
    propagate_mean,
    right_invariant_error_matrix,
    skew,
)

G = np.array(GRAVITY)


@pytest.fixture(autouse=True, scope="module")
def _one_blas_thread():
    """Small matrices: BLAS threads only contend (the machine is shared)."""
    with threadpool_limits(limits=1):
        yield


GO1_FEET = ("FL_foot", "FR_foot", "RL_foot", "RR_foot")


# ----------------------------------------------------------------- the truths
class SyntheticLegs:
    """Three "legs" whose joint triples map to foot positions by ``c_j + M_j (q + 0.1 sin q)``."""

    def __init__(self, n_feet: int = 3) -> None:
        rng = np.random.default_rng(7)
        self.feet = tuple(f"foot{j}" for j in range(n_feet))
        self.nq_joints = self.nv_joints = 3 * n_feet
        self.c = np.array(
            [
                [
                    0.3 * math.cos(2 * math.pi * j / n_feet),
                    0.3 * math.sin(2 * math.pi * j / n_feet),
                    -0.4,
                ]
                for j in range(n_feet)
            ]
        )
        self.M = [Rotation.from_rotvec(rng.normal(size=3)).as_matrix() for _ in range(n_feet)]

    def positions_and_jacobians(self, q):
        q = np.asarray(q).reshape(-1, 3)
        h = np.array([self.c[j] + self.M[j] @ (q[j] + 0.1 * np.sin(q[j])) for j in range(len(q))])
        jac = np.zeros((len(q), 3, self.nv_joints))
        for j in range(len(q)):
            jac[j][:, 3 * j : 3 * j + 3] = self.M[j] * (1 + 0.1 * np.cos(q[j]))
        return h, jac

    def inverse(self, h):
        """Joint angles putting foot j at ``h[j]`` (Newton on ``u + 0.1 sin u = Mᵀ(h − c)``)."""
        out = []
        for j, hj in enumerate(h):
            y = self.M[j].T @ (hj - self.c[j])
            u = y.copy()
            for _ in range(50):
                u -= (u + 0.1 * np.sin(u) - y) / (1 + 0.1 * np.cos(u))
            out.append(u)
        return np.concatenate(out)


def flow(R, v, p, omega, acc, h):
    """The exact flow of ``Ṙ = R ω^, v̇ = R a + g, ṗ = v`` with ω, a held, as one generic expm."""
    L = np.zeros((16, 16))
    W = skew(omega)
    for i in range(3):  # rows of R: d/dt R[i, :] = R[i, :] W
        L[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = W.T
        L[9 + i, 3 * i : 3 * i + 3] = acc  # v̇_i = R[i, :] · a + g_i
        L[12 + i, 9 + i] = 1.0
    L[9:12, 15] = G
    s = expm(L * h) @ np.concatenate([R.reshape(-1), v, p, [1.0]])
    return s[:9].reshape(3, 3), s[9:12], s[12:15]


def imu_reading(t, R, v, p, wobble=1.0):
    """Smooth body rates, and a specific force steering the base around a small oscillation."""
    omega = wobble * np.array([0.3 * math.sin(2 * t), 0.2 * math.cos(3 * t), 0.4 * math.sin(t)])
    p_ref = np.array([0.05 * math.sin(t), 0.03 * math.sin(1.3 * t), 0.02 * math.cos(2 * t)])
    acc_world = -4.0 * (p - p_ref) - 4.0 * v
    return omega, R.T @ (acc_world - G)


def truth(legs, rate, duration, *, swing=None, wobble=1.0, feet_z=-0.4, inverse=None):
    """Samples ``(t, R, v, p, q_joints, gyro, acc, contacts)`` of a base moving over fixed feet.

    ``swing``: ``(foot, t_off, t_on, step)``: that foot leaves the ground at ``t_off`` and lands
    ``step`` [m] further at ``t_on`` (it moves in between).
    """
    R, v, p = np.eye(3), np.zeros(3), np.zeros(3)
    h0, _ = legs.positions_and_jacobians(getattr(legs, "stance", np.zeros(legs.nq_joints)))
    d = h0.copy()
    if feet_z is not None:
        d[:, 2] = feet_z
    d_end = d.copy()
    if swing is not None:
        d_end[swing[0]] += swing[3]
    n = round(duration * rate)
    out = []
    for k in range(n + 1):
        t = k / rate
        feet = d.copy()
        contacts = [True] * len(d)
        if swing is not None:
            j, t_off, t_on, _ = swing
            if t >= t_on:
                feet[j] = d_end[j]
            elif t > t_off:
                s = (t - t_off) / (t_on - t_off)
                feet[j] = (
                    d[j] + s * (d_end[j] - d[j]) + np.array([0, 0, 0.05 * math.sin(math.pi * s)])
                )
                contacts[j] = False
        q = (inverse or legs.inverse)((feet - p) @ R)  # h_j = Rᵀ(d_j − p)
        omega, acc = imu_reading(t, R, v, p, wobble)
        out.append((t, R, v, p, q, omega, acc, contacts))
        R, v, p = flow(R, v, p, omega, acc, 1.0 / rate)
    return out


def free_flyer_q(R, p, q_joints):
    return np.concatenate([p, Rotation.from_matrix(R).as_quat(), q_joints])


def reset_through_imu(ekf, sample, R_bi, r_bi):
    """Reset ``ekf`` on the truth's first ``sample`` (its IMU's pose and twist) for a base
    whose IMU sits at ``(R_bi, r_bi)``: the base's pose and twist from the IMU's."""
    _, R_i, v_i, p_i, q, omega, acc, contacts = sample
    R_b = R_i @ R_bi.T
    omega_b = R_bi @ omega
    v0 = np.concatenate([R_b.T @ v_i - np.cross(omega_b, r_bi), omega_b, np.zeros(len(q))])
    ekf.reset(
        0.0, free_flyer_q(R_b, p_i - R_b @ r_bi, q), v0, gyro=omega, acc=acc, contacts=contacts
    )


def run(ekf, samples, *, R0=None, v0=None, prior=None):
    t, R, v, p, q, omega, acc, contacts = samples[0]
    R0 = R if R0 is None else R0
    v0 = v if v0 is None else v0
    ekf.reset(
        t,
        free_flyer_q(R0, p, q),
        np.concatenate([R0.T @ v0, omega, np.zeros(len(q))]),
        gyro=omega,
        acc=acc,
        contacts=contacts,
        prior=prior,
    )
    for t, R, v, p, q, omega, acc, contacts in samples[1:]:
        yield ekf.update(t, q, omega, acc, contacts), (R, v, p)


@cache
def synthetic_truth(rate=500.0, duration=3.0, swing=True, wobble=1.0):
    step = (1, 1.0, 1.4, np.array([0.05, 0.02, 0.0])) if swing else None
    return truth(SyntheticLegs(3), rate, duration, swing=step, wobble=wobble)


class Go1Legs(FootKinematics):
    """go1's real kinematics, with inverse kinematics by Newton's method (warm-started)."""

    stance = np.tile([0.0, 0.8, -1.6], 4)

    def __init__(self, imu_frame: str | None = None) -> None:
        super().__init__(pinobs.load("go1"), GO1_FEET, imu_frame=imu_frame)
        self._last = self.stance.copy()

    def inverse(self, targets):
        q = self._last.copy()
        for _ in range(30):
            h, jac = self.positions_and_jacobians(q)
            err = (targets - h).reshape(-1)
            if np.abs(err).max() < 1e-14:
                break
            q += np.linalg.solve(np.concatenate(jac), err)
        self._last = q
        return q


def pose_errors(est, R, v, p):
    return (
        np.abs(est.rotation - R).max(),
        np.abs(est.velocity_world - v).max(),
        np.abs(est.q[:3] - p).max(),
    )


# ------------------------------------------------------------ closed forms
@pytest.mark.parametrize("angle", [0.0, 1e-6, 0.05, 0.0999, 0.1001, 0.7, 3.0])
def test_gammas_equal_a_generic_matrix_exponential(angle: float) -> None:
    phi = angle * np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    M = np.zeros((9, 9))  # expm([[φ^, I, 0], [0, 0, I], [0, 0, 0]]) = [[Γ0, Γ1, Γ2], …]
    M[:3, :3] = skew(phi)
    M[:3, 3:6] = M[3:6, 6:9] = np.eye(3)
    E = expm(M)
    for m, gamma in enumerate(gammas(phi)):
        np.testing.assert_allclose(gamma, E[:3, 3 * m : 3 * m + 3], rtol=0, atol=1e-14)


def test_propagation_is_the_exact_flow_of_the_imu_model(rng) -> None:
    R = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    v, p = rng.normal(size=3), rng.normal(size=3)
    for omega, h in ((rng.normal(size=3) * 3, 0.5), (np.zeros(3), 0.1), (rng.normal(size=3), 1e-3)):
        acc = rng.normal(size=3) * 5
        got = propagate_mean(R, v, p, omega, acc, h)
        for a, b in zip(got, flow(R, v, p, omega, acc, h), strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


# ------------------------------------------------------------ invariance
def test_started_on_the_truth_it_stays_there_through_contact_changes() -> None:
    samples = synthetic_truth()
    ekf = InvariantEKF(SyntheticLegs(3))
    worst = 0.0
    seen = set()
    for est, (R, v, p) in run(ekf, samples):
        worst = max(worst, *pose_errors(est, R, v, p))
        seen.add(est.contacts)
        assert est.covariance.shape == (15 + 3 * len(est.contacts),) * 2
    assert worst < 1e-9
    # foot1 lifted at 1.0 s (removed), landed at 1.4 s (added back, last)
    assert seen == {("foot0", "foot1", "foot2"), ("foot0", "foot2"), ("foot0", "foot2", "foot1")}
    _t, R, v, p, q, *_ = samples[-1]
    h, _ = SyntheticLegs(3).positions_and_jacobians(q)
    np.testing.assert_allclose(est.foot_positions, (p + h @ R.T)[[0, 2, 1]], atol=1e-9)
    np.testing.assert_allclose(est.bias, 0.0, atol=1e-9)


@pytest.mark.parametrize("tau", [0.0, LEVER_TAU])
@pytest.mark.parametrize("imu_frame", [None, "imu_link"])
def test_started_on_the_truth_it_stays_there_on_go1(imu_frame: str | None, tau: float) -> None:
    """go1's kinematics; with ``imu_frame`` the IMU is 7 cm off the root joint: the truth is
    the IMU's motion and the estimate, of the root joint, is compared with the root's:
    exactly with the raw gyro in the lever arm (``lever_tau`` 0, imu_link.py's M3); with
    M4's low-pass (the default) the pose exactly and the root's velocity within the lag's
    bound ``|r_bi| τ max_k |ω_k − ω_{k−1}| / Δt`` (test_imu_link.py's TALOS test); at the
    root (no ``imu_frame``) there is no lever arm and nothing is low-passed."""
    rate = 200.0
    legs = Go1Legs(imu_frame)  # IK of the feet in the IMU's frame
    R_bi, r_bi = legs.imu_placement
    assert (np.linalg.norm(r_bi) > 0.05) == (imu_frame is not None)
    samples = truth(legs, rate, 2.0, wobble=0.5, feet_z=None, inverse=legs.inverse)
    gains = InEKFGains(lever_tau=tau)
    ekf = InvariantEKF(pinobs.load("go1"), GO1_FEET, imu_frame=imu_frame, gains=gains)
    reset_through_imu(ekf, samples[0], R_bi, r_bi)
    worst, linear = 0.0, 0.0
    for t, R_i, v_i, p_i, q, omega, acc, contacts in samples[1:]:
        est = ekf.update(t, q, omega, acc, contacts)
        R_b = R_i @ R_bi.T
        v_b = v_i - np.cross(R_i @ omega, R_b @ r_bi)  # the root's origin's world velocity
        rotation, velocity, position = pose_errors(est, R_b, v_b, p_i - R_b @ r_bi)
        worst, linear = max(worst, rotation, position), max(linear, velocity)
        np.testing.assert_allclose(est.v[3:6], R_bi @ omega, atol=1e-12)
    assert worst < 1e-9
    assert (ekf.state.lever is not None) == (imu_frame is not None and tau > 0)
    if ekf.state.lever is None:
        assert linear < 1e-9
    else:
        omegas = np.array([sample[5] for sample in samples])
        step = float(np.linalg.norm(np.diff(omegas, axis=0), axis=1).max())
        assert 1e-6 < linear <= float(np.linalg.norm(r_bi)) * tau * step * rate + 1e-9
    assert est.q.shape == (19,) and est.v.shape == (18,)
    tilt = np.arccos(np.clip(samples[-1][1][2, 2], -1, 1))
    assert tilt > 0.02  # the base did move


def test_update_checked_is_update_without_its_checks() -> None:
    """``update_checked`` (what ``legged_run`` called on the rows it checked once) with
    ``update_inputs``' answer is ``update``, bit for bit (go1, rolling feet, slip speeds);
    so is ``update_rows`` (what it calls now): its root rows and quaternion are the
    estimate's ``q`` and ``v``, and the estimate it leaves to make is ``update``'s;
    ``update`` still checks what it is given."""
    legs = Go1Legs("imu_link")
    samples = truth(legs, 200.0, 0.5, wobble=0.5, feet_z=None, inverse=legs.inverse)
    outs = []
    for how in ("update", "checked", "rows"):
        ekf = InvariantEKF(
            pinobs.load("go1"), GO1_FEET, imu_frame="imu_link", foot_radius=0.02, slip_speed=True
        )
        reset_through_imu(ekf, samples[0], *legs.imu_placement)
        rows = []
        for t, _, _, _, q, omega, acc, contacts in samples[1:]:
            dq = 0.1 * np.sin(np.arange(12) + t)
            u = ekf.setup.update_inputs(ekf.state.t, t, q, omega, acc, contacts, dq)
            if how == "checked":
                est = ekf.update_checked(u)
            elif how == "rows":
                base, quat, nis, dof, _ = ekf.update_rows(u)
                est = ekf.estimate  # made now, from what update_rows kept
                quat = -quat if quat[3] < 0 else quat
                np.testing.assert_array_equal(est.q, np.concatenate([base[0], quat, u.q_joints]))
                np.testing.assert_array_equal(est.v, np.concatenate([base[2], base[1], dq]))
                assert (nis, dof) == (est.nis, est.nis_dof)
            else:
                est = ekf.update(t, q, omega, acc, contacts, joint_velocities=dq)
            rows.append(np.concatenate([est.q, est.v, est.covariance.ravel()]))
        outs.append(rows)
    assert len(outs[0]) > 50
    for a, b, c in zip(*outs, strict=True):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)
    t, _, _, _, q, omega, acc, contacts = samples[-1]
    with pytest.raises(TimestampError):
        ekf.update(t, q, omega, acc, contacts)


# ----------------------------------------------------- autonomous error dynamics
def _log(R, x):
    """log of SE_K(3): ``(φ, ρ_1, …)`` with ``R = Γ_0(φ)``, ``x_i = Γ_1(φ) ρ_i``."""
    phi = Rotation.from_matrix(R).as_rotvec()
    return np.concatenate([phi, np.linalg.solve(gammas(phi)[1], x.T).T.reshape(-1)])


def _exp(xi):
    R = Rotation.from_rotvec(xi[:3]).as_matrix()
    return R, xi[3:].reshape(-1, 3) @ gammas(xi[:3])[1].T


def _step(R, x, omega, acc, h):
    R1, v1, p1 = propagate_mean(R, x[0], x[1], omega, acc, h)
    return R1, np.vstack([v1, p1, x[2:]])


def _fd_transition(R, x, omega, acc, h, *, left=False, eps=1e-6):
    """``∂ξ(h)/∂ξ(0)`` by central differences, ``ξ = log(X̂ X⁻¹)`` (or ``log(X⁻¹ X̂)``)."""
    n = 3 + 3 * x.shape[0]
    R1, x1 = _step(R, x, omega, acc, h)
    out = np.zeros((n, n))
    for i in range(n):
        cols = []
        for sign in (1.0, -1.0):
            dR, dx = _exp(sign * eps * np.eye(n)[i])
            if left:  # X̂ = X exp(ξ)
                Re, xe = R @ dR, x + dx @ R.T
            else:  # X̂ = exp(ξ) X
                Re, xe = dR @ R, x @ dR.T + dx
            Rh, xh = _step(Re, xe, omega, acc, h)
            if left:
                cols.append(_log(R1.T @ Rh, (xh - x1) @ R1))
            else:
                cols.append(_log(Rh @ R1.T, xh - x1 @ (Rh @ R1.T).T))
        out[:, i] = (cols[0] - cols[1]) / (2 * eps)
    return out


def test_right_invariant_error_dynamics_do_not_depend_on_the_trajectory(rng) -> None:
    h = 0.01
    A = right_invariant_error_matrix(2)
    expected = expm(A * h)
    transitions = {}
    for name in ("slow", "fast"):
        scale = 0.1 if name == "slow" else 3.0
        R = Rotation.from_rotvec(rng.normal(size=3) * scale).as_matrix()
        x = rng.normal(size=(4, 3)) * scale
        omega, acc = rng.normal(size=3) * 5 * scale, rng.normal(size=3) * 10 * scale
        transitions[name] = _fd_transition(R, x, omega, acc, h)
        transitions["left " + name] = _fd_transition(R, x, omega, acc, h, left=True)
        np.testing.assert_allclose(transitions[name], expected, rtol=0, atol=1e-7)
        # the filter's own transition: its ξ-block is exactly expm(A h)
        Phi = error_transition(R, x, omega, acc, h)
        np.testing.assert_allclose(Phi[:15, :15], expected, rtol=0, atol=1e-13)
    # the control: the left-invariant error's transition does depend on the trajectory
    assert np.abs(transitions["left slow"] - transitions["left fast"]).max() > 1e-2


def test_bias_columns_of_the_transition_match_finite_differences(rng) -> None:
    """Eq. (3): the "imperfect" columns, ``∂ξ(h)/∂ζ`` with ``ζ = θ̂ − θ``, the estimate's only entry."""
    h, eps = 0.02, 1e-6
    R = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    x = rng.normal(size=(3, 3))
    omega, acc = rng.normal(size=3) * 2, rng.normal(size=3) * 5
    Phi = error_transition(R, x, omega, acc, h)
    R1, x1 = _step(R, x, omega, acc, h)
    for i in range(6):
        cols = []
        for sign in (1.0, -1.0):
            dz = sign * eps * np.eye(6)[i]  # θ̂ = θ + ζ: the estimate sees readings minus ζ
            Rh, xh = _step(R, x, omega - dz[:3], acc - dz[3:], h)
            cols.append(_log(Rh @ R1.T, xh - x1 @ (Rh @ R1.T).T))
        np.testing.assert_allclose(Phi[:12, 12 + i], (cols[0] - cols[1]) / (2 * eps), atol=1e-8)
    np.testing.assert_array_equal(Phi[12:, 12:], np.eye(6))


# ---------------------------------------------------------------- convergence
@pytest.mark.parametrize("legs", ["synthetic", "go1"])
def test_converges_in_roll_pitch_and_velocity_from_30_degrees_and_1_m_per_s(legs: str) -> None:
    """Roll, pitch and the body-frame velocity are observable; yaw is not (its error and
    variance stay), so the world-frame velocity is not compared."""
    if legs == "go1":
        kin = Go1Legs()
        samples = truth(kin, 200.0, 4.0, wobble=0.5, feet_z=None, inverse=kin.inverse)
        ekf = InvariantEKF(pinobs.load("go1"), GO1_FEET)
    else:
        samples = synthetic_truth(rate=200.0, duration=6.0, swing=False)
        ekf = InvariantEKF(SyntheticLegs(3))
    R0, v0 = samples[0][1], samples[0][2]
    axis = np.array([1.0, 1.0, 0.0]) / math.sqrt(2)  # R0 = I: a pure 30° tilt
    Rw = Rotation.from_rotvec(math.radians(30) * axis).as_matrix() @ R0
    vw = v0 + np.array([0.6, 0.8, 0.0])
    prior = InEKFPrior(attitude=0.6, velocity=1.0)
    tilt, speed, yaw_var = [], [], []
    for est, (R, v, _) in run(ekf, samples, R0=Rw, v0=vw, prior=prior):
        cos = float(np.clip((est.rotation.T @ [0, 0, 1]) @ (R.T @ [0, 0, 1]), -1, 1))
        tilt.append(math.acos(cos))
        speed.append(np.linalg.norm(est.v[:3] - R.T @ v))
        yaw_var.append(est.covariance[2, 2])
    tilt, speed = np.array(tilt), np.array(speed)
    one_second = 200
    assert tilt[one_second] < 0.05 * math.radians(30) and speed[one_second] < 0.05
    assert tilt[-one_second:].max() < 2e-3 and speed[-one_second:].max() < 5e-3
    # yaw (the world z of ξ_R) is unobservable: its variance is never reduced
    assert min(yaw_var) > 0.6**2


# ------------------------------------------------------------------ outputs
def test_outputs_follow_pinocchio_free_flyer_conventions() -> None:
    legs = SyntheticLegs(3)
    samples = synthetic_truth()
    ekf = InvariantEKF(legs)
    for _ in run(ekf, samples[:11]):
        pass
    t, R, v, _, q, omega, acc, contacts = samples[11]
    est = ekf.update(t, q, omega, acc, contacts, joint_velocities=np.arange(9.0))
    np.testing.assert_allclose(est.q[3:7], Rotation.from_matrix(R).as_quat(), atol=1e-9)
    np.testing.assert_allclose(est.v[:3], R.T @ v, atol=1e-9)  # body-frame linear velocity
    np.testing.assert_allclose(est.v[3:6], omega, atol=1e-9)
    np.testing.assert_array_equal(est.v[6:], np.arange(9.0))
    np.testing.assert_array_equal(est.q[7:], q)
    t, R, v, _p, q, omega, acc, contacts = samples[12]
    est = ekf.update(t, np.concatenate([np.zeros(7), q]), omega, acc, contacts)  # a full q
    assert np.isnan(est.v[6:]).all()
    with pytest.raises(ValueError, match="read-only"):
        est.q[0] = 1.0


# ------------------------------------------------------------------ errors
def test_a_foot_frame_not_in_the_model_is_named_with_the_frames_that_are() -> None:
    with pytest.raises(UnknownNameError, match=r"'FL_fot'.*did you mean 'FL_foot'"):
        InvariantEKF(pinobs.load("go1"), ["FL_fot", "FR_foot"])


def test_a_robot_without_a_free_flyer_is_refused() -> None:
    with pytest.raises(UnsupportedRobotError, match="free-flyer"):
        InvariantEKF(pinobs.load("ur5"), ["tool0"])


def _started():
    samples = synthetic_truth()
    ekf = InvariantEKF(SyntheticLegs(3))
    t, R, _v, p, q, omega, acc, contacts = samples[0]
    ekf.reset(t, free_flyer_q(R, p, q), gyro=omega, acc=acc, contacts=contacts)
    return ekf, samples[1]


@pytest.mark.parametrize(
    ("field", "value", "error", "match"),
    [
        ("gyro", np.zeros(6), DimensionError, r"gyro must have shape \(3,\), got shape \(6,\)"),
        ("acc", np.zeros((3, 1)), DimensionError, r"acc must have shape \(3,\)"),
        ("acc", [0.0, np.nan, 9.8], ValueError, "acc has non-finite"),
        ("q", np.zeros(5), DimensionError, r"q must have shape \(9,\) .* or \(16,\)"),
        ("t", 0.0, TimestampError, "not after"),
        (
            "contacts",
            {"foot0": True, "foot1": True},
            UnknownNameError,
            "no entry for \\['foot2'\\]",
        ),
        ("contacts", {"foot0": 1, "foot1": 1, "foot2": 1, "paw": 0}, UnknownNameError, "'paw'"),
        ("contacts", [True, True], DimensionError, "2 entries, expected 3"),
        ("contacts", [True, True, "yes"], DimensionError, "'foot2'.* must be a bool"),
    ],
)
def test_bad_inputs_are_named_and_leave_the_filter_unchanged(field, value, error, match) -> None:
    ekf, (t, _R, _v, _p, q, omega, acc, contacts) = _started()
    before = ekf.state
    args = {"t": t, "q": q, "gyro": omega, "acc": acc, "contacts": contacts, field: value}
    with pytest.raises(error, match=match):
        ekf.update(**args)
    assert ekf.state is before


def test_update_before_reset_raises() -> None:
    ekf = InvariantEKF(SyntheticLegs(3))
    with pytest.raises(NotResetError, match="reset"):
        ekf.update(0.1, np.zeros(9), np.zeros(3), np.zeros(3), [True] * 3)


def test_contacts_never_set_warn_once_naming_the_feet() -> None:
    ekf, (_t, R, _v, p, q, omega, acc, _) = _started()
    ekf.reset(0.0, free_flyer_q(R, p, q), gyro=omega, acc=acc)
    with pytest.warns(ContactWarning, match="foot0, foot1, foot2") as record:
        for k in range(1, 200):
            ekf.update(k * 0.005, q, omega, acc, dict.fromkeys(ekf.feet, False))
    assert len(record) == 1
    assert ekf.estimate.contacts == ()


@pytest.mark.parametrize("name", ["gyro", "joint", "contact"])
def test_gains_are_validated(name: str) -> None:
    with pytest.raises(GainError, match=name):
        InEKFGains(**{name: -1.0})
    with pytest.raises(GainError, match="both 0"):
        InEKFGains(joint=0.0, kinematics=0.0)


# ---------------------------------------------------------------- consistency
def test_with_noise_matching_its_gains_the_innovations_are_chi2(rng) -> None:
    """Noisy gyro, accelerometer and encoders at the levels the gains say: the mean NIS of
    the foot measurements is χ²(9)'s mean, 9, and the error of the observable part
    (roll, pitch, velocity) is as large as the covariance says."""
    rate = 200.0
    samples = synthetic_truth(rate=rate, duration=6.0, swing=False)
    gains = InEKFGains(
        gyro=2e-3,
        accel=2e-2,
        gyro_bias=1e-6,
        accel_bias=1e-5,
        contact=1e-4,
        joint=2e-3,
        kinematics=0.0,
    )
    ekf = InvariantEKF(SyntheticLegs(3), gains=gains)
    noisy = [
        (
            t,
            R,
            v,
            p,
            q + rng.normal(0, gains.joint, q.shape),
            omega + rng.normal(0, gains.gyro * math.sqrt(rate), 3),
            acc + rng.normal(0, gains.accel * math.sqrt(rate), 3),
            contacts,
        )
        for t, R, v, p, q, omega, acc, contacts in samples
    ]
    nis, nees = [], []
    for est, (R, v, _) in run(ekf, noisy, prior=InEKFPrior(attitude=0.01, velocity=0.01)):
        nis.append(est.nis)
        # the observable part of the error: roll, pitch (world x, y of ξ_R) and ξ_v
        xi_R = Rotation.from_matrix(est.rotation @ R.T).as_rotvec()
        xi_v = est.velocity_world - est.rotation @ R.T @ v
        e = np.concatenate([xi_R[:2], xi_v])
        P = est.covariance[np.ix_([0, 1, 3, 4, 5], [0, 1, 3, 4, 5])]
        nees.append(e @ np.linalg.solve(P, e))
    mean_nis = float(np.mean(nis[200:]))  # after the first second; 1000 samples: σ = 0.13
    assert 9 * 0.9 < mean_nis < 9 * 1.1
    mean_nees = float(np.mean(nees[200:]))  # 5 dof, correlated in time: a loose band
    assert 5 * 0.5 < mean_nees < 5 * 1.5


# ------------------------------------------------------------- sampled smooth motion
def smooth_truth(legs, rate, duration):
    """A smooth base motion sampled: ``R(t) = Rz(ψ) Ry(θ) Rx(φ)``, ``p(t)`` analytic, and its
    exact IMU readings at the samples (gyro ``Rᵀ Ṙ``, accelerometer ``Rᵀ(p̈ − g)``): between
    samples they are not constant, so a filter that holds them errs by O(period)."""
    d = legs.positions_and_jacobians(np.zeros(legs.nq_joints))[0]
    d[:, 2] = -0.4
    out = []
    for k in range(round(duration * rate) + 1):
        t = k / rate
        angles = np.array([0.1 * math.sin(2 * t), 0.08 * math.sin(3 * t + 1), 0.3 * math.sin(t)])
        rates = np.array([0.2 * math.cos(2 * t), 0.24 * math.cos(3 * t + 1), 0.3 * math.cos(t)])
        rx, ry, rz = (
            Rotation.from_rotvec(a * e).as_matrix() for a, e in zip(angles, np.eye(3), strict=True)
        )
        R = rz @ ry @ rx
        Rdot = (
            rates[2] * rz @ skew([0, 0, 1]) @ ry @ rx
            + rates[1] * rz @ ry @ skew([0, 1, 0]) @ rx
            + rates[0] * R @ skew([1, 0, 0])
        )
        W = R.T @ Rdot
        omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
        p = np.array([0.05 * math.sin(t), 0.03 * math.sin(1.3 * t), 0.02 * math.cos(2 * t)])
        v = np.array([0.05 * math.cos(t), 0.039 * math.cos(1.3 * t), -0.04 * math.sin(2 * t)])
        a = np.array([-0.05 * math.sin(t), -0.0507 * math.sin(1.3 * t), -0.08 * math.cos(2 * t)])
        q = legs.inverse((d - p) @ R)
        out.append((t, R, v, p, q, omega, R.T @ (a - G), [True] * len(d)))
    return out


@pytest.mark.parametrize(("hold", "order"), [("previous", 1), ("average", 2)])
def test_sampling_a_smooth_motion_errs_in_a_power_of_the_period(hold: str, order: int) -> None:
    """Holding the reading at ``t_k`` over ``[t_k, t_{k+1}]`` is exact for readings that are
    held, first order for readings sampled from a smooth motion; holding the mean of the two
    bounding readings is second order (measured at 200 Hz: tilt 8.2e-4 and 1.8e-6 rad, body
    velocity 1.1e-3 and 5.7e-6 m/s)."""
    legs = SyntheticLegs(3)
    worst = {}
    for rate in (200.0, 400.0):
        ekf = InvariantEKF(legs, gains=InEKFGains(joint=1e-4, kinematics=0.0), imu_hold=hold)
        tilt, speed = [], []
        for est, (R, v, _) in run(ekf, smooth_truth(legs, rate, 3.0)):
            cos = (est.rotation.T @ [0, 0, 1]) @ (R.T @ [0, 0, 1])
            tilt.append(math.acos(min(1.0, cos)))
            speed.append(np.linalg.norm(est.v[:3] - R.T @ v))
        worst[rate] = (max(tilt), max(speed))
    bound = 1e-3 if order == 1 else 1e-5
    assert worst[200.0][0] < bound and worst[200.0][1] < 2 * bound
    for i in range(2):
        assert 0.8 * 2**order < worst[200.0][i] / worst[400.0][i] < 1.25 * 2**order


def test_an_unknown_imu_hold_is_refused() -> None:
    with pytest.raises(GainError, match="imu_hold must be 'previous' or 'average', got 'next'"):
        InvariantEKF(SyntheticLegs(3), imu_hold="next")


def test_reset_refuses_a_quaternion_off_unit_norm() -> None:
    ekf = InvariantEKF(SyntheticLegs(3))
    q = np.concatenate([np.zeros(3), [0.0, 0.0, 0.0, 2.0], np.zeros(9)])
    with pytest.raises(ConfigurationError, match=r"q\[3:7\].*not a unit quaternion"):
        ekf.reset(0.0, q)


def test_a_non_finite_estimate_raises_and_keeps_the_last_state() -> None:
    class Broken(SyntheticLegs):
        def positions_and_jacobians(self, q):
            h, jac = super().positions_and_jacobians(q)
            return h * np.nan if q[0] > 100 else h, jac

    samples = synthetic_truth()
    ekf = InvariantEKF(Broken(3))
    for _ in run(ekf, samples[:5]):
        pass
    before = ekf.state
    t, _, _, _, q, omega, acc, contacts = samples[5]
    with pytest.raises(ObserverDiverged, match="non-finite") as info:
        ekf.update(t, q + 1000.0, omega, acc, contacts)
    assert ekf.state is before and info.value.last_estimate is ekf.estimate


def test_the_estimate_has_every_field_its_constructor_sets() -> None:
    """The estimate is built by one dictionary update (not ``InEKFEstimate.__init__``): it has
    each field, and equals the estimate the constructor makes of them."""
    import dataclasses

    from pinobs.observers.legs import InEKFEstimate

    samples = synthetic_truth()
    ekf = InvariantEKF(SyntheticLegs(3), foot_gate=0.01)
    for est, _ in run(ekf, samples[:5]):
        values = {f.name: getattr(est, f.name) for f in dataclasses.fields(InEKFEstimate)}
        assert set(vars(est)) == set(values)
        assert est == InEKFEstimate(**values) and est.nis_dof > 0
        with pytest.raises(dataclasses.FrozenInstanceError):
            est.t = 0.0  # type: ignore[misc]


# ------------------------------------------------------------------ invariance
def test_moving_the_world_origin_leaves_the_velocity_estimate_unchanged() -> None:
    """A translation of the world is a symmetry of the legged system; with the prior on the
    base's own errors (mapped to the right-invariant error at the estimate), the filter is
    equivariant: the same velocity and attitude, the position shifted by the translation.
    (With a diagonal prior on ξ the velocity was already unchanged, to 1e-13 m/s, but the
    final position differed by 0.97 m for this 14 m shift.)  Rounding grows as |shift|²
    (the prior's p̂^ terms): 2e-11 m/s here, 2e-9 at 140 m."""
    samples = synthetic_truth(rate=200.0, duration=2.0, swing=True)
    R0 = Rotation.from_rotvec([0.3, -0.2, 0.1]).as_matrix() @ samples[0][1]
    v0 = samples[0][2] + np.array([0.3, -0.2, 0.1])
    prior = InEKFPrior(attitude=0.4, velocity=0.5)
    shift = np.array([12.0, -7.5, 0.4])  # [m]
    out = []
    for offset in (np.zeros(3), shift):
        moved = [(s[0], s[1], s[2], s[3] + offset, *s[4:]) for s in samples]
        ekf = InvariantEKF(SyntheticLegs(3))
        estimates = run(ekf, moved, R0=R0, v0=v0, prior=prior)
        out.append([(e.v[:3], e.rotation, e.q[:3]) for e, _ in estimates])
    for (v_a, R_a, p_a), (v_b, R_b, p_b) in zip(*out, strict=True):
        assert np.abs(v_a - v_b).max() < 1e-9
        assert np.abs(R_a - R_b).max() < 1e-9
        assert np.abs(p_b - p_a - shift).max() < 1e-9
