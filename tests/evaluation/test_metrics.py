"""Metrics and tables."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pinobs
from pinobs.evaluation import convergence_time, format_table


def test_convergence_time_of_an_exponential_decay_onto_noise() -> None:
    t = np.arange(0, 5, 1e-3)
    rng = np.random.default_rng(0)
    err = np.exp(-5 * t) + 1e-3 * np.abs(rng.standard_normal(t.size))
    tc = convergence_time(t, err)
    # |e| reaches the band 3 × (tail RMS ≈ 1e-3) near ln(1/3e-3)/5 ≈ 1.16 s
    assert 0.9 < tc < 1.3


def test_convergence_time_is_zero_when_started_on_the_truth_and_inf_for_nan() -> None:
    t = np.arange(0, 1, 1e-3)
    assert convergence_time(t, np.full(t.size, 1e-6)) == 0.0
    assert convergence_time(t, np.full(t.size, np.nan)) == math.inf


def test_evaluate_reports_every_observer_and_the_table_lists_them() -> None:
    robot = pinobs.load("cartpole")
    res = pinobs.simulate(
        robot,
        ["fd", "kf"],
        duration=1.0,
        sensor=pinobs.Sensor(noise_std=1e-4),
        perturb_v=0.5,
        seed=1,
    )
    metrics = pinobs.evaluate(res, robot)
    assert [m.observer for m in metrics] == ["fd", "kf"]
    for m in metrics:
        assert 0 < m.rms_v_error < 1 and m.max_v_error >= m.rms_v_error and m.time_per_update > 0
        assert 0 < m.convergence_time < 0.5
    text = format_table(metrics, aba_seconds=1e-6, title="t")
    assert "fd" in text and "kf" in text and "rms v err" in text


def test_rms_is_computed_after_the_transient_only() -> None:
    robot = pinobs.load("pendulum")
    res = pinobs.simulate(robot, ["kf"], duration=1.0, perturb_v=10.0, seed=0)
    early = pinobs.evaluate(res, robot, transient=0.0)[0].rms_v_error
    late = pinobs.evaluate(res, robot, transient=0.5)[0].rms_v_error
    assert late < early
    e = res.trace("kf").v - res.v
    assert late == pytest.approx(np.sqrt(np.mean(e[res.t >= 0.5] ** 2)))


def test_measure_cost_reads_the_given_clock_around_every_chunk() -> None:
    import time

    import pinobs
    from pinobs.evaluation import measure_cost

    reads: list[float] = []

    def clock() -> float:
        reads.append(time.thread_time())
        return reads[-1]

    ob = pinobs.make_observer("kf", pinobs.load("pendulum"), rate=1000.0, noise_std=1e-4)
    cost = measure_cost(ob, samples=200, rounds=2, chunk=20, clock=clock)
    assert len(reads) == 3 * 2 * (200 // (2 * 20))  # three reads per chunk, five chunks a round
    assert cost["ratio"] > 0 and cost["update_s"] > 0 and cost["aba_s"] > 0


@pytest.mark.parametrize("transient", [-1.0, math.nan, math.inf, 0.1, 0.2])
def test_evaluate_refuses_a_transient_outside_the_run(transient: float) -> None:
    robot = pinobs.load("pendulum")
    res = pinobs.simulate(robot, ["kf"], duration=0.1)
    with pytest.raises(pinobs.errors.GainError, match=r"transient=.* is out of range"):
        pinobs.evaluate(res, robot, transient=transient)
    assert pinobs.evaluate(res, robot, transient=0.0)[0].rms_v_error < 1.0


def test_format_table_of_no_observers_is_the_header() -> None:
    assert format_table([]).splitlines()[0].split()[0] == "observer"
