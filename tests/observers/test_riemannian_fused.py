"""``riemannian``'s plain update in one Python call (``pinobs.observers.riemannian_fused``,
issue 39): the same bits and the same errors as the base's own path, which it leaves every
update it does not take."""

from __future__ import annotations

import pickle
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import pinobs
from pinobs.errors import (
    ConfigurationError,
    DimensionError,
    NonFiniteError,
    PinobsWarning,
    TimestampError,
)
from tests.conftest import varied_samples


def _pair(robot: pinobs.Robot, **options: Any) -> tuple[pinobs.Observer, pinobs.Observer]:
    fused, base = (
        pinobs.make_observer("riemannian", robot, rate=1000.0, noise_std=1e-4, **options)
        for _ in "ab"
    )
    base._fused_path = False  # the base's own path
    assert fused._fused_path
    return fused, base


def _same(a: pinobs.Observer, b: pinobs.Observer) -> bool:
    sa, sb = a._state, b._state
    jac = (sa.jacobi is None and sb.jacobi is None) or (
        sa.jacobi is not None
        and sb.jacobi is not None
        and sa.jacobi.tobytes() == sb.jacobi.tobytes()
    )
    return (
        sa.q.tobytes() == sb.q.tobytes()
        and sa.v.tobytes() == sb.v.tobytes()
        and (sa.elapsed, sa.age, sa.P, sa.gate) == (sb.elapsed, sb.age, sb.P, sb.gate)
        and jac
        and a._tau.tobytes() == b._tau.tobytes()
        and list(a._nis) == list(b._nis)
        and (a._gated, a._t, a._ts) == (b._gated, b._t, b._ts)
    )


@pytest.mark.parametrize("robot_name", ["ur5", "go1", "cartpole"])
def test_the_fused_update_gives_the_base_paths_bits(robot_name: str) -> None:
    """Over a run with dropped samples, missed ticks, an outlier, no torque now and then, float
    and NumPy times, strided and read-only samples: the same estimates, state, held torque and
    NIS, on a vector space (ur5), a free-flyer (go1) and continuous joints (cartpole)."""
    robot = pinobs.load(robot_name)
    sim = pinobs.simulate(
        robot, [], duration=0.4, sensor=pinobs.Sensor(rate=1000.0, noise_std=1e-4), seed=1
    )
    fused, base = _pair(robot)
    for ob in (fused, base):
        ob.reset(sim.t[0], sim.q[0], None, sim.tau[0])

    def outlier(q: np.ndarray) -> np.ndarray:
        return robot.integrate(q, 0.3 * np.ones(robot.nv))

    # (missed ticks: the next update spans two periods, the base's sub-steps)
    for _, t, q, tau in varied_samples(sim, outlier_at=200, outlier=outlier, missed=True):
        a, b = fused.update(t, q, tau), base.update(t, q, tau)
        assert a.q.tobytes() == b.q.tobytes() and a.v.tobytes() == b.v.tobytes()
        assert (a.t, a.nis, a.gated) == (b.t, b.nis, b.gated)
        assert not a.q.flags.writeable and not a.v.flags.writeable
        assert _same(fused, base)
    assert fused._gated >= 1


_CHANGES: list[tuple[str, Callable[..., tuple[Any, ...]], type[Exception]]] = [
    ("nan sample", lambda t, q, tau: (t, np.where(np.arange(q.size) == 1, np.nan, q), tau),
     NonFiniteError),
    ("inf torque", lambda t, q, tau: (t, q, np.where(np.arange(tau.size) == 0, np.inf, tau)),
     NonFiniteError),
    ("absurd torque", lambda t, q, tau: (t, q, tau * 1e9), NonFiniteError),
    ("short sample", lambda t, q, tau: (t, q[:-1], tau), DimensionError),
    ("short torque", lambda t, q, tau: (t, q, tau[:-1]), DimensionError),
    ("same time", lambda t, q, tau: (t - 1e-3, q, tau), TimestampError),
    ("nan time", lambda t, q, tau: (np.nan, q, tau), TimestampError),
]  # fmt: skip


@pytest.mark.parametrize("robot_name", ["ur5", "go1"])
@pytest.mark.parametrize(("label", "change", "error"), _CHANGES, ids=[c[0] for c in _CHANGES])
def test_a_bad_input_gives_the_base_paths_error_and_changes_nothing(
    robot_name: str, label: str, change: Callable[..., tuple[Any, ...]], error: type[Exception]
) -> None:
    """Refused by the fused path, a bad input goes to the base's, which raises as it always
    did; the observer is left as it was and goes on as the base's."""
    robot = pinobs.load(robot_name)
    fused, base = _pair(robot)
    q0 = robot.neutral()
    rng = np.random.default_rng(2)
    for ob in (fused, base):
        ob.reset(0.0, q0)
    for k in range(1, 30):
        q = robot.integrate(q0, 1e-4 * np.sin(k + np.arange(robot.nv)))
        for ob in (fused, base):
            ob.update(k * 1e-3, q, np.ones(robot.nv))
    before = pickle.dumps(fused._state)
    q = robot.integrate(q0, 1e-4 * rng.standard_normal(robot.nv))
    for ob in (fused, base):
        with pytest.raises(error):
            ob.update(*change(30e-3, q.copy(), np.ones(robot.nv)))
    assert pickle.dumps(fused._state) == before and _same(fused, base)
    a, b = fused.update(30e-3, q, None), base.update(30e-3, q, None)
    assert a.v.tobytes() == b.v.tobytes() and _same(fused, base)


