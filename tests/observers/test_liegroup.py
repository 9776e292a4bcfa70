"""The Lie-group observer (Maithripala–Berg–Dayawansa) on SO(3) and SE(3).

Coefficients from structure constants against the model layer (an
independent construction from Pinocchio's ABA), the paper's explicit forms
(eqs. 29, 42–43), the parallel transport against an exactly integrated one,
the sampled-data scheme, invariance, convergence, the cut locus, and the
heavy top of §IV-A.

Measured on this machine (numbers quoted in the assertions' comments):
invariance on the truth ≤ 4e-14 rad/s; the heavy top from 0.8 rad and 30 rad/s
error decays at the slow pole −α + √(α² − β) = −0.513 1/s (measured 0.514).
The curvature gain: the printed ``+1`` loses a transversely spun top, the
default ``−1`` does not.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pinocchio as pin
import pytest
from scipy.linalg import expm

import pinobs
from pinobs.model import Robot, lie_rk4
from pinobs.observers.liegroup import (
    LieAlgebraGeometry,
    LieGroupObserver,
    correction_weights,
    so3_basis,
    structure_constants,
)

H = 1e-3  # [s] sample period of every run here


# ------------------------------------------------------------------ robots
@cache
def heavy_top() -> Robot:
    """The axisymmetric heavy top of §IV-A, parameters chosen here (the paper gives none).

    m = 1 kg, centre of mass l = 0.05 m up the symmetry axis e₃, principal
    moments about the centre of mass I₁ = I₂ = 0.01, I₃ = 0.02 kg·m², so about
    the pivot I = diag(0.0125, 0.0125, 0.02) kg·m² (the project's ``top`` has
    the same parameters).
    """
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "pivot")
    model.appendBodyToJoint(
        j,
        pin.Inertia(1.0, np.array([0.0, 0.0, 0.05]), np.diag([0.01, 0.01, 0.02])),
        pin.SE3.Identity(),
    )
    return Robot(model, name="heavy_top", source="tests")


@cache
def isotropic_top() -> Robot:
    """A top isotropic about its pivot (l = 0.1 m: I = 0.02·1 kg·m²): a bi-invariant metric."""
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "pivot")
    model.appendBodyToJoint(
        j,
        pin.Inertia(1.0, np.array([0.0, 0.0, 0.1]), np.diag([0.01, 0.01, 0.02])),
        pin.SE3.Identity(),
    )
    return Robot(model, name="isotropic_top", source="tests")


@cache
def generic_body(kind: str) -> Robot:
    """One rigid body with an off-centre mass and products of inertia, on SO(3) or SE(3)."""
    rng = np.random.default_rng(7)
    a = rng.standard_normal((3, 3))
    inertia = pin.Inertia(1.3, np.array([0.12, -0.2, 0.07]), 0.01 * a @ a.T + 0.01 * np.eye(3))
    joint = pin.JointModelSpherical() if kind == "so3" else pin.JointModelFreeFlyer()
    model = pin.Model()
    j = model.addJoint(0, joint, pin.SE3.Identity(), "root")
    model.appendBodyToJoint(j, inertia, pin.SE3.Identity())
    return Robot(model, name=f"generic_{kind}", source="tests")


def _robot(name: str) -> Robot:
    if name == "heavy_top":
        return heavy_top()
    if name.startswith("generic_"):
        return generic_body(name.removeprefix("generic_"))
    return pinobs.load(name)


BODIES = ["top", "rigid_body", "heavy_top", "generic_so3", "generic_se3"]


def _rotation(q: np.ndarray) -> np.ndarray:
    return pin.Quaternion(q[3], q[0], q[1], q[2]).toRotationMatrix()


def _run(robot, observer, q0, v0, q_hat0, v_hat0, *, duration, inputs=None, h=H):
    """Plant (RKMK4) and observer sampled every ``h`` [s], noise-free; times, true and estimated states."""
    n = round(duration / h)
    q, v = q0.copy(), v0.copy()
    tau = np.zeros(robot.nv) if inputs is None else inputs(0.0, q, v)
    observer.reset(0.0, q_hat0, v_hat0, tau)
    out_q, out_v, est_q, est_v = [q], [v], [observer.estimate.q], [observer.estimate.v]
    for k in range(1, n + 1):
        held = tau
        q, v = lie_rk4(
            robot, q, v, h, lambda qq, vv, t=held: (vv, robot.forward_dynamics(qq, vv, t))
        )
        tau = np.zeros(robot.nv) if inputs is None else inputs(k * h, q, v)
        est = observer.update(k * h, q, tau)
        out_q.append(q), out_v.append(v), est_q.append(est.q), est_v.append(est.v)
    return np.arange(n + 1) * h, np.array(out_q), np.array(out_v), np.array(est_q), np.array(est_v)


def _errors(robot, q, v, q_hat, v_hat):
    e_q = np.array([np.linalg.norm(robot.difference(a, b)) for a, b in zip(q, q_hat, strict=True)])
    return e_q, np.linalg.norm(v_hat - v, axis=1)


def _multisine(robot: Robot, seed: int):
    """Torques [N·m] and forces [N] about gravity compensation: a few seeded sines per direction."""
    rng = np.random.default_rng(seed)
    f = rng.uniform(0.2, 1.5, (robot.nv, 3))
    ph = rng.uniform(0, 2 * np.pi, (robot.nv, 3))
    amp = 2.0 * np.diag(robot.mass_matrix(robot.neutral()))

    def inputs(t, q, v):
        return robot.gravity(q) + amp * np.sin(2 * np.pi * f * t + ph).sum(axis=1) / 3.0

    return inputs


# -------------------------------------------------- the local error (§II-C)
@pytest.mark.parametrize("name", ["top", "rigid_body"])
def test_difference_is_the_group_log_of_g_inverse_g_hat(name: str, rng) -> None:
    robot = _robot(name)
    ob = pinobs.make_observer("liegroup", robot)
    for _ in range(20):
        g, g_hat = (
            robot.random_configuration(rng, scale=2.0),
            robot.random_configuration(rng, scale=2.0),
        )
        if name == "top":
            ref = pin.log3(_rotation(g).T @ _rotation(g_hat))
        else:
            ref = pin.log6(pin.XYZQUATToSE3(g).inverse() * pin.XYZQUATToSE3(g_hat)).vector
        # measured: ≤ 3.2e-13 (SO(3)), 1e-14 (SE(3)): the same log, computed differently
        np.testing.assert_allclose(ob.error(g, g_hat), ref, atol=1e-12)


@pytest.mark.parametrize("name", BODIES)
def test_mass_matrix_of_a_single_rigid_body_is_constant(name: str, rng) -> None:
    robot = _robot(name)
    m0 = robot.mass_matrix(robot.neutral())
    for _ in range(10):
        np.testing.assert_allclose(
            robot.mass_matrix(robot.random_configuration(rng, scale=3.0)), m0, atol=1e-14
        )


# -------------------------------------------- coefficients (eqs. 2, 7, 8)
def test_so3_structure_constants_are_the_papers() -> None:
    C = structure_constants(so3_basis())
    expected = np.zeros((3, 3, 3))
    # Maithripala et al. §IV-A: C³₁₂ = 1, C²₁₃ = −1, C¹₂₃ = 1 (and antisymmetry)
    for k, i, j, c in [(2, 0, 1, 1.0), (1, 0, 2, -1.0), (0, 1, 2, 1.0)]:
        expected[k, i, j], expected[k, j, i] = c, -c
    np.testing.assert_array_equal(C, expected)


@pytest.mark.parametrize("name", BODIES)
def test_coefficients_from_structure_constants_agree_with_the_model_layer(name: str, rng) -> None:
    """Bracket, connection (eq. 2) and curvature (eqs. 7–8) against ``Robot`` (ABA-based)."""
    robot = _robot(name)
    geo = pinobs.make_observer("liegroup", robot).geometry
    worst = {"bracket": 0.0, "connection": 0.0, "curvature": 0.0}
    for _ in range(10):
        q = robot.random_configuration(rng, scale=2.0)
        x, y, z = rng.standard_normal((3, robot.nv))
        pairs = {
            "bracket": (geo.bracket(x, y), robot.bracket(x, y)),
            "connection": (geo.connection(x, y), robot.connection(q, x, y)),
            "curvature": (geo.curvature(x, y, z), robot.curvature(q, x, y, z)),
        }
        for key, (ours, model) in pairs.items():
            worst[key] = max(
                worst[key], np.max(np.abs(ours - model)) / (1.0 + np.max(np.abs(model)))
            )
    # measured: bracket ≤ 2e-16, connection ≤ 1.3e-14, curvature ≤ 5.7e-14 (relative, generic SE(3))
    assert max(worst.values()) < 1e-12, worst


@pytest.mark.parametrize("name", ["generic_so3", "generic_se3"])
def test_printed_eq8_with_its_extra_bracket_term_disagrees_with_the_curvature(
    name: str, rng
) -> None:
    """The typo documented in the module: eq. (8)'s ``−ω^k_ij C^i_ab ζ^a η^b Ω^j`` counts ∇_[ζ,η] twice."""
    robot = _robot(name)
    geo = pinobs.make_observer("liegroup", robot).geometry
    x, y, z = rng.standard_normal((3, robot.nv))
    q = robot.neutral()
    extra = np.einsum("kij,iab,a,b,j->k", geo.omega, geo.C, x, y, z)
    printed = geo.curvature(x, y, z) - extra
    ref = robot.curvature(q, x, y, z)
    assert np.linalg.norm(printed - ref) > 0.1 * np.linalg.norm(ref)
    np.testing.assert_allclose(geo.curvature(x, y, z), ref, atol=1e-12)


