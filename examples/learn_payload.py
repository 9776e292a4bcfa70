# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs", "matplotlib"]
# ///
"""Learn a robot whose truth differs from its URDF: offline identification and the adaptive observer.

The truth is a UR5 whose links are 20 % heavier or lighter than the URDF
says, carrying an unknown payload (``pinobs.simulation.mismatch``,
``inertia20_payload``).  Three ways to estimate its velocities from noisy
positions (σ = 1e-4 rad, 1 kHz) and the commanded torques:

1. trust the URDF: ``ekf`` and ``riemannian`` on the nominal model;
2. identify first: ``pinobs.identify`` on a 15 s log (a fit on Savitzky–Golay
   velocities, then two on the RTS smoother's velocities over the model just
   fitted), save the calibrated URDF, run ``ekf`` and ``riemannian`` with
   their default options on it over a *different* trajectory;
3. learn online: ``adaptive`` from the nominal URDF.

``kf*`` is the per-joint Kalman filter with its jerk density tuned on the
validation run itself (the best a model-free filter can do).  Prints a table
(RMS velocity error after 5 s) and writes ``learn_payload.png``: the error
of each estimate over time, and the error of the adaptive observer's learned
M(q) and g(q) (at a configuration of the run) converging from the URDF's
level (single parameters such as the last link's mass are not identifiable
from this motion: the payload shows up in combinations).

Run:  python examples/learn_payload.py [--out DIR] [--quick]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import pinobs
from pinobs.observers import make_observer
from pinobs.simulation import Sensor
from pinobs.simulation.mismatch import mismatched_plant


def run(observer, res) -> np.ndarray:
    """The observer's velocities over a recorded run."""
    observer.reset(0.0, res.q[0], res.v[0], res.tau[0])
    out = [res.v[0]]
    for k in range(1, len(res.t)):
        qm = res.q_meas[k]
        out.append(observer.update(res.t[k], None if np.isnan(qm).any() else qm, res.tau[k]).v)
    return np.array(out)


def model_errors(model: pinobs.Robot, truth: pinobs.Robot, q: np.ndarray) -> tuple[float, float]:
    """Relative errors of M(q) and g(q) at a configuration of the run (single parameters
    such as one link's mass are often not identifiable; these combinations are)."""
    m_t, g_t = truth.mass_matrix(q), truth.gravity(q)
    m_err = np.linalg.norm(model.mass_matrix(q) - m_t) / np.linalg.norm(m_t)
    g_err = np.linalg.norm(model.gravity(q) - g_t) / np.linalg.norm(g_t)
    return float(m_err), float(g_err)


def run_adaptive(adaptive, val, truth: pinobs.Robot, q_ref: np.ndarray, masses: list) -> np.ndarray:
    """``adaptive``'s velocities over ``val``; every 100 samples, the errors of the model it
    has learned appended to ``masses`` as ``(t, M error, g error)``."""
    adaptive.reset(0.0, val.q[0], val.v[0], val.tau[0])
    v = [val.v[0]]
    for k in range(1, len(val.t)):
        v.append(adaptive.update(val.t[k], val.q_meas[k], val.tau[k]).v)
        if k % 100 == 0:  # what the learned model predicts, against the truth
            learned = adaptive.learned_robot()
            masses.append((val.t[k], *model_errors(learned, truth, q_ref)))
    return np.array(v)


def plot(png: Path, estimates: dict, val, masses: list, levels: dict) -> None:
    """The estimates' errors over time, and the adaptive observer's model errors against the
    URDF's and the identified model's (``levels``: name -> (M error, g error))."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for name, v in estimates.items():
        err = np.linalg.norm(v - val.v, axis=1)
        ax1.semilogy(val.t[1:], np.maximum(err[1:], 1e-7), lw=0.8, label=name)
    ax1.set_ylabel("|v̂ − v| [rad/s]")
    ax1.legend(fontsize=7, ncol=2)
    ax1.set_title("UR5 with ±20 % link inertias and an unknown payload")
    t_m, m_err, g_err = np.array(masses).T
    ax2.semilogy(t_m, m_err, color="C0", label="adaptive's model: M(q) error")
    ax2.semilogy(t_m, g_err, color="C1", label="adaptive's model: g(q) error")
    for (name, (m, g)), ls in zip(levels.items(), (":", "--"), strict=True):
        ax2.axhline(m, color="C0", ls=ls, label=f"{name}: M {m:.2g}")
        ax2.axhline(g, color="C1", ls=ls, label=f"{name}: g {g:.2g}")
    ax2.set_xlabel("t [s]")
    ax2.set_ylabel("relative error at a configuration of the run")
    ax2.set_title(
        "The learned dynamics converge (one link's mass alone is not identifiable)", fontsize=9
    )
    ax2.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    fig.savefig(png, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=".", help="folder for learn_payload.png and calibrated.urdf")
    ap.add_argument("--quick", action="store_true", help="short runs (CI)")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    id_duration, duration, t0 = (6.0, 4.0, 2.0) if args.quick else (15.0, 12.0, 5.0)
    sensor = Sensor(rate=1000.0, noise_std=1e-4)
    robot = pinobs.load("ur5")
    truth = mismatched_plant(robot, "inertia20_payload", seed=0)

    log = pinobs.simulate(robot, [], duration=id_duration, sensor=sensor, seed=3, plant=truth)
    ident = pinobs.identify(robot, log)
    path = ident.save(str(out / "calibrated.urdf"))
    print(
        f"identified from {id_duration:g} s: condition number {ident.report['condition']:.3g}, "
        f"held-out residual {np.mean(ident.report['holdout_before']):.3g} -> "
        f"{np.mean(ident.report['holdout_after']):.3g}; wrote {path}"
    )
    calibrated = ident.robot

    val = pinobs.simulate(robot, [], duration=duration, sensor=sensor, seed=7, plant=truth)
    hints = {"rate": 1000.0, "noise_std": 1e-4}
    adaptive = make_observer("adaptive", robot, **hints)
    q_ref = val.q[len(val.t) // 2]
    masses: list = []
    estimates = {
        "ekf (URDF)": run(make_observer("ekf", robot, **hints), val),
        "riemannian (URDF)": run(make_observer("riemannian", robot, **hints), val),
        "ekf (identified)": run(make_observer("ekf", calibrated, **hints), val),
        "riemannian (identified)": run(make_observer("riemannian", calibrated, **hints), val),
        "adaptive (learns online)": run_adaptive(adaptive, val, truth, q_ref, masses),
    }
    kfs = {
        j: run(make_observer("kf", robot, jerk_psd=j, **hints), val) for j in (1e1, 1e2, 1e3, 1e4)
    }
    k0 = int(t0 * 1000)
    rms = {n: float(np.sqrt(np.mean((v[k0:] - val.v[k0:]) ** 2))) for n, v in kfs.items()}
    best = min(rms, key=rms.__getitem__)
    estimates[f"kf* (jerk {best:g}, tuned on this run)"] = kfs[best]

    print(f"\nRMS velocity error after {t0:g} s [rad/s] (UR5, links ±20 % and a payload)")
    ref = rms[best]
    for name, v in estimates.items():
        e = float(np.sqrt(np.mean((v[k0:] - val.v[k0:]) ** 2)))
        print(f"  {name:32s} {e:10.3g}   {e / ref:8.3g} x kf*")

    levels = {
        "URDF": model_errors(robot, truth, q_ref),
        "identified offline": model_errors(calibrated, truth, q_ref),
    }
    png = out / "learn_payload.png"
    plot(png, estimates, val, masses, levels)
    print(f"wrote {png}")


if __name__ == "__main__":
    main()
