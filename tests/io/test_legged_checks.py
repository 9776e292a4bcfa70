"""A legged log's IMU frame and contacts against the model (issue 38, bad input)."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

import pinobs
from pinobs.io import legged_checks, read_log
from pinobs.io.legged_run import legged_run


@pytest.fixture(scope="module")
def trot() -> pd.DataFrame:
    pytest.importorskip("mujoco")
    from pinobs.simulation.legged import simulate_legged

    run = simulate_legged("trot", 2.0, seed=3)
    return pd.DataFrame(
        {k: v for k, v in run.columns.items() if not k.startswith(("truth.", "contact."))}
    )


def _run(frame: pd.DataFrame, robot: pinobs.Robot, monkeypatch: pytest.MonkeyPatch):
    """``legged_run`` over ``frame``: its warnings and the angle the frame check measured."""
    seen: list[float] = []
    angle = legged_checks._angle

    def spy(a: np.ndarray, b: np.ndarray) -> float:
        seen.append(angle(a, b))
        return seen[-1]

    monkeypatch.setattr(legged_checks, "_angle", spy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (the reader's notes: the base pose not in the log)
        run = legged_run(robot, read_log(frame, robot)).run
    return run.warnings, seen


def _frame_notes(said: list[str]) -> list[str]:
    return [w for w in said if "the IMU's axes" in w]


def test_the_simulated_trots_imu_agrees_with_its_legs(trot, monkeypatch) -> None:
    """MuJoCo go1 trot (2 s, seed 3): the accelerometer's up 13-14° from the legs' (measured:
    go1's IMU ahead of the feet's centroid), far below the 45° the check says from."""
    said, seen = _run(trot, pinobs.load("go1"), monkeypatch)
    assert len(seen) == 1 and 5.0 < seen[0] < 25.0, seen
    assert not _frame_notes(said)
    assert not [w for w in said if "no foot is in contact" in w]


def test_an_imu_with_its_axes_swapped_is_named(trot, monkeypatch) -> None:
    """x and z of the accelerometer and the gyro swapped: ~90° off, said with the frame."""
    bad = trot.copy()
    for s in ("imu.acc.", "imu.gyro."):
        bad[s + "x"], bad[s + "z"] = trot[s + "z"], trot[s + "x"]
    said, seen = _run(bad, pinobs.load("go1"), monkeypatch)
    assert seen[0] > 75.0, seen
    (note,) = _frame_notes(said)
    assert "'imu_link'" in note and f"{seen[0]:.0f}°" in note


def test_an_upside_down_imu_is_named(trot, monkeypatch) -> None:
    bad = trot.copy()
    for c in ("imu.acc.y", "imu.acc.z", "imu.gyro.y", "imu.gyro.z"):  # (x kept: a rotation)
        bad[c] = -trot[c]
    said, seen = _run(bad, pinobs.load("go1"), monkeypatch)
    assert seen[0] > 150.0, seen
    assert len(_frame_notes(said)) == 1


def test_contacts_never_set_are_named_with_the_forces_peak(trot, monkeypatch) -> None:
    light = trot.copy()
    force = [c for c in trot.columns if c.startswith("force.")]
    light[force] = trot[force] * 1e-3  # (forces in kN read as N: below every threshold)
    said, seen = _run(light, pinobs.load("go1"), monkeypatch)
    (note,) = [w for w in said if "no foot is in contact on any row" in w]
    peak = float(np.nanmax(light[force].to_numpy()))
    assert f"{peak:.4g} N" in note and "--contact-force" in note
    assert not seen  # (no row with a foot down: nothing to check the frame against)


def test_the_real_go1_logs_imu_agrees_with_its_legs(monkeypatch) -> None:
    """SEROW's Go1 log as recorded: 15.5° (measured), no note."""
    from tests.io.test_legged_columns import serow_go1_csv, serow_go1_frame

    said, seen = _run(serow_go1_frame(serow_go1_csv()), pinobs.load("go1"), monkeypatch)
    assert len(seen) == 1 and seen[0] < 25.0, seen
    assert not _frame_notes(said)


def test_the_cli_says_the_readers_unit_warning_once(tmp_path, trot, capsys) -> None:
    """An accelerometer in g: the reader's warning printed once (it was twice: the warning
    and the log's note)."""
    from pinobs.cli import main

    g = trot.copy()
    for a in "xyz":
        g[f"imu.acc.{a}"] = trot[f"imu.acc.{a}"] / 9.80665
    path = tmp_path / "g.csv"
    g.to_csv(path, index=False)
    rc = main(
        ["estimate", "--robot", "go1", "--observer", "inekf", "--log", str(path),
         "--out", str(tmp_path / "est.csv")]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 0
    assert err.count("looks like it reads in g") == 1, err
