"""The invariant EKF's foot noise: the encoders' covariance through the legs' Jacobian
(``joint_std``, eq. 4) and the contact noise from the foot's predicted speed
(``slip_speed``, eq. 9) of ``pinobs.observers.inekf``."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.errors import DimensionError, GainError, NonFiniteError
from pinobs.observers.inekf import InEKFGains, InvariantEKF
from pinobs.observers.legs import foot_noise, noise_densities, slip_densities, slip_speeds
from tests.observers.test_inekf import GO1_FEET, Go1Legs, free_flyer_q, pose_errors, truth

#: σ per joint [rad], different on every joint (go1: 12)
SIGMA = np.linspace(4e-5, 2e-4, 12)


def test_foot_noise_is_the_encoders_covariance_through_finite_difference_jacobians(rng) -> None:
    """``J diag(σ²) Jᵀ + σ_k² I`` with ``J`` by central differences of the feet's positions,
    and a Monte Carlo covariance of the positions at encoder noise σ (linear at this σ)."""
    legs = Go1Legs("imu_link")
    q = legs.stance + 0.1 * np.sin(np.arange(12))
    _, jac = legs.positions_and_jacobians(q)
    gains = InEKFGains(kinematics=2e-5)
    eps = 1e-6
    fd = np.zeros((4, 3, 12))
    for i in range(12):
        dq = np.zeros(12)
        dq[i] = eps
        fd[:, :, i] = (legs.positions_and_jacobians(q + dq)[0] - legs.positions_and_jacobians(q - dq)[0]) / (2 * eps)  # fmt: skip
    expected = fd * SIGMA**2 @ np.swapaxes(fd, 1, 2) + gains.kinematics**2 * np.eye(3)
    got = foot_noise(gains, jac * SIGMA, 1.0)  # the filter's: J's columns scaled by σ
    np.testing.assert_allclose(got, expected, rtol=1e-7, atol=1e-18)
    samples = np.array(
        [legs.positions_and_jacobians(q + rng.normal(0.0, SIGMA))[0] for _ in range(4000)]
    )
    for f in range(4):  # 4000 samples: the variances to ~2.2 % (σ), 10 % is 4.5 σ
        mc = np.cov(samples[:, f].T) + gains.kinematics**2 * np.eye(3)
        np.testing.assert_allclose(np.diag(mc), np.diag(got[f]), rtol=0.1)


def _run(ekf, samples, *, speeds=True):
    """The go1 truth from the IMU frame (as test_inekf's invariance test), joint velocities
    by central differences of the joint angles; returns the estimates and the worst error."""
    legs = Go1Legs("imu_link")
    R_bi, r_bi = legs.imu_placement
    t0, R_i, v_i, p_i, q0, omega0, acc0, contacts0 = samples[0]
    R_b = R_i @ R_bi.T
    omega_b = R_bi @ omega0
    v0 = np.concatenate([R_b.T @ v_i - np.cross(omega_b, r_bi), omega_b, np.zeros(12)])
    ekf.reset(t0, free_flyer_q(R_b, p_i - R_b @ r_bi, q0), v0, gyro=omega0, acc=acc0,
              contacts=contacts0)  # fmt: skip
    worst, out = 0.0, []
    for k in range(1, len(samples) - 1):
        t, R_i, v_i, p_i, q, omega, acc, contacts = samples[k]
        dq = (samples[k + 1][4] - samples[k - 1][4]) / (samples[k + 1][0] - samples[k - 1][0])
        est = ekf.update(t, q, omega, acc, contacts, joint_velocities=dq if speeds else None)
        R_b = R_i @ R_bi.T
        v_b = v_i - np.cross(R_i @ omega, R_b @ r_bi)
        worst = max(worst, *pose_errors(est, R_b, v_b, p_i - R_b @ r_bi))
        out.append(est)
    return out, worst


@pytest.fixture(scope="module")
def go1_truth():
    legs = Go1Legs("imu_link")
    return truth(legs, 200.0, 1.5, wobble=0.5, feet_z=None, inverse=legs.inverse)


def test_started_on_the_truth_it_stays_there_with_joint_std_and_slip_speed(go1_truth) -> None:
    exact = InEKFGains(lever_tau=0.0)  # the raw gyro in the lever arm (imu_link.py's M3)
    for slip_gyro in (0.0, 1e-2):  # eq. (10) changes Q, not the mean
        ekf = InvariantEKF(pinobs.load("go1"), GO1_FEET, imu_frame="imu_link", joint_std=SIGMA,
                           slip_speed=True, slip_gyro=slip_gyro, gains=exact)  # fmt: skip
        _, worst = _run(ekf, go1_truth)
        assert worst < 1e-9


def test_joint_std_equal_to_gains_joint_gives_the_same_filter(go1_truth) -> None:
    """σ_q per joint all equal to ``gains.joint``: the estimates and covariances of the scalar
    ``gains.joint`` (to rounding: ``J σ`` squared instead of ``σ² J Jᵀ``)."""
    go1, gains = pinobs.load("go1"), InEKFGains(joint=3e-4)
    a = InvariantEKF(go1, GO1_FEET, imu_frame="imu_link", gains=gains)
    b = InvariantEKF(go1, GO1_FEET, imu_frame="imu_link", gains=gains, joint_std=np.full(12, 3e-4))
    ea, _ = _run(a, go1_truth)
    eb, _ = _run(b, go1_truth)
    for x, y in zip(ea, eb, strict=True):
        np.testing.assert_allclose(y.covariance, x.covariance, rtol=1e-9, atol=1e-15)  # P ~ 5e-3
        assert y.nis == pytest.approx(x.nis, rel=1e-9, abs=1e-15)


def test_slip_speed_off_or_still_feet_leave_the_filter_bit_identical(go1_truth) -> None:
    """``slip_speed=False`` ignores the joint velocities (bit-identical); with it on, feet
    that stand still (the truth's, seen through differenced joint angles: |ṗ_j| ≤ 4e-4 m/s
    measured, their error) add ``|ṗ_j|² h`` ≤ 1e-9 to foot densities of 1e-2 (squared): the
    covariance moves by less than 1e-6 of its largest entry (1e-2)."""
    go1 = pinobs.load("go1")
    plain, _ = _run(InvariantEKF(go1, GO1_FEET, imu_frame="imu_link"), go1_truth, speeds=False)
    off, _ = _run(InvariantEKF(go1, GO1_FEET, imu_frame="imu_link"), go1_truth)
    on, _ = _run(InvariantEKF(go1, GO1_FEET, imu_frame="imu_link", slip_speed=True), go1_truth)
    for p, o, s in zip(plain, off, on, strict=True):
        assert np.array_equal(p.covariance, o.covariance) and np.array_equal(p.q, o.q)
        np.testing.assert_allclose(s.covariance, p.covariance, rtol=0.0, atol=1e-8)


def test_slip_densities_add_the_feet_displacement_over_the_step() -> None:
    gains = InEKFGains(contact=1e-3)
    qc = noise_densities(gains, 2)
    out = slip_densities(qc, np.array([0.5, 0.0]), 0.0025)
    np.testing.assert_array_equal(out[9:12], 1e-6 + 0.25 * 0.0025)  # σ_c² + |ṗ|² h
    np.testing.assert_array_equal(out[12:15], 1e-6)
    np.testing.assert_array_equal(np.delete(out, range(9, 15)), np.delete(qc, range(9, 15)))
    assert not out.flags.writeable


def test_a_foot_that_moves_raises_its_contact_noise() -> None:
    """A foot the filter sees moving (joint velocities swinging FL's thigh at 2 rad/s: 0.59
    m/s) gets ``|ṗ_j|² h`` (eq. 9) more density on its block: after the next update its
    covariance is larger than with the same joints still, more than the other feet's (which
    move with it through the base's position)."""
    go1 = pinobs.load("go1")
    legs = Go1Legs("imu_link")
    q = legs.stance.copy()
    out = []
    for dq in (np.zeros(12), np.r_[0.0, 2.0, 0.0, np.zeros(9)]):  # FL's thigh at 2 rad/s
        ekf = InvariantEKF(go1, GO1_FEET, imu_frame="imu_link", slip_speed=True)
        q0 = np.r_[0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0, q]
        acc = np.array([0.0, 0.0, 9.81])
        ekf.reset(0.0, q0, gyro=np.zeros(3), acc=acc, contacts=[True] * 4)
        ekf.update(0.0025, q, np.zeros(3), acc, [True] * 4, joint_velocities=dq)
        speed = np.linalg.norm(ekf.foot_velocities(q, dq, np.zeros(3)), axis=1)
        ekf.update(0.005, q, np.zeros(3), acc, [True] * 4, joint_velocities=dq)
        out.append((speed, ekf.state.P))
    (s0, P0), (s1, P1) = out
    assert s0.max() < 1e-12 and s1[0] > 0.3 and np.all(s1[1:] < 1e-12)
    grow = [np.trace(P1[b : b + 3, b : b + 3] - P0[b : b + 3, b : b + 3]) for b in (9, 12, 15, 18)]
    assert grow[0] > 1e-8  # measured 8.0e-8 (the update takes most of the 6.6e-6 added)
    assert max(abs(g) for g in grow[1:]) < 0.5 * grow[0]  # measured 3.4e-8


@pytest.mark.parametrize(
    ("joint_std", "error", "match"),
    [
        (np.r_[SIGMA[:3], -1e-4, SIGMA[4:]], GainError, r"joint_std\[3\] = -0.0001"),
        (np.r_[SIGMA[:5], np.nan, SIGMA[6:]], NonFiniteError, r"joint_std has non-finite .*\[5\]"),
        (np.r_[SIGMA[:5], np.inf, SIGMA[6:]], NonFiniteError, r"joint_std has non-finite"),
        (SIGMA[:11], DimensionError, r"joint_std must have shape \(12,\)"),
    ],
)
def test_a_bad_encoder_sigma_is_named(joint_std, error, match) -> None:
    with pytest.raises(error, match=match):
        InvariantEKF(pinobs.load("go1"), GO1_FEET, joint_std=joint_std)


def test_encoder_sigma_zero_with_no_kinematic_floor_is_refused() -> None:
    with pytest.raises(GainError, match="joint_std is all 0"):
        InvariantEKF(pinobs.load("go1"), GO1_FEET, joint_std=np.zeros(12),
                     gains=InEKFGains(kinematics=0.0))  # fmt: skip


def test_the_gyros_noise_is_not_taken_for_slip(rng) -> None:
    """Eq. (10) (``slip_gyro``): go1 standing still 1 s at 400 Hz, the gyro reading white at
    the filter's own density (σ_g √400 = 0.2 rad/s per sample: |ω̃ × h_j| ≈ 0.08 m/s at the feet), joint
    velocities 0.  The feet's covariance relative to the base (``P_dd − P_dp − P_pd + P_pp``,
    what the next innovation sees) with ``slip_speed`` over the one without: measured 1.34
    with (10); 1.87 with eq. (9) on the raw speed (the noise taken for slip, ``slip_gyro=0``).
    A negative ``slip_gyro`` is refused."""
    go1 = pinobs.load("go1")
    legs = Go1Legs("imu_link")
    q = legs.stance.copy()
    gains = InEKFGains(contact=1e-3)
    acc = np.array([0.0, 0.0, 9.81])
    noise = gains.gyro * np.sqrt(400.0) * rng.standard_normal((401, 3))
    relative = []
    for slip in (False, True):
        ekf = InvariantEKF(go1, GO1_FEET, imu_frame="imu_link", gains=gains, slip_speed=slip,
                           slip_gyro=gains.gyro)  # fmt: skip
        q0 = np.r_[0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0, q]
        ekf.reset(0.0, q0, gyro=noise[0], acc=acc, contacts=[True] * 4)
        for k in range(1, 401):
            ekf.update(k / 400.0, q, noise[k], acc, [True] * 4, joint_velocities=np.zeros(12))
        P = ekf.state.P
        relative.append(
            sum(
                np.trace(P[b : b + 3, b : b + 3] - 2 * P[b : b + 3, 6:9] + P[6:9, 6:9])
                for b in (9, 12, 15, 18)
            )
        )
    assert relative[1] < 1.6 * relative[0], relative
    with pytest.raises(GainError, match=r"slip_gyro=-0\.001"):
        InvariantEKF(go1, GO1_FEET, imu_frame="imu_link", slip_speed=True, slip_gyro=-1e-3)


def test_slip_speeds_take_the_held_gyros_noise_out_of_the_squared_speed() -> None:
    """Eq. (10) in closed form: ``|ṗ|² − 2|h|² σ_g²/T`` (here 0.25 − 2·0.1·1e-4·400 = 0.242),
    and 0 where the noise exceeds the speed."""
    h = np.array([[0.3, 0.0, -0.1], [0.2, 0.1, -0.3]])  # |h|² = 0.1, 0.14
    vel = np.array([[0.3, 0.4, 0.0], [0.01, 0.0, 0.0]])  # |ṗ|² = 0.25, 1e-4
    got = slip_speeds(vel, h, 1e-2, 1 / 400)
    np.testing.assert_allclose(got, [np.sqrt(0.25 - 2 * 0.1 * 1e-4 * 400), 0.0], rtol=1e-12)
