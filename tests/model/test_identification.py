"""Momentum-form identification against known truths (MATH §9)."""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.errors import IdentificationError
from pinobs.model.identification import (
    MomentumRegressor,
    identify,
    pseudo_inertia,
    smooth_path,
    solve,
)
from pinobs.model.identification.leastsquares import _consistent, _is_consistent
from pinobs.model.identification.savgol import convolve_nearest, savgol_coefficients
from pinobs.model.urdf_writer import write_urdf
from pinobs.simulation import Sensor
from tests.conftest import dropped_rows, planar_3r_truth, resampled_log, torque_error

ROBOTS = ["cartpole", "planar_3r", "ur5"]


@pytest.mark.parametrize("name", ROBOTS)
def test_momentum_regressor_is_mass_matrix_times_velocity(
    name: str, rng: np.random.Generator
) -> None:
    robot = pinobs.load(name)
    reg = MomentumRegressor(robot)
    pi = reg.nominal()[: reg.n_inertial]
    for _ in range(5):
        q = robot.random_configuration(rng)
        v = rng.normal(size=robot.nv)
        np.testing.assert_allclose(reg.momentum(q, v) @ pi, robot.mass_matrix(q) @ v, atol=1e-12)


@pytest.mark.parametrize("name", ROBOTS)
def test_drift_regressor_is_coriolis_transpose_minus_gravity(
    name: str, rng: np.random.Generator
) -> None:
    robot = pinobs.load(name)
    reg = MomentumRegressor(robot)
    pi = reg.nominal()[: reg.n_inertial]
    for _ in range(5):
        q = robot.random_configuration(rng)
        v = rng.normal(size=robot.nv)
        expected = robot.coriolis_matrix(q, v).T @ v - robot.gravity(q)
        scale = 1.0 + np.abs(expected).max()
        np.testing.assert_allclose(reg.drift(q, v) @ pi, expected, atol=1e-7 * scale)


@pytest.mark.parametrize("name", ["cartpole", "planar_3r"])
def test_rows_vanish_on_the_true_parameters_along_a_noise_free_path(name: str) -> None:
    robot = pinobs.load(name)
    res = pinobs.simulate(robot, [], duration=2.0, sensor=Sensor(rate=1000.0), seed=3)
    reg = MomentumRegressor(robot, friction=False, offset=False)
    A, y = reg.system(res.t, res.q, res.v, res.tau, window=100, stride=1)
    assert A.shape == (robot.nv * 20, reg.size)
    rel = np.abs(A @ reg.nominal() - y).max() / np.abs(y).max()
    assert rel < 1e-4  # trapezoid quadrature of a smooth integrand at 1 ms


def test_with_parameters_of_the_nominal_values_is_the_same_robot(rng: np.random.Generator) -> None:
    robot = pinobs.load("ur5")
    reg = MomentumRegressor(robot)
    same = reg.with_parameters(reg.nominal())
    q = robot.random_configuration(rng)
    np.testing.assert_allclose(same.mass_matrix(q), robot.mass_matrix(q), atol=1e-12)
    with pytest.raises(pinobs.DimensionError, match="shape"):
        reg.with_parameters(np.zeros(3))


def test_smooth_path_recovers_the_velocity_of_a_noisy_sine() -> None:
    robot = pinobs.load("cartpole")
    t = np.arange(2001) * 1e-3
    q = np.column_stack([0.3 * np.sin(2 * t), 0.5 * np.cos(3 * t)])
    v = np.column_stack([0.6 * np.cos(2 * t), -1.5 * np.sin(3 * t)])
    noisy = q + np.random.default_rng(0).normal(0, 1e-4, q.shape)
    _, v_hat = smooth_path(robot, t, noisy, half_window=50)
    assert np.sqrt(np.mean((v_hat[100:-100] - v[100:-100]) ** 2)) < 2e-3


