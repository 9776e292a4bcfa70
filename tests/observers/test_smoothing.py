"""The RTS smoother: a closed form on a linear model, the filter it starts from, chunks, calibration."""

from __future__ import annotations

import functools
import json
import math
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

import pinobs
from pinobs.errors import (
    ChunkWarning,
    ConfigurationError,
    ConsistencyWarning,
    CostWarning,
    DimensionError,
    GainError,
    LatencyWarning,
    NoiseWarning,
    NonFiniteError,
    OptionError,
    TimestampError,
    TimestampWarning,
)
from pinobs.io import Log, estimate_log
from pinobs.observers import make_observer
from pinobs.observers.base import NOISE_FLOOR
from pinobs.observers.kf import WhiteJerkFilter
from pinobs.simulation import Sensor, simulate
from pinobs.smoothing import (
    AUTO_WHITE_SCALE,
    OFFSET_SCALE_RANGE,
    Smoother,
    api,
    consistent_offset_scale,
    default_overlap,
    latency,
    logs,
    pipeline,
    replay,
    select_accel_psd,
    select_latency,
    smooth,
    streaming_smoother,
)
from pinobs.smoothing import band as band_module
from pinobs.smoothing.band import noise_step
from pinobs.smoothing.rts import _backward, _Step
from tests.conftest import cached_robot, dropped_rows, irregular_loop_log


def _log(res: pinobs.Result) -> Log:
    """The log a run records: times, *measured* configurations, torques."""
    return Log(t=res.t, q=res.q_meas, tau=res.tau)


class _LinState(NamedTuple):
    q: np.ndarray
    v: np.ndarray
    P: np.ndarray


@pytest.fixture(params=["compiled", "numpy"])
def noise_path(request, monkeypatch) -> str:  # type: ignore[no-untyped-def]
    """The noise recursion's path: the compiled loops (small state) or NumPy's products."""
    for kernel in (band_module.noise_forward_kernel, band_module.noise_backward_kernel):
        if request.param == "compiled":
            kernel.load()
        else:
            monkeypatch.setattr(kernel, "compiled", None)
    return str(request.param)


def _random_linear_model(rng) -> tuple:  # type: ignore[no-untyped-def,type-arg]
    """UR5-sized (``q ⊕ δ = q + δ``) random linear model: ``robot, nv, n, r, m, Φs, Qs``."""
    robot = cached_robot("ur5")
    nv, n, r = robot.nv, 6, 0.3
    m = 2 * nv
    Phis = [np.eye(m) + 0.2 * rng.standard_normal((m, m)) for _ in range(n - 1)]
    Qs = [(lambda a: a @ a.T + 0.1 * np.eye(m))(rng.standard_normal((m, m))) for _ in range(n - 1)]
    return robot, nv, n, r, m, Phis, Qs


def _linear_rts(robot, Phis, Fs, Qs, P0, m0, ys, r) -> tuple[np.ndarray, ...]:  # type: ignore[no-untyped-def]
    """A linear Kalman filter (measurements ``ys[k]`` of the first ``nv`` states, ``None``:
    dropped; none at sample 0) whose mean moves by ``Fs`` and covariance by ``Phis`` (the
    EKF's mean step and its approximate Jacobian), then :func:`_backward`: ``(v^s, diag
    P^s, noise band)`` per sample (the band's entries other than velocities are NaN)."""
    nv, n, m = robot.nv, len(ys), P0.shape[0]
    H = np.hstack([np.eye(nv), np.zeros((nv, m - nv))])
    steps: list[_Step] = []
    x, P = m0, P0
    noise = None
    for k in range(n):
        pred = F = None
        if k > 0:
            xp, Pp = Fs[k - 1] @ x, Phis[k - 1] @ P @ Phis[k - 1].T + Qs[k - 1]
            pred, F = _LinState(xp[:nv], xp[nv:], Pp), Fs[k - 1]
            steps[-1] = steps[-1]._replace(pred=pred, Phi=Phis[k - 1], F=F)
            x, P = xp, Pp
            if ys[k] is not None:
                S = H @ Pp @ H.T + r * np.eye(nv)
                K = Pp @ H.T @ np.linalg.inv(S)
                x, P = xp + K @ (ys[k] - H @ xp), (np.eye(m) - K @ H) @ Pp
        state = _LinState(x[:nv], x[nv:], P) if ys[k] is not None or k == 0 else pred
        noise = noise_step(noise, pred, F, state, nv, r)
        steps.append(_Step(state, None, None, noise))
    got_v, got_var, got_noise = np.empty((n, nv)), np.empty((n, m)), np.empty((n, m))

    def emit(i: int, q: np.ndarray, v: np.ndarray, var: np.ndarray, var_n: np.ndarray) -> None:
        got_v[i], got_var[i], got_noise[i] = v, var, var_n

    _backward(robot, steps, emit, r)
    return got_v, got_var, got_noise


def test_backward_pass_equals_batch_conditioning_on_a_linear_gaussian_model(
    rng, noise_path: str
) -> None:
    """On a linear model (UR5: q ⊕ δ = q + δ) the RTS means and covariances are those of the
    joint Gaussian of all states conditioned on all measurements (computed directly), and the
    noise band (band="noise") is the covariance of that same linear estimate's error when the
    states move without process noise: ``(I − W C) T₀ P₀ T₀ᵀ (I − W C)ᵀ + r W Wᵀ``, with ``W``
    the batch gain.  Sample 3 is dropped (predicted over).  Both paths of the noise recursion:
    the compiled loops (small state) and NumPy's products."""
    robot, nv, n, r, m, Phis, Qs = _random_linear_model(rng)
    m0 = rng.standard_normal(m)
    P0 = np.eye(m)
    ys = [None] + [None if k == 3 else rng.standard_normal(nv) for k in range(1, n)]
    got_v, got_var, got_noise = _linear_rts(robot, Phis, Phis, Qs, P0, m0, ys, r)
    # batch: X = T z with z = (x0, w1..w_{n-1}); Y = C X + noise
    T = np.zeros((n * m, n * m))
    for k in range(n):
        for j in range(k + 1):
            A = np.eye(m)
            for i in range(j, k):
                A = Phis[i] @ A
            T[k * m : (k + 1) * m, j * m : (j + 1) * m] = A
    cov_z = np.zeros((n * m, n * m))
    cov_z[:m, :m] = P0
    for k in range(1, n):
        cov_z[k * m : (k + 1) * m, k * m : (k + 1) * m] = Qs[k - 1]
    mean_x = T[:, :m] @ m0
    cov_x = T @ cov_z @ T.T
    measured = [k for k in range(n) if ys[k] is not None]
    C = np.zeros((len(measured) * nv, n * m))
    for row, k in enumerate(measured):
        C[row * nv : (row + 1) * nv, k * m : k * m + nv] = np.eye(nv)
    y = np.concatenate([ys[k] for k in measured])
    S = C @ cov_x @ C.T + r * np.eye(len(measured) * nv)
    gain = cov_x @ C.T @ np.linalg.inv(S)
    post_mean = mean_x + gain @ (y - C @ mean_x)
    post_cov = cov_x - gain @ C @ cov_x
    want = post_mean.reshape(n, m)
    np.testing.assert_allclose(got_v, want[:, nv:], atol=1e-10)
    np.testing.assert_allclose(got_var, np.diag(post_cov).reshape(n, m), atol=1e-10)
    # the same estimate's error without process noise: x0 − m0 ~ N(0, P0), measurement noise r
    resid = np.eye(n * m) - gain @ C
    T0 = T[:, :m]
    cov_noise = resid @ T0 @ P0 @ T0.T @ resid.T + r * gain @ gain.T
    vel = np.diag(cov_noise).reshape(n, m)[:, nv:]  # v_std's entries (the others are NaN)
    np.testing.assert_allclose(got_noise[:, nv:], vel, atol=1e-10)
    assert np.all(got_noise[:, nv:] < got_var[:, nv:])  # the process noise's share is left out


def test_noise_band_propagates_the_error_by_the_mean_steps_jacobian(rng, noise_path: str) -> None:
    """The EKF's ``Φ`` only approximates the Jacobian ``F`` of its mean's step
    (:meth:`ExtendedKalmanFilter.predict_flow`); the truth's error moves by ``F``.  On a
    linear model whose mean moves by ``F`` and covariance by ``Φ ≠ F``, the noise band is
    the covariance of the smoothed velocity's error computed directly: the estimate is
    linear in the prior mean and the measurements (its matrices by superposition), the
    truth ``x_k = F_{k−1} ⋯ F_0 x_0`` with ``x_0 ~ N(m_0, P_0)``.  Sample 3 is dropped."""
    robot, nv, n, r, m, Phis, Qs = _random_linear_model(rng)
    Fs = [phi + 0.05 * rng.standard_normal((m, m)) for phi in Phis]
    P0 = np.eye(m)
    measured = [k for k in range(1, n) if k != 3]

    def v_s(m0: np.ndarray, y: np.ndarray) -> np.ndarray:  # the smoothed velocities, stacked
        ys: list[np.ndarray | None] = [None] * n
        for row, k in enumerate(measured):
            ys[k] = y[row * nv : (row + 1) * nv]
        return _linear_rts(robot, Phis, Fs, Qs, P0, m0, ys, r)[0].ravel()

    ny = len(measured) * nv
    L_m = np.column_stack([v_s(e, np.zeros(ny)) for e in np.eye(m)])
    L_y = np.column_stack([v_s(np.zeros(m), e) for e in np.eye(ny)])
    # the truth from x_0: T_F (stacked states), C (the measured positions), V (velocities)
    T_F = np.vstack([functools.reduce(np.matmul, Fs[:k][::-1], np.eye(m)) for k in range(n)])
    C = np.vstack([T_F[k * m : k * m + nv] for k in measured])
    V = np.vstack([T_F[k * m + nv : (k + 1) * m] for k in range(n)])
    M = L_y @ C - V  # the error's map from x_0: e = (L_m + M) m_0 + M δ + L_y n
    np.testing.assert_allclose(L_m + M, 0.0, atol=1e-10)  # unbiased: no noise, no error
    want = np.diag(M @ P0 @ M.T + r * L_y @ L_y.T).reshape(n, nv)
    ys = [rng.standard_normal(nv) if k in measured else None for k in range(n)]  # any values
    got = _linear_rts(robot, Phis, Fs, Qs, P0, m0=np.zeros(m), ys=ys, r=r)[2]
    np.testing.assert_allclose(got[:, nv:], want, rtol=1e-9, atol=1e-12)
    # with Φ in its place (the band before F) the answer is measurably different
    wrong = _linear_rts(robot, Phis, Phis, Qs, P0, m0=np.zeros(m), ys=ys, r=r)[2]
    assert np.max(np.abs(wrong[:, nv:] / want - 1.0)) > 1e-2


class _Gains(NamedTuple):
    meas_std: float


class _DoubleIntegratorKF:
    """A linear Kalman filter of ``nv`` independent double integrators (white acceleration
    of density ``a``, positions measured with ``σ``): a
    :class:`~pinobs.observers.base.GaussianFilter`, the smoother's filter interface."""

    disturbance_psd = None

    def __init__(self, robot: pinobs.Robot, a: float, sigma: float) -> None:
        self.robot, self.gains, self.a = robot, _Gains(sigma), a
        self.options: dict[str, object] = {}

    def initial_state(self, q0: np.ndarray, v0: np.ndarray) -> _LinState:
        nv = self.robot.nv
        return _LinState(q0, v0, np.diag(np.r_[np.full(nv, 1e-2), np.full(nv, 1e2)]))

    def predict(self, s: _LinState, dt: float, tau: np.ndarray) -> tuple[_LinState, np.ndarray]:
        nv = self.robot.nv
        Phi = np.block([[np.eye(nv), dt * np.eye(nv)], [np.zeros((nv, nv)), np.eye(nv)]])
        Q = np.kron(self.a * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]), np.eye(nv))
        return _LinState(s.q + dt * s.v, s.v, Phi @ s.P @ Phi.T + Q), Phi

    def predict_flow(
        self, s: _LinState, dt: float, tau: np.ndarray
    ) -> tuple[_LinState, np.ndarray, np.ndarray]:
        pred, Phi = self.predict(s, dt, tau)
        return pred, Phi, Phi  # linear: Φ is the mean's Jacobian

    def gate_limit(self, s: _LinState) -> float:
        return math.inf  # no outlier gate

    def correct(self, s: _LinState, q_meas: np.ndarray) -> _LinState:
        nv = self.robot.nv
        H = np.hstack([np.eye(nv), np.zeros((nv, nv))])
        K = s.P @ H.T @ np.linalg.inv(s.P[:nv, :nv] + self.gains.meas_std**2 * np.eye(nv))
        x = np.r_[s.q, s.v] + K @ (q_meas - s.q)
        return _LinState(x[:nv], x[nv:], (np.eye(2 * nv) - K @ H) @ s.P)


