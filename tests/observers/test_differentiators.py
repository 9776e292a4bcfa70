"""Ibrir's differentiators (Theorems 2.1 and 2.2): gains, transfer functions, invariance, noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pinobs
from pinobs.errors import GainError
from pinobs.evaluation import evaluate
from pinobs.observers import make_observer
from pinobs.observers.differentiators import (
    chain_matrix,
    gain_riccati_rhs,
    steady_gain_matrix,
    steady_gains,
    transfer_function,
)
from pinobs.simulation import Sensor, simulate


# ---------------------------------------------------------------- algebra
@pytest.mark.parametrize("n", [2, 3, 4, 5])
def test_steady_gain_matrix_solves_eq9_and_gives_the_binomial_gains(n: int) -> None:
    gamma = 7.5
    L = steady_gain_matrix(n, gamma)
    assert np.abs(gain_riccati_rhs(L, gamma)).max() < 1e-12  # eq. (9)
    gains = np.linalg.solve(L, np.eye(n)[:, 0])
    expected = [math.comb(n, k) * gamma**k for k in range(1, n + 1)]  # Remark 2.1
    np.testing.assert_allclose(gains, expected, rtol=1e-10)
    np.testing.assert_allclose(steady_gains(n, gamma), expected, rtol=1e-15)


@pytest.mark.parametrize("n", [2, 3, 4])
def test_eq13_equals_the_state_space_transfer_function_eq10(n: int) -> None:
    gamma = 3.0
    A = chain_matrix(n)
    C = np.eye(n)[:1]
    Linv = np.linalg.inv(steady_gain_matrix(n, gamma))
    for s in [0.3j, 1.0 + 2.0j, 17.0j, -0.5 + 0.1j]:
        eq10 = np.linalg.solve(s * np.eye(n) - A + Linv @ C.T @ C, Linv @ C.T).ravel()
        np.testing.assert_allclose(transfer_function(n, gamma, s), eq10, rtol=1e-12)
    # eq. (14): X̂_j → s^{j−1} as γ → ∞
    s = 2.0j
    np.testing.assert_allclose(transfer_function(n, 1e5, s), s ** np.arange(n), rtol=1e-3)


# ---------------------------------------------------------------- highgain
def test_dynamic_gain_L_of_t_ramps_up_to_the_steady_gains() -> None:
    robot = pinobs.load("pendulum")
    gamma, n = 100.0, 3
    ob = make_observer("highgain", robot, order=n, gamma=gamma, gain_ramp=10.0)
    ob.reset(0.0, np.zeros(1))
    g0 = ob.gain()
    np.testing.assert_allclose(g0, steady_gains(n, gamma / 10.0), rtol=1e-12)
    history = []
    for k in range(1, 301):
        ob.update(k * 1e-3, np.zeros(1))
        history.append(ob.gain()[0])
    # after 0.3 s = 30/γ the gain is the steady one (measured relative error 1e-9)
    np.testing.assert_allclose(ob.gain(), steady_gains(n, gamma), rtol=1e-6)
    assert np.all(np.linalg.eigvalsh(ob.gain_matrix()) > 0)
    assert history[0] < history[-1]


def test_highgain_vector_field_is_exact_on_polynomials_of_degree_below_n() -> None:
    """On y = polynomial of degree n − 1 with x̂ = its derivatives, eq. (7) is the chain."""
    robot = pinobs.load("pendulum")
    n, gamma = 4, 30.0
    ob = make_observer("highgain", robot, order=n, gamma=gamma)
    derivs = np.array([0.3, -1.2, 0.7, 2.5])  # y, ẏ, ÿ, d³y/dt³ at t
    L = steady_gain_matrix(n, gamma) * 3.0  # any L(t)
    u, X_dot, L_dot = ob.vector_field(derivs[:1], derivs[1:, None], L, derivs[:1])
    np.testing.assert_allclose(u, derivs[1:2], atol=1e-15)
    np.testing.assert_allclose(X_dot[:, 0], [derivs[2], derivs[3], 0.0], atol=1e-15)
    np.testing.assert_allclose(L_dot, gain_riccati_rhs(L, gamma), atol=1e-15)


def test_sampled_highgain_reproduces_the_eq13_frequency_response() -> None:
    """y = a sin ωt at 1 kHz: every steady state x̂_j is Re(H_j(jω) a e^{jωt}) of eq. (13)."""
    robot = pinobs.load("pendulum")
    n, gamma, a, w, h = 3, 100.0, 0.5, 2.0 * math.pi, 1e-3
    ob = make_observer("highgain", robot, order=n, gamma=gamma, gain_ramp=1.0, rate=1 / h)
    ob.reset(0.0, np.zeros(1))
    H = transfer_function(n, gamma, 1j * w)
    worst = 0.0
    for k in range(1, 2001):
        t = k * h
        est = ob.update(t, np.array([a * math.sin(w * t)]))
        if t > 1.0:
            states = np.concatenate([est.q, ob.derivatives()[:, 0]])
            predicted = np.imag(H * a * np.exp(1j * w * t))
            scale = a * w ** np.arange(n)
            worst = max(worst, float(np.max(np.abs(states - predicted) / scale)))
    assert worst < 1e-3  # measured 2e-5 of each derivative's amplitude


@pytest.mark.parametrize("name", ["highgain", "sliding"])
@pytest.mark.parametrize("order", [2, 4])
def test_differentiators_track_a_constant_body_velocity_on_so3_exactly(
    name: str, order: int
) -> None:
    """Lie-group joints differentiate the group error: q(t) = q₀ exp(ωt) gives v̂ → ω exactly."""
    robot = pinobs.load("top")
    rng = np.random.default_rng(0)
    q0 = robot.random_configuration(rng)
    w = np.array([0.7, -1.2, 2.0])
    ob = make_observer(name, robot, order=order, rate=1000)
    ob.reset(0.0, robot.integrate(q0, np.array([0.05, 0.0, 0.0])))
    for k in range(1, 1001):
        est = ob.update(k * 1e-3, robot.integrate(q0, w * k * 1e-3))
    assert np.abs(est.v - w).max() < 1e-9  # measured 6e-14 (highgain), 6e-13 (sliding)
    assert np.abs(robot.difference(est.q, robot.integrate(q0, w))).max() < 1e-12


# measured max velocity error after 0.5 s, noise-free, 1 kHz, default gains:
# highgain (γ = 200, order 4): cartpole 1.6e-4, ur5 1.4e-4 — the lag of eq. (13);
# sliding (γ = 500, order 4): cartpole 7.1e-6, ur5 5.9e-6.
_LAG = {"highgain": 5e-4, "sliding": 2e-5}


@pytest.mark.parametrize("name", ["highgain", "sliding"])
@pytest.mark.parametrize("robot_name", ["cartpole", "ur5"])
def test_differentiator_started_on_the_truth_stays_within_its_lag(
    name: str, robot_name: str
) -> None:
    robot = pinobs.load(robot_name)
    res = simulate(robot, [name], sensor=Sensor(1000, 0.0), inputs="pd", duration=1.0, seed=1)
    err = np.abs(res.trace(name).v - res.v)
    assert err[res.t > 0.5].max() < _LAG[name]


@pytest.mark.parametrize("name", ["highgain", "sliding"])
@pytest.mark.parametrize("robot_name", ["cartpole", "ur5"])
def test_differentiator_converges_from_a_perturbed_start(name: str, robot_name: str) -> None:
    robot = pinobs.load(robot_name)
    res = simulate(
        robot,
        [name],
        sensor=Sensor(1000, 0.0),
        inputs="pd",
        duration=1.0,
        perturb_q=0.1,
        perturb_v=0.5,
        seed=2,
    )
    err = np.abs(res.trace(name).v - res.v)
    assert err[0].max() > 0.1
    assert err[res.t > 0.5].max() < _LAG[name]


# ------------------------------------------------------------------ sliding
def test_implicit_sliding_does_not_chatter_and_explicit_does() -> None:
    """Noise-free sine at 1 kHz: implicit lands on the sliding surface, explicit sign chatters."""
    robot = pinobs.load("pendulum")
    err, jump = {}, {}
    for disc in ("implicit", "explicit"):
        ob = make_observer("sliding", robot, order=3, gamma=100.0, discretization=disc, rate=1000)
        ob.reset(0.0, np.zeros(1), np.array([math.pi]))
        e = []
        for k in range(1, 1001):
            t = k * 1e-3
            est = ob.update(t, np.array([0.5 * math.sin(2 * math.pi * t)]))
            e.append(est.v[0] - math.pi * math.cos(2 * math.pi * t))
        tail = np.array(e[500:])
        err[disc] = np.abs(tail).max()
        jump[disc] = np.abs(np.diff(tail)).max()
    lag = 0.5 * (2 * math.pi) ** 3 / 100.0**2  # max |d³y/dt³| / γ², the reduced chain's lag
    # measured: implicit error 1.11e-2 (lag bound 1.24e-2), sample-to-sample change 7e-5;
    # explicit error 10.7 rad/s, sample-to-sample jumps of 21 rad/s (±h k₂ square wave)
    assert err["implicit"] < lag
    assert jump["implicit"] < 1e-4
    assert jump["explicit"] > 1.0


def test_sliding_rejects_an_unknown_discretization() -> None:
    with pytest.raises(GainError, match="discretization"):
        make_observer("sliding", pinobs.load("pendulum"), discretization="trapezoid")


def test_differentiators_reject_order_one() -> None:
    with pytest.raises(GainError, match="order"):
        make_observer("highgain", pinobs.load("pendulum"), order=1)


# ---------------------------------------------------------------- with noise
def test_differentiators_against_the_best_per_joint_kalman_filter_on_a_noisy_ur5() -> None:
    """1 kHz, σ = 1e-4 rad, UR5 tracking: highgain within 1.5× of the best kf (issue 6).

    The best ``kf`` over jerk_psd ∈ {0.1, 1, 3, 10, 30, 1e2, 1e3, 1e4} is 10
    (5.2e-3 rad/s on a 2 s run).  Measured (2 s): highgain 4.2e-3 (0.81×),
    sliding 1.0e-2 (1.9×: the sliding differentiator does not filter the position;
    it misses the 1.5× target, see the module docstring).
    """
    robot = pinobs.load("ur5")
    res = simulate(
        robot,
        {
            "kf": make_observer("kf", robot, rate=1000, noise_std=1e-4, jerk_psd=10.0),
            "highgain": make_observer("highgain", robot, rate=1000, noise_std=1e-4),
            "sliding": make_observer("sliding", robot, rate=1000, noise_std=1e-4),
        },
        sensor=Sensor(1000, 1e-4),
        inputs="pd",
        duration=2.0,
        seed=0,
    )
    m = {x.observer: x.rms_v_error for x in evaluate(res, robot)}
    assert m["highgain"] < 1.5 * m["kf"]
    assert m["sliding"] < 2.2 * m["kf"]


def test_sliding_regimes() -> None:
    """The two regimes of the implicit sliding step on noisy data (module docstring).

    Sliding (default γ, ``hγ ≫ σ``): ``x̂₁ = y_k`` at almost every sample and the
    velocity error is well above the best ``kf``'s.  Not sliding (γ = 0.03,
    ``hγ < σ``): ``x̂₁`` is filtered and the error is within 1.5× of the ``kf``'s.
    """
    robot = pinobs.load("ur5")
    obs = {
        "kf": make_observer("kf", robot, rate=1000, noise_std=1e-4, jerk_psd=10.0),
        "sliding": make_observer("sliding", robot, rate=1000, noise_std=1e-4),
        "linear": make_observer("sliding", robot, gamma=0.03, lam=70.0),
    }
    res = simulate(robot, obs, sensor=Sensor(1000, 1e-4), inputs="pd", duration=2.0, seed=0)
    m = {x.observer: x.rms_v_error for x in evaluate(res, robot)}
    after = res.t >= 0.5
    on_sample = {
        tr.name: float(np.mean(np.all(tr.q[after] == res.q_meas[after], axis=1)))
        for tr in res.traces
    }
    assert obs["sliding"].gains.gamma * 1e-3 > 10 * 1e-4
    assert on_sample["sliding"] > 0.99 and m["sliding"] > 1.5 * m["kf"]
    assert on_sample["linear"] < 0.01 and m["linear"] < 1.5 * m["kf"]


def _estimates(ob: object, sim: object, drops: bool) -> tuple[np.ndarray, np.ndarray]:
    """``(q̂, v̂)`` of ``ob`` over ``sim``'s noisy samples (every 37th dropped if ``drops``)."""
    ob.reset(sim.t[0], sim.q[0], None, sim.tau[0])  # type: ignore[attr-defined]
    qs, vs = [], []
    for k in range(1, sim.t.size):  # type: ignore[attr-defined]
        q = None if drops and k % 37 == 0 else sim.q_meas[k]  # type: ignore[attr-defined]
        e = ob.update(sim.t[k], q, sim.tau[k])  # type: ignore[attr-defined]
        qs.append(e.q)
        vs.append(e.v)
    return np.array(qs), np.array(vs)


