"""``ekf``'s and ``kalman``'s plain update in one Python call (``pinobs.observers.ekf_fused``,
``pinobs.observers.kalman_step.update_fused``; issue 39): the same bits and the same errors
as the base's own path, which it leaves every update it does not take."""

from __future__ import annotations

import pickle
from typing import Any

import numpy as np
import pytest

import pinobs
from pinobs.errors import ConfigurationError, DimensionError, NonFiniteError, TimestampError
from pinobs.observers.ekf import ExtendedKalmanFilter
from pinobs.observers.ekf_fused import coast_update_kernel, finish_update_kernel
from pinobs.observers.kalman_step import coast_update_kernel as kalman_coast
from pinobs.observers.kalman_step import correct_update_kernel
from tests.conftest import varied_samples

NAMES = ("ekf", "kalman")


def _pair(name: str, robot: pinobs.Robot, **options: Any) -> tuple[Any, Any]:
    fused, base = (
        pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4, **options) for _ in "ab"
    )
    base._fused_path = False  # the base's own path
    assert fused._fused_path
    return fused, base


def _same(a: Any, b: Any) -> bool:
    sa, sb = a._state, b._state
    return (
        all(x.tobytes() == y.tobytes() for x, y in zip(sa[:3], sb[:3], strict=True))
        and sa.gate == sb.gate
        and a._tau.tobytes() == b._tau.tobytes()
        and list(a._nis) == list(b._nis)
        and (a._gated, a._t, a._ts, a._diverged) == (b._gated, b._t, b._ts, b._diverged)
    )


def _equal(a: pinobs.Estimate, b: pinobs.Estimate) -> bool:
    return (
        a.q.tobytes() == b.q.tobytes()
        and a.v.tobytes() == b.v.tobytes()
        and (a.t, a.nis, a.gated) == (b.t, b.nis, b.gated)
        and type(a.t) is type(b.t)
    )


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("robot_name", ["ur5", "panda"])
def test_the_fused_update_gives_the_base_paths_bits(name: str, robot_name: str) -> None:
    """Over a run with dropped samples, an outlier, no torque now and then, float and NumPy
    times, strided and read-only samples and torques: the same estimates, state, held torque
    and NIS, read-only estimates; the fused path took the plain updates."""
    robot = pinobs.load(robot_name)
    sim = pinobs.simulate(
        robot, [], duration=0.5, sensor=pinobs.Sensor(rate=1000.0, noise_std=1e-4), seed=1
    )
    fused, base = _pair(name, robot)
    for ob in (fused, base):
        ob.reset(sim.t[0], sim.q[0], None, sim.tau[0])
    taken = 0
    for k, t, q, tau in varied_samples(
        sim, outlier_at=300, outlier=lambda q: q + 0.3, varied_tau=True
    ):
        last = fused._last
        a, b = fused.update(t, q, tau), base.update(t, q, tau)
        assert _equal(a, b), k
        assert not a.q.flags.writeable and not a.v.flags.writeable
        taken += a.q.base is not None and a.q.base is a.v.base  # (one array: the fused path's)
        assert fused._last is a and last is not a
    assert _same(fused, base) and fused._gated >= 1
    assert taken >= sim.t.size - 30  # all but the gated and the first (no kernel's layout)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize(
    ("change", "error"),
    [
        (lambda t, q, tau: (t, np.where(np.arange(q.size) == 2, np.nan, q), tau), NonFiniteError),
        (lambda t, q, tau: (t, q, 1e12 * np.ones_like(tau)), NonFiniteError),
        (lambda t, q, tau: (t, q, np.where(np.arange(tau.size) == 1, np.inf, tau)), NonFiniteError),
        (lambda t, q, tau: (t, q[:-1], tau), DimensionError),
        (lambda t, q, tau: (t - 5e-3, q, tau), TimestampError),
        (lambda t, q, tau: (np.nan, q, tau), TimestampError),
    ],
)
def test_what_the_fused_update_does_not_take_the_base_refuses_as_before(
    name: str, change: Any, error: type[Exception]
) -> None:
    """A non-finite sample, an absurd or infinite torque, a sample of the wrong size, a time
    not after the last: the base's error, the observer as it was (then the same updates as
    the base's path)."""
    robot = pinobs.load("ur5")
    fused, base = _pair(name, robot)
    q0 = robot.neutral()
    for ob in (fused, base):
        ob.reset(0.0, q0)
        for k in range(1, 30):
            ob.update(k * 1e-3, q0 + 1e-4 * np.sin(k + np.arange(robot.nq)), np.ones(robot.nv))
    before = pickle.dumps(fused._state)
    for ob in (fused, base):
        with pytest.raises(error):
            ob.update(*change(30e-3, q0.copy(), np.ones(robot.nv)))
    assert pickle.dumps(fused._state) == before and _same(fused, base)
    for k in (30, 31):
        a, b = fused.update(k * 1e-3, q0, None), base.update(k * 1e-3, q0, None)
        assert _equal(a, b) and _same(fused, base)