def _double_integrators(rng, nv: int, n: int, h: float, a: float, sigma: float) -> tuple:  # type: ignore[no-untyped-def,type-arg]
    """``nv`` double integrators driven by white acceleration of density ``a`` over ``n``
    samples ``h`` apart, positions measured with ``σ``: the states and the measurements."""
    x = np.zeros((n, 2 * nv))
    Q = np.kron(a * np.array([[h**3 / 3, h**2 / 2], [h**2 / 2, h]]), np.eye(nv))
    L = np.linalg.cholesky(Q)
    for k in range(1, n):
        x[k, :nv] = x[k - 1, :nv] + h * x[k - 1, nv:]
        x[k, nv:] = x[k - 1, nv:]
        x[k] += L @ rng.standard_normal(2 * nv)
    return x, x[:, :nv] + sigma * rng.standard_normal((n, nv))


def _smoothed(filt, y: np.ndarray, h: float) -> tuple[Smoother, np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """The whole-log smoother over ``y`` (samples ``h`` apart): it, ``v^s`` and ``diag P^s_vv``."""
    sm = Smoother(filt, None, 0)
    done = [r for k in range(len(y)) for r in sm.push(k * h, y[k], np.zeros(y.shape[1]))]
    done = sorted([*done, *sm.close()], key=lambda r: r[0])
    return sm, np.array([r[2] for r in done]), np.array([r[3] for r in done])


def test_filter_smoother_consistency_is_one_when_the_densities_are_the_truths(rng) -> None:
    """``ρ`` (Smoother.consistency): E[ρ] = 1 under the filter's own model, checked on
    double integrators driven by white acceleration of a known density; a filter that
    assumes 100x less (more) process noise than the truth reads ρ >> 1 (< 1)."""
    robot = cached_robot("ur5")
    nv, n, h, a, sigma = robot.nv, 4000, 0.01, 1.0, 0.01
    _, y = _double_integrators(rng, nv, n, h, a, sigma)
    rho = {}
    for scale in (1.0, 1e-2, 1e2):
        sm, _, _ = _smoothed(_DoubleIntegratorKF(robot, scale * a, sigma), y, h)
        rho[scale] = sm.consistency
    assert abs(rho[1.0] - 1.0) < 0.1, rho
    assert rho[1e-2] > 3.0 and rho[1e2] < 0.7, rho


def test_consistency_is_the_variance_factor_when_every_noise_level_is_off_by_one_factor(
    rng,
) -> None:
    """The ``inflated`` band's premise (module docstring): with the process and measurement
    noise both 4x the filter's (variances), ρ reads 4 and the smoother's band scaled by √ρ
    covers the truth as a calibrated ±2σ band does (95.4 %); unscaled, as a ±1σ band."""
    robot = cached_robot("ur5")
    nv, n, h, a, sigma, c2 = robot.nv, 4000, 0.01, 1.0, 0.01, 4.0
    x, y = _double_integrators(rng, nv, n, h, c2 * a, np.sqrt(c2) * sigma)
    sm, v, var = _smoothed(_DoubleIntegratorKF(robot, a, sigma), y, h)
    assert sm.consistency == pytest.approx(c2, rel=0.1)
    late = slice(100, None)  # after the start-up
    err = np.abs(v - x[:, nv:])[late]
    inside = np.mean(err <= 2 * np.sqrt(sm.consistency * var[late]))
    assert 0.93 <= inside <= 0.975, inside
    assert 0.62 <= np.mean(err <= 2 * np.sqrt(var[late])) <= 0.74  # P(|z| ≤ 1) = 0.683


@pytest.fixture(scope="module")
def ur5_log() -> pinobs.Result:
    robot = cached_robot("ur5")
    return simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=0.6, seed=4)


def test_last_sample_is_the_causal_filter_and_earlier_ones_differ(ur5_log) -> None:
    robot = cached_robot("ur5")
    res = ur5_log
    log = Log(t=res.t, q=res.q_meas, tau=res.tau)
    ekf = make_observer("ekf", robot, noise_std=1e-4, accel_psd=1e-4)
    causal = estimate_log(ekf, Log(t=res.t[1:], q=res.q_meas[1:], tau=res.tau[1:]))
    s = smooth(robot, log, noise_std=1e-4, accel_psd=1e-4)
    assert np.all(np.isnan(s.v[0]))  # the simulator does not measure sample 0
    np.testing.assert_allclose(s.v[-1], causal.v[-1], rtol=0, atol=1e-12)
    assert np.abs(s.v[1:-1] - causal.v[:-1]).max() > 1e-4


@pytest.mark.parametrize("name", ["ur5", "top", "rigid_body"])
def test_smoother_removes_the_filters_start_up_transient_on_noise_free_data(name: str) -> None:
    """The filter starts at v = 0 (error ≈ 0.5 rad/s); the smoother uses the later samples.
    On the top (SO(3)) and a free body (SE(3)) this exercises ⊕/⊖ on the manifold."""
    robot = cached_robot(name)
    res = simulate(
        robot,
        [],
        sensor=Sensor(1000, 0.0),
        inputs="pd",
        duration=0.5,
        seed=5,
        v0=np.full(robot.nv, 0.5),
    )
    s = smooth(robot, _log(res), noise_std=1e-6, accel_psd=1e-6)
    ekf = make_observer("ekf", robot, noise_std=1e-6, accel_psd=1e-6)
    causal = estimate_log(ekf, Log(t=res.t[1:], q=res.q_meas[1:], tau=res.tau[1:]))
    err_s = np.abs(s.v[1:] - res.v[1:]).max(axis=1)
    err_f = np.abs(causal.v - res.v[1:]).max(axis=1)
    assert err_f[0] > 0.4
    # the extended smoother linearises along the filter's wrong start: not exact there
    assert err_s[0] < 1e-2 * err_f[0]  # measured 9.1e-4, 2.2e-4, 3.0e-4 (filter 0.48-0.59)
    assert err_s[res.t[1:] > 0.05].max() < 1e-6  # measured 1.2e-8, 2.4e-9, 2.7e-9


def test_a_quaternion_off_unit_norm_is_refused_before_the_passes_and_nan_smooths_over_it() -> None:
    """One bad quaternion row stopped the smoother at that row (after the passes before it);
    it is refused up front, naming the rows, and the row set to NaN is a dropped sample."""
    robot = cached_robot("rigid_body")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=0.3, seed=5)
    t, q = res.t[1:], res.q_meas[1:].copy()
    q[100, 3:7] = [0.0, 0.0, 0.0, 0.5]
    q[150, 3:7] *= 1.01
    with pytest.raises(ConfigurationError, match=r"2 rows of q .* \(rows 100, 150; row 100: "):
        smooth(robot, (t, q, res.tau[1:]), noise_std=1e-4)
    q[[100, 150]] = np.nan
    s = smooth(robot, (t, q, res.tau[1:]), noise_std=1e-4)
    assert np.all(np.isfinite(s.v)) and s.v.shape == (t.size, robot.nv)
    assert not robot.off_unit_rows(res.q_meas[1:]).any()


def test_smoother_over_the_disturbance_state_ends_on_the_filter_and_beats_it() -> None:
    """With ``disturbance_psd`` the error state is (δq, δv, δd): 3nv, d smoothed as a vector."""
    robot = cached_robot("top")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=0.4, seed=5)
    opts = {"noise_std": 1e-4, "accel_psd": 1e-4, "disturbance_psd": 1.0}
    s = smooth(robot, _log(res), **opts)  # type: ignore[arg-type]
    ekf = make_observer("ekf", robot, **opts)
    causal = estimate_log(ekf, Log(t=res.t[1:], q=res.q_meas[1:], tau=res.tau[1:]))
    np.testing.assert_allclose(s.v[-1], causal.v[-1], rtol=0, atol=1e-12)
    rms_s = np.sqrt(np.mean((s.v - res.v)[200:] ** 2))
    rms_f = np.sqrt(np.mean((causal.v - res.v[1:])[199:] ** 2))
    assert rms_s < 0.5 * rms_f  # measured 5.4e-4 vs 2.3e-3


def test_smoother_beats_the_filter_on_a_lie_group_robot() -> None:
    """The top (SO(3)): ⊕/⊖ are exp/log; smoothed RMS below the causal filter's."""
    robot = cached_robot("top")
    res = simulate(robot, ["ekf"], sensor=Sensor(1000, 1e-3), inputs="pd", duration=0.6, seed=6)
    s = smooth(robot, _log(res), noise_std=1e-3, accel_psd=1e-8)
    late = res.t > 0.2
    rms_s = np.sqrt(np.mean((s.v - res.v)[late] ** 2))
    rms_f = np.sqrt(np.mean((res.trace("ekf").v - res.v)[late] ** 2))
    # measured 7.7e-4 vs 1.14e-3 (1.5×; the steady-state double integrator gives 2×)
    assert rms_s < 0.8 * rms_f


def _lti_slowest_pole(mass: np.ndarray, q_w: float, j: float, r: float) -> float:
    """The slowest pole of the steady-state Kalman filter of q̈ = w + M⁻¹d, ḋ = w_d, y = q + n
    (densities q_w I, j diag(Mᵢᵢ²), r I), from the continuous algebraic Riccati equation."""
    from scipy.linalg import block_diag, solve_continuous_are

    n = mass.shape[0]
    z, e = np.zeros((n, n)), np.eye(n)
    a = np.block([[z, e, z], [z, z, np.linalg.inv(mass)], [z, z, z]])
    c = np.hstack([e, z, z])
    q = block_diag(z, q_w * e, np.diag(j * np.diag(mass) ** 2))
    p = solve_continuous_are(a.T, c.T, q, r * e)
    return float(np.min(np.abs(np.linalg.eigvals(a - p @ c.T @ c / r).real)))


@pytest.mark.parametrize("name", ["planar_3r", "ur5", "panda"])
def test_default_overlap_is_the_slowest_pole_of_the_steady_state_filter(name: str) -> None:
    """default_overlap's poles (the roots of r s⁶ + q_w s² − λ per eigen-direction of the
    offset's acceleration density) against the Riccati equation's filter, at densities where
    it is well conditioned; the closed forms of its limits; the coupling of M lengthens it."""
    robot = cached_robot(name)
    mass = robot.mass_matrix(robot.random_configuration(np.random.default_rng(3)))
    sigma, h, q_w, j = 1e-2, 1e-3, 1.0, 10.0
    got = default_overlap(q_w, sigma, h, disturbance_psd=j, mass_matrices=[mass])
    want = np.log(1e6) / _lti_slowest_pole(mass, q_w, j, sigma**2 * h)
    assert got == pytest.approx(want, rel=1e-6)
    r = 1e-8 * 1e-3  # σ = 1e-4 at 1 kHz
    assert default_overlap(1e-4, 1e-4, 1e-3) == pytest.approx(
        np.sqrt(2) * np.log(1e6) / (1e-4 / r) ** 0.25, rel=1e-12
    )
    assert default_overlap(0.0, 1e-4, 1e-3, disturbance_psd=1.0) == pytest.approx(
        2 * np.log(1e6) / (1.0 / r) ** (1 / 6), rel=1e-9
    )
    iso = default_overlap(1e-4, 1e-4, 1e-3, disturbance_psd=1.0)
    assert default_overlap(1e-4, 1e-4, 1e-3, disturbance_psd=1.0, mass_matrices=[mass]) > iso


@pytest.mark.filterwarnings("ignore::pinobs.errors.ConsistencyWarning")  # the model error
def test_chunked_smoother_with_a_torque_offset_equals_the_whole_log_one() -> None:
    """ekf with disturbance_psd under model error: the offset's slow pole through M⁻¹ sets the
    overlap (0.47 s on this UR5 log: 1.1e-6 of v_std; the isotropic 0.41 s left 8.7e-6 here,
    2.0e-5 on a 10 s log)."""
    robot = cached_robot("ur5")
    res = _mismatched_log("ur5", "inertia20_payload", 2.0)
    opts = {"noise_std": 1e-4, "accel_psd": 1e-4, "disturbance_psd": 1.0}
    whole = smooth(robot, _log(res), **opts)  # type: ignore[arg-type]
    chunked = smooth(robot, _log(res), chunk=0.5, **opts)  # type: ignore[arg-type]
    assert chunked.options["overlap"] > default_overlap(1e-4, 1e-4, 1e-3, disturbance_psd=1.0)
    assert 0.5 + chunked.options["overlap"] < 1.5  # the windows do not all reach the log's end
    rel = np.max(np.abs(chunked.v - whole.v)[1:] / whole.v_std[1:])
    assert rel < 1e-5  # CHUNK_TOL = 1e-6 aimed at; measured 1.1e-6