def test_isotropic_top_has_sectional_curvature_one_over_four_c(rng) -> None:
    """A top isotropic about its pivot, c = 0.02 kg·m²: K = 1/(4c) = 12.5 (MATH §3)."""
    geo = pinobs.make_observer("liegroup", isotropic_top()).geometry
    np.testing.assert_allclose(geo.inertia, 0.02 * np.eye(3), atol=1e-15)
    for _ in range(5):
        x, y = rng.standard_normal((2, 3))
        area2 = (x @ geo.inertia @ x) * (y @ geo.inertia @ y) - (x @ geo.inertia @ y) ** 2
        k = geo.curvature(x, y, y) @ geo.inertia @ x / area2
        assert k == pytest.approx(12.5, rel=1e-12)


def test_connection_is_the_papers_explicit_so3_form(rng) -> None:
    """eq. (29)'s acceleration terms: −ω(ζ̃ − 2αζ_e, ζ̃) = I⁻¹(Iζ̃×ζ̃ − α(Iζ̃×ζ_e + Iζ_e×ζ̃)) + αζ_e×ζ̃."""
    geo = pinobs.make_observer("liegroup", generic_body("so3")).geometry
    inertia, alpha = geo.inertia, 10.0
    for _ in range(5):
        zt, ze = rng.standard_normal((2, 3))
        paper = np.linalg.solve(
            inertia,
            np.cross(inertia @ zt, zt)
            - alpha * (np.cross(inertia @ zt, ze) + np.cross(inertia @ ze, zt)),
        ) + alpha * np.cross(ze, zt)
        np.testing.assert_allclose(-geo.connection(zt - 2 * alpha * ze, zt), paper, atol=1e-12)


