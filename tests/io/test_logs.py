"""Recorded logs: reading, bad rows, round trips through the CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import pinobs
from pinobs.cli import main
from pinobs.io import estimate_log, read_log, write_log

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "ur5_log.csv"


def _log(tmp_path: Path, *, tau: bool = True, n: int = 300) -> tuple[Path, pinobs.Result]:
    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=n / 1000, sensor=pinobs.Sensor(1000.0, 1e-4), seed=1)
    # row 0 of a simulation has no measurement (NaN): the log starts at the first sample
    path = write_log(tmp_path / "log.csv", res.t[1:], res.q_meas[1:], res.tau[1:] if tau else None)
    return path, res


def test_cli_round_trips_a_ur5_csv_log_with_the_same_row_count(tmp_path: Path, capsys) -> None:
    out = tmp_path / "est.csv"
    assert (
        main(
            [
                "estimate",
                "--robot",
                "ur5",
                "--observer",
                "kf",
                "--log",
                str(EXAMPLE),
                "--out",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    est = np.genfromtxt(out, delimiter=",", names=True)
    log = np.genfromtxt(EXAMPLE, delimiter=",", names=True)
    assert est.size == log.size
    assert est.dtype.names == ("t", *(f"q{i}" for i in range(6)), *(f"v{i}" for i in range(6)))
    np.testing.assert_array_equal(est["t"], log["t"])
    assert (
        "200 rows: 200 estimated (200 with their measurement, 0 propagated only), 0 without an estimate; 0 rows reported"
        in capsys.readouterr().out
    )


def test_estimates_from_a_log_match_the_live_loop(tmp_path: Path) -> None:
    path, res = _log(tmp_path)
    robot = pinobs.load("ur5")
    run = estimate_log(pinobs.make_observer("kf", robot, noise_std=1e-4), read_log(path, robot))
    live = pinobs.make_observer("kf", robot, noise_std=1e-4)
    est = live.reset(res.t[1], res.q_meas[1], None, res.tau[1])
    for k in range(2, 51):
        est = live.update(res.t[k], res.q_meas[k], res.tau[k])
    np.testing.assert_allclose(run.v[49], est.v, rtol=1e-12, atol=1e-12)


def test_bad_rows_are_reported_and_the_rest_is_processed(tmp_path: Path) -> None:
    path, _ = _log(tmp_path, n=100)
    lines = path.read_text().splitlines()
    lines[10] = lines[10].replace(lines[10].split(",")[2], "abc", 1)  # unreadable q1 (line 11)
    cells = lines[20].split(",")
    cells[1] = "nan"  # non-finite q0 (line 21)
    lines[20] = ",".join(cells)
    cells = lines[30].split(",")
    cells[0] = lines[29].split(",")[0]  # duplicated timestamp (line 31)
    lines[30] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    robot = pinobs.load("ur5")
    run = estimate_log(pinobs.make_observer("kf", robot, noise_std=1e-4), read_log(path, robot))
    bad = dict(run.bad_rows)
    assert set(bad) == {11, 21, 31}
    assert "'q1' unreadable" in bad[11]
    assert "non-finite" in bad[21] and "dropped sample" in bad[21]
    assert "not after the previous sample" in bad[31]
    assert run.v.shape == (100, 6)
    finite_rows = np.isfinite(run.v[:, 0])
    assert finite_rows.sum() == 99  # only the duplicated-time row has no estimate
    assert not finite_rows[31 - 2]


def test_log_without_torques_warns_model_based_observers_only(tmp_path: Path) -> None:
    path, _ = _log(tmp_path, tau=False, n=50)
    robot = pinobs.load("ur5")
    log = read_log(path, robot)
    assert log.tau is None
    assert estimate_log(pinobs.make_observer("kf", robot), log).warnings == []
    model_based = [
        n for n in pinobs.observer_names() if pinobs.observers.observer_class(n).uses_torque
    ]
    for name in model_based:
        try:
            ob = pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4)
        except pinobs.UnsupportedRobotError:
            continue
        warnings = estimate_log(ob, log).warnings
        assert warnings and "no torque columns" in warnings[0]
    # blended never behind kf (pinobs.estimate's default on a log), the warning names the
    # observer asked for, not the blend ("'never_behind' uses the model's dynamics" before)
    blend = pinobs.make_observer("ekf", robot, rate=1000.0, noise_std=1e-4, never_behind=True)
    warnings = estimate_log(blend, log).warnings
    assert "no torque columns: 'ekf' (blended never behind kf) uses" in warnings[0]


def test_npz_log_is_read_like_csv(tmp_path: Path) -> None:
    path, _ = _log(tmp_path, n=40)
    robot = pinobs.load("ur5")
    csv_log = read_log(path, robot)
    np.savez(tmp_path / "log.npz", t=csv_log.t, q=csv_log.q, tau=csv_log.tau)
    npz_log = read_log(tmp_path / "log.npz", robot)
    np.testing.assert_array_equal(npz_log.q, csv_log.q)
    np.testing.assert_array_equal(npz_log.tau, csv_log.tau)


def test_a_saved_run_is_read_as_what_its_sensor_measured(tmp_path: Path) -> None:
    """``pinobs run --save`` writes the truth ``q`` and the measurements ``q_meas``; read as a
    log it is the measurements (row 0, never measured, a dropped sample), not the truth an
    observer would then track perfectly (ρ ≈ 1e-20 from the smoother before this was fixed)."""
    _, res = _log(tmp_path, n=40)
    path = res.save(tmp_path / "run.npz")
    log = read_log(path, pinobs.load("ur5"))
    np.testing.assert_array_equal(log.q, res.q_meas)
    assert np.isnan(log.q[0]).all() and not np.array_equal(log.q[1:], res.q[1:])
    np.testing.assert_array_equal(log.tau, res.tau)


def test_log_columns_that_do_not_fit_the_robot_are_rejected(tmp_path: Path) -> None:
    path, _ = _log(tmp_path, n=10)
    with pytest.raises(pinobs.DimensionError, match=r"lack \['q6 or q.panda_joint7'"):
        read_log(path, pinobs.load("panda"))
    with pytest.raises(pinobs.ModelFileError, match="does not exist") as info:
        read_log(tmp_path / "missing.csv", pinobs.load("ur5"))
    assert isinstance(info.value, FileNotFoundError)
    np.savez(tmp_path / "bad.npz", t=np.zeros(3), q=np.zeros((3, 5)))
    with pytest.raises(pinobs.DimensionError, match=r"needs q of shape \(N, 6\)"):
        read_log(tmp_path / "bad.npz", pinobs.load("ur5"))


def test_cli_round_trips_a_ur5_csv_log_with_the_riemannian_observer(tmp_path: Path, capsys) -> None:
    path, res = _log(tmp_path, n=400)
    out = tmp_path / "est.csv"
    args = [
        "estimate",
        "--robot",
        "ur5",
        "--observer",
        "riemannian",
        "--log",
        str(path),
        "--out",
        str(out),
    ]
    assert main([*args, "--noise", "1e-4", "--no-progress"]) == 0
    est = np.genfromtxt(out, delimiter=",", names=True)
    assert est.size == 400
    v_hat = np.column_stack([est[f"v{i}"] for i in range(6)])
    # the log starts at the truth's configuration at rest; after 0.2 s the estimate has converged
    err = np.abs(v_hat[200:] - res.v[201:]).max()
    assert err < 5e-3  # measured 3e-4 rad/s
    assert (
        "400 rows: 400 estimated (400 with their measurement, 0 propagated only), 0 without an estimate; 0 rows reported"
        in capsys.readouterr().out
    )


def test_cli_estimate_writes_a_playback_of_the_log(tmp_path: Path, capsys) -> None:
    path, _ = _log(tmp_path, n=60)
    out, html = tmp_path / "est.csv", tmp_path / "play.html"
    args = ["estimate", "--robot", "ur5", "--observer", "kf", "--log", str(path)]
    assert main([*args, "--out", str(out), "--html", str(html), "--no-progress"]) == 0
    assert html.stat().st_size > 10_000 and "wrote" in capsys.readouterr().out
    assert len(np.genfromtxt(out, delimiter=",", names=True)) == 60


def _seven_joint_panda_log(tmp_path: Path) -> tuple[Path, pinobs.Result]:
    """A Franka arm log without its fingers: a run of the panda with them locked."""
    arm = pinobs.load("panda", lock=["panda_finger_joint1", "panda_finger_joint2"])
    res = pinobs.simulate(arm, [], duration=0.3, sensor=pinobs.Sensor(1000.0, 1e-4), seed=3)
    path = write_log(tmp_path / "franka.csv", res.t[1:], res.q_meas[1:], res.tau[1:], digits=12)
    return path, res


def test_a_log_lacking_the_fingers_names_lock_as_the_fix_and_reads_with_it(tmp_path: Path) -> None:
    path, res = _seven_joint_panda_log(tmp_path)
    fingers = ["panda_finger_joint1", "panda_finger_joint2"]
    with pytest.raises(pinobs.DimensionError, match=r"lack \['q7 or q.panda_finger_joint1'") as e:
        read_log(path, pinobs.load("panda"))
    text = str(e.value)
    assert (
        f"lock={fingers}" in text
        and "--lock panda_finger_joint1 --lock panda_finger_joint2" in text
    )
    log = read_log(path, pinobs.load("panda", lock=fingers))  # what it says to do
    np.testing.assert_allclose(log.q, res.q_meas[1:], atol=1e-11)
    # a saved run (NPZ: no column names) of the locked arm says the same
    npz = res.save(tmp_path / "run.npz")
    with pytest.raises(pinobs.DimensionError, match=r"--lock panda_finger_joint1 --lock panda"):
        read_log(npz, pinobs.load("panda"))
    # a log without q columns at all (another robot's) is not told to lock every joint
    bare = tmp_path / "t_only.csv"
    bare.write_text("t,x\n0,1\n0.001,2\n")
    with pytest.raises(pinobs.DimensionError, match="lack") as e:
        read_log(bare, pinobs.load("panda"))
    assert "lock" not in str(e.value)


def test_a_log_of_an_arm_without_its_hand_is_told_to_lock_the_hand_by_one_pattern(
    tmp_path: Path,
) -> None:
    """TIAGo's arm log (torso and arm, no hand, head or wheels): the message gives one
    pattern for the hand's 36 joints, the others by name, and reads with what it says."""
    full = pinobs.load("tiago")
    told = ["hand_*", "head_1_joint", "head_2_joint", "wheel_left_joint", "wheel_right_joint"]
    arm = pinobs.load("tiago", lock=told)
    assert list(arm.joint_names) == ["torso_lift_joint"] + [f"arm_{i}_joint" for i in range(1, 8)]
    q = np.full((3, arm.nq), 0.1)
    path = write_log(tmp_path / "tiago_arm.csv", np.arange(3) * 0.01, q, None, digits=12)
    with pytest.raises(pinobs.DimensionError, match="lack") as e:
        read_log(path, full)
    text = str(e.value)
    assert f"lock={told}" in text, text
    assert "--lock 'hand_*' --lock head_1_joint --lock head_2_joint" in text
    assert text.count("hand_thumb_joint") == 1  # named once, in what the log lacks
    np.testing.assert_array_equal(read_log(path, arm).q, q)