def test_a_streamed_smoother_with_a_torque_offset_takes_the_inertia_where_the_log_goes() -> None:
    """No log at construction: the overlap takes M at the configurations given (the log's first
    rows: pinobs.io.smoothing), by default the neutral one and 31 random ones."""
    robot = cached_robot("ur5")
    opts = {"dt": 1e-3, "noise_std": 1e-4, "accel_psd": 1e-4, "disturbance_psd": 1.0, "chunk": 1.0}
    q = np.array([robot.random_configuration(np.random.default_rng(k)) for k in range(3)])
    _, given = streaming_smoother(robot, configurations=q, **opts)  # type: ignore[arg-type]
    masses = [robot.mass_matrix(c) for c in q]
    want = default_overlap(1e-4, 1e-4, 1e-3, disturbance_psd=1.0, mass_matrices=masses)
    assert given["overlap"] == pytest.approx(want, abs=1e-3)
    _, default = streaming_smoother(robot, **opts)  # type: ignore[arg-type]
    assert default["overlap"] > default_overlap(1e-4, 1e-4, 1e-3, disturbance_psd=1.0)
    with pytest.raises(DimensionError, match="no finite row"):
        streaming_smoother(robot, configurations=np.full((2, 6), np.nan), **opts)  # type: ignore[arg-type]


@pytest.mark.parametrize(("name", "sigma", "psd"), [("ur5", 1e-4, 1e-4), ("panda", 1e-3, 1e-2)])
def test_chunked_smoother_equals_the_whole_log_one_to_the_stated_tolerance(
    name: str, sigma: float, psd: float
) -> None:
    robot = cached_robot(name)
    res = simulate(robot, [], sensor=Sensor(1000, sigma), inputs="pd", duration=1.0, seed=7)
    whole = smooth(robot, _log(res), noise_std=sigma, accel_psd=psd)
    chunked = smooth(robot, _log(res), noise_std=sigma, accel_psd=psd, chunk=0.2)
    overlap = default_overlap(psd, sigma, 1e-3)
    assert chunked.options["overlap"] == pytest.approx(overlap, abs=1e-3)
    assert 0.2 + overlap < 0.6  # the windows do not all reach the log's end
    rel = np.nanmax(np.abs(chunked.v - whole.v) / whole.v_std)
    assert rel < 1e-5  # CHUNK_TOL = 1e-6 aimed at; measured 1.8e-6 (panda), 1.7e-6 (ur5)
    np.testing.assert_allclose(chunked.v_std[1:], whole.v_std[1:], rtol=1e-9)


@pytest.mark.parametrize("observer", ["ekf", "kf"])
def test_a_gap_in_the_overlap_does_not_shorten_it(observer: str) -> None:
    """The overlap counts measured samples: a sample without one does not contract the backward
    pass's error, so a gap inside the overlap shortened it.  UR5, 2 s, 0.38 s of dropped samples
    from 0.52 s (in the overlap after the first 0.5 s chunk).  Measured: chunked off the whole
    log by 6.5e-2 (ekf) and 3.0e-2 (kf) of v_std before, 2.6e-6 and 2.5e-6 now (on a 6 s log
    with 1 s dropped, 0.34 and 41 before).  kf's compiled path, and Smoother streamed."""
    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=2.0, seed=2)
    q = res.q_meas.copy()
    q[520:900] = np.nan
    opts = {"observer": observer, "noise_std": 1e-4}
    if observer == "ekf":
        opts["accel_psd"] = 1e-4
    whole = smooth(robot, (res.t, q, res.tau), **opts)  # type: ignore[arg-type]
    chunked = smooth(robot, (res.t, q, res.tau), chunk=0.5, **opts)  # type: ignore[arg-type]
    assert chunked.options["overlap"] < 0.5  # the gap (0.3 s) would have eaten most of it
    assert np.nanmax(np.abs(chunked.v - whole.v) / whole.v_std) < 1e-5
    make, info = streaming_smoother(robot, dt=1e-3, chunk=0.5, **opts)  # type: ignore[arg-type]
    smoother = make()
    k0 = int(np.flatnonzero(np.isfinite(q).all(axis=1))[0])  # pushed from its first sample
    out = np.full_like(res.v, np.nan)
    for t, qk, tau in zip(res.t[k0:], q[k0:], res.tau[k0:], strict=True):
        for i, _, vs, _ in smoother.push(t, None if np.isnan(qk).any() else qk, tau):
            out[k0 + i] = vs
    for i, _, vs, _ in smoother.close():
        out[k0 + i] = vs
    assert info["overlap"] == pytest.approx(chunked.options["overlap"])
    assert np.nanmax(np.abs(out - whole.v) / whole.v_std) < 1e-5


def test_noise_band_is_chunked_like_the_estimate_and_chosen_per_observer(ur5_log) -> None:
    """band="noise" changes v_std only; its recursion restarts at each window's end as the
    estimate's does (B = I, U = 0: the smoother is the filter there), so chunked equals whole
    to the same tolerance.  Default: "model" over ekf (adaptive: test below)."""
    robot = cached_robot("ur5")
    opts = {"noise_std": 1e-4, "accel_psd": 1e-2}
    model = smooth(robot, _log(ur5_log), **opts)  # type: ignore[arg-type]
    assert model.options["band"] == "model"
    whole = smooth(robot, _log(ur5_log), band="noise", **opts)  # type: ignore[arg-type]
    np.testing.assert_array_equal(whole.v, model.v)
    assert whole.consistency == model.consistency  # ρ tests the model's covariance
    assert np.all(whole.v_std[1:] < model.v_std[1:])
    chunked = smooth(robot, _log(ur5_log), band="noise", chunk=0.1, **opts)  # type: ignore[arg-type]
    np.testing.assert_allclose(chunked.v_std[1:], whole.v_std[1:], rtol=1e-5)
    with pytest.raises(OptionError, match=r"band='wide': give one of \['model', 'noise', 'infl"):
        smooth(robot, _log(ur5_log), band="wide", **opts)  # type: ignore[arg-type]
    with pytest.raises(OptionError, match="band="):
        streaming_smoother(robot, dt=1e-3, noise_std=1e-4, accel_psd=1e-2, lag=0.1, band="x")
    with pytest.raises(GainError, match="needs noise_std"):
        streaming_smoother(robot, dt=1e-3, accel_psd=1e-2, lag=0.1)


def test_inflated_band_is_the_noise_band_scaled_by_the_logs_consistency_never_narrower() -> None:
    """band="inflated" (adaptive's default): v_std = √max(1, ρ) × the noise band, the same
    estimate; with ρ < 1 (densities larger than the log needs) it is the noise band.  Only
    the whole-log smoother knows ρ: a Smoother or a streamed one refuses it."""
    robot = cached_robot("planar_3r")
    res = _mismatched_log("planar_3r", "inertia20_payload", 1.2)
    adaptive = {"observer": "adaptive", "noise_std": 1e-4, "model_window": 0.5}
    with pytest.warns(ConsistencyWarning, match="widened by"):  # 1.2 s: too short to learn
        default = smooth(robot, _log(res), **adaptive)  # type: ignore[arg-type]
    assert default.options["band"] == "inflated"
    for psd in (1e-12, 1e2):  # ekf on the nominal model: ρ ≫ 1 (said), then ρ < 1
        opts = {"noise_std": 1e-4, "accel_psd": psd}
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            inflated = smooth(robot, _log(res), band="inflated", **opts)  # type: ignore[arg-type]
            noise = smooth(robot, _log(res), band="noise", **opts)  # type: ignore[arg-type]
        assert [type(w.message) for w in said] == [ConsistencyWarning] * (2 if psd < 1 else 0)
        np.testing.assert_array_equal(inflated.v, noise.v)
        rho = inflated.consistency
        assert (rho > 10.0) if psd == 1e-12 else (rho < 1.0), rho
        scale = inflated.options["band_scale"]
        assert scale == np.sqrt(max(1.0, rho))
        np.testing.assert_allclose(inflated.v_std, scale * noise.v_std, rtol=1e-12)
    with pytest.raises(OptionError, match="a Smoother gives one of"):
        Smoother(make_observer("ekf", robot, noise_std=1e-4), None, 0, "inflated")  # type: ignore[arg-type]
    with pytest.raises(OptionError, match=r"use smooth\(\) on the whole log"):
        streaming_smoother(robot, dt=1e-3, noise_std=1e-4, accel_psd=1e-2, lag=0.1, band="inflated")


def test_fixed_lag_uses_later_samples_and_short_lags_lose_accuracy(ur5_log) -> None:
    robot = cached_robot("ur5")
    res = ur5_log
    whole = smooth(robot, _log(res), noise_std=1e-4, accel_psd=1e-2)
    rel = {}
    for lag in (0.02, 0.1):
        lagged = smooth(robot, _log(res), noise_std=1e-4, accel_psd=1e-2, lag=lag)
        assert lagged.options["chunk"] == pytest.approx(lag)
        rel[lag] = np.nanmax(np.abs(lagged.v - whole.v) / whole.v_std)
    # bandwidth ω = 178 rad/s: 0.1 s is 12/ω, 0.02 s is 2.5/ω
    assert rel[0.1] < 1e-4  # measured 8.0e-6
    assert rel[0.02] > 1e-2  # measured 0.13


def test_dropped_samples_are_predicted_over_and_get_a_wider_band(ur5_log) -> None:
    robot = cached_robot("ur5")
    q = np.array(ur5_log.q_meas)
    q[300:340] = np.nan
    s = smooth(robot, (ur5_log.t, q, ur5_log.tau), noise_std=1e-4, accel_psd=1e-2)
    assert np.all(np.isfinite(s.v[1:]))
    assert s.v_std[320].max() > 1.2 * s.v_std[200].max()  # measured 1.35×
    assert not s.v.flags.writeable and not s.v_std.flags.writeable


def test_likelihood_choice_of_accel_psd_is_the_largest_the_data_do_not_reject(ur5_log) -> None:
    robot = cached_robot("ur5")
    grid = (1e-10, 1e-6, 1e-2)
    lls = [smooth(robot, _log(ur5_log), noise_std=1e-4, accel_psd=p).log_likelihood for p in grid]
    chosen = select_accel_psd(robot, _log(ur5_log), noise_std=1e-4, grid=grid)
    best = max(lls)
    ok = [p for p, ll in zip(grid, lls, strict=True) if ll >= best - 1.92]
    assert chosen == max(ok)


@pytest.mark.slow  # 10-21 s on a 2-core machine: the default run stays under 10 min
def test_a_sample_the_gate_rejects_decides_neither_the_density_nor_the_latency() -> None:
    """One glitch (a joint 1 rad off, or 1e6) is rejected by the EKF's outlier gate, and the
    likelihood counts it at the gate (:func:`pinobs.smoothing.rts.forward_pass`): ``"auto"`` and the latency
    search choose on the glitched log what they choose on the clean one (before: 1 instead of
    1e-9 rad²/s³, an RMS 900× larger; 1 ms found on a log without latency), and the
    likelihood moves by less than the gate's half (χ²₆(1 − 1e-6)/2 ≈ 20 nats)."""
    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=2.0, seed=0)
    clean = Log(t=res.t, q=res.q_meas, tau=res.tau)
    for glitch in (1.0, 1e6):
        q = np.array(res.q_meas)
        q[500, 2] += glitch
        log = Log(t=res.t, q=q, tau=res.tau)
        for opts in ({"accel_psd": "auto"}, {"filter_options": {"latency": "auto"}}):
            want = smooth(robot, clean, noise_std=1e-4, **opts)  # type: ignore[arg-type]
            got = smooth(robot, log, noise_std=1e-4, **opts)  # type: ignore[arg-type]
            assert got.options["accel_psd"] == want.options["accel_psd"]
            assert got.options["latency"] == want.options["latency"] == 0.0
            assert abs(got.log_likelihood - want.log_likelihood) < 25.0
            rms = [np.sqrt(np.nanmean((x.v - res.v) ** 2)) for x in (got, want)]
            assert rms[0] < 1.05 * rms[1]  # measured 1.4e-5 and 2.1e-5 rad/s, both logs


def test_families_declare_what_the_smoother_needs_on_the_public_protocol() -> None:
    """Smoothable families are found from the registry by their class attributes; each
    gives its Gaussian filter (or, learning its model, says how it is smoothed); the
    others refuse, naming the smoothable ones."""
    robot = cached_robot("ur5")
    names = pinobs.observer_names()
    cls = pinobs.observers.observer_class
    assert [n for n in names if cls(n).smoothable] == ["adaptive", "ekf", "kf"]
    assert [n for n in names if cls(n).model_free and cls(n).smoothable] == ["kf"]
    assert [n for n in names if cls(n).learns_model] == ["adaptive"]
    assert {cls(n).process_density for n in ("ekf", "kf")} == {"accel_psd", "jerk_psd"}
    ekf = make_observer("ekf", robot, noise_std=1e-4)
    assert ekf.smoothing_filter() is ekf
    jerk = make_observer("kf", robot, noise_std=1e-4).smoothing_filter()
    assert isinstance(jerk, WhiteJerkFilter) and jerk.disturbance_psd is None
    with pytest.raises(OptionError, match="smoothable: \\['adaptive', 'ekf', 'kf'\\]"):
        make_observer("fd", robot).smoothing_filter()
    with pytest.raises(OptionError, match="learns its model"):
        make_observer("adaptive", robot, noise_std=1e-4).smoothing_filter()


