"""Rolling spherical feet (:mod:`pinobs.observers.rolling`): closed forms, Jacobians, invariance."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import pinobs
from pinobs.errors import ConfigurationError, GainError
from pinobs.model import FootKinematics
from pinobs.observers.inekf import InEKFGains, InvariantEKF
from pinobs.observers.qekf import QuaternionEKF
from pinobs.observers.rolling import RollingFeet
from tests.observers.test_inekf import (
    GO1_FEET,
    Go1Legs,
    free_flyer_q,
    pose_errors,
    reset_through_imu,
    truth,
)

RADIUS = 0.02  # go1's foot spheres [m]


class RollingSphere:
    """One foot: a sphere of radius ``r`` rolling along +x on the plane z = −0.3 − r, its joint
    the rolling angle φ: centre ``(r φ, 0, −0.3)``, orientation ``Rot_y(φ)`` (rolling without
    slipping, eq. R1: ``ċ = φ̇ ŷ × r ẑ``)."""

    feet = ("foot",)
    nq_joints = nv_joints = 1

    def __init__(self, r: float) -> None:
        self.r = r

    def placements_and_jacobians(self, q):
        phi = float(q[0])
        h = np.array([[self.r * phi, 0.0, -0.3]])
        rot = Rotation.from_rotvec([0.0, phi, 0.0]).as_matrix()[None]
        lin = np.array([[[self.r], [0.0], [0.0]]])
        ang = np.array([[[0.0], [1.0], [0.0]]])
        return h, rot, lin, ang


@pytest.mark.parametrize("phi", [0.0, 0.05, 0.1, 0.5, -0.3])
def test_the_touchdown_point_of_a_rolling_sphere_moves_along_a_cycloid(phi: float) -> None:
    """(R3): ``a(φ) − a(0) = r (φ − sin φ) x̂ + r (1 − cos φ) ẑ`` and its Jacobian the
    derivative of that, while the centre moves ``r φ``."""
    r = RADIUS
    feet = RollingFeet(RollingSphere(r), r)
    a0, _ = feet.legs(np.zeros(1), np.eye(3), [True])  # lands at φ = 0
    np.testing.assert_allclose(a0[0], [0.0, 0.0, -0.3 - r], atol=1e-15)  # the lowest point
    a, jac = feet.legs(np.array([phi]))
    expected = [r * (phi - math.sin(phi)), 0.0, r * (1.0 - math.cos(phi))]
    np.testing.assert_allclose(a[0] - a0[0], expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(
        jac[0][:, 0], [r * (1 - math.cos(phi)), 0.0, r * math.sin(phi)], rtol=0, atol=1e-15
    )
    if phi:  # third order along the walking axis, where the centre moved r φ
        assert abs(a[0, 0] - a0[0, 0]) < 0.2 * phi**2 * r * abs(phi)


def test_feet_that_lift_off_are_measured_at_their_centre_and_reanchored_when_they_land() -> None:
    r = RADIUS
    feet = RollingFeet(RollingSphere(r), r)
    feet.legs(np.zeros(1), np.eye(3), [True])
    h_up, _ = feet.legs(np.array([0.2]), np.eye(3), [False])
    np.testing.assert_allclose(h_up[0], [r * 0.2, 0.0, -0.3], atol=1e-15)
    tilted = Rotation.from_rotvec([0.3, 0.0, 0.0]).as_matrix()  # the base rolled by 0.3 rad
    h_down, _ = feet.legs(np.array([0.2]), tilted, [True])
    # the point −r n of the world, expressed in the base frame: r (0, −sin 0.3, −cos 0.3)
    np.testing.assert_allclose(
        h_down[0] - h_up[0], r * np.array([0.0, -math.sin(0.3), -math.cos(0.3)]), atol=1e-15
    )
    feet.restart()
    h, _ = feet.legs(np.array([0.2]))
    np.testing.assert_allclose(h, h_up, atol=0)


def test_the_measured_points_jacobian_matches_finite_differences_on_go1(rng) -> None:
    legs = FootKinematics(pinobs.load("go1"), GO1_FEET, imu_frame="imu_link")
    feet = RollingFeet(legs, RADIUS)
    q0 = np.tile([0.0, 0.8, -1.6], 4)
    feet.legs(q0, Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix(), [True] * 4)
    q = q0 + 0.2 * rng.normal(size=12)
    h, jac = feet.legs(q)
    eps = 1e-6
    for i in range(12):
        dq = np.zeros(12)
        dq[i] = eps
        fd = (feet.legs(q + dq)[0] - feet.legs(q - dq)[0]) / (2 * eps)
        np.testing.assert_allclose(jac[:, :, i], fd, rtol=0, atol=1e-8)
    centre, centre_jac = legs.positions_and_jacobians(q)
    assert np.allclose(np.linalg.norm(h - centre, axis=1), RADIUS)
    assert not np.allclose(jac, centre_jac)


def test_placements_and_jacobians_agree_with_positions_and_jacobians(rng) -> None:
    for imu_frame in (None, "imu_link"):
        legs = FootKinematics(pinobs.load("go1"), GO1_FEET, imu_frame=imu_frame)
        q = np.tile([0.0, 0.8, -1.6], 4) + 0.3 * rng.normal(size=12)
        h, rot, lin, ang = legs.placements_and_jacobians(q)
        h_ref, lin_ref = legs.positions_and_jacobians(q)
        np.testing.assert_allclose(h, h_ref, atol=1e-15)
        np.testing.assert_allclose(lin, lin_ref, atol=1e-15)
        # the angular Jacobian by finite differences of the orientation: (R⁺ Rᵀ)^∨ / ε
        eps = 1e-7
        for i in range(12):
            dq = np.zeros(12)
            dq[i] = eps
            rot_plus = legs.placements_and_jacobians(q + dq)[1]
            w = np.array(
                [
                    Rotation.from_matrix(a @ b.T).as_rotvec()
                    for a, b in zip(rot_plus, rot, strict=True)
                ]
            )
            np.testing.assert_allclose(ang[:, :, i], w / eps, rtol=0, atol=1e-6)


class RollingGo1Legs(Go1Legs):
    """go1 whose feet are measured at their touch-down points (R2), anchored at the stance
    with the base level: the truth helper's inverse kinematics keeps those points still."""

    def __init__(self) -> None:
        super().__init__("imu_link")
        self.rolling = RollingFeet(
            FootKinematics(pinobs.load("go1"), GO1_FEET, imu_frame="imu_link"), RADIUS
        )
        self.rolling.legs(self.stance, np.eye(3), [True] * 4)

    def positions_and_jacobians(self, q):
        return self.rolling.legs(q)


