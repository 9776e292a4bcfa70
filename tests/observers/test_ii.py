"""The I&I observer of Sarras et al.: Assumption 1 check, β = kQ, invariance, the decay bound, Prop. 4."""

from __future__ import annotations

import itertools
import math
from functools import cache

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.errors import GainError, PinobsError, UnsupportedRobotError
from pinobs.model import Robot
from pinobs.model.paper_systems import sarras_eq21
from pinobs.observers import make_observer
from pinobs.observers.ii import (
    CholeskyFactor,
    CustomFactor,
    IIObserver,
    check_assumption1,
    momentum_residual,
    potential,
    structure_functions,
)
from pinobs.simulation import Sensor, simulate

GAIN = 10.0  # [1/s]
INVARIANCE_TOL = 1e-9  # [rad/s] measured 1.0e-10 on the cart-poles (PD, 1 kHz, 1 s)


# ------------------------------------------------------------------ models
@cache
def _load(name: str) -> Robot:
    return pinobs.load(name)


def cartpole_variant(m_cart: float, m_pole: float, length: float) -> Robot:
    """The project's cart-pole with other masses [kg] and pole length [m] (uniform rod)."""
    model = _load("cartpole").model.copy()
    model.inertias[1] = pin.Inertia(m_cart, np.zeros(3), np.diag([0.01, 0.02, 0.02]) * m_cart)
    i_rod = m_pole * length**2 / 12.0
    model.inertias[2] = pin.Inertia(
        m_pole, np.array([0.0, 0.0, 0.5 * length]), np.diag([i_rod, i_rod, 1e-4])
    )
    return Robot(model, name=f"cartpole_{m_cart}_{m_pole}_{length}", source="test")


CARTPOLES = {
    "project": lambda: _load("cartpole"),
    "heavy_short": lambda: cartpole_variant(3.0, 0.8, 0.5),
    "light_long": lambda: cartpole_variant(0.5, 0.3, 2.0),
}


def sarras_eq23(q: np.ndarray) -> np.ndarray:
    """Sarras et al. eq. (23): a factor of eq. (21) whose columns span so(3)."""
    s1, c1, q2 = math.sin(q[0]), math.cos(q[0]), q[1]
    a = 1.0 + q2 * q2
    r = math.sqrt(a)
    return np.array([[s1 * q2, c1 * q2, 1.0], [a * c1, -a * s1, 0.0], [r * s1, r * c1, 0.0]])


def _momentum_error(ob: IIObserver, result, label: str = "ii") -> np.ndarray:
    """``z_k = P̂_k − P_k = T(q_k)⁻¹ (v̂_k − v_k)`` at every sample."""
    tr = result.trace(label)
    return np.array(
        [ob.momentum(q, vh - v) for q, vh, v in zip(result.q, tr.v, result.v, strict=True)]
    )


# -------------------------------------------------------------- Assumption 1
def test_cartpole_assumption1_holds_only_with_theta_eliminated_first() -> None:
    robot = _load("cartpole")
    report = check_assumption1(robot, samples=12, seed=1)
    assert report.holds
    assert report.best.ordering == (1, 0)  # (pole_theta, cart_x)
    assert report.best.residual < 1e-12  # measured 1e-16
    assert report.best.commutator < 1e-12  # columns commute: β = kQ applies
    plain = next(r for r in report.results if r.ordering == (0, 1))
    assert not plain.holds and plain.residual > 0.5  # measured 1.03
    # T is upper-triangular in model order with T₁₁ = 1/√(m_c + m_p) (MATH §5)
    t = CholeskyFactor(robot, (1, 0)).frame(np.array([0.4, 1.1]))
    assert t[1, 0] == 0.0
    assert t[0, 0] == pytest.approx(1.0 / math.sqrt(1.2), rel=1e-12)


