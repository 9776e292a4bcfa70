"""The intrinsic Riemannian observer: geometry, discretisation, invariance, convergence, S³."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

import pinobs
from pinobs.evaluation import measure_cost
from pinobs.model import lie_rk4
from pinobs.model.sphere import (
    anisi_hamberg_potential,
    anisi_hamberg_torque,
    body_velocity,
    coordinate_velocity,
    hyperspherical,
    quaternion,
    unit_three_sphere,
)
from pinobs.observers.riemannian import (
    RiemannianObserver,
    anisi_hamberg_curvature_gain,
    discrete_gains,
    gains_from_noise,
    geodesic_error,
    jacobi_operator,
    jacobi_term,
    steady_gains,
    transport_first_order,
)
from pinobs.simulation import InputProfile, Sensor, simulate

# ----------------------------------------------------------------- geometry


@pytest.mark.parametrize("name", ["ur5", "rigid_body", "top", "double_pendulum_continuous"])
def test_jacobi_contractions_equal_the_model_curvature(name: str, rng) -> None:
    robot = pinobs.load(name)
    q = robot.random_configuration(rng)
    v, z = rng.standard_normal(robot.nv), 1e-2 * rng.standard_normal(robot.nv)
    reference = robot.curvature(q, v, z, v)
    scale = np.abs(reference).max()
    assert np.abs(jacobi_term(robot, q, v, z) - reference).max() <= 1e-12 * max(scale, 1.0)
    assert np.abs(jacobi_operator(robot, q, v) @ z - reference).max() <= 1e-8 * max(scale, 1.0)


@pytest.mark.parametrize("name", ["ur5", "rigid_body"])
def test_model_jacobian_helpers_agree_with_the_dynamics(name: str, rng) -> None:
    robot = pinobs.load(name)
    q = robot.random_configuration(rng)
    v, tau = rng.standard_normal(robot.nv), rng.standard_normal(robot.nv)
    acc, a_q, a_v = robot.forward_dynamics_jacobians(q, v, tau)
    dq, dv, _ = robot.forward_dynamics_derivatives(q, v, tau)
    np.testing.assert_allclose(acc, robot.forward_dynamics(q, v, tau), atol=1e-12)
    np.testing.assert_allclose(a_q, dq, atol=1e-12)
    np.testing.assert_allclose(a_v, dv, atol=1e-12)
    spray, s_q, s_x = robot.spray_jacobians(q, v)
    np.testing.assert_allclose(spray, robot.geodesic_spray(q, v), atol=1e-12)
    np.testing.assert_allclose(s_q, robot.spray_derivative(q, v), atol=1e-12)
    np.testing.assert_allclose(s_x @ tau, 2.0 * robot.christoffel(q, v, tau), atol=1e-10)


def _geodesic_transport(robot, q_hat, u, y0, n=200):
    """Geodesic from q̂ with initial velocity u over [0, 1], carrying y parallel: (γ(1), y(1))."""

    def rhs(q, x):
        v, y = x[: robot.nv], x[robot.nv :]
        return v, np.concatenate([-robot.geodesic_spray(q, v), -robot.connection(q, v, y)])

    q, x = q_hat, np.concatenate([u, y0])
    for _ in range(n):
        q, x = lie_rk4(robot, q, x, 1.0 / n, rhs)
    return q, x[robot.nv :]


@pytest.mark.parametrize("name", ["ur5", "rigid_body", "double_pendulum_continuous"])
def test_geodesic_error_is_third_order_and_transport_second_order(name: str, rng) -> None:
    """ζ = −log_q̂(q) to O(|u|³); S∥ = S − ω(ζ, S) to O(|u|²) against an integrated transport."""
    robot = pinobs.load(name)
    q_hat = robot.random_configuration(rng)
    d = rng.standard_normal(robot.nv)
    d /= np.linalg.norm(d)
    s_hat = rng.standard_normal(robot.nv)
    zeta_err, transport_err, printed_err = [], [], []
    for eps in (0.1, 0.05, 0.025):
        u = eps * d  # log_q̂(q) = u exactly, so ζ = −u
        q, s_at_q = _geodesic_transport(robot, q_hat, u, s_hat)  # S at q, its transport is s_hat
        zeta = geodesic_error(robot, q_hat, q)
        zeta_err.append(np.linalg.norm(zeta + u))
        transport_err.append(
            np.linalg.norm(transport_first_order(robot, q_hat, zeta, s_at_q) - s_hat)
        )
        printed = s_at_q - robot.connection(q_hat, s_at_q, zeta)  # Maithripala eq. (19) as printed
        printed_err.append(np.linalg.norm(printed - s_hat))
    zeta_ratio = zeta_err[1] / zeta_err[2]
    transport_ratio = transport_err[1] / transport_err[2]
    assert 7.0 < zeta_ratio < 9.0  # halving |u| divides the error by 8
    assert 3.6 < transport_ratio < 4.4  # ... and by 4
    if robot.has_lie_group_joints:  # the printed argument order is only first order: ratio 2
        assert 1.8 < printed_err[1] / printed_err[2] < 2.2
        assert printed_err[2] > 50 * transport_err[2]


# ------------------------------------------------------------ discretisation


@pytest.mark.parametrize("alpha_h", [0.01, 0.5, 1.0, 3.0, 30.0])
@pytest.mark.parametrize("beta_over_alpha2", [0.25, 1.0, 4.0])
def test_discrete_error_poles_are_the_exponentials_of_the_continuous_ones(
    alpha_h: float, beta_over_alpha2: float
) -> None:
    h = 1e-3
    alpha = alpha_h / h
    beta = beta_over_alpha2 * alpha**2
    k1, k2 = discrete_gains(alpha, beta, h)
    closed = (np.eye(2) - np.outer([k1, k2], [1.0, 0.0])) @ np.array([[1.0, h], [0.0, 1.0]])
    continuous = np.array([[-2.0 * alpha, 1.0], [-beta, 0.0]])
    lam = np.sort_complex(np.linalg.eigvals(closed))
    expected = np.sort_complex(np.linalg.eigvals(scipy.linalg.expm(continuous * h)))
    np.testing.assert_allclose(lam, expected, atol=1e-9)
    assert np.abs(lam).max() < 1.0  # stable at every α·h


def test_discrete_gains_tend_to_the_continuous_observer() -> None:
    k1, k2 = discrete_gains(30.0, 500.0, 1e-6)
    assert k1 == pytest.approx(2 * 30.0 * 1e-6, rel=1e-4)
    assert k2 == pytest.approx(500.0 * 1e-6 / 1e-6 * 1e-6, rel=1e-3)


def test_gain_rule_reproduces_the_steady_state_kalman_gain() -> None:
    rate, sigma, psd = 1000.0, 1e-4, 1e-6
    h = 1.0 / rate
    alpha, beta = gains_from_noise(rate, sigma, psd)
    F = np.array([[1.0, h], [0.0, 1.0]])
    Q = psd * np.array([[h**3 / 3, h**2 / 2], [h**2 / 2, h]])
    P = scipy.linalg.solve_discrete_are(F.T, np.array([[1.0], [0.0]]), Q, np.array([[sigma**2]]))
    kalman = P[:, 0] / (P[0, 0] + sigma**2)
    np.testing.assert_allclose(discrete_gains(alpha, beta, h), kalman, rtol=1e-8)
    ob = RiemannianObserver(pinobs.load("cartpole"), rate=rate, noise_std=sigma, accel_psd=psd)
    assert ob.options["gain_rule"] == "kalman" and ob.gains.alpha == pytest.approx(alpha)


@pytest.mark.parametrize("sigma", [1e-4, 1e-5])
def test_gain_rule_reproduces_fast_kalman_gains(sigma: float) -> None:
    # 500 Hz, accel_psd 1: at σ 1e-5 the error poles are a complex pair of negative real part
    rate, psd = 500.0, 1.0
    h = 1.0 / rate
    F = np.array([[1.0, h], [0.0, 1.0]])
    Q = psd * np.array([[h**3 / 3, h**2 / 2], [h**2 / 2, h]])
    P = scipy.linalg.solve_discrete_are(F.T, np.array([[1.0], [0.0]]), Q, np.array([[sigma**2]]))
    kalman = P[:, 0] / (P[0, 0] + sigma**2)
    np.testing.assert_allclose(
        discrete_gains(*gains_from_noise(rate, sigma, psd), h), kalman, rtol=1e-8
    )


def _dare_gain(rate: float, sigma: float, psd: float) -> tuple[np.ndarray, np.ndarray]:
    """The steady-state Kalman gain of the double integrator and its error poles (SciPy)."""
    h = 1.0 / rate
    F = np.array([[1.0, h], [0.0, 1.0]])
    Q = psd * np.array([[h**3 / 3, h**2 / 2], [h**2 / 2, h]])
    P = scipy.linalg.solve_discrete_are(F.T, np.array([[1.0], [0.0]]), Q, np.array([[sigma**2]]))
    gain = P[:, 0] / (P[0, 0] + sigma**2)
    return gain, np.linalg.eigvals((np.eye(2) - np.outer(gain, [1.0, 0.0])) @ F)


@pytest.mark.parametrize(
    ("rate", "sigma", "psd"),
    [(500.0, 1e-6, 1.0), (500.0, 1e-7, 1.0), (500.0, 1e-9, 1.0), (100.0, 5.24e-6, 28.1)],
)
def test_gain_rule_clips_negative_real_kalman_poles_to_the_nearest_reachable_gain(
    rate: float, sigma: float, psd: float
) -> None:
    """Where the DARE's error poles are two negative reals (no (α, β) has them; it used to
    raise, and before that returned β = -8.6e4 at 1e-6), the rule keeps k₁ and takes the
    largest k₂ the form reaches, k₂h = (1 + √(1 − k₁))²: the double pole −√(1 − k₁).
    The last case is TIAGo's identified density at its σ and rate."""
    h = 1.0 / rate
    kalman, poles = _dare_gain(rate, sigma, psd)
    assert np.all(poles.real < 0.0) and np.all(np.abs(poles.imag) < 1e-12)  # the premise
    rule = steady_gains(rate, sigma, psd)
    assert rule.clipped
    np.testing.assert_allclose(rule.kalman, kalman, rtol=1e-9)
    k1, k2 = discrete_gains(rule.alpha, rule.beta, h)
    assert k1 == pytest.approx(kalman[0], rel=1e-12)
    bound = (1.0 + math.sqrt(1.0 - k1)) ** 2
    assert k2 * h == pytest.approx(bound, rel=1e-9) and k2 < kalman[1]
    closed = (np.eye(2) - np.outer([k1, k2], [1.0, 0.0])) @ np.array([[1.0, h], [0.0, 1.0]])
    assert np.trace(closed) == pytest.approx(-2.0 * math.sqrt(1.0 - k1), rel=1e-6)
    assert np.linalg.det(closed) == pytest.approx(1.0 - k1, rel=1e-6)
    # the bound is the largest k₂ of this k₁: no β reaches past it
    betas = np.add.outer(rule.alpha**2 * np.array([0.01, 0.5, 1.0]), np.linspace(0, 40, 41) / h**2)
    for beta in betas.ravel():
        assert discrete_gains(rule.alpha, beta, h)[1] * h <= bound * (1.0 + 1e-12)


