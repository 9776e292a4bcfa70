"""The cost of one observer update, as a multiple of one ``pin.aba`` call on the same robot."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from pinobs.model import aba_call, dynamics_rk4
from pinobs.observers import Observer

__all__ = ["measure_cost"]


@threadpool_limits.wrap(limits=1, user_api="blas")  # as simulate: small matrices
def measure_cost(
    observer: Observer[Any],
    *,
    samples: int = 2000,
    rounds: int = 10,
    rate: float = 1000.0,
    seed: int = 0,
    chunk: int = 20,
    clock: Callable[[], float] = time.perf_counter,
) -> dict[str, float]:
    """``time(update) / time(pin.aba)`` of ``observer`` on its robot, measured in the same run.

    Feeds ``samples`` updates along a slow motion of the model (from a random
    configuration at 0.3 rad/s, the torque holding gravity there; noise-free,
    so no outlier gate fires) from a slightly wrong start (every correction
    term is computed), in ``rounds`` blocks (each restarts near the path).  Updates are timed ``chunk`` at a time and each chunk is
    followed at once by ``chunk`` ``pin.aba`` calls on the same robot (the
    call of :func:`pinobs.model.aba_time`), so every ratio compares the two
    under the same machine load, a millisecond apart.  A chunk's time is a
    mean, so work an observer does every k-th sample (k dividing ``chunk``;
    ``riemannian``'s Jacobi operator, every 10th) counts at its amortised
    share.  The reported ratio is the median over the chunks.  BLAS runs on
    one thread during the measurement (as in :func:`pinobs.simulate`).

    ``clock`` reads the chunks' times [s]: wall time by default; on a loaded
    machine ``time.thread_time`` (this thread's CPU time) leaves out the time
    the process waited for a core, which lands mostly in the long update
    chunks and inflates their ratio (go1 ``riemannian`` at load average 5 on
    2 cores: 63–69× aba by wall time, 27–29× by CPU time, measured interleaved).

    Returns:
        ``{"update_s": ..., "aba_s": ..., "ratio": ...}`` (medians over the chunks).
    """
    robot = observer.robot
    rng = np.random.default_rng(seed)
    q0 = robot.random_configuration(rng, scale=0.5)
    vel = 0.3 * rng.standard_normal(robot.nv)
    tau = robot.gravity(q0)  # hold the start: light links do not fling off
    h = 1.0 / rate
    block = 1 + chunk * max(1, samples // (rounds * chunk))  # a warm-up call, whole chunks
    # the model's own motion (an outlier gate has nothing to reject)
    meas: list[Any] = []
    q: Any = q0
    v: Any = vel
    for _ in range(block):
        q, v = dynamics_rk4(robot, q, v, tau, h)
        meas.append(q)
    aba = aba_call(robot, seed=seed)
    updates, abas = [], []
    for _ in range(rounds):
        # each block restarts near the path's start (its model motion drifts away)
        observer.reset(0.0, robot.integrate(q0, 1e-4 * rng.standard_normal(robot.nv)), vel, tau)
        observer.update(h, meas[0], tau)  # first call: caches warm
        for k0 in range(1, block, chunk):
            t0 = clock()
            for k in range(k0, k0 + chunk):
                observer.update((k + 1) * h, meas[k], tau)
            t1 = clock()
            for _ in range(chunk):
                aba()
            t2 = clock()
            updates.append((t1 - t0) / chunk)
            abas.append((t2 - t1) / chunk)
    ratios = np.array(updates) / np.array(abas)
    return {
        "update_s": float(np.median(updates)),
        "aba_s": float(np.median(abas)),
        "ratio": float(np.median(ratios)),
    }