def test_bad_inputs_are_rejected_with_what_would_be_valid(ur5_log) -> None:
    robot = cached_robot("ur5")
    t, q, tau = ur5_log.t, ur5_log.q_meas, ur5_log.tau
    with pytest.raises(OptionError, match="smoothable: \\['adaptive', 'ekf', 'kf'\\]"):
        smooth(robot, (t, q, tau), observer="fd")
    with pytest.raises(OptionError, match="give lag alone"):
        smooth(robot, (t, q, tau), lag=0.1, chunk=0.2)
    with pytest.raises(DimensionError, match=r"needs \(601, 6\)"):
        smooth(robot, (t, q[:, :5], tau))
    t_bad = np.array(t)
    t_bad[10] = t_bad[9]
    with pytest.raises(TimestampError, match="strictly increasing"):
        smooth(robot, (t_bad, q, tau))
    # t in ms: the filter was lost with no word of the unit; now the unit is asked first
    with pytest.warns(TimestampWarning, match=r"is t in milliseconds"):
        with pytest.raises(NonFiniteError, match="the filter is lost"):
            smooth(robot, (1e3 * t, q, tau), noise_std=1e-4)
    with pytest.raises(GainError, match="lag"):
        smooth(robot, (t, q, tau), lag=-1.0)
    with pytest.raises(OptionError, match=r"overlap=0\.5 without chunk"):
        smooth(robot, (t, q, tau), noise_std=1e-4, overlap=0.5)  # (was ignored)
    with pytest.raises(GainError, match="noise_std=0 is out of range"):
        smooth(robot, (t, q, tau), noise_std=0)  # (was floored to 1e-6, then blamed the model)
    with pytest.raises(OptionError, match=r"filter_options\['noise_std'\]"):
        smooth(robot, (t, q, tau), noise_std=1e-4, filter_options={"noise_std": 1e-3})
    with pytest.raises(OptionError, match="filter_options is a list"):
        smooth(robot, (t, q, tau), noise_std=1e-4, filter_options=[("latency", 1e-3)])  # type: ignore[arg-type]
    with pytest.raises(GainError, match="not shorter than the log"):
        smooth(robot, (t, q, tau), noise_std=1e-4, filter_options={"latency": 10.0})
    with pytest.raises(DimensionError, match=r"give a pinobs\.io\.Log"):
        smooth(robot, np.zeros((3, 6)), noise_std=1e-4)  # type: ignore[arg-type]


def test_a_log_and_a_density_are_taken_in_any_of_their_natural_forms(ur5_log) -> None:
    """A list or a mapping of the arrays is the tuple; an int or NumPy density is the float
    (the latency search and ``adaptive`` took an int for no density; a ``np.float32`` left the
    options unserialisable); Unix times (1.7e9 s) re-time under a latency as relative ones
    (the merge tolerance was finer than their float64 step: a NaN row appeared)."""
    robot = cached_robot("ur5")
    t, q, tau = ur5_log.t, ur5_log.q_meas, ur5_log.tau
    want = smooth(robot, (t, q, tau), noise_std=1e-4, accel_psd=1e-6)
    for log in ([t, q, tau], {"t": t, "q": q, "tau": tau}):
        got = smooth(robot, log, noise_std=1e-4, accel_psd=1e-6)  # type: ignore[arg-type]
        np.testing.assert_array_equal(got.v, want.v)
    for psd in (1, np.float32(1.0), np.int64(1)):
        got = smooth(robot, (t, q, tau), noise_std=1e-4, accel_psd=psd)  # type: ignore[arg-type]
        assert type(got.options["accel_psd"]) is float and got.options["accel_psd"] == 1.0
        assert got.options["accel_psd_from_log"] is False
        json.dumps({k: v for k, v in got.options.items() if not isinstance(v, np.ndarray)})
    late = np.vstack([np.full((1, robot.nq), np.nan), q[:-1]])  # 1 ms late
    opts = {"noise_std": 1e-4, "filter_options": {"latency": 1e-3}}
    stamps = np.round(1.7e9 + t, 6)  # on float64's 2.4e-7 s grid there
    rel = smooth(robot, (t, late, tau), **opts)  # type: ignore[arg-type]
    unix = smooth(robot, (stamps, late, tau), **opts)  # type: ignore[arg-type]
    assert np.array_equal(np.isnan(unix.v), np.isnan(rel.v))
    for times in (t, stamps):  # each measurement on the stamp before it: no row of its own
        assert logs.retimed(times, late, tau, 1e-3)[0].size == t.size + 1


def test_a_chunk_far_shorter_than_its_overlap_is_warned(ur5_log) -> None:
    """A chunk a tenth of the overlap or less makes every window's backward pass mostly
    overlap (at 2 ms against 0.3 s, 150× the whole log's) for no memory saved: warned; a lag
    (chunk = overlap) is not, nor a log within one window (it said 151× over a 0.2 s log).
    An overlap shorter than the default one is warned with the deviation it allows (it was
    silent), CHUNK_TOL^(overlap/default): measured 0.18 of v_std at 0.05 s (said 0.14), 4.0e-3
    at 0.15 s (2.5e-3), 1.1e-5 at 0.3 s (6.5e-6)."""
    robot = cached_robot("ur5")
    opts = {"noise_std": 1e-4, "accel_psd": 1e-4}  # the default overlap: 0.347 s
    log = _log(ur5_log)
    with pytest.warns(CostWarning, match=r"chunk=0.002 s with an overlap of 0.4 s: .* 201×"):
        smooth(robot, log, chunk=0.002, overlap=0.4, **opts)  # type: ignore[arg-type]
    smooth(robot, log, lag=0.4, **opts)  # type: ignore[arg-type]
    smooth(robot, log, chunk=0.04, overlap=0.4, **opts)  # type: ignore[arg-type]
    short = (log.t[:200], log.q[:200], log.tau[:200])  # 0.2 s: one window, one backward pass
    smooth(robot, short, chunk=0.002, overlap=0.4, **opts)  # type: ignore[arg-type]
    whole = smooth(robot, log, **opts)  # type: ignore[arg-type]
    with pytest.warns(ChunkWarning, match=r"overlap=0.05 s is shorter than the 0.347 s .* 0.14 of"):
        chunked = smooth(robot, log, chunk=0.1, overlap=0.05, **opts)  # type: ignore[arg-type]
    assert np.nanmax(np.abs(chunked.v - whole.v) / whole.v_std) > 1e-3


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "sigma"), [("ur5", 1e-4), ("ur5", 1e-3), ("panda", 1e-4), ("panda", 1e-3)]
)
def test_smoother_targets_on_exact_model_logs(name: str, sigma: float) -> None:
    """Targets of issue 19 with accel_psd chosen by likelihood (no truth used):
    RMS ≥ 3× below the causal ekf (default options), ±2σ covers 90–98 %.

    Seed 0 is the log the README's table reports (measured 3.1–10.3×, 95.4–97.6 %).
    Not every 3 s log meets them: on seeds 1–3 (README, "Seeds 0 to 3") the ratio is
    2.4–7.7× (UR5 at σ = 1e-3: 2.4× and 2.5× on seeds 1 and 3; on seed 3 no density
    reaches 3×, the best on the truth gives 2.7×) and one log's coverage 87.8–100 %,
    because the smoothed error of an exact-model log is a slowly varying curve with
    few independent values; 10 s logs: next test."""
    robot = cached_robot(name)
    res = simulate(robot, ["ekf"], sensor=Sensor(1000, sigma), inputs="pd", duration=3.0, seed=0)
    psd = select_accel_psd(
        robot, _log(res), noise_std=sigma, grid=tuple(10.0 ** np.arange(-14, -3))
    )
    s = smooth(robot, _log(res), noise_std=sigma, accel_psd=psd)
    late = res.t > 0.5
    rms_s = np.sqrt(np.mean((s.v - res.v)[late] ** 2))
    rms_f = np.sqrt(np.mean((res.trace("ekf").v - res.v)[late] ** 2))
    cover = np.mean(np.abs(s.v - res.v)[late] <= 2 * s.v_std[late])
    assert rms_f / rms_s >= 3.0
    assert 0.90 <= cover <= 0.98


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_smoother_targets_on_10_s_exact_model_logs_of_four_seeds(name: str) -> None:
    """The same targets on 10 s logs at σ = 1e-3 (the harder noise), seeds 0–3: every log
    ≥ 3× below the causal ekf (measured 5.1–11.3× UR5, 8.2–12.4× Panda), and the
    four logs' samples pooled covered at 90–98 %: measured 96.8 % on the Panda; 98.1 %
    on the UR5, a known miss of the upper end (README), where only the lower is asserted."""
    robot = cached_robot(name)
    covered = []
    for seed in range(4):
        res = simulate(
            robot, ["ekf"], sensor=Sensor(1000, 1e-3), inputs="pd", duration=10.0, seed=seed
        )
        s = smooth(robot, _log(res), noise_std=1e-3, accel_psd="auto")
        late = res.t > 0.5
        rms_s = np.sqrt(np.mean((s.v - res.v)[late] ** 2))
        rms_f = np.sqrt(np.mean((res.trace("ekf").v - res.v)[late] ** 2))
        assert rms_f / rms_s >= 3.0
        covered.append(np.abs(s.v - res.v)[late] <= 2 * s.v_std[late])
    assert np.mean(covered) >= 0.90
    if name == "panda":
        assert np.mean(covered) <= 0.98


