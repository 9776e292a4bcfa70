"""The identified model's own acceleration error as a white-noise density
(:mod:`pinobs.model.identification.model_error`), against known truths, and its sidecar."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import savgol_coeffs

import pinobs
from pinobs.errors import ModelFileError
from pinobs.model.identification.model_error import acceleration_error_psd
from pinobs.model.urdf_writer import write_urdf
from pinobs.simulation import Sensor

RATE = 1000.0


def _log(plant: pinobs.Robot, sigma: float, seed: int):
    robot = pinobs.load("planar_3r")
    res = pinobs.simulate(
        robot, [], duration=4.0, sensor=Sensor(rate=RATE, noise_std=sigma), seed=seed, plant=plant
    )
    return res, (res.t, np.array(res.q_meas), np.array(res.tau))


@pytest.mark.parametrize("seed", [1, 2])
def test_a_payload_the_model_lacks_gives_the_density_of_its_acceleration_error(seed: int) -> None:
    """Truth: planar_3r with 0.5 kg 5 cm out on its last link; model: without it.  Expected:
    ``mean(e²)·h`` of ``e = a_model − a_truth`` at the true states and torques, over the rows
    the measurement uses (all but the fit's half window, 50 rows, at each end; seed 1 with
    the truth of ``planar_3r_truth``: 0.2104 against 0.2101 measured, per joint within
    0.3 %)."""
    robot = pinobs.load("planar_3r")
    truth = robot.perturbed(payload=(0.5, [0.05, 0.0, 0.0]))
    res, log = _log(truth, 1e-5, seed)
    q, v, tau = np.array(res.q), np.array(res.v), log[2]
    e = np.array(
        [
            robot.forward_dynamics(q[k], v[k], tau[k]) - truth.forward_dynamics(q[k], v[k], tau[k])
            for k in range(50, len(res.t) - 50)
        ]
    )
    expected = (e**2).mean(axis=0) / RATE
    psd, per_joint = acceleration_error_psd(robot, log)
    np.testing.assert_allclose(per_joint, expected, rtol=0.03)
    assert psd == pytest.approx(expected.mean(), rel=0.03)


def test_an_exact_model_gives_the_derivative_estimates_own_noise_floor() -> None:
    """Exact model, σ = 1e-4: the Savitzky–Golay acceleration's noise ``σ² Σ c₂² · h``
    (8.4e-6 rad²/s³) plus its smoothing bias (measured 1.07e-5 in all, 1.27× the floor)."""
    robot = pinobs.load("planar_3r")
    sigma = 1e-4
    log = _log(robot, sigma, 1)[1]
    c2 = savgol_coeffs(101, 4, deriv=2, delta=1.0 / RATE)  # half window 0.05 s, degree 4
    floor = sigma**2 * float(np.sum(c2**2)) / RATE
    psd, _ = acceleration_error_psd(robot, log)
    assert 0.9 * floor < psd < 1.5 * floor


def test_pinobs_identify_stores_a_model_error_it_cannot_fit_beyond_the_estimators_floor() -> None:
    """Truth with Coulomb friction, identified without friction (``friction=False``): the
    friction it cannot fit stays, and the stored density is that model's error at the true
    states (``mean(e²)·h``), less the estimator's noise floor."""
    robot = pinobs.load("planar_3r")
    truth = robot.perturbed(coulomb=[0.3, 0.2, 0.1])
    res, log = _log(truth, 1e-5, 1)
    ident = pinobs.identify(robot, log, friction=False, refine=())
    rep = ident.report
    fit = (res.t <= rep["fit_end"]) & (res.t > res.t[1] + 0.05)
    q, v, tau = np.array(res.q)[fit], np.array(res.v)[fit], log[2][fit]
    e = np.array(
        [
            ident.robot.forward_dynamics(q[k], v[k], tau[k] + ident.offset)
            - truth.forward_dynamics(q[k], v[k], tau[k])
            for k in range(len(q))
        ]
    )
    expected = float((e**2).mean()) / RATE
    assert ident.robot.model_error_psd == rep["model_error_psd"]
    assert rep["model_error_psd"] == pytest.approx(expected, rel=0.1)
    assert len(rep["model_error_psd_per_joint"]) == robot.nv
    assert rep["model_error_floor"] < 1e-3 * expected
    assert robot.model_error_psd is None  # the nominal robot keeps none


def test_a_model_identified_down_to_the_estimators_floor_stores_none() -> None:
    """The payload identified (σ = 1e-4): what is left is the Savitzky–Golay estimate's own
    error, about its noise floor ψ₀ (8.4e-6 rad²/s³); not stored, so the observers keep 1e-8."""
    robot = pinobs.load("planar_3r")
    truth = robot.perturbed(payload=(0.5, [0.05, 0.0, 0.0]))
    ident = pinobs.identify(robot, _log(truth, 1e-4, 1)[1], refine=())
    rep = ident.report
    assert rep["model_error_floor"] == pytest.approx(8.4e-6, rel=0.05)
    assert rep["model_error_psd"] <= rep["model_error_floor"]
    assert ident.robot.model_error_psd is None


def test_the_density_survives_copy_pickle_with_inertials_and_a_written_urdf(
    tmp_path: Path,
) -> None:
    robot = pinobs.load("ur5")
    robot.model_error_psd = 3.4e-3
    for other in (
        robot.copy(),
        pickle.loads(pickle.dumps(robot)),
        robot.with_inertials(robot.model.copy()),
        robot.with_model(robot.model.copy()),
    ):
        assert other.model_error_psd == 3.4e-3
    assert robot.perturbed(payload=(1.0, [0.0, 0.0, 0.1])).model_error_psd is None
    path = write_urdf(robot, tmp_path / "ident.urdf")
    sidecar = json.loads((tmp_path / "ident.pinobs.json").read_text())
    assert sidecar["model_error_psd"] == 3.4e-3
    assert pinobs.load(path).model_error_psd == 3.4e-3
    write_urdf(pinobs.load("ur5"), path)  # a robot without one: the stale sidecar removed
    assert not (tmp_path / "ident.pinobs.json").exists()
    assert pinobs.load(path).model_error_psd is None


@pytest.mark.parametrize("bad", [0.0, -1.0, "big", True])
def test_a_sidecar_density_that_is_not_a_positive_number_is_refused(
    bad: object, tmp_path: Path
) -> None:
    robot = pinobs.load("ur5")
    robot.model_error_psd = 1e-3
    path = write_urdf(robot, tmp_path / "ident.urdf")
    side = tmp_path / "ident.pinobs.json"
    data = json.loads(side.read_text())
    data["model_error_psd"] = bad
    side.write_text(json.dumps(data))
    with pytest.raises(ModelFileError, match="model_error_psd"):
        pinobs.load(path)
