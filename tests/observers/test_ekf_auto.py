"""``ekf`` with ``disturbance_psd="auto"`` alone (issue 36, item 2): the learned density's
ceiling ``AUTO_CEILING · σ² / h⁵``, a pure ``initial_state``, the truth kept, convergence, and
a grossly wrong model degrading to about the ``kf`` at 100 Hz (where it diverged before)."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.errors import GainError
from pinobs.evaluation import evaluate
from pinobs.observers import make_observer
from pinobs.observers.ekf import (
    AUTO_CEILING,
    AUTO_PSD_BOUNDS,
    AUTO_WINDOW,
    EKFState,
    ExtendedKalmanFilter,
)
from pinobs.observers.neverbehind import match_density
from pinobs.simulation import Sensor, simulate
from tests.observers.test_purity import fingerprint


def _auto(robot: pinobs.Robot, rate: float, noise_std: float) -> ExtendedKalmanFilter:
    ob = make_observer("ekf", robot, rate=rate, noise_std=noise_std, disturbance_psd="auto")
    assert isinstance(ob, ExtendedKalmanFilter)
    return ob


def _rms(res: pinobs.simulation.Result, robot: pinobs.Robot) -> dict[str, float]:
    return {m.observer: m.rms_v_error for m in evaluate(res, robot)}


def test_initial_state_writes_nothing_on_the_observer() -> None:
    """The density's per-joint scale lives in the state (it was ``self._psd_bounds``)."""
    robot = pinobs.load("ur5")
    ob = _auto(robot, 1000.0, 1e-4)
    before = fingerprint(vars(ob))
    q0 = robot.neutral()
    s1 = ob.initial_state(q0, np.zeros(robot.nv))
    q1 = robot.integrate(q0, np.full(robot.nv, 0.3))
    s2 = ob.initial_state(q1, np.zeros(robot.nv))
    assert fingerprint(vars(ob)) == before
    m1 = np.diag(robot.mass_matrix(q0)) ** 2
    m2 = np.diag(robot.mass_matrix(q1)) ** 2
    assert s1.psd_scale is not None and s2.psd_scale is not None
    np.testing.assert_array_equal(s1.psd_scale, m1)
    np.testing.assert_array_equal(s2.psd_scale, m2)
    assert not np.array_equal(m1, m2)  # each state its own: nothing shared through self


def _stepped(ob: ExtendedKalmanFilter, rate: float) -> tuple[EKFState, EKFState, np.ndarray]:
    """A committed state after 0.3 s, its next predicted state and measurement."""
    robot = ob.robot
    res = simulate(robot, [], sensor=Sensor(rate, ob.gains.meas_std), inputs="pd", duration=0.3)
    ob.reset(res.t[0], res.q[0], res.v[0], res.tau[0])
    for k in range(1, res.t.size - 1):
        ob.update(res.t[k], res.q_meas[k], res.tau[k])
    state = ob._state
    assert state is not None
    dt = float(res.t[-1] - res.t[-2])
    pred, _ = ob.predict(state, dt, res.tau[-2])
    return state, pred, res.q_meas[-1]


def test_the_density_matched_as_before_where_the_ceiling_does_not_bind() -> None:
    """σ = 1e-3 at 1 kHz: the ceiling (1e9 rad²/s⁵) is above ``AUTO_PSD_BOUNDS``' top, so the
    update is bit for bit the former one (bounds ``AUTO_PSD_BOUNDS · M̄ᵢᵢ²`` from the reset)."""
    robot = pinobs.load("ur5")
    ob = _auto(robot, 1000.0, 1e-3)
    assert AUTO_CEILING * 1e-6 / 1e-15 > AUTO_PSD_BOUNDS[1]
    _, pred, q_meas = _stepped(ob, 1000.0)
    assert pred.d_psd is not None and pred.psd_scale is not None
    nv, dt = robot.nv, 1e-3
    e = robot.difference(pred.q, q_meas)
    s = pred.P.diagonal()[:nv] + ob.gains.meas_std**2
    old_bounds = np.outer(AUTO_PSD_BOUNDS, pred.psd_scale)
    old = match_density(pred.d_psd, e, s, dt, window=AUTO_WINDOW, bounds=old_bounds)
    np.testing.assert_array_equal(ob.matched_density(pred, e, s, dt), old)


