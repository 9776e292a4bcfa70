"""The invariant EKF's compiled steps (``pinobs.observers.inekf_loops``) against the module
docstring's equations written with dense matrices: ``P⁺ = Φ P Φᵀ + Q`` with ``Φ`` from
:func:`error_transition` (the propagation), and eq. (5) with ``H`` built explicitly and
``S`` inverted (the correction)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from scipy.linalg import expm

from pinobs.observers.inekf import GRAVITY, InEKFGains, adjoint, error_transition, sek3_exp
from pinobs.observers.inekf_loops import (
    _matmul,
    _matvec3,
    correct_kernel,
    gamma_coefficients,
    load_kernels,
    propagate_kernel,
)
from pinobs.observers.legs import foot_noise, noise_densities, rotation_to_quaternion

G = np.array(GRAVITY)


@pytest.fixture(scope="module", autouse=True)
def _compiled() -> None:
    load_kernels()


def _state(rng: np.random.Generator, n_feet: int) -> tuple[np.ndarray, ...]:
    """A random rotation, rows ``v, p, d_j`` a metre or two away, biases, an SPD ``P``."""
    R = expm(np.cross(np.eye(3), rng.normal(size=3)))
    x = rng.normal(size=(2 + n_feet, 3))
    x[1:] += 2.0
    theta = 0.05 * rng.normal(size=6)
    n = 15 + 3 * n_feet
    A = rng.normal(size=(n, n))
    P = 1e-3 * (A @ A.T + n * np.eye(n))
    return R, x, theta, P


#: the propagation kernel's arguments without eq. (9)'s slip term
_NO_SLIP = (np.zeros(0), np.zeros(0, dtype=np.intp))


def _rows(k: int) -> np.ndarray:
    """The correction kernel's ``rows``: every foot, in order."""
    return np.arange(k, dtype=np.intp)


def _frame(R: np.ndarray, x: np.ndarray) -> np.ndarray:
    n = 9 + 3 * (x.shape[0] - 2)
    T = np.eye(n + 6)
    T[:n, :n] = adjoint(R, x)
    return T


@pytest.mark.parametrize("n_feet", [0, 1, 4])
@pytest.mark.parametrize("rate", [2.0, 500.0])
def test_compiled_propagation_is_phi_p_phi_t_plus_q(n_feet: int, rate: float) -> None:
    """``Q = T⁺ ½ (Φ_ε Q_c Φ_εᵀ + Q_c) h T⁺ᵀ``, ``Φ_ε = T⁺⁻¹ Φ T``; a 0.5 s step scales the
    series (its ‖F h‖ > 1/8)."""
    rng = np.random.default_rng(n_feet)
    R, x, theta, P = _state(rng, n_feet)
    imu = np.concatenate([rng.normal(size=3), rng.normal(size=3) + np.array([0.0, 0.0, 9.81])])
    h = 1.0 / rate
    gains = InEKFGains()
    qc = noise_densities(gains, n_feet)
    R1, x1, P1 = np.empty((3, 3)), np.empty_like(x), np.empty_like(P)
    assert propagate_kernel.compiled is not None
    propagate_kernel.compiled(R, x, theta, imu, h, G.copy(), qc, *_NO_SLIP, P, R1, x1, P1)
    w, a = imu[:3] - theta[:3], imu[3:] - theta[3:]
    Phi = error_transition(R, x, w, a, h)
    T0, T1 = _frame(R, x), _frame(R1, x1)
    Phi_e = np.linalg.solve(T1, Phi @ T0)
    Q = T1 @ (0.5 * h * (Phi_e @ np.diag(qc) @ Phi_e.T + np.diag(qc))) @ T1.T
    np.testing.assert_allclose(P1, Phi @ P @ Phi.T + Q, rtol=0, atol=1e-12 * np.abs(P1).max())
    np.testing.assert_array_equal(P1, P1.T)
    np.testing.assert_allclose(R1.T @ R1, np.eye(3), atol=1e-14)