def test_cli_estimate_smooth_writes_estimate_columns_plus_v_std(tmp_path, ur5_log) -> None:
    from pinobs.cli import main
    from pinobs.io import write_log

    rows = slice(1, 301)
    log = write_log(tmp_path / "log.csv", ur5_log.t[rows], ur5_log.q_meas[rows], ur5_log.tau[rows])
    out = tmp_path / "est.csv"
    argv = ["estimate", "--robot", "ur5", "--observer", "ekf", "--log", str(log), "--out", str(out)]
    assert main([*argv, "--smooth", "--noise", "1e-4", "--lag", "0.05", "--accel-psd", "1e-4"]) == 0
    header = out.read_text().splitlines()[0].split(",")
    assert header == [
        "t",
        *(f"q{i}" for i in range(6)),
        *(f"v{i}" for i in range(6)),
        *(f"v_std{i}" for i in range(6)),
    ]
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape == (300, 19)
    want = smooth(
        cached_robot("ur5"),
        (ur5_log.t[rows], ur5_log.q_meas[rows], ur5_log.tau[rows]),
        noise_std=1e-4,
        accel_psd=1e-4,
        lag=0.05,
    )
    np.testing.assert_allclose(data[:, 7:13], want.v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(data[:, 13:], want.v_std, rtol=0, atol=1e-15)
    assert main([*argv, "--smooth"]) != 0  # no --noise: refused with a message


def test_cli_estimate_smooth_writes_through_the_io_writer_and_refuses_to_overwrite(
    tmp_path, ur5_log
) -> None:
    from pinobs.cli import main
    from pinobs.io import write_log

    rows = slice(1, 201)
    log = write_log(tmp_path / "log.csv", ur5_log.t[rows], ur5_log.q_meas[rows], ur5_log.tau[rows])
    out = tmp_path / "est.csv"
    argv = ["estimate", "--robot", "ur5", "--observer", "ekf", "--log", str(log)]
    smooth_args = ["--smooth", "--noise", "1e-4", "--lag", "0.05"]
    assert main([*argv, "--out", str(out), *smooth_args]) == 0
    first = out.read_text()
    assert main([*argv, "--out", str(out), *smooth_args, "--accel-psd", "1e-4"]) == 2
    assert out.read_text() == first  # refused: exists, no --force
    assert main([*argv, "--out", str(out), *smooth_args, "--accel-psd", "1e-4", "--force"]) == 0
    assert out.read_text() != first
    assert main([*argv, "--out", str(log), *smooth_args, "--force"]) == 2  # the input itself
    # --chunk: the whole-log smoother's result in bounded memory
    whole, chunked = tmp_path / "whole.csv", tmp_path / "chunked.csv"
    psd = ["--smooth", "--noise", "1e-4", "--accel-psd", "1e-2"]  # overlap 0.11 s of 0.2 s
    assert main([*argv, "--out", str(whole), *psd]) == 0
    assert main([*argv, "--out", str(chunked), *psd, "--chunk", "0.05"]) == 0
    a, b = (np.loadtxt(f, delimiter=",", skiprows=1) for f in (whole, chunked))
    assert np.max(np.abs(a[:, 7:13] - b[:, 7:13]) / a[:, 13:]) < 1e-5
    assert not list(tmp_path.glob(".*.part"))  # no temporary file left behind


def test_cli_estimate_smooth_screens_rows_like_estimate_and_reads_every_format(
    tmp_path, ur5_log, capsys
) -> None:
    """One output row per log row: an unreadable row is a dropped sample, a row back in time
    is skipped (NaN, reported); a Parquet copy of the log gives the same numbers."""
    pd = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    from pinobs.cli import main
    from pinobs.io import write_log

    rows = slice(1, 201)
    t, q, tau = ur5_log.t[rows].copy(), ur5_log.q_meas[rows].copy(), ur5_log.tau[rows]
    t[120] = t[100]  # back in time: skipped
    log = write_log(tmp_path / "log.csv", t, q, tau)
    text = log.read_text().splitlines()
    text[51] = text[51].replace(text[51].split(",")[3], "oops", 1)  # row 50: q2 unreadable
    log.write_text("\n".join(text) + "\n")
    out = tmp_path / "est.csv"
    argv = ["estimate", "--robot", "ur5", "--observer", "ekf", "--out", str(out)]
    assert main([*argv, "--log", str(log), "--smooth", "--noise", "1e-4"]) == 0
    err = capsys.readouterr()
    assert "not after the previous sample" in err.err and "oops" in err.err.lower()
    assert "200 rows: 199 estimated (198 with their measurement" in err.out
    got = np.loadtxt(out, delimiter=",", skiprows=1)
    assert got.shape == (200, 19)
    assert np.all(np.isnan(got[120, 7:])) and np.all(np.isfinite(got[50, 7:]))
    frame = pd.read_csv(log)
    frame["q2"] = pd.to_numeric(frame["q2"], errors="coerce")
    frame.to_parquet(tmp_path / "log.parquet")
    out2 = tmp_path / "est2.csv"
    argv[-1] = str(out2)
    assert main([*argv, "--log", str(tmp_path / "log.parquet"), "--smooth", "--noise", "1e-4"]) == 0
    np.testing.assert_allclose(np.loadtxt(out2, delimiter=",", skiprows=1), got, rtol=0, atol=1e-12)


def test_cli_labels_each_stretch_it_smooths(tmp_path, ur5_log, capsys) -> None:
    """A gap of 21 periods restarts the smoother: two stretches, each with its own ρ, which
    were printed as two bare lines; each now says which stretch and times it is."""
    from pinobs.cli import main
    from pinobs.io import write_log

    keep = np.r_[1:250, 270:601]
    log = write_log(tmp_path / "log.csv", ur5_log.t[keep], ur5_log.q_meas[keep], ur5_log.tau[keep])
    argv = ["estimate", "--robot", "ur5", "--observer", "ekf", "--log", str(log)]
    argv += ["--out", str(tmp_path / "e.csv")]
    assert main([*argv, "--smooth", "--noise", "1e-4", "--accel-psd", "1e-4"]) == 0
    err = capsys.readouterr().err
    assert "stretch 1 of 2, t = 0.001 to 0.249 s:" in err
    assert "stretch 2 of 2, t = 0.27 to 0.6 s:" in err
    assert err.count("filter–smoother consistency ρ") == 2


def test_streamed_smoothing_of_a_log_file_equals_the_recorded_one_through_gaps_and_restarts(
    tmp_path, ur5_log
) -> None:
    """Read 37 rows at a time; an unreadable row, a row back in time, a 5-period gap
    (propagated in sub-steps) and a 20-period gap (a restart: two stretches).  Streaming
    keeps only chunk + overlap samples and gives the numbers of smoothing at the end."""
    from pinobs.io import write_log
    from pinobs.io.smoothing import smooth_log

    keep = np.r_[1:100, 104:250, 270:601]  # gaps of 5 and 21 periods
    t, q, tau = ur5_log.t[keep].copy(), ur5_log.q_meas[keep].copy(), ur5_log.tau[keep]
    t[150] = t[140]  # back in time: skipped
    q[50, 2] = np.nan  # unreadable: a dropped sample
    log = write_log(tmp_path / "log.csv", t, q, tau)
    opts = {"noise_std": 1e-4, "accel_psd": 1e-4, "lag": 0.03, "chunk_rows": 37}
    robot = cached_robot("ur5")
    run_s, o_s = smooth_log(log, robot, tmp_path / "s.csv", **opts)  # type: ignore[arg-type]
    run_r, o_r = smooth_log(log, robot, tmp_path / "r.csv", stream=False, **opts)  # type: ignore[arg-type]
    # one ρ for the stream: the stretches' terms pooled
    pooled = sum(o["consistency"] * o["consistency_terms"] for o in o_r)
    n = sum(o["consistency_terms"] for o in o_r)
    assert o_s[0]["consistency_terms"] == n > 0
    assert o_s[0]["consistency"] == pytest.approx(pooled / n, rel=1e-12)
    a, b = (np.loadtxt(tmp_path / f, delimiter=",", skiprows=1) for f in ("s.csv", "r.csv"))
    assert a.shape == b.shape == (len(keep), 19)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    assert np.all(np.isnan(a[150, 7:])) and np.all(np.isfinite(a[50, 7:]))
    assert len(o_r) == 2  # the restart after the long gap
    assert (run_s.rows, run_s.estimated, run_s.bad_rows) == (
        run_r.rows,
        run_r.estimated,
        run_r.bad_rows,
    )
    assert run_s.estimated == len(keep) - 1 and run_s.t.size == 0  # streamed: nothing kept


@pytest.mark.parametrize("stream", [False, True])
def test_smoothed_rows_with_their_measurement_are_counted_among_the_estimated(
    tmp_path, ur5_log, stream: bool
) -> None:
    """A stretch of one sample (a restart right after the first row) gets no estimate, and is
    not counted as estimated with its measurement (the summary said "-1 propagated only")."""
    from pinobs.io import write_log
    from pinobs.io.smoothing import smooth_log

    robot = cached_robot("ur5")
    t = np.array(ur5_log.t[1:])
    t[1:] += 100.0  # a restart after the first row
    log = write_log(tmp_path / "log.csv", t, ur5_log.q_meas[1:], ur5_log.tau[1:])
    run, _ = smooth_log(
        log, robot, tmp_path / "s.csv", noise_std=1e-4, accel_psd=1e-4,
        **({"lag": 0.1} if stream else {}),
    )  # fmt: skip
    assert (run.rows, run.estimated, run.measured) == (t.size, t.size - 1, t.size - 1)
    assert "0 propagated only" in run.summary()


def test_cli_estimate_smooth_checks_the_rate_and_says_pinobs_warnings_plainly(
    tmp_path, ur5_log, capsys
) -> None:
    """``--rate`` is checked with ``--smooth`` as without (a negative rate flagged every row
    as a gap and wrote NaN; 0 meant "from the log"); a pinobs warning prints as
    ``warning: …`` (as the run's own warnings), not as Python's file and line."""
    from pinobs.cli import main
    from pinobs.io import write_log

    log = write_log(tmp_path / "log.csv", ur5_log.t[1:], ur5_log.q_meas[1:], ur5_log.tau[1:])
    argv = ["estimate", "--robot", "ur5", "--observer", "ekf", "--log", str(log), "--noise", "1e-4"]
    argv += ["--smooth"]
    for rate in ("-5", "0"):
        assert main([*argv, "--out", str(tmp_path / "r.csv"), "--rate", rate]) == 2
        assert f"rate={float(rate)!r} is out of range" in capsys.readouterr().err
    with warnings.catch_warnings():
        warnings.simplefilter("always", CostWarning)
        assert main([*argv, "--out", str(tmp_path / "c.csv"), "--chunk", "0.002"]) == 0
    err = capsys.readouterr().err
    assert "\nwarning: chunk=0.002 s with an overlap of" in f"\n{err}" and ".py:" not in err


def test_smooth_log_and_the_cli_estimate_the_noise_when_none_is_given(
    tmp_path, ur5_log, capsys
) -> None:
    """``smooth_log`` (and ``estimate --smooth`` without ``--noise``): σ̂ from the first
    chunk's first second, as :func:`pinobs.smooth` takes it, reported in the run."""
    from pinobs.cli import main
    from pinobs.io import write_log
    from pinobs.io.smoothing import smooth_log

    robot = cached_robot("ur5")
    log = write_log(tmp_path / "log.csv", ur5_log.t[1:], ur5_log.q_meas[1:], ur5_log.tau[1:])
    with pytest.warns(NoiseWarning):
        direct = smooth(robot, _log(ur5_log), accel_psd=1e-4)
    run, stretches = smooth_log(log, robot, tmp_path / "s.csv", accel_psd=1e-4)
    assert run.noise_std == stretches[0]["noise_std"] == direct.options["noise_std"]
    assert run.noise_std == pytest.approx(1e-4, rel=0.1)  # the simulated σ
    assert run.noise_std_per_joint is not None and run.noise_std_per_joint.shape == (robot.nv,)
    assert "estimated σ = " in run.warnings[0]
    est = np.loadtxt(tmp_path / "s.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(est[:, 7:13], direct.v[1:])
    out = tmp_path / "cli.csv"
    argv = ["estimate", "--robot", "ur5", "--observer", "ekf", "--log", str(log), "--out"]
    assert main([*argv, str(out), "--smooth", "--accel-psd", "1e-4"]) == 0
    assert "warning: no noise level given: estimated σ = " in capsys.readouterr().err
    np.testing.assert_array_equal(np.loadtxt(out, delimiter=",", skiprows=1), est)


def test_cli_estimate_smooth_writes_the_playback_of_the_smoothed_estimate(
    tmp_path, ur5_log, capsys
) -> None:
    """``--smooth --html``: the logged motion and the smoothed estimate (it was ignored);
    the estimates kept for it are those the streamed run writes."""
    from pinobs.cli import main
    from pinobs.io import write_log

    log = write_log(tmp_path / "log.csv", ur5_log.t[1:], ur5_log.q_meas[1:], ur5_log.tau[1:])
    argv = ["estimate", "--robot", "ur5", "--observer", "ekf", "--log", str(log), "--noise"]
    argv += ["1e-4", "--smooth", "--lag", "0.05", "--accel-psd", "1e-4", "--out"]
    html = tmp_path / "play.html"
    assert main([*argv, str(tmp_path / "a.csv"), "--html", str(html)]) == 0
    assert "(the logged motion, and the estimate as a ghost)" in capsys.readouterr().out
    assert html.stat().st_size > 10_000 and "ekf smoothed" in html.read_text()
    assert main([*argv, str(tmp_path / "b.csv")]) == 0  # streamed, nothing kept
    a, b = (np.loadtxt(tmp_path / f, delimiter=",", skiprows=1) for f in ("a.csv", "b.csv"))
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_cli_estimate_smooth_over_adaptive_says_how_its_model_was_frozen(
    tmp_path, ur5_log, capsys
) -> None:
    from pinobs.cli import main
    from pinobs.io import write_log

    rows = slice(1, 301)
    log = write_log(tmp_path / "log.csv", ur5_log.t[rows], ur5_log.q_meas[rows], ur5_log.tau[rows])
    out = tmp_path / "est.csv"
    argv = ["estimate", "--robot", "ur5", "--observer", "adaptive", "--log", str(log)]
    assert main([*argv, "--out", str(out), "--smooth", "--noise", "1e-4"]) == 0
    err = capsys.readouterr().err
    assert "learned model frozen per 10 s window" in err
    assert "filter–smoother consistency ρ = " in err
    assert "times √max(1, ρ) = " in err and "(--band inflated;" in err  # adaptive's default
    inflated = np.loadtxt(out, delimiter=",", skiprows=1)
    assert np.all(np.isfinite(inflated))
    bands = {}
    for band in ("noise", "model"):
        path = tmp_path / f"{band}.csv"
        assert main([*argv, "--out", str(path), "--smooth", "--noise", "1e-4", "--band", band]) == 0
        bands[band] = np.loadtxt(path, delimiter=",", skiprows=1)
        np.testing.assert_array_equal(bands[band][:, :13], inflated[:, :13])  # the same estimate
    assert np.all(bands["model"][:, 13:] > bands["noise"][:, 13:])  # without the modelled noise
    ratio = inflated[:, 13:] / bands["noise"][:, 13:]
    assert np.all(ratio >= 1.0) and np.ptp(ratio) < 1e-12  # one factor, √max(1, ρ)


@pytest.mark.slow  # 10-21 s on a 2-core machine: the default run stays under 10 min
def test_a_log_the_model_does_not_explain_is_said_and_auto_skips_densities_that_lose_the_filter(
    tmp_path, monkeypatch, capsys
) -> None:
    """A UR5 log with 20 % inertia error and a payload (nominal model, 4.5 s).  At small
    densities the filter is lost (1e-13: at 4.09 s): ``"auto"`` rejects such a candidate
    instead of failing.  At the default density the estimate follows the model error with
    a band far too narrow, which is said (ρ ≫ RHO_WARN); ``"auto"`` at its grid's largest
    density is said too (the model explains the log no better than white acceleration)."""
    from pinobs.cli import main
    from pinobs.io import write_log

    robot = cached_robot("ur5")
    res = _mismatched_log("ur5", "inertia20_payload", 4.5)
    with pytest.raises(
        pinobs.errors.NonFiniteError, match=r"\(t = 4.09\d* s\): the filter is lost"
    ):
        smooth(robot, _log(res), noise_std=1e-4, accel_psd=1e-13)
    assert select_accel_psd(robot, _log(res), noise_std=1e-4, grid=(1e-13, 1e-2)) == 1e-2
    with pytest.warns(ConsistencyWarning, match="does not explain the log") as said:
        default = smooth(robot, _log(res), noise_std=1e-4)
    assert default.consistency > 1e6 and len(said) == 1
    assert "model band is too narrow, by about √ρ" in str(said[0].message)
    # a latency was searched for (none was given) and none explains the log: kept as stamped
    assert default.options["latency_searched"] and default.options["latency"] == 0.0
    assert "no measurement latency of up to 3 sample intervals explains it" in str(said[0].message)
    late = res.t > 1.0
    cover = np.mean(np.abs(default.v - res.v)[late] <= 2 * default.v_std[late])
    assert cover < 0.1  # why it is said
    grid = (1e-13, 1e-2, 1.0)
    monkeypatch.setattr(pipeline, "DEFAULT_GRID", grid)  # the density chosen
    monkeypatch.setattr(api, "DEFAULT_GRID", grid)  # its warning
    with pytest.warns(ConsistencyWarning, match="chose 1 rad²/s³, the largest it tries"):
        auto = smooth(robot, _log(res), noise_std=1e-4, accel_psd="auto")
    assert auto.options["accel_psd"] == 1.0
    log = write_log(tmp_path / "log.csv", res.t[1:], res.q_meas[1:], res.tau[1:])
    argv = ["estimate", "--robot", "ur5", "--observer", "ekf", "--log", str(log)]
    argv += ["--out", str(tmp_path / "s.csv")]
    assert main([*argv, "--smooth", "--noise", "1e-4"]) == 0
    assert "warning: the model does not explain the log: filter–smoother" in capsys.readouterr().err


def test_retimed_log_puts_each_sample_at_the_time_it_was_taken_and_torques_at_theirs() -> None:
    """A latency d: the sample stamped t_k was taken at t_k − d; the torque switches at t_k."""
    t = np.array([0.0, 1.0, 2.0, 3.0]) * 1e-3
    q, tau = np.arange(4.0)[:, None], 10 * np.arange(4.0)[:, None]
    times, q_r, tau_r, rows = logs.retimed(t, q, tau, 0.4e-3)
    np.testing.assert_allclose(times, [-0.4, 0, 0.6, 1, 1.6, 2, 2.6, 3] * np.array(1e-3))
    np.testing.assert_array_equal(q_r[::2, 0], [0, 1, 2, 3])
    assert np.all(np.isnan(q_r[1::2]))  # the stamped times: predicted over
    np.testing.assert_array_equal(tau_r[:, 0], [0, 0, 0, 10, 10, 20, 20, 30])
    np.testing.assert_array_equal(times[rows], t)  # the estimates come out at the stamped times
    times, q_r, tau_r, rows = logs.retimed(t, q, tau, 1e-3)  # a whole interval: merged
    np.testing.assert_allclose(times, [-1e-3, 0, 1e-3, 2e-3, 3e-3])
    np.testing.assert_array_equal(q_r[:4, 0], [0, 1, 2, 3])
    assert np.all(np.isnan(q_r[4]))
    np.testing.assert_array_equal(tau_r[:, 0], [0, 0, 10, 20, 30])
    np.testing.assert_array_equal(rows, [1, 2, 3, 4])


def _late_log(latency_steps: int, rate: float, duration: float) -> tuple[np.ndarray, ...]:
    """A UR5 log at 1 kHz whose positions were taken ``latency_steps / rate`` s before their
    stamps: simulated at ``rate`` with the sensor ``latency_steps`` samples late and the PD
    torque held over each 1 ms, then every ``rate / 1000``-th row kept."""
    from pinobs.simulation.inputs import InputProfile, make_input

    robot = cached_robot("ur5")
    pd = make_input("pd", robot, rng=np.random.default_rng(0))

    class Held(InputProfile):  # the torque of the 1 kHz controller
        name = "held"

        def __init__(self) -> None:
            self.last: np.ndarray | None = None

        def torque(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
            if self.last is None or abs(t * 1e3 - round(t * 1e3)) < 1e-6:
                self.last = pd.torque(t, q, v)
            return self.last

    sensor = Sensor(rate, 1e-4, delay=latency_steps)
    res = simulate(robot, [], sensor=sensor, inputs=Held(), duration=duration, seed=0)
    keep = slice(None, None, round(rate / 1000))
    return res.t[keep], res.q_meas[keep], res.tau[keep], res.v[keep]


@pytest.mark.slow  # 6-8 s on a 2-core machine: the default run stays under 10 min
def test_a_known_latency_is_smoothed_on_the_times_the_samples_were_taken() -> None:
    """0.5 ms latency (half a sample interval) given: the error is the exact-model
    smoother's and the band covers; not given (or wrong), ρ says the model does not explain
    the log.  Measured: RMS 1.05e-5 with the latency, 25–55× more with 0, 0.25, 0.75, 1 ms.
    A streamed smoother cannot re-time the log: it refuses the latency."""
    robot = cached_robot("ur5")
    t, q, tau, v = _late_log(1, 2000.0, 3.0)
    late = t > 0.5
    opts = {"noise_std": 1e-4, "accel_psd": 1e-10}
    given = smooth(robot, (t, q, tau), filter_options={"latency": 0.5e-3}, **opts)  # type: ignore[arg-type]
    assert given.options["latency"] == 0.5e-3
    np.testing.assert_array_equal(given.t, t)
    err = np.abs(given.v - v)[late]
    assert np.sqrt(np.mean(err**2)) < 2e-5  # measured 1.05e-5
    assert 0.90 <= np.mean(err <= 2 * given.v_std[late]) <= 0.98  # measured 95.2 %
    assert given.consistency < 2.0  # measured 0.79
    with pytest.warns(ConsistencyWarning, match="does not explain the log"):
        blind = smooth(robot, (t, q, tau), filter_options={"latency": 0.0}, **opts)  # type: ignore[arg-type]
    assert np.sqrt(np.mean((blind.v - v)[late] ** 2)) > 20 * np.sqrt(np.mean(err**2))
    # none given: the log as stamped is not explained (ρ 3.8e3), so the latency is searched,
    # found, adopted (ρ with it below RHO_WARN) and said
    with pytest.warns(LatencyWarning, match="0.5 ms late"):
        found = smooth(robot, (t, q, tau), **opts)  # type: ignore[arg-type]
    assert found.options["latency"] == pytest.approx(0.5e-3, abs=1e-12)
    assert found.options["latency_from_log"] and found.options["latency_searched"]
    assert found.options["consistency_without_latency"] > 1e3
    np.testing.assert_allclose(found.v, given.v, rtol=0, atol=1e-12)
    # chunked equals whole to the stated tolerance (the overlap from the measurement interval,
    # not the re-timed rows'; measured 2.3e-6, 1.0e-5 when it took the rows')
    short = {"noise_std": 1e-4, "accel_psd": 1e-6, "filter_options": {"latency": 0.5e-3}}
    whole = smooth(robot, (t, q, tau), **short)  # type: ignore[arg-type]
    chunked = smooth(robot, (t, q, tau), chunk=0.5, **short)  # type: ignore[arg-type]
    after = t > 0.1
    assert np.max(np.abs(chunked.v - whole.v)[after] / whole.v_std[after]) < 5e-6
    with pytest.raises(OptionError, match="re-times the whole log"):
        streaming_smoother(
            robot, dt=1e-3, noise_std=1e-4, accel_psd=1e-10, lag=0.1,
            filter_options={"latency": 1e-3},
        )  # fmt: skip
    with pytest.raises(GainError, match="latency"):
        smooth(robot, (t, q, tau), filter_options={"latency": -1e-3}, **opts)  # type: ignore[arg-type]
    # unknown: the likeliest of 0, 1, 2 intervals (ℓ falls from 1 on), then the parabola's
    # vertex, 0.5 intervals (no truth used): 4 passes (8 with the halvings before)
    found, tried = select_latency(robot, (t, q, tau), noise_std=1e-4, accel_psd=1e-10)
    assert found == pytest.approx(0.5e-3, abs=1e-12) and len(tried) == 4
    assert max(tried, key=lambda p: p[1])[0] == found
    auto = smooth(robot, (t, q, tau), filter_options={"latency": "auto"}, **opts)  # type: ignore[arg-type]
    assert auto.options["latency_from_log"] and auto.options["latency"] == found
    np.testing.assert_allclose(auto.v, given.v, rtol=0, atol=1e-12)
    assert given.options["latency_from_log"] is False
    with pytest.raises(OptionError, match="latency='auto'"):
        streaming_smoother(
            robot, dt=1e-3, noise_std=1e-4, accel_psd=1e-10, lag=0.1,
            filter_options={"latency": "auto"},
        )  # fmt: skip


@pytest.mark.slow  # 10-21 s on a 2-core machine: the default run stays under 10 min
def test_auto_density_does_not_hide_an_unknown_latency() -> None:
    """accel_psd='auto' over ekf explains any log (ρ about 1): on a UR5 log 2 ms late it took
    1e-2 rad²/s³ as stamped, RMS 9.45e-3 rad/s and a 62.5 % band, and said nothing.  A density
    above ekf's own now searches the latency, adopts it (it explains the log at ekf's own
    density and is likelier under 'auto'), and says so.  Measured: 2 ms, 1e-10 rad²/s³, RMS
    7.05e-6.  On the exact-model log as stamped 'auto' takes 1e-10 and no search runs."""
    robot = cached_robot("ur5")
    t, q, tau, v = _late_log(2, 1000.0, 3.0)
    late = t > 0.5
    with pytest.warns(LatencyWarning, match=r"2 ms late.*accel_psd='auto' took 0.01 rad²/s³"):
        found = smooth(robot, (t, q, tau), noise_std=1e-4, accel_psd="auto")
    assert found.options["latency"] == 2e-3  # exactly: the search's candidates are rounded
    assert found.options["accel_psd_without_latency"] == 1e-2
    err = np.abs(found.v - v)[late]
    assert np.sqrt(np.mean(err**2)) < 2e-5  # measured 7.05e-6
    covered = np.mean(err <= 2 * found.v_std[late])  # measured 98.5 %
    t0, q0, tau0, v0 = _late_log(0, 1000.0, 3.0)
    stamped = smooth(robot, (t0, q0, tau0), noise_std=1e-4, accel_psd="auto")
    assert stamped.options["accel_psd"] == 1e-10 and not stamped.options["latency_searched"]
    # the band is as calibrated as on the log without latency (98.5 % there too: 'auto's
    # band on this log is a little wide of the 90-98 % target, latency or not)
    err0 = np.abs(stamped.v - v0)[late]
    assert abs(covered - np.mean(err0 <= 2 * stamped.v_std[late])) < 0.01


def test_adaptive_with_a_known_latency_learns_and_smooths_on_the_sample_times() -> None:
    """``adaptive`` given the latency: its learning pass takes it (as the causal observer
    does) and the frozen-model pass runs on the re-timed log (each row in the window of the
    latest stamp at or before it).  UR5, exact model, positions one sample (1 ms) late, 6 s.
    Measured after 3 s: RMS 1.7e-5 given (band 93.6 %, ρ 0.59), 4.7e-3 not (ρ 24, warned)."""
    robot = cached_robot("ur5")
    t, q, tau, v = _late_log(1, 1000.0, 6.0)
    late = t > 3.0
    opts = {"observer": "adaptive", "noise_std": 1e-4, "model_window": 3.0}
    given = smooth(robot, (t, q, tau), filter_options={"latency": 1e-3}, **opts)  # type: ignore[arg-type]
    assert given.options["latency"] == 1e-3 and given.options["blend"] is True
    rms = np.sqrt(np.mean((given.v - v)[late] ** 2))
    with pytest.warns(ConsistencyWarning):
        blind = smooth(robot, (t, q, tau), filter_options={"latency": 0.0}, **opts)  # type: ignore[arg-type]
    assert rms < 0.1 * np.sqrt(np.mean((blind.v - v)[late] ** 2)), rms
    assert 0.90 <= np.mean(np.abs(given.v - v)[late] <= 2 * given.v_std[late]) <= 0.98


def test_cli_estimate_takes_a_latency_filtered_smoothed_and_over_many_logs(
    tmp_path, capsys
) -> None:
    """``estimate --latency S`` (the causal observer's ``latency=``), ``--smooth --latency
    S|auto`` (the smoother re-times the log), and with ``--out-dir`` every log gets it.
    UR5, positions 1 ms late."""
    from pinobs.cli import main
    from pinobs.io import write_log

    t, q, tau, v = _late_log(1, 1000.0, 3.0)
    (tmp_path / "logs").mkdir()
    log = write_log(tmp_path / "logs" / "late.csv", t[1:], q[1:], tau[1:])
    late = t[1:] > 0.5
    base = ["estimate", "--robot", "ur5", "--observer", "ekf", "--log", str(log)]
    base += ["--noise", "1e-4", "--no-progress"]

    def rms(path: Path) -> float:
        est = np.loadtxt(path, delimiter=",", skiprows=1)
        return float(np.sqrt(np.mean((est[:, 7:13] - v[1:])[late] ** 2)))

    runs = {
        "blind": [],
        "given": ["--latency", "1e-3"],
        "smoothed": ["--smooth", "--accel-psd", "1e-10", "--latency", "auto"],
    }
    for name, extra in runs.items():
        assert main([*base, "--out", str(tmp_path / f"{name}.csv"), *extra]) == 0, name
    assert "latency = 0.001 s (chosen from the log)" in capsys.readouterr().err
    assert rms(tmp_path / "given.csv") < 0.05 * rms(tmp_path / "blind.csv")
    assert rms(tmp_path / "smoothed.csv") < rms(tmp_path / "given.csv")
    assert main([*base, "--out", str(tmp_path / "x.csv"), "--latency", "auto"]) == 2
    assert "--latency auto is chosen from the whole log by the smoother" in capsys.readouterr().err
    many = [*base[:5], "--log", str(tmp_path / "logs"), "--noise", "1e-4", "--no-progress"]
    assert (
        main([*many, "--out-dir", str(tmp_path / "out"), "--workers", "0", "--latency", "1e-3"])
        == 0
    )
    assert (tmp_path / "out" / "late.csv").read_bytes() == (tmp_path / "given.csv").read_bytes()
    # --smooth with no --latency: found (the log as stamped is not explained) and said; the
    # summary calls the log consistent (with the latency it is)
    capsys.readouterr()
    smoothed = [*base, "--out", str(tmp_path / "found.csv"), "--smooth", "--accel-psd", "1e-10"]
    assert main(smoothed) == 0
    said = capsys.readouterr().err
    assert "warning: the model explains the log only with a measurement latency: its " in said
    assert "1 ms late" in said
    assert rms(tmp_path / "found.csv") == rms(tmp_path / "smoothed.csv")
    out = tmp_path / "out_smoothed"
    many += ["--smooth", "--accel-psd", "1e-10", "--workers", "0", "--out-dir", str(out)]
    assert main(many) == 0
    summary = pytest.importorskip("pandas").read_parquet(out / "summary.parquet")
    assert summary["consistency"].tolist() == ["consistent"] and summary["rho"][0] < 2.0
    assert summary["latency"].tolist() == [1e-3]  # the latency found, in the table too
    assert "latency" in capsys.readouterr().out


@pytest.mark.slow
def test_adaptive_finds_an_unknown_latency_from_the_log() -> None:
    """``filter_options={"latency": "auto"}`` over ``adaptive``: a learning pass and a
    frozen-model pass per candidate (3 here: 0, 1, 2 ms, the vertex at 1); the 1 ms found, and the
    estimate as with the latency given; so too with no latency given (found because the log as
    stamped is not explained).  Measured: 1 ms found; RMS after 3 s 1.7e-5."""
    robot = cached_robot("ur5")
    t, q, tau, v = _late_log(1, 1000.0, 6.0)
    late = t > 3.0
    opts = {"observer": "adaptive", "noise_std": 1e-4, "model_window": 3.0}
    auto = smooth(robot, (t, q, tau), filter_options={"latency": "auto"}, **opts)  # type: ignore[arg-type]
    assert auto.options["latency"] == pytest.approx(1e-3, abs=1e-12)
    given = smooth(robot, (t, q, tau), filter_options={"latency": 1e-3}, **opts)  # type: ignore[arg-type]
    np.testing.assert_allclose(auto.v[late], given.v[late], rtol=0, atol=1e-9)
    # none given: the log as stamped is not explained (ρ 24), so the same search runs
    with pytest.warns(LatencyWarning, match="1 ms late"):
        found = smooth(robot, (t, q, tau), **opts)  # type: ignore[arg-type]
    np.testing.assert_allclose(found.v[late], given.v[late], rtol=0, atol=1e-9)
    assert np.sqrt(np.mean((auto.v - v)[late] ** 2)) < 3e-5


def test_strings_other_than_auto_are_refused(ur5_log) -> None:
    robot = cached_robot("ur5")
    with pytest.raises(GainError, match="or 'auto'"):
        smooth(robot, _log(ur5_log), noise_std=1e-4, accel_psd="big")  # type: ignore[arg-type]


@pytest.mark.parametrize("observer", ["ekf", "adaptive"])
def test_without_noise_std_sigma_is_estimated_from_the_log_warned_and_used(observer) -> None:
    """No ``noise_std``: σ̂ from the log's first second (median over joints), warned, reported,
    and used by every filter the smoother runs (before, the smoother's ``ekf`` took its
    default 1e-6: on this log ``adaptive``'s RMS was 15× the one with σ given, silently)."""
    robot = cached_robot("ur5")
    sigma = 1e-3
    res = simulate(robot, [], sensor=Sensor(1000, sigma), inputs="pd", duration=1.5, seed=2)
    opts = {"observer": observer, "accel_psd": 1e-6 if observer == "ekf" else None}
    with pytest.warns(NoiseWarning, match=r"estimated σ = .* from the log's first second"):
        found = smooth(robot, _log(res), **opts)  # type: ignore[arg-type]
    sigma_hat = found.options["noise_std"]
    assert found.options["noise_std_from_log"] is True
    assert sigma_hat == pytest.approx(sigma, rel=0.1)  # the truth's σ
    given = smooth(robot, _log(res), noise_std=sigma_hat, **opts)  # type: ignore[arg-type]
    assert given.options["noise_std_from_log"] is False
    np.testing.assert_array_equal(found.v, given.v)  # σ̂ is what every pass used
    np.testing.assert_array_equal(found.v_std, given.v_std)
    late = res.t > 0.5
    truth = smooth(robot, _log(res), noise_std=sigma, **opts)  # type: ignore[arg-type]
    rms = [float(np.sqrt(np.mean((s.v - res.v)[late] ** 2))) for s in (found, truth)]
    assert rms[0] < 1.1 * rms[1], rms


def test_without_noise_std_a_noise_free_log_takes_the_floor_and_a_short_one_is_refused() -> None:
    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 0.0), inputs="pd", duration=0.3, seed=2)
    with pytest.warns(NoiseWarning, match="taken as noise-free, σ = 1e-06 used"):
        s = smooth(robot, _log(res), accel_psd=1e-6)
    assert s.options["noise_std"] == NOISE_FLOOR
    with pytest.raises(GainError, match="too few finite rows"):
        smooth(robot, (res.t[:11], res.q_meas[:11], res.tau[:11]), accel_psd=1e-6)


def test_a_result_is_read_through_its_measurements_not_its_truth(ur5_log) -> None:
    robot = cached_robot("ur5")
    from_result = smooth(robot, ur5_log, noise_std=1e-4, accel_psd=1e-2)
    from_log = smooth(robot, _log(ur5_log), noise_std=1e-4, accel_psd=1e-2)
    np.testing.assert_array_equal(from_result.v, from_log.v)
    assert np.isnan(from_result.v[0, 0])  # sample 0 is not measured (its truth is known)


# ------------------------------------------------------------- adaptive, model frozen per window
def _mismatched_log(name: str, scenario: str, duration: float, seed: int = 1) -> pinobs.Result:
    from pinobs.simulation.mismatch import mismatched_plant

    robot = cached_robot(name)
    plant = mismatched_plant(robot, scenario, seed=0)
    return simulate(robot, [], sensor=Sensor(1000, 1e-4), duration=duration, seed=seed, plant=plant)


@pytest.mark.slow  # 6-8 s on a 2-core machine: the default run stays under 10 min
@pytest.mark.filterwarnings("ignore::pinobs.errors.ConsistencyWarning")  # 1.2 s: ρ = 133
def test_adaptive_is_smoothed_with_its_model_frozen_per_window_and_chunks_change_nothing() -> None:
    """The learning pass runs once; each window's model is the one the causal pass held at the
    window's end (its regime reported).  Chunking is a memory device only: it does not change
    the windows, so chunked equals whole-log to the stated tolerance, across the windows'
    model switches and from the first sample."""
    robot = cached_robot("planar_3r")
    res = _mismatched_log("planar_3r", "inertia20_payload", 1.2)
    # accel_psd replaces every window's density, the offset's scaled with it
    opts = {"observer": "adaptive", "noise_std": 1e-4, "model_window": 0.5, "accel_psd": 1e-2}
    whole = smooth(robot, _log(res), **opts)  # type: ignore[arg-type]
    assert whole.options["model_window"] == 0.5
    assert len(whole.options["model_regimes"]) == 3  # [0, 0.5), [0.5, 1), [1, 1.2]
    assert set(whole.options["model_regimes"]) <= {"warmup", "nominal", "learned"}
    assert np.all(np.isfinite(whole.v[1:])) and np.all(whole.v_std[1:] > 0)

    # Chunked: a log longer than a window plus its overlap, 20 model windows of 0.7 s.  Before
    # the overlap took the offset's slow pole through M⁻¹ (default_overlap), 0.41 s of overlap
    # left 3.2e-3 of v_std at the model switch at 0.7 s; it is 9.4 s here.
    res = _mismatched_log("planar_3r", "inertia20_payload", 14.0)
    opts["model_window"] = 0.7
    whole = smooth(robot, _log(res), **opts)  # type: ignore[arg-type]
    chunked = smooth(robot, _log(res), chunk=3.0, **opts)  # type: ignore[arg-type]
    assert len(whole.options["model_regimes"]) == 20
    q = res.q_meas[1:]
    configs = q[np.unique(np.linspace(0, len(q) - 1, 32).astype(int))]
    masses = [robot.mass_matrix(c) for c in configs]
    want = max(
        default_overlap(1e-2, 1e-4, 1e-3, disturbance_psd=d * 1e-2 / a, mass_matrices=masses)
        for a, d in whole.options["model_densities"]
    )
    assert chunked.options["overlap"] == pytest.approx(want, abs=1e-3)
    assert 3.0 + want < 13.0  # the windows do not all reach the log's end
    rel = np.max(np.abs(chunked.v - whole.v)[1:] / whole.v_std[1:])
    assert rel < 1e-5  # CHUNK_TOL = 1e-6 aimed at; measured 1.3e-8 (1.1e-9 after 0.1 s)
    np.testing.assert_allclose(chunked.v_std[1:], whole.v_std[1:], rtol=1e-6)


def _snapshots(monkeypatch, robot, res, bank: bool | None, **options) -> tuple[list, list[bool]]:
    """The learning pass's snapshots, and the ``blend`` of each observer it made (``bank``:
    forced on or off; ``None``: as :func:`pinobs.smoothing.replay.learned_models` chooses)."""
    made: list[bool] = []

    def make(name, robot, **kw):  # type: ignore[no-untyped-def]
        if bank is not None:
            kw["blend"] = bank
        made.append(kw["blend"])
        return make_observer(name, robot, **kw)

    monkeypatch.setattr(replay, "make_observer", make)
    t, q, tau = res.t[1:], res.q_meas[1:], res.tau[1:]  # sample 0 is not measured
    maker, _ = replay.learned_models(robot, t, q, tau, np.ones(t.size, bool), 1e-4, options, 0.5)
    monkeypatch.undo()
    return list(maker(None)._snaps), made


def _same_snapshots(a: list, b: list, robot: pinobs.Robot) -> None:
    rng = np.random.default_rng(0)
    q, v = robot.random_configuration(rng), rng.normal(size=robot.nv)
    acc = rng.normal(size=robot.nv)
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert (x.regime, x.accel_psd) == (y.regime, y.accel_psd)
        np.testing.assert_array_equal(x.offset, y.offset)
        np.testing.assert_array_equal(x.disturbance_psd, y.disturbance_psd)
        for f in (lambda r: r.inverse_dynamics(q, v, acc), lambda r: r.friction_torque(v)):
            np.testing.assert_array_equal(f(x.robot), f(y.robot))


def test_the_learning_pass_runs_without_the_bank_and_learns_the_same_models(monkeypatch) -> None:
    """The learning pass leaves out the blend's model-free bank (it costs ~10 %): the models
    learned do not depend on it.  Where the bank matters, a lost model-based filter that it
    would restart (the adaptive test's friction log), the pass is run again with it."""
    robot = cached_robot("planar_3r")
    res = _mismatched_log("planar_3r", "inertia20_payload", 1.2)
    plain, made = _snapshots(monkeypatch, robot, res, None)
    assert made == [False]  # one pass, no bank
    with_bank, _ = _snapshots(monkeypatch, robot, res, True)
    assert {s.regime for s in plain} != {"warmup"}  # something was learned
    _same_snapshots(plain, with_bank, robot)

    robot = cached_robot("ur5")
    res = _mismatched_log("ur5", "friction", 5.6)  # lost at 5.47 s without friction columns
    plain, made = _snapshots(monkeypatch, robot, res, None, friction=False)
    assert made == [False, True]  # lost without the bank: run again with it
    with_bank, _ = _snapshots(monkeypatch, robot, res, True, friction=False)
    _same_snapshots(plain, with_bank, robot)
    # the user's blend=False is the user's filter: lost, it is not rerun with a bank
    with pytest.raises(pinobs.errors.ObserverDiverged):
        _snapshots(monkeypatch, robot, res, None, friction=False, blend=False)


def test_auto_densities_over_adaptive_make_the_filter_smoother_consistency_one() -> None:
    """``accel_psd="auto"`` over ``adaptive``: white acceleration at AUTO_WHITE_SCALE of the
    regimes', the offset density scaled until ρ = 1 (secant; ρ falls as the scale grows)."""
    robot = cached_robot("planar_3r")
    res = _mismatched_log("planar_3r", "inertia20_payload", 2.0)
    opts = {"observer": "adaptive", "noise_std": 1e-4, "model_window": 1.0}
    scale = consistent_offset_scale(robot, _log(res), noise_std=1e-4, model_window=1.0)
    auto = smooth(robot, _log(res), accel_psd="auto", **opts)  # type: ignore[arg-type]
    assert auto.options["offset_scale"] == scale
    assert OFFSET_SCALE_RANGE[0] < scale < OFFSET_SCALE_RANGE[1]
    assert auto.consistency == pytest.approx(1.0, abs=0.05)
    regime = smooth(robot, _log(res), **opts)  # type: ignore[arg-type]
    white = [AUTO_WHITE_SCALE * a for a in regime.options["model_accel_psd"]]
    assert auto.options["model_accel_psd"] == pytest.approx(white)
    with pytest.raises(GainError, match="at least 1 smoother pass"):
        consistent_offset_scale(robot, _log(res), noise_std=1e-4, max_passes=0)
    with pytest.raises(GainError, match="tol"):
        consistent_offset_scale(robot, _log(res), noise_std=1e-4, tol=0.0)


def test_adaptive_smoothing_options_that_do_not_apply_are_refused(ur5_log) -> None:
    robot = cached_robot("ur5")
    with pytest.raises(OptionError, match=r"model_window=1\.0 is for a filter that learns"):
        smooth(robot, _log(ur5_log), noise_std=1e-4, model_window=1.0)
    with pytest.raises(OptionError, match="adaptive's densities are its regimes'"):
        smooth(robot, _log(ur5_log), observer="adaptive", noise_std=1e-4, disturbance_psd=1.0)
    with pytest.raises(GainError, match="model_window"):
        smooth(robot, _log(ur5_log), observer="adaptive", noise_std=1e-4, model_window=-1.0)
    with pytest.raises(OptionError, match=r"model_window=0\.0001 s is shorter than the log's"):
        smooth(robot, _log(ur5_log), observer="adaptive", noise_std=1e-4, model_window=1e-4)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "scenario"),
    [
        ("ur5", "inertia20_payload"),
        ("ur5", "torque_scale"),
        ("ur5", "friction"),
        ("panda", "inertia20_payload"),
        ("panda", "torque_scale"),
        ("panda", "friction"),
    ],
)
def test_adaptive_smoother_targets_under_model_error(name: str, scenario: str) -> None:
    """Issue 19 under the learning benchmark's model errors (``benchmarks/learning.py``: 12 s,
    σ = 1e-4, seed 1, RMS after 5 s): ≥ 2× below causal ``adaptive``, which is fed the same
    samples, and the default band (``inflated``: the noise band × √max(1, ρ), with the
    regimes' densities) covers 90–98 % (measured 92.1–96.7 %; the noise band alone 88.8 %
    on the UR5's friction log).  The ``model`` band of the same estimate is wider (98.9–100 %
    measured); ``accel_psd="auto"`` makes ρ = 1 and narrows the model band."""
    robot = cached_robot(name)
    res = _mismatched_log(name, "exact" if scenario == "torque_scale" else scenario, 12.0)
    tau = 0.9 * res.tau + 0.3 if scenario == "torque_scale" else np.array(res.tau)
    log = Log(t=res.t, q=res.q_meas, tau=tau)
    ad = make_observer("adaptive", robot, noise_std=1e-4, rate=1000.0)
    causal = estimate_log(ad, Log(t=res.t[1:], q=res.q_meas[1:], tau=tau[1:]))
    late = res.t > 5.0
    rms_c = np.sqrt(np.mean((causal.v - res.v[1:])[late[1:]] ** 2))
    cover = {}
    for psd, band in ((None, None), (None, "model"), ("auto", None)):
        s = smooth(robot, log, observer="adaptive", noise_std=1e-4, accel_psd=psd, band=band)
        rms_s = np.sqrt(np.mean((s.v - res.v)[late] ** 2))
        assert rms_c / rms_s >= 2.0
        cover[psd, s.options["band"]] = np.mean(np.abs(s.v - res.v)[late] <= 2 * s.v_std[late])
    assert s.consistency == pytest.approx(1.0, abs=0.05)
    assert cover["auto", "model"] <= cover[None, "model"]
    assert cover[None, "inflated"] < cover[None, "model"]
    assert 0.90 <= cover[None, "inflated"] <= 0.98