def test_clipped_gain_rule_is_continuous_with_the_exact_one_at_the_boundary() -> None:
    """At 500 Hz, ψ = 1: σ 1e-5 gives complex poles, 1e-6 negative reals.  Bisected to the σ
    where the rule starts to clip, the exact rule's β there is α² + (π/h)², the clipped one's."""
    lo, hi = math.log(1e-5), math.log(1e-6)  # lo: not clipped, hi: clipped
    assert not steady_gains(500.0, 1e-5, 1.0).clipped and steady_gains(500.0, 1e-6, 1.0).clipped
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if steady_gains(500.0, math.exp(mid), 1.0).clipped else (mid, hi)
    exact, clipped = steady_gains(500.0, math.exp(lo), 1.0), steady_gains(500.0, math.exp(hi), 1.0)
    assert not exact.clipped and clipped.clipped
    assert exact.alpha == pytest.approx(clipped.alpha, rel=1e-9)
    assert exact.beta == pytest.approx(clipped.beta, rel=1e-6)  # (measured 4e-8)


@pytest.mark.parametrize("sigma", [1e-6, 1e-9])
def test_observer_records_the_clipped_rule_and_warns_where_it_runs_it(sigma: float) -> None:
    robot = pinobs.load("cartpole")
    ob = RiemannianObserver(robot, rate=500.0, noise_std=sigma, accel_psd=1.0)
    assert ob.options["gain_rule"] == "kalman-clipped" and ob.gain_schedule == "riccati"
    with pytest.warns(pinobs.PinobsWarning, match=r"out of \(alpha, beta\)'s reach"):
        steady = RiemannianObserver(
            robot, rate=500.0, noise_std=sigma, accel_psd=1.0, gain_schedule="steady"
        )
    assert (steady.gains.alpha, steady.gains.beta) == gains_from_noise(500.0, sigma, 1.0)
    assert steady.options["gain_rule"] == "kalman-clipped"


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"alpha": 0.0, "beta": 1.0}, "alpha=0.0 is out of range"),
        ({"alpha": 1.0, "beta": -2.0}, "beta=-2.0 is out of range"),
        ({"alpha": float("nan"), "beta": 1.0}, "alpha=nan is out of range"),
        ({"alpha": 1.0}, "give both alpha and beta or neither"),
        ({"curvature_gain": float("inf")}, "curvature_gain=inf is not a finite number"),
        ({"curvature_every": 0}, "curvature_every=0; give an integer >= 1"),
        ({"accel_psd": 0.0}, "accel_psd=0.0 is out of range"),
        ({"gain_a": 3.0, "beta": 1.0}, "not callable"),
        ({"gain_a": lambda s, v: -1.0, "beta": 1.0}, r"gain_a\(S=0, speed=0\) = -1.0"),
    ],
)
def test_bad_gains_raise_gainerror_naming_them(options, match: str) -> None:
    with pytest.raises(pinobs.GainError, match=match) as info:
        RiemannianObserver(pinobs.load("cartpole"), **options)
    assert isinstance(info.value, ValueError)


