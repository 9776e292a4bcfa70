"""Identification with model-based (RTS-smoothed) velocities, against known truths."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pinobs
from pinobs.calibration import identify
from pinobs.observers.noise import estimate_noise_std
from pinobs.simulation import Sensor
from pinobs.smoothing import RHO_WARN
from tests.conftest import planar_3r_truth, torque_error


def _acc_error(model: pinobs.Robot, truth: pinobs.Robot, rng: np.random.Generator) -> float:
    """RMS of the error in ``M(q)⁻¹(τ − h(q, v))`` at random states [rad/s²]."""
    errs = []
    for _ in range(50):
        q, v = truth.random_configuration(rng), rng.normal(size=truth.nv)
        tau = rng.normal(size=truth.nv)
        errs.append(model.forward_dynamics(q, v, tau) - truth.forward_dynamics(q, v, tau))
    return float(np.sqrt(np.mean(np.square(errs))))


@pytest.mark.parametrize("sigma", [1e-5, 1e-4, 1e-3])
def test_estimated_noise_std_matches_the_simulated_sensor(sigma: float) -> None:
    robot = pinobs.load("planar_3r")
    res = pinobs.simulate(
        robot, [], duration=2.0, sensor=Sensor(rate=1000.0, noise_std=sigma), seed=2
    )
    q = np.array(res.q_meas)
    sigma_joint = estimate_noise_std(res.t, q, robot)  # the estimator identify uses
    assert sigma_joint is not None
    assert float(np.median(sigma_joint)) == pytest.approx(sigma, rel=0.1)


def test_smoothed_velocities_identify_closer_to_the_truth_than_savitzky_golay(
    rng: np.random.Generator,
) -> None:
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    res = pinobs.simulate(
        robot, [], duration=4.0, sensor=Sensor(rate=1000.0, noise_std=1e-4), seed=1, plant=truth
    )
    sg = identify(robot, res, refine=())
    refined = identify(robot, res)
    assert sg.report["velocities"] == "savgol"
    assert refined.report["velocities"] == "rts(accel_psd=1e-07)"
    assert refined.report["noise_std"] == pytest.approx(1e-4, rel=0.1)
    assert _acc_error(refined.robot, truth, rng) < 0.5 * _acc_error(sg.robot, truth, rng)
    assert max(refined.report["holdout_after"]) < 0.5 * max(sg.report["holdout_after"])


@pytest.mark.parametrize("seed", [1, 2])
def test_the_refined_fit_recovers_the_armature_and_without_it_predicts_far_worse(
    seed: int,
) -> None:
    """planar_3r's truth with rotors of 0.05, 0.2, 0.1 kg·m² (6 s, σ = 1e-4).  Measured on 8 s
    logs (seeds 1–3): joints 2 and 3 within 1e-4 kg·m², the torque prediction error on a
    fresh trajectory (:func:`~tests.conftest.torque_error`) per joint 2400–10000× lower
    than ``armature=False``'s; joint 1's rotor is one column with link 1's inertia about
    its axis (only their sum, in M, is identifiable)."""
    robot = pinobs.load("planar_3r")
    model = planar_3r_truth(robot).model.copy()
    model.armature = np.array([0.05, 0.2, 0.1])
    truth = robot.with_model(model)
    res = pinobs.simulate(
        robot, [], duration=6.0, sensor=Sensor(rate=1000.0, noise_std=1e-4), seed=seed, plant=truth
    )
    # rows weighted by M⁻¹, as measured (weighting="torque", seed 2: the torque error of
    # joints 1, 2 0.021, 0.034 against armature=False's 0.36, 0.82: 17× and 24×, not 100×)
    ident = identify(robot, res, weighting="inertia")
    without = identify(robot, res, armature=False, weighting="inertia")
    np.testing.assert_allclose(ident.robot.model.armature[1:], [0.2, 0.1], rtol=0.02)
    assert not np.any(without.robot.model.armature)
    np.testing.assert_array_less(
        torque_error(ident.robot, truth), 0.01 * torque_error(without.robot, truth)
    )


def test_refinement_keeps_the_savitzky_golay_velocities_across_a_gap() -> None:
    """A stretch too short to smooth, or a gap of NaN rows, leaves the rest of the log usable."""
    robot = pinobs.load("planar_3r")
    truth = robot.perturbed(inertia_scale=[1.2, 0.8, 1.1])
    res = pinobs.simulate(
        robot, [], duration=4.0, sensor=Sensor(rate=1000.0, noise_std=1e-4), seed=4, plant=truth
    )
    q = np.array(res.q_meas)
    q[1500:1510] = np.nan
    ident = identify(robot, (res.t, q, np.array(res.tau)), friction=False)
    assert ident.report["rows"] > 0 and ident.report["velocities"].startswith("rts")


def test_refine_rejects_a_non_positive_density() -> None:
    robot = pinobs.load("planar_3r")
    t = np.arange(3000) * 1e-3
    with pytest.raises(pinobs.GainError, match="refine"):
        identify(robot, (t, np.zeros((t.size, 3)), np.zeros((t.size, 3))), refine=(0.0,))


def test_report_gives_the_smoothers_consistency_about_one_on_exact_torques_large_on_noisy_ones(
    rng: np.random.Generator,
) -> None:
    """``report["smoother_consistency"]``: the last pass's ρ, the sign that the smoother takes
    noisy torques as exact (module docstring, "Limitation: noisy torques"); NaN unsmoothed."""
    robot = pinobs.load("planar_3r")
    res = pinobs.simulate(
        robot,
        [],
        duration=3.0,
        sensor=Sensor(rate=1000.0, noise_std=1e-4),
        seed=1,
        plant=planar_3r_truth(robot),
    )
    t, q, tau = res.t, np.array(res.q_meas), np.array(res.tau)
    noisy = tau + 0.05 * np.sqrt(np.mean(tau**2, axis=0)) * rng.standard_normal(tau.shape)
    clean_rho = identify(robot, (t, q, tau)).report["smoother_consistency"]
    noisy_rho = identify(robot, (t, q, noisy)).report["smoother_consistency"]
    assert clean_rho < RHO_WARN
    assert noisy_rho > 100.0 * RHO_WARN
    assert math.isnan(identify(robot, (t, q, tau), refine=()).report["smoother_consistency"])
