"""Every observer's estimates on fixed inputs, to check that a change leaves them bit-identical.

Runs each registered family (UR5, ``ii`` with ``unguaranteed=True``, ``liegroup`` on the
top, ``adaptive`` both ways with its background jobs waited for, ``ekf`` with
``never_behind``) over a simulated 1 kHz log, and ``InvariantEKF`` on go1 over a synthetic
IMU and contact stream, and saves every ``(q, v)`` estimate::

    git checkout A && python benchmarks/observer_outputs.py a.npz
    git checkout B && python benchmarks/observer_outputs.py b.npz
    python benchmarks/observer_outputs.py --compare a.npz b.npz   # exit 1 if any differs
"""

from __future__ import annotations

import sys

import numpy as np

import pinobs
from pinobs.observers import adaptive_learner


def record(path: str) -> None:
    """Every observer on fixed inputs; their estimates saved to ``path`` (``.npz``)."""
    out: dict[str, np.ndarray] = {}
    CASES = [
        ("ur5", n, {}, 1.5)
        for n in ("adaptive", "ekf", "fd", "highgain", "kalman", "kf", "riemannian", "sliding")
    ]
    CASES += [
        ("ur5", "adaptive", {"learning": "background"}, 1.5),
        ("ur5", "ii", {"unguaranteed": True}, 0.3),
        ("top", "liegroup", {}, 1.0),
        ("ur5", "ekf", {"never_behind": True}, 1.0),
    ]
    sims = {}
    for robot_name, name, opts, dur in CASES:
        robot = pinobs.load(robot_name)
        key = (robot_name, dur)
        if key not in sims:
            sims[key] = pinobs.simulate(
                robot, [], duration=dur, sensor=pinobs.Sensor(rate=1000.0, noise_std=1e-4), seed=3
            )
        sim = sims[key]
        if opts.get("learning") == "background":
            adaptive_learner.Learner.join = True  # every job waited for: deterministic
        o = pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4, **opts)
        o.reset(sim.t[0], sim.q[0], None, sim.tau[0])
        qs, vs = [], []
        for k in range(1, sim.t.size):
            e = o.update(sim.t[k], sim.q[k], sim.tau[k])
            qs.append(e.q.copy())
            vs.append(e.v.copy())
        adaptive_learner.Learner.join = False
        label = f"{robot_name}-{name}-{'-'.join(f'{k}={v}' for k, v in opts.items())}"
        out[label + "-q"], out[label + "-v"] = np.array(qs), np.array(vs)
        print(label, "scipy.signal" in sys.modules, flush=True)
    # inekf on go1, synthetic IMU, contacts toggling
    from pinobs.observers.inekf import InvariantEKF

    robot = pinobs.load("go1")
    o = InvariantEKF(robot, ("FL_foot", "FR_foot", "RL_foot", "RR_foot"))
    q = robot.neutral()
    q[2] = 0.3
    rng = np.random.default_rng(0)
    gyro, acc = np.array([0.01, -0.02, 0.03]), np.array([0.1, 0.0, 9.81])
    o.reset(0.0, q, gyro=gyro, acc=acc, contacts=[True] * 4)
    qs, vs = [], []
    for k in range(1, 1000):
        qk = q.copy()
        qk[7:] += 1e-3 * rng.standard_normal(12)
        e = o.update(
            k * 2e-3,
            qk,
            gyro + 1e-3 * rng.standard_normal(3),
            acc + 1e-2 * rng.standard_normal(3),
            [True, k % 100 < 50, True, k % 80 < 40],
        )
        qs.append(e.q.copy())
        vs.append(e.v.copy())
    out["go1-inekf-q"], out["go1-inekf-v"] = np.array(qs), np.array(vs)
    np.savez(path, **out)
    print("saved", len(out))


def compare(a_path: str, b_path: str) -> int:
    """Print each array identical or not; the number that differ."""
    a, b = np.load(a_path), np.load(b_path)
    if sorted(a.files) != sorted(b.files):
        print(f"different runs: {sorted(set(a.files) ^ set(b.files))}")
        return 1
    bad = 0
    for k in sorted(a.files):
        same = a[k].shape == b[k].shape and np.array_equal(a[k], b[k], equal_nan=True)
        bad += not same
        diff = "" if same else f"DIFFERENT (max {np.nanmax(np.abs(a[k] - b[k])):g})"
        print(f"{k:45s} {diff or 'identical'}")
    print("all bit-identical" if not bad else f"{bad} differ")
    return bad


if __name__ == "__main__":
    if sys.argv[1] == "--compare":
        sys.exit(1 if compare(sys.argv[2], sys.argv[3]) else 0)
    record(sys.argv[1])