def test_state_dependent_gain_failing_at_run_time_raises_gainerror() -> None:
    robot = pinobs.load("cartpole")
    ob = RiemannianObserver(robot, gain_a=lambda s, v: 1.0 if s == 0.0 else math.nan, beta=1.0)
    ob.reset(0.0, robot.neutral())
    with pytest.raises(pinobs.GainError, match=r"gain_a.*must be finite and > 0"):
        ob.update(1e-3, robot.integrate(robot.neutral(), np.array([1e-2, 0.0])))


def test_anisi_hamberg_curvature_gain_tends_to_minus_one() -> None:
    c = anisi_hamberg_curvature_gain(1.0)
    assert c(0.0, 0.0) == pytest.approx(-1.0)
    s = 0.5 * 1.0**2  # distance 1 on the unit sphere: −2 tan(½)/1
    assert c(s, 0.0) == pytest.approx(-2.0 * math.tan(0.5))
    assert anisi_hamberg_curvature_gain(-1.0)(s, 0.0) == pytest.approx(-2.0 * math.tanh(0.5))
    with pytest.raises(pinobs.GainError, match="kappa=0"):
        anisi_hamberg_curvature_gain(0.0)


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"curvature_gain": 0.0},
        {"gain_schedule": "steady"},
        {"alpha": 5.0, "beta": 50.0, "gain_a": lambda s, speed: 10.0 + s},
    ],
)
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_compiled_vector_space_correction_equals_the_general_one(name: str, options, rng) -> None:
    robot = pinobs.load(name)
    ob = RiemannianObserver(robot, rate=1000.0, noise_std=1e-4, **options)
    tau = rng.standard_normal(robot.nv)
    ob.reset(0.0, robot.random_configuration(rng), rng.standard_normal(robot.nv), tau)
    state = ob._state
    q = robot.random_configuration(rng)
    v = rng.standard_normal(robot.nv)
    q_meas = robot.integrate(q, 1e-2 * rng.standard_normal(robot.nv))
    general = ob._correct(state, q, v, q_meas, tau, 1e-3)
    compiled = ob._correct_vector_space(state, q, v, q_meas, tau, 1e-3, None, state.gate)
    assert np.abs(general.v - v).max() > 1e-4  # the correction did something
    assert np.abs(compiled.q - general.q).max() <= 1e-14
    assert np.abs(compiled.v - general.v).max() <= 1e-13 * np.abs(general.v).max()
    assert compiled.P == general.P and compiled.age == general.age