def _worst_pose_error(cls, samples, legs, imu_frame="imu_link", **options) -> float:
    """The largest pose error of ``cls`` (go1, ``imu_frame``, ``options``) started on the
    truth through the IMU and run over the noise-free ``samples``; the root's velocity with
    the raw gyro in the lever arm (``lever_tau`` 0, imu_link.py's M3: exact; the default M4
    lags by its τ, bounded in test_inekf.py's go1 test)."""
    options.setdefault("gains", InEKFGains(lever_tau=0.0))
    R_bi, r_bi = legs.imu_placement
    ekf = cls(pinobs.load("go1"), GO1_FEET, imu_frame=imu_frame, **options)
    reset_through_imu(ekf, samples[0], R_bi, r_bi)
    worst = 0.0
    for t, R_i, v_i, p_i, q, omega, acc, contacts in samples[1:]:
        est = ekf.update(t, q, omega, acc, contacts)
        R_b = R_i @ R_bi.T
        v_b = v_i - np.cross(R_i @ omega, R_b @ r_bi)
        worst = max(worst, *pose_errors(est, R_b, v_b, p_i - R_b @ r_bi))
    return worst


@pytest.mark.parametrize("cls", [InvariantEKF, QuaternionEKF])
def test_started_on_the_truth_with_rolling_feet_it_stays_there(cls) -> None:
    """Noise-free go1 whose feet rotate about their still touch-down points (the centres move
    by up to millimetres): with ``foot_radius`` and (R4) alone (``rolling_lift=False``: these
    points, not their projections, are still; R5's truth is the test below) the filter stays
    on the truth; without a radius, not."""
    legs = RollingGo1Legs()
    samples = truth(legs, 200.0, 2.0, wobble=0.5, feet_z=None, inverse=legs.inverse)
    centres = np.array([legs.rolling.kinematics.positions(s[4]) for s in samples])
    worst = {
        radius: _worst_pose_error(cls, samples, legs, foot_radius=radius, rolling_lift=False)
        for radius in (RADIUS, 0.0)
    }
    world = np.array(
        [s[3] + c @ s[1].T for s, c in zip(samples, centres, strict=True)]
    )  # centres' world
    assert np.ptp(world, axis=0).max() > 1e-3  # the centres moved: the feet rolled
    assert worst[RADIUS] < 1e-9
    assert worst[0.0] > 1e-4


