"""EXPERIMENT (reverted in the next commit): mean squared one-step prediction error over σ²
from a common position ``q̂_c`` (rows) with each family's velocity (columns) or the truth, on an
exact model; see benchmarks/never_behind_exact.md, "Common-position velocity score".

    python benchmarks/never_behind_orth.py ur5 1000 1e-3 1
"""
import warnings, sys
import numpy as np, pinobs
from pinobs.simulation import Sensor
rname, rate, sig, seed = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
robot = pinobs.load(rname)
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    res = pinobs.simulate(robot, [], duration=3.0, sensor=Sensor(rate, sig), seed=seed)
t, q, tau, vt = res.t[1:], res.q_meas[1:], res.tau[1:], res.v[1:]
est = {}
for fam in ("kf", "ekf", "riemannian"):
    ob = pinobs.make_observer(fam, robot, rate=rate, noise_std=sig)
    ob.reset(t[0], q[0], None, tau[0])
    Q = np.empty_like(q); V = np.empty_like(vt)
    Q[0], V[0] = q[0], 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k in range(1, t.size):
            e = ob.update(t[k], q[k], tau[k]); Q[k], V[k] = e.q, e.v
    est[fam] = (Q, V)
h = np.diff(t)[:, None]
a = np.gradient(vt, t, axis=0)
late = t[:-1] > 1.0
def ms(Qc, Vi):
    e = q[1:] - (Qc[:-1] + h * Vi[:-1] + 0.5 * h * h * a[:-1])
    return np.mean(e[late] ** 2) / sig**2
print(f"{rname} {rate:g} Hz σ={sig:g} seed {seed}: mean e²/σ² (after 1 s); rows: common position q̂_c, columns: velocity")
print("q̂_c \\ v̂ :   kf      ekf     riemannian  truth")
for c in ("kf", "ekf", "riemannian"):
    print(f"{c:10s}", " ".join(f"{ms(est[c][0], est[f][1]):8.4f}" for f in ("kf", "ekf", "riemannian")), f"{ms(est[c][0], vt):8.4f}")
print("velocity RMS:", {f: float(np.sqrt(np.mean((est[f][1]-vt)[1:][late]**2))) for f in est})