@pytest.mark.parametrize(
    ("length", "order", "h"), [(101, 4, 1e-3), (11, 4, 1e-2), (7, 2, 1.0), (9, 8, 4e-3)]
)
def test_savgol_coefficients_and_their_convolution_are_scipy_s_to_the_bit(
    length: int, order: int, h: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 39: the learner's smoothing no longer imports ``scipy.signal`` nor
    ``scipy.ndimage`` (0.5 s CPU); its coefficients and convolutions (NumPy's, without
    ``scipy.ndimage`` imported), and hence every learned model, are the same bits as
    theirs, on (anti)symmetric and general weights."""
    import sys

    from scipy.ndimage import convolve1d
    from scipy.signal import savgol_coeffs

    monkeypatch.delitem(sys.modules, "scipy.ndimage")  # convolve_nearest's NumPy path

    c_v, c_u = savgol_coefficients(length, order, h)
    assert np.array_equal(c_v, savgol_coeffs(length, order, deriv=1, delta=h))
    assert np.array_equal(c_u, savgol_coeffs(length, order))
    rng = np.random.default_rng(length)
    general = rng.normal(size=length)
    for rows in (length // 2 + 1, length, 3 * length):
        u = rng.normal(size=(rows, 6)).cumsum(axis=0)
        for c in (c_v, c_u, general):
            assert np.array_equal(convolve_nearest(u, c), convolve1d(u, c, axis=0, mode="nearest"))
    with pytest.raises(ValueError, match="odd number of weights, not 4"):
        convolve_nearest(u, np.ones(4))


def test_consistency_step_returns_positive_semidefinite_pseudo_inertias() -> None:
    robot = pinobs.load("planar_3r")
    reg = MomentumRegressor(robot, friction=True, offset=False, armature=True)
    theta = reg.nominal()
    theta[4] = -0.5 * abs(theta[0]) - 1.0  # Ixx of the first body: breaks the triangle inequality
    theta[reg.n_inertial] = -1.0  # negative damping
    theta[reg.armature_slice.start] = -0.1  # negative armature
    assert not _is_consistent(reg, theta)
    s = reg.prior_std()
    fixed = _consistent(reg, theta, np.eye(reg.size), s)
    for k in range(reg.n_inertial // 10):
        assert np.linalg.eigvalsh(pseudo_inertia(fixed[10 * k : 10 * k + 10]))[0] >= -1e-9
    assert np.all(fixed[reg.n_inertial :] >= 0)


def _log(robot: pinobs.Robot, plant: pinobs.Robot, duration: float, noise: float, seed: int):
    res = pinobs.simulate(
        robot,
        [],
        duration=duration,
        sensor=Sensor(rate=1000.0, noise_std=noise),
        seed=seed,
        plant=plant,
    )
    q = np.array(res.q_meas)
    q[0] = res.q[0]
    return res.t, q, np.array(res.tau)


def test_identify_recovers_a_payload_and_friction_on_planar_3r(rng: np.random.Generator) -> None:
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    ident = identify(robot, _log(robot, truth, 8.0, 1e-5, 1))
    rep = ident.report
    assert rep["condition"] < 1e6 and 0 < rep["rank"] <= rep["n_parameters"]
    # the fit explains the held-out data far better than the nominal model
    assert max(rep["holdout_after"]) < 0.1 * max(rep["holdout_before"])
    errs_nominal, errs = [], []
    for _ in range(20):
        q = robot.random_configuration(rng)
        m_true = truth.mass_matrix(q)
        errs.append(np.abs(ident.robot.mass_matrix(q) - m_true).max() / np.abs(m_true).max())
        errs_nominal.append(np.abs(robot.mass_matrix(q) - m_true).max() / np.abs(m_true).max())
        assert np.linalg.eigvalsh(ident.robot.mass_matrix(q))[0] > 0
    assert max(errs) < 0.1 * max(errs_nominal)
    for j, d in zip(("joint1", "joint2", "joint3"), (0.2, 0.1, 0.05), strict=True):
        assert ident.parameters[f"{j}.damping"] == pytest.approx(d, abs=0.3 * d)


def _with_armature(robot: pinobs.Robot, armature: list[float]) -> pinobs.Robot:
    model = robot.model.copy()
    model.armature = np.asarray(armature, dtype=float)
    return robot.with_model(model)


def test_the_armature_is_on_the_mass_matrix_diagonal_and_in_the_dynamics(
    rng: np.random.Generator,
) -> None:
    """Pinocchio's CRBA, ABA and RNEA add ``model.armature`` (every observer's M)."""
    robot = pinobs.load("ur5")
    armature = [0.5, 0.4, 0.2, 0.1, 0.1, 0.05]
    geared = _with_armature(robot, armature)
    for _ in range(5):
        q, v, tau = robot.random_configuration(rng), rng.normal(size=6), rng.normal(size=6)
        np.testing.assert_allclose(
            geared.mass_matrix(q) - robot.mass_matrix(q), np.diag(armature), atol=1e-12
        )
        a = geared.forward_dynamics(q, v, tau)
        bias = robot.forward_dynamics(q, v, np.zeros(6))  # M⁻¹(−C v − g) of the links alone
        np.testing.assert_allclose(
            geared.mass_matrix(q) @ a, tau + robot.mass_matrix(q) @ bias, atol=1e-9
        )


@pytest.mark.parametrize("identified", [False, True])
def test_rows_vanish_on_the_true_parameters_of_a_model_with_armature(identified: bool) -> None:
    """Identified or taken as known, the armature's momentum ``I_a (v₂ − v₁)`` is in the rows."""
    robot = _with_armature(pinobs.load("planar_3r"), [0.05, 0.2, 0.1])
    res = pinobs.simulate(robot, [], duration=2.0, sensor=Sensor(rate=1000.0), seed=3)
    reg = MomentumRegressor(robot, friction=False, offset=False, armature=identified)
    assert reg.size == reg.n_inertial + (3 if identified else 0)
    A, y = reg.system(res.t, res.q, res.v, res.tau, window=100, stride=1)
    assert np.abs(A @ reg.nominal() - y).max() / np.abs(y).max() < 1e-4


def test_rows_are_weighted_with_the_armature_floor_only_when_it_is_identified() -> None:
    """A rotor the nominal model lacks would have a wrist's rows weighed by its link alone
    (UR10e: 2e-4 kg·m² against a 0.44 rotor): the weights' model has the prior's floor."""
    from pinobs.model.identification import PRIOR_ARMATURE_FLOOR

    robot = pinobs.load("ur5")
    m_bar = np.diag(robot.mass_matrix(robot.neutral()))
    floor = PRIOR_ARMATURE_FLOOR * m_bar.max()
    reg = MomentumRegressor(robot, armature=True)
    np.testing.assert_allclose(reg.weight_robot.model.armature, np.full(6, floor))
    np.testing.assert_array_equal(robot.model.armature, np.zeros(6))  # the nominal untouched
    np.testing.assert_allclose(reg.prior_std()[reg.armature_slice], np.maximum(m_bar, floor))
    assert MomentumRegressor(robot).weight_robot is robot
    # a given weights' model (identify's second stage: the nominal one with the first stage's
    # rotors): the weights are its, the priors keep the floor's inertia (a prior does not
    # depend on the data)
    theta = reg.nominal()
    theta[reg.armature_slice] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.2]
    fitted = reg.armature_weights(theta)
    np.testing.assert_array_equal(fitted.model.armature, [0, 0, 0, 0, 0, 0.2])
    np.testing.assert_allclose(
        fitted.mass_matrix(robot.neutral()) - np.diag(fitted.model.armature),
        robot.mass_matrix(robot.neutral()),
        rtol=0,
        atol=1e-12,
    )
    given = MomentumRegressor(robot, armature=True, weight_model=fitted)
    assert given.weight_robot is fitted
    np.testing.assert_allclose(given.prior_robot.model.armature, np.full(6, floor))
    np.testing.assert_array_equal(given.prior_std(), reg.prior_std())
    with pytest.raises(pinobs.DimensionError, match="weight_model"):
        MomentumRegressor(robot, armature=True, weight_model=pinobs.load("planar_3r"))


