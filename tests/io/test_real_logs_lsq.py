"""``benchmarks/real_logs.py``'s reference fits of pinobs's own columns at each sample
(``pinobs_columns``, ``lsq_pinobs_columns``) on torques made by RNEA from a known,
physically consistent model, plus noise: the columns are checked against the closed-form dynamics, not
against themselves."""

from __future__ import annotations

from types import ModuleType

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from tests.io.test_real_data import bench_module, needs_data

VS = 0.01  # [rad/s] the URDF friction law's smoothing velocity (pinobs's default)
NOISE = 0.01  # [N·m] the torques' measurement noise (standard deviation)


def _real_logs() -> ModuleType:
    return bench_module("real_logs")


def _known(robot: pinobs.Robot):
    """A smooth trajectory and ``τ = RNEA(q, v, a) + I_a a + F_v v + F_c tanh(v/VS) − b``
    with fixed positive ``I_a``, ``F_v``, ``F_c`` and any-sign ``b``."""
    model = robot.model
    n = model.nv
    t = np.arange(0.0, 8.0, 0.01)
    w = 2 * np.pi * np.array([0.3, 0.5, 0.7])[:n]
    q = 0.8 * np.sin(np.outer(t, w) + 0.3)
    v = 0.8 * w * np.cos(np.outer(t, w) + 0.3)
    a = -0.8 * w**2 * np.sin(np.outer(t, w) + 0.3)
    arm, fv, fc, b = (
        0.05 * np.ones(n),
        0.3 * np.ones(n),
        0.2 * np.ones(n),
        np.array([0.1, -0.2, 0.05])[:n],
    )
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], v[k], a[k]) for k in range(len(t))])
    tau += arm * a + fv * v + fc * np.tanh(v / VS) - b
    return t, q, v, a, tau


@pytest.mark.parametrize(("prior", "consistent"), [(None, False), (1e3, False), (1e3, True)])
def test_lsq_pinobs_columns_recover_the_torques_of_a_known_consistent_model(prior, consistent):
    rl = _real_logs()
    robot = pinobs.load("planar_3r")
    t, q, v, a, tau = _known(robot)
    reg, C, known = rl.pinobs_columns(robot, (), q, v, a)
    fit = t <= 6.0
    # noise: pinobs's solve weighs each channel by its residual's median, which a noise-free
    # fit drives to rounding
    noisy = tau + NOISE * np.random.default_rng(0).standard_normal(tau.shape)
    pred, theta = rl.lsq_pinobs_columns(
        reg, C, known, noisy, fit, list(range(robot.nv)), prior=prior, consistent=consistent
    )
    # the held-out end against the noise-free torques: the fit averages the noise down to
    # about NOISE·√(parameters/rows) ≈ 0.15 NOISE here (42 parameters, 3 × 601 rows)
    assert np.sqrt(np.mean((pred - tau)[~fit] ** 2)) < 0.5 * NOISE
    if consistent:
        assert rl.inconsistent(reg, theta) == []


def test_inconsistent_names_a_negative_rotor_inertia_and_a_negative_mass():
    rl = _real_logs()
    robot = pinobs.load("planar_3r")
    reg, _, _ = rl.pinobs_columns(robot, (), *np.zeros((3, 2, robot.nv)))
    theta = reg.nominal().copy()
    assert rl.inconsistent(reg, theta) == []
    theta[0] = -1.0  # the first body's mass
    theta[reg.armature_slice.start] = -0.1
    said = rl.inconsistent(reg, theta)
    assert len(said) == 2 and "mass -1" in said[0] and "armature" in said[1]


@pytest.mark.parametrize("prior", [1.0, 1e3, 1e6])
def test_lsq_pinobs_columns_fit_noise_free_torques_to_rounding_with_wide_priors(prior):
    """Noise-free: each channel's σ is at rounding level; the wide-prior fits returned fitted
    residuals of 5.5e-11 (×1), 6.4e4 (×1e3) and 1.1e10 N·m (×1e6) before ``solve`` took its
    weighted step by a truncated SVD there; now 6.5e-15 to 8.9e-15 N·m (measured)."""
    rl = _real_logs()
    robot = pinobs.load("planar_3r")
    t, q, v, a, tau = _known(robot)
    reg, C, known = rl.pinobs_columns(robot, (), q, v, a)
    fit = t <= 6.0
    pred, _ = rl.lsq_pinobs_columns(
        reg, C, known, tau, fit, list(range(robot.nv)), prior=prior, consistent=False
    )
    scale = np.sqrt(np.mean(tau**2))
    assert np.sqrt(np.mean((pred - tau)[fit] ** 2)) < 1e-10 * scale
    assert np.sqrt(np.mean((pred - tau)[~fit] ** 2)) < 1e-10 * scale


@needs_data
@pytest.mark.parametrize("consistent", [False, True])
def test_tiago_reference_fit_with_prior_widths_times_1e6_fits_as_well_as_times_1e3(consistent):
    """TIAGo's reference fit (``tiago_lsq``'s rows: torso and arm_1..4, first 80 % of the
    log's time) with the prior ×1e6: its fitted residual was 1.4–124 N·m per channel (2.4–162
    consistent) against 0.71–2.36 at ×1e3, ``solve``'s normal equations having lost the prior
    to rounding; measured now within 0.3 % of ×1e3's on every channel, and consistent."""
    rl = _real_logs()
    log, _, _, t, q, tau = rl.tiago_rows()
    robot = log.robot
    exclude = list(rl.rd.TIAGO_JOINTS[5:])
    _, v, a = rl.sg_fit(t, q)
    fitted = np.zeros(len(t), bool)
    fitted[rl.SG_WINDOW // 2 : len(t) - rl.SG_WINDOW // 2] = True
    fitted &= t <= t[0] + 0.8 * (t[-1] - t[0])
    reg, C, known = rl.pinobs_columns(robot, exclude, q, v, a)
    model = robot.model
    channels = [model.joints[model.getJointId(j)].idx_v for j in rl.TIAGO_TORQUE_JOINTS]
    res = {}
    for prior in (1e3, 1e6):
        pred, theta = rl.lsq_pinobs_columns(
            reg, C, known, tau, fitted, channels, prior=prior, consistent=consistent
        )
        res[prior] = rl.rms((pred - tau)[fitted])[channels]
    assert np.all(res[1e6] < 1.02 * res[1e3]), (res[1e6], res[1e3])
    if consistent:
        assert rl.inconsistent(reg, theta) == []
