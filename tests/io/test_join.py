"""Tables of one clock joined on t (pinobs.io.join_tables, ``--join``): a JointState exported
as position and effort tables reads as the one table it was."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import pinobs
from pinobs.cli import main
from pinobs.io import join_tables, read_log


def _split(tmp_path: Path, n: int = 400) -> tuple[Path, Path, pd.DataFrame]:
    """A UR5 log written whole and as a position table and an effort table (TIAGo's export:
    ``t`` then one column per joint in each)."""
    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], sensor=pinobs.Sensor(1000.0, 1e-4), inputs="pd",
                          duration=n / 1000, seed=2)  # fmt: skip
    names = robot.joint_names
    whole = pd.DataFrame(
        {
            "t": res.t[1:],
            **{f"q.{j}": res.q_meas[1:, i] for i, j in enumerate(names)},
            **{f"tau.{j}": res.tau[1:, i] for i, j in enumerate(names)},
        }
    )
    pos, eff = tmp_path / "position.csv", tmp_path / "effort.csv"
    whole[["t", *(f"q.{j}" for j in names)]].to_csv(pos, index=False, float_format="%.17g")
    whole[["t", *(f"tau.{j}" for j in names)]].to_csv(eff, index=False, float_format="%.17g")
    return pos, eff, whole


def test_joined_tables_are_the_log_written_whole(tmp_path: Path) -> None:
    pos, eff, whole = _split(tmp_path)
    joined = join_tables([pos, eff])
    assert list(joined.columns) == list(whole.columns)
    np.testing.assert_array_equal(joined.to_numpy(), whole.to_numpy())
    robot = pinobs.load("ur5")
    a, b = read_log(joined, robot), read_log(whole, robot)
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.tau, b.tau)


def test_estimate_with_join_writes_what_the_whole_log_gives(tmp_path: Path, capsys) -> None:
    pos, eff, whole = _split(tmp_path)
    path = tmp_path / "whole.csv"
    whole.to_csv(path, index=False, float_format="%.17g")
    base = ["estimate", "--robot", "ur5", "--observer", "ekf", "--noise", "1e-4"]
    base += ["--no-progress", "--clock", "stamps"]
    assert main([*base, "--log", str(path), "--out", str(tmp_path / "a.csv")]) == 0
    argv = ["--log", str(pos), "--join", str(eff), "--out", str(tmp_path / "b.csv")]
    assert main([*base, *argv]) == 0
    a = np.loadtxt(tmp_path / "a.csv", delimiter=",", skiprows=1)
    b = np.loadtxt(tmp_path / "b.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(a, b)
    assert "no torque columns" not in capsys.readouterr().err


def test_tables_of_other_stamps_or_columns_twice_or_no_t_are_refused(tmp_path: Path) -> None:
    pos, eff, _ = _split(tmp_path, n=50)
    shifted = pd.read_csv(eff)
    shifted.loc[7, "t"] += 1e-3
    other = tmp_path / "shifted.csv"
    shifted.to_csv(other, index=False, float_format="%.17g")
    with pytest.raises(pinobs.DimensionError, match=r"t differs .* at row 8 .*1 rows differ"):
        join_tables([pos, other])
    short = tmp_path / "short.csv"
    pd.read_csv(eff).iloc[:-1].to_csv(short, index=False)
    with pytest.raises(pinobs.DimensionError, match=r"has 49 rows and .* 50"):
        join_tables([pos, short])
    with pytest.raises(pinobs.DimensionError, match=r"columns \['q.shoulder_pan_joint'"):
        join_tables([pos, pos])
    bare = tmp_path / "bare.csv"
    pd.read_csv(eff).drop(columns="t").to_csv(bare, index=False)
    with pytest.raises(pinobs.LogFormatError, match="no t column to join on"):
        join_tables([pos, bare])
    with pytest.raises(pinobs.ModelFileError, match="does not exist"):
        join_tables([pos, tmp_path / "missing.csv"])