@pytest.mark.parametrize("name", NAMES)
def test_a_reset_and_a_pause_leave_the_fused_update_as_the_base(name: str) -> None:
    """A reset mid-run, then a pause past the restart limit (the base's restart) and a step
    over dropped samples (its sub-steps): the same bits on both paths after each."""
    robot = pinobs.load("ur5")
    fused, base = _pair(name, robot)
    q0 = robot.neutral()
    times = [*np.arange(1, 40) * 1e-3, 0.5, *(0.5 + np.arange(1, 20) * 1e-3), 0.5265, 0.527]
    for ob in (fused, base):
        ob.reset(0.0, q0)
        for k in range(1, 20):
            ob.update(k * 1e-3, q0 + 1e-3 * np.sin(k + np.arange(robot.nq)), np.ones(robot.nv))
        ob.reset(19e-3, q0 + 0.01, np.full(robot.nv, 0.1))
    for k, t in enumerate(times[19:]):
        q = q0 + 1e-3 * np.cos(k + np.arange(robot.nq))
        a, b = fused.update(t, q, np.ones(robot.nv)), base.update(t, q, np.ones(robot.nv))
        assert _equal(a, b) and _same(fused, base), t
    assert fused.pauses == base.pauses and len(fused.pauses) == 1


def test_ekfs_fused_update_leaves_the_offset_state_and_a_latency_to_the_base() -> None:
    """With ``disturbance_psd`` (the offset state) or a latency the fused path takes nothing
    (``None``, the observer unchanged); a subclass has no fused path (its own methods)."""
    robot = pinobs.load("ur5")
    q0 = robot.neutral()
    offset = pinobs.make_observer("ekf", robot, rate=1000.0, noise_std=1e-4, disturbance_psd=1.0)
    late = pinobs.make_observer("ekf", robot, rate=1000.0, noise_std=1e-4)
    for ob in (offset, late):
        ob.reset(0.0, q0)
    late.set_latency(2e-3)
    for ob in (offset, late):
        before = pickle.dumps(ob._state)
        assert ob._update_fused(1e-3, q0, None) is None
        assert pickle.dumps(ob._state) == before and ob._t == 0.0
        assert ob.update(1e-3, q0, None).t == 1e-3  # (the base's path)

    class Own(ExtendedKalmanFilter):
        pass

    assert not Own(robot, rate=1000.0, noise_std=1e-4)._fused_path


def test_a_replaced_model_goes_on_by_the_fused_update() -> None:
    """``replace_robot`` (``adaptive``'s identified model, a copy's rebound fast path): the
    fused path on the new model gives the base's bits."""
    robot = pinobs.load("ur5")
    heavy = robot.with_inertials(robot.perturbed(payload=(2.0, [0.0, 0.0, 0.1])).model.copy())
    fused, base = _pair("ekf", robot)
    q0 = robot.neutral()
    for ob in (fused, base):
        ob.reset(0.0, q0)
        for k in range(1, 10):
            ob.update(k * 1e-3, q0 + 1e-4 * k, np.ones(robot.nv))
        ob.replace_robot(heavy)
    assert fused._fused_path and fused._fast is not None
    for k in range(10, 30):
        q = q0 + 1e-4 * k
        assert _equal(fused.update(k * 1e-3, q, np.ones(6)), base.update(k * 1e-3, q, np.ones(6)))
    assert _same(fused, base)


