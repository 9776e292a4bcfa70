"""A known measurement latency (issue 14 item 4): the state at the measurement time, the estimate delivered now."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.observers import make_observer, observer_names
from pinobs.simulation import Sensor


def _rms(robot, res, name, latency=None, t0=1.0):
    opts = {} if latency is None else {"latency": latency}
    ob = make_observer(name, robot, rate=1000.0, noise_std=res.meta["noise_std"] or None, **opts)
    ob.reset(0.0, res.q[0], res.v[0], res.tau[0])
    v = [res.v[0]]
    for k in range(1, len(res.t)):
        qm = res.q_meas[k]
        v.append(ob.update(res.t[k], None if np.isnan(qm).any() else qm, res.tau[k]).v)
    k0 = int(np.searchsorted(res.t, t0))
    return float(np.sqrt(np.mean((np.array(v)[k0:] - res.v[k0:]) ** 2))), np.array(v)


@pytest.mark.parametrize("name", ["ekf", "riemannian", "adaptive"])
def test_given_latency_restores_the_no_latency_accuracy(name: str) -> None:
    """Measured (UR5, 4 s, σ = 1e-4, seed 1): ekf 3.0e-5 without latency, 4.2e-3 with 1 ms
    unknown, 3.0e-5 with latency=1e-3 given (3 ms: 1.25e-2 and 3.0e-5)."""
    robot = pinobs.load("ur5")
    clean = pinobs.simulate(robot, [], duration=3.0, sensor=Sensor(noise_std=1e-4), seed=1)
    late = pinobs.simulate(robot, [], duration=3.0, sensor=Sensor(noise_std=1e-4, delay=2), seed=1)
    base, _ = _rms(robot, clean, name)
    unknown, _ = _rms(robot, late, name)
    given, _ = _rms(robot, late, name, latency=2e-3)
    assert given < 1.5 * base
    if name != "adaptive":  # (adaptive's blend hides part of the latency error: not asserted)
        assert unknown > 10 * base


def test_started_on_the_truth_with_latency_it_stays_there() -> None:
    robot = pinobs.load("planar_3r")
    res = pinobs.simulate(robot, [], duration=1.0, sensor=Sensor(delay=3), seed=0)
    for name in ("ekf", "riemannian"):
        _, v = _rms(robot, res, name, latency=3e-3, t0=0.0)
        assert np.abs(v - res.v).max() < 1e-6


@pytest.mark.parametrize("name", observer_names())
def test_every_observer_accepts_a_latency_and_rejects_a_negative_one(name: str) -> None:
    robot = pinobs.load("top" if name == "liegroup" else "cartpole")
    ob = make_observer(name, robot, rate=1000.0, latency=1e-3)
    assert ob.latency == 1e-3
    with pytest.raises(pinobs.GainError, match="latency"):
        make_observer(name, robot, rate=1000.0, latency=-1.0)


@pytest.mark.parametrize("name", ["kf", "ekf"])
def test_a_pause_whose_first_update_has_no_sample_restarts_under_a_latency(name: str) -> None:
    """A 1 s pause under a 3 ms latency whose first update brings no sample: the next sample
    restarts the state (at rest here: zero velocity, its position).  Before, the torque
    held through the pause was stamped at the update without a sample, after the state's
    time, and the lookup raised ``StopIteration`` (found by helper kfbuf)."""
    robot = pinobs.load("ur5")
    ob = make_observer(name, robot, noise_std=1e-4, rate=1000.0, latency=3e-3)
    q = robot.neutral()
    ob.reset(0.0, q, None, robot.gravity(q))
    for k in range(1, 20):
        ob.update(k * 1e-3, q, robot.gravity(q))
    ob.update(19e-3 + 1.0, None, robot.gravity(q))
    est = ob.update(20e-3 + 1.0, q, robot.gravity(q))
    assert len(ob.pauses) == 1
    np.testing.assert_allclose(est.v, 0.0, atol=1e-9)
    np.testing.assert_allclose(est.q, q, atol=1e-9)