def test_connection_is_the_papers_explicit_se3_form(rng) -> None:
    """eqs. (42)–(43) for I = diag(M·1, I_b) (``rigid_body``: centre of mass at the origin).

    Pinocchio orders ``(v, Ω)``; the paper ``(Ω, v)``.
    """
    geo = pinobs.make_observer("liegroup", pinobs.load("rigid_body")).geometry
    ib, alpha = geo.inertia[3:, 3:], 10.0
    for _ in range(5):
        zt, ze = rng.standard_normal((2, 6))
        (vt, wt), we = (zt[:3], zt[3:]), ze[3:]
        ang = np.linalg.solve(
            ib, np.cross(ib @ wt, wt) - alpha * (np.cross(ib @ wt, we) + np.cross(ib @ we, wt))
        ) + alpha * np.cross(we, wt)  # eq. (42)
        lin = np.cross(vt, wt) - 2 * alpha * np.cross(vt, we)  # eq. (43)
        np.testing.assert_allclose(
            -geo.connection(zt - 2 * alpha * ze, zt), np.r_[lin, ang], atol=1e-12
        )


@pytest.mark.parametrize("name", ["generic_so3", "generic_se3"])
def test_transport_term_is_first_order_accurate_and_the_printed_slot_order_is_not(
    name: str, rng
) -> None:
    """eq. (19) against the exact transport along ``g·exp(tζ_e)``: ``ẏ = −ω(ζ_e, y)``, ``y(1) = exp(−A)S``."""
    geo = pinobs.make_observer("liegroup", _robot(name)).geometry
    s = rng.standard_normal(geo.dim)
    direction = rng.standard_normal(geo.dim)
    errs, printed = [], []
    for eps in (1e-2, 5e-3, 2.5e-3):
        ze = eps * direction
        exact = expm(-np.einsum("kij,i->kj", geo.omega, ze)) @ s
        errs.append(np.linalg.norm(geo.transport(s, ze) - exact))
        printed.append(np.linalg.norm(s - geo.connection(s, ze) - exact))  # ω^k_ij S^i ζ_e^j
    # halving ζ_e divides the error by 4 (order 2), the printed order's by 2 (order 1)
    assert errs[0] / errs[1] == pytest.approx(4.0, rel=0.1)
    assert errs[1] / errs[2] == pytest.approx(4.0, rel=0.1)
    assert printed[1] / printed[2] == pytest.approx(2.0, rel=0.1)