def test_the_update_kernels_are_loaded_when_the_observer_is_made() -> None:
    """The fused path's kernels are loaded by the constructor (not in the first update)."""
    robot = pinobs.load("ur5")
    for name in NAMES:
        pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4)
    kernels = (finish_update_kernel, coast_update_kernel, correct_update_kernel, kalman_coast)
    assert all(k.compiled is not None for k in kernels)


@pytest.mark.parametrize(("robot_name", "sigma"), [("go1", 1e-3), ("talos", 1e-4)])
def test_the_block_update_gives_the_base_paths_bits(robot_name: str, sigma: float) -> None:
    """A large robot's ``ekf`` (the block step, ``ekf_fused.update_blocks``), over a run with
    dropped samples, an outlier, no torque now and then, float and NumPy times, strided and
    read-only samples and torques: the same estimates, state, held torque and NIS as the
    base's path; the fused path took every plain update with a sample."""
    robot = pinobs.load(robot_name)
    sim = pinobs.simulate(
        robot, [], duration=0.25, sensor=pinobs.Sensor(rate=1000.0, noise_std=sigma), seed=2
    )
    fused, base = (pinobs.make_observer("ekf", robot, rate=1000.0, noise_std=sigma) for _ in "ab")
    base._fused_path = False
    assert fused._fused_path and fused._fast is None

    def joints_off(q: np.ndarray) -> np.ndarray:  # (the outlier: the joints', not the base's)
        return np.concatenate([q[:7], q[7:] + 0.3])

    for ob in (fused, base):
        ob.reset(sim.t[0], sim.q[0], None, sim.tau[0])
    taken = 0
    for k, t, q, tau in varied_samples(
        sim, outlier_at=120, outlier=joints_off, missed=True, varied_tau=True
    ):
        a, b = fused.update(t, q, tau), base.update(t, q, tau)
        assert _equal(a, b), k
        assert not a.q.flags.writeable and not a.v.flags.writeable
        taken += a.q.base is not None and a.q.base is a.v.base  # (one array: the fused path's)
    assert _same(fused, base) and fused._gated >= 1
    dropped = sum(1 for k in range(1, sim.t.size) if k % 29 == 0 or k % 31 == 4)
    assert taken >= sim.t.size - dropped - 10  # (the first, wide: Joseph's form; the pauses')


@pytest.mark.parametrize(
    ("change", "error"),
    [
        (lambda t, q, tau: (t, np.where(np.arange(q.size) == 2, np.nan, q), tau), NonFiniteError),
        (lambda t, q, tau: (t, q, 1e12 * np.ones_like(tau)), NonFiniteError),
        (lambda t, q, tau: (t, q, np.where(np.arange(tau.size) == 1, np.inf, tau)), NonFiniteError),
        (lambda t, q, tau: (t, np.where(np.arange(q.size) == 3, 2.0, q), tau), ConfigurationError),
        (lambda t, q, tau: (t, q[:-1], tau), DimensionError),
        (lambda t, q, tau: (t - 5e-3, q, tau), TimestampError),
        (lambda t, q, tau: (np.nan, q, tau), TimestampError),
    ],
)
def test_what_the_block_update_does_not_take_the_base_refuses_as_before(
    change: Any, error: type[Exception]
) -> None:
    """A talos's ``ekf``: a non-finite sample, an absurd or infinite torque, a quaternion far
    from unit norm, a sample of the wrong size, a time not after the last: the base's error,
    the observer as it was (then the same updates as the base's path)."""
    robot = pinobs.load("talos")
    fused, base = (pinobs.make_observer("ekf", robot, rate=1000.0, noise_std=1e-4) for _ in "ab")
    base._fused_path = False
    q0 = robot.neutral()
    tau = robot.gravity(q0)
    for ob in (fused, base):
        ob.reset(0.0, q0, None, tau)
        for k in range(1, 30):
            ob.update(k * 1e-3, robot.integrate(q0, 1e-4 * np.sin(k + np.arange(robot.nv))), tau)
    before = pickle.dumps(fused._state)
    for ob in (fused, base):
        with pytest.raises(error):
            ob.update(*change(30e-3, q0.copy(), tau.copy()))
    assert pickle.dumps(fused._state) == before and _same(fused, base)
    for k in (30, 31):
        a, b = fused.update(k * 1e-3, q0, tau), base.update(k * 1e-3, q0, tau)
        assert _equal(a, b) and _same(fused, base)
