"""The never-behind blend at the samples the kf's outlier gate rejects, on one real UR10e log.

``ekf`` with ``disturbance_psd="auto"``, blended (``never_behind=True``), on the model
``real_logs.py`` identifies (its two 12-harmonic logs), against ``kf`` and the robot's own
velocity after ``real_logs.SETTLE``: per-joint velocity RMS, the samples with the largest
excess squared error over the ``kf``, and at each sample the ``kf`` rejects (and the next)
the blend's weights, both observers' velocities, the scores ``s_m, s_kf`` and the far gate's
two sides ``h |v̂_m − v̂_kf|`` and ``10 √(s_kf / c)``.  At the sample after a rejection the
``kf``'s one-step error is computed as a scored sample would have it (its prediction from
its state before, two steps after its last correction) and the score ``s_kf`` it would give
(``s_kf if scored``): the module docstring's **Gated** (``pinobs.observers.neverbehind``).

    PINOBS_SHARED_DATA=../shared/data python benchmarks/never_behind_gated.py ur-19_10_01-13_51_41
"""

import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import real_data as rd
import real_logs as R

import pinobs
from pinobs.observers import neverbehind as nb

name = sys.argv[1] if len(sys.argv) > 1 else "ur-19_10_01-13_51_41"
robot = rd.ur10e_robot()
ident = R.ur10e_identify(R.UR10E_FIT, robot)[0].robot
folder = "validation_data" if name.startswith("ur-20_01_17") else "identification_data"
log = rd.load_log(f"ur10e/{folder}/{name}")
t, q, _ = R.arrays(log.frame)
rows = t >= t[0] + R.SETTLE
trace: list[dict] = []
step = nb.NeverBehind.step


def recorded(self, state, dt, q_meas, tau):  # the blend's step, its state kept
    new = step(self, state, dt, q_meas, tau)
    vk0 = self.reference.output(state.kf)
    ahead = 0.0 if state.dt_prev <= 0 else 0.5 * dt * dt / state.dt_prev
    e_kf = (
        None
        if q_meas is None
        else q_meas - (vk0[0] + dt * vk0[1] + ahead * (state.v - state.v_prev))
    )
    trace.append(
        dict(dt=dt, q=q_meas, e_kf=e_kf, old=state, new=new,
             gated=self.reference.innovation(new.kf)[1],
             v_m=self.model.output(new.model)[1], v_kf=self.reference.output(new.kf)[1])
    )  # fmt: skip
    return new


nb.NeverBehind.step = recorded  # type: ignore[method-assign]
v = {}
for label, rob, opts in (
    ("kf", robot, {}),
    ("ekf+auto+nb+id", ident, {"never_behind": True, "disturbance_psd": "auto"}),
):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        df = pinobs.estimate(label.split("+")[0], log.frame, robot=rob, options=opts)
    v[label] = df[[f"v{i}" for i in range(6)]].to_numpy()
nb.NeverBehind.step = step  # type: ignore[method-assign]
ref = log.velocity
err = {k: (x - ref)[rows] for k, x in v.items()}
kf_rms = float(R.rms(err["kf"].ravel()))
print(f"{name}: kf {kf_rms:.4g} rad/s; per joint", np.round(R.rms(err["kf"]), 5))
blend = err["ekf+auto+nb+id"]
print(f"  blend {R.rms(blend.ravel()) / kf_rms:.3f}x kf; per joint", np.round(R.rms(blend), 5))
print(f"  re-seeds {trace[-1]['new'].reseeds}, kf rejections {sum(x['gated'] for x in trace)}")
excess = (v["ekf+auto+nb+id"] - ref) ** 2 - (v["kf"] - ref) ** 2
excess[~rows] = 0.0
total = excess.sum()
for k, j in zip(*np.unravel_index(np.argsort(-excess, axis=None)[:3], excess.shape), strict=True):
    print(
        f"  excess at t = {t[k] - t[0]:.3f} s joint {j}: {excess[k, j]:.3g} of {total:.3g} rad²/s²"
    )
offset = len(t) - len(trace)  # (the first row resets the observer: no step)
lam = np.minimum(1.0, np.array([x["dt"] for x in trace]) / 0.2)
for i, x in enumerate(trace):
    if not (x["gated"] or (i > 0 and trace[i - 1]["gated"])):
        continue
    k = i + offset
    new, dt = x["new"], x["dt"]
    far = dt * np.abs(x["v_m"] - x["v_kf"])
    reach = nb.FAR_GATE * np.sqrt(new.s[1] / max(new.c, 1e-300))
    j = int(np.argmax(far / reach))
    line = (
        f"  t = {t[k] - t[0]:.3f} s {'rejected' if x['gated'] else 'next    '} joint {j}: "
        f"w {np.array2string(x['old'].w, precision=2)} -> {np.array2string(new.w, precision=2)} "
        f"v_m {x['v_m'][j]:+.4f} v_kf {x['v_kf'][j]:+.4f} ref {ref[k, j]:+.4f}; "
        f"s_m {new.s[0, j]:.3g} s_kf {new.s[1, j]:.3g}; far {far[j]:.3g} vs {reach[j]:.3g}"
    )
    if not x["gated"] and x["e_kf"] is not None:
        s_if = x["old"].s[1, j] + lam[i] * (x["e_kf"][j] ** 2 - x["old"].s[1, j])
        line += f"; kf error {abs(x['e_kf'][j]):.3g} (s_kf if scored {s_if:.3g})"
    print(line)
