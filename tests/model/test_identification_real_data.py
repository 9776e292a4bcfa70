"""Payload identification on the UR10e's recorded logs (Mamedov et al. 2020): skipped without
``../shared/data``; slow (a calibration, then the payload)."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

import pinobs
from pinobs.model.identification import pseudo_inertia
from tests.io.test_real_data import bench_module, needs_data, real_data

#: The load of their ``estimate_drive_gains.m`` [kg], and the rows (1-based, inclusive, of the
#: raw CSV) it keeps of the unloaded and loaded runs of the same trajectory.
LOAD_KG = 2.805
UNLOADED = ("ur-20_02_19_14harm50sec", 195, 4966)
LOADED = ("ur-20_02_19_14harm50secLoad", 308, 5071)


def _trimmed(name: str, first: int, last: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, q, tau)`` of the rows ``first..last`` of the raw file, less the rows that repeat
    the previous position exactly (the logger's stale reads)."""
    root = real_data.data_root()
    raw = root / "ur10e" / "dataset_ur10e" / "identification_data" / f"{name}.csv"
    stamps = pd.read_csv(raw, header=None, usecols=[0]).to_numpy()[:, 0]
    frame = real_data.load_log(f"ur10e/identification_data/{name}").frame
    t = frame["t"].to_numpy(float)
    q = frame[[c for c in frame.columns if c.startswith("q.")]].to_numpy(float)
    tau = frame[[c for c in frame.columns if c.startswith("tau.")]].to_numpy(float)
    keep = (t >= stamps[first - 1]) & (t <= stamps[last - 1])
    keep[1:] &= ~(q[1:] == q[:-1]).all(axis=1)
    return t[keep] - t[keep][0], q[keep], tau[keep]


@pytest.fixture(scope="module")
def payload() -> pinobs.Identification:
    """The load identified on tool0 of the model pinobs identifies on the unloaded run."""
    robot = real_data.ur10e_robot()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fits' warnings on real data: not this test's
        calibrated = pinobs.identify(robot, _trimmed(*UNLOADED), holdout=0.0).robot
        return pinobs.identify(calibrated, _trimmed(*LOADED), payload="tool0")


@needs_data
@pytest.mark.slow
def test_ur10e_payload_is_consistent_and_explains_the_loaded_torques(payload) -> None:
    assert np.linalg.eigvalsh(pseudo_inertia(payload.parameters.values))[0] >= -1e-9
    rep = payload.report
    before, after = rep["holdout_torque_before"], rep["holdout_torque_after"]
    # the shoulder lift and elbow carry the load's weight: the fit explains most of it
    assert after[1] < 0.3 * before[1] and after[2] < 0.3 * before[2]
    assert rep["payload"]["mass"] == pytest.approx(LOAD_KG, rel=0.15)


@needs_data
@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="measured 2.59 kg (−7.8 %; 2.52 before the two-stage weighting): the torques are "
    "drvGains × current with the published gains, and the model-free difference of the loaded and unloaded runs' torques along the "
    "same trajectory gives 2.47 kg: the torque scale, not the fit (issue 36, drives)",
)
def test_ur10e_payload_mass_is_within_five_percent(payload) -> None:
    assert payload.report["payload"]["mass"] == pytest.approx(LOAD_KG, rel=0.05)


@needs_data
@pytest.mark.slow
@pytest.mark.parametrize(("fit", "held"), [("14harm", "15harm"), ("15harm", "14harm")])
def test_ur10e_payload_is_within_five_percent_with_gains_identified_on_the_other_pair(
    fit: str, held: str
) -> None:
    """Drive gains identified on one unloaded/loaded pair (2.805 kg known), the load then
    identified on the other pair with them (``benchmarks/drive_gains.py``): measured 2.688 kg
    (−4.2 %) on 15harm and 2.867 kg (+2.2 %) on 14harm, against 2.155 and 2.585 kg with the
    published gains."""
    bench = bench_module("drive_gains")
    robot = real_data.ur10e_robot()
    gains = np.array(bench.gains_on(robot, fit)["gains"])
    assert bench.payload_on(robot, held, gains)["mass"] == pytest.approx(LOAD_KG, rel=0.05)


@needs_data
def test_tiago_noise_is_measured_where_its_joints_move_not_at_rest() -> None:
    """TIAGo's torso and arm_1..4 are still in the log's first second (third differences
    1e-18 there): σ was their rounding step; their moving rows say more."""
    from pinobs.calibration import _noise_std
    from pinobs.observers.noise import noise_from_log, quantisation_std

    log = real_data.tiago_log()
    frame = log.frame
    t = frame["t"].to_numpy(float)
    q = frame[[c for c in frame.columns if c.startswith("q.")]].to_numpy(float)
    first = noise_from_log(t, q, log.robot, floor=1e-9)
    assert first is not None
    sigma = _noise_std(log.robot, t, q)
    assert sigma > 2.0 * first[0]
    assert sigma > float(np.median(quantisation_std(q, log.robot)))
