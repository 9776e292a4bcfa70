"""``kf``'s compiled banks on Lie-group joints (continuous, spherical, free-flyer): the group's
``integrate``/``difference`` in loops (``pinobs/observers/kf_kernels.py``) against Pinocchio's,
and the compiled ``"auto"`` and bank steps against the NumPy ones."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.model import Robot
from pinobs.observers import kf_kernels
from pinobs.observers.kf import KFBank

LIE_ROBOTS = ["go1", "top", "kinova", "double_pendulum_continuous"]


@pytest.mark.parametrize("name", LIE_ROBOTS)
def test_compiled_integrate_and_difference_equal_pinocchios(name: str) -> None:
    """``q ⊕ d`` and ``difference(q0, q1)`` per joint against ``pin.integrate`` and
    ``pin.difference``, from 1e-9 (the Taylor branches) to 3 rad steps (measured: integrate
    within 3.3e-16, difference within 5e-16 × max(1, |d|) away from the cut locus)."""
    robot = pinobs.load(name)
    table = kf_kernels.joint_table(robot.joints, robot.nq, robot.nv)
    assert table is not None and table.shape[0] > 0
    pinobs.make_observer("kf", robot, noise_std=1e-4)  # loads the kernels (and the helpers)
    rng = np.random.default_rng(0)
    for k in range(600):
        scale = (1e-9, 1e-5, 1e-3, 0.1, 1.0, 3.0)[k % 6]
        q0 = robot.random_configuration(rng, scale=3.0)
        d = rng.uniform(-scale, scale, robot.nv)
        q1 = np.empty(robot.nq)
        kf_kernels.integrate_joints(q0, d, table, q1)
        np.testing.assert_allclose(q1, pin.integrate(robot.model, q0, d), rtol=0, atol=1e-15)
        e = np.empty(robot.nv)
        kf_kernels.difference_joints(q0, q1, table, e)
        ref = pin.difference(robot.model, q0, q1)
        if scale < 1.0:  # (3 rad about three axes reaches the cut locus at π)
            assert np.all(np.abs(e - ref) <= 4e-15 * np.maximum(1.0, np.abs(ref)))
        else:
            assert np.all(np.abs(e - ref) <= 1e-11 * np.maximum(1.0, np.abs(ref)))


def _noisy_log(
    robot: Robot, rng: np.random.Generator, n: int
) -> tuple[np.ndarray, list, np.ndarray]:
    """``(t, q_meas, missing)``: a smooth motion measured with 1e-4 noise, four jumps (two
    paired), 5 % of the samples missing and a 1 s pause."""
    h, v, q = 1e-3, rng.uniform(-1.0, 1.0, robot.nv), robot.neutral()
    qs = []
    for k in range(n):
        q = robot.integrate(q, h * (v + 0.5 * np.sin(7 * k * h + np.arange(robot.nv))))
        qs.append(robot.integrate(q, 1e-4 * rng.standard_normal(robot.nv)))
    for k in (300, 500, 501, 800):
        qs[k] = robot.integrate(qs[k], 0.05 * rng.choice([-1.0, 1.0], size=robot.nv))
    t = np.arange(n) * h
    t[700:] += 1.0
    return t, qs, rng.random(n) < 0.05


def _run(robot: Robot, t: np.ndarray, qs: list, missing: np.ndarray) -> tuple[np.ndarray, ...]:
    ob = pinobs.make_observer("kf", robot, noise_std=1e-4, rate=1000.0)
    ob.reset(t[0], qs[0])
    out = [ob.update(t[k], None if missing[k] else qs[k]) for k in range(1, t.size)]
    est = np.array([np.concatenate([e.q, e.v]) for e in out])
    nis = np.array([np.nan if e.nis is None else e.nis for e in out])
    bank = KFBank(robot, (1e1, 1e3, 1e5), 1e-4)
    state, rows = bank.initial(qs[0], np.zeros(robot.nv), 1.0), []
    for k in range(1, t.size):
        state = bank.step(state, float(t[k] - t[k - 1]), None if missing[k] else qs[k])
        rows.append(np.concatenate([state.q.ravel(), state.v.ravel()]))
    ll = bank.log_likelihoods(t, np.array(qs), ~missing, 1.0)
    gated = np.array([e.gated for e in out])
    return est, nis, gated, ob.densities, np.array(rows), ll, np.array([ob.auto_bank.compiled])


@pytest.mark.parametrize("name", ["go1", "top", "kinova"])
def test_compiled_banks_equal_the_numpy_ones_on_lie_groups(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The compiled ``"auto"`` step and ``KFBank.step``/``run`` against their NumPy paths
    (``pin.integrate``/``difference`` filter by filter) on a free-flyer, a spherical joint and
    continuous joints: the same samples gated; ``"auto"``'s estimates within 1e-12 of each
    signal's largest value (measured on this log: 8.3e-15 go1, 4.3e-15 top, 3.9e-13 kinova;
    element-wise up to 1e-9 where a signal crosses zero); the bank's states (``q, v`` of
    densities 1e1–1e5) within 1e-11 of it (measured 1.1e-12, 2.9e-12, 7.7e-13; the
    vector-joint kernel on ur5, the same log: 7.7e-13: the loops' ``P`` and gain round
    otherwise than NumPy's products, and ``e = q_meas − q⁻`` cancels about 1e4 of ``q``'s
    digits); NIS, densities and log-likelihoods relative (measured 1.3e-11, 1.3e-12,
    2.4e-15)."""
    robot = pinobs.load(name)
    t, qs, missing = _noisy_log(robot, np.random.default_rng(1), 1000)
    compiled = _run(robot, t, qs, missing)
    for kernel in (kf_kernels.auto_kernel, kf_kernels.bank_kernel):
        monkeypatch.setattr(kernel, "compiled", None)
        monkeypatch.setattr(kernel, "load", lambda: None)  # (a new bank would load it again)
    numpy = _run(robot, t, qs, missing)
    assert compiled[6][0] and not numpy[6][0]
    assert np.array_equal(compiled[2], numpy[2]) and 2 <= int(np.sum(numpy[2])) <= 5
    pairs = ((compiled[0], numpy[0], 1e-12), (compiled[4], numpy[4], 1e-11))
    for a, b, tol in pairs:
        assert np.all(np.abs(a - b) <= tol * np.max(np.abs(b), axis=0))
    ok = np.isfinite(numpy[1])
    np.testing.assert_array_equal(np.isfinite(compiled[1]), ok)
    np.testing.assert_allclose(compiled[1][ok], numpy[1][ok], rtol=1e-10)
    np.testing.assert_allclose(compiled[3], numpy[3], rtol=1e-11)
    np.testing.assert_allclose(compiled[5], numpy[5], rtol=1e-13)


