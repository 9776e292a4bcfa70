"""The cost of one observer update, as a multiple of one ``pin.aba`` call on the same robot."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from pinobs.model import aba_time
from pinobs.observers import Observer

__all__ = ["measure_cost"]


def measure_cost(
    observer: Observer[Any],
    *,
    samples: int = 2000,
    rounds: int = 10,
    rate: float = 1000.0,
    seed: int = 0,
) -> dict[str, float]:
    """``time(update) / time(pin.aba)`` of ``observer`` on its robot, measured in the same run.

    Feeds ``samples`` updates along a slow motion from a slightly wrong start
    (every correction term is computed), in ``rounds`` blocks; after each
    block, times ``pin.aba`` (:func:`pinobs.model.aba_time`) on the same
    robot, so both see the same machine load.  The ratio is the median over
    the blocks of ``median update time / aba time`` (medians: robust to a
    process being preempted on a loaded machine).

    Returns:
        ``{"update_s": ..., "aba_s": ..., "ratio": ...}`` (medians).
    """
    robot = observer.robot
    rng = np.random.default_rng(seed)
    q0 = robot.random_configuration(rng, scale=0.5)
    vel = 0.3 * rng.standard_normal(robot.nv)
    tau = robot.gravity(q0)  # hold the start: light links do not fling off
    h = 1.0 / rate
    block = max(samples // rounds, 1)
    meas = [robot.integrate(q0, (k + 1) * h * vel) for k in range(block)]
    updates, abas = [], []
    for _ in range(rounds):
        # each block restarts near the path: a constant-velocity path is not a
        # motion of the model, so long blocks would measure a diverging estimate
        observer.reset(0.0, robot.integrate(q0, 1e-4 * rng.standard_normal(robot.nv)), vel, tau)
        times = []
        for k in range(block):
            t0 = time.perf_counter()
            observer.update((k + 1) * h, meas[k], tau)
            times.append(time.perf_counter() - t0)
        updates.append(float(np.median(times)))  # the median ignores preempted updates
        abas.append(aba_time(robot, repeats=100, rounds=5, seed=seed))
    ratios = np.array(updates) / np.array(abas)
    return {
        "update_s": float(np.median(updates)),
        "aba_s": float(np.median(abas)),
        "ratio": float(np.median(ratios)),
    }