# ------------------------------------------------ the observer, continuous
@pytest.mark.parametrize("name", ["heavy_top", "generic_se3"])
def test_vector_field_on_the_truth_is_the_model(name: str, rng) -> None:
    robot = _robot(name)
    ob = pinobs.make_observer("liegroup", robot)
    q, v, tau = (
        robot.random_configuration(rng),
        rng.standard_normal(robot.nv),
        rng.standard_normal(robot.nv),
    )
    u, v_dot = ob.vector_field(q, v, q, tau)
    np.testing.assert_array_equal(u, v)
    np.testing.assert_allclose(v_dot, robot.forward_dynamics(q, v, tau), atol=1e-12)


# ------------------------------------------------- the sampled-data scheme
@pytest.mark.parametrize(
    ("alpha", "beta", "h"), [(10, 10, 1e-3), (10, 500, 1e-3), (300, 1e4, 1e-2), (5, 1e6, 1e-3)]
)
def test_flat_error_map_has_the_sampled_continuous_poles(alpha, beta, h) -> None:
    l1, tau_v = correction_weights(alpha, beta, h)
    step = np.array([[1 - l1, (1 - l1) * h], [-beta * tau_v, 1 - beta * tau_v * h]])
    lam = np.roots([1.0, 2.0 * alpha, beta])
    np.testing.assert_allclose(
        np.sort_complex(np.linalg.eigvals(step)), np.sort_complex(np.exp(lam * h)), rtol=1e-9
    )
    assert np.max(np.abs(np.linalg.eigvals(step))) < 1.0


def test_weights_tend_to_the_sample_period_for_small_steps() -> None:
    l1, tau_v = correction_weights(10.0, 10.0, 1e-6)
    assert l1 / 2e-5 == pytest.approx(1.0, rel=1e-4)
    assert tau_v / 1e-6 == pytest.approx(1.0, rel=1e-4)