@pytest.mark.parametrize("variant", sorted(CARTPOLES))
def test_cartpole_variants_satisfy_assumption1(variant: str) -> None:
    report = check_assumption1(CARTPOLES[variant](), samples=6, seed=2)
    assert report.holds and report.best.ordering == (1, 0)


def test_planar_3r_fails_assumption1_for_every_cholesky_ordering() -> None:
    report = check_assumption1(_load("planar_3r"), samples=12, seed=0)
    assert report.search == "all 6 orderings"
    assert len(report.results) == 6
    assert not report.holds
    assert (
        min(r.residual for r in report.results) > 0.5
    )  # measured 1.12 (best: joint1, joint3, joint2)


def test_panda_fails_assumption1_and_the_check_takes_under_two_cpu_seconds() -> None:
    import time

    start = time.process_time()  # CPU time: other processes sharing the cores do not count
    report = check_assumption1(_load("panda"), samples=12, seed=0)
    elapsed = time.process_time() - start
    assert elapsed < 2.0  # measured 0.1-0.4 s (34 orderings, 12 samples)
    assert "heuristic subset" in report.search
    assert not report.holds and report.best.residual > 0.5  # measured 1.00


def test_report_format_states_verdict_ordering_residual_and_location() -> None:
    text = check_assumption1(_load("cartpole"), samples=4).format()
    assert "HOLDS" in text
    assert "Cholesky in order (pole_theta, cart_x)" in text
    assert "worst at q = [" in text
    assert "(0,1)" in text and "(1,0)" in text
    failing = check_assumption1(_load("planar_3r"), samples=4).format()
    assert "FAILS" in failing and "relative residual" in failing


def test_momentum_residual_is_the_defect_of_the_momentum_dynamics(
    rng: np.random.Generator,
) -> None:
    """Ṗ = Tᵀ(τ − ∂V/∂q) + D_T(q, P) (Sarras et al. eq. 9) on the panda, where D_T ≠ 0."""
    robot = _load("panda").copy()
    factor = CholeskyFactor(robot, tuple(range(robot.nv)))
    q = robot.random_configuration(rng)
    v, tau = rng.standard_normal((2, robot.nv))
    a = robot.forward_dynamics(q, v, tau)
    e = 1e-6

    def mom(s: float) -> np.ndarray:
        return np.linalg.solve(factor.frame(q + s * v), v + s * a)

    p_dot = (mom(e) - mom(-e)) / (2 * e)
    t, dts = factor.columns_jet(q)
    p = np.linalg.solve(t, v)
    predicted = t.T @ (tau - robot.gravity(q)) + momentum_residual(
        structure_functions(t, dts)[0], p
    )
    assert np.allclose(p_dot, predicted, atol=1e-7 * np.abs(p_dot).max())
    assert np.abs(momentum_residual(structure_functions(t, dts)[0], p)).max() > 0.1


# ------------------------------------------------- Proposition 4 (n = 3 example)
def test_paper_eq23_factor_satisfies_assumption1_on_a_curved_metric(
    rng: np.random.Generator,
) -> None:
    """Sarras et al. Prop. 4: D_T ≡ 0 for eq. (23), yet eq. (21) is not Euclidean."""
    m = sarras_eq21()
    factor = CustomFactor(sarras_eq23, n=3, label="Sarras et al. eq. (23)")
    for _ in range(3):
        q = rng.uniform(-2, 2, 3)
        t = sarras_eq23(q)
        assert np.allclose(t @ t.T, np.linalg.inv(m.mass_matrix(q)), atol=1e-12)
    report = check_assumption1(m, factor=factor, samples=12, seed=0)
    assert report.holds and report.best.residual < 1e-8  # measured 2e-10 (difference derivatives)
    assert report.best.commutator > 0.5  # the columns do not commute: (24)
    # (24): {P1, P2} = −P3, {P2, P3} = −P1, {P3, P1} = −P2, i.e. c_12^3 = c_23^1 = c_31^2 = 1
    q = rng.uniform(-2, 2, 3)
    c, _ = structure_functions(*factor.columns_jet(q))
    assert c[0, 1, 2] == pytest.approx(1.0, abs=1e-8)
    assert c[1, 2, 0] == pytest.approx(1.0, abs=1e-8)
    assert c[2, 0, 1] == pytest.approx(1.0, abs=1e-8)
    # no Cholesky ordering of eq. (21) satisfies Assumption 1 (measured residual 0.80)
    assert not check_assumption1(m, samples=6).holds