def test_update_costs_the_counted_dynamics_calls(monkeypatch) -> None:
    """Per update: 4 ABA (RK4), 1 ABA-derivatives call, 4 more (curvature) every 10 samples.

    Counted at Pinocchio itself, so no wrapper can hide a call.
    """
    import pinocchio

    robot = pinobs.load("ur5")
    counts = {"aba": 0, "computeABADerivatives": 0}
    for method in counts:
        original = getattr(pinocchio, method)

        def counted(*args, _original=original, _method=method):
            counts[_method] += 1
            return _original(*args)

        monkeypatch.setattr(pinocchio, method, counted)
    # built after the patch: the observer binds Pinocchio's calls when it is made
    ob = RiemannianObserver(robot, alpha=20.0, beta=400.0)
    q0 = robot.neutral()
    ob.reset(0.0, q0, np.ones(robot.nv))
    for k in range(1, 21):
        ob.update(k * 1e-3, robot.integrate(q0, k * 1e-3 * np.ones(robot.nv) + 1e-5))
    assert counts == {"aba": 20 * 4, "computeABADerivatives": 20 + 2 * 4}
    monkeypatch.undo()
    ratio = measure_cost(RiemannianObserver(robot, alpha=20.0, beta=400.0), samples=500)["ratio"]
    print(f"ur5: time(update)/time(pin.aba) = {ratio:.1f}")
    assert math.isfinite(ratio) and ratio > 1.0


