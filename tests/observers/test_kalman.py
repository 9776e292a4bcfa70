"""Ibrir's Kalman observer (Theorem 3.1): state-affine form, invariance, §4 example, noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pinobs
from pinobs.errors import GainError
from pinobs.evaluation import evaluate
from pinobs.model import lie_rk4
from pinobs.model.paper_systems import BOWL, bowl_and_cylinder
from pinobs.observers import make_observer
from pinobs.simulation import Sensor, simulate

M_EQ, LAM, J_EQ, K_SPRING, G = (BOWL[n] for n in ("M_eq", "lam", "J_eq", "k", "g"))


def test_state_affine_form_is_ibrir_eqs_16_and_17_on_thebowl_and_cylinder() -> None:
    ob = make_observer("kalman", bowl_and_cylinder())
    rng = np.random.default_rng(0)
    for _ in range(5):
        y, yd, u = rng.normal(0, 1, 2), rng.normal(0, 1, 2), float(rng.normal())
        F, Gv = ob.state_affine(y, yd, np.array([u, 0.0]))
        s, c = math.sin(y[1]), math.cos(y[1])
        d = M_EQ * J_EQ - (LAM * s) ** 2
        F16 = np.zeros((4, 4))
        F16[0, 2] = F16[1, 3] = 1.0
        F16[2, 3] = -J_EQ * LAM * yd[1] * c / d  # Ibrir eq. (16)
        F16[3, 3] = LAM**2 * s * c * yd[1] / d
        G17 = np.array(
            [
                0.0,
                0.0,
                (J_EQ * u - J_EQ * K_SPRING * y[0] + LAM**2 * G * s**2) / d,  # Ibrir eq. (17)
                (-LAM * u * s + LAM * K_SPRING * y[0] * s - M_EQ * LAM * G * s) / d,
            ]
        )
        np.testing.assert_allclose(F, F16, atol=1e-12)
        np.testing.assert_allclose(Gv, G17, atol=1e-12)


def test_state_affine_form_with_the_true_velocity_is_the_forward_dynamics() -> None:
    """F(q, v) x + G(q, τ) = (v, aba(q, v, τ)): eq. (5) is the model, rewritten."""
    robot = pinobs.load("ur5")
    ob = make_observer("kalman", robot)
    rng = np.random.default_rng(1)
    q = robot.random_configuration(rng)
    v, tau = rng.normal(0, 1, robot.nv), rng.normal(0, 5, robot.nv)
    F, Gv = ob.state_affine(q, v, tau)
    xdot = F @ np.concatenate([np.zeros(robot.nv), v]) + Gv
    np.testing.assert_allclose(xdot[: robot.nv], v, atol=1e-14)
    np.testing.assert_allclose(xdot[robot.nv :], robot.forward_dynamics(q, v, tau), atol=1e-9)


def test_state_affine_form_includes_the_robots_joint_friction() -> None:
    """With URDF-style friction, F(q, v) x + G equals the model at ẏ = v (C_f from the friction)."""
    robot = pinobs.load("ur5").perturbed(damping=[0.5] * 6, coulomb=[0.3] * 6)
    ob = make_observer("kalman", robot)
    rng = np.random.default_rng(5)
    q = robot.random_configuration(rng)
    v, tau = rng.normal(0, 1, robot.nv), rng.normal(0, 5, robot.nv)
    F, Gv = ob.state_affine(q, v, tau)
    xdot = F @ np.concatenate([np.zeros(robot.nv), v]) + Gv
    np.testing.assert_allclose(xdot[robot.nv :], robot.forward_dynamics(q, v, tau), atol=1e-9)


def test_vector_field_on_the_truth_is_the_model_without_correction() -> None:
    """Theorem 3.1 at x̂ = x, ẏ = v: the correction vanishes and x̂̇ = (v, aba(q, v, τ))."""
    robot = pinobs.load("ur5")
    ob = make_observer("kalman", robot)
    rng = np.random.default_rng(4)
    q = robot.random_configuration(rng)
    v, tau = rng.normal(0, 1, robot.nv), rng.normal(0, 5, robot.nv)
    P = np.eye(2 * robot.nv)
    qd, vd = ob.vector_field(q, v, q, v, tau, P)
    np.testing.assert_allclose(qd, v, atol=1e-14)
    np.testing.assert_allclose(vd, robot.forward_dynamics(q, v, tau), atol=1e-9)


@pytest.mark.parametrize("robot_name", ["cartpole", "ur5"])
def test_kalman_started_on_the_truth_stays_on_it(robot_name: str) -> None:
    robot = pinobs.load(robot_name)
    res = simulate(robot, ["kalman"], sensor=Sensor(1000, 0.0), inputs="pd", duration=0.5, seed=1)
    err = np.abs(res.trace("kalman").v - res.v).max()
    # measured max 5.1e-7 (cartpole), 2.2e-6 (ur5, at t = 23 ms; 1.1e-6 after 0.1 s): the
    # model is evaluated at the interpolated measurement, O(h²) away from the true path
    assert err < 5e-6


@pytest.mark.parametrize("robot_name", ["cartpole", "ur5"])
def test_kalman_converges_from_a_perturbed_start(robot_name: str) -> None:
    robot = pinobs.load(robot_name)
    res = simulate(
        robot,
        ["kalman"],
        sensor=Sensor(1000, 0.0),
        inputs="pd",
        duration=0.5,
        perturb_q=0.1,
        perturb_v=0.5,
        seed=2,
    )
    err = np.abs(res.trace("kalman").v - res.v)
    assert err[0].max() > 0.1
    assert err[res.t > 0.2].max() < 2e-6


def _bowl_run(ob: pinobs.Observer, duration: float, rate: float) -> np.ndarray:
    """Ibrir §4: x₀ = (0, 0.4, 0, 0), x̂₀ = (15, 20, −10, −2), u = 2 sin t; returns |v̂ − v|."""
    robot = bowl_and_cylinder()
    h = 1.0 / rate
    q, v = np.array([0.0, 0.4]), np.zeros(2)
    errs = []
    for i in range(round(duration * rate) + 1):
        t = i * h
        if i > 0:
            tp = np.array([2.0 * math.sin(t - h), 0.0])
            q, v = lie_rk4(
                robot, q, v, h, lambda a, b, tp=tp: (b, robot.forward_dynamics(a, b, tp))
            )
        tau = np.array([2.0 * math.sin(t), 0.0])
        if i == 0:
            est = ob.reset(0.0, np.array([15.0, 20.0]), np.array([-10.0, -2.0]), tau)
        else:
            est = ob.update(t, q, tau)
        errs.append(np.abs(est.v - v).max())
    return np.array(errs)


def test_ibrir_section4_bowl_and_cylinder_estimates_converge() -> None:
    """Figs. 2–3: the printed observer (R = I, no process noise) and the practical one."""
    rate = 250.0
    paper = make_observer(
        "kalman",
        bowl_and_cylinder(),
        form="paper",
        output_weight=1.0,
        q0_std=10.0,
        v0_std=10.0,
        diff_order=2,
        diff_gamma=50.0,
        rate=rate,
    )
    practical = make_observer("kalman", bowl_and_cylinder(), q0_std=10.0, v0_std=10.0, rate=rate)
    e_paper = _bowl_run(paper, 5.0, rate)
    e_practical = _bowl_run(practical, 5.0, rate)
    assert e_paper[0] == pytest.approx(10.0)
    # measured at t = 1, 2, 5 s: 1.95, 0.37, 4.0e-2 (the same at 1 kHz to two digits)
    assert e_paper[round(2 * rate)] < 0.5
    assert e_paper[-1] < 0.06
    # measured: below 1e-5 after 0.1 s
    assert e_practical[round(rate) :].max() < 1e-4


def test_paper_form_gain_fades_and_practical_form_keeps_it() -> None:
    robot = pinobs.load("cartpole")
    obs = {
        "paper": make_observer("kalman", robot, form="paper", rate=1000, noise_std=1e-4),
        "practical": make_observer("kalman", robot, accel_psd=1e-4, rate=1000, noise_std=1e-4),
    }
    traces: dict[str, list[float]] = {k: [] for k in obs}
    rng = np.random.default_rng(3)
    q = robot.neutral()
    for name, ob in obs.items():
        ob.reset(0.0, q)
        for k in range(1, 2001):
            ob.update(k * 1e-3, robot.integrate(q, rng.normal(0, 1e-4, robot.nv)))
            traces[name].append(float(np.trace(ob.covariance()[robot.nv :, robot.nv :])))
    paper, practical = np.array(traces["paper"]), np.array(traces["practical"])
    assert np.all(np.diff(paper[10:]) < 0)  # P only shrinks without process noise
    assert paper[-1] < 1e-3 * paper[0]
    assert practical[-1] == pytest.approx(practical[-500], rel=1e-3)  # a steady gain


def test_kalman_is_within_1_5x_of_the_exact_model_ekf_on_a_noisy_ur5() -> None:
    """1 kHz, σ = 1e-4 rad.  Measured (2 s run): kalman 3.42e-5, ekf 3.45e-5 rad/s (ratio 0.99).

    The printed form's ẏ from the differentiator (``velocity_source="differentiator"``)
    gives 2.5e-4 at its best process noise (1e-6): its error on ẏ is model error.
    """
    robot = pinobs.load("ur5")
    res = simulate(
        robot,
        ["kalman", "ekf"],
        sensor=Sensor(1000, 1e-4),
        inputs="pd",
        duration=2.0,
        seed=0,
    )
    m = {x.observer: x.rms_v_error for x in evaluate(res, robot)}
    assert m["kalman"] < 1.5 * m["ekf"]


@pytest.mark.parametrize(
    ("option", "value"),
    [("form", "printed"), ("velocity_source", "oracle"), ("schedule", "future")],
)
def test_kalman_rejects_unknown_choices(option: str, value: str) -> None:
    with pytest.raises(GainError, match=option):
        make_observer("kalman", pinobs.load("pendulum"), **{option: value})


# ---------------------------------------------------------------- the speed work
def _reference_solve(S: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, bool]:
    return np.linalg.solve(S, B), True


def _reference_joseph(P: np.ndarray, e: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray]:
    nv = e.shape[0]
    K = np.linalg.solve(P[:nv, :nv] + r * np.eye(nv), P[:nv, :]).T
    IKH = np.eye(P.shape[0])
    IKH[:, :nv] -= K
    P_new = IKH @ P @ IKH.T + r * (K @ K.T)
    return K @ e, 0.5 * (P_new + P_new.T)


def _reference_transition(A: np.ndarray, h: float) -> np.ndarray:
    Ah = A * h
    eye = np.eye(A.shape[0])
    return eye + Ah @ (eye + 0.5 * Ah @ (eye + Ah / 3.0))


@pytest.mark.parametrize(
    ("robot_name", "duration", "options"),
    [
        ("ur5", 0.3, {}),
        ("ur5", 0.3, {"form": "paper"}),
        ("ur5", 0.3, {"schedule": "filtered", "velocity_source": "differentiator"}),
        ("top", 0.3, {}),
        ("cartpole", 0.3, {"viscous": 0.3}),
    ],
)
def test_fast_kalman_equals_the_dense_reference_implementation(
    robot_name: str, duration: float, options: dict[str, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The speed work (Cholesky instead of LU, the factored Joseph product, F without G,
    then F, Φ, P⁻ and the update in one compiled call) changes outputs by at most 1e-12
    (measured: ≤ 2e-14 rad/s): the same class run with the dense pre-optimisation helpers,
    ``F`` taken from ``state_affine`` and no compiled call."""
    from pinobs.observers import ibrir_kalman

    robot = pinobs.load(robot_name)
    runs = {}
    for label in ("ref", "fast"):
        with monkeypatch.context() as m:
            if label == "ref":
                m.setattr(ibrir_kalman, "cholesky_solve", _reference_solve)
                m.setattr(ibrir_kalman, "joseph_update", _reference_joseph)
                m.setattr(ibrir_kalman, "transition_matrix", _reference_transition)
                m.setattr(ibrir_kalman, "_fused_kernel", lambda: None)
                m.setattr(
                    ibrir_kalman.IbrirKalman,
                    "_state_matrix",
                    lambda self, y, yd: self.state_affine(y, yd, np.zeros(robot.nv))[0],
                )
            ob = make_observer("kalman", robot, rate=1000, noise_std=1e-4, **options)
            # the compiled path runs on vector-space robots (not on the top's SO(3))
            assert (ob._fused is not None) == (label == "fast" and robot_name != "top")
            runs[label] = simulate(
                robot,
                {label: ob},
                sensor=Sensor(1000, 1e-4, dropout=0.1),
                inputs="pd",
                duration=duration,
                perturb_q=0.01,
                perturb_v=0.1,
                seed=4,
            )
    ref, fast = runs["ref"].trace("ref"), runs["fast"].trace("fast")
    assert np.abs(ref.v - runs["ref"].v).max() > 1e-4  # a real filtering problem
    np.testing.assert_allclose(fast.v, ref.v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.q, ref.q, rtol=0, atol=1e-12)