@pytest.mark.parametrize(
    ("peak", "lost", "want", "passes"),
    [
        (0.5, (), 0.5, 4),  # 0, 1, 2 then the vertex
        (1.0, (), 1.0, 3),  # the vertex is a whole interval: cached
        (0.8, (), 0.75, 4),  # the vertex rounded to h/4
        (2.6, (), 2.5, 5),  # ℓ still rises at 2: 3 tried, then the vertex
        (9.0, (), 3.0, 4),  # beyond the range: its end
        (1.0, (2.0,), 1.0, 7),  # a lost filter at 2: no parabola, the halvings
    ],
)
def test_latency_search_finds_a_quadratic_peak_in_few_passes(
    peak: float, lost: tuple[float, ...], want: float, passes: int
) -> None:
    """:func:`select_latency`'s search on a synthetic ``ℓ(d) = −(d − peak)²`` (in intervals
    of h = 1 ms; ``−∞`` where the filter is lost)."""
    from pinobs.smoothing.latency import _latency_search

    h, tried = 1e-3, {}

    def ll(d: float) -> float:
        if d not in tried:
            x = d / h
            lost_here = any(abs(x - b) < 1e-9 for b in lost)
            tried[d] = -np.inf if lost_here else -((x - peak) ** 2)
        return tried[d]

    _latency_search(ll, h, 3)
    assert max(tried, key=tried.__getitem__) == pytest.approx(want * h, abs=1e-12)
    assert len(tried) == passes