def test_free_flyer_run_equals_the_dense_solve_and_numpy_norm_to_1e_12(monkeypatch) -> None:
    """go1: the run with the Lie-group RK's LAPACK block solves and the cheaper quaternion
    normalisation equals, to 1e-12, the run with the dense ``np.linalg.solve`` of the
    exponential's Jacobian and ``np.linalg.norm`` (the implementation before)."""
    from pinobs.model.robot import Robot

    robot = pinobs.load("go1")
    res = simulate(robot, [], duration=0.3, sensor=Sensor(1000.0, 1e-4), seed=2)

    def run() -> tuple[np.ndarray, np.ndarray]:
        ob = RiemannianObserver(robot, rate=1000.0, noise_std=1e-4)
        ob.reset(res.t[0], robot.integrate(res.q[0], np.full(robot.nv, 1e-3)), None, res.tau[0])
        rows = zip(res.t[1:], res.q_meas[1:], res.tau[1:], strict=True)
        est = [ob.update(t, q, tau) for t, q, tau in rows]
        return np.array([e.q for e in est]), np.array([e.v for e in est])

    q_new, v_new = run()

    def dense_solve(self, q, xi, u):
        return np.linalg.solve(self.integrate_jacobian(q, xi), u)

    def numpy_norm(self, q):
        out = np.array(q, dtype=float)
        for s in self._unit_slices:
            out[s] /= np.linalg.norm(out[s])
        return out

    monkeypatch.setattr(Robot, "integrate_jacobian_solve", dense_solve)
    monkeypatch.setattr(Robot, "normalize", numpy_norm)
    q_old, v_old = run()
    # a run that does something: from a 1e-3 start error, the velocity error falls 100-fold
    assert np.abs(v_new[-100:] - res.v[-100:]).max() < 0.01 * np.abs(v_new[:10] - res.v[1:11]).max()
    np.testing.assert_allclose(q_new, q_old, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v_new, v_old, rtol=0, atol=1e-12 * np.abs(v_old).max())


# ------------------------------------------------------- continuous time


@pytest.mark.parametrize("name", ["panda", "rigid_body", "double_pendulum_continuous"])
def test_vector_field_on_the_truth_is_the_model(name: str, rng) -> None:
    robot = pinobs.load(name)
    ob = RiemannianObserver(robot, alpha=50.0, beta=900.0)
    q = robot.random_configuration(rng)
    v, tau = rng.standard_normal(robot.nv), rng.standard_normal(robot.nv)
    q_dot, v_dot = ob.vector_field(q, v, q, tau)
    np.testing.assert_allclose(q_dot, v, atol=1e-12)
    np.testing.assert_allclose(v_dot, robot.forward_dynamics(q, v, tau), atol=1e-9)


# ----------------------------------------------------------- sampled runs


@pytest.mark.parametrize(
    ("name", "duration"),
    [("panda", 1.0), ("rigid_body", 1.0), ("double_pendulum_continuous", 1.0), ("pr2", 0.3)],
)
def test_started_on_the_truth_without_noise_it_stays_there(name: str, duration: float) -> None:
    robot = pinobs.load(name)
    ob = RiemannianObserver(robot, alpha=60.0, beta=900.0)
    res = simulate(robot, {"r": ob}, duration=duration, sensor=Sensor(rate=1000.0), seed=1)
    err = np.abs(res.trace("r").v - res.v)
    # measured: 2.4e-14 (panda), 3.1e-14 (rigid_body), 4.4e-15 (double pendulum), 1.5e-14 (pr2) rad/s
    assert np.all(np.isfinite(err)) and err.max() < 1e-9


@pytest.mark.parametrize("name", ["cartpole", "ur5", "top", "rigid_body"])
def test_converges_from_a_perturbed_start(name: str) -> None:
    robot = pinobs.load(name)
    ob = RiemannianObserver(robot, alpha=20.0, beta=400.0)
    res = simulate(
        robot,
        {"r": ob},
        duration=1.0,
        sensor=Sensor(rate=1000.0),
        seed=1,
        perturb_q=0.1,
        perturb_v=1.0,
    )
    err = np.linalg.norm(res.trace("r").v - res.v, axis=1)
    # measured at 1 s from 1.0 rad/s: 1.1e-7 (cartpole), 6.9e-8 (ur5), 6.0e-8 (top), 6.8e-8 (rigid_body)
    assert err[-1] < 1e-5 * err[0]
    assert err[500:].max() < 1e-2 * err[0]


def _identified(name: str, psd: float):
    """``name`` carrying an identified model error ψ = ``psd`` [rad²/s³] (exact model)."""
    robot = pinobs.load(name)
    robot.model_error_psd = psd
    return robot


def _on_the_robots_density(robot, schedule: str) -> RiemannianObserver:
    """riemannian at its default density (the robot's ψ), 1 kHz, σ its default 1e-6."""
    if schedule == "riccati":
        return RiemannianObserver(robot, rate=1000.0)
    with pytest.warns(pinobs.PinobsWarning, match="out of"):  # (ψ = 28.1 is: clipped)
        return RiemannianObserver(robot, rate=1000.0, gain_schedule=schedule)


