""":func:`pinobs.model.identification.solve` on rows fitted to rounding: a noise-free known
truth, whose per-channel residual scales collapse to rounding level, and prior widths many
orders wide; and rows fitted exactly."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.model.identification import MomentumRegressor, leastsquares, solve
from pinobs.model.identification.leastsquares import NORMAL_EQUATIONS_LIMIT


def _rigid_rows(robot: pinobs.Robot, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per sample of a smooth path, pin's joint-torque regressor in :class:`MomentumRegressor`'s
    rigid-body columns (the others zero: not identifiable, held by the prior), and the channels."""
    reg = MomentumRegressor(robot, armature=True, weighting="torque")
    model, data = robot.model, robot.model.createData()
    w = 2 * np.pi * np.array([0.3, 0.5, 0.7])
    q = 0.8 * np.sin(np.outer(t, w) + 0.3)
    v = 0.8 * w * np.cos(np.outer(t, w) + 0.3)
    a = -0.8 * w**2 * np.sin(np.outer(t, w) + 0.3)
    rows = np.zeros((t.size, model.nv, reg.size))
    for k in range(t.size):
        rows[k, :, : reg.n_inertial] = pin.computeJointTorqueRegressor(
            model, data, q[k], v[k], a[k]
        )
    channel = np.tile(np.arange(model.nv), t.size)
    return rows.reshape(-1, reg.size), channel


@pytest.mark.parametrize("consistent", [False, True])
@pytest.mark.parametrize("widen", [1.0, 1e3, 1e6])
def test_noise_free_known_truth_is_fitted_to_rounding_and_predicts_the_held_out_torques(
    widen: float, consistent: bool
) -> None:
    """τ = Y(q, v, a) θ exactly, θ the nominal planar_3r with its links 20 % heavier
    (physically consistent).  Each channel's σ collapses to rounding (~1e-14 N·m): the
    weighted normal equations then had eigenvalues ~1e35–1e41 against the prior's 1.  Measured
    fitted residual [N·m], priors ×1, ×1e3, ×1e6, before the truncated-SVD step of ``solve``:
    8.8e-7, 8.9, 1.5e19 (consistent 8.6e-7, 3.7e6, 6.5); now 9.1e-15, 1.1e-14, 5.4e-15
    (consistent 7.4e-15, 9.9e-15, 5.8e-15)."""
    robot = pinobs.load("planar_3r")
    reg = MomentumRegressor(robot, armature=True, weighting="torque")
    A, channel = _rigid_rows(robot, np.arange(0.0, 6.0, 0.01))
    A_held, _ = _rigid_rows(robot, np.arange(6.0, 8.0, 0.01))
    truth = reg.nominal().copy()
    truth[: reg.n_inertial] *= 1.2
    y = A @ truth
    sol = solve(
        reg, A, y, prior_std=widen * reg.prior_std(), channel=channel, consistent=consistent
    )
    scale = float(np.sqrt(np.mean(y**2)))  # 39 N·m
    assert np.sqrt(np.mean((A @ sol.theta - y) ** 2)) < 1e-10 * scale
    y_held = A_held @ truth
    assert np.sqrt(np.mean((A_held @ sol.theta - y_held) ** 2)) < 1e-10 * scale
    assert np.all(np.isfinite(sol.std)) and np.all(sol.std > 0.0)
    # what the rows do not see keeps the prior's mean (friction, armature, offset), except
    # where consistency's barrier lifts friction and armature off their nominal 0
    if not consistent:
        np.testing.assert_array_equal(sol.theta[reg.n_inertial :], reg.nominal()[reg.n_inertial :])