@pytest.mark.parametrize("n_feet", [1, 4])
def test_compiled_correction_is_the_kalman_update_with_h_written_out(n_feet: int) -> None:
    rng = np.random.default_rng(10 + n_feet)
    R, x, theta, P = _state(rng, n_feet)
    gains = InEKFGains()
    hm = x[2:] @ R + 0.01 * rng.normal(size=(n_feet, 3))  # ≈ Rᵀ (d_j − p) per row
    hm -= x[1] @ R
    jac = 0.3 * rng.normal(size=(n_feet, 3, 12))
    noise = foot_noise(gains, jac)
    R1, x1, th1, P1 = np.empty((3, 3)), np.empty_like(x), np.empty(6), np.empty_like(P)
    assert correct_kernel.compiled is not None
    nis = correct_kernel.compiled(
        R, x, theta, P, hm, jac, _rows(n_feet), gains.joint**2, gains.kinematics**2, R1, x1, th1, P1
    )
    n, m = P.shape[0], 3 * n_feet
    H = np.zeros((m, n))
    N = np.zeros((m, m))
    r = np.empty(m)
    for j in range(n_feet):
        H[3 * j : 3 * j + 3, 6:9] = np.eye(3)
        H[3 * j : 3 * j + 3, 9 + 3 * j : 12 + 3 * j] = -np.eye(3)
        N[3 * j : 3 * j + 3, 3 * j : 3 * j + 3] = R @ noise[j] @ R.T
        r[3 * j : 3 * j + 3] = R @ hm[j] - (x[2 + j] - x[1])  # eq. (4)
    S = H @ P @ H.T + N
    K = P @ H.T @ np.linalg.inv(S)
    IKH = np.eye(n) - K @ H
    delta = K @ r
    dR, dx = sek3_exp(-delta[: n - 6])
    np.testing.assert_allclose(nis, r @ np.linalg.solve(S, r), rtol=1e-10)
    np.testing.assert_allclose(
        P1, IKH @ P @ IKH.T + K @ N @ K.T, rtol=0, atol=1e-12 * np.abs(P).max()
    )
    np.testing.assert_allclose(R1, dR @ R, atol=1e-14)
    np.testing.assert_allclose(x1, x @ dR.T + dx, atol=1e-13)
    np.testing.assert_allclose(th1, theta - delta[n - 6 :], atol=1e-15)


def test_the_correction_reports_an_innovation_covariance_that_is_not_positive_definite() -> None:
    R, x, theta, P = _state(np.random.default_rng(3), 1)
    jac = np.zeros((1, 3, 12))
    out = (np.empty((3, 3)), np.empty_like(x), np.empty(6), np.empty_like(P))
    assert correct_kernel.compiled is not None  # S = H P Hᵀ − 1000 I
    rows = _rows(1)
    assert (
        correct_kernel.compiled(R, x, theta, P, np.zeros((1, 3)), jac, rows, 1.0, -1e3, *out)
        == -1.0
    )


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-4, 0.3, 3.0])
def test_gamma_coefficients_are_the_series_of_the_closed_forms(angle: float) -> None:
    """``a_m, b_m`` against the series ``Σ_k (−θ²)^k/(2k+1+m)!``, ``Σ_k (−θ²)^k/(2k+2+m)!``
    summed to 30 terms."""
    from math import factorial

    t2 = angle**2

    def series(j: int) -> float:
        return sum((-t2) ** k / factorial(2 * k + j) for k in range(30))

    want = [series(1), series(2), series(2), series(3), series(3), series(4)]
    np.testing.assert_allclose(gamma_coefficients(t2), want, rtol=1e-12, atol=1e-15)


def _fma(a: float, b: float, c: float) -> float:
    """``a·b + c`` rounded once (exact rationals)."""
    return float(Fraction(a) * Fraction(b) + Fraction(c))


def test_the_kernels_products_are_fused_multiply_adds_in_blas_order(
    rng: np.random.Generator,
) -> None:
    """The loops that replaced numba's ``@`` in the kernels (issue 39: it called SciPy's BLAS,
    importing ``scipy.linalg``): ``_matmul``'s entries are ``Σ_k`` by fused multiply-adds in
    the order of ``k`` (OpenBLAS ``gemm``'s), ``_matvec3``'s ``(a₁x₁ + a₀x₀) + a₂x₂``
    (``gemv``'s on a 3 × 3), each rounded once; a transposed view is read as its transpose."""
    import numba

    @numba.njit
    def products(A, B, x, AB, AtB, Ax):  # type: ignore[no-untyped-def]
        _matmul(A, B, AB)
        _matmul(A.T, B, AtB)
        _matvec3(A[:3, :3], x, Ax)

    for n in (3, 15):
        A, B, x = rng.normal(size=(n, n)), rng.normal(size=(n, n)), rng.normal(size=3)
        AB, AtB, Ax = np.empty((n, n)), np.empty((n, n)), np.empty(3)
        products(A, B, x, AB, AtB, Ax)
        for M, out in ((A, AB), (A.T, AtB)):
            want = np.empty((n, n))
            for i in range(n):
                for j in range(n):
                    t = 0.0
                    for k in range(n):
                        t = _fma(M[i, k], B[k, j], t)
                    want[i, j] = t
            np.testing.assert_array_equal(out, want)
            np.testing.assert_allclose(out, M @ B, rtol=0, atol=1e-14 * n)
        a = A[:3, :3]
        want_x = [_fma(a[i, 2], x[2], _fma(a[i, 0], x[0], a[i, 1] * x[1])) for i in range(3)]
        np.testing.assert_array_equal(Ax, want_x)


