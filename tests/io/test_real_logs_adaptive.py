"""``adaptive`` on the UR10e logs of ``benchmarks/real_logs.py`` (skipped without
``../shared/data``): its own blend keeps it near the model-free ``kf`` (issue 36)."""

from __future__ import annotations

import warnings

import pytest

import pinobs
from tests.io.test_real_data import bench_module, needs_data


@needs_data
@pytest.mark.parametrize("name", ["ur-19_09_27-15_11_06", "ur-19_10_01-14_04_41"])
def test_adaptive_stays_near_kf_on_the_ur10e_logs_it_fell_behind_on(name: str) -> None:
    """As ``benchmarks/real_logs.py`` runs it (σ from the log, RMS from 1 s after the start
    against the robot's own velocity): its model-based filter, lost every 2-4 steps, gated
    the samples of the blend's ``kf`` bank, 3.4x and 4.1x the ``kf``'s RMS there
    (0.0361 and 0.0215 rad/s).  Measured since: 0.99x and 0.92x (0.0104, 0.0048)."""
    rl = bench_module("real_logs")
    log = rl.rd.load_log(f"ur10e/identification_data/{name}")
    robot = rl.rd.ur10e_robot()
    t, _, _ = rl.arrays(log.frame)
    rows = t >= t[0] + rl.SETTLE
    rms = {}
    for observer in ("kf", "adaptive"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the log's clock, the nominal model's NIS
            df = pinobs.estimate(observer, log.frame, robot=robot)
        v = df[[f"v{i}" for i in range(robot.nv)]].to_numpy()
        rms[observer] = float(rl.rms((v - log.velocity)[rows].ravel()))
    assert rms["adaptive"] <= 1.2 * rms["kf"]  # issue 36's bound
