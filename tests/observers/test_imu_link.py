"""An IMU on a link that moves relative to the root joint (TALOS's ``imu_link``, on the torso):
the feet in its frame through the torso joints, and the root's pose and twist from its
(``pinobs.observers.imu_link``, ``pinobs.model.legs``' K1-K2)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.model import FootKinematics
from pinobs.observers.imu_link import LEVER_TAU, lever_shift, root_twist, smoothed
from pinobs.observers.inekf import InvariantEKF
from pinobs.observers.legs import InEKFGains
from pinobs.observers.qekf import QuaternionEKF
from pinobs.simulation.humanoid import TALOS_FEET, TALOS_STANCE
from tests.observers.test_inekf import GO1_FEET, Go1Legs, free_flyer_q, reset_through_imu, truth

#: torso_1 (yaw) and torso_2 (pitch): velocity indices among the joints
TORSO = (12, 13)


def torso(t: float) -> tuple[np.ndarray, np.ndarray]:
    """The torso joints' sway at ``t`` [s]: angles [rad] and their rates [rad/s]."""
    angles = np.array([0.15 * math.sin(2.0 * t), 0.1 * math.sin(3.0 * t)])
    rates = np.array([0.3 * math.cos(2.0 * t), 0.3 * math.cos(3.0 * t)])
    return angles, rates


class TalosLegs(FootKinematics):
    """TALOS's soles in its ``imu_link`` frame; the legs' inverse kinematics for the torso's
    sway at the sample's time (one call per sample at ``rate``, in order)."""

    stance = np.array(TALOS_STANCE)

    def __init__(self, rate: float) -> None:
        super().__init__(pinobs.load("talos"), TALOS_FEET, imu_frame="imu_link")
        self._last, self._k, self.rate = self.stance.copy(), 0, rate

    def inverse(self, targets: np.ndarray) -> np.ndarray:
        q = self._last.copy()
        q[list(TORSO)] = self.stance[list(TORSO)] + torso(self._k / self.rate)[0]
        self._k += 1
        for _ in range(30):
            h, jac = self.positions_and_jacobians(q)
            err = (targets - h).reshape(-1)
            if np.abs(err).max() < 1e-14:
                break
            q[:12] += np.linalg.lstsq(np.concatenate(jac)[:, :12], err, rcond=None)[0]
        self._last = q
        return q