def test_the_latency_search_runs_no_candidate_twice(monkeypatch) -> None:
    """A log not explained as stamped (UR5, 0.5 ms late): the first pass is the search's
    candidate 0 (its preparation, over ``adaptive`` the learning pass, and its likelihood),
    and the latency found is smoothed from the search's preparation: each latency prepared
    once, and a likelihood pass for each candidate but 0."""
    robot = cached_robot("ur5")
    t, q, tau, _ = _late_log(1, 2000.0, 1.0)
    prepared: list[float] = []
    passes: list[int] = []
    real_prepare, real_ll = latency.prepare_log, latency.forward_log_likelihood

    def prepare(*args, **kwargs):  # type: ignore[no-untyped-def]
        prepared.append(logs.latency_option(args[7])[0])
        return real_prepare(*args, **kwargs)

    def ll(*args, **kwargs):  # type: ignore[no-untyped-def]
        passes.append(1)
        return real_ll(*args, **kwargs)

    monkeypatch.setattr(pipeline, "prepare_log", prepare)  # the first pass
    monkeypatch.setattr(latency, "prepare_log", prepare)  # the search's candidates
    monkeypatch.setattr(latency, "forward_log_likelihood", ll)
    with pytest.warns(LatencyWarning, match="0.5 ms late"):
        found = smooth(robot, (t, q, tau), noise_std=1e-4, accel_psd=1e-10)
    assert sorted(prepared) == pytest.approx([0.0, 0.5e-3, 1e-3, 2e-3], abs=1e-12)
    assert len(passes) == 3 and found.options["latency_found"] == pytest.approx(0.5e-3)