@pytest.mark.parametrize("column_major", [False, True])
def test_the_estimate_kernel_is_the_numpy_conversion_to_the_root_joint(
    rng: np.random.Generator, column_major: bool
) -> None:
    """``base_kernel`` (``LeggedSetup.estimate``'s conversion, legs.py's module docstring):
    ``R_b = R R_biᵀ``, ``p_b = p − R_b r_bi``, ``ω_b = R_bi (ω̃ − b̂_g)``, ``v_b = R_bᵀ v −
    ω̄_b × r_bi`` (imu_link.py's (M4): ``ω̄_b = R_bi (ω̄ − b̂_g)``, ``ω̄`` the low-passed gyro
    given beside the reading) and ``R_b v_b``, as NumPy computes them to rounding; a
    column-major ``R_bi`` (Pinocchio's) sums ``R_bi ω`` over its columns from the first,
    rounded once each; ``R_b``'s quaternion as ``rotation_to_quaternion`` gives it, bit for
    bit; with the reading itself as ``ω̄`` (M3), ``v_b = R_bᵀ v − ω_b × r_bi``."""
    from pinobs.observers.inekf_loops import base_kernel, load_leg_kernels

    load_leg_kernels()
    R, x, theta, _ = _state(rng, 2)
    R_bi = expm(np.cross(np.eye(3), rng.normal(size=3)))
    r_bi, imu = rng.normal(size=3), rng.normal(size=6)
    R_b, out, quat = np.empty((3, 3)), np.empty((4, 3)), np.empty(4)
    lever = rng.normal(size=3)
    base_kernel.compiled(R, x, imu, lever, theta, R_bi, r_bi, column_major, R_b, out, quat)  # type: ignore[misc]
    omega = imu[:3] - theta[:3]
    w_b = R_bi @ omega
    v_b = R_b.T @ x[0] - np.cross(R_bi @ (lever - theta[:3]), r_bi)
    np.testing.assert_allclose(R_b, R @ R_bi.T, rtol=0, atol=1e-15)
    np.testing.assert_allclose(out[0], x[1] - R_b @ r_bi, rtol=0, atol=1e-14)
    np.testing.assert_allclose(out[1], w_b, rtol=0, atol=1e-14)
    np.testing.assert_allclose(out[2], v_b, rtol=0, atol=1e-14)
    np.testing.assert_allclose(out[3], R_b @ out[2], rtol=0, atol=1e-14)
    quat /= np.sqrt(quat @ quat)  # the same bits as rotation_to_quaternion's, normalised alike
    np.testing.assert_array_equal(quat if quat[3] >= 0 else -quat, rotation_to_quaternion(R_b))
    if column_major:
        want = [_fma(R_bi[i, 2], omega[2], _fma(R_bi[i, 1], omega[1], R_bi[i, 0] * omega[0]))
                for i in range(3)]  # fmt: skip
        np.testing.assert_array_equal(out[1], want)
    raw = np.empty((4, 3))
    base_kernel.compiled(R, x, imu, imu, theta, R_bi, r_bi, column_major, R_b, raw, quat)  # type: ignore[misc]
    np.testing.assert_allclose(raw[2], R_b.T @ x[0] - np.cross(w_b, r_bi), rtol=0, atol=1e-14)
    np.testing.assert_array_equal(raw[:2], out[:2])


