# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""Why the ±2σ band of the smoother over ``adaptive`` is too wide: a density sweep.

The smoother over ``adaptive`` (``pinobs.smooth(..., observer="adaptive")``)
freezes the learned model per window and uses the regime's two densities:
white acceleration ``accel_psd`` and the torque-offset random walk
``disturbance_psd``.  Here both are scaled apart (``a×``, ``d×``) on the
learning benchmark's model-error logs (``benchmarks/learning.py``: 12 s,
σ = 1e-4, 1 kHz; the learning pass run once per log) and each pair is scored by

- ``ll − max``: the innovation log-likelihood [nats] against the sweep's best
  (the rule ``accel_psd="auto"`` uses, there along the diagonal only);
- ``ρ``: the filter–smoother consistency (no truth; 1 when the densities
  explain the log: :attr:`pinobs.smoothing.Smoother.consistency`);
- ``z² filter``, ``z² smoother``: the mean squared velocity error over the
  claimed variance after 5 s, against the truth (1: calibrated);
- ``cover``: the smoother's ±2σ coverage after 5 s (target 90–98 %), and its RMS.

Uses the smoother's internals (the frozen-model filter) to scale the two
densities apart; ``pinobs.smooth`` exposes only their common scale.

    python benchmarks/smoothing_densities.py --out benchmarks
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

import pinobs
from pinobs.io import Log
from pinobs.simulation.mismatch import mismatched_plant
from pinobs.smoothing import filters, logs, rts

CASES = (("ur5", "inertia20_payload", 1), ("panda", "friction", 1), ("ur5", "torque_scale", 2))
A_SCALES = (1e-3, 1e-2, 1e-1, 1.0, 1e1)
D_SCALES = (1e-2, 1e-1, 1.0, 1e1)


def sweep(name: str, scenario: str, seed: int) -> list[str]:
    from learning import NOISE, record

    robot = pinobs.load(name)
    nv = robot.nv
    truth = "exact" if scenario == "torque_scale" else scenario
    res = record(robot, mismatched_plant(robot, truth, seed=0), duration=12.0, seed=seed)
    tau = 0.9 * res.tau + 0.3 if scenario == "torque_scale" else np.array(res.tau)
    t, q, ta = logs.smoothing_arrays(robot, Log(t=res.t, q=res.q_meas, tau=tau))
    k0, good = logs.first_good(q)
    arrays = (t[k0:], q[k0:], ta[k0:], good)
    make, _ = filters.filter_maker(robot, "adaptive", arrays, NOISE, None, None, None)
    snaps = make(None)._snaps  # the learning pass ran once, in _filter_maker
    v_true, late = res.v[k0:], t[k0:] > 5.0
    rows: list[tuple[float, ...]] = []
    for a in A_SCALES:
        for d in D_SCALES:
            filt: Any = make(None)
            filt._snaps = [
                s._replace(accel_psd=a * s.accel_psd, disturbance_psd=d * s.disturbance_psd)
                for s in snaps
            ]
            steps: list[rts._Step] = []
            ll = 0.0
            for _, pred, Phi, state, lk, _ in rts.forward_pass(filt, rts.log_rows(*arrays), k0):
                ll += lk
                if pred is not None:
                    steps[-1] = steps[-1]._replace(pred=pred, Phi=Phi)
                steps.append(rts._Step(state, None, None))
            n = len(steps)
            v_s, var_s = np.empty((n, nv)), np.empty((n, nv))

            def emit(
                i: int, qs: Any, vs: Any, var: Any, _: Any, v_s: Any = v_s, var_s: Any = var_s
            ) -> None:
                v_s[i], var_s[i] = vs, var[nv : 2 * nv]

            rts._backward(robot, steps, emit)
            v_f = np.array([s.filt.v for s in steps])
            var_f = np.array([np.diag(s.filt.P)[nv : 2 * nv] for s in steps])
            dvar = var_f - var_s
            ok = dvar > 1e-9 * var_f
            rho = float(np.mean(((v_s - v_f) ** 2)[ok] / dvar[ok]))
            z_f = float(np.mean(((v_f - v_true) ** 2 / var_f)[late]))
            z_s = float(np.mean(((v_s - v_true) ** 2 / var_s)[late]))
            err = (v_s - v_true)[late]
            cover = 100 * float(np.mean(np.abs(err) <= 2 * np.sqrt(var_s[late])))
            rows.append((ll, a, d, rho, z_f, z_s, cover, float(np.sqrt(np.mean(err**2)))))
    best = max(r[0] for r in rows)
    return [
        f"| {name} | {scenario} | {seed} | {a:g} | {d:g} | {ll - best:.0f} | {rho:.2f} "
        f"| {z_f:.2f} | {z_s:.2f} | {cover:.1f} % | {e:.2e} |"
        for ll, a, d, rho, z_f, z_s, cover, e in rows
    ]


def main(out: Path) -> str:
    table = [
        "| robot | scenario | seed | a× | d× | ll − max [nats] | ρ | z² filter | z² smoother "
        "| cover ±2σ | RMS [rad/s] |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for case in CASES:
        table += sweep(*case)
    text = "\n".join(table) + "\n"
    out.mkdir(parents=True, exist_ok=True)
    (out / "smoothing_densities.md").write_text(text)
    return text


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks"))
    print(main(parser.parse_args().out))