def test_the_feet_in_a_moving_imu_frame_are_pinocchios_relative_placements(rng) -> None:
    """(K1) against ``oM_imu⁻¹ oM_foot`` of the full model (root anywhere), (K2) against
    central differences."""
    robot = pinobs.load("talos")
    legs = FootKinematics(robot, TALOS_FEET, imu_frame="imu_link")
    assert legs.imu_moves
    q = np.array(TALOS_STANCE) + 0.3 * rng.normal(size=robot.nq - 7)
    h, R, J, J_w = legs.placements_and_jacobians(q)
    model, data = robot.model, robot.model.createData()
    base = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3))
    pin.framesForwardKinematics(model, data, free_flyer_q(base.rotation, base.translation, q))
    oMi = data.oMf[model.getFrameId("imu_link")]
    for j, foot in enumerate(TALOS_FEET):
        rel = oMi.actInv(data.oMf[model.getFrameId(foot)])
        np.testing.assert_allclose(h[j], rel.translation, rtol=0, atol=1e-14)
        np.testing.assert_allclose(R[j], rel.rotation, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(legs.positions_and_jacobians(q)[0], h)
    eps = 1e-6
    for c in (0, 6, *TORSO):  # a joint of each leg, and the torso's
        dq = np.zeros(robot.nv - 6)
        dq[c] = eps
        (hp, Rp), (hm, Rm) = (legs.placements_and_jacobians(q + s * dq)[:2] for s in (1, -1))
        np.testing.assert_allclose((hp - hm) / (2 * eps), J[:, :, c], rtol=0, atol=1e-8)
        for j in range(2):
            turn = pin.log3(Rp[j] @ Rm[j].T) / (2 * eps)
            np.testing.assert_allclose(turn, J_w[j, :, c], rtol=0, atol=1e-8)
    assert np.linalg.norm(J[:, :, list(TORSO)], axis=1).min() > 0.1  # the torso moves the feet


@pytest.mark.parametrize("tau", [0.0, LEVER_TAU])
@pytest.mark.parametrize("family", [InvariantEKF, QuaternionEKF])
def test_started_on_the_truth_it_stays_there_with_the_imu_on_talos_torso(family, tau) -> None:
    """The truth is ``imu_link``'s motion (its exact flow under held readings), the torso
    swaying (±0.15, ±0.1 rad), the soles fixed in the world.  The estimate, of the root, is
    checked through Pinocchio's own kinematics: ``est.q`` puts ``imu_link`` at the truth's
    pose, and ``(est.q, est.v)`` give it the truth's velocity (both filters: they share the
    legs and the conversion, :class:`~pinobs.observers.legs.LeggedSetup`): exactly with the
    raw reading in the lever arm (``lever_tau`` 0, M3); with M4's low-pass, its velocity
    within the lag's bound ``|r_bi| τ max_k |ω_k − ω_{k−1}| / Δt`` (the recursion's
    ``|ω̄_k − ω_k| ≤ Σ_j (1 − α)^j |Δω| = (1 − α)/α |Δω|`` and ``(1 − α)/α ≤ τ/Δt``)."""
    rate = 200.0
    legs = TalosLegs(rate)
    samples = truth(legs, rate, 2.0, wobble=0.5, feet_z=None, inverse=legs.inverse)
    robot = pinobs.load("talos")
    model, data, imu = robot.model, robot.model.createData(), robot.model.getFrameId("imu_link")
    ekf = family(robot, TALOS_FEET, imu_frame="imu_link", gains=InEKFGains(lever_tau=tau))
    worst, moved, linear = 0.0, 0.0, 0.0
    for k, (t, R_i, v_i, p_i, q, omega, acc, contacts) in enumerate(samples):
        rates = np.zeros(robot.nv - 6)
        rates[list(TORSO)] = torso(t)[1]
        if k == 0:
            R_bi, r_bi, J_bi = legs.imu_motion(q)
            R_b = R_i @ R_bi.T
            w_b = R_bi @ omega - J_bi[3:] @ rates
            v_b = R_b.T @ v_i - np.cross(w_b, r_bi) - J_bi[:3] @ rates
            q0 = free_flyer_q(R_b, p_i - R_b @ r_bi, q)
            v0 = np.concatenate([v_b, w_b, rates])
            est = ekf.reset(t, q0, v0, gyro=omega, acc=acc, contacts=contacts)
        else:
            est = ekf.update(t, q, omega, acc, contacts, joint_velocities=rates)
        pin.forwardKinematics(model, data, est.q, est.v)
        oMi = pin.updateFramePlacement(model, data, imu)
        local = pin.getFrameVelocity(model, data, imu, pin.ReferenceFrame.LOCAL)
        world = pin.getFrameVelocity(model, data, imu, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        errors = (oMi.rotation - R_i, oMi.translation - p_i, local.angular - omega)
        worst = max(worst, *(float(np.abs(e).max()) for e in errors))
        linear = max(linear, float(np.linalg.norm(world.linear - v_i)))
        moved = max(moved, float(np.abs(q[list(TORSO)]).max()))
    assert worst < 1e-9
    if tau == 0.0:
        assert linear < 1e-9
    else:
        omegas = np.array([sample[5] for sample in samples])
        step = float(np.linalg.norm(np.diff(omegas, axis=0), axis=1).max())
        lever = float(np.linalg.norm(legs.imu_placement[1]))
        assert 1e-6 < linear <= lever * tau * step * rate + 1e-9
    assert moved > 0.09  # the torso did sway
    assert np.abs(est.v[:6]).max() > 0.01 and np.isfinite(est.v).all()


def test_without_joint_velocities_the_root_twist_is_unknown_with_a_moving_imu() -> None:
    legs = TalosLegs(200.0)
    samples = truth(legs, 200.0, 0.02, wobble=0.5, feet_z=None, inverse=legs.inverse)
    ekf = InvariantEKF(pinobs.load("talos"), TALOS_FEET, imu_frame="imu_link")
    t, R_i, _, p_i, q, omega, acc, contacts = samples[0]
    ekf.reset(t, free_flyer_q(R_i, p_i, q), gyro=omega, acc=acc, contacts=contacts)
    est = ekf.update(*samples[1][:1], samples[1][4], *samples[1][5:])
    assert np.isnan(est.v).all() and np.isfinite(est.q).all()


def test_the_low_passed_lever_arm_leaves_the_state_and_the_angular_velocity(rng) -> None:
    """(M4) changes the root's linear velocity alone: with a noisy gyro, the state ``(R, x,
    P, bias)`` and the output's ``q`` and ``ω_b`` are those of (M3) (``lever_tau`` 0) bit for
    bit; ``v_b`` differs."""
    legs = TalosLegs(200.0)
    samples = truth(legs, 200.0, 0.5, wobble=0.5, feet_z=None, inverse=legs.inverse)
    robot = pinobs.load("talos")
    filters = [
        InvariantEKF(robot, TALOS_FEET, imu_frame="imu_link", gains=InEKFGains(lever_tau=tau))
        for tau in (0.0, LEVER_TAU)
    ]
    moved = 0.0
    for k, (t, R_i, _, p_i, q, omega, acc, contacts) in enumerate(samples):
        gyro = omega + 0.03 * rng.normal(size=3)
        rates = np.zeros(robot.nv - 6)
        rates[list(TORSO)] = torso(t)[1]
        if k == 0:
            q0 = free_flyer_q(R_i, p_i, q)
            raw, low = (f.reset(t, q0, gyro=gyro, acc=acc, contacts=contacts) for f in filters)
        else:
            raw, low = (
                f.update(t, q, gyro, acc, contacts, joint_velocities=rates) for f in filters
            )
        a, b = (f.state for f in filters)
        for x, y in ((a.R, b.R), (a.x, b.x), (a.P, b.P), (a.bias, b.bias), (raw.q, low.q)):
            np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(raw.v[3:], low.v[3:])
        moved = max(moved, float(np.abs(raw.v[:3] - low.v[:3]).max()))
    assert a.lever is None and b.lever is not None
    assert moved > 1e-3


@pytest.mark.parametrize("family", [InvariantEKF, QuaternionEKF])
def test_go1s_fixed_imu_frame_takes_the_low_passed_lever_arm_alone(family, rng) -> None:
    """(M4) on a frame fixed to the root (go1's ``imu_link``, 7 cm off it, ``J_i = J_iω = 0``):
    with a noisy gyro, the state ``(R, x, P, bias)``, ``q`` and ``ω_b`` are (M3)'s
    (``lever_tau`` 0) bit for bit, and ``v_b`` moves by ``(R_bi (ω̃ − ω̄)) × r_bi``, ``ω̄``
    the state's low-passed reading (:func:`smoothed` of the readings given)."""
    legs = Go1Legs("imu_link")
    R_bi, r_bi = legs.imu_placement
    samples = truth(legs, 200.0, 0.5, wobble=0.5, feet_z=None, inverse=legs.inverse)
    robot = pinobs.load("go1")
    filters = [
        family(robot, GO1_FEET, imu_frame="imu_link", gains=InEKFGains(lever_tau=tau))
        for tau in (0.0, LEVER_TAU)
    ]
    gyros = samples[0][5] + 0.03 * rng.normal(size=(len(samples), 3))
    for f in filters:
        reset_through_imu(f, (*samples[0][:5], gyros[0], *samples[0][6:]), R_bi, r_bi)
    lever, moved = gyros[0], 0.0
    for k, (t, _, _, _, q, _, acc, contacts) in enumerate(samples[1:], start=1):
        raw, low = (f.update(t, q, gyros[k], acc, contacts) for f in filters)
        lever = smoothed(lever, gyros[k], t - samples[k - 1][0])
        a, b = (f.state for f in filters)
        for x, y in ((a.R, b.R), (a.x, b.x), (a.P, b.P), (a.bias, b.bias), (raw.q, low.q)):
            np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(raw.v[3:], low.v[3:])
        np.testing.assert_allclose(b.lever, lever, rtol=0, atol=1e-15)
        shift = np.cross(R_bi @ (gyros[k] - lever), r_bi)
        np.testing.assert_allclose(low.v[:3] - raw.v[:3], shift, rtol=0, atol=1e-12)
        moved = max(moved, float(np.abs(shift).max()))
    assert a.lever is None and moved > 1e-3


def test_the_low_passed_lever_arm_cuts_the_gyros_white_noise_by_the_expected_factor(rng) -> None:
    """A rigid rotation at constant ``ω`` (the IMU 0.16 m above the root, tilted, a root
    moving at ``v_b``), the gyro read with white noise (σ 0.045 rad/s per sample at 500 Hz:
    2·10⁻³ rad/s/√Hz): (M3)'s root velocity error is ``−(R_bi n_k) × r_bi``, (M4)'s
    ``−(R_bi (ω̄_k − ω)) × r_bi``, whose variance is the first-order recursion's
    ``α/(2 − α)`` times the reading's (``α = 1 − e^{−Δt/τ}``; ``ω`` constant: no lag)."""
    dt, sigma, n = 1 / 500, 2e-3 * math.sqrt(500), 20000
    R_bi, r_bi = pin.exp3(np.array([0.1, -0.2, 0.3])), np.array([0.02, 0.0, 0.16])
    R_b, omega, v_b = pin.exp3(np.array([0.3, 0.1, -0.5])), np.array([0.1, -0.2, 0.05]), np.ones(3)
    w_b = R_bi @ omega
    v = R_b @ (v_b + np.cross(w_b, r_bi))  # the IMU's world velocity (M2, J_i = 0)
    errors: dict[str, list[np.ndarray]] = {"M3": [], "M4": []}
    lever = None
    for k in range(n):
        reading = np.concatenate([omega + sigma * rng.normal(size=3), np.zeros(3)])
        lever = smoothed(lever, reading, dt)
        for name, shift in (("M3", None), ("M4", lever_shift(R_bi, reading, lever))):
            measured = R_bi @ reading[:3]  # the compiled conversion's rows (fixed frame)
            base = np.array([np.zeros(3), measured, R_b.T @ v - np.cross(measured, r_bi), v])
            root_twist(base, R_b, np.zeros(2), r_bi, np.zeros((6, 2)), shift)
            np.testing.assert_array_equal(base[1], measured)  # the output ω_b: the reading's
            if k >= 100:  # (after 5 τ)
                errors[name].append(base[2] - v_b)
    alpha = 1 - math.exp(-dt / LEVER_TAU)
    expected = math.sqrt(alpha / (2 - alpha))  # 0.224
    m3, m4 = (float(np.sqrt(np.mean(np.square(errors[k])))) for k in ("M3", "M4"))
    assert m3 == pytest.approx(sigma * math.sqrt(2 / 3) * np.linalg.norm(r_bi), rel=0.05)
    assert m4 / m3 == pytest.approx(expected, rel=0.08)


@pytest.mark.parametrize("frame", [None, "imu_link"])
def test_go1s_fixed_imu_frame_does_not_move(frame: str | None) -> None:
    legs = FootKinematics(pinobs.load("go1"), ("FL_foot",), imu_frame=frame)
    R_bi, r_bi, J_bi = legs.imu_motion(np.zeros(12))
    assert not legs.imu_moves and not J_bi.any()
    np.testing.assert_array_equal(R_bi, legs.imu_placement[0])
    np.testing.assert_array_equal(r_bi, legs.imu_placement[1])


@pytest.mark.slow
def test_talos_imu_link_by_default_tracks_mujocos_root_velocity() -> None:
    """MuJoCo's TALOS swaying with its torso swaying too (±0.1 rad), its IMU on ``imu_link``,
    through ``legged_run`` with its defaults (no ``imu_frame``: ``imu_link``), against the same
    motion with the IMU at the root (``imu_frame="base_link"``).  Measured here (3 s, seed 0):
    root velocity RMS 0.0082 m/s on ``imu_link``, 0.0073 at the root (1.12×; 0.0101 with
    M3's raw gyro in the lever arm ``r_bi``, before M4); over 10 s, seeds 0-2, stand and sway:
    0.0077-0.0079 against 0.0067-0.0078 (``benchmarks/talos_imu_link.py``)."""
    pytest.importorskip("mujoco")
    pd = pytest.importorskip("pandas")
    from pinobs.io import read_log
    from pinobs.io.legged_run import legged_run
    from pinobs.simulation.humanoid import simulate_humanoid

    robot = pinobs.load("talos")
    rms = {}
    for body, frame in (("base_link", "base_link"), ("imu_link", None)):
        run = simulate_humanoid("sway", 3.0, imu_body=body, torso=0.1, robot=robot)
        measured = {
            k: c for k, c in run.columns.items() if not k.startswith(("truth.", "contact."))
        }
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (the note that the log has no base pose)
            log = read_log(pd.DataFrame(measured), robot)
        v = legged_run(robot, log, imu_frame=frame).run.v
        e = v[250:, :3] - run.base_v()[250:, :3]  # after 0.5 s
        assert np.isfinite(e).all()
        rms[body] = float(np.sqrt(np.mean(e**2)))
    assert rms["imu_link"] < 0.012
    assert rms["imu_link"] < 1.6 * rms["base_link"]


def test_the_smoothed_gyro_has_the_bits_of_the_array_expression() -> None:
    """(M4)'s ``ω̄_k = ω̄_{k−1} + (1 − e^{−dt/τ}) (ω̃_k − ω̄_{k−1})``, written axis by axis in
    Python floats: the bits of the same operations on arrays."""
    rng = np.random.default_rng(4)
    for _ in range(2000):
        lever, reading = rng.normal(size=3), rng.normal(size=6)
        dt, tau = rng.uniform(1e-4, 0.01), rng.uniform(1e-3, 0.2)
        want = lever + (1.0 - math.exp(-dt / tau)) * (reading[:3] - lever)  # (as it was)
        np.testing.assert_array_equal(smoothed(lever, reading, dt, tau), want)