def test_the_velocity_kernel_is_the_feet_velocities_and_their_norms(
    rng: np.random.Generator,
) -> None:
    """``velocity_kernel``: ``ṗ̂_j = v̂ + R̂ (ω × h_j + J_j q̇)``, ``ω = ω̃ − b̂_g`` from the
    reading's and the biases' first three entries, and ``|ṗ̂_j|`` (the speeds of
    ``slip_speeds`` without its gyro term, bit for bit from the same velocities)."""
    from pinobs.observers.inekf_loops import load_leg_kernels, velocity_kernel
    from pinobs.observers.legs import slip_speeds

    load_leg_kernels()
    R, x, theta, _ = _state(rng, 0)
    reading, h, jdq = rng.normal(size=6), rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    out, speed = np.empty((4, 3)), np.empty(4)
    velocity_kernel.compiled(reading, theta, h, jdq, R, x[0], out, speed)  # type: ignore[misc]
    want = x[0] + (np.cross(reading[:3] - theta[:3], h) + jdq) @ R.T
    np.testing.assert_allclose(out, want, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(speed, slip_speeds(out, h, 0.0, 0.002))
    np.testing.assert_array_equal(speed, np.sqrt(np.sum(out * out, axis=1)))


@pytest.mark.parametrize("feet", [(0,), (2, 0), (1, 3, 0, 2)])
def test_the_slip_kernel_is_slip_densities(rng: np.random.Generator, feet: tuple[int, ...]) -> None:
    """``slip_kernel``: eq. (9), the bits of :func:`~pinobs.observers.legs.slip_densities`
    (what the filter's propagation called before), the feet in state order."""
    from pinobs.observers.inekf_loops import slip_kernel
    from pinobs.observers.legs import slip_densities

    qc = noise_densities(InEKFGains(contact=1e-4), len(feet))
    speed = np.abs(rng.normal(size=4))
    out = np.empty(qc.shape[0])
    slip_kernel.compiled(qc, speed, 0.0025, np.array(feet, dtype=np.intp), out)  # type: ignore[misc]
    want = slip_densities(qc, speed, 0.0025, feet)
    assert not np.array_equal(want, qc)
    np.testing.assert_array_equal(out, want)


@pytest.mark.parametrize("feet", [(0,), (2, 0), (1, 3, 0, 2)])
def test_the_propagation_with_speeds_is_the_slip_kernel_then_the_propagation(
    rng: np.random.Generator, feet: tuple[int, ...]
) -> None:
    """Eq. (9) inside the propagation's kernel (its ``speed``, ``feet`` arguments): the bits of
    ``slip_kernel``'s ``Q_c`` propagated without them (the filter's two calls before)."""
    from pinobs.observers.inekf_loops import slip_kernel

    R, x, theta, P = _state(rng, len(feet))
    imu = np.concatenate([rng.normal(size=3), rng.normal(size=3) + np.array([0.0, 0.0, 9.81])])
    qc = noise_densities(InEKFGains(contact=1e-4), len(feet))
    speed, rows = np.abs(rng.normal(size=4)), np.array(feet, dtype=np.intp)
    slipped = np.empty(qc.shape[0])
    slip_kernel.compiled(qc, speed, 0.0025, rows, slipped)  # type: ignore[misc]
    slipped.setflags(write=False)
    outs = [(np.empty((3, 3)), np.empty_like(x), np.empty_like(P)) for _ in range(2)]
    assert propagate_kernel.compiled is not None
    propagate_kernel.compiled(R, x, theta, imu, 0.0025, G.copy(), slipped, *_NO_SLIP, P, *outs[0])
    propagate_kernel.compiled(R, x, theta, imu, 0.0025, G.copy(), qc, speed, rows, P, *outs[1])
    for a, b in zip(*outs, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(slipped, qc)


def _dense_core(w: np.ndarray, a: np.ndarray, h: float) -> np.ndarray:
    """``expm(F_ε h)`` by the dense Horner series (every product of the 15-term sums, in
    order): what ``_body_core`` computed before it skipped exact zeros and ones."""
    from pinobs.observers.inekf_loops import expm_degree

    F = np.zeros((15, 15))
    for i in range(3):
        F[i, 9 + i], F[3 + i, 12 + i], F[6 + i, 3 + i] = -h, -h, h
    for o in (0, 3, 6):
        F[o, o + 1], F[o, o + 2], F[o + 1, o + 2] = w[2] * h, -w[1] * h, w[0] * h
        F[o + 1, o], F[o + 2, o], F[o + 2, o + 1] = -w[2] * h, w[1] * h, -w[0] * h
    F[3, 1], F[3, 2], F[4, 2] = a[2] * h, -a[1] * h, a[0] * h
    F[4, 0], F[5, 0], F[5, 1] = -a[2] * h, a[1] * h, -a[0] * h
    s, degree = expm_degree(float(np.abs(F[:9]).sum(axis=1).max()))
    F /= 2.0**s
    core = np.eye(15)
    core[:9] += F[:9] / degree
    for k in range(degree - 1, 0, -1):
        tmp = np.empty((9, 15))
        for i in range(9):
            for j in range(15):
                t = 0.0
                for m in range(15):
                    t += float(F[i, m]) * float(core[m, j])
                tmp[i, j] = t
        core[:9] = tmp / k + np.eye(15)[:9]
    assert s == 0  # (the squarings are _matmul's, unchanged)
    return core


@pytest.mark.parametrize("seed", range(4))
def test_the_sparse_series_of_the_body_transition_has_the_dense_series_bits(seed: int) -> None:
    """``_body_core`` skips the Horner products with ``F_ε``'s exact zeros and ``core``'s bias
    rows ``[0, I]`` and the divisions of exact zeros: the same bits as every product summed."""
    from pinobs.observers.inekf_loops import _body_core

    rng = np.random.default_rng(seed)
    w, a = rng.normal(size=3), rng.normal(size=3) + np.array([0.0, 0.0, 9.81])
    if seed == 3:
        w[1] = 0.0  # an exact zero in ω: more products skipped
    core = np.empty((15, 15))
    _body_core(w, a, 0.0025, core)  # (its Python: float64 products and sums, as compiled)
    np.testing.assert_array_equal(core, _dense_core(w, a, 0.0025))
