"""The log's clock on the command line: estimate (filtered and smoothed) and identify read a
recorded log on its loop's clock and say so once."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import pinobs
from pinobs.cli import main
from pinobs.simulation import Logger, Sensor
from tests.conftest import planar_3r_truth

#: a logger clock without drops: the identification needs no drop handling to use it
LOGGER = Logger(jitter=4e-4, stale=0.06, digits=6)


@pytest.fixture(scope="module")
def planar_recorded(tmp_path_factory):
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    res = pinobs.simulate(
        robot, [], duration=8.0, sensor=Sensor(rate=1000.0, noise_std=1e-5), seed=1, plant=truth
    )
    rec = LOGGER.record(res, 3)
    folder = tmp_path_factory.mktemp("logs")
    path = rec.to_csv(folder / "recorded.csv", robot)
    return path, rec, res, truth


def _velocity_rms(path, rec, res, nv):
    df = pd.read_csv(path)
    v = df[[f"v{i}" for i in range(nv)]].to_numpy()
    late = res.t[rec.tick] > 1.0
    return float(np.sqrt(np.nanmean((v[late] - res.v[rec.tick[late]]) ** 2)))


@pytest.mark.parametrize("smooth", [False, True])
def test_estimate_repairs_the_clock_and_says_so_once(planar_recorded, tmp_path, capsys, smooth):
    log, rec, res, _ = planar_recorded
    extra = ["--smooth"] if smooth else []
    base = ["estimate", "--robot", "planar_3r", "--observer", "kf", "--log", str(log)]
    base += ["--noise", "1e-5", "--no-progress", *extra]
    assert main([*base, "--out", str(tmp_path / "auto.csv")]) == 0
    err = capsys.readouterr().err
    assert err.count("log clock repaired") == 1
    assert f"{int(rec.stale.sum())} stale rows" in err
    assert main([*base, "--clock", "stamps", "--out", str(tmp_path / "stamps.csv")]) == 0
    err = capsys.readouterr().err
    assert "log clock: stamps kept (clock='stamps')" in err
    auto = _velocity_rms(tmp_path / "auto.csv", rec, res, 3)
    stamps = _velocity_rms(tmp_path / "stamps.csv", rec, res, 3)
    assert auto < 0.5 * stamps, (auto, stamps)


@pytest.mark.slow  # 6-8 s on a 2-core machine: the default run stays under 10 min
def test_identify_fits_the_samples_on_the_loop_clock(planar_recorded, tmp_path, capsys):
    log, rec, _, truth = planar_recorded
    out = tmp_path / "auto.urdf"
    args = ["identify", "--robot", "planar_3r", "--log", str(log), "--out", str(out)]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "log clock repaired" in err and f"{int(rec.stale.sum())} stale rows" in err
    nominal, calibrated = pinobs.load("planar_3r"), pinobs.load(out)
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = nominal.random_configuration(rng)
        m = truth.mass_matrix(q)
        err_cal = np.abs(calibrated.mass_matrix(q) - m).max()
        assert err_cal < 0.2 * np.abs(nominal.mass_matrix(q) - m).max()
    # as stamped, the jitter and the stale rows are in the fit (or it is refused)
    stamped = tmp_path / "stamps.urdf"
    code = main([*args[:-1], str(stamped), "--clock", "stamps"])
    err = capsys.readouterr().err
    if code == 0:
        worse = pinobs.load(stamped)
        q = nominal.random_configuration(rng)
        m = truth.mass_matrix(q)
        assert np.abs(worse.mass_matrix(q) - m).max() >= np.abs(calibrated.mass_matrix(q) - m).max()
    else:
        assert "timestamp jitter" in err
