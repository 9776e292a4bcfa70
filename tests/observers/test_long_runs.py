"""Numerical faults: long runs, near-singular mass matrices, divergence reported, not NaN."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from pinobs.model import Robot
from pinobs.observers import observer_names


def _spin(robot: Robot, n: int, ob, *, h: float = 1e-3) -> None:
    """Feed ``n`` noise-free samples of a constant body-rate rotation."""
    v = np.zeros(robot.nv)
    v[-3:] = [0.3, -0.2, 5.0]
    q = robot.neutral()
    ob.reset(0.0, q, v)
    for k in range(1, n + 1):
        q = robot.integrate(q, h * v)
        ob.update(k * h, q, np.zeros(robot.nv))


@pytest.mark.parametrize(
    "n", [20_000, pytest.param(1_000_000, marks=pytest.mark.slow, id="a million")]
)
@pytest.mark.parametrize("jerk_psd", [1e3, "auto"])
def test_kf_keeps_unit_quaternions_and_a_symmetric_covariance_over_many_updates(
    n: int, jerk_psd: float | str
) -> None:
    robot = pinobs.load("top")
    ob = pinobs.make_observer("kf", robot, noise_std=1e-4, jerk_psd=jerk_psd)
    _spin(robot, n, ob)
    assert abs(np.linalg.norm(ob.estimate.q) - 1.0) < 1e-12
    state = ob._state
    for P in [state.P] if jerk_psd != "auto" else list(state.bank.P):  # "auto": every filter's
        np.testing.assert_array_equal(P, P.T)
        assert np.linalg.eigvalsh(P).min() > 0


@pytest.mark.parametrize("name", observer_names())
def test_quaternion_estimates_stay_unit_over_twenty_thousand_updates(name: str) -> None:
    robot = pinobs.load("top")
    try:
        ob = pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4)
    except pinobs.UnsupportedRobotError:
        pytest.skip(f"{name} does not run on a spherical joint")
    _spin(robot, 20_000, ob)
    assert abs(np.linalg.norm(ob.estimate.q) - 1.0) < 1e-12


def _cartpole_with_pole_mass(mass: float) -> Robot:
    robot = pinobs.load("cartpole")
    model = robot.model.copy()
    i = model.getJointId("pole_theta")
    inertia = model.inertias[i]
    model.inertias[i] = pin.Inertia(mass, inertia.lever, inertia.inertia * mass / inertia.mass)
    return Robot(model, name=f"cartpole_pole_{mass:g}", source="test")


@pytest.mark.parametrize("name", observer_names())
def test_a_near_singular_mass_matrix_gives_finite_estimates_or_a_reported_divergence(
    name: str,
) -> None:
    robot = _cartpole_with_pole_mass(1e-7)
    m = robot.mass_matrix(robot.neutral())
    assert np.linalg.cond(m) > 1e6
    try:
        ob = pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4)
    except pinobs.PinobsError as exc:  # refusing the robot with a reason is also honest
        assert str(exc)
        return
    res = pinobs.simulate(
        robot, {name: ob}, duration=0.3, sensor=pinobs.Sensor(1000.0, 1e-4), seed=0
    )
    tr = res.trace(name)
    if tr.diverged_at is None:
        assert np.all(np.isfinite(tr.v))
    else:
        k = int(np.searchsorted(res.t, tr.diverged_at))
        assert np.all(np.isfinite(tr.v[:k])) and np.all(np.isnan(tr.v[k:]))


def test_divergence_raises_with_the_time_and_the_last_finite_estimate() -> None:
    from pinobs.observers.base import Observer  # a deliberately unstable toy family, not registered

    class Unstable(Observer[tuple]):
        name = "unstable_toy"

        def initial_state(self, q0, v0):
            return (q0, v0)

        def step(self, state, dt, q_meas, tau):
            q, v = state
            return (q, np.full_like(v, np.inf))

        def output(self, state):
            return state

    robot = pinobs.load("pendulum")
    ob = Unstable(robot)
    ob.reset(0.0, np.zeros(1), np.ones(1))
    with pytest.raises(pinobs.ObserverDiverged, match=r"diverged at t = 0\.001") as info:
        ob.update(0.001, np.zeros(1))
    assert info.value.t == 0.001
    assert info.value.last_estimate.t == 0.0 and np.isfinite(info.value.last_estimate.v).all()
    assert ob.estimate.t == 0.0  # state kept
    assert "unstable_toy" not in observer_names()  # the toy was never registered