def test_the_second_stage_weights_by_the_armature_the_first_fitted() -> None:
    """UR5 truth with links ±20 % and a payload, no rotors (10 s, σ = 1e-4): weighted by the
    floor's rotors the wrists' rows count ~8× less than their inertia says (wrist 3's ``M̄``
    0.017 against a floor of 0.13); the second stage is weighted by the nominal model
    carrying the first stage's rotors (near 0 at the wrists).  Measured ``‖M̂⁻¹ M − I‖₂``
    (RMS over 60 configurations of a fresh trajectory), seeds 1-6, default against the
    floor's weights kept: 0.0025/0.0047, 0.0135/0.0147, 0.0059/0.0093, 0.0047/0.0052,
    0.0060/0.0066, 0.0036/0.0093 (without armature: 0.0030, 0.0079, 0.0059, 0.0047, 0.0047,
    0.0037).  On ``benchmarks/learning.py``'s one-pass UR5 ``ekf`` the floor's weights cost
    3×: 1.95e-3 against 6.6e-4 rad/s."""
    from pinobs.simulation.mismatch import mismatched_plant

    robot = pinobs.load("ur5")
    truth = mismatched_plant(robot, "inertia20_payload", seed=0)
    reg = MomentumRegressor(robot, armature=True)
    val = pinobs.simulate(robot, [], duration=6.0, sensor=Sensor(rate=1000.0), seed=7, plant=truth)

    def error(model: pinobs.Robot) -> float:
        m_hat_inv_m = [
            np.linalg.solve(model.mass_matrix(q), truth.mass_matrix(q)) for q in val.q[::100]
        ]
        return float(np.sqrt(np.mean([np.linalg.norm(x - np.eye(6), 2) ** 2 for x in m_hat_inv_m])))

    ratios = []
    for seed in (1, 2, 3):
        sensor = Sensor(rate=1000.0, noise_std=1e-4)
        log = pinobs.simulate(robot, [], duration=10.0, sensor=sensor, seed=seed, plant=truth)
        ident = identify(robot, log)
        # the rows weighted by the nominal model with the rotors kept (none here:
        # determined_armature drops those the data do not determine), not by the floor's
        weights = np.asarray(ident.regressor.weight_robot.model.armature)
        np.testing.assert_array_less(weights[3:], 0.1 * reg.armature_floor()[3:])
        ratios.append(
            error(ident.robot) / error(identify(robot, log, weight_model=reg.prior_robot).robot)
        )
    # measured 0.63, 0.55, 0.69 (no rotor kept: the default fit is armature=False's, 0.0030,
    # 0.0079, 0.0059; with every rotor kept it was 0.53, 0.92, 0.63)
    assert max(ratios) < 1.0 and np.mean(ratios) < 0.8


def test_identify_recovers_the_armature_and_predicts_better_than_without_it(
    rng: np.random.Generator,
) -> None:
    """planar_3r's truth with rotors of 0.05, 0.2, 0.1 kg·m² on its joints (seed 1, σ = 1e-5).

    Joint 1's armature is the same column as body 1's rotational inertia about its fixed
    axis (not identifiable apart from it: only their sum, which M holds, is).  Compared in
    torque on a fresh trajectory: the weighted residuals of the two fits are not in the
    same units (the rows' weights include the armature's floor when it is identified)."""
    robot = pinobs.load("planar_3r")
    truth = _with_armature(planar_3r_truth(robot), [0.05, 0.2, 0.1])
    log = _log(robot, truth, 8.0, 1e-5, 1)
    ident = identify(robot, log)
    without = identify(robot, log, armature=False)
    assert ident.parameters["joint2.armature"] == pytest.approx(0.2, rel=0.02)
    assert ident.parameters["joint3.armature"] == pytest.approx(0.1, rel=0.02)
    # joint 1's rotor is not determined apart from link 1's inertia: the model's own (0) kept
    assert ident.regressor.armature_joints == ("joint2", "joint3")
    assert "joint1.armature" not in ident.parameters.names
    np.testing.assert_array_equal(
        ident.robot.model.armature,
        [0.0, ident.parameters["joint2.armature"], ident.parameters["joint3.armature"]],
    )
    assert "joint1.armature" not in without.parameters.names
    np.testing.assert_array_less(
        torque_error(ident.robot, truth), 0.01 * torque_error(without.robot, truth)
    )
    for _ in range(10):
        q = robot.random_configuration(rng)
        m_true = truth.mass_matrix(q)
        err = np.abs(ident.robot.mass_matrix(q) - m_true).max()
        assert err < 0.01 * np.abs(m_true).max()
        assert err < 0.1 * np.abs(without.robot.mass_matrix(q) - m_true).max()


def test_identifying_the_armature_of_a_truth_without_one_keeps_it_near_zero() -> None:
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    log = _log(robot, truth, 8.0, 1e-5, 1)
    # rows weighted by M⁻¹ (its armature floor is what keeps the wrist's rotor honest: module
    # docstring); weighting="torque" measured 1.11× the fit without armature on joint 2
    ident = identify(robot, log, weighting="inertia")
    without = identify(robot, log, armature=False, weighting="inertia")
    m_bar = np.diag(robot.mass_matrix(robot.neutral()))
    armature = np.asarray(ident.robot.model.armature)
    assert np.all(armature >= 0) and np.all(armature < 1e-2 * m_bar)
    np.testing.assert_array_less(
        torque_error(ident.robot, truth), 1.1 * torque_error(without.robot, truth)
    )