@pytest.mark.parametrize("schedule", ["riccati", "steady"])
@pytest.mark.parametrize("psd", [1e-3, 28.1])
def test_on_the_truth_with_the_robots_own_density_it_stays_there(psd: float, schedule: str) -> None:
    """Invariance with an identified ψ (28.1: TIAGo's, clipped at 1 kHz, σ 1e-6): the gains
    change, the fixed point does not."""
    robot = _identified("panda", psd)
    if schedule == "steady" and psd < 1.0:
        ob = RiemannianObserver(robot, rate=1000.0, gain_schedule="steady")  # (not clipped)
    else:
        ob = _on_the_robots_density(robot, schedule)
    assert ob.accel_psd == psd and ob.gain_rule == ("kalman-clipped" if psd > 1 else "kalman")
    res = simulate(robot, {"r": ob}, duration=1.0, sensor=Sensor(rate=1000.0), seed=1)
    err = np.abs(res.trace("r").v - res.v)
    assert np.all(np.isfinite(err)) and err.max() < 1e-9


@pytest.mark.parametrize("schedule", ["riccati", "steady"])
@pytest.mark.parametrize("name", ["ur5", "rigid_body"])
def test_converges_from_a_perturbed_start_with_clipped_gains(name: str, schedule: str) -> None:
    ob = _on_the_robots_density(_identified(name, 28.1), schedule)
    assert ob.gain_rule == "kalman-clipped"
    res = simulate(
        ob.robot, {"r": ob}, duration=0.5, sensor=Sensor(rate=1000.0), seed=1,
        perturb_q=0.1, perturb_v=1.0,
    )  # fmt: skip
    err = np.linalg.norm(res.trace("r").v - res.v, axis=1)
    assert err[-1] < 1e-5 * err[0]
    assert err[50:].max() < 1e-2 * err[0]


@pytest.mark.slow  # (about 60 s: the truth in 40 substeps, the prediction in friction substeps)
def test_coulomb_friction_in_the_model_keeps_the_accuracy() -> None:
    """Smoothed Coulomb friction in the model (and the truth) makes the prediction stiff near
    v = 0 (λh up to 55 on a Panda at 1 kHz): predicted in ``friction_substeps`` substeps as
    the ekf's, within 2× of the frictionless accuracy (measured, 1 s, seeds 0 and 1:
    1.4e-4 -> 5.6e-5, 5.9e-5 -> 5.2e-5 rad/s; in one RK4 step: 0.052 and 0.057).  The truth
    integrated finely (40 substeps), as ``test_ekf.py``'s."""
    base = pinobs.load("panda")
    fc = np.random.default_rng(0).uniform(1.0, 3.0, base.nv)
    rms = []
    for r in (base, base.perturbed(coulomb=fc, damping=np.zeros(base.nv))):
        res = simulate(
            r, ["riemannian"], sensor=Sensor(1000, 1e-4), inputs="pd", duration=1.0, seed=0,
            substeps=40,
        )  # fmt: skip
        rms.append(float(np.sqrt(np.mean((res.trace("riemannian").v - res.v)[250:] ** 2))))
    assert rms[1] < 2.0 * rms[0]


class _Spin(InputProfile):
    """Computed torque: joint 1 at constant speed ``w`` [rad/s], joint 2 held at ``q2`` [rad]."""

    name = "spin"

    def __init__(self, robot, w: float, q2: float) -> None:
        self.robot, self.w, self.q2 = robot.copy(), w, q2

    def torque(self, t, q, v):
        q2 = math.atan2(q[3], q[2])
        a = np.array([20.0 * (self.w - v[0]), 400.0 * (self.q2 - q2) - 40.0 * v[1]])
        return self.robot.inverse_dynamics(q, v, a)


def _spin_errors(curvature_gain: float) -> np.ndarray:
    robot = pinobs.load("double_pendulum_continuous")
    q0 = robot.integrate(robot.neutral(), np.array([0.0, 2.6]))
    ob = RiemannianObserver(robot, alpha=10.0, beta=100.0, curvature_gain=curvature_gain)
    res = simulate(
        robot,
        {"r": ob},
        duration=1.5,
        sensor=Sensor(rate=1000.0),
        inputs=_Spin(robot, 20.0, 2.6),
        q0=q0,
        v0=np.array([20.0, 0.0]),
        perturb_q=2e-3,
        perturb_v=5e-2,
        seed=2,
    )
    return np.linalg.norm(res.trace("r").v - res.v, axis=1)


def test_curvature_term_makes_convergence_hold_where_dropping_it_fails() -> None:
    """Folded double pendulum (q2 = 2.6, sectional curvature −207) spun at 20 rad/s.

    Linearised error dynamics: D_tε = −βJ + (1 + C) R(v, J)v, with
    R(v,J)v = +207·|v|²_g J here (|v|²_g = 0.0566 rad²·kg·m²/s² → 234 > β = 100).
    C = −1 (default) cancels it; C = 0 (term dropped) leaves a negative
    stiffness 100 − 234; C = +1 (MATH §4 / Maithripala as printed) doubles it.
    """
    with_term, dropped, doubled = _spin_errors(-1.0), _spin_errors(0.0), _spin_errors(1.0)
    # measured at 1.5 s from 5e-2 rad/s: 2.5e-7, 6.0e-2, 3.0e1
    assert with_term[-1] < 1e-5
    assert dropped[-1] > 1e-2
    assert doubled[-1] > 1.0


