# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs[io]", "scipy"]
# ///
"""``riemannian`` on an identified model with the model's own error density, on a subset of
``real_logs.py``'s velocity runs (issue 36): a few minutes instead of ``real_logs.py``'s 20.

**Setting** (``real_logs.py``'s, its functions): the UR10e model ``pinobs.identify`` fits on
:data:`real_logs.UR10E_FIT`, run on the held-out logs :data:`LOGS` (reference: the robot's
own ``dq``, rows from :data:`real_logs.SETTLE` s on, all joints); TIAGo identified on its
first 80 % (held-out rows, torso and arm_1..4, as ``real_logs.tiago``).  Every observer by
``pinobs.estimate`` alone (``never_behind=False``), σ estimated from the log.  Columns:

* *kf*: the default ``kf`` (the denominator of ``real_logs.md``'s ratios);
* *ekf+id*: ``ekf`` at its default density, the robot's own ``model_error_psd`` ψ;
* *riem+id 1e-8*: ``riemannian`` at ``accel_psd=1e-8`` (its default before it took ψ);
* *riem+id*: ``riemannian`` at its default, ψ (Riccati schedule: the Kalman gains);
* *riem+id steady*: the same with ``gain_schedule="steady"`` (the constant gains: clipped to
  the paper form's reach where ψ's Kalman gain is out of it, ``gain_rule``).

    python benchmarks/real_riemannian.py                 # prints; writes real_riemannian.json
    python benchmarks/real_riemannian.py --logs 1        # one UR10e log and TIAGo
    python benchmarks/real_riemannian.py --logs 0        # TIAGo alone
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import real_data as rd
import real_logs as rl

import pinobs

#: Held-out UR10e logs: (folder, name) — ``real_ekf_phases.py``'s.
LOGS = (
    ("validation_data", "ur-20_01_17-ptp_10_points"),
    ("identification_data", "ur-20_02_05-20sec_12harm"),
    ("identification_data", "ur-20_02_10-30sec_12harm"),
)
#: label -> (observer, on the identified robot, options).
RUNS: dict[str, tuple[str, bool, dict[str, Any]]] = {
    "kf": ("kf", False, {}),
    "ekf+id": ("ekf", True, {"never_behind": False}),
    "riem+id 1e-8": ("riemannian", True, {"never_behind": False, "accel_psd": 1e-8}),
    "riem+id": ("riemannian", True, {"never_behind": False}),
    "riem+id steady": ("riemannian", True, {"never_behind": False, "gain_schedule": "steady"}),
}


def velocity(frame, robot, ident, ref, rows, joints) -> dict[str, Any]:
    """Per run of :data:`RUNS`: RMS [rad/s] against ``ref`` over ``rows`` and ``joints``, the
    observer's options as ``pinobs.estimate`` reported them, and the seconds it took."""
    out: dict[str, Any] = {}
    for label, (name, on_ident, options) in RUNS.items():
        rob = ident if on_ident else robot
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            df = pinobs.estimate(name, frame, robot=rob, options=options)
        v = df[[f"v{i}" for i in range(rob.nv)]].to_numpy()
        err = (v - ref)[rows][:, joints]
        out[label] = {
            "rms": float(rl.rms(err.ravel())) if np.isfinite(err).all() else math.inf,
            "seconds": time.perf_counter() - t0,
            "noise_std": df.attrs.get("noise_std"),
            "warnings": sorted({str(w.message)[:200] for w in caught}),
        }
    return out


def ur10e(n_logs: int) -> dict[str, Any]:
    if n_logs == 0:
        return {"model_error_psd": math.nan, "logs": {}}
    robot = rd.ur10e_robot()
    ident = rl.ur10e_identify(rl.UR10E_FIT, robot)[0].robot
    res: dict[str, Any] = {"model_error_psd": ident.model_error_psd, "logs": {}}
    for folder, name in LOGS[:n_logs]:
        log = rd.load_log(f"ur10e/{folder}/{name}")
        t = rl.arrays(log.frame)[0]
        rows = t >= t[0] + rl.SETTLE
        res["logs"][name] = velocity(log.frame, robot, ident, log.velocity, rows, list(range(6)))
        print(f"  ur10e {name}: {table_row(name, res['logs'][name])}", flush=True)
    return res


def tiago() -> dict[str, Any]:
    log, _, keep, t, q, tau = rl.tiago_rows()
    robot = log.robot
    frame = log.frame[keep].copy()
    frame["t"] = t
    common = {"holdout": 0.2, "exclude": list(rd.TIAGO_JOINTS[5:]), "max_condition": 1e8}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fitted = pinobs.identify(robot, (t, q, tau), **common)
    split = rl.checked_split(fitted, t)
    joints = [rd.TIAGO_JOINTS.index(j) for j in rl.TIAGO_TORQUE_JOINTS]
    vel = velocity(frame, robot, fitted.robot, log.velocity[keep], t > split, joints)
    print(f"  tiago: {table_row('tiago', vel)}", flush=True)
    return {"model_error_psd": fitted.robot.model_error_psd, "logs": {"tiago": vel}}


def table_row(name: str, r: dict[str, Any]) -> str:
    kf = r["kf"]["rms"]
    cells = [f"{r[k]['rms']:.4g} ({r[k]['rms'] / kf:.2f})" for k in RUNS]
    return f"| {name} | " + " | ".join(cells) + " |"


def markdown(res: dict[str, Any]) -> str:
    lines = [
        f"real_riemannian.py, {res['date']}, {res['seconds']:.0f} s; ψ: UR10e "
        f"{res['ur10e']['model_error_psd']:.3g}, TIAGo {res['tiago']['model_error_psd']:.3g} "
        "rad²/s³.  Velocity RMS [rad/s] (÷ kf).",
        "",
        "| log | " + " | ".join(RUNS) + " |",
        "|---|" + "---|" * len(RUNS),
    ]
    for part in ("ur10e", "tiago"):
        lines += [table_row(n, r) for n, r in res[part]["logs"].items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--logs", type=int, default=len(LOGS), help="how many UR10e logs of LOGS")
    p.add_argument("--out", default=str(Path(__file__).with_suffix(".json")))
    a = p.parse_args(argv)
    if rd.data_root() is None:
        print(f"no data: set {rd.ENV} or put the shared data at ../shared/data; skipped")
        return 0
    t0 = time.perf_counter()
    res: dict[str, Any] = {"date": time.strftime("%Y-%m-%d", time.gmtime())}
    res["pinobs"] = pinobs.__version__
    res["ur10e"] = ur10e(a.logs)
    res["tiago"] = tiago()
    res["seconds"] = time.perf_counter() - t0
    Path(a.out).write_text(json.dumps(res, indent=1, default=float))
    print(markdown(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
