"""Legged-robot columns of table logs (issue 38 item 4): IMU, foot forces, contacts."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import pinobs
from pinobs.errors import DimensionError, LogFormatError, SensorWarning
from pinobs.io import iter_log, read_log
from tests.io.test_real_data import bench_module

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def go1() -> pinobs.Robot:
    return pinobs.load("go1")


@pytest.fixture(scope="module")
def run():
    pytest.importorskip("mujoco")
    from pinobs.simulation.legged import simulate_legged

    return simulate_legged("stand", 0.2, seed=1)


def _frame(run) -> pd.DataFrame:
    return pd.DataFrame({k: v for k, v in run.columns.items() if not k.startswith("truth.")})


def test_simulated_go1_log_reads_imu_forces_and_joints_as_written(tmp_path, go1, run) -> None:
    frame = _frame(run)
    frame.to_csv(tmp_path / "go1.csv", index=False)
    frame.to_parquet(tmp_path / "go1.parquet")
    for source in (frame, tmp_path / "go1.csv", tmp_path / "go1.parquet"):
        with warnings.catch_warnings():
            warnings.simplefilter("error", SensorWarning)  # m/s², rad/s: nothing to say
            log = read_log(source, go1)
        cols = run.columns
        np.testing.assert_array_equal(log.t, cols["t"])
        np.testing.assert_array_equal(
            log.imu_gyro, np.column_stack([cols[f"imu.gyro.{a}"] for a in "xyz"])
        )
        np.testing.assert_array_equal(
            log.imu_acc, np.column_stack([cols[f"imu.acc.{a}"] for a in "xyz"])
        )
        assert log.feet == run.feet
        np.testing.assert_array_equal(
            log.foot_force, np.column_stack([cols[f"force.{f}"] for f in run.feet])
        )
        assert all(f"contact.{f}" in cols for f in run.feet)  # the simulation writes both
        np.testing.assert_array_equal(
            log.contact, np.column_stack([cols[f"contact.{f}"] for f in run.feet])
        )
        for name in run.joints:  # joint columns at the joint's index in q
            b = next(j for j in go1.joints if j.name == name)
            np.testing.assert_array_equal(log.q[:, b.idx_q], cols[f"q.{name}"])
        assert np.isnan(log.q[:, :7]).all()  # the base pose is not measured
        assert any("base pose" in n for n in log.notes)


def test_with_the_root_fixed_the_legs_read_without_nan(run) -> None:
    legs = pinobs.load("go1", root_joint="fixed")
    log = read_log(_frame(run), legs)
    assert log.q.shape == (len(run.columns["t"]), 12) and np.isfinite(log.q).all()
    assert log.imu_acc is not None and not log.notes


def test_chunks_join_to_the_whole_log(tmp_path, go1, run) -> None:
    _frame(run).to_csv(tmp_path / "go1.csv", index=False)
    whole = read_log(tmp_path / "go1.csv", go1)
    chunks = list(iter_log(tmp_path / "go1.csv", go1, chunk_rows=7))
    assert len(chunks) > 1
    np.testing.assert_array_equal(np.concatenate([c.imu_acc for c in chunks]), whole.imu_acc)
    np.testing.assert_array_equal(np.concatenate([c.foot_force for c in chunks]), whole.foot_force)


def test_concat_logs_keeps_the_feet_of_any_chunk(go1, run) -> None:
    from pinobs.io import concat_logs

    log = read_log(_frame(run), go1)
    empty = pinobs.io.Log(np.empty(0), np.empty((0, go1.nq)), None)
    joined = concat_logs([empty, log])
    assert joined.feet == log.feet
    np.testing.assert_array_equal(joined.foot_force, log.foot_force)
    np.testing.assert_array_equal(joined.imu_gyro, log.imu_gyro)


def test_contact_flags_read_and_a_force_in_a_contact_column_is_refused(go1) -> None:
    frame = pd.DataFrame({"t": [0.0, 0.01], **{f"q.{n}": [0.1, 0.1] for n in go1.joint_names[1:]}})
    frame["contact.FL_foot"] = [1, 0]
    frame["contact.FR_foot"] = [0, 1]
    # without IMU columns the base pose is still required, as before
    with pytest.raises(DimensionError, match="root_joint"):
        read_log(frame, go1)
    frame[[f"q.root_joint.{k}" for k in range(7)]] = [0, 0, 0.3, 0, 0, 0, 1]
    log = read_log(frame, go1)
    assert log.feet == ("FL_foot", "FR_foot")
    np.testing.assert_array_equal(log.contact, [[1, 0], [0, 1]])
    assert log.imu_gyro is None and log.foot_force is None
    frame["contact.FR_foot"] = [0, 87.0]
    with pytest.raises(LogFormatError, match=r"'contact.FR_foot', row 1: 87.0 is not a contact"):
        read_log(frame, go1)


def test_a_foot_not_in_the_model_and_incomplete_imu_columns_are_named(go1, run) -> None:
    frame = _frame(run)
    with pytest.raises(DimensionError, match=r"'force.FL_toe'.*FL_foot"):
        read_log(frame.rename(columns={"force.FL_foot": "force.FL_toe"}), go1)
    with pytest.raises(DimensionError, match=r"lacks \['imu.acc.z'\]"):
        read_log(frame.drop(columns="imu.acc.z"), go1)
    with pytest.raises(DimensionError, match=r"'imu.gyro.w'"):
        read_log(frame.assign(**{"imu.gyro.w": 0.0}), go1)


def test_an_accelerometer_in_g_and_a_gyro_in_deg_per_s_are_warned_naming_the_columns(
    go1, run
) -> None:
    frame = _frame(run)
    in_g = frame.assign(**{f"imu.acc.{a}": frame[f"imu.acc.{a}"] / 9.80665 for a in "xyz"})
    with pytest.warns(SensorWarning, match=r"imu.acc.x.*looks like it reads in g"):
        log = read_log(in_g, go1)
    assert any("in g" in n for n in log.notes)
    moving = frame.assign(**{"imu.gyro.z": np.linspace(0, 2.0, len(frame))})  # up to 2 rad/s
    with warnings.catch_warnings():
        warnings.simplefilter("error", SensorWarning)
        read_log(moving, go1)
    deg = moving.assign(**{"imu.gyro.z": np.degrees(moving["imu.gyro.z"])})
    with pytest.warns(SensorWarning, match=r"'imu.gyro.z'.*deg/s"):
        read_log(deg, go1)


def test_logs_without_legged_columns_have_none_of_them(tmp_path) -> None:
    ur5 = pinobs.load("ur5")
    log = read_log(ROOT / "examples" / "ur5_log.csv", ur5)
    assert log.imu_gyro is None and log.imu_acc is None
    assert log.foot_force is None and log.contact is None and log.feet == ()


# --------------------------------------------------------------- the real Go1 log
SEROW_MG = bench_module("real_data").SEROW_MG


def serow_go1_frame(path: Path) -> pd.DataFrame:
    """SEROW's Go1 unit-test CSV in pinobs' table columns (benchmarks/real_data.py)."""
    return bench_module("real_data").serow_go1_frame(path)


def serow_go1_csv() -> Path:
    """SEROW's Go1 log in the shared data folder; the test skips where it is absent."""
    root = bench_module("real_data").data_root()
    path = None if root is None else root / "serow_go1/evaluation/unit_tests/data/go1.csv"
    if path is None or not path.is_file():
        pytest.skip("no shared data folder with serow_go1")
    return path


