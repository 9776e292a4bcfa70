"""The model-free baselines: backward difference + low-pass (`fd`) and per-joint Kalman (`kf`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pinobs
from pinobs.observers.fd import default_cutoff
from pinobs.observers.kf import transition


def _ramp(robot, ob, v: np.ndarray, n: int = 400, h: float = 1e-3) -> pinobs.Estimate:
    q0 = robot.neutral()
    ob.reset(0.0, q0)
    est = ob.estimate
    for k in range(1, n):
        est = ob.update(k * h, robot.integrate(q0, k * h * v))
    return est


@pytest.mark.parametrize("robot_name", ["ur5", "top", "rigid_body"])
@pytest.mark.parametrize("name", ["fd", "kf"])
def test_baselines_recover_a_constant_velocity_exactly_on_every_joint_group(
    robot_name: str, name: str
) -> None:
    robot = pinobs.load(robot_name)
    v = np.linspace(-1.0, 1.0, robot.nv)
    est = _ramp(robot, pinobs.make_observer(name, robot, rate=1000.0), v, n=2000)
    np.testing.assert_allclose(est.v, v, atol=1e-6)


def test_fd_without_filter_is_the_backward_difference() -> None:
    robot = pinobs.load("pendulum")
    ob = pinobs.make_observer("fd", robot, cutoff=1e9)
    ob.reset(0.0, np.array([0.0]))
    ob.update(0.01, np.array([0.02]))
    est = ob.update(0.02, np.array([0.05]))
    np.testing.assert_allclose(est.v, [3.0], rtol=1e-12)


def test_fd_default_cutoff_balances_noise_and_lag() -> None:
    rate, sigma, accel = 1000.0, 1e-4, 10.0
    fc = default_cutoff(rate, sigma, accel)
    h = 1 / rate

    def total(f: float) -> float:  # the error model the rule minimises
        return 2 * math.pi * sigma**2 * f / h + (accel / (2 * math.pi * f)) ** 2

    assert total(fc) <= min(total(0.8 * fc), total(1.25 * fc))
    assert default_cutoff(rate, 0.0, accel) == rate / 2


def test_fd_rejects_a_non_positive_cutoff() -> None:
    with pytest.raises(pinobs.GainError, match="cutoff=-1"):
        pinobs.make_observer("fd", pinobs.load("pendulum"), cutoff=-1.0)


def test_kf_transition_matches_the_integrated_white_jerk_model() -> None:
    h, j = 0.01, 3.0
    F, Q = transition(h, j)
    # Q = ∫₀ʰ e^{As} B Bᵀ e^{Aᵀs} ds j, by quadrature
    s = np.linspace(0, h, 2001)
    g = np.stack([np.array([u**2 / 2, u, 1.0]) for u in s])
    Qn = j * np.trapezoid(g[:, :, None] * g[:, None, :], s, axis=0)
    np.testing.assert_allclose(Q, Qn, rtol=1e-6)
    np.testing.assert_allclose(
        F @ np.array([1.0, 2.0, 3.0]), [1 + 2 * h + 1.5 * h * h, 2 + 3 * h, 3.0]
    )


def test_kf_beats_fd_on_noisy_positions() -> None:
    robot = pinobs.load("ur5")
    res = pinobs.simulate(
        robot, ["fd", "kf"], duration=2.0, sensor=pinobs.Sensor(1000.0, 1e-4), seed=3
    )
    m = {x.observer: x for x in pinobs.evaluate(res, robot)}
    assert m["kf"].rms_v_error < m["fd"].rms_v_error


@pytest.mark.parametrize("jerk_psd", [1e3, "auto"])
def test_kf_covariance_stays_symmetric_positive_definite_over_a_long_run(jerk_psd) -> None:
    robot = pinobs.load("pendulum")
    ob = pinobs.make_observer("kf", robot, noise_std=1e-4, jerk_psd=jerk_psd)
    rng = np.random.default_rng(0)
    ob.reset(0.0, np.zeros(1))
    for k in range(1, 20001):
        ob.update(k * 1e-3, rng.normal(0, 1e-4, 1))
    state = ob._state
    for P in [state.P] if jerk_psd != "auto" else list(state.bank.P):  # "auto": every filter's
        np.testing.assert_array_equal(P, P.T)
        assert np.linalg.eigvalsh(P).min() > 0