def test_on_the_sphere_the_curvature_gain_sets_the_stiffness_as_derived() -> None:
    """Unit S³ (K = 1), geodesic at |v|_g = 5: slow decay rate α − √(α² − β − (1+C)K|v|²)."""
    robot = unit_three_sphere()
    alpha, beta, speed2 = 10.0, 25.0, 25.0
    for c in (-1.0, 0.0, 1.0):
        ob = RiemannianObserver(robot, alpha=alpha, beta=beta, curvature_gain=c, curvature_every=1)
        res = simulate(
            robot,
            {"r": ob},
            duration=2.0,
            sensor=Sensor(rate=1000.0),
            inputs="zero",
            q0=robot.neutral(),
            v0=np.array([10.0, 0.0, 0.0]),
            perturb_q=1e-3,
            perturb_v=1e-2,
            seed=3,
        )
        perp = np.linalg.norm((res.trace("r").v - res.v)[:, 1:], axis=1)  # error ⊥ v
        sel = (res.t > 0.8) & (res.t < 1.8)
        rate = -np.polyfit(res.t[sel], np.log(perp[sel]), 1)[0]
        stiffness = beta + (1.0 + c) * 1.0 * speed2
        expected = alpha - math.sqrt(alpha**2 - stiffness)
        assert rate == pytest.approx(expected, rel=0.03)  # measured 1.33, 2.93, 5.02


def test_noisy_ur5_velocity_error_is_within_1_5_of_the_exact_model_ekf() -> None:
    """UR5, pd input, 1 kHz, σ = 1e-4 rad, 2 s (RMS after 0.5 s); the same process noise as ``ekf``."""
    robot = pinobs.load("ur5")
    names = ["kf", "ekf"] if "ekf" in pinobs.observer_names() else ["kf"]
    obs = {n: pinobs.make_observer(n, robot, rate=1000.0, noise_std=1e-4) for n in names}
    obs["riemannian"] = RiemannianObserver(robot, rate=1000.0, noise_std=1e-4)
    res = simulate(
        robot, obs, duration=2.0, sensor=Sensor(rate=1000.0, noise_std=1e-4), inputs="pd"
    )
    rms = {m.observer: m.rms_v_error for m in pinobs.evaluate(res, robot, transient=0.5)}
    print({k: f"{v:.3g}" for k, v in rms.items()})
    assert rms["riemannian"] < rms["kf"] / 10
    if "ekf" in rms:  # measured: 3.3e-5 vs 3.5e-5 (kf 1.2e-2)
        assert rms["riemannian"] < 1.5 * rms["ekf"]


# --------------------------------------------------------------------- S³


def test_sphere_model_is_the_unit_three_sphere(rng) -> None:
    robot = unit_three_sphere()
    q0 = robot.neutral()
    x, y = rng.standard_normal(3), rng.standard_normal(3)
    assert robot.sectional_curvature(q0, x, y) == pytest.approx(1.0)
    assert np.abs(robot.geodesic_spray(q0, x)).max() < 1e-14  # bi-invariant: group log exact
    coords = np.array([1.0, 0.7, 2.0])
    np.testing.assert_allclose(hyperspherical(quaternion(coords)), coords, atol=1e-14)
    xdot = np.array([2.25, 1.25, 4.0])
    omega = body_velocity(coords, xdot)
    np.testing.assert_allclose(coordinate_velocity(quaternion(coords), omega), xdot, atol=1e-12)
    metric = np.diag([1.0, math.sin(1.0) ** 2, (math.sin(1.0) * math.sin(0.7)) ** 2])
    assert robot.metric(quaternion(coords), omega, omega) == pytest.approx(xdot @ metric @ xdot)
    # distances: metric norm of the rotation log = S³ arc while <q0, q1> > 0, π − arc beyond
    for arc in (0.3, 1.2, 2.0):
        q1 = quaternion(np.array([arc, 0.4, 1.0]))
        p0 = quaternion(np.zeros(3))
        log = robot.difference(p0, q1)
        d = math.sqrt(robot.metric(p0, log, log))
        assert d == pytest.approx(arc if arc < math.pi / 2 else math.pi - arc, abs=1e-12)
    q = quaternion(coords)
    fd = np.array(
        [
            -(
                anisi_hamberg_potential(robot.integrate(q, 1e-6 * e))
                - anisi_hamberg_potential(robot.integrate(q, -1e-6 * e))
            )
            / 2e-6
            for e in np.eye(3)
        ]
    )
    np.testing.assert_allclose(anisi_hamberg_torque(q), fd, atol=1e-8)