@pytest.mark.parametrize("drops", [False, True])
def test_compiled_highgain_steps_equal_the_numpy_steps(drops: bool) -> None:
    """Issue 39: on a vector space ``highgain`` steps in one compiled call
    (:mod:`pinobs.observers.chain_kernels`), while ``L(t)`` converges (its RK4, ``L⁻¹Cᵀ`` as
    OpenBLAS's ``gesv`` computes it) and once it is steady (the first-order hold, its product
    as ``gemm``): the NumPy steps' estimates over 1 s (the switch to the steady gain at 0.67 s
    included), with dropped samples or without; and no one-BLAS-thread limit.  The same bits
    where OpenBLAS's kernel sums in the order written out (the machine it was written on);
    the order of a BLAS kernel is the CPU's, so the test asks for rounding: 1e-12 of each
    signal's scale."""
    robot = pinobs.load("ur5")
    sim = simulate(robot, [], duration=1.0, sensor=Sensor(1000.0, 1e-4), seed=3)
    fast = make_observer("highgain", robot, rate=1000.0, noise_std=1e-4)
    slow = make_observer("highgain", robot, rate=1000.0, noise_std=1e-4)
    slow._rk4 = slow._hold = None  # type: ignore[attr-defined]
    assert not fast.uses_blas
    (q1, v1), (q2, v2) = _estimates(fast, sim, drops), _estimates(slow, sim, drops)
    assert fast._state.L is fast._L_inf  # type: ignore[attr-defined]  # steady by the end
    for a, b in ((q1, q2), (v1, v2)):
        scale = np.abs(b).max(axis=0)
        assert np.all(np.abs(a - b).max(axis=0) <= 1e-12 * scale), np.abs(a - b).max(axis=0)