@pytest.mark.parametrize(
    ("name", "driven"), [("top", False), ("heavy_top", False), ("rigid_body", True)]
)
def test_started_on_the_truth_without_noise_it_stays_on_it(name: str, driven: bool, rng) -> None:
    robot = _robot(name)
    q0 = robot.random_configuration(rng, scale=0.5)
    v0 = np.zeros(robot.nv)
    v0[-3:] = [1.0, -0.5, 30.0]  # fast spin about the symmetry axis
    inputs = _multisine(robot, 1) if driven else None
    ob = pinobs.make_observer("liegroup", robot)
    _, q, v, q_hat, v_hat = _run(robot, ob, q0, v0, q0, v0, duration=1.0, inputs=inputs)
    e_q, e_v = _errors(robot, q, v, q_hat, v_hat)
    # measured: e_v ≤ 3.6e-14 rad/s, e_q ≤ 3.9e-15 rad (RK4 in observer and plant)
    assert e_v.max() < 1e-9 and e_q.max() < 1e-9


def test_stable_for_large_gains_at_a_slow_rate(rng) -> None:
    """αh = 3, βh² = 1 (100 Hz): the correction keeps the sampled error map contracting."""
    robot = heavy_top()
    q0 = robot.integrate(robot.neutral(), np.array([0.3, 0.0, 0.0]))
    v0 = np.array([1.0, -0.5, 30.0])
    ob = LieGroupObserver(robot, alpha=300.0, beta=1e4, noise_std=0.0)  # noise-free samples
    ob.reset(0.0, robot.integrate(q0, np.array([0.3, -0.2, 0.1])), np.zeros(3))
    q, v, h = q0, v0, 1e-2
    for k in range(1, 201):
        for _ in range(10):
            q, v = lie_rk4(
                robot,
                q,
                v,
                h / 10,
                lambda qq, vv: (vv, robot.forward_dynamics(qq, vv, np.zeros(3))),
            )
        est = ob.update(k * h, q, np.zeros(3))
    # measured: 2.4e-5 rad/s after 2 s (one RK4 prediction over 10 ms is the limit)
    assert np.linalg.norm(est.v - v) < 1e-3


def test_dropped_samples_correct_over_the_time_since_the_last_sample(rng) -> None:
    """Every other sample missing at 1 kHz ≈ sampling at 500 Hz (the two differ by the RK4 split)."""
    robot = heavy_top()
    q = robot.random_configuration(rng, scale=0.5)
    v = np.array([1.0, -0.5, 30.0])
    q_hat0 = robot.integrate(q, np.array([0.05, -0.03, 0.02]))
    dropped, slow = (pinobs.make_observer("liegroup", robot) for _ in range(2))
    for ob in (dropped, slow):
        ob.reset(0.0, q_hat0, np.zeros(3))
    rhs = lambda qq, vv: (vv, robot.forward_dynamics(qq, vv, np.zeros(3)))  # noqa: E731
    for k in range(1, 1001):
        q, v = lie_rk4(robot, q, v, H, rhs)
        a = dropped.update(k * H, q if k % 2 == 0 else None)
        if k % 2 == 0:
            b = slow.update(k * H, q)
            # measured: ≤ 1.1e-9 rad/s over 1 s (two RK4 steps against one)
            np.testing.assert_allclose(a.v, b.v, atol=1e-7)


# -------------------------------------------------------- the paper's example
def test_heavy_top_converges_from_large_attitude_error_and_fast_spin() -> None:
    """§IV-A with α = β = 10: 0.8 rad attitude error, estimate at rest while the top spins at 30 rad/s."""
    robot = heavy_top()
    q0 = robot.integrate(robot.neutral(), np.array([0.3, 0.0, 0.0]))
    v0 = np.array([1.0, -0.5, 30.0])
    axis = np.array([1.0, -1.0, 0.5]) / 1.5
    ob = pinobs.make_observer("liegroup", robot, alpha=10.0, beta=10.0)
    _, q, v, q_hat, v_hat = _run(
        robot, ob, q0, v0, robot.integrate(q0, 0.8 * axis), np.zeros(3), duration=16.0
    )
    e_q, e_v = _errors(robot, q, v, q_hat, v_hat)
    assert e_q[0] == pytest.approx(0.8) and e_v[0] > 30.0
    # the slow pole of s² + 2αs + β: −α + √(α² − β) = −0.513 1/s
    rate = np.log(e_v[int(8 / H)] / e_v[-1]) / 8.0
    assert rate == pytest.approx(10 - np.sqrt(90), rel=0.05)  # measured 0.514
    assert e_v[-1] < 1e-2 and e_q[-1] < 1e-3  # measured 8.6e-3 rad/s, 4.3e-4 rad