def test_the_density_stays_below_its_ceiling() -> None:
    """An innovation 1e6 σ off would raise ψ far above; it stops at ``σ²/h⁵ · M̄ᵢᵢ²``."""
    robot = pinobs.load("ur5")
    ob = _auto(robot, 100.0, 1e-4)
    _, pred, _ = _stepped(ob, 100.0)
    assert pred.d_psd is not None and pred.psd_scale is not None
    nv, dt = robot.nv, 0.01
    ceiling = AUTO_CEILING * 1e-8 / dt**5 * pred.psd_scale
    e, state = np.full(nv, 100.0), pred._replace(d_psd=0.5 * ceiling)
    for _ in range(3):  # ×1.87 each (the step's clip, h/T = 0.1)
        state = state._replace(d_psd=ob.matched_density(state, e, np.full(nv, 1e-8), dt))
    np.testing.assert_allclose(state.d_psd, ceiling, rtol=1e-12)


def test_started_on_the_truth_noise_free_it_stays_at_100_hz() -> None:
    robot = pinobs.load("ur5")
    ob = make_observer("ekf", robot, noise_std=0.0, disturbance_psd="auto")
    res = simulate(robot, {"auto": ob}, sensor=Sensor(100, 0.0), inputs="pd", duration=1.0, seed=1)
    assert np.abs(res.trace("auto").v - res.v).max() < 1e-8


def test_converges_from_a_perturbed_start() -> None:
    """Exact model, 1 kHz, σ = 1e-4, started 0.5 rad/s off on every joint: within 2× the
    started-on-the-truth run's error after the settling time (measured 1.0×)."""
    robot = pinobs.load("ur5")
    obs = {"on": _auto(robot, 1000.0, 1e-4), "off": _auto(robot, 1000.0, 1e-4)}
    res = simulate(robot, [], sensor=Sensor(1000, 1e-4), inputs="pd", duration=2.0, seed=0)
    err = {}
    for label, ob in obs.items():
        v0 = res.v[0] + (0.5 if label == "off" else 0.0)
        ob.reset(res.t[0], res.q[0], v0, res.tau[0])
        v = [ob.update(res.t[k], res.q_meas[k], res.tau[k]).v for k in range(1, res.t.size)]
        late = res.t[1:] >= 1.0
        err[label] = float(np.sqrt(np.mean((np.array(v) - res.v[1:])[late] ** 2)))
    assert err["off"] <= 2.0 * err["on"]
    assert err["on"] < 1e-3


@pytest.mark.parametrize("rate", [100.0, 1000.0])
def test_a_grossly_wrong_model_degrades_to_about_the_kf(rate: float) -> None:
    """Masses ×3 in the truth, UR5, pd tracking, σ = 1e-4.  At 100 Hz the density without
    its ceiling ran to 2e7 rad²/s⁵ and the filter diverged (NaN; the plain ekf too); with it
    1.34× the ``kf`` (1.8e-2 against 1.3e-2).  At 1 kHz the ceiling (1e7) does not bind:
    3.0× the ``kf`` as before (1.6e-2 against 5.2e-3: what the learned density cannot follow
    of an error that varies as fast as the motion)."""
    robot = pinobs.load("ur5")
    truth = robot.perturbed(name="ur5x3", inertia_scale=np.full(len(robot.joints), 3.0))
    obs = {
        "auto": _auto(robot, rate, 1e-4),
        "kf": make_observer("kf", robot, rate=rate, noise_std=1e-4),
    }
    res = simulate(
        robot, obs, sensor=Sensor(rate, 1e-4), inputs="pd", duration=3.0, seed=0, plant=truth
    )
    rms = _rms(res, robot)
    assert np.isfinite(rms["auto"])
    assert rms["auto"] <= (1.5 if rate == 100.0 else 3.5) * rms["kf"]


def test_matched_density_refuses_a_state_without_the_learned_density() -> None:
    robot = pinobs.load("ur5")
    ob = make_observer("ekf", robot, rate=1000.0, noise_std=1e-4, disturbance_psd=1.0)
    assert isinstance(ob, ExtendedKalmanFilter)
    state = ob.initial_state(robot.neutral(), np.zeros(robot.nv))
    e = np.zeros(robot.nv)
    with pytest.raises(GainError, match="disturbance_psd='auto'"):
        ob.matched_density(state, e, np.ones(robot.nv), 1e-3)
