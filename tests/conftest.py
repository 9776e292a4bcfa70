"""Shared fixtures: a seeded generator and robots built once per session."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterator
from functools import cache

import numpy as np
import pytest

import pinobs


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261121)


@cache
def cached_robot(name: str) -> pinobs.Robot:
    """Load once per session; callers that mutate must ``.copy()``."""
    return pinobs.load(name)


def planar_3r_truth(robot: pinobs.Robot) -> pinobs.Robot:
    """The identification tests' truth for a planar 3R: inertias scaled by (1.2, 0.8, 1.1),
    a 0.5 kg payload 5 cm out, viscous and Coulomb friction."""
    return robot.perturbed(
        inertia_scale=[1.2, 0.8, 1.1],
        payload=(0.5, [0.05, 0.0, 0.0]),
        damping=[0.2, 0.1, 0.05],
        coulomb=[0.1, 0.05, 0.02],
    )


def torque_error(model: pinobs.Robot, truth: pinobs.Robot, *, seed: int = 7) -> np.ndarray:
    """Per joint, the RMS [N·m or N] of ``model``'s inverse dynamics (friction included)
    against the torques of a fresh 4 s trajectory of ``truth`` (at its own accelerations,
    every 10th sample of 1 kHz): a prediction error in the torques' own units, whatever
    weighting a fit used."""
    from pinobs.simulation import Sensor

    val = pinobs.simulate(
        model, [], duration=4.0, sensor=Sensor(rate=1000.0), seed=seed, plant=truth
    )
    errs = []
    for q, v, tau in zip(val.q[::10], val.v[::10], val.tau[::10], strict=True):
        a = truth.forward_dynamics(q, v, tau)
        errs.append(model.inverse_dynamics(q, v, a) - model.friction_torque(v) - tau)
    return np.sqrt(np.mean(np.square(errs), axis=0))


@pytest.fixture
def robot_factory():
    return lambda name: cached_robot(name).copy()


def dropped_rows(n: int, fraction: float, seed: int) -> np.ndarray:
    """Which of ``n`` log rows a lossy logger keeps (booleans): ``fraction`` of them lost,
    80 % of the losses single rows, the others runs of 3–9 rows; the first two rows and the
    last ten are kept, and two runs never touch (each is one interval of 2–10 periods)."""
    rng = np.random.default_rng(seed)
    keep = np.ones(n, dtype=bool)
    lost = 0
    while lost < fraction * n:
        k = int(rng.integers(2, n - 12))
        run = 1 if rng.random() < 0.8 else int(rng.integers(3, 10))
        if keep[k - 1 : k + run + 1].all():
            keep[k : k + run] = False
            lost += run
    return keep


def resampled_log(
    robot: pinobs.Robot, plant: pinobs.Robot, duration: float, noise: float, seed: int
) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """One 10 kHz run of ``plant`` (``pd`` input, torque held 0.1 ms) sampled twice: every
    1 ms (the clean log) and at intervals uniform in 0.5–1.5 ms on the 0.1 ms grid (a
    truly irregular, correctly stamped log); each ``(t, q, tau)``, positions with white
    noise ``noise`` [rad] (the first row exact), torques as sampled at the rows."""
    from pinobs.simulation import Sensor

    res = pinobs.simulate(
        robot, [], duration=duration, sensor=Sensor(rate=10_000.0), seed=seed, plant=plant
    )
    n = res.t.size
    steps = np.random.default_rng(seed + 1).integers(5, 16, size=n)  # 0.5–1.5 ms
    irregular = np.concatenate([[0], np.cumsum(steps)])
    logs = []
    for rows in (np.arange(0, n, 10), irregular[irregular < n]):
        noise_rng = np.random.default_rng(seed + 2)
        q = np.array(
            [plant.integrate(res.q[k], noise_rng.normal(0, noise, plant.nv)) for k in rows]
        )
        q[0] = res.q[rows[0]]
        logs.append((res.t[rows], q, np.array(res.tau[rows])))
    return logs[0], logs[1]


def irregular_loop_log(
    plant: pinobs.Robot, duration: float, noise: float, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A control loop run at intervals uniform in 0.5–1.5 ms, each torque held over its own
    interval (``pd`` input about the configuration and reference ``pinobs.simulate`` draws
    with ``seed``): ``(t, q, tau, v)``, ``q`` measured with white noise ``noise`` [rad]
    (the first row exact), ``v`` the true velocity."""
    from pinobs.simulation.inputs import make_input
    from pinobs.simulation.run import _plant_step

    rng = np.random.default_rng(seed)  # as simulate draws them
    q = plant.random_configuration(rng, scale=0.3)
    inputs = make_input("pd", plant, rng=rng, center=q)
    steps = np.random.default_rng(seed + 1).uniform(0.5e-3, 1.5e-3, int(2 * duration / 0.5e-3))
    t = np.concatenate([[0.0], np.cumsum(steps)])
    t = t[t <= duration]
    qs, vs, taus = [], [], []
    v = np.zeros(plant.nv)
    for k in range(t.size):
        if k:
            q, v = _plant_step(plant, q, v, taus[-1], t[k] - t[k - 1], 1)
        qs.append(q)
        vs.append(v)
        taus.append(inputs.torque(t[k], q, v))
    noise_rng = np.random.default_rng(seed + 2)
    q_meas = np.array([plant.integrate(x, noise_rng.normal(0, noise, plant.nv)) for x in qs])
    q_meas[0] = qs[0]
    return t, q_meas, np.array(taus), np.array(vs)


def last_line(code: str, *, runs: int = 1) -> str:
    """The last line ``code`` prints in a fresh Python process, run ``runs`` times in a row
    (the last run's: a first run fills a cache the next one reads)."""
    for _ in range(runs):
        out = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        )
    return out.stdout.strip().splitlines()[-1]


def varied_samples(
    sim: pinobs.Result,
    *,
    outlier_at: int,
    outlier: Callable[[np.ndarray], np.ndarray],
    missed: bool = False,
    varied_tau: bool = False,
) -> Iterator[tuple[int, float | np.float64, np.ndarray | None, np.ndarray | None]]:
    """``sim``'s samples from the second on, ``(k, t, q, tau)``, as a live loop may pass them
    (a fused update against its base path, issue 39): ``q`` ``None`` every 29th (dropped), a
    strided view every 3rd, read-only every 7th, ``outlier(q)`` at ``outlier_at``; ``tau``
    ``None`` every 11th (``varied_tau``: strided every 5th, read-only every 13th); ``t`` a
    float on odd ``k``, NumPy's on even; ``missed``: the ticks ``k % 31 == 4`` skipped (the
    next update spans two periods)."""
    wide = np.zeros((sim.t.size, 2 * sim.q_meas.shape[1]))
    wide[:, ::2] = sim.q_meas
    for k in range(1, sim.t.size):
        if missed and k % 31 == 4:
            continue
        q = None if k % 29 == 0 else (wide[k, ::2] if k % 3 == 0 else sim.q_meas[k].copy())
        if q is not None and k == outlier_at:
            q = outlier(q)
        if q is not None and k % 7 == 0:
            q.setflags(write=False)
        tau = None if k % 11 == 0 else sim.tau[k].copy()
        if varied_tau and tau is not None and k % 5 == 0:
            tau = np.repeat(tau, 2)[::2]
        if varied_tau and tau is not None and k % 13 == 0:
            tau.setflags(write=False)
        yield k, (float(sim.t[k]) if k % 2 else sim.t[k]), q, tau