@pytest.mark.parametrize(("c", "lost"), [(1.0, True), (-1.0, False)])
def test_printed_curvature_sign_loses_a_transversely_spun_top_and_the_default_does_not(
    c: float, lost: bool
) -> None:
    """Spin 30 rad/s about e₁ (sectional curvature K(e₁, e₂) = −16 /(kg·m²)), error 0.05 rad, 0.6 rad/s.

    The linearised error obeys ``D_t ε = −βJ + (1 + c) R(ζ, J)ζ`` (module
    docstring): with the printed ``c = +1`` the negative curvature beats β.
    """
    robot = heavy_top()
    geo = pinobs.make_observer("liegroup", robot).geometry
    e1, e2 = np.eye(3)[0], np.eye(3)[1]
    k12 = geo.curvature(e1, e2, e2) @ geo.inertia @ e1 / (geo.inertia[0, 0] * geo.inertia[1, 1])
    assert k12 == pytest.approx(-16.0)
    q0 = robot.integrate(robot.neutral(), np.array([0.3, 0.0, 0.0]))
    v0 = np.array([30.0, 0.5, 0.2])
    q_hat0 = robot.integrate(q0, 0.05 * np.array([1.0, -1.0, 0.5]) / 1.5)
    ob = pinobs.make_observer("liegroup", robot, curvature_gain=c)
    _, q, v, q_hat, v_hat = _run(
        robot, ob, q0, v0, q_hat0, v0 + np.array([0.5, 0.3, -0.2]), duration=4.0
    )
    e_q, e_v = _errors(robot, q, v, q_hat, v_hat)
    # measured: c = +1 ends at 34 rad/s and 0.99 rad; c = −1 at 0.116 rad/s and 4.9e-3 rad
    if lost:
        assert e_v[-1] > 10.0 and e_q[-1] > 0.5
    else:
        assert e_v[-1] < 0.2 and e_q[-1] < 1e-2


def test_free_body_on_se3_converges_under_forces_and_torques(rng) -> None:
    robot = pinobs.load("rigid_body")
    q0 = robot.random_configuration(rng, scale=0.5)
    v0 = np.array([0.2, -0.1, 0.3, 1.0, -0.5, 10.0])
    q_hat0 = robot.integrate(q0, np.array([0.3, -0.2, 0.1, 0.55, 0.45, -0.4]))  # 0.81 rad, 0.37 m
    ob = pinobs.make_observer("liegroup", robot)
    _, q, v, q_hat, v_hat = _run(
        robot, ob, q0, v0, q_hat0, np.zeros(6), duration=12.0, inputs=_multisine(robot, 2)
    )
    e_q, e_v = _errors(robot, q, v, q_hat, v_hat)
    assert e_v[0] > 10.0
    assert e_v[-1] < 3e-2 and e_q[-1] < 2e-3  # measured 2.2e-2 and 1.1e-3 (norms of mixed units)


def test_noisy_updates_keep_unit_quaternions(rng) -> None:
    """2·10⁴ updates with σ = 1e-3 rad noise: the estimate's quaternion stays unit-norm."""
    robot = pinobs.load("top")
    ob = pinobs.make_observer("liegroup", robot, noise_std=1e-3)
    q = robot.random_configuration(rng)
    ob.reset(0.0, q, np.array([0.0, 0.0, 20.0]))
    worst = 0.0
    for k in range(1, 20001):
        est = ob.update(k * H, robot.integrate(q, 1e-3 * rng.standard_normal(3)))
        worst = max(worst, abs(np.linalg.norm(est.q) - 1.0))
    assert worst < 1e-14  # measured: ≤ 2.3e-16 (one ulp)