@pytest.mark.parametrize("channels", [True, False])
def test_rows_fitted_exactly_by_the_prior_mean_keep_it_with_finite_widths(channels: bool) -> None:
    """Every residual exactly 0 (``y = A θ₀``): the rows are weighted alike (σ = 1) instead of
    by 1/0, which made weights of 1e600 and a failed SVD."""
    robot = pinobs.load("planar_3r")
    reg = MomentumRegressor(robot, armature=True, weighting="torque")
    A, channel = _rigid_rows(robot, np.arange(0.0, 2.0, 0.01))
    sol = solve(reg, A, A @ reg.nominal(), channel=channel if channels else None)
    np.testing.assert_array_equal(sol.theta, reg.nominal())
    np.testing.assert_array_equal(sol.channel_sigma, np.ones(3 if channels else 1))
    assert np.all(np.isfinite(sol.std)) and np.all(sol.std <= reg.prior_std())


def test_fewer_noise_free_rows_than_parameters_are_fitted_and_the_rest_keeps_the_prior() -> None:
    """Four samples (12 rows, 42 parameters), noise-free: the truncated-SVD step's V is
    completed to every parameter, the unseen directions keep the prior's width."""
    robot = pinobs.load("planar_3r")
    reg = MomentumRegressor(robot, armature=True, weighting="torque")
    A, channel = _rigid_rows(robot, np.arange(0.0, 0.04, 0.01))
    truth = reg.nominal().copy()
    truth[: reg.n_inertial] *= 1.2
    y = A @ truth
    sol = solve(reg, A, y, prior_std=1e3 * reg.prior_std(), channel=channel)
    assert np.sqrt(np.mean((A @ sol.theta - y) ** 2)) < 1e-10 * np.sqrt(np.mean(y**2))
    assert sol.std.shape == (reg.size,) and np.all(np.isfinite(sol.std))
    assert int(np.sum(sol.excited)) <= A.shape[0]
    np.testing.assert_allclose(sol.std[reg.n_inertial :], 1e3 * reg.prior_std()[reg.n_inertial :])


def test_rows_that_do_not_over_determine_the_fit_keep_the_normal_equations(monkeypatch) -> None:
    """As many rows as their rank are fitted exactly by the first pass, whose residual scale
    (rounding) then puts the weighted step past :data:`NORMAL_EQUATIONS_LIMIT` although it
    says nothing about the noise.  The truncated-SVD step fitted such rows exactly, which
    overfitted: ``adaptive``'s first solve on a UR5 (18 rows, 78 parameters) had masses of
    −0.34 kg and was rejected (0 solves where there had been 1), planar 3R with a payload
    (18 rows, 39 parameters) 64 prior widths from the truth.  They keep the normal
    equations: the solve is the one without the SVD step, to the bit."""
    robot = pinobs.load("planar_3r")
    reg = MomentumRegressor(robot, armature=True, weighting="torque")
    A, channel = _rigid_rows(robot, np.arange(0.0, 0.02, 0.01))  # 2 samples: 6 rows
    assert np.linalg.matrix_rank(A) == A.shape[0] < reg.size
    truth = reg.nominal().copy()
    truth[: reg.n_inertial] *= 1.2
    y = A @ truth + 0.01 * np.random.default_rng(0).standard_normal(A.shape[0])
    # the first pass fits them to rounding: past the limit
    As = A * reg.prior_std()
    u0 = np.linalg.lstsq(As, y - A @ reg.nominal(), rcond=None)[0]
    sigma0 = 1.4826 * np.median(np.abs(As @ u0 - (y - A @ reg.nominal())))
    lam_max = np.linalg.eigvalsh(As.T @ As)[-1] / sigma0**2
    assert np.finfo(float).eps * lam_max > NORMAL_EQUATIONS_LIMIT
    for consistent, chan in ((False, None), (True, channel)):
        sol = solve(reg, A, y, consistent=consistent, channel=chan)
        with monkeypatch.context() as m:
            m.setattr(leastsquares, "NORMAL_EQUATIONS_LIMIT", math.inf)
            ref = solve(reg, A, y, consistent=consistent, channel=chan)
        np.testing.assert_array_equal(sol.theta, ref.theta)
        np.testing.assert_array_equal(sol.std, ref.std)
