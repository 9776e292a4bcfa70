"""Never-behind observers on the real logs (issue 36, item 2): velocity RMS over the default kf.

The conditions and functions of ``real_logs.py`` (its identified model as ``@id``); labels
are ``family+option+...``: ``nb`` = ``never_behind=True``, ``auto`` =
``disturbance_psd="auto"``, ``d=X`` / ``a=X`` fixed densities, ``p=X`` the blend's ``prior_log_odds``, ``onlyid`` / ``noid`` one model.

    python benchmarks/never_behind_real.py tiago 1 kf,ekf+nb,riemannian+nb,kalman+nb
    python benchmarks/never_behind_real.py ur10e 17 kf,ekf+nb,riemannian+nb,kalman+nb
"""

import json
import math
import re
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import real_data as rd
import real_logs as R

import pinobs

which = sys.argv[1]  # ur10e | tiago
nlogs = int(sys.argv[2]) if len(sys.argv) > 2 else 3
runs = (
    sys.argv[3].split(",")
    if len(sys.argv) > 3
    else ["kf", "ekf+nb", "riemannian+nb", "kalman+nb", "ekf+auto", "ekf+auto+nb"]
)
out = {}


def run(frame, rob, ref, rows, joints, label):
    base, *suf = label.split("+")
    opts = {"never_behind": "nb" in suf}  # (explicit: pinobs.estimate's default is the blend)
    if "auto" in suf:
        opts["disturbance_psd"] = "auto"
    for x in suf:
        if x.startswith("d="):
            opts["disturbance_psd"] = float(x[2:])
        if x.startswith("a="):
            opts["accel_psd"] = float(x[2:])
        if x.startswith("j="):
            opts["jerk_psd"] = float(x[2:])
        if x.startswith("p="):
            opts["prior_log_odds"] = float(x[2:])
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            df = pinobs.estimate(base, frame, robot=rob, options=opts)
        restarts = sum("re-initialised" in str(b[1]) for b in df.attrs["bad_rows"])
        v = df[[f"v{i}" for i in range(rob.nv)]].to_numpy()
        err = (v - ref)[rows][:, joints]
        val = float(R.rms(err.ravel())) if np.isfinite(err).all() else math.inf
    except Exception as e:
        val, restarts = math.nan, -1
        print("  error", label, type(e).__name__, str(e)[:200])
    return val, restarts, time.perf_counter() - t0


def do(name, frame, robot, ident, ref, rows, joints):
    res = {}
    for lab in runs:
        for suffix, rob in (("", robot), ("@id", ident)):
            if lab.startswith("kf") and suffix:
                continue
            if "noid" in lab and suffix:
                continue
            if "onlyid" in lab and not suffix:
                continue
            val, rs, secs = run(frame, rob, ref, rows, joints, lab)
            res[lab + suffix] = (val, rs)
            print(f"  {name} {lab + suffix:22s} {val:.4g}  restarts={rs} ({secs:.0f}s)", flush=True)
    kf = res["kf"][0]
    print(name, " ".join(f"{k}={v[0] / kf:.2f}" for k, v in res.items()), flush=True)
    out[name] = res


if which == "ur10e":
    robot = rd.ur10e_robot()
    ident, secs, _ = R.ur10e_identify(R.UR10E_FIT, robot)
    print(f"identified in {secs:.0f}s", flush=True)
    unloaded = [
        n
        for n in R.ur10e_names("identification_data")
        if n not in R.UR10E_FIT and not re.search(r"(?<!un)load", n, re.IGNORECASE)
    ]
    moving = ["ur-20_01_17-ptp_10_points", *unloaded]
    sel = sys.argv[4].split(",") if len(sys.argv) > 4 else moving[:nlogs]
    for n in sel:
        folder = "validation_data" if n.startswith("ur-20_01_17") else "identification_data"
        log = rd.load_log(f"ur10e/{folder}/{n}")
        t, q, tau = R.arrays(log.frame)
        rows = t >= t[0] + R.SETTLE
        do(n, log.frame, robot, ident.robot, log.velocity, rows, list(range(6)))
else:
    log = rd.tiago_log()
    robot = log.robot
    t_raw, q, tau = R.arrays(log.frame)
    clock = pinobs.io.fit_clock(t_raw, q)
    t = np.asarray(clock.t, float)
    keep = ~np.asarray(clock.stale) & np.isfinite(t)
    t, q, tau, ref = t[keep], q[keep], tau[keep], log.velocity[keep]
    frame = log.frame[keep].copy()
    frame["t"] = t
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # as real_logs.py identifies it (its comment: the wrist bodies seen through arm_1..4's
        # torques alone make the condition 2e6, above identify's default bound)
        ident = pinobs.identify(
            robot,
            (t, q, tau),
            holdout=0.2,
            exclude=list(rd.TIAGO_JOINTS[5:]),
            max_condition=1e8,
        )
    split = ident.report["fit_end"]
    joints = [rd.TIAGO_JOINTS.index(j) for j in R.TIAGO_TORQUE_JOINTS]
    do("tiago", frame, robot, ident.robot, ref, t > split, joints)
print(json.dumps(out))