def test_kalman_compiled_step_makes_no_blas_call_and_equals_the_numpy_step() -> None:
    """Issue 39: on a vector space with the default options ``kalman`` steps in six compiled
    calls around Pinocchio's (:mod:`pinobs.observers.kalman_step`), no BLAS call, so no
    one-BLAS-thread limit; equal to its NumPy step to rounding (the RK4's products summed
    as ``gemm`` where the NumPy step's ``gemv`` sums in its kernel's order, the step without a
    sample by Cholesky loops where it took LAPACK's).  Measured (UR5, 1 s, σ = 1e-4, dropped
    samples and an outlier): ≤ 3e-16 rad/s, NIS to 2e-16 relative."""
    robot = pinobs.load("ur5")
    sim = simulate(robot, [], duration=1.0, sensor=Sensor(1000, 1e-4), seed=3)
    fast = make_observer("kalman", robot, rate=1000, noise_std=1e-4)
    slow = make_observer("kalman", robot, rate=1000, noise_std=1e-4)
    slow._fast = None  # type: ignore[attr-defined]
    assert not fast.uses_blas and fast._fast is not None  # type: ignore[attr-defined]
    out = []
    for ob in (fast, slow):
        ob.reset(sim.t[0], sim.q[0], None, sim.tau[0])
        rows = []
        for k in range(1, sim.t.size):
            q = None if k % 37 == 0 else sim.q_meas[k]
            if k == 300:
                q = q + 0.05  # an outlier: gated, the step redone without it
            e = ob.update(sim.t[k], q, sim.tau[k])
            rows.append(np.concatenate([e.q, e.v, [np.nan if e.nis is None else e.nis]]))
        out.append(np.array(rows))
    assert out[0][299, -1] > 1e3  # (the outlier's NIS)
    np.testing.assert_allclose(out[0][:, :12], out[1][:, :12], rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[0][:, 12], out[1][:, 12], rtol=1e-12)
