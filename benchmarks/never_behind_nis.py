"""EXPERIMENT (reverted in the next commit): the model-based observer's windowed NIS / m and
its learned disturbance density inside the blend (``PINOBS_NBDIAG``), on exact models
(``exact``) or on UR10e logs (``real LOG,LOG``); see benchmarks/never_behind_exact.md,
"Common-position velocity score".

    python benchmarks/never_behind_nis.py exact
    python benchmarks/never_behind_nis.py real ur-20_02_19_14harm50sec,ur-19_09_27-11_28_22
"""
import os, sys, warnings
os.environ["PINOBS_NBDIAG"] = "1"
from pathlib import Path
sys.path.insert(0, "benchmarks")
import numpy as np
import pinobs
import pinobs.observers.neverbehind as nb
from pinobs.simulation import Sensor
from scipy.stats import chi2

def summarize(label, nv, skip_t=1.0, T=0.2):
    d = nb._DIAG[:]
    nb._DIAG.clear()
    dt = np.array([x[0] for x in d]); nis = np.array([x[1] for x in d]); dp = np.array([x[2] for x in d])
    t = np.cumsum(dt)
    m = np.empty_like(nis); acc = float(nv)
    for k in range(nis.size):
        lam = min(1.0, dt[k] / T)
        if np.isfinite(nis[k]):
            acc += lam * (nis[k] - acc)
        m[k] = acc / nv
    late = t > skip_t
    lam = np.median(dt) / T
    nu = nv * (2 - lam) / lam
    hi = chi2.ppf(0.995, nu) / nu; lo = chi2.ppf(0.005, nu) / nu
    r = m[late]
    p = np.percentile(r, [5, 50, 95, 100])
    out = f"{label:45s} NIS/m EW p5 {p[0]:.3g} p50 {p[1]:.3g} p95 {p[2]:.3g} max {p[3]:.3g} | bounds {lo:.2f}-{hi:.2f} frac>hi {np.mean(r>hi):.3f} frac<lo {np.mean(r<lo):.3f}"
    if np.isfinite(dp).any():
        q = np.nanpercentile(dp[late], [50, 95, 100])
        out += f" | psd/M2 p50 {q[0]:.3g} p95 {q[1]:.3g} max {q[2]:.3g}"
    out += f" lost {sum(x[3] for x in d)}"
    print(out, flush=True)

if sys.argv[1] == "exact":
    for rname, rate, sig, seed in [("ur5", 1000, 1e-3, 5), ("ur5", 100, 1e-4, 1), ("panda", 100, 1e-4, 7), ("panda", 1000, 1e-3, 6), ("ur5", 1000, 1e-4, 0)]:
        robot = pinobs.load(rname)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = pinobs.simulate(robot, [], duration=3.0, sensor=Sensor(rate, sig), seed=seed)
        t, q, tau = res.t[1:], res.q_meas[1:], res.tau[1:]
        for fam, opts in [("ekf", {}), ("ekf", {"disturbance_psd": "auto"}), ("riemannian", {}), ("kalman", {})]:
            ob = pinobs.make_observer(fam, robot, rate=rate, noise_std=sig, never_behind=True, **opts)
            ob.reset(t[0], q[0], None, tau[0]); nb._DIAG.clear()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                for k in range(1, t.size):
                    ob.update(t[k], q[k], tau[k])
            summarize(f"{rname} {rate} {sig} s{seed} {fam}{'+auto' if opts else ''}", robot.nv)
else:
    import real_data as rd, real_logs as R
    robot = rd.ur10e_robot()
    ident, secs, _ = R.ur10e_identify(R.UR10E_FIT, robot)
    for n in sys.argv[2].split(","):
        folder = "validation_data" if n.startswith("ur-20_01_17") else "identification_data"
        log = rd.load_log(f"ur10e/{folder}/{n}")
        for fam, opts in [("ekf", {}), ("ekf", {"disturbance_psd": "auto"}), ("riemannian", {}), ("kalman", {})]:
            for suf, rob in (("", robot), ("@id", ident.robot)):
                nb._DIAG.clear()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    pinobs.estimate(fam, log.frame, robot=rob, options={"never_behind": True, **opts})
                summarize(f"{n} {fam}{'+auto' if opts else ''}{suf}", 6)