def test_real_go1_log_reads_every_row(go1) -> None:
    path = serow_go1_csv()
    log = read_log(serow_go1_frame(path), go1)
    with path.open() as fh:
        n = sum(1 for _ in fh) - 1
    assert len(log) == n and not log.problems
    assert np.isfinite(log.imu_acc).all() and np.isfinite(log.q[:, 7:]).all()
    rate = 1.0 / np.median(np.diff(log.t))
    assert 350 < rate < 450  # its README: 400 Hz
    g = np.linalg.norm(log.imu_acc.mean(axis=0))
    assert 9.0 < g < 10.5  # m/s², not g
    assert log.feet == ("FR_foot", "FL_foot", "RR_foot", "RL_foot")
    assert (log.foot_force >= 0).all() and (log.foot_force <= SEROW_MG).all()
    assert any("base pose" in n for n in log.notes)


# ------------------------------------------------------------------ ROS bags
def _write_legged_bag(path: Path, robot: pinobs.Robot, *, imu_gap: bool = False) -> None:
    """JointState at 100 Hz (t = 0.001 + k/100), Imu at 250 Hz, a WrenchStamped per foot at
    200 Hz, every sensor value linear in time (interpolation is then exact)."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    js, imu, wr = (
        T["sensor_msgs/msg/JointState"],
        T["sensor_msgs/msg/Imu"],
        T["geometry_msgs/msg/WrenchStamped"],
    )
    Header, Time, V3, Q = (
        T["std_msgs/msg/Header"],
        T["builtin_interfaces/msg/Time"],
        T["geometry_msgs/msg/Vector3"],
        T["geometry_msgs/msg/Quaternion"],
    )
    Wrench = T["geometry_msgs/msg/Wrench"]

    def header(t: float, frame: str = "") -> object:
        return Header(stamp=Time(sec=int(t), nanosec=round((t % 1) * 1e9)), frame_id=frame)

    names = list(robot.joint_names[1:])
    with Writer(path, version=9) as w:
        cj = w.add_connection("/joint_states", js.__msgtype__, typestore=ts)
        ci = w.add_connection("/imu", imu.__msgtype__, typestore=ts)
        cf = {
            f: w.add_connection(f"/force/{f}", wr.__msgtype__, typestore=ts)
            for f in ("FL_foot", "RR_foot")
        }
        for k in range(250):
            t = k / 250
            if imu_gap and 0.5 < t < 0.6:
                continue
            m = imu(
                header=header(t, "imu_link"),
                orientation=Q(x=0, y=0, z=0, w=1),
                orientation_covariance=np.zeros(9),
                angular_velocity=V3(x=t, y=2 * t, z=-t),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=V3(x=0.1 * t, y=0.0, z=9.81 + t),
                linear_acceleration_covariance=np.zeros(9),
            )
            w.write(ci, int(t * 1e9), ts.serialize_cdr(m, imu.__msgtype__))
        for k in range(200):
            t = k / 200
            for i, (foot, conn) in enumerate(cf.items()):
                m = wr(
                    header=header(t, foot),
                    wrench=Wrench(
                        force=V3(x=1.0, y=0.0, z=50 + 10 * t + i), torque=V3(x=0, y=0, z=0)
                    ),
                )
                w.write(conn, int(t * 1e9), ts.serialize_cdr(m, wr.__msgtype__))
        for k in range(100):
            t = 0.001 + k / 100
            m = js(
                header=header(t),
                name=names,
                position=np.full(len(names), t),
                velocity=np.empty(0),
                effort=np.empty(0),
            )
            w.write(cj, int(t * 1e9), ts.serialize_cdr(m, js.__msgtype__))


def test_bag_imu_and_wrenches_are_interpolated_at_the_joint_stamps(tmp_path, go1) -> None:
    pytest.importorskip("rosbags")
    _write_legged_bag(tmp_path / "bag", go1)
    log = read_log(tmp_path / "bag", go1)
    t = 0.001 + np.arange(100) / 100
    assert len(log) == 100  # one row per JointState message
    np.testing.assert_allclose(log.t, t, atol=1e-9)
    last = 249 / 250  # the IMU's last stamp: the rows after it have no IMU value
    inside = t <= last
    np.testing.assert_allclose(
        log.imu_gyro[inside], np.column_stack([t, 2 * t, -t])[inside], atol=1e-9
    )
    np.testing.assert_allclose(log.imu_acc[inside, 2], 9.81 + t[inside], atol=1e-9)
    assert np.isnan(log.imu_gyro[~inside]).all()
    assert log.feet == ("FL_foot", "RR_foot")
    ok = t <= 199 / 200
    np.testing.assert_allclose(
        log.foot_force[ok], np.column_stack([50 + 10 * t, 51 + 10 * t])[ok], atol=1e-9
    )
    lost = {k for k, text in log.problems if "/imu" in text}
    assert lost == set(np.flatnonzero(~inside))  # every NaN row said, by message number
    assert np.isnan(log.q[:, :7]).all() and np.isfinite(log.q[:, 7:]).all()
    chunks = list(iter_log(tmp_path / "bag", go1, chunk_rows=30))
    np.testing.assert_array_equal(np.concatenate([c.imu_acc for c in chunks]), log.imu_acc)


def test_a_bag_imu_dropout_is_nan_and_said_not_bridged(tmp_path, go1) -> None:
    pytest.importorskip("rosbags")
    _write_legged_bag(tmp_path / "bag", go1, imu_gap=True)
    log = read_log(tmp_path / "bag", go1)
    t = log.t
    gap = (t > 0.5) & (t < 0.6)
    assert gap.sum() == 10 and np.isnan(log.imu_gyro[gap]).all()
    assert np.isfinite(log.imu_gyro[(t < 0.49) | ((t > 0.61) & (t < 0.99))]).all()
    assert {k for k, text in log.problems if "a gap" in text} >= set(np.flatnonzero(gap))


def test_a_free_flyer_bag_without_imu_is_still_refused(tmp_path, go1) -> None:
    pytest.importorskip("rosbags")
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    js = ts.types["sensor_msgs/msg/JointState"]
    with Writer(tmp_path / "bag", version=9) as w:
        w.add_connection("/joint_states", js.__msgtype__, typestore=ts)
    with pytest.raises(DimensionError, match=r"root_joint.*se3.*sensor_msgs/Imu"):
        read_log(tmp_path / "bag", go1)