def test_the_compiled_gain_solve_is_numpys() -> None:
    """``chain_kernels._first_gain`` (OpenBLAS's ``getf2`` and ``getrs`` written out) against
    ``np.linalg.solve(L, e₁)`` on matrices along ``L(t)``'s path from ``L∞(γ/10)`` to
    ``L∞(γ)`` (perturbed), orders 2–5: a backward-stable solve (residual within 64 ε of
    ``‖L‖ ‖k‖``) and NumPy's to the conditioning's rounding (the same bits where OpenBLAS's
    kernel sums in the order written out; the order is the CPU's)."""
    from pinobs.observers import chain_kernels
    from pinobs.observers.fused import loaded

    loaded(chain_kernels.chain_rk4_kernel)  # (compiles the helper in place)
    rng = np.random.default_rng(0)
    for n in (2, 3, 4, 5):
        e1 = np.eye(n)[:, 0]
        for gamma in (5.0, 48.0, 500.0):
            L0, L1 = steady_gain_matrix(n, gamma / 10.0), steady_gain_matrix(n, gamma)
            for s in np.linspace(0.0, 1.0, 50):
                noise = 1e-3 * s * (1.0 - s) * rng.standard_normal((n, n)) * np.abs(L1)
                L = (1.0 - s) * L0 + s * L1 + noise
                k = np.empty(n)
                chain_kernels._first_gain(L, k)
                ref = np.linalg.solve(L, e1)
                eps = np.finfo(float).eps
                norm = np.linalg.norm(L, np.inf) * np.abs(k).max()
                assert np.abs(L @ k - e1).max() <= 64 * eps * norm, (n, gamma, s)
                bound = 64 * eps * np.linalg.cond(L, np.inf) * np.abs(ref).max()
                assert np.abs(k - ref).max() <= bound, (n, gamma, s)