def test_a_sample_off_the_unit_quaternions_gives_the_base_paths_error() -> None:
    """go1: a sample whose base quaternion is off unit norm (past the tolerance) is the base's
    ``ConfigurationError``; within it, normalised as the base does (the same bits)."""
    robot = pinobs.load("go1")
    fused, base = _pair(robot)
    q0 = robot.neutral()
    for ob in (fused, base):
        ob.reset(0.0, q0)
    off = q0.copy()
    off[3:7] *= 1.5
    for ob in (fused, base):
        with pytest.raises(ConfigurationError):
            ob.update(1e-3, off)
    near = q0.copy()
    near[3:7] *= 1.0 + 1e-9
    a, b = fused.update(1e-3, near), base.update(1e-3, near)
    assert a.q.tobytes() == b.q.tobytes() and _same(fused, base)


def test_what_the_fused_path_does_not_take_is_the_base_paths() -> None:
    """A latency, σ being learnt, the steady schedule and a pause: the base's path (the fused
    one declines), the same bits as an observer without it."""
    robot = pinobs.load("ur5")
    q0 = robot.neutral()
    for options in ({"noise_std": None}, {"gain_schedule": "steady"}):
        ob = pinobs.make_observer("riemannian", robot, rate=1000.0, **options)
        ob.reset(0.0, q0)
        assert ob._update_fused(1e-3, q0, None) is None
    fused, base = _pair(robot)
    for ob in (fused, base):
        ob.set_latency(2e-3)
        ob.reset(0.0, q0)
    assert fused._update_fused(1e-3, q0, None) is None
    for k, t in enumerate((1e-3, 2e-3, 0.5, 0.501)):  # (0.5: a pause, restarted)
        q = q0 + 1e-4 * np.cos(k + np.arange(robot.nq))
        a, b = fused.update(t, q), base.update(t, q)
        assert a.v.tobytes() == b.v.tobytes() and _same(fused, base)


def test_a_diverged_estimate_is_the_base_paths_error() -> None:
    """An estimate that is not finite: the fused path declines and the base raises
    ``ObserverDiverged``, the state kept."""
    robot = pinobs.load("ur5")
    fused, base = _pair(robot)
    q0 = robot.neutral()
    for ob in (fused, base):
        ob.reset(0.0, q0, np.full(robot.nv, 1e300))
    for ob in (fused, base):
        with pytest.raises(pinobs.ObserverDiverged):
            ob.update(1e-3, q0)
    assert _same(fused, base)


def test_the_clipped_gain_warning_points_at_the_users_call() -> None:
    """``gain_schedule="steady"`` with clipped gains (TIAGo's density, σ and rate) warns at
    the line that made the observer, through ``make_observer`` or the class."""
    robot = pinobs.load("ur5")
    options = {"rate": 100.0, "noise_std": 5.24e-6, "accel_psd": 28.1, "gain_schedule": "steady"}
    cls = type(pinobs.make_observer("riemannian", robot))
    for make in (
        lambda: pinobs.make_observer("riemannian", robot, **options),
        lambda: cls(robot, **options),
    ):
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            make()
        clipped = [w for w in seen if issubclass(w.category, PinobsWarning)]
        assert len(clipped) == 1 and "out of (alpha, beta)'s reach" in str(clipped[0].message)
        assert clipped[0].filename == __file__, clipped[0].filename


def test_the_compiled_gate_is_gatestates_rule() -> None:
    """``gate_loops`` (compiled once a fused observer is made) against
    ``GateState.measured`` (the model-based families' ``spike = ∞``) over NIS around the limit,
    runs at and past ``MAX_GATE_RUN``, levels and drifts given or ``None``: the same fields."""
    from pinobs.observers import riemannian_fused
    from pinobs.observers.gating import MAX_GATE_RUN, GateState

    pinobs.make_observer("riemannian", pinobs.load("ur5"), rate=1000.0, noise_std=1e-4)
    gate = riemannian_fused.gate_loops
    assert hasattr(gate, "py_func")  # (compiled: a helper of the loaded kernels)
    rng = np.random.default_rng(4)
    threshold, dof = 22.46, 6
    for _ in range(2000):
        run = int(rng.integers(0, MAX_GATE_RUN + 3))
        level = None if rng.random() < 0.3 else float(rng.uniform(1.0, 60.0))
        drift = None if rng.random() < 0.5 else float(rng.uniform(1.0, 1e4))
        nis = float(np.exp(rng.uniform(-3.0, 8.0)))
        want = GateState(0.0, False, run, level, drift).measured(nis, threshold, dof)
        gated, run1, level1, drift1, none = gate(
            nis, run, 0.0 if level is None else level, level is None,
            0.0 if drift is None else drift, drift is None, threshold, dof,
        )  # fmt: skip
        got = GateState(nis, gated, run1, level1, None if none else drift1)
        assert got == want, (nis, run, level, drift)