# ------------------------------------------------------------- cut locus
@pytest.mark.parametrize("name", ["top", "rigid_body"])
def test_error_at_the_cut_locus_is_finite_deterministic_and_of_norm_pi(name: str) -> None:
    robot = _robot(name)
    ob = pinobs.make_observer("liegroup", robot)
    g = robot.neutral()
    axis = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
    for psi in (np.pi - 1e-9, np.pi, np.pi + 1e-9):
        xi = np.zeros(robot.nv)
        xi[-3:] = psi * axis
        g_hat = robot.integrate(g, xi)
        z1, z2 = ob.error(g, g_hat), ob.error(g.copy(), g_hat.copy())
        assert np.all(np.isfinite(z1))
        np.testing.assert_array_equal(z1, z2)
        assert np.linalg.norm(z1[-3:]) <= np.pi + 1e-12
        # exp(ζ_e) = g⁻¹ g̃ whichever minimal log was returned
        np.testing.assert_allclose(
            np.abs(robot.integrate(g, z1)[-4:] @ g_hat[-4:]), 1.0, atol=1e-12
        )


def test_observer_started_on_the_cut_locus_leaves_it_deterministically() -> None:
    """Estimate exactly π away (w = 0 relative quaternion), body at rest: finite and convergent."""
    robot = pinobs.load("top")
    g = robot.neutral()
    g_hat = np.array([1.0, 2.0, 3.0, 0.0]) / np.sqrt(14.0)  # rotation by π about (1, 2, 3)
    runs = []
    for _ in range(2):
        ob = pinobs.make_observer("liegroup", robot)
        _, q, v, q_hat, v_hat = _run(robot, ob, g, np.zeros(3), g_hat, np.zeros(3), duration=6.0)
        runs.append((q_hat, v_hat))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    e_q, _ = _errors(robot, q, v, q_hat, v_hat)
    assert e_q[0] == pytest.approx(np.pi)
    assert np.all(np.diff(e_q[:50]) < 0)  # leaves the cut locus at once
    assert e_q[-1] < 1e-2  # measured 3.8e-3 rad (0.05 rad after 1 s)


# --------------------------------------------------------- errors, options
@pytest.mark.parametrize("name", ["cartpole", "pendulum", "planar_3r"])
def test_robot_that_is_not_a_single_rigid_body_on_a_group_is_refused(name: str) -> None:
    with pytest.raises(pinobs.UnsupportedRobotError, match="riemannian"):
        pinobs.make_observer("liegroup", pinobs.load(name))


def test_two_bodies_on_a_spherical_root_are_refused() -> None:
    model = generic_body("so3").model.copy()
    j = model.addJoint(
        1, pin.JointModelRX(), pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3])), "hinge"
    )
    model.appendBodyToJoint(
        j, pin.Inertia(0.5, np.array([0.0, 0.0, 0.1]), 0.01 * np.eye(3)), pin.SE3.Identity()
    )
    robot = Robot(model, name="top_and_hinge", source="tests")
    with pytest.raises(pinobs.PinobsError, match="riemannian"):
        pinobs.make_observer("liegroup", robot)


@pytest.mark.parametrize(
    ("option", "value"),
    [("alpha", 0.0), ("beta", -1.0), ("alpha", float("nan")), ("curvature_gain", float("inf"))],
)
def test_gains_out_of_range_raise_naming_the_option(option: str, value: float) -> None:
    with pytest.raises(pinobs.GainError, match=option):
        pinobs.make_observer("liegroup", pinobs.load("top"), **{option: value})


def test_options_report_the_gains() -> None:
    ob = pinobs.make_observer("liegroup", pinobs.load("top"), alpha=3.0, beta=7.0)
    assert ob.options["alpha"] == 3.0 and ob.options["beta"] == 7.0
    assert ob.options["curvature_gain"] == -1.0
    assert isinstance(ob.geometry, LieAlgebraGeometry) and ob.geometry.group == "so3"