def test_bad_foot_radius_is_refused() -> None:
    go1 = pinobs.load("go1")
    with pytest.raises(GainError, match="foot_radius"):
        InvariantEKF(go1, GO1_FEET, foot_radius=-0.02)
    with pytest.raises(GainError, match="foot_radius"):
        QuaternionEKF(go1, GO1_FEET, foot_radius=math.nan)

    class NoOrientations:
        feet = ("foot",)
        nq_joints = nv_joints = 1

        def positions_and_jacobians(self, q):
            return np.zeros((1, 3)), np.zeros((1, 3, 1))

    with pytest.raises(ConfigurationError, match="placements_and_jacobians"):
        InvariantEKF(NoOrientations(), foot_radius=0.02)


def test_foot_radius_zero_is_bit_for_bit_the_filter_without_it() -> None:
    legs = Go1Legs("imu_link")
    samples = truth(legs, 200.0, 0.5, wobble=0.5, feet_z=None, inverse=legs.inverse)
    outs = []
    for kwargs in ({}, {"foot_radius": 0.0}):
        ekf = InvariantEKF(pinobs.load("go1"), GO1_FEET, imu_frame="imu_link", **kwargs)
        t, R, _, p, q, omega, acc, contacts = samples[0]
        ekf.reset(t, free_flyer_q(R, p, q), gyro=omega, acc=acc, contacts=contacts)
        outs.append([ekf.update(t, q, w, a, c).v.copy() for t, _, _, _, q, w, a, c in samples[1:]])
    np.testing.assert_array_equal(outs[0], outs[1])


def test_the_compiled_points_are_r4_in_numpy() -> None:
    """The compiled (R4) equals its NumPy form: ``h + R s`` and ``J − (R s)^ J_ω``."""
    from pinobs.observers.rolling import rolled_kernel

    rng = np.random.default_rng(0)
    h, s = rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    rot = Rotation.random(4, random_state=1).as_matrix()
    jac, jac_w = rng.normal(size=(4, 3, 12)), rng.normal(size=(4, 3, 12))
    normals, down = np.zeros((4, 3)), np.ones(4, dtype=bool)  # (R5) off: lift False
    rolled_kernel.load()
    h_out, jac_out = np.empty_like(h), np.empty_like(jac)
    rolled_kernel.compiled(h, rot, jac, jac_w, s, normals, down, False, RADIUS, h_out, jac_out)
    o = np.einsum("kab,kb->ka", rot, s)
    hat = np.zeros((4, 3, 3))
    hat[:, 0, 1], hat[:, 0, 2], hat[:, 1, 2] = -o[:, 2], o[:, 1], -o[:, 0]
    hat -= hat.transpose(0, 2, 1)
    np.testing.assert_allclose(h_out, h + o, rtol=0, atol=1e-15)
    np.testing.assert_allclose(jac_out, jac - hat @ jac_w, rtol=0, atol=1e-14)