@pytest.mark.parametrize("discretization", ["implicit", "explicit"])
def test_compiled_sliding_step_equals_the_numpy_step(discretization: str) -> None:
    """Issue 39: on a vector space ``sliding`` steps in one compiled call, no BLAS.  Its drift
    ``Σ x̂_{j+m} hᵐ/m!`` sums in the order of ``m`` where NumPy's vector–matrix product
    (OpenBLAS's ``gemv``) sums in its kernel's order: equal to rounding.  Measured (UR5, 1 s,
    σ = 1e-4, dropped samples): ≤ 3e-14 rad/s; noise-free at the default γ = 500 /s, which
    amplifies rounding most: 2.1e-12 rad/s on |v̂| ≈ 0.2."""
    robot = pinobs.load("ur5")
    sim = simulate(robot, [], duration=1.0, sensor=Sensor(1000.0, 1e-4), seed=3)
    opts = {"discretization": discretization, "gamma": 30.0}
    fast = make_observer("sliding", robot, rate=1000.0, noise_std=1e-4, **opts)
    slow = make_observer("sliding", robot, rate=1000.0, noise_std=1e-4, **opts)
    slow._fast = None  # type: ignore[attr-defined]
    assert not fast.uses_blas
    (q1, v1), (q2, v2) = _estimates(fast, sim, True), _estimates(slow, sim, True)
    np.testing.assert_allclose(q1, q2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v1, v2, rtol=0, atol=1e-12)
    assert np.ptp(v1) > 0.1  # a moving estimate (the explicit one chatters: module docstring)