# ------------------------------------------- agreement with ``riemannian``
needs_riemannian = pytest.mark.skipif(
    "riemannian" not in pinobs.observer_names(), reason="the riemannian observer is not registered"
)


def _pair(robot: Robot, **gains):
    """``liegroup`` and ``riemannian`` with the same gains (curvature recomputed every sample)."""
    return (
        pinobs.make_observer("liegroup", robot, **gains),
        pinobs.make_observer("riemannian", robot, curvature_every=1, **gains),
    )


@needs_riemannian
def test_vector_field_equals_the_riemannian_observers_on_the_bi_invariant_top(rng) -> None:
    """Isotropic inertia about the pivot: the group log is the Riemannian log, the two are one observer."""
    robot = isotropic_top()
    lg, rm = _pair(robot, alpha=10.0, beta=10.0)
    for _ in range(10):
        q = robot.random_configuration(rng)
        q_meas = robot.integrate(q, 0.1 * rng.standard_normal(3))
        v, tau = 5.0 * rng.standard_normal(3), rng.standard_normal(3)
        for ours, theirs in zip(
            lg.vector_field(q, v, q_meas, tau), rm.vector_field(q, v, q_meas, tau), strict=True
        ):
            np.testing.assert_allclose(ours, theirs, atol=1e-11)  # measured ≤ 4e-13


@needs_riemannian
@pytest.mark.parametrize("name", ["heavy_top", "rigid_body"])
def test_vector_field_agrees_with_the_riemannian_observers_to_second_order(name: str, rng) -> None:
    """Non-bi-invariant metric: the group log and the Riemannian log differ by O(|ζ|²), so do the fields."""
    robot = _robot(name)
    lg, rm = _pair(robot, alpha=10.0, beta=10.0)
    q = robot.random_configuration(rng)
    v, tau = 5.0 * rng.standard_normal(robot.nv), rng.standard_normal(robot.nv)
    direction = rng.standard_normal(robot.nv)
    gaps = []
    for eps in (1e-2, 1e-3):
        q_meas = robot.integrate(q, eps * direction)
        gaps.append(
            max(
                np.max(np.abs(a - b))
                for a, b in zip(
                    lg.vector_field(q, v, q_meas, tau),
                    rm.vector_field(q, v, q_meas, tau),
                    strict=True,
                )
            )
        )
    assert gaps[0] / gaps[1] == pytest.approx(100.0, rel=0.2)  # second order; measured 100.0


@needs_riemannian
@pytest.mark.parametrize("name", ["top", "rigid_body"])
def test_sampled_estimates_agree_with_riemannian_to_integration_accuracy(name: str) -> None:
    """Same gains, same data: the estimates differ by O(h) (the two schemes weigh the force and
    curvature corrections by ``τ_v`` and ``h``); halving h halves the gap.

    Measured (1e-3 error, 0.5 s, spin 20 rad/s): top 1.05e-4 → 5.2e-5 rad/s,
    rigid_body 9.8e-5 → 4.8e-5 (ratio 2.01, 2.02).
    """
    robot = _robot(name)
    rng = np.random.default_rng(1)
    q0 = robot.random_configuration(rng, scale=0.5)
    v0 = np.zeros(robot.nv)
    v0[-3:] = [1.0, -0.5, 20.0]
    q_hat0 = robot.integrate(q0, 1e-3 * rng.standard_normal(robot.nv) / np.sqrt(robot.nv))
    gaps = []
    for h in (1e-3, 5e-4):
        runs = [
            _run(robot, ob, q0, v0, q_hat0, v0, duration=0.5, inputs=_multisine(robot, 1), h=h)
            for ob in _pair(robot, alpha=10.0, beta=10.0)
        ]
        gaps.append(np.max(np.abs(runs[0][4] - runs[1][4])))
    assert gaps[1] < 1e-3 * np.max(np.abs(v0))
    assert gaps[0] / gaps[1] == pytest.approx(2.0, rel=0.2)