def test_auto_keeps_unit_quaternions_in_its_compiled_step() -> None:
    robot = pinobs.load("go1")
    t, qs, missing = _noisy_log(robot, np.random.default_rng(2), 2000)
    est = _run(robot, t, qs, missing)[0]
    quat = est[:, 3:7]
    assert np.max(np.abs(np.linalg.norm(quat, axis=1) - 1.0)) < 1e-14


def test_a_planar_joint_takes_the_numpy_path() -> None:
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelPlanar(), pin.SE3.Identity(), "base")
    model.appendBodyToJoint(joint, pin.Inertia.FromBox(1.0, 0.2, 0.1, 0.1), pin.SE3.Identity())
    robot = Robot(model, name="planar_body", source="test")
    assert kf_kernels.joint_table(robot.joints, robot.nq, robot.nv) is None
    ob = pinobs.make_observer("kf", robot, noise_std=1e-4, rate=1000.0)
    assert ob.auto_bank is not None and not ob.auto_bank.compiled
    q = robot.neutral()
    ob.reset(0.0, q)
    for k in range(1, 20):
        q = robot.integrate(q, np.array([1e-3, 0.0, 2e-3]))
        est = ob.update(k * 1e-3, q)
    assert np.all(np.isfinite(est.v))


def test_storing_a_log_run_needs_vector_joints() -> None:
    robot = pinobs.load("top")
    bank = KFBank(robot, (1e3,), 1e-4)
    t = np.arange(3) * 1e-3
    q = np.tile(robot.neutral(), (3, 1))
    with pytest.raises(pinobs.UnsupportedRobotError, match="nq = nv"):
        bank.run(t, q, np.ones(3, dtype=bool), 1.0)
    assert np.all(np.isfinite(bank.log_likelihoods(t, q, np.ones(3, dtype=bool), 1.0)))