# ------------------------------------------------ highgain's first-order hold (issue 39)
def _jittered_run(robot, sim, obs, stamps) -> np.ndarray:
    """The estimates ``(q̂, v̂)`` of ``obs`` over ``sim``'s samples at ``stamps``."""
    obs.reset(stamps[0], sim.q[0], None, sim.tau[0])
    out = []
    for k in range(1, stamps.size):
        q = None if k % 97 == 0 else sim.q_meas[k]  # a dropped sample now and then
        e = obs.update(stamps[k], q, sim.tau[k])
        out.append(np.concatenate([e.q, e.v]))
    return np.array(out)


def _expm_holds(obs) -> list[float]:
    """Make ``obs`` take every hold from SciPy's ``expm`` (the path before issue 39's change:
    ``expm(M·dt)`` at every interval); returns the list of intervals it computes."""
    import scipy.linalg

    n, seen = obs.gains.order, []

    class EveryInterval:  # (the cache's place: its ``get`` at every interval)
        @staticmethod
        def get(dt: float):
            seen.append(dt)
            E = scipy.linalg.expm(obs._M * dt)
            return E[:n, :n].copy(), E[:n, n].copy(), E[:n, n + 1].copy()

    obs._foh_cache = EveryInterval()
    return seen


@pytest.mark.parametrize("opts", [{}, {"order": 3, "gain_ramp": 1.0}])
def test_regular_and_jittered_stamps_agree_with_expms_holds(opts, monkeypatch) -> None:
    """Regular stamps (``arange·h``: intervals off ``h`` in their last bits) and ±50 µs of
    jitter at 1 kHz: within 1e-12 (relative) of ``expm(M·dt)`` at every interval, without
    calling ``expm`` (measured: 9e-16 on ``q̂``, 8e-14 on ``v̂`` with jitter); the hold at the
    nominal interval is ``expm``'s, bit for bit."""
    import scipy.linalg

    robot = pinobs.load("ur5")
    sim = simulate(robot, [], duration=1.5, sensor=Sensor(rate=1000.0, noise_std=1e-4), seed=0)
    rng = np.random.default_rng(1)
    jittered = sim.t + rng.uniform(-50e-6, 50e-6, size=sim.t.size)
    jittered[0] = sim.t[0]
    calls: list[tuple[object, ...]] = []
    for stamps in (sim.t, jittered):
        obs = make_observer("highgain", robot, rate=1000.0, noise_std=1e-4, **opts)
        monkeypatch.setattr(scipy.linalg, "expm", lambda *a: calls.append(a))
        got = _jittered_run(robot, sim, obs, stamps)
        monkeypatch.undo()
        assert calls == []  # no expm in an update
        ref = make_observer("highgain", robot, rate=1000.0, noise_std=1e-4, **opts)
        intervals = _expm_holds(ref)
        expected = _jittered_run(robot, sim, ref, stamps)
        assert len(set(intervals)) >= 3  # (the hold ran, at several dt)
        scale = np.abs(expected).max(axis=0)
        assert np.max(np.abs(got - expected) / scale) <= 1e-12
    n, h = obs.gains.order, obs._h
    E = scipy.linalg.expm(obs._M * h)
    Phi, psi0, psi1 = obs._foh_cache[h]
    assert np.array_equal(Phi, E[:n, :n]) and np.array_equal(psi0, E[:n, n])
    assert np.array_equal(psi1, E[:n, n + 1])