@pytest.mark.parametrize("phi", [0.05, 0.1, 0.5, -0.3])
def test_with_lift_the_point_of_a_rolling_sphere_stays_on_the_plane(phi: float) -> None:
    """(R5): R3 without its rise, ``a(φ) − a(0) = r (φ − sin φ) x̂`` (third order), with the
    Jacobian of that; at touch-down (φ = 0) it is R4's point."""
    r = RADIUS
    feet = RollingFeet(RollingSphere(r), r, lift=True)
    a0, _ = feet.legs(np.zeros(1), np.eye(3), [True])
    np.testing.assert_allclose(a0[0], [0.0, 0.0, -0.3 - r], atol=1e-15)
    a, jac = feet.legs(np.array([phi]), np.eye(3), [True])
    np.testing.assert_allclose(a[0] - a0[0], [r * (phi - math.sin(phi)), 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(jac[0][:, 0], [r * (1 - math.cos(phi)), 0.0, 0.0], atol=1e-15)


def test_the_lifted_points_jacobian_matches_finite_differences_on_go1(rng) -> None:
    legs = FootKinematics(pinobs.load("go1"), GO1_FEET, imu_frame="imu_link")
    feet = RollingFeet(legs, RADIUS, lift=True)
    R = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix()
    q0 = np.tile([0.0, 0.8, -1.6], 4)
    feet.legs(q0, R, [True] * 4)
    q = q0 + 0.2 * rng.normal(size=12)
    h, jac = feet.legs(q, R, [True] * 4)
    eps = 1e-6
    for i in range(12):
        dq = np.zeros(12)
        dq[i] = eps
        fd = (feet.legs(q + dq, R, [True] * 4)[0] - feet.legs(q - dq, R, [True] * 4)[0]) / (2 * eps)
        np.testing.assert_allclose(jac[:, :, i], fd, rtol=0, atol=1e-8)
    # the measured points sit at the spheres' lowest level: r below the centres along n
    centre, _ = legs.positions_and_jacobians(q)
    np.testing.assert_allclose((h - centre) @ (R.T @ [0.0, 0.0, 1.0]), -RADIUS, atol=1e-15)


class LiftedGo1Legs(Go1Legs):
    """go1 whose feet roll on the plane: the measured points (R5, anchored at the stance with
    the base level) are kept still by the truth helper's inverse kinematics, which reads the
    base's orientation of each sample from ``rotations`` (the base's motion does not depend
    on the legs)."""

    def __init__(self, rotations) -> None:
        super().__init__("imu_link")
        self.rolling = RollingFeet(
            FootKinematics(pinobs.load("go1"), GO1_FEET, imu_frame="imu_link"), RADIUS, lift=True
        )
        self.rolling.legs(self.stance, np.eye(3), [True] * 4)
        self.rotations, self.k = rotations, 0

    def positions_and_jacobians(self, q):
        R = self.rotations[min(self.k, len(self.rotations) - 1)]
        self.rolling.normals[:] = R.T @ [0.0, 0.0, 1.0]  # the true normal in the IMU frame
        return self.rolling.legs(q, R, [True] * 4)

    def inverse(self, targets):
        q = super().inverse(targets)
        self.k += 1
        return q


@pytest.mark.parametrize("cls", [InvariantEKF, QuaternionEKF])
def test_started_on_the_truth_with_feet_rolling_on_the_plane_it_stays_there(cls) -> None:
    """Noise-free go1 whose feet roll on the plane (the R5 points still, the R4 points rising
    along their cycloids): with ``rolling_lift`` the filter stays on the truth; with R4 alone,
    not."""
    level = Go1Legs("imu_link")
    base = truth(level, 200.0, 2.0, wobble=0.5, feet_z=None, inverse=level.inverse)
    legs = LiftedGo1Legs([s[1] for s in base])
    samples = truth(legs, 200.0, 2.0, wobble=0.5, feet_z=None, inverse=legs.inverse)
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(base, samples, strict=True))
    worst = {
        lift: _worst_pose_error(cls, samples, legs, foot_radius=RADIUS, rolling_lift=lift)
        for lift in (True, False)
    }
    assert worst[True] < 1e-9
    assert worst[False] > 1e-4


@pytest.mark.parametrize("cls", [InvariantEKF, QuaternionEKF])
def test_rolling_lift_is_the_default_and_off_is_r4_alone(cls, monkeypatch) -> None:
    """With a radius the default is (R5) (``rolling_lift=True``, bit for bit);
    ``rolling_lift=False`` is (R4) alone (the lift never computed: no compiled call with
    ``lift`` and a foot down) and differs; without a radius ``rolling_lift`` changes nothing
    (the foot frames measured): estimates and covariances bit for bit."""
    from pinobs.observers import rolling

    legs = Go1Legs("imu_link")
    samples = truth(legs, 200.0, 0.5, wobble=0.5, feet_z=None, inverse=legs.inverse)
    settings = (
        {"foot_radius": RADIUS},
        {"foot_radius": RADIUS, "rolling_lift": True},
        {"foot_radius": RADIUS, "rolling_lift": False},
        {},
        {"rolling_lift": False},
        {"rolling_lift": True},
    )
    outs, lifted = [], []
    for name, down in (("step_kernel", 5), ("rolled_kernel", 6)):  # (args: lift at 7)
        kernel = getattr(rolling, name)
        kernel.load()

        def counted(*args, real=kernel.compiled, down=down):  # type: ignore[no-untyped-def]
            lifted[-1] += bool(args[7] and np.any(args[down]))  # (R5) computed for a foot
            return real(*args)

        monkeypatch.setattr(kernel, "compiled", counted)
    for kwargs in settings:
        lifted.append(0)
        ekf = cls(pinobs.load("go1"), GO1_FEET, imu_frame="imu_link", **kwargs)
        t, R, _, p, q, omega, acc, contacts = samples[0]
        ekf.reset(t, free_flyer_q(R, p, q), gyro=omega, acc=acc, contacts=contacts)
        est = [ekf.update(t, q, w, a, c) for t, _, _, _, q, w, a, c in samples[1:]]
        outs.append([np.concatenate([e.q, e.v[:6], e.covariance.ravel()]) for e in est])
    np.testing.assert_array_equal(outs[0], outs[1])
    assert not np.array_equal(outs[0], outs[2])
    np.testing.assert_array_equal(outs[3], outs[4])
    np.testing.assert_array_equal(outs[3], outs[5])
    assert not np.array_equal(outs[2], outs[3])
    assert lifted[0] > 0 and lifted[1] == lifted[0]
    assert lifted[2] == 0 and lifted[3:] == [0, 0, 0]


def test_the_compiled_lift_is_r5_in_numpy() -> None:
    """The compiled (R5) equals its NumPy form for the feet down (the others (R4)'s):
    ``h + P o − r n̂`` and ``J − P o^ J_ω``, ``o = R s``, ``P = I − n̂ n̂ᵀ``."""
    from pinobs.observers.rolling import rolled_kernel

    rng = np.random.default_rng(0)
    h, s = rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    normals = Rotation.random(4, random_state=2).apply([0.0, 0.0, 1.0])
    rot = Rotation.random(4, random_state=1).as_matrix()
    jac, jac_w = rng.normal(size=(4, 3, 12)), rng.normal(size=(4, 3, 12))
    down = np.array([True, False, True, True])
    rolled_kernel.load()
    h_out, jac_out = np.zeros_like(h), np.zeros_like(jac)
    rolled_kernel.compiled(h, rot, jac, jac_w, s, normals, down, True, RADIUS, h_out, jac_out)
    for k in range(4):
        o, n = rot[k] @ s[k], normals[k]
        P = np.eye(3) - np.outer(n, n) if down[k] else np.eye(3)
        r = RADIUS if down[k] else 0.0
        o_hat = np.array([[0.0, -o[2], o[1]], [o[2], 0.0, -o[0]], [-o[1], o[0], 0.0]])
        np.testing.assert_allclose(h_out[k], h[k] + P @ o - r * n, rtol=0, atol=1e-15)
        np.testing.assert_allclose(jac_out[k], jac[k] - P @ o_hat @ jac_w[k], rtol=0, atol=1e-14)


def test_shared_placements_are_the_copied_ones_and_copies_are_the_callers(rng) -> None:
    """``shared_placements_and_jacobians`` (the rolling feet's, not copied) gives the arrays
    ``placements_and_jacobians`` copies; writing to a copy changes no later answer."""
    legs = FootKinematics(pinobs.load("go1"), GO1_FEET, imu_frame="imu_link")
    q = np.tile([0.0, 0.8, -1.6], 4) + 0.3 * rng.normal(size=12)
    copied = legs.placements_and_jacobians(q)
    shared = legs.shared_placements_and_jacobians(q)
    for a, b in zip(copied, shared, strict=True):
        np.testing.assert_array_equal(a, b)
        assert not np.shares_memory(a, b)
        a[...] = np.nan
    for a, b in zip(legs.placements_and_jacobians(q), shared, strict=True):
        np.testing.assert_array_equal(a, b)
        assert np.isfinite(a).all()