def test_a_model_with_armature_is_saved_with_its_sidecar_and_reloads_the_same(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    robot = pinobs.load("planar_3r")
    truth = _with_armature(planar_3r_truth(robot), [0.05, 0.2, 0.1])
    ident = identify(robot, _log(robot, truth, 8.0, 1e-5, 1))
    path = ident.save(str(tmp_path / "calibrated.urdf"))
    assert (tmp_path / "calibrated.pinobs.json").is_file()
    back = pinobs.load(path, friction=True)
    np.testing.assert_array_equal(back.model.armature, ident.robot.model.armature)
    for _ in range(10):
        q = robot.random_configuration(rng)
        np.testing.assert_allclose(
            back.mass_matrix(q), ident.robot.mass_matrix(q), rtol=0, atol=1e-12
        )


def test_identify_refuses_logs_without_torque_motion_or_length() -> None:
    robot = pinobs.load("planar_3r")
    t = np.arange(3000) * 1e-3
    q = np.zeros((t.size, robot.nq))
    with pytest.raises(IdentificationError, match="no torques"):
        identify(robot, (t, q, None))
    with pytest.raises(IdentificationError, match="never moves"):
        identify(robot, (t, q, np.zeros((t.size, robot.nv))))
    with pytest.raises(IdentificationError, match="spans"):
        identify(robot, (t[:100], q[:100], np.zeros((100, robot.nv))))


def test_solve_refuses_an_empty_system() -> None:
    reg = MomentumRegressor(pinobs.load("cartpole"))
    with pytest.raises(IdentificationError, match="too short"):
        solve(reg, np.zeros((0, reg.size)), np.zeros(0))


@pytest.mark.parametrize("name", ["planar_3r", "ur5"])
def test_saved_urdf_reloads_with_the_same_dynamics(name, tmp_path, rng) -> None:
    """The UR5's file also has <transmission><joint> elements and fixed links merged into
    wrist_3."""
    robot = pinobs.load(name)
    n = len(robot.joints)
    truth = robot.perturbed(
        inertia_scale=np.linspace(0.8, 1.2, n),
        payload=(0.5, [0.05, 0.01, 0.0]),
        damping=np.linspace(0.05, 0.2, n),
        coulomb=np.linspace(0.02, 0.1, n),
    )
    path = write_urdf(truth, tmp_path / "calibrated.urdf")
    back = pinobs.load(path, friction=True)  # and no warning (pytest: warnings are errors)
    for _ in range(10):
        q = robot.random_configuration(rng)
        v = rng.normal(size=robot.nv)
        tau = rng.normal(size=robot.nv)
        np.testing.assert_allclose(
            back.forward_dynamics(q, v, tau), truth.forward_dynamics(q, v, tau), atol=1e-12
        )


def _mesh_files(path: str) -> list[str]:
    return [m.get("filename", "") for m in ET.parse(path).getroot().iter("mesh")]


def test_saved_urdf_of_a_registered_robot_loads_its_package_meshes_from_another_folder(
    tmp_path: Path,
) -> None:
    """ur5's meshes are package://example-robot-data/… URIs found through the wheel's share
    folder; written elsewhere they must still be found (they were not: 14 meshes missing)."""
    robot = pinobs.load("ur5")
    path = write_urdf(robot.perturbed(inertia_scale=np.full(6, 1.1)), tmp_path / "a" / "ur5.urdf")
    files = _mesh_files(path)
    assert len(files) == 14
    assert all(Path(f).is_absolute() and Path(f).is_file() for f in files), files
    back = pinobs.load(path)
    assert back.visual_model.ngeoms == robot.visual_model.ngeoms == 7
    assert back.collision_model.ngeoms == robot.collision_model.ngeoms


ARM = """<robot name="arm">
  <link name="base"><visual><geometry><mesh filename="{base}"/></geometry></visual></link>
  <link name="l1">
    <inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/>
    </inertial>
    <visual><geometry><mesh filename="{l1}"/></geometry></visual>
  </link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


@pytest.mark.parametrize(
    ("urdf", "base", "l1", "package_dirs"),
    [  # relative to the URDF's folder; package:// found only through the package_dirs given
        ("share/arm_pkg/urdf/arm.urdf", "../meshes/box.stl", "./../meshes/box.stl", False),
        (
            "src/arm.urdf",
            "package://arm_pkg/meshes/box.stl",
            "package://arm_pkg/meshes/box.stl",
            True,
        ),
    ],
)
def test_saved_urdf_of_a_file_loads_its_relative_meshes_from_another_folder(
    tmp_path: Path, urdf: str, base: str, l1: str, package_dirs: bool
) -> None:
    """Written as the absolute paths they resolved to (they were kept relative: not found)."""
    box = tmp_path / "share" / "arm_pkg" / "meshes" / "box.stl"
    box.parent.mkdir(parents=True)
    erd = pinobs.model.loading._erd_share_dir() / "example-robot-data" / "robots"
    shutil.copy(erd / "ur_description/meshes/ur5/collision/base.stl", box)
    source = tmp_path / urdf
    source.parent.mkdir(parents=True, exist_ok=True)
    source.write_text(ARM.format(base=base, l1=l1))
    robot = pinobs.load(source, package_dirs=[tmp_path / "share"] if package_dirs else None)
    assert robot.visual_model.ngeoms == 2
    path = write_urdf(robot.perturbed(inertia_scale=[1.5]), tmp_path / "out" / "arm.urdf")
    assert _mesh_files(path) == [str(box.resolve())] * 2
    assert pinobs.load(path).visual_model.ngeoms == 2


def test_calibrated_mass_matrix_is_positive_definite_at_a_thousand_configurations() -> None:
    robot = pinobs.load("ur5")
    truth = robot.perturbed(inertia_scale=np.linspace(0.8, 1.2, 6), payload=(1.0, [0.0, 0.0, 0.05]))
    ident = identify(robot, _log(robot, truth, 6.0, 1e-4, 2))
    # "not excited" parameters stay nominal unless consistency moved them, and then are named
    # (wrist_3's mass went 0.188 → 1.617 under "stay near their nominal values")
    reg, rep = ident.regressor, ident.report
    for name in set(rep["not_excited"]) - set(rep["moved_by_consistency"]):
        i = reg.names.index(name)
        moved = abs(ident.parameters.values[i] - ident.parameters.nominal[i])
        assert moved <= 0.5 * reg.prior_std()[i] or not rep["projected"], name
    rng = np.random.default_rng(5)
    smallest = min(
        np.linalg.eigvalsh(ident.robot.mass_matrix(robot.random_configuration(rng, scale=np.pi)))[0]
        for _ in range(1000)
    )
    assert smallest > 0


def test_consistency_step_is_optimal_under_a_metric_spanning_fifteen_decades() -> None:
    """A nearly noise-free log's posterior precision spans ~1e15 (UR5, measured): the
    closest consistent point must still beat any other consistent point, e.g. the truth."""
    robot = pinobs.load("ur5")
    reg = MomentumRegressor(robot, friction=True, offset=False)
    s = reg.prior_std()
    rng = np.random.default_rng(3)
    truth = MomentumRegressor(
        robot.perturbed(inertia_scale=np.linspace(0.8, 1.2, 6), payload=(1.0, [0.0, 0.0, 0.05])),
        friction=True,
        offset=False,
    ).nominal()
    truth[reg.n_inertial :] = 0.1 * s[reg.n_inertial :]  # strictly positive friction
    basis, _ = np.linalg.qr(rng.normal(size=(reg.size, reg.size)))
    lam = np.logspace(0, 15, reg.size)
    prec = (basis * lam) @ basis.T
    # the unconstrained estimate: the truth moved far along the weakly seen directions
    theta_hat = truth + s * (basis @ (rng.normal(size=reg.size) * 3.0 / np.sqrt(lam)))
    assert not _is_consistent(reg, theta_hat)
    fixed = _consistent(reg, theta_hat, prec, s)
    assert _is_consistent(reg, fixed)

    def cost(theta: np.ndarray) -> float:
        d = (theta - theta_hat) / s
        return float(d @ prec @ d)

    assert cost(fixed) <= cost(truth)


def test_identify_with_the_true_path_finds_the_true_dynamics(rng: np.random.Generator) -> None:
    """Given exact velocities (errors-in-variables removed), the fit reaches the truth."""
    robot = pinobs.load("planar_3r")
    truth = robot.perturbed(inertia_scale=[1.2, 0.8, 1.1], payload=(0.5, [0.05, 0.0, 0.0]))
    res = pinobs.simulate(
        robot, [], duration=6.0, sensor=Sensor(rate=1000.0, noise_std=1e-4), seed=1, plant=truth
    )
    sg = identify(robot, res, friction=False, offset=False)
    exact = identify(robot, res, friction=False, offset=False, path=(res.q, res.v))

    def acc_error(model: pinobs.Robot) -> float:
        errs = []
        for _ in range(50):
            q, v = robot.random_configuration(rng), rng.normal(size=robot.nv)
            tau = rng.normal(size=robot.nv)
            errs.append(model.forward_dynamics(q, v, tau) - truth.forward_dynamics(q, v, tau))
        return float(np.sqrt(np.mean(np.square(errs))))

    assert acc_error(exact.robot) < 0.1 * acc_error(sg.robot)
    assert max(exact.report["holdout_after"]) < 0.1 * max(sg.report["holdout_after"])
    with pytest.raises(pinobs.DimensionError, match="path shapes"):
        identify(robot, res, path=(res.q[:10], res.v[:10]))


def _pendulum_log(scenario: str, noise: float, seed: int = 3):
    from pinobs.simulation.mismatch import mismatched_plant

    robot = pinobs.load("double_pendulum")
    return robot, _log(robot, mismatched_plant(robot, scenario, seed=seed), 4.0, noise, seed)


def _unexplained_said(rep: dict) -> bool:
    return any("unexplained than noise" in w for w in rep["warnings"])


@pytest.mark.parametrize("noise", [1e-4, 1e-3])
def test_unexplained_warning_is_relative_to_the_noise_floor(noise: float) -> None:
    """A sweep wrote a URDF with link1 at 7.15 kg (truth 0.32) from negated torques: 26–32 %
    unexplained, below the old 50 % bar; reversed joint order left 12–14 %, no friction on a
    plant with friction 28–35 %.  Clean logs leave about what noise does."""
    robot, (t, q, tau) = _pendulum_log("friction", noise)
    clean = identify(robot, (t, q, tau), offset=False).report
    assert not _unexplained_said(clean)
    assert max(clean["unexplained"]) < 3 * max(clean["unexplained_floor"]) + 0.01
    for bad, friction in ((-tau, True), (tau[:, ::-1], True), (tau, False)):
        rep = identify(robot, (t, q, bad), offset=False, friction=friction).report
        assert _unexplained_said(rep), rep["unexplained"]


def test_a_single_torque_spike_is_named_not_a_hundred_percent_unexplained() -> None:
    robot, (t, q, tau) = _pendulum_log("inertia20_payload", 1e-4)
    spiked = tau.copy()
    spiked[1000, 0] = 1e5
    rep = identify(robot, (t, q, spiked), offset=False).report
    assert max(rep["unexplained"]) < 0.01 and not _unexplained_said(rep)
    assert rep["outlier_windows"] == [pytest.approx(1.1)]
    assert any("t = 1.1 s" in w for w in rep["warnings"])
    assert identify(robot, (t, q, tau), offset=False).report["outlier_windows"] == []


def test_absurd_torques_are_refused_naming_the_row() -> None:
    robot = pinobs.load("ur5")
    t = np.arange(2000) * 1e-3
    q = np.zeros((t.size, robot.nq))
    tau = np.zeros((t.size, robot.nv))
    tau[700, 2] = 1e300
    with pytest.raises(IdentificationError, match=r"absurd torques, the first tau\[700\]"):
        identify(robot, (t, q, tau))


def test_repeated_or_backward_timestamps_are_refused() -> None:
    robot, (t, q, tau) = _pendulum_log("inertia20_payload", 1e-4)
    for times in (np.insert(t, 500, t[500]), t[np.r_[0:500, 501, 500, 502 : t.size]]):
        n = times.size
        qq, tt = np.resize(q, (n, q.shape[1])), np.resize(tau, (n, tau.shape[1]))
        with pytest.raises(pinobs.TimestampError, match="do not increase"):
            identify(robot, (times, qq, tt))


def test_a_log_broken_by_long_gaps_is_refused_saying_so() -> None:
    """Dropped samples are used as they are; gaps of 40 ms every 100 ms leave no window."""
    robot, (t, q, tau) = _pendulum_log("inertia20_payload", 1e-4)
    keep = np.arange(t.size) % 100 < 60
    with pytest.raises(IdentificationError, match=r"gaps longer than 16 median intervals"):
        identify(robot, (t[keep], q[keep], tau[keep]))


def test_nan_rows_are_filled_and_give_nearly_the_clean_result() -> None:
    """2 % single NaN rows split a UR5 log into ~50-sample stretches, shorter than a window:
    the acceleration error went from 0.013 to 0.50 (pinobs.identify)."""
    robot, (t, q, tau) = _pendulum_log("inertia20_payload", 1e-4)
    holes = np.random.default_rng(1).choice(np.arange(1, t.size - 1), t.size // 50, replace=False)
    qn, taun = q.copy(), tau.copy()
    qn[holes] = np.nan
    taun[holes[::2]] = np.nan
    clean = identify(robot, (t, q, tau), offset=False)
    holed = identify(robot, (t, qn, taun), offset=False)
    assert holed.report["filled_rows"] == holes.size
    assert any("filled" in w for w in holed.report["warnings"])
    np.testing.assert_allclose(
        holed.parameters.values, clean.parameters.values, rtol=0.05, atol=1e-3
    )


def test_a_given_path_is_not_used_near_the_ends_of_its_stretches() -> None:
    """A smoother started afresh on each stretch errs at its start (0.4–6 rad/s measured
    after gaps); those rows must not reach the regressor."""
    robot = pinobs.load("planar_3r")
    res = pinobs.simulate(
        robot, [], duration=4.0, sensor=Sensor(rate=1000.0, noise_std=1e-4), seed=1
    )
    t, q, tau = res.t, np.array(res.q_meas), np.array(res.tau)
    q[0] = res.q[0]
    # without armature: joint1's is the same column as link1's inertia about its axis, and
    # which of the two takes a change moves with the consistency step (the dynamics do not:
    # both fits' acceleration error against the truth is 7e-4 to 1.3e-3 with it, measured)
    opts = {"friction": False, "offset": False, "armature": False}
    exact = identify(robot, (t, q, tau), path=(res.q, res.v), **opts)
    v = np.array(res.v)
    qs = np.array(res.q)
    for k in (0, 1500, 2500):  # a gap of 30 rows, then a smoother start-up error
        qs[k : k + 30], v[k : k + 30] = np.nan, np.nan
        v[k + 30 : k + 40] += 3.0
    q[1500:1530] = np.nan
    q[2500:2530] = np.nan
    gapped = identify(robot, (t, q, tau), path=(qs, v), **opts)
    np.testing.assert_allclose(
        gapped.parameters.values, exact.parameters.values, rtol=0.02, atol=1e-4
    )


def test_sampled_torques_give_rate_independent_parameters_on_an_excitation() -> None:
    """A zero-order hold's ∫τ = Σ τₖh on torques sampled at the instants (``pinobs
    excite``'s) gave planar_3r a spurious damping of 0.16 at 100 Hz, 0.016 at 1 kHz."""
    from pinobs.model.excitation import excite

    robot = pinobs.load("planar_3r")
    found = {}
    for rate in (100.0, 1000.0):
        exc = excite(robot, duration=6.0, rate=rate, seed=0)
        # without armature, as measured (with it the two rates' accelerations differed by up
        # to 0.32 %, above this test's 0.2 %: not looked into yet)
        ident = identify(
            robot,
            (exc.t, exc.q, exc.tau),
            offset=False,
            armature=False,
            path=(exc.q, exc.v),
            torque="sampled",
            # rows weighted by M⁻¹, as measured (weighting="torque": a damping of 2.1e-3 at
            # 100 Hz, against the held torque's 0.16)
            weighting="inertia",
        )
        damping = [ident.parameters[f"joint{j}.damping"] for j in (1, 2, 3)]
        assert max(damping) < 1e-3, (rate, damping)  # the excitation has no friction
        found[rate] = ident.robot
    rng = np.random.default_rng(0)
    for _ in range(10):
        q, v, tau = robot.random_configuration(rng), rng.normal(size=3), rng.normal(size=3)
        a100, a1k = (found[r].forward_dynamics(q, v, tau) for r in (100.0, 1000.0))
        np.testing.assert_allclose(a100, a1k, atol=2e-3 * (1 + np.abs(a1k).max()))
    with pytest.raises(pinobs.OptionError, match="held"):
        identify(robot, (exc.t, exc.q, exc.tau), torque="zoh")


def test_too_short_logs_are_refused_or_warned_with_the_length_needed() -> None:
    """A 0.5 s log had as many rows as identifiable combinations (the fit interpolates):
    planar_3r came out worse than nominal, without a word."""
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    t, q, tau = _log(robot, truth, 8.0, 1e-4, 1)
    with pytest.raises(IdentificationError, match=r"interpolate.*at least [\d.]+ s"):
        identify(robot, (t[:501], q[:501], tau[:501]), offset=False)
    short = identify(robot, (t[:2001], q[:2001], tau[:2001]), offset=False).report
    assert any("loosely determined" in w for w in short["warnings"])
    full = identify(robot, (t, q, tau), offset=False).report
    assert not any("loosely determined" in w for w in full["warnings"])


def test_a_log_that_does_not_excite_names_the_still_joint_and_the_weak_parameters() -> None:
    """A frozen joint was refused with a condition number alone."""
    robot = pinobs.load("ur5")
    t, q, tau = _log(robot, robot, 4.0, 1e-4, 1)
    q[:, 5] = q[0, 5] + np.random.default_rng(0).normal(0, 1e-4, t.size)
    with pytest.raises(
        IdentificationError,
        match=r"never moving .*wrist_3_joint.*least excited: .*wrist_3_joint.*--max-condition",
    ):
        identify(robot, (t, q, tau))


def test_a_still_noisy_log_is_refused() -> None:
    robot = pinobs.load("planar_3r")
    t = np.arange(4000) * 1e-3
    q = np.random.default_rng(0).normal(0, 1e-3, (t.size, robot.nq))
    with pytest.raises(IdentificationError, match="never moves"):
        identify(robot, (t, q, np.ones((t.size, robot.nv))))


def test_identify_options_are_checked_naming_the_value() -> None:
    robot = pinobs.load("planar_3r")
    log = (np.arange(10) * 1e-3, np.zeros((10, 3)), np.zeros((10, 3)))
    for kwargs, error, said in (
        ({"window": 0.0}, pinobs.GainError, "window=0.0"),
        ({"window": float("nan")}, pinobs.GainError, "window=nan"),
        ({"max_condition": float("nan")}, pinobs.GainError, "max_condition=nan"),
        ({"holdout": "0.2"}, pinobs.OptionError, "holdout='0.2'"),
        ({"holdout": float("nan")}, pinobs.DimensionError, "holdout=nan"),
        ({"friction": "no"}, pinobs.OptionError, "friction='no'"),
    ):
        with pytest.raises(error, match=said):
            identify(robot, log, **kwargs)
    with pytest.raises(pinobs.DimensionError, match=r"t \(N,\)"):
        identify(robot, (np.zeros((10, 1)), np.zeros((10, 3)), np.zeros((10, 3))))


def _acceleration_error(model: pinobs.Robot, truth: pinobs.Robot) -> float:
    """RMS of ``model``'s forward dynamics minus the truth's at 100 random states (seed 0)."""
    rng = np.random.default_rng(0)
    errs = []
    for _ in range(100):
        q, v, tau = truth.random_configuration(rng), rng.normal(size=truth.nv), rng.normal(size=3)
        errs.append(model.forward_dynamics(q, v, tau) - truth.forward_dynamics(q, v, tau))
    return float(np.sqrt(np.mean(np.square(errs))))


def test_a_log_with_dropped_rows_is_identified_about_as_well_as_the_clean_log() -> None:
    """8 % of the rows of 8 s planar_3r logs deleted (80 % of the losses single rows, the
    others runs of 3–9), σ = 1e-4: it was refused ("timestamp jitter").  Acceleration
    error against the truth, dropped over clean, measured: 0.977, 0.978, 0.959 (seeds 1–3;
    seeds 4, 5: 1.138, 0.974); with pinobs.identify's refinement 0.514, 0.917, 1.122, 0.812,
    0.995 (benchmarks/irregular_logs.py).  The bound, 1.2: a fit as good as the clean
    log's, to within the seed-to-seed spread of these ratios."""
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    ratios = []
    for seed in (1, 2, 3):
        t, q, tau = _log(robot, truth, 8.0, 1e-4, seed)
        keep = dropped_rows(t.size, 0.08, seed)
        # without armature, as measured (with it: 1.010, 0.998, 1.326; not looked into yet);
        # rows weighted by M⁻¹, as measured (weighting="torque": 1.245, 0.997, 1.030)
        opts = {"offset": False, "armature": False, "weighting": "inertia"}
        clean = identify(robot, (t, q, tau), **opts)
        dropped = identify(robot, (t[keep], q[keep], tau[keep]), **opts)
        assert dropped.report["rows"] >= 0.95 * clean.report["rows"]  # no window lost
        ratios.append(
            _acceleration_error(dropped.robot, truth) / _acceleration_error(clean.robot, truth)
        )
    assert max(ratios) <= 1.2, ratios


@pytest.mark.slow  # 10-21 s on a 2-core machine: the default run stays under 10 min
def test_an_irregularly_sampled_log_is_identified_about_as_well_as_the_clean_log() -> None:
    """One 10 kHz run sampled every 1 ms and at intervals uniform in 0.5–1.5 ms (torques as
    sampled), σ = 1e-4.  Acceleration error, irregular over clean, measured: 0.541, 0.960,
    0.768 (seeds 1–3; seeds 4, 5: 1.049, 0.929); with pinobs.identify's refinement 1.071,
    0.967, 0.931, 1.071, 0.939 (benchmarks/irregular_logs.py).  The two logs' noise
    draws differ, which is most of the spread."""
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    ratios = []
    for seed in (1, 2, 3):
        clean_log, irregular_log = resampled_log(robot, truth, 8.0, 1e-4, seed)
        clean = identify(robot, clean_log, offset=False, torque="sampled")
        irregular = identify(robot, irregular_log, offset=False, torque="sampled")
        ratios.append(
            _acceleration_error(irregular.robot, truth) / _acceleration_error(clean.robot, truth)
        )
    assert max(ratios) <= 1.2, ratios


# ------------------------------------------------------- weighting, channels, payload
def test_payload_placement_map_is_the_action_of_the_placement(rng: np.random.Generator) -> None:
    from pinobs.model.identification import PayloadRegressor

    for _ in range(5):
        placement = pin.SE3.Random()
        inertia = pin.Inertia.Random()
        T = PayloadRegressor.placement_map(placement)
        np.testing.assert_allclose(
            T @ inertia.toDynamicParameters(),
            placement.act(inertia).toDynamicParameters(),
            atol=1e-10 * (1 + np.abs(inertia.toDynamicParameters()).max()),
        )


def _loaded(robot: pinobs.Robot, frame: str, load: pin.Inertia) -> pinobs.Robot:
    """``robot`` with ``load`` (given in ``frame``) added to the body carrying the frame."""
    model = robot.model.copy()
    f = model.frames[model.getFrameId(frame)]
    model.inertias[f.parentJoint] = model.inertias[f.parentJoint] + f.placement.act(load)
    return robot.with_model(model)


@pytest.mark.parametrize("weighting", ["torque", "inertia"])
def test_identify_payload_recovers_a_known_load_on_a_noise_free_log(weighting: str) -> None:
    """UR5, a 2.8 kg load 6 cm out on tool0 (a frame fixed to wrist 3, not its body): its ten
    parameters recovered, everything else known."""
    robot = pinobs.load("ur5")
    load = pin.Inertia(2.8, np.array([0.01, -0.02, 0.06]), np.diag([0.004, 0.005, 0.003]))
    truth = _loaded(robot, "tool0", load)
    res = pinobs.simulate(robot, [], duration=8.0, sensor=Sensor(rate=1000.0), seed=1, plant=truth)
    log = (res.t, np.array(res.q_meas), np.array(res.tau))
    ident = identify(robot, log, payload="tool0", weighting=weighting)
    phi = ident.parameters.values
    np.testing.assert_allclose(phi, load.toDynamicParameters(), rtol=2e-3, atol=2e-5)
    assert ident.report["payload"]["mass"] == pytest.approx(2.8, rel=1e-4)
    np.testing.assert_allclose(ident.report["payload"]["com"], load.lever, atol=1e-4)
    assert np.linalg.eigvalsh(pseudo_inertia(phi))[0] >= -1e-12
    q = robot.random_configuration(np.random.default_rng(0))
    np.testing.assert_allclose(
        ident.robot.mass_matrix(q), truth.mass_matrix(q), atol=1e-4 * truth.mass_matrix(q).max()
    )
    rep = ident.report
    assert max(rep["holdout_after"]) < 1e-2 * max(rep["holdout_before"])
    # the held-out torques in N·m whatever the weighting: the load's weight on the shoulder
    # lift (2.8 kg · 9.81 at up to ~1 m) before, nothing after
    before, after = np.array(rep["holdout_torque_before"]), np.array(rep["holdout_torque_after"])
    assert np.isfinite(before).all() and 1.0 < before[1] < 2.8 * 9.81 * 1.2
    assert max(after) < 1e-2 * max(before)


def test_identify_payload_of_a_point_mass_stays_physically_consistent() -> None:
    """A point mass (its pseudo-inertia of rank one, on the cone's boundary) on a noisy log:
    the fit is moved onto the cone when it leaves it, and the mass is still found."""
    robot = pinobs.load("ur5")
    load = pin.Inertia(1.5, np.array([0.0, 0.0, 0.08]), np.zeros((3, 3)))
    truth = _loaded(robot, "wrist_3_link", load)
    log = _log(robot, truth, 6.0, 1e-4, 2)
    ident = identify(robot, log, payload="wrist_3_link")
    assert np.linalg.eigvalsh(pseudo_inertia(ident.parameters.values))[0] >= -1e-9
    assert ident.report["payload"]["mass"] == pytest.approx(1.5, rel=0.05)


def test_identify_payload_refuses_an_unknown_or_fixed_frame() -> None:
    robot = pinobs.load("planar_3r")
    log = _log(robot, robot, 2.0, 1e-5, 1)
    with pytest.raises(pinobs.OptionError, match="link3"):
        identify(robot, log, payload="gripper")
    with pytest.raises(pinobs.OptionError, match="fixed to the world"):
        identify(robot, log, payload="world")
    with pytest.raises(pinobs.DimensionError, match="path shapes"):  # as identify's own
        identify(robot, log, payload="link3", path=(log[1][:10], log[1][:10]))


def test_a_mostly_zero_torque_channel_is_refused_by_name_unless_excluded() -> None:
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    t, q, tau = _log(robot, truth, 6.0, 1e-5, 1)
    tau[: int(0.8 * t.size), 2] = 0.0  # joint3's effort not recorded most of the time
    with pytest.raises(IdentificationError, match=r"joint3 \(80 % .*exclude=\['joint3'\]"):
        identify(robot, (t, q, tau))
    ident = identify(robot, (t, q, tau), exclude=["joint3"], weighting="torque")
    rep = ident.report
    assert rep["excluded"] == ["joint3"] and np.isnan(rep["torque_sigma"][2])
    assert np.all(np.isfinite(rep["torque_sigma"][:2]))
    assert not any("joint3" in w for w in rep["warnings"])
    # the two channels kept still fit their joints far better than the nominal model
    after, before = rep["holdout_torque_after"], rep["holdout_torque_before"]
    assert after[0] < 0.1 * before[0] and after[1] < 0.1 * before[1]
    # physically consistent in this mode too
    reg = ident.regressor
    assert _is_consistent(reg, ident.parameters.values)
    with pytest.raises(pinobs.OptionError, match="joint1, joint2, joint3"):
        identify(robot, (t, q, tau), exclude=["joint4"])
    # rows weighted by M⁻¹: the kept joints' block (joint3 held), joint3's rows zero
    by_inertia = identify(robot, (t, q, tau), exclude=["joint3"], weighting="inertia")
    after, before = (
        by_inertia.report["holdout_torque_after"],
        by_inertia.report["holdout_torque_before"],
    )
    assert after[0] < 0.1 * before[0] and after[1] < 0.1 * before[1]
    reg = MomentumRegressor(robot, exclude=["joint3"])
    A, y = reg.system(
        t[:1000], q[:1000], np.gradient(q[:1000], t[:1000], axis=0), tau[:1000], window=100
    )
    assert not np.any(A.reshape(-1, 3, reg.size)[:, 2]) and not np.any(y.reshape(-1, 3)[:, 2])
    assert np.any(A.reshape(-1, 3, reg.size)[:, :2])
    with pytest.raises(pinobs.OptionError, match="weighting="):
        identify(robot, (t, q, tau), weighting="mass")


def test_torque_weighting_gives_each_channel_its_own_noise_in_newton_metres() -> None:
    """White torque noise 100× larger on joint 1 than on joints 2, 3: the channels' residual
    scales say so, and the held-out report in N·m is the same rows' whatever the weighting."""
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    t, q, tau = _log(robot, truth, 6.0, 1e-6, 1)
    tau = tau + np.random.default_rng(5).normal(size=tau.shape) * [0.5, 0.005, 0.005]
    by_torque = identify(robot, (t, q, tau), weighting="torque")
    sigma = by_torque.report["torque_sigma"]
    assert sigma[0] > 10 * max(sigma[1:])
    np.testing.assert_array_equal(
        by_torque.report["holdout_torque_after"], by_torque.report["holdout_after"]
    )
    by_inertia = identify(robot, (t, q, tau), weighting="inertia")
    np.testing.assert_allclose(
        by_inertia.report["holdout_torque_before"],
        by_torque.report["holdout_torque_before"],
        rtol=1e-12,
    )
    assert by_inertia.report["weighting"] == "inertia"
    assert np.all(np.isnan(by_inertia.report["torque_sigma"]))
