"""The compiled steps of ``ekf`` and ``riemannian`` (:mod:`pinobs.observers.fused`, issue 39)
equal the NumPy steps they replace, to rounding, and are taken where they apply."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

import pinobs
from pinobs.model import dynamics_rk4
from pinobs.observers import make_observer
from pinobs.observers.base import Vector
from pinobs.observers.ekf import ExtendedKalmanFilter
from pinobs.observers.fused import (
    _warm_predict,
    ekf_predict_kernel,
    loaded,
    rk4_stage_kernel,
    rk4_start_kernel,
    rk4_start_loops,
)
from pinobs.observers.linalg import LazyKernel
from pinobs.observers.riemannian import RiemannianObserver
from pinobs.simulation import Sensor
from tests.conftest import cached_robot


def _run(ob: Any, res: pinobs.Result) -> tuple[np.ndarray, np.ndarray]:
    """``ob`` over ``res`` from a start off the truth, every 7th sample missing; its
    estimates ``(q, v)``."""
    robot = ob.robot
    ob.reset(res.t[0], robot.integrate(res.q[0], np.full(robot.nv, 1e-3)), None, res.tau[0])
    qs, vs = [], []
    for k in range(1, res.t.size):
        missing = k % 7 == 0 or not np.all(np.isfinite(res.q_meas[k]))
        est = ob.update(res.t[k], None if missing else res.q_meas[k], res.tau[k])
        qs.append(est.q)
        vs.append(est.v)
    return np.array(qs), np.array(vs)


def _assert_close_per_signal(a: np.ndarray, b: np.ndarray, rel: float) -> None:
    """Each column of ``a`` within ``rel`` of the largest |value| of that column of ``b``."""
    scale = np.abs(b).max(axis=0)
    assert np.all(np.abs(a - b).max(axis=0) <= rel * scale), np.abs(a - b).max(axis=0) / scale


@pytest.mark.parametrize(
    ("robot_name", "name", "options"),
    [
        ("ur5", "ekf", {}),
        ("ur5", "ekf", {"disturbance_psd": 1.0}),
        ("ur5", "ekf", {"disturbance_psd": "auto"}),
        ("panda", "ekf", {}),
        ("ur5", "riemannian", {}),
        ("panda", "riemannian", {"alpha": 20.0, "beta": 400.0}),
    ],
)
def test_the_compiled_step_equals_the_numpy_step_to_1e_12(
    robot_name: str, name: str, options: dict[str, Any]
) -> None:
    """A run with missing samples (and the gate on): estimates equal per signal to 1e-12 of
    its largest value, the compiled step against the NumPy one (the same observer with its
    compiled step switched off)."""
    robot = cached_robot(robot_name)
    res = pinobs.simulate(robot, [], duration=0.4, sensor=Sensor(1000.0, 1e-4), seed=4)
    fast = make_observer(name, robot, rate=1000.0, noise_std=1e-4, **options)
    slow = make_observer(name, robot, rate=1000.0, noise_std=1e-4, **options)
    attrs = ("_fast",) if name == "ekf" else ("_scratch_calls", "_scratch_fast")
    assert getattr(fast, attrs[0]) is not None  # the compiled step is the one compared
    for attr in attrs:
        setattr(slow, attr, None)
    q_fast, v_fast = _run(fast, res)
    q_slow, v_slow = _run(slow, res)
    _assert_close_per_signal(q_fast, q_slow, 1e-12)
    _assert_close_per_signal(v_fast, v_slow, 1e-12)


def test_riemannians_step_in_one_call_is_its_step_of_separate_calls_to_the_bit() -> None:
    """:class:`~pinobs.observers.fused.RiccatiStep` (the RK4's last stage with ``δ``, the
    correction into the caller's arrays) against the same observer without it (its RK4
    stages and correction called one by one): over 1500 updates from a start off the truth,
    with missing samples, outliers and the Jacobi operator recomputed, the same bits."""
    robot = cached_robot("ur5")
    res = pinobs.simulate(robot, [], duration=1.5, sensor=Sensor(1000.0, 1e-4), seed=6)
    q_meas = np.array(res.q_meas)
    q_meas[[200, 450, 1201]] += 0.2  # (the gate rejects them)
    res = replace(res, q_meas=q_meas)
    fast = make_observer("riemannian", robot, rate=1000.0, noise_std=1e-4)
    slow = make_observer("riemannian", robot, rate=1000.0, noise_std=1e-4)
    assert fast._scratch_fast is not None
    slow._scratch_fast = None
    q_fast, v_fast = _run(fast, res)
    q_slow, v_slow = _run(slow, res)
    assert fast._gated >= 3 and fast._state.jacobi is not None
    np.testing.assert_array_equal(q_fast, q_slow)
    np.testing.assert_array_equal(v_fast, v_slow)


def test_the_compiled_rk4_step_equals_dynamics_rk4() -> None:
    """The stages of :func:`~pinobs.observers.fused.rk4_stage_loops` are those of
    :func:`pinobs.model.dynamics_rk4` (its stacked form), to rounding (to the bit where the
    BLAS fuses its products' multiply-adds as the kernel does: here)."""
    robot = cached_robot("ur5")
    start, stage = loaded(rk4_start_kernel), loaded(rk4_stage_kernel)
    rng = np.random.default_rng(1)
    q, v = robot.random_configuration(rng), rng.standard_normal(robot.nv)
    tau = rng.standard_normal(robot.nv)
    h = 1e-3
    w = np.zeros((8, robot.nv))
    start(w, q, v, robot.forward_dynamics(q, v, tau), h)
    for k in (2, 3, 4):
        stage(w, robot.forward_dynamics(w[6], w[7], tau), k, h)
    q_ref, v_ref = dynamics_rk4(robot, q, v, tau, h)
    np.testing.assert_allclose(w[6], q_ref, rtol=0, atol=1e-14 * np.abs(q_ref).max())
    np.testing.assert_allclose(w[7], v_ref, rtol=0, atol=1e-14 * np.abs(v_ref).max())


def test_the_compiled_step_is_taken_where_it_applies_and_only_there() -> None:
    """Vector-space robots without friction (``ekf``: ``nv ≤ 12`` as well); not on Lie
    groups (their own compiled paths); ``ekf``'s compiled step makes no BLAS call, so its
    update enters no thread limit."""
    ur5, go1 = cached_robot("ur5"), cached_robot("go1")
    ekf = ExtendedKalmanFilter(ur5, rate=1000.0, noise_std=1e-4)
    assert ekf._fast is not None and not ekf.uses_blas
    assert RiemannianObserver(ur5, rate=1000.0)._scratch_calls is not None
    lie = ExtendedKalmanFilter(go1, rate=1000.0, noise_std=1e-4)
    assert lie._fast is None and lie.uses_blas  # (Lie groups: tests/observers/test_fused_lie.py)
    assert RiemannianObserver(go1, rate=1000.0)._scratch_calls is None


def test_the_compiled_ekf_step_reads_the_gains_a_caller_sets_after_construction() -> None:
    """``adaptive`` and the smoother's replay set ``ekf.gains`` between steps: the compiled
    step uses them as the NumPy step does."""
    robot = cached_robot("ur5")
    res = pinobs.simulate(robot, [], duration=0.2, sensor=Sensor(1000.0, 1e-4), seed=6)
    fast = ExtendedKalmanFilter(robot, rate=1000.0, noise_std=1e-4)
    slow = ExtendedKalmanFilter(robot, rate=1000.0, noise_std=1e-4)
    slow._fast = None
    out = []
    for ob in (fast, slow):
        ob.gains = replace(ob.gains, accel_psd=1e-2, meas_std=3e-4)
        out.append(_run(ob, res))
    default = _run(ExtendedKalmanFilter(robot, rate=1000.0, noise_std=1e-4), res)
    for a, b in zip(out[0], out[1], strict=True):
        _assert_close_per_signal(a, b, 1e-12)
    assert np.abs(out[0][1] - default[1]).max() > 1e-6  # the new gains made a difference


def test_the_ekf_prediction_kernel_gives_the_full_sums_bits() -> None:
    """``ekf_predict_loops`` (the exact zeros of ``A``'s constant blocks skipped, ``(Φ P) Φᵀ``
    by whole rows) against the full sums (:func:`_full_predict_loops`, compiled with
    the same ``contract``): ``w``, ``A``, ``Φ`` and ``P⁻`` to the bit, with and without the
    offset state, over scales from 1e-3 to 1e3, signed zeros in ``∂a/∂q`` and ``∂a/∂v``."""
    full = loaded(
        LazyKernel(
            _full_predict_loops,
            *_warm_predict(),
            helpers=(rk4_start_loops, _full_times_a),
            contract=True,
        )
    )
    kernel = loaded(ekf_predict_kernel)
    rng = np.random.default_rng(5)
    for nv in (1, 2, 6, 7, 12):
        for with_d in (False, True):
            n = (3 if with_d else 2) * nv
            for trial in range(40):
                scale = 10.0 ** rng.uniform(-3, 3)
                dq, dv = (scale * rng.standard_normal((nv, nv)) for _ in "ab")
                dq[trial % nv, (trial + 1) % nv], dv[0, trial % nv] = -0.0, 0.0
                minv = rng.standard_normal((nv, nv))
                X = rng.standard_normal((n, n))
                P = X @ X.T * 10.0 ** rng.uniform(-12, 0)
                q, v, acc = (rng.standard_normal(nv) for _ in "abc")
                h = (1e-3, 2e-3, 1e-2, 3.7e-4)[trial % 4]
                d_psd = rng.random(nv) if with_d else np.zeros(nv)
                outs = []
                for f in (full, kernel):
                    w, A = np.zeros((8, nv)), np.zeros((n, n))
                    A[:nv, nv : 2 * nv] = np.eye(nv)
                    Phi, out = np.empty((n, n)), np.empty((n, n))
                    f(w, q, v, acc, dq, dv, minv, P, h, 1e-8, d_psd, A, Phi, out)
                    outs.append([x.tobytes() for x in (w, A, Phi, out)])
                assert outs[0] == outs[1], (nv, with_d, trial)


def _joseph_columns(P: Vector, e: Vector, r: float, dx: Vector, out: Vector) -> bool:  # noqa: C901, PLR0912 -- numba kernel: its branches are loops over small matrices
    """``linalg._joseph_loops`` as it was before issue 39: ``Kᵀ``'s triangular solves
    column by column (the reference its solves by rows must give the bits of)."""
    n, nv = P.shape[0], e.shape[0]
    L = np.zeros((nv, nv))
    for j in range(nv):
        d = P[j, j] + r
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, nv):
            t = P[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / L[j, j]
    Kt = np.empty((nv, n))
    for c in range(n):  # L y = B[:, c], then Lᵀ x = y
        for i in range(nv):
            t = P[i, c]
            for k in range(i):
                t -= L[i, k] * Kt[k, c]
            Kt[i, c] = t / L[i, i]
        for i in range(nv - 1, -1, -1):
            t = Kt[i, c]
            for k in range(i + 1, nv):
                t -= L[k, i] * Kt[k, c]
            Kt[i, c] = t / L[i, i]
    # each entry's sum in the order of k as t −= …, with k outside the loop over j (the
    # entries of a row independent: no chain of dependent subtractions, the same bits)
    C = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            C[i, j] = P[i, j]
        for k in range(nv):
            c = Kt[k, i]
            for j in range(n):
                C[i, j] -= c * P[k, j]
    for i in range(n):
        for j in range(n):
            out[i, j] = C[i, j]
        for k in range(nv):
            g = C[i, k] - r * Kt[k, i]
            for j in range(n):
                out[i, j] -= g * Kt[k, j]
    for i in range(n):
        for j in range(i):
            m = 0.5 * (out[i, j] + out[j, i])
            out[i, j] = m
            out[j, i] = m
        t = 0.0
        for k in range(nv):
            t += Kt[k, i] * e[k]
        dx[i] = t
    return True


def test_the_ekf_correction_solves_by_rows_give_the_column_loops_bits() -> None:
    """``linalg._joseph_loops`` (``Kᵀ``'s triangular solves by rows; ``ekf``'s and ``kalman``'s
    fused kernels inline it) against the column-by-column loops it replaced: ``dx`` and ``P⁺`` to the bit wherever ``S`` is
    positive definite (the same answer where it is not), with and without the offset state,
    covariances from 1e-12 to 1e2 and measurement variances from 1e-10 to 1e-4."""
    from pinobs.observers.linalg import joseph_kernel

    rows = loaded(joseph_kernel)
    columns = loaded(
        LazyKernel(_joseph_columns, np.eye(2), np.zeros(1), 1.0, np.zeros(2), np.zeros((2, 2)))
    )
    rng = np.random.default_rng(7)
    taken = 0
    for nv in (1, 2, 6, 7, 12):
        for n in (2 * nv, 3 * nv):
            for _ in range(60):
                X = rng.standard_normal((n, n))
                P = X @ X.T * 10.0 ** rng.uniform(-12, 2)
                e, r = 1e-4 * rng.standard_normal(nv), 10.0 ** rng.uniform(-10, -4)
                outs = []
                for f in (columns, rows):
                    dx, out = np.zeros(n), np.zeros((n, n))
                    ok = f(P, e, r, dx, out)
                    outs.append((ok, dx.tobytes(), out.tobytes()) if ok else (ok,))
                assert outs[0] == outs[1], (nv, n)
                taken += outs[0][0]
    assert taken >= 500


def _full_times_a(A: Vector, X: Vector, nv: int, c: float, out: Vector) -> None:
    """``out = I + c A X``, the products with ``A``'s constant rows copies, the others full."""
    n = A.shape[0]
    row = np.empty(n)
    for i in range(n):
        if i < nv:
            for j in range(n):
                row[j] = X[nv + i, j]
        else:
            row[:] = 0.0
            if i < 2 * nv:
                for k in range(n):
                    a = A[i, k]
                    for j in range(n):
                        row[j] += a * X[k, j]
        for j in range(n):
            out[i, j] = c * row[j] + (1.0 if i == j else 0.0)


def _full_predict_loops(  # noqa: C901, PLR0912 -- numba kernel: loops
    w: Vector, q: Vector, v: Vector, acc: Vector, dq: Vector, dv: Vector, minv: Vector,
    P: Vector, h: float, psd: float, d_psd: Vector, A: Vector, Phi: Vector, out: Vector,
) -> None:  # fmt: skip
    """``fused.ekf_predict_loops`` before issue 39's structure: every product's full sum, the
    triangle of ``(Φ P) Φᵀ`` (the reference of its bits)."""
    rk4_start_loops(w, q, v, acc, h)
    nv, n = q.shape[0], P.shape[0]
    with_d = n == 3 * nv
    for i in range(nv):
        for j in range(nv):
            A[nv + i, j] = dq[i, j]
            A[nv + i, nv + j] = dv[i, j]
            if with_d:
                A[nv + i, 2 * nv + j] = minv[i, j] if i <= j else minv[j, i]
    inner = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            inner[i, j] = A[i, j] * h / 3.0 + (1.0 if i == j else 0.0)
    mid = np.empty((n, n))
    _full_times_a(A, inner, nv, 0.5 * h, mid)
    _full_times_a(A, mid, nv, h, Phi)
    m = 2 * nv if with_d else n
    T = np.zeros((n, n))
    for i in range(m):
        for k in range(n):
            c = Phi[i, k]
            for j in range(n):
                T[i, j] += c * P[k, j]
    for i in range(m, n):
        for j in range(n):
            T[i, j] = P[i, j]
    Phi_t = Phi.T.copy()
    out[:, :] = 0.0
    for i in range(n):
        for k in range(n):
            c = T[i, k]
            for j in range(i, m):
                out[i, j] += c * Phi_t[k, j]
        for j in range(max(i, m), n):
            out[i, j] = T[i, j]
        for j in range(i + 1, n):
            out[j, i] = out[i, j]
    q3, q2, q1 = psd * (h**3 / 3.0), psd * (h**2 / 2.0), psd * h
    for i in range(nv):
        out[i, i] += q3
        out[i, nv + i] += q2
        out[nv + i, i] += q2
        out[nv + i, nv + i] += q1
        if with_d:
            out[2 * nv + i, 2 * nv + i] += d_psd[i] * h