def test_a_log_with_dropped_rows_is_smoothed_about_as_well_as_the_clean_log() -> None:
    """8 % of a UR5 log's rows deleted (runs of 1 and 3–9), exact model, σ = 1e-4: the
    smoother runs on the log's ticks, each missing sample predicted over with its torque on
    the line between its neighbours' (holding the torque before the gap instead made the
    error 33× the clean log's).  Velocity RMS error, dropped over clean, measured: 1.24
    (1.71e-5 and 2.11e-5 rad/s, this log); the measurements lost alone cost 1.04× (the
    missing samples' true torques given), the rest is their torques' interpolation.
    benchmarks/irregular_logs.py for more seeds."""
    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), duration=4.0, seed=1)
    t, q, tau = res.t[1:], np.array(res.q_meas[1:]), np.array(res.tau[1:])
    keep = dropped_rows(t.size, 0.08, 0)
    errors = []
    for rows in (np.ones(t.size, dtype=bool), keep):
        sm = smooth(robot, (t[rows], q[rows], tau[rows]), noise_std=1e-4)
        assert sm.t.shape == (rows.sum(),)
        inner = (t[rows] > 0.2) & (t[rows] < 3.8)
        errors.append(float(np.sqrt(np.mean((sm.v - res.v[1:][rows])[inner] ** 2))))
    assert sm.options["missing_samples"] == t.size - keep.sum()
    assert errors[1] <= 1.35 * errors[0], errors


def test_cli_smooths_a_csv_with_dropped_rows_as_smooth_does(tmp_path) -> None:
    """``estimate --smooth`` on a CSV with dropped rows: one row per log row, equal to
    :func:`smooth` on the same rows (it held the torque before each gap of more than three
    periods across it, and fed shorter ones as they were)."""
    from pinobs.cli import main
    from pinobs.io import write_log

    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), duration=1.0, seed=2)
    t, q, tau = res.t[1:], np.array(res.q_meas[1:]), np.array(res.tau[1:])
    keep = dropped_rows(t.size, 0.08, 2)
    log = write_log(tmp_path / "dropped.csv", t[keep], q[keep], tau[keep])
    out = tmp_path / "est.csv"
    argv = ["estimate", "--robot", "ur5", "--observer", "ekf", "--log", str(log), "--out", str(out)]
    assert main([*argv, "--smooth", "--noise", "1e-4", "--accel-psd", "1e-8"]) == 0
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    read = np.loadtxt(log, delimiter=",", skiprows=1)
    want = smooth(robot, (read[:, 0], read[:, 1:7], read[:, 7:]), noise_std=1e-4, accel_psd=1e-8)
    assert data.shape[0] == keep.sum()
    np.testing.assert_allclose(data[:, 7:13], want.v, rtol=0, atol=1e-9)
    assert np.sqrt(np.mean((want.v - res.v[1:][keep]) ** 2)) < 1e-3


def test_an_irregularly_sampled_log_is_smoothed_about_as_well_as_the_clean_log() -> None:
    """A UR5 control loop run at intervals uniform in 0.5–1.5 ms (torques held over each),
    exact model, σ = 1e-4, against the 1 kHz run of the same reference: it is smoothed at
    its own times, no sample taken as lost.  Velocity RMS error, irregular over clean,
    measured: 0.86 (seed 1); 0.90, 1.04 (seeds 2, 3).  Taking its intervals from 1.5
    periods on as a lost sample each (78 of them) made it 1.70."""
    robot = cached_robot("ur5")
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), duration=4.0, seed=1)
    t, q, tau, v = irregular_loop_log(robot, 4.0, 1e-4, 1)
    errors = []
    for log, truth in (((res.t[1:], res.q_meas[1:], res.tau[1:]), res.v[1:]), ((t, q, tau), v)):
        sm = smooth(robot, log, noise_std=1e-4)
        inner = (log[0] > 0.2) & (log[0] < 3.8)
        errors.append(float(np.sqrt(np.mean((sm.v - truth)[inner] ** 2))))
    assert sm.options["missing_samples"] == 0
    assert errors[1] <= 1.2 * errors[0], errors