def test_paper_eq21_metric_has_nonzero_riemann_symbols(rng: np.random.Generator) -> None:
    """R_1212, R_1313, R_2323 ≠ 0 everywhere, R_1223 ≠ 0 for q₂ ≠ 0 (R_ijkl = ⟨e_i, R(e_k, e_l) e_j⟩).

    The paper lists R_1323 among the nonzero symbols; it vanishes identically:
    (q₁, q₂, q₃) → (−q₁, q₂, −q₃) is an isometry of eq. (21) that flips its
    sign.  R_1313 is the nonzero one (a typo in the paper).
    """
    m = sarras_eq21()
    e = np.eye(3)
    for _ in range(4):
        q = rng.uniform(-2, 2, 3)
        mq = m.mass_matrix(q)

        def r(i: int, j: int, k: int, ll: int, q: np.ndarray = q, mq: np.ndarray = mq) -> float:
            return float(e[i] @ mq @ m.curvature(q, e[k], e[ll], e[j]))

        assert abs(r(0, 1, 0, 1)) > 1e-3
        assert abs(r(0, 2, 0, 2)) > 1e-3
        assert abs(r(1, 2, 1, 2)) > 1e-3
        assert abs(r(0, 1, 1, 2)) > 1e-4 * abs(q[1])
        assert abs(r(0, 2, 1, 2)) < 1e-8
        assert abs(r(0, 1, 0, 2)) < 1e-8


# ------------------------------------------------------------- β = k Q
def test_potential_q_is_path_independent_and_its_jacobian_is_t_inverse(
    rng: np.random.Generator,
) -> None:
    robot = _load("cartpole").copy()
    factor = CholeskyFactor(robot, (1, 0))
    q_ref = np.array([0.2, -0.3])
    q = np.array([-1.4, 2.9])
    straight = potential(factor, q, q_ref)
    corner = np.array([q_ref[0], q[1]])
    legs = potential(factor, corner, q_ref) + potential(factor, q, corner)
    corner2 = np.array([3.0, -2.0])
    detour = potential(factor, corner2, q_ref) + potential(factor, q, corner2)
    assert np.allclose(straight, legs, atol=1e-12)  # measured 2e-15
    assert np.allclose(straight, detour, atol=1e-12)
    e = 1e-6
    jac = np.column_stack(
        [
            (potential(factor, q + e * d, q_ref) - potential(factor, q - e * d, q_ref)) / (2 * e)
            for d in np.eye(2)
        ]
    )
    assert np.allclose(jac, factor.inverse(q), atol=1e-8)


def test_potential_is_path_dependent_when_the_columns_do_not_commute() -> None:
    """Contrast: on planar_3r the loop integral of T⁻¹ dq does not vanish (no Q exists)."""
    factor = CholeskyFactor(_load("planar_3r").copy(), (0, 1, 2))
    a, b, c = np.zeros(3), np.array([0.0, 1.5, 0.0]), np.array([0.0, 1.5, 1.5])
    loop = potential(factor, b, a) + potential(factor, c, b) + potential(factor, a, c)
    assert np.abs(loop).max() > 1e-2