def test_anisi_hamberg_example_tracks_position_and_slides_in_velocity() -> None:
    """§5: A = 3(1+S)/√(S+1e-7), B = 3, C = −1, F = −grad W, ξ(0) = x(0), η(0) = 0.

    Near S = 0, A·ζ has norm ≈ 3√2 > |Δv|_g = 3.30: the position error is held
    in a sliding regime (dist ≈ 5e-3 rad) while the velocity error decays only
    at ≈ B/A ≈ 5e-3 /s, as V̇ = −2ABS ≈ −18√S of their §4.4 implies.
    """
    robot = unit_three_sphere()
    coords, xdot = np.array([1.0, 0.7, 2.0]), np.array([2.25, 1.25, 4.0])
    q, v = quaternion(coords), body_velocity(coords, xdot)
    ob = RiemannianObserver(
        robot,
        gain_a=lambda s, speed: 3.0 * (1.0 + s) / math.sqrt(s + 1e-7),
        beta=3.0,
        curvature_gain=-1.0,
        curvature_every=1,
    )
    ob.reset(0.0, q, np.zeros(3), anisi_hamberg_torque(q))
    h, dist, verr = 1e-3, [], []
    for k in range(1, 2001):
        tau = anisi_hamberg_torque(q)
        q, v = lie_rk4(
            robot, q, v, h, lambda qq, vv, tau=tau: (vv, robot.forward_dynamics(qq, vv, tau))
        )
        est = ob.update(k * h, q, anisi_hamberg_torque(q))
        dist.append(math.acos(min(1.0, float(q @ est.q))))
        verr.append(math.sqrt(robot.metric(q, est.v - v, est.v - v)))
    assert max(dist) < 1e-2  # measured 4.7e-3 max
    assert 3.0 < verr[-1] < verr[0]  # measured 3.30 -> 3.26 over 2 s


def test_riccati_schedule_settles_on_the_steady_state_kalman_gains() -> None:
    from pinobs.observers.riemannian import discrete_gains, gains_from_noise

    robot = pinobs.load("pendulum")
    ob = pinobs.make_observer("riemannian", robot, rate=1000.0, noise_std=1e-4)
    assert ob.options["gain_schedule"] == "riccati"
    ob.reset(0.0, np.zeros(1))
    for k in range(1, 20001):
        ob.update(k * 1e-3, np.zeros(1))
    p00, p01, p11 = (
        ob._state.P
    )  # the posterior covariance after 20 s: the next gain is the steady one
    P = np.array([[p00, p01], [p01, p11]])
    alpha, beta = gains_from_noise(1000.0, 1e-4, 1e-8)
    k1, k2 = discrete_gains(alpha, beta, 1e-3)
    h, q = 1e-3, 1e-8
    F = np.array([[1.0, h], [0.0, 1.0]])
    prior = F @ P @ F.T + q * np.array([[h**3 / 3, h**2 / 2], [h**2 / 2, h]])
    gain = prior[:, 0] / (prior[0, 0] + 1e-8)
    np.testing.assert_allclose(gain, [k1, k2], rtol=1e-6)


def test_riccati_schedule_shortens_the_transient_and_keeps_the_noise_level() -> None:
    robot = pinobs.load("ur5")
    obs = {
        "riccati": pinobs.make_observer("riemannian", robot, rate=1000.0, noise_std=1e-4),
        "steady": pinobs.make_observer(
            "riemannian", robot, rate=1000.0, noise_std=1e-4, gain_schedule="steady"
        ),
        "ekf": pinobs.make_observer("ekf", robot, rate=1000.0, noise_std=1e-4),
    }
    res = pinobs.simulate(
        robot,
        obs,
        duration=3.0,
        sensor=pinobs.Sensor(1000.0, 1e-4),
        perturb_q=0.05,
        perturb_v=0.5,
        seed=0,
    )
    m = {x.observer: x for x in pinobs.evaluate(res, robot)}
    # measured: 0.041 s vs 1.22 s; RMS after 0.75 s 4.05e-5 vs 3.0e-3; ekf 3.99e-5
    assert m["riccati"].convergence_time < 0.2 * m["steady"].convergence_time
    assert m["riccati"].rms_v_error < 1.5 * m["ekf"].rms_v_error
    late = res.t > 2.0
    err = {
        k: np.sqrt(np.mean((res.trace(k).v[late] - res.v[late]) ** 2))
        for k in ("riccati", "steady")
    }
    assert (
        err["riccati"] < 1.5 * err["steady"]
    )  # same steady state: the schedule ends on the same gains