def test_the_hold_between_intervals_is_expms_compiled_or_not() -> None:
    """:meth:`hold_between` against ``expm``, scaled per entry by the chain's ``γ^{i−j}``:
    within 1e-14 of it for |dt − h| ≤ h/2 (measured 1.1e-15) and 1e-13 up to 10.5 h (measured
    1.9e-14); the compiled kernel and the NumPy path agree to 1e-14."""
    import scipy.linalg

    robot = pinobs.load("ur5")
    rng = np.random.default_rng(0)
    for order in (2, 4, 6):
        obs = make_observer("highgain", robot, rate=1000.0, noise_std=1e-4, order=order)
        n, h = order, obs._h
        s = obs.gains.gamma ** np.r_[np.arange(n), 0.0, 1.0]
        scale = s[None, :] / s[:n, None]
        for dts, tol in ((h + rng.uniform(-0.5, 0.5, 100) * h, 1e-14),
                         (rng.uniform(1e-7, 10.5, 100) * h, 1e-13)):  # fmt: skip
            for dt in dts:
                E = scipy.linalg.expm(obs._M * dt)[:n]
                compiled = np.column_stack(obs.hold_between(dt))
                kernel, obs._between = obs._between, None
                numpy = np.column_stack(obs.hold_between(dt))
                obs._between = kernel
                top = np.max(np.abs(E) * scale)
                assert np.max(np.abs(compiled - E) * scale) <= tol * top
                assert np.max(np.abs(numpy - compiled) * scale) <= 1e-14 * top