# ----------------------------------------------------------------- observer
def test_vector_field_leaves_the_manifold_invariant_and_contracts_off_it(
    rng: np.random.Generator,
) -> None:
    """ż = 𝒫T P − η̇ − Ṗ equals −kz (0 on the manifold), with Ṗ from the true dynamics."""
    robot = _load("cartpole").copy()
    ob = IIObserver(robot, gain=GAIN)
    q, v, tau = rng.standard_normal((3, 2))
    state = ob.initial_state(q, v)
    beta, pt = ob.beta_and_jacobian(q, state)
    a = robot.forward_dynamics(q, v, tau)
    e = 1e-6
    p_dot = (ob.momentum(q + e * v, v + e * a) - ob.momentum(q - e * v, v - e * a)) / (2 * e)
    p = ob.momentum(q, v)
    for z in (np.zeros(2), rng.standard_normal(2)):
        eta = beta - p - z
        eta_dot = ob.vector_field(q, eta, tau, beta=beta, pt=pt)
        z_dot = pt @ p - eta_dot - p_dot  # β̇ = 𝒫 q̇ = 𝒫 T P
        assert np.allclose(z_dot, -GAIN * z, atol=1e-8)


def test_started_on_the_truth_the_estimate_stays_on_it() -> None:
    robot = _load("cartpole")
    ob = make_observer("ii", robot, gain=GAIN)
    result = simulate(robot, {"ii": ob}, duration=1.0, inputs="pd", seed=1)
    err = np.abs(result.trace("ii").v - result.v).max()
    assert err < INVARIANCE_TOL


def test_started_on_the_truth_stays_on_it_through_dropouts() -> None:
    robot = _load("cartpole")
    ob = make_observer("ii", robot, gain=GAIN)
    sensor = Sensor(rate=1000.0, dropout=0.3)
    result = simulate(robot, {"ii": ob}, duration=0.5, inputs="pd", seed=4, sensor=sensor)
    assert np.abs(result.trace("ii").v - result.v).max() < INVARIANCE_TOL
    assert np.abs(result.trace("ii").q - result.q).max() < INVARIANCE_TOL


@pytest.mark.parametrize("variant", sorted(CARTPOLES))
def test_momentum_error_obeys_the_exponential_bound_at_every_sample(variant: str) -> None:
    """|P̂ − P|² ≤ e^{−εt} |P̂(0) − P(0)|² with ε = 2k (Prop. 5, 𝒫T = kI), checked at every sample.

    The continuous-time bound is an equality here, so the sampled run may
    exceed it only by its discretisation error: a relative 1e-6 (measured
    ≤ 6e-10 while |z| > 1e-4 |z₀|) plus the invariance floor 1e-9 (measured
    max(|z| − bound) = 5.3e-10, invariance 1.0e-10).
    """
    robot = CARTPOLES[variant]()
    ob = make_observer("ii", robot, gain=GAIN)
    assert ob.options["assumption2_epsilon"] == 2 * GAIN
    result = simulate(robot, {"ii": ob}, duration=1.0, inputs="pd", seed=1, perturb_v=1.0)
    # the NIS's start-up term (v0_std, decaying at ε) keeps the transient from being gated
    assert ob.consistency().gated == 0
    z = np.linalg.norm(_momentum_error(ob, result), axis=1)
    eps = ob.options["assumption2_epsilon"]
    bound = np.exp(-0.5 * eps * result.t) * z[0]
    assert np.all(z <= bound * (1.0 + 1e-6) + INVARIANCE_TOL)
    window = z > 1e-4 * z[0]
    rate = -np.log(z[window][1:] / z[0]) / result.t[window][1:]
    assert np.allclose(rate, GAIN, rtol=1e-5)  # measured |rate − k| / k ≤ 7e-8


def test_assumption1_failure_raises_with_the_residual_in_the_message() -> None:
    with pytest.raises(UnsupportedRobotError, match=r"Assumption 1 .* fails .* relative residual"):
        make_observer("ii", _load("panda"))
    with pytest.raises(PinobsError, match=r"unguaranteed=True"):
        make_observer("ii", _load("planar_3r"))
    with pytest.raises(PinobsError, match=r"fails on 'ur5'"):
        make_observer("ii", _load("ur5"))


