"""Innovation consistency (NIS) and the outlier gate of the model-based filters (issue 14 item 3)."""

from __future__ import annotations

import numpy as np
import pytest

import pinobs
from pinobs.observers import make_observer
from pinobs.observers.base import chi2_quantile
from pinobs.simulation import Sensor
from pinobs.simulation.mismatch import mismatched_plant


def _run(robot, plant, names, *, duration=2.0, spikes=(), seed=0, **opts):
    res = pinobs.simulate(
        robot,
        [],
        duration=duration,
        sensor=Sensor(rate=1000.0, noise_std=1e-4),
        seed=seed,
        plant=plant,
    )
    q_meas = np.array(res.q_meas)
    for k, j, size in spikes:
        q_meas[k, j] += size
    out = {}
    for name in names:
        ob = make_observer(name, robot, rate=1000.0, noise_std=1e-4, **opts.get(name, {}))
        ob.reset(0.0, res.q[0], res.v[0], res.tau[0])
        ests = [ob.update(res.t[k], q_meas[k], res.tau[k]) for k in range(1, len(res.t))]
        out[name] = (ob, ests)
    return res, out


def test_chi2_quantile_is_close_to_scipys_and_conservative() -> None:
    from scipy.stats import chi2

    for dof in (1, 2, 6, 9, 18):
        exact = chi2.isf(1e-6, dof)
        assert exact <= chi2_quantile(dof, 1e-6) <= 1.16 * exact


def test_exact_model_is_consistent_and_a_payload_is_not() -> None:
    robot = pinobs.load("ur5")
    _, exact = _run(robot, None, ["ekf"])
    report = exact["ekf"][0].consistency()
    assert report.verdict == "consistent", report
    assert 0.5 * report.expected < report.mean_nis < report.bound
    assert all(e.nis is not None for e in exact["ekf"][1])
    plant = mismatched_plant(robot, "inertia20_payload", seed=0)
    _, wrong = _run(robot, plant, ["ekf"])
    report = wrong["ekf"][0].consistency()
    assert report.verdict == "inconsistent" and report.mean_nis > 10 * report.expected
    assert any("payload" in c for c in report.causes)


def test_model_free_observers_report_no_innovation() -> None:
    robot = pinobs.load("cartpole")
    _, out = _run(robot, None, ["kf"], duration=0.2)
    assert out["kf"][1][-1].nis is None
    assert out["kf"][0].consistency().verdict == "unknown"


@pytest.mark.parametrize("name", ["ekf", "adaptive", "riemannian"])
@pytest.mark.parametrize("size", [10.0, 1000.0])
def test_a_single_spike_is_gated_and_moves_nothing_beyond_the_noise(name: str, size: float) -> None:
    """Before the gate a +10 rad spike corrupted ekf and riemannian for 1.5 s and +1000 rad
    never recovered."""
    robot = pinobs.load("ur5")
    k_spike = 1000
    res, clean = _run(robot, None, [name], duration=2.5)
    _, spiked = _run(robot, None, [name], duration=2.5, spikes=[(k_spike, 2, size)])
    ests_c, ests_s = clean[name][1], spiked[name][1]
    assert ests_s[k_spike - 1].gated and not ests_c[k_spike - 1].gated
    v_c = np.array([e.v for e in ests_c])
    v_s = np.array([e.v for e in ests_s])
    noise_level = np.sqrt(np.mean((v_c[500:] - res.v[501:]) ** 2))
    assert np.abs(v_s[k_spike - 1 :] - v_c[k_spike - 1 :]).max() < 3 * noise_level
    assert spiked[name][0].consistency().gated == 1


def test_the_gate_can_be_switched_off_and_rejects_bad_values() -> None:
    robot = pinobs.load("cartpole")
    _, out = _run(
        robot,
        None,
        ["ekf"],
        duration=1.0,
        spikes=[(500, 0, 10.0)],
        ekf={"outlier_probability": None},
    )
    assert not any(e.gated for e in out["ekf"][1])
    for bad in (0.0, 0.7, -1.0, "x"):
        with pytest.raises(pinobs.GainError, match="outlier_probability"):
            make_observer("ekf", robot, outlier_probability=bad)
