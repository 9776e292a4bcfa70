"""The compiled steps of ``ekf`` and ``riemannian`` on robots with Lie-group or continuous
joints (:class:`~pinobs.observers.fused_lie.LieRK4`, the Lie correction and Jacobi kernels,
:class:`~pinobs.observers.fused_lie.LieRiccatiStep`, :mod:`pinobs.observers.blocks`; issue 39)
equal the NumPy steps they replace, to rounding, over a few thousand updates (and the same
operations to the bit)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.model import AnalyticMetric, dynamics_rk4
from pinobs.model.integrators import difference_call, integrate_call
from pinobs.observers import blocks, make_observer
from pinobs.observers.blockstep import MOST_RATIO, bracket_table, transition_kernels
from pinobs.observers.fused import lie_correction_kernel, loaded
from pinobs.observers.fused_jacobi import JacobiCalls, ad_kernel, jacobi_kernel
from pinobs.observers.fused_lie import LieRiccatiStep, LieRK4, bracket_kernel, rkmk4_solve_kernel
from pinobs.observers.linalg import joseph_update, transition_matrix
from pinobs.observers.riemannian import jacobi_operator
from pinobs.simulation import Sensor
from tests.conftest import cached_robot
from tests.observers.test_fused import _run
from tests.observers.test_purity import fingerprint

# the attributes that switch the compiled paths on (None: the NumPy step)
_COMPILED = (
    "_scratch_lie",
    "_lie_correction",
    "_riccati_correction",
    "_scratch_calls",
    "_lie_fast",
    "_scratch_fast",
)


@pytest.mark.parametrize(
    ("robot_name", "name", "duration"),
    [
        ("ur5", "riemannian", 3.0),
        ("go1", "riemannian", 3.0),
        ("top", "ekf", 3.0),
        ("rigid_body", "ekf", 3.0),
        ("go1", "ekf", 3.0),
        ("talos", "ekf", 2.0),
        ("talos", "riemannian", 2.0),
        ("cartpole_continuous", "riemannian", 3.0),
        ("cartpole_continuous", "ekf", 3.0),
    ],
)
def test_the_compiled_step_equals_the_numpy_step_over_thousands_of_updates(
    robot_name: str, name: str, duration: float
) -> None:
    """A run with missing samples (and the gate on), 2000–3000 updates from a start off the
    truth: the compiled step against the NumPy one (the same observer with its compiled paths
    switched off), the estimates equal to rounding: per signal to 1e-12 of its largest value,
    or, where the run itself amplifies rounding beyond that, no further apart than 4× what
    one ulp on one sample moves the NumPy run (its own sensitivity to rounding).  Measured:
    talos ``riemannian`` on a CPU without AVX-512 (OpenBLAS's Haswell kernels) 1.5–1.9e-12
    of a velocity's largest value apart, and the NumPy run 1.6e-12 from itself with one ulp
    on its first sample (within 1e-12 on an AVX-512 machine, where it was written)."""
    robot = cached_robot(robot_name)
    res = pinobs.simulate(robot, [], duration=duration, sensor=Sensor(1000.0, 1e-4), seed=4)
    fast = make_observer(name, robot, rate=1000.0, noise_std=1e-4)
    taken = [a for a in _COMPILED if getattr(fast, a, None) is not None]
    assert taken  # a compiled path is the one compared

    def numpy_run(r: pinobs.Result) -> tuple[np.ndarray, np.ndarray]:
        slow = make_observer(name, robot, rate=1000.0, noise_std=1e-4)
        for attr in taken:
            setattr(slow, attr, None)
        return _run(slow, r)

    fast_qv, slow_qv = _run(fast, res), numpy_run(res)
    assert np.isfinite(slow_qv[1]).all()
    apart = [_largest_relative(a, b) for a, b in zip(fast_qv, slow_qv, strict=True)]
    limit = 1e-12
    if max(apart) > limit:  # the run's own rounding sensitivity: one ulp on one sample
        q_meas = res.q_meas.copy()
        q_meas[1] = np.nextafter(q_meas[1], np.inf)
        nudged = dataclasses.replace(res, q_meas=q_meas)
        spread = [_largest_relative(a, b) for a, b in zip(numpy_run(nudged), slow_qv, strict=True)]
        assert 0.0 < max(spread) < 1e-10  # (a sensitivity of rounding size, not a blow-up)
        limit = 4.0 * max(spread)
    assert max(apart) <= limit, (apart, limit)


def _largest_relative(a: np.ndarray, b: np.ndarray) -> float:
    """The largest difference of a signal (column) over its largest |value| in ``b``."""
    return float(np.max(np.abs(a - b).max(axis=0) / np.abs(b).max(axis=0)))


@pytest.mark.parametrize("robot_name", ["go1", "talos", "cartpole_continuous", "top", "brackets"])
def test_the_compiled_rkmk4_step_is_dynamics_rk4_to_the_bit(robot_name: str) -> None:
    """:class:`LieRK4` runs :func:`pinobs.model.dynamics_rk4`'s operations in its order
    (no fused multiply-adds; the block solves by the same LAPACK ``dgesv`` on the same
    matrices, compiled where there is no planar joint): the same bits, with and without the
    first stage given, at speeds up to rotations of ~2 rad in a step."""
    robot = _floating_planar_spherical() if robot_name == "brackets" else cached_robot(robot_name)
    rk4 = LieRK4.build(robot)
    assert rk4 is not None and rk4.solves == (robot_name != "brackets")
    rng = np.random.default_rng(3)
    for i in range(8):
        q, v = robot.random_configuration(rng), rng.standard_normal(robot.nv) * 10.0 ** (i % 4)
        tau = rng.standard_normal(robot.nv)
        q_ref, v_ref = dynamics_rk4(robot, q, v, tau, 1e-3)
        for acc0 in (None, robot.forward_dynamics(q, v, tau)):
            q_new, v_new = rk4.step(q, v, tau, 1e-3, acc0=acc0)
            np.testing.assert_array_equal(q_new, q_ref)
            np.testing.assert_array_equal(v_new, v_ref)


@pytest.mark.parametrize("robot_name", ["ur5", "go1", "talos", "cartpole_continuous"])
def test_the_compiled_jacobi_operator_equals_the_numpy_products(
    robot_name: str, monkeypatch: Any
) -> None:
    """:func:`jacobi_operator` by :func:`~pinobs.observers.fused_jacobi.jacobi_loops` (no BLAS)
    equals its NumPy products to 1e-13 of its largest term (``∂_q Γs(v, v)``,
    ``(∂_v Γs(v, v))²``; the operator itself: on a cartpole, flat, the terms cancel to
    1e-12 of them)."""
    robot = cached_robot(robot_name)
    jacobi_kernel.load()
    rng = np.random.default_rng(5)
    for _ in range(4):
        q, v = robot.random_configuration(rng), rng.standard_normal(robot.nv)
        compiled = jacobi_operator(robot, q, v)
        with monkeypatch.context() as m:
            m.setattr(jacobi_kernel, "compiled", None)
            reference = jacobi_operator(robot, q, v)
        _, p_v, b_v = robot.spray_jacobians(q, v)
        scale = max(np.abs(reference).max(), np.abs(p_v).max(), np.abs(b_v).max() ** 2)
        assert np.abs(compiled - reference).max() <= 1e-13 * scale


@pytest.mark.parametrize("robot_name", ["ur5", "go1", "cartpole_continuous", "top"])
def test_the_jacobi_calls_are_jacobi_operator_to_the_bit(robot_name: str) -> None:
    """:class:`JacobiCalls` (its own ``pin.Data``, signs folded into the kernel, ``q ± εv``
    on a vector space) makes the operations of :func:`jacobi_operator` with its compiled
    products on the same numbers: the same bits, at speeds from 1e-3 to 10 and zero; and
    ``J z`` is the model's curvature ``R(v, z)v`` (:meth:`Robot.curvature`, ABA calls
    only, no finite difference) to the finite difference's 1e-8.  With Lie-group joints
    (free-flyer, spherical) ``ad_v`` and ``ad_Γs(v,v)`` are compiled
    (:func:`~pinobs.observers.fused_jacobi.ad_loops`; tested alone below, with a planar joint)."""
    robot = cached_robot(robot_name)
    jacobi_kernel.load()
    calls = JacobiCalls.build(robot)
    assert calls is not None
    rng = np.random.default_rng(8)
    for speed in (1e-3, 1.0, 10.0, 0.0):
        q, v = robot.random_configuration(rng), rng.standard_normal(robot.nv)
        v *= speed / np.linalg.norm(v)
        J = calls(q, v)
        np.testing.assert_array_equal(J, jacobi_operator(robot, q, v))
        z = 1e-2 * rng.standard_normal(robot.nv)
        reference = robot.curvature(q, v, z, v)
        assert np.abs(J @ z - reference).max() <= 1e-8 * max(np.abs(reference).max(), 1.0)
    assert JacobiCalls.build(AnalyticMetric(lambda q: np.eye(2), n=2)) is None  # not a Robot


@pytest.mark.parametrize(
    ("robot_name", "options"),
    [("ur5", {}), ("ur5", {"gain_schedule": "steady"}), ("go1", {"curvature_every": 3})],
)
def test_the_observer_with_jacobi_calls_is_the_observer_with_jacobi_operator_to_the_bit(
    robot_name: str, options: dict[str, Any]
) -> None:
    """``riemannian`` with :class:`JacobiCalls` on its correction's ``pin.Data`` (the
    operator first, then the correction's call) against the same observer calling
    :func:`jacobi_operator` on the robot's data: over 1500 updates from a start off the
    truth, with missing samples, the same bits (and the operator was recomputed)."""
    robot = cached_robot(robot_name)
    res = pinobs.simulate(robot, [], duration=1.5, sensor=Sensor(1000.0, 1e-4), seed=6)
    fast = make_observer("riemannian", robot, rate=1000.0, noise_std=1e-4, **options)
    slow = make_observer("riemannian", robot, rate=1000.0, noise_std=1e-4, **options)
    assert isinstance(fast._scratch_jacobi, JacobiCalls)
    assert fast._scratch_jacobi.calls.data is fast._scratch_derivatives.data
    slow._scratch_jacobi = None
    q_fast, v_fast = _run(fast, res)
    q_slow, v_slow = _run(slow, res)
    assert fast._state.jacobi is not None and np.abs(fast._state.jacobi).max() > 0.0
    np.testing.assert_array_equal(q_fast, q_slow)
    np.testing.assert_array_equal(v_fast, v_slow)


@pytest.mark.parametrize("with_offset", [False, True])
def test_the_block_products_equal_the_dense_ones(with_offset: bool) -> None:
    """On a talos's ``A`` (free-flyer: ``−ad_v̂`` on six rows), :func:`blocks.transition`
    equals :func:`transition_matrix` and :func:`blocks.joseph_update` the dense
    :func:`joseph_update`, to 1e-13 of their largest entries."""
    robot = cached_robot("talos")
    nv = robot.nv
    n = (3 if with_offset else 2) * nv
    rng = np.random.default_rng(2)
    q, v = robot.random_configuration(rng), rng.standard_normal(nv)
    _, da_dq, da_dv, minv = robot.forward_dynamics_with_derivatives(q, v, robot.gravity(q))
    A = np.zeros((n, n))
    A[:nv, :nv] = -robot.bracket_matrix(v)
    A[:nv, nv : 2 * nv] = np.eye(nv)
    A[nv : 2 * nv, :nv], A[nv : 2 * nv, nv : 2 * nv] = da_dq, da_dv
    if with_offset:
        A[nv : 2 * nv, 2 * nv :] = np.triu(minv) + np.triu(minv, 1).T
    rows = blocks.bracket_rows(robot)
    assert rows == (slice(0, 6),)
    Phi = blocks.transition(A, 1e-3, nv, rows)
    ref = transition_matrix(A, 1e-3)
    assert np.abs(Phi - ref).max() <= 1e-13 * np.abs(ref).max()
    X = rng.standard_normal((n, n))
    P = 1e-4 * (X @ X.T) / n + 1e-6 * np.eye(n)
    e = 1e-3 * rng.standard_normal(nv)
    for r in (1e-8, 1e-2):
        dx, P_new = blocks.joseph_update(P, e, r)
        dx_ref, P_ref = joseph_update(P, e, r)
        assert np.abs(dx - dx_ref).max() <= 1e-13 * np.abs(dx_ref).max()
        assert np.abs(P_new - P_ref).max() <= 1e-13 * np.abs(P_ref).max()
        np.testing.assert_array_equal(P_new, P_new.T)


def test_the_lie_group_paths_are_taken_where_they_apply() -> None:
    """``riemannian`` takes the compiled Lie-group paths on go1 and talos and with constant
    gains makes no BLAS call there (its update enters no thread limit); ``ekf`` takes its
    compiled RKMK4 up to nv = 12 (top), the block step above (go1, talos: covariance
    products on one BLAS thread), and with the offset state the general path on a go1."""
    go1, talos, top = cached_robot("go1"), cached_robot("talos"), cached_robot("top")
    small = make_observer("ekf", top, rate=1000.0, noise_std=1e-4)
    assert small._lie_fast is not None and small._lie_fast.rk4 is not None
    for robot in (go1, talos):  # the block step, on one BLAS thread (its products)
        large = make_observer("ekf", robot, rate=1000.0, noise_std=1e-4)
        assert large._lie_fast is not None and large._lie_fast.rk4 is None and large.uses_blas
        assert large._lie_fast.blocks is not None
    offset = make_observer("ekf", go1, rate=1000.0, noise_std=1e-4, disturbance_psd=1.0)
    assert offset._lie_fast is None  # between the two, with the offset: the general path
    for robot in (go1, talos):  # the whole step with the schedule, else the correction
        rie = make_observer("riemannian", robot, rate=1000.0, noise_std=1e-4)
        assert isinstance(rie._scratch_fast, LieRiccatiStep) and rie._scratch_lie.solves
        assert not rie.uses_blas
        steady = make_observer("riemannian", robot, rate=1000.0, gain_schedule="steady")
        assert steady._scratch_fast is None and steady._lie_correction is not None
        assert not steady.uses_blas
    # state-dependent gains: the general correction, on one BLAS thread
    rie = make_observer("riemannian", go1, beta=100.0, gain_a=lambda s, speed: 8.0 + s)
    assert rie._lie_correction is None and rie.uses_blas


@pytest.mark.parametrize(
    ("robot_name", "name"), [("top", "ekf"), ("talos", "ekf"), ("go1", "riemannian")]
)
def test_the_lie_group_paths_keep_step_pure(robot_name: str, name: str) -> None:
    """``step`` on the Lie-group paths changes only working memory (``_scratch*``,
    ``pin.Data``: tests/observers/test_purity.py, whose robots take the vector-space paths
    for these families) and gives the same state twice from the same inputs."""
    robot = cached_robot(robot_name)
    res = pinobs.simulate(robot, [], duration=0.2, sensor=Sensor(1000.0, 1e-4), seed=3)
    ob = make_observer(name, robot, rate=1000.0, noise_std=1e-4)
    ob.reset(res.t[0], res.q[0], None, res.tau[0])
    for k in range(1, res.t.size - 1):
        ob.update(res.t[k], res.q_meas[k], res.tau[k])
    state, before = ob._state, fingerprint(ob)
    first = ob.step(state, 1e-3, res.q_meas[-1], res.tau[-1])
    assert fingerprint(ob) == before
    second = ob.step(state, 1e-3, res.q_meas[-1], res.tau[-1])
    assert fingerprint(ob) == before
    for a, b in zip(first, second, strict=True):
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)


def _talos_state(
    rng: np.random.Generator, robot: pinobs.Robot, scale: float = 1e-6
) -> tuple[Any, ...]:
    nv = robot.nv
    q, v = robot.random_configuration(rng, scale=0.5), rng.standard_normal(nv)
    X = rng.standard_normal((2 * nv, 4 * nv))
    P = scale * (X @ X.T) / (4 * nv) + 1e-8 * np.eye(2 * nv)  # SPD, spread as a filter's
    return q, v, P, robot.gravity(q)


def test_the_block_step_equals_predict_then_correct_on_talos() -> None:
    """:class:`~pinobs.observers.blockstep.BlockStep` (``Φ`` from ``A``'s blocks, the Cholesky
    gain by rows, the Joseph update's lower block triangle) against the filter's
    :meth:`predict` and :meth:`correct` on ``A`` (:func:`blocks.transition`,
    :func:`blocks.joseph_update`): ``(q⁻, v⁻)`` to the bit (both RKMK4 steps are
    :func:`dynamics_rk4`'s), ``P⁻``, ``dx``, ``P⁺`` to 1e-13 of their largest entries,
    ``P⁺`` exactly symmetric (the block step's ``P⁻ − Zᵀ Z`` against the Joseph form, with
    ``P⁻_qq`` up to 1e-6, 100 ``R``: below ``MOST_RATIO``)."""
    robot = cached_robot("talos")
    nv = robot.nv
    ekf = make_observer("ekf", robot, rate=1000.0, noise_std=1e-4)
    step = ekf._lie_fast.blocks
    assert step is not None
    rng = np.random.default_rng(7)
    for _ in range(3):
        q, v, P, tau = _talos_state(rng, robot)
        state = ekf.initial_state(q, v)._replace(P=P)
        pred, _ = ekf.predict(state, 1e-3, tau)
        r, psd = ekf.gains.meas_std**2, ekf.gains.accel_psd
        q_b, v_b, P_b = step.predict(q, v, tau, 1e-3, P, psd, r)
        np.testing.assert_array_equal(q_b, pred.q)
        np.testing.assert_array_equal(v_b, pred.v)
        assert np.abs(P_b - pred.P).max() <= 1e-13 * np.abs(pred.P).max()
        e = 1e-3 * rng.standard_normal(nv)
        dx, P_new, nis, v_new = step.correct(P_b, e, r, v_b)
        dx_ref, P_ref = blocks.joseph_update(pred.P, e, r)
        assert np.abs(dx - dx_ref).max() <= 1e-13 * np.abs(dx_ref).max()
        np.testing.assert_array_equal(v_new, v_b + dx[nv:])  # v⁺ = v⁻ + dx_v
        assert np.abs(P_new - P_ref).max() <= 1e-13 * np.abs(P_ref).max()
        np.testing.assert_array_equal(P_new, P_new.T)
        S = pred.P[:nv, :nv] + r * np.eye(nv)
        assert nis == pytest.approx(float(e @ np.linalg.solve(S, e)), rel=1e-9)


@pytest.mark.parametrize("case", ["indefinite", "wide"])
def test_the_block_step_takes_the_general_correction_where_s_is_not_positive_definite(
    case: str,
) -> None:
    """A covariance whose ``S = P_qq + R`` is indefinite (a filter being lost), or whose
    ``P_qq`` exceeds ``MOST_RATIO · R`` (a wide start, where ``P⁻ − Zᵀ Z`` would lose
    ``P⁺_qq``'s digits): the block step reports it (NaN NIS) and the filter's step equals
    the general path's (Joseph form)."""
    robot = cached_robot("talos")
    nv = robot.nv
    fast = make_observer("ekf", robot, rate=1000.0, noise_std=1e-4)
    slow = make_observer("ekf", robot, rate=1000.0, noise_std=1e-4)
    slow._lie_fast = None
    rng = np.random.default_rng(8)
    q, v, P, tau = _talos_state(rng, robot)
    if case == "indefinite":
        P[:nv, :nv] -= 2.0 * np.abs(P).max() * np.eye(nv)  # S negative definite
    else:
        P[:nv, :nv] += 2.0 * MOST_RATIO * 1e-8 * np.eye(nv)  # P_qq,ii > MOST_RATIO · R
    state = fast.initial_state(q, v)._replace(P=P)
    step = fast._lie_fast.blocks
    _, v_b, P_b = step.predict(q, v, tau, 1e-3, P, fast.gains.accel_psd, 1e-8)
    assert np.isnan(step.correct(P_b, np.zeros(nv), 1e-8, v_b)[2])
    q_meas = robot.integrate(q, 1e-4 * rng.standard_normal(nv))
    a = fast.step(state, 1e-3, q_meas, tau)
    b = slow.step(state, 1e-3, q_meas, tau)
    for x, y in ((a.q, b.q), (a.v, b.v), (a.P, b.P)):
        assert np.abs(x - y).max() <= 1e-12 * np.abs(y).max()


@pytest.mark.parametrize("robot_name", ["go1", "talos"])
def test_the_block_step_started_on_the_truth_stays_on_it_and_converges_from_off_it(
    robot_name: str,
) -> None:
    """The block step (go1, nv = 18; talos, nv = 38), noise-free: started on the truth it
    stays on it; started off it, it converges."""
    robot = cached_robot(robot_name)
    assert make_observer("ekf", robot)._lie_fast.blocks is not None  # the path tested
    res = pinobs.simulate(robot, ["ekf"], sensor=Sensor(1000, 0.0), duration=0.3, seed=1)
    assert (
        np.abs(res.trace("ekf").v - res.v).max() < 1e-10
    )  # measured 3.0e-14 (talos, |v| ≤ 11), 4.1e-14 (go1)
    res = pinobs.simulate(
        robot, ["ekf"], sensor=Sensor(1000, 0.0), duration=0.3, seed=1, perturb_q=0.01,
        perturb_v=0.1,
    )  # fmt: skip
    err = np.abs(res.trace("ekf").v - res.v)
    assert err[0].max() > 0.01
    assert (
        err[res.t > 0.2].max() < 1e-8
    )  # 4.1e-2, 4.4e-2 at the start; 5.3e-11, 4.9e-11 after 0.2 s


def _floating_planar_spherical() -> pinobs.Robot:
    """A free-flyer carrying a spherical joint and a planar one (every bracket kind)."""
    model = pin.Model()
    inertia = pin.Inertia.FromBox(1.0, 0.2, 0.1, 0.1)
    base = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
    model.appendBodyToJoint(base, inertia, pin.SE3.Identity())
    ball = model.addJoint(base, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    model.appendBodyToJoint(ball, inertia, pin.SE3.Identity())
    plane = model.addJoint(ball, pin.JointModelPlanar(), pin.SE3.Identity(), "plane")
    model.appendBodyToJoint(plane, inertia, pin.SE3.Identity())
    return pinobs.Robot(model, name="brackets", source="test")


@pytest.mark.parametrize("robot_name", ["talos", "top", "brackets"])
def test_the_compiled_bracket_blocks_are_the_robots(robot_name: str) -> None:
    """The block step's ``D = −ad_v`` (:func:`~pinobs.observers.blockstep.bracket_table`'s
    kernel) equals ``−robot.bracket_matrix(v)`` on the runs of bracket rows (adjacent joints'
    blocks merged), to the bit, for the free-flyer, spherical and planar joints;
    ``G = [∂a/∂q ∂a/∂v]`` copied."""
    robot = _floating_planar_spherical() if robot_name == "brackets" else cached_robot(robot_name)
    nv = robot.nv
    start = loaded(transition_kernels[0])
    table = bracket_table(robot)
    rng = np.random.default_rng(9)
    for _ in range(3):
        v, a_q, a_v = (
            rng.standard_normal(nv),
            rng.standard_normal((nv, nv)),
            rng.standard_normal((nv, nv)),
        )
        G, D = np.empty((nv, 2 * nv)), np.zeros((nv, nv))  # (zero off the blocks, as BlockStep's)
        start(a_q, a_v, v, table, G, D)
        np.testing.assert_array_equal(G, np.hstack([a_q, a_v]))
        ref = -robot.bracket_matrix(v)
        for s in blocks.bracket_rows(robot):
            np.testing.assert_array_equal(D[s, s], ref[s, s])


def test_the_bound_difference_and_integrate_are_the_robots_to_the_bit() -> None:
    """:func:`~pinobs.model.integrators.difference_call` and ``integrate_call`` (the block
    step's, without the methods' Python calls) give :meth:`Robot.difference`'s and
    :meth:`Robot.integrate`'s arrays on a talos, and are the methods themselves where a
    subclass overrides them."""
    robot = cached_robot("talos")
    rng = np.random.default_rng(4)
    q0, q1 = robot.random_configuration(rng), robot.random_configuration(rng)
    dx = rng.standard_normal(robot.nv)
    diff, integ = difference_call(robot), integrate_call(robot)
    np.testing.assert_array_equal(diff(q0, q1), robot.difference(q0, q1))
    np.testing.assert_array_equal(integ(q0, dx), robot.integrate(q0, dx))
    assert diff(q0, q1).dtype == np.float64 and integ(q0, dx).dtype == np.float64

    class Shifted(pinobs.Robot):
        def difference(self, q0: Any, q1: Any) -> Any:
            return super().difference(q0, q1) + 1.0

        def integrate(self, q: Any, v: Any) -> Any:
            return super().integrate(q, v)

    shifted = object.__new__(Shifted)
    shifted.__dict__.update(robot.__dict__)
    assert difference_call(shifted) == shifted.difference
    assert integrate_call(shifted) == shifted.integrate


@pytest.mark.parametrize("robot_name", ["talos", "top", "brackets"])
def test_the_compiled_bracket_and_ad_are_the_robots_to_the_bit(robot_name: str) -> None:
    """:func:`~pinobs.observers.fused_lie.bracket_loops` (the correction's ``[ζ, w]``) gives
    :meth:`Robot.bracket`'s arrays (``pin.Motion``'s cross product in a free-flyer, ``np.cross``
    in a spherical joint, the se(2) expressions in a planar one) and
    :func:`~pinobs.observers.fused_jacobi.ad_loops` (the Jacobi operator's) ``bracket_matrix``'s,
    vectors of scales 1e-6 to 1e3."""
    robot = _floating_planar_spherical() if robot_name == "brackets" else cached_robot(robot_name)
    bracket, ad = loaded(bracket_kernel), loaded(ad_kernel)
    table, out, mat = bracket_table(robot), np.empty(robot.nv), np.zeros((robot.nv, robot.nv))
    rng = np.random.default_rng(10)
    for i in range(200):
        x = rng.standard_normal(robot.nv) * 10.0 ** (i % 10 - 6)
        y = rng.standard_normal(robot.nv) * 10.0 ** (i % 7 - 3)
        bracket(table, x, y, out)
        np.testing.assert_array_equal(out, robot.bracket(x, y))
        ad(table, x, mat)
        np.testing.assert_array_equal(mat, robot.bracket_matrix(x))


def _run_with_outliers(ob: Any, res: pinobs.Result) -> tuple[np.ndarray, ...]:
    """``ob`` over ``res`` from a start off the truth, every 7th sample missing and every 11th
    an outlier (0.05 rad off): its estimates ``(q, v, nis)``."""
    robot, rng = ob.robot, np.random.default_rng(12)
    ob.reset(res.t[0], robot.integrate(res.q[0], np.full(robot.nv, 1e-3)), None, res.tau[0])
    out: list[list[Any]] = [[], [], []]
    for k in range(1, res.t.size):
        q = None if k % 7 == 0 else res.q_meas[k]
        if q is not None and k % 11 == 0:
            q = robot.integrate(q, 0.05 * rng.standard_normal(robot.nv))
        est = ob.update(res.t[k], q, res.tau[k])
        for row, x in zip(out, (est.q, est.v, np.nan if est.nis is None else est.nis), strict=True):
            row.append(x)
    return tuple(np.array(row) for row in out)


@pytest.mark.parametrize("robot_name", ["go1", "top", "cartpole_continuous"])
def test_the_whole_lie_riccati_step_is_the_step_it_replaces_to_the_bit(robot_name: str) -> None:
    """``riemannian`` by :class:`~pinobs.observers.fused_lie.LieRiccatiStep` (one Python call:
    the compiled solves and stages, ``normalize`` in place, the schedule's gains, the
    correction and its bracket in one kernel) against the same observer's step by methods
    (:meth:`_predicted`, the NumPy gate, :meth:`_correct_compiled` and ``Robot.bracket``): 1000
    updates from a start off the truth, with missing samples and outliers (some gated), the
    Jacobi operator recomputed: the same bits."""
    robot = cached_robot(robot_name)
    res = pinobs.simulate(robot, [], duration=1.0, sensor=Sensor(1000.0, 1e-4), seed=11)
    fast = make_observer("riemannian", robot, rate=1000.0, noise_std=1e-4)
    slow = make_observer("riemannian", robot, rate=1000.0, noise_std=1e-4)
    assert isinstance(fast._scratch_fast, LieRiccatiStep)
    slow._scratch_fast, slow._lie_correction = None, loaded(lie_correction_kernel)
    a, b = _run_with_outliers(fast, res), _run_with_outliers(slow, res)
    assert np.sum(a[2] > 1e3) > 50  # the outliers' NIS (the gate's path taken)
    if robot.has_lie_group_joints:
        assert np.abs(fast._state.jacobi).max() > 0.0
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)


def test_the_compiled_solve_gives_nan_where_the_block_is_singular() -> None:
    """A block ``J_r(ξ)`` that LAPACK cannot factor (a zero matrix) gives NaN in that block of
    ``k``, as :meth:`Robot.integrate_jacobian_solve` does, and ``v_s`` elsewhere."""
    solve_stage = loaded(rkmk4_solve_kernel)
    w, k = np.zeros((10, 8)), np.empty(8)
    w[9] = np.arange(1.0, 9.0)
    jexp = np.zeros((1, 6, 6))
    solve_stage(w, np.zeros(8), jexp, np.array([[6, 0]], dtype=np.int64), k, 2, 1e-3)
    assert np.isnan(k[:6]).all() and np.array_equal(k[6:], [7.0, 8.0])
    jexp[0], w[9] = np.eye(6), np.arange(1.0, 9.0)  # (the stage wrote the next v_s there)
    solve_stage(w, np.zeros(8), jexp, np.array([[6, 0]], dtype=np.int64), k, 2, 1e-3)
    np.testing.assert_array_equal(k, np.arange(1.0, 9.0))


def test_the_rkmk4_step_keeps_a_subclass_s_own_solve_and_normalize() -> None:
    """Where a :class:`Robot` subclass overrides ``normalize`` or ``integrate_jacobian_solve``,
    :class:`LieRK4` calls its methods (no compiled solves, no normalisation in place) and still
    gives :func:`dynamics_rk4`'s bits."""
    robot = cached_robot("go1")

    class OwnNormalize(pinobs.Robot):
        def normalize(self, q: Any) -> Any:
            return super().normalize(q)

    class OwnSolve(pinobs.Robot):
        def integrate_jacobian_solve(self, q: Any, xi: Any, u: Any) -> Any:
            return super().integrate_jacobian_solve(q, xi, u)

    rng = np.random.default_rng(13)
    for cls in (OwnNormalize, OwnSolve):
        own = object.__new__(cls)
        own.__dict__.update(robot.__dict__)
        rk4 = LieRK4.build(own)
        assert rk4 is not None and not rk4.solves and rk4.solve_stage is None
        q, v = own.random_configuration(rng), rng.standard_normal(own.nv)
        tau = rng.standard_normal(own.nv)
        q_new, v_new = rk4.step(q, v, tau, 1e-3)
        q_ref, v_ref = dynamics_rk4(own, q, v, tau, 1e-3)
        np.testing.assert_array_equal(q_new, q_ref)
        np.testing.assert_array_equal(v_new, v_ref)
