"""Drives (pinobs.io.drives): motor positions and currents read as joint ones, through gear
ratios, motor constants and a coupled wrist's transmission."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import pinobs
from pinobs.cli import main
from pinobs.errors import DimensionError, OptionError
from pinobs.io import Drives, read_log, write_log

#: FIGAROH's TX40 reduction matrix (config/TX40_config.yaml; the wrist's coupling T[5, 4]).
TX40_RATIO = (32.0, 32.0, 45.0, -48.0, 45.0, 32.0)


def tx40_transmission() -> np.ndarray:
    T = np.diag(TX40_RATIO)
    T[5, 4] = TX40_RATIO[5]
    return T


def test_motor_positions_round_trip_through_a_coupled_transmission(rng) -> None:
    d = Drives(transmission=tx40_transmission(), position_offset=rng.normal(size=6))
    q = rng.normal(size=(50, 6))
    np.testing.assert_allclose(d.joint_positions(d.motor_positions(q)), q, rtol=0, atol=1e-13)
    m = rng.normal(size=(50, 6))
    np.testing.assert_allclose(d.motor_positions(d.joint_positions(m)), m, rtol=0, atol=1e-12)


def test_the_coupled_wrist_gives_the_known_motor_angles_and_joint_torques() -> None:
    d = Drives(transmission=tx40_transmission(), motor_constant=np.full(6, 2.0))
    q = np.array([[0.1, 0.2, 0.3, 0.4, 0.5, 0.6]])
    # motor 6 turns with joints 5 and 6: 32 (q5 + q6); the others N_j q_j
    np.testing.assert_allclose(
        d.motor_positions(q), [[3.2, 6.4, 13.5, -19.2, 22.5, 32.0 * 1.1]], rtol=1e-14
    )
    i = np.array([[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]])
    # τ = Tᵀ (k i): joint 5 carries motor 5's and motor 6's torque, joint 6 motor 6's alone
    expected = [[64.0, 128.0, 270.0, -384.0, 2 * (45 * 5 + 32 * 6), 2 * 32 * 6]]
    np.testing.assert_allclose(d.joint_torques(i), expected, rtol=1e-14)


def test_drives_compare_and_hash_by_value() -> None:
    a = Drives(transmission=tx40_transmission(), motor_constant=np.ones(6))
    b = Drives(transmission=tx40_transmission(), motor_constant=[1.0] * 6)
    assert a == b and hash(a) == hash(b)
    assert a != Drives(transmission=tx40_transmission(), motor_constant=np.full(6, 2.0))


def test_joint_torques_balance_the_motors_power(rng) -> None:
    """τ_mᵀ θ̇_m = τᵀ q̇ for any transmission (the motors do the joints' work)."""
    T = rng.normal(size=(4, 4)) + 4 * np.eye(4)
    d = Drives(transmission=T, motor_constant=rng.uniform(0.1, 1.0, 4))
    v = rng.normal(size=(20, 4))
    i = rng.normal(size=(20, 4))
    motor_speed = d.motor_positions(v)  # linear: the motor speeds of joint speeds v
    motor_power = np.sum(i * d.motor_constant * motor_speed, axis=1)
    np.testing.assert_allclose(np.sum(d.joint_torques(i) * v, axis=1), motor_power, rtol=1e-12)


def _motor_frame(robot, drives, rng, n=400):
    """A log of the motors (qm, i) and the joints' (q, tau) it stands for."""
    t = np.arange(n) * 1e-3
    q = np.sin(np.outer(t, [3.0, 5.0, 7.0]) + rng.normal(size=3))
    i = rng.normal(size=(n, 3))
    tau = drives.joint_torques(i)
    names = robot.joint_names
    motor = pd.DataFrame(
        {
            "t": t,
            **{f"qm.{j}": drives.motor_positions(q)[:, k] for k, j in enumerate(names)},
            **{f"i.{j}": i[:, k] for k, j in enumerate(names)},
        }
    )
    return motor, t, q, tau


def test_a_log_of_motors_reads_as_the_joints_it_drives(rng, tmp_path) -> None:
    robot = pinobs.load("planar_3r")
    T = np.array([[50.0, 0.0, 0.0], [0.0, 30.0, 0.0], [0.0, 20.0, -20.0]])
    drives = Drives(transmission=T, motor_constant=[0.1, 0.2, 0.3], position_offset=[0, 0.5, 0])
    motor, t, q, tau = _motor_frame(robot, drives, rng)
    for source in (motor, tmp_path / "motor.csv"):
        if not isinstance(source, pd.DataFrame):
            motor.to_csv(source, index=False)
        log = read_log(source, robot, drives=drives)
        np.testing.assert_allclose(log.t, t, rtol=0, atol=1e-15)
        np.testing.assert_allclose(log.q, q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(log.tau, tau, rtol=1e-12)


def test_torque_scale_multiplies_the_torque_columns_of_every_format(rng, tmp_path) -> None:
    robot = pinobs.load("planar_3r")
    t = np.arange(10) * 1e-3
    q, tau = rng.normal(size=(10, 3)), rng.normal(size=(10, 3))
    scale = np.array([100 * 0.136, 100 * 0.136, -100 * 0.087])
    write_log(tmp_path / "log.csv", t, q, tau)
    np.savez(tmp_path / "log.npz", t=t, q=q, tau=tau)
    for path in (tmp_path / "log.csv", tmp_path / "log.npz"):
        log = read_log(path, robot, drives=Drives(torque_scale=scale))
        np.testing.assert_allclose(log.tau, tau * scale, rtol=1e-12)
        np.testing.assert_allclose(log.q, q, rtol=1e-12)


def test_bad_drives_are_refused_naming_what_is_wrong(rng) -> None:
    robot = pinobs.load("planar_3r")
    drives = Drives(gear_ratio=[10.0, 10.0, 10.0], motor_constant=[1.0, 1.0, 1.0])
    motor, *_ = _motor_frame(robot, drives, rng, n=5)
    # a current column without a scale
    currents = motor.drop(columns=[c for c in motor if c.startswith("qm.")])
    currents = currents.assign(**{f"q.{j}": 0.0 for j in robot.joint_names})
    with pytest.raises(OptionError, match=r"i\.joint1.*motor currents.*motor_constant"):
        read_log(currents, robot)
    with pytest.raises(OptionError, match="motor_constant"):
        read_log(currents, robot, drives=Drives(gear_ratio=[10.0, 10.0, 10.0]))
    # motor positions without a transmission
    with pytest.raises(DimensionError, match=r"qm\.joint1.*motor positions.*gear"):
        read_log(motor.drop(columns=[c for c in motor if c.startswith("i.")]), robot)
    # a transmission of the wrong shape, singular; a scale of the wrong length
    with pytest.raises(DimensionError, match="square"):
        Drives(transmission=np.ones((3, 2)))
    with pytest.raises(DimensionError, match="singular"):
        Drives(transmission=[[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(DimensionError, match=r"describe 2 joints.*has 3"):
        read_log(motor, robot, drives=Drives(gear_ratio=[1.0, 2.0], motor_constant=[1.0, 1.0]))
    # a square transmission of another robot's size: named, with the size wanted
    four = Drives(transmission=np.eye(4), motor_constant=np.ones(4))
    with pytest.raises(DimensionError, match=r"describe 4 joints.*has 3.*3 × 3 transmission"):
        read_log(motor, robot, drives=four)
    with pytest.raises(DimensionError, match="different sizes"):
        Drives(gear_ratio=[1.0, 2.0, 3.0], motor_constant=[1.0, 1.0])
    with pytest.raises(DimensionError, match="zero"):
        Drives(gear_ratio=[1.0, 0.0, 3.0])
    with pytest.raises(OptionError, match="not both"):
        Drives(gear_ratio=[1.0, 2.0, 3.0], transmission=np.eye(3))
    # drives the log does not use; a joint's q beside its motor's
    joint_side = pd.DataFrame({"t": [0.0, 1e-3], **{f"q.{j}": 0.0 for j in robot.joint_names}})
    with pytest.raises(OptionError, match="not used: gear_ratio"):
        read_log(joint_side, robot, drives=Drives(gear_ratio=[1.0, 2.0, 3.0]))
    with pytest.raises(OptionError, match="not used: torque_scale"):
        read_log(joint_side, robot, drives=Drives(torque_scale=[1.0, 2.0, 3.0]))
    with pytest.raises(DimensionError, match="keep one"):
        read_log(motor.assign(**{"q.joint1": 0.0}), robot, drives=drives)


def test_estimate_reads_a_motor_log_as_the_joint_log_through_the_cli(rng, tmp_path, capsys) -> None:
    robot = pinobs.load("planar_3r")
    drives = Drives(gear_ratio=[50.0, -30.0, 20.0], motor_constant=[0.1, 0.2, 0.3])
    motor, t, q, tau = _motor_frame(robot, drives, rng)
    motor.to_csv(tmp_path / "motor.csv", index=False)
    write_log(tmp_path / "joint.csv", t, q, tau)
    flags = ["--gear-ratio", "50,-30,20", "--motor-constant", "0.1,0.2,0.3"]
    est = ["estimate", "--robot", "planar_3r", "--observer", "kf", "--noise", "1e-5"]
    assert main([*est, "--log", str(tmp_path / "joint.csv"), "--out", str(tmp_path / "a.csv")]) == 0
    out = str(tmp_path / "b.csv")
    assert main([*est, "--log", str(tmp_path / "motor.csv"), "--out", out, *flags]) == 0
    a, b = (np.loadtxt(tmp_path / n, delimiter=",", skiprows=1) for n in ("a.csv", "b.csv"))
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-9)
    # a flag the log cannot use: refused, naming it
    capsys.readouterr()
    bad = [*est, "--log", str(tmp_path / "joint.csv"), "--out", str(tmp_path / "c.csv")]
    assert main([*bad, "--motor-constant", "1,1,1"]) == 2
    assert "motor_constant" in capsys.readouterr().err
    assert main([*bad, "--transmission", "1,0;0,1"]) == 2
    assert "transmission" in capsys.readouterr().err
    ident = ["identify", "--robot", "planar_3r", "--log", str(tmp_path / "joint.csv")]
    assert main([*ident, "--out", str(tmp_path / "id.urdf"), "--gear-ratio", "1,2,3"]) == 2
    assert "not used: gear_ratio" in capsys.readouterr().err
    assert not (tmp_path / "id.urdf").exists()
    # many logs (--out-dir) read through the same drives
    logs = tmp_path / "logs"
    logs.mkdir()
    motor.to_csv(logs / "motor.csv", index=False)
    many = [*est, "--log", str(logs), "--out-dir", str(tmp_path / "many"), "--workers", "0"]
    assert main([*many, *flags, "--no-progress"]) == 0
    c = np.loadtxt(tmp_path / "many" / "motor.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(c, a, rtol=0, atol=1e-9)


def _real_data():
    from tests.io.test_real_data import real_data

    return real_data


@pytest.mark.skipif(_real_data().data_root() is None, reason="no shared data folder")
def test_the_tx40_identified_through_its_drives_predicts_held_out_torques_better() -> None:
    """FIGAROH's TX40: motor encoders and currents through the coupled wrist, identified with
    armature (its URDF's M is singular without), beats the nominal model on the held-out end."""
    import warnings

    root = _real_data().data_root() / "figaroh" / "examples" / "staubli_TX40"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its meshes are not in the data
        robot = pinobs.load(str(root / "urdf" / "tx40_mdh_modified.urdf"), check=False)
    motor = pd.read_csv(root / "data" / "pos_read_data.csv").to_numpy(dtype=float)
    current = pd.read_csv(root / "data" / "curr_data.csv").to_numpy(dtype=float)
    names = robot.joint_names
    frame = pd.DataFrame(
        {
            "t": np.arange(len(motor)) / 5000.0,
            **{f"qm.{j}": motor[:, k] for k, j in enumerate(names)},
            **{f"i.{j}": current[:, k] for k, j in enumerate(names)},
        }
    )
    drives = Drives(
        transmission=tx40_transmission(),
        motor_constant=np.ones(6),
        position_offset=[0.0, -np.pi / 2, np.pi / 2, 0.0, 0.0, 0.0],
    )
    log = read_log(frame, robot, drives=drives)
    # FIGAROH's own conversion (utils/staubli_tx40_tools.py), written out independently
    R = tx40_transmission()
    np.testing.assert_allclose(log.q[:, 4:], np.linalg.solve(R, motor.T).T[:, 4:], atol=1e-12)
    np.testing.assert_allclose(log.tau, (R.T @ current.T).T, rtol=1e-12)
    sl = slice(0, None, 5)  # 1 kHz
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ident = pinobs.identify(robot, (log.t[sl], log.q[sl], log.tau[sl]), refine=())
    assert np.all(ident.robot.model.armature > 0)
    assert np.linalg.cond(ident.robot.mass_matrix(log.q[0])) < 1e6  # regular with the rotors
    held = np.flatnonzero(log.t[sl] > ident.report["fit_end"])[5:-5]
    t, q, tau = log.t[sl], log.q[sl], log.tau[sl]
    v = np.gradient(q, t, axis=0)
    a = np.gradient(v, t, axis=0)

    def residual(rob):
        pred = [rob.inverse_dynamics(q[k], v[k], a[k]) - rob.friction_torque(v[k]) for k in held]
        return np.sqrt(np.mean((np.array(pred) - tau[held]) ** 2, axis=0))

    nominal, fitted = residual(robot), residual(ident.robot)
    # measured (np.gradient derivatives at 1 kHz): nominal 4.9 8.7 3.5 1.9, fitted 2.3 6.7 1.8
    # 0.64 N·m on j1..j4; j5, j6 are not asserted (the coupled wrist's motor-6 inertia and
    # friction act on both, which pinobs's per-joint armature and friction cannot express)
    assert np.all(fitted[:4] < nominal[:4])