def test_unguaranteed_runs_on_panda_labelled_and_stays_on_the_truth() -> None:
    robot = _load("panda")
    ob = make_observer("ii", robot, gain=GAIN, unguaranteed=True)
    assert str(ob.options["label"]).startswith("UNGUARANTEED (Assumption 1 fails")
    assert ob.options["guaranteed"] is False
    assert "unguaranteed" in repr(ob)
    result = simulate(robot, {"ii": ob}, duration=0.03, seed=1)
    # certainty-equivalent D_T(q, P̂) keeps the manifold invariant (measured 5e-9 rad/s)
    assert np.abs(result.trace("ii").v - result.v).max() < 1e-7


def test_lie_group_joints_are_rejected_with_a_pointer_to_the_right_observer() -> None:
    with pytest.raises(UnsupportedRobotError, match="liegroup"):
        make_observer("ii", _load("top"))
    with pytest.raises(UnsupportedRobotError, match="so3"):
        check_assumption1(_load("top"))


def test_v0_std_must_be_a_positive_number() -> None:
    for bad in (0.0, -1.0, "1"):
        with pytest.raises(GainError, match="v0_std"):
            make_observer("ii", _load("cartpole"), v0_std=bad)


def test_ordering_option_accepts_joint_names_and_rejects_non_permutations() -> None:
    robot = _load("cartpole")
    ob = make_observer("ii", robot, ordering=["pole_theta", "cart_x"])
    assert ob.options["construction"] == "potential"
    with pytest.raises(UnsupportedRobotError, match="Assumption 1"):
        make_observer("ii", robot, ordering=[0, 1])
    with pytest.raises(GainError, match="permutation"):
        make_observer("ii", robot, ordering=[0, 0])
    with pytest.raises(GainError, match="gain"):
        make_observer("ii", robot, gain=-1.0)


def test_custom_factor_must_factor_the_inverse_mass_matrix() -> None:
    m = sarras_eq21()
    wrong = CustomFactor(lambda q: 2.0 * sarras_eq23(q), n=3)
    with pytest.raises(GainError, match="T Tᵀ = M⁻¹"):
        IIObserver(m, factor=wrong)


def test_paper_example_observer_converges_within_the_assumption2_bound() -> None:
    """On eq. (21) with factor (23): homotopy β, ε from sampled Assumption 2, bound at every sample."""
    m = sarras_eq21()
    ob = IIObserver(m, gain=GAIN, factor=CustomFactor(sarras_eq23, n=3))
    assert ob.options["construction"] == "homotopy"
    assert ob.options["label"] == "Assumption 1 holds; Assumption 2 is checked at reset"
    q0, v0 = np.array([0.2, 0.3, -0.1]), np.array([0.3, -0.2, 0.4])
    result = simulate(
        m, {"ii": ob}, duration=0.3, inputs="zero", q0=q0, v0=v0, perturb_v=0.5, seed=3
    )
    assert str(ob.options["label"]).startswith("guaranteed")
    eps = ob.options["assumption2_epsilon"]
    assert eps is not None and eps > 0  # measured 18.5 /s on q0 + [−0.5, 0.5]³ (2k = 20)
    z2 = np.sum(_momentum_error(ob, result) ** 2, axis=1)
    assert np.all(z2 <= np.exp(-eps * result.t) * z2[0] * (1 + 1e-9))
    quiet = IIObserver(m, gain=GAIN, factor=CustomFactor(sarras_eq23, n=3))
    truth = simulate(m, {"ii": quiet}, duration=0.1, inputs="zero", q0=q0, v0=v0, seed=3)
    assert np.abs(truth.trace("ii").v - truth.v).max() < INVARIANCE_TOL  # measured 4e-13


