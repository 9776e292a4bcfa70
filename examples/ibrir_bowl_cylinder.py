# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs", "matplotlib"]
# ///
"""Ibrir §4 again: a cylinder rolling in a bowl on a spring, Figs. 2 and 3.

The paper gives the equations of motion (its Σ and eqs. 16–17) but not the
parameters.  Its equations are those of the metric and potential

    M(θ) = [[M_eq, λ sin θ], [λ sin θ, J_eq]],   V = ½ k x² − λ g cos θ,   τ = (u, 0)

(checked: M⁻¹(u − C(q, q̇) q̇ − ∂V/∂q) with the Christoffel ``C`` reproduces
both printed accelerations and eqs. 16–17 term by term), built here as an
analytic model (:class:`pinobs.model.AnalyticMetric`).  Parameters chosen:
bowl 1.5 kg, solid cylinder m = 0.5 kg of radius 0.1 m rolling at ρ = 0.5 m
from the bowl's centre, so M_eq = 2.0 kg, λ = m ρ = 0.25 kg·m,
J_eq = (m + I/r²) ρ² = 1.5 m ρ² = 0.1875 kg·m², spring k = 10 N/m,
g = 9.81 m/s².  Paper's settings: x₀ = (0, 0.4, 0, 0),
x̂₀ = (15, 20, −10, −2), u = 2 sin t, R = I (continuous-time weight).
Choices of ours: P(0) = 100 I (the size of the initial error; with P(0) = I
the printed observer is still 0.27 off after 20 s), the differentiator of Theorem 3.1 of order 2
with γ = 50 /s started at ``(ŷ, ŷ̇) = x̂₀``, positions sampled at 1 kHz
without noise (standing in for continuous time: 250 Hz gives the same
errors to two digits), 20 s.  The printed form has no process noise, so
its gain fades while the differentiator's lag on ẏ (order 2, γ = 50)
still enters F: its error settles near 1e-2, not zero.  The practical form
(process noise, ẏ = v̂, R from the encoder) converges within a few samples.

Run:  python examples/ibrir_bowl_cylinder.py [--out DIR] [--quick]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from pinobs.model import lie_rk4
from pinobs.model.paper_systems import BOWL, bowl_and_cylinder
from pinobs.observers import make_observer

M_EQ, LAM, J_EQ, K_SPRING, G = (BOWL[n] for n in ("M_eq", "lam", "J_eq", "k", "g"))
X0 = np.array([0.0, 0.4, 0.0, 0.0])
XHAT0 = np.array([15.0, 20.0, -10.0, -2.0])


def paper_accelerations(q: np.ndarray, v: np.ndarray, u: float) -> np.ndarray:
    """Ibrir's printed (q̈₁, q̈₂) of §4, for checking the model."""
    s, c = math.sin(q[1]), math.cos(q[1])
    d = M_EQ * J_EQ - (LAM * s) ** 2
    a1 = (-J_EQ * (K_SPRING * q[0] + LAM * v[1] ** 2 * c) + LAM**2 * G * s**2 + J_EQ * u) / d
    a2 = (LAM * s * (K_SPRING * q[0] + LAM * v[1] ** 2 * c) - M_EQ * LAM * G * s - LAM * s * u) / d
    return np.array([a1, a2])


def run(duration: float, rate: float) -> dict[str, np.ndarray]:
    """Simulate the plant and the observers; return time, truth and estimates."""
    robot = bowl_and_cylinder()
    h = 1.0 / rate
    observers = {
        "paper": make_observer(
            "kalman",
            robot,
            form="paper",
            output_weight=1.0,
            q0_std=10.0,
            v0_std=10.0,
            diff_order=2,
            diff_gamma=50.0,
            rate=rate,
        ),
        "practical": make_observer("kalman", robot, q0_std=10.0, v0_std=10.0, rate=rate),
        "highgain": make_observer("highgain", robot, rate=rate),
    }
    n = round(duration * rate) + 1
    t = np.arange(n) * h
    q, v = X0[:2].copy(), X0[2:].copy()
    out = {"t": t, "v": np.empty((n, 2))}
    for k in observers:
        out[k] = np.empty((n, 2))
    for i in range(n):
        if i > 0:
            tau_prev = np.array([2.0 * math.sin(t[i - 1]), 0.0])
            q, v = lie_rk4(
                robot, q, v, h, lambda qq, vv, tp=tau_prev: (vv, robot.forward_dynamics(qq, vv, tp))
            )
        tau = np.array([2.0 * math.sin(t[i]), 0.0])
        out["v"][i] = v
        for name, ob in observers.items():
            est = ob.reset(0.0, XHAT0[:2], XHAT0[2:], tau) if i == 0 else ob.update(t[i], q, tau)
            out[name][i] = est.v
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("examples/out"))
    parser.add_argument("--quick", action="store_true", help="5 s at 250 Hz (CI)")
    args = parser.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    robot = bowl_and_cylinder()
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(20):
        qq, vv, u = rng.normal(0, 1, 2), rng.normal(0, 1, 2), rng.normal()
        a = robot.forward_dynamics(qq, vv, np.array([u, 0.0]))
        worst = max(worst, float(np.abs(a - paper_accelerations(qq, vv, u)).max()))
    print(f"model vs Ibrir's printed accelerations: max difference {worst:.1e}")

    duration, rate = (5.0, 250.0) if args.quick else (20.0, 1000.0)
    res = run(duration, rate)
    args.out.mkdir(parents=True, exist_ok=True)
    t = res["t"]
    labels = {
        "paper": "Thm 3.1 as printed (no process noise)",
        "practical": "practical form (process noise)",
        "highgain": "highgain differentiator (Thm 2.1)",
    }
    for j, (fig_no, what, unit) in enumerate(
        [(2, "velocity of the bowl", "m/s"), (3, "angular velocity of the cylinder", "rad/s")]
    ):
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.plot(t, res["v"][:, j], "k", lw=1.5, label="exact")
        ax.plot(t, res["paper"][:, j], "r--", lw=1.2, label=labels["paper"])
        ax.plot(t, res["practical"][:, j], "b:", lw=1.2, label=labels["practical"])
        lo, hi = res["v"][:, j].min(), res["v"][:, j].max()
        pad = 0.5 * (hi - lo) + 0.1
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_xlabel("t [s]")
        ax.set_ylabel(f"[{unit}]")
        ax.set_title(f"Ibrir Fig. {fig_no}: the exact {what} and its estimate")
        ax.legend(loc="upper right", fontsize=8)
        fig.tight_layout()
        path = args.out / f"ibrir_fig{fig_no}.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        print(f"wrote {path}")
    for name in ("paper", "practical", "highgain"):
        err = np.abs(res[name] - res["v"])
        late = t >= t[-1] - 1.0
        print(
            f"{name:9s}: |v̂ − v| at t = 0: {err[0].max():.2f}, "
            f"max over the last second: {err[late].max():.2e} (bowl m/s, cylinder rad/s)"
        )


if __name__ == "__main__":
    main()