def test_all_cholesky_orderings_are_searched_for_small_n() -> None:
    report = check_assumption1(sarras_eq21(), samples=2)
    assert {r.ordering for r in report.results} == set(itertools.permutations(range(3)))


def test_assumption2_is_checked_at_reset_and_its_failure_is_labelled() -> None:
    """Homotopy β on eq. (21): ε > 0 near the reset configuration, < 0 over a wide box."""
    q0 = np.array([0.2, 0.3, -0.1])
    eps = {}
    for region in (0.5, 2.0):
        ob = IIObserver(
            sarras_eq21(), gain=GAIN, factor=CustomFactor(sarras_eq23, n=3), region=region
        )
        ob.reset(0.0, q0, np.zeros(3))
        eps[region] = ob.options["assumption2_epsilon"]
        label = str(ob.options["label"])
        assert label.startswith("guaranteed" if region == 0.5 else "UNGUARANTEED (Assumption 2")
    assert eps[0.5] > 0 > eps[2.0]  # measured 18.5 and −11.7 /s (2k = 20)


# ------------------------------------------- continuous joints (angle chart)
def test_continuous_cartpole_stays_on_the_truth_as_the_revolute_one_does() -> None:
    robot = _load("cartpole_continuous")
    assert (robot.nq, robot.nv) == (3, 2)
    ob = make_observer("ii", robot, gain=GAIN)
    assert ob.options["construction"] == "potential"
    result = simulate(robot, {"ii": ob}, duration=1.0, inputs="pd", seed=1)
    assert np.abs(result.trace("ii").v - result.v).max() < INVARIANCE_TOL
    assert np.abs(result.trace("ii").q - result.q).max() < INVARIANCE_TOL


def test_continuous_pole_spinning_through_many_turns_runs_as_the_revolute_one() -> None:
    """A free spin at 30 rad/s (4.8 turns in 1 s, 0.03 rad per sample), both cart-poles.

    The unwrapped chart gives the revolute observer's estimates (measured to
    4e-13 rad/s); at this speed both leave the truth by 1.39e-8 rad/s (the
    sampled-data floor grows with the speed; 1e-10 under the PD input).
    """
    runs = {}
    for name in ("cartpole", "cartpole_continuous"):
        robot = _load(name)
        ob = make_observer("ii", robot, gain=GAIN)
        runs[name] = simulate(
            robot,
            {"ii": ob},
            duration=1.0,
            inputs="zero",
            q0=robot.neutral(),
            v0=np.array([0.0, 30.0]),
            seed=2,
        )
    cont, rev = runs["cartpole_continuous"], runs["cartpole"]
    theta = np.unwrap(np.arctan2(cont.q[:, 2], cont.q[:, 1]))
    assert abs(theta[-1] - theta[0]) > 4 * 2 * np.pi  # it did turn
    np.testing.assert_allclose(theta, rev.q[:, 1], rtol=0, atol=1e-11)
    assert np.abs(cont.trace("ii").v - rev.trace("ii").v).max() < 1e-11
    for r in (cont, rev):
        assert np.abs(r.trace("ii").v - r.v).max() < 2e-8


@pytest.mark.parametrize("name", ["cartpole", "cartpole_continuous"])
def test_continuous_and_revolute_cartpoles_decay_at_the_same_rate(name: str) -> None:
    robot = _load(name)
    ob = make_observer("ii", robot, gain=GAIN)
    result = simulate(robot, {"ii": ob}, duration=1.0, inputs="pd", seed=1, perturb_v=1.0)
    z = np.linalg.norm(_momentum_error(ob, result), axis=1)
    bound = np.exp(-GAIN * result.t) * z[0]
    assert np.all(z <= bound * (1.0 + 1e-6) + INVARIANCE_TOL)
    window = z > 1e-4 * z[0]
    rate = -np.log(z[window][1:] / z[0]) / result.t[window][1:]
    assert np.allclose(rate, GAIN, rtol=1e-5)
