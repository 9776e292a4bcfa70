# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs", "matplotlib"]
# ///
"""Anisi–Hamberg §5: the intrinsic observer on the unit 3-sphere.

The paper's example: configuration manifold the unit S³ (constant curvature
κ = 1) in hyperspherical coordinates ``x₁, x₂ ∈ [0, π]``, ``x₃ ∈ [0, 2π)``,
external force ``F = −grad W`` with ``W = sin x₁ cos x₂ cos x₃``, gains
``A = 3(1+S)/√(S+1e-7)``, ``B = 3``, ``C = −1`` (their eq. 6; ``A = 2α`` here),
initial data ``x(0) = ξ(0) = (1, 0.7, 2)``, ``ẋ(0) = (2.25, 1.25, 4)``,
``η(0) = 0``.  Their Fig. 4 plots the system (solid) and the observer (dashed).

Realisation (justified in :mod:`pinobs.model.sphere`): S³ is the unit
quaternions, and a rigid body with isotropic inertia ¼ on a Pinocchio
spherical joint has exactly the round metric of the unit S³; the observer runs
on that ``Robot`` unchanged, with no coordinate chart.  Coordinates are used
only to set the initial data and to plot.

The truth is integrated by RKMK4 at the sample rate with the force held
between samples (zero-order hold, MATH §7), so the observer's model is exact;
samples are noise-free, as in the paper.

What it shows (printed and plotted): near ``S = 0`` the injection ``Aζ`` has
norm ``≈ 3√2 ≈ 4.24``, more than the initial velocity error
``|Δv|_g = 3.30``; the estimate ξ is held on x (a sliding regime,
dist ≈ 5e-3 rad, all curves of the top row coincide) while η, the velocity
estimate, decays only at ``≈ B/A``: their Lyapunov function has
``V̇ = −2ABS ≈ −18√S``, which vanishes with S.  Observer velocity in the
second row: the coordinate velocity of η (Z₁ output) and that of the estimated
trajectory ``ξ̇ = η − Aζ``, which equals ``ẋ``.

Run: ``python examples/s3_anisi_hamberg.py [--out DIR] [--quick]``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import matplotlib
import numpy as np

from pinobs.model import lie_rk4
from pinobs.model.sphere import (
    anisi_hamberg_torque,
    body_velocity,
    coordinate_velocity,
    hyperspherical,
    quaternion,
    unit_three_sphere,
)
from pinobs.observers.riemannian import RiemannianObserver, anisi_hamberg_curvature_gain


def gain_a(s: float, speed: float) -> float:
    """Anisi–Hamberg §5: ``A = 3(1+S)/√(S+1e-7)`` [1/s]."""
    return 3.0 * (1.0 + s) / math.sqrt(s + 1e-7)


def run(duration: float, rate: float, curvature: str = "constant") -> dict[str, np.ndarray]:
    """Simulate the §5 example; ``curvature`` is ``"constant"`` (C = −1) or ``"upsilon"`` (C = −2Υ(S))."""
    robot = unit_three_sphere()
    x0, xdot0 = np.array([1.0, 0.7, 2.0]), np.array([2.25, 1.25, 4.0])
    q, v = quaternion(x0), body_velocity(x0, xdot0)
    ob = RiemannianObserver(
        robot,
        gain_a=gain_a,
        beta=3.0,
        curvature_gain=-1.0,
        gain_c=anisi_hamberg_curvature_gain(1.0) if curvature == "upsilon" else None,
        curvature_every=1,
    )
    est = ob.reset(0.0, q, np.zeros(3), anisi_hamberg_torque(q))
    h = 1.0 / rate
    n = round(duration * rate)
    out: dict[str, list[np.ndarray]] = {
        k: [] for k in ("t", "x", "xi", "xd", "etad", "xid", "dist", "dv")
    }
    q_hat_prev = est.q
    for k in range(1, n + 1):
        tau = anisi_hamberg_torque(q)

        def rhs(
            qq: np.ndarray, vv: np.ndarray, tau: np.ndarray = tau
        ) -> tuple[np.ndarray, np.ndarray]:
            return vv, robot.forward_dynamics(qq, vv, tau)

        q, v = lie_rk4(robot, q, v, h, rhs)
        est = ob.update(k * h, q, anisi_hamberg_torque(q))
        out["t"].append(np.array(k * h))
        out["x"].append(hyperspherical(q))
        out["xi"].append(hyperspherical(est.q))
        out["xd"].append(coordinate_velocity(q, v))
        out["etad"].append(coordinate_velocity(est.q, est.v))
        out["xid"].append(coordinate_velocity(est.q, robot.difference(q_hat_prev, est.q) / h))
        out["dist"].append(np.array(math.acos(min(1.0, float(q @ est.q)))))  # S³ arc
        out["dv"].append(np.array(math.sqrt(robot.metric(q, est.v - v, est.v - v))))
        q_hat_prev = est.q
    return {k: np.array(val) for k, val in out.items()}


def plot(res: dict[str, np.ndarray], path: Path) -> None:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 3, figsize=(12, 9), sharex=True)
    t = res["t"]
    for i in range(3):
        ax = axes[0, i]
        ax.plot(t, res["x"][:, i], "k-", lw=1.2, label="system x")
        ax.plot(t, res["xi"][:, i], "r--", lw=1.2, label="observer ξ")
        ax.set_ylabel(f"$x_{i + 1}$ [rad]")
        ax = axes[1, i]
        ax.plot(t, res["xd"][:, i], "k-", lw=1.2, label="system ẋ")
        ax.plot(t, res["etad"][:, i], "r--", lw=1.0, label="observer η (coordinates)")
        ax.plot(t, res["xid"][:, i], "b:", lw=1.0, label="observer ξ̇")
        ax.set_ylabel(f"$\\dot x_{i + 1}$ [rad/s]")
        ax.set_ylim(-20, 20)
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[1, 0].legend(loc="upper right", fontsize=8)
    ax = axes[2, 0]
    ax.semilogy(t, res["dist"], "k-")
    ax.set_ylabel("dist(ξ, x) [rad]")
    ax = axes[2, 1]
    ax.plot(t, res["dv"], "k-")
    ax.set_ylabel("|η − v|_g [rad/s]")
    axes[2, 2].axis("off")
    for ax in axes[2, :2]:
        ax.set_xlabel("t [s]")
    fig.suptitle("Anisi–Hamberg §5 on the unit S³: system (solid) and observer (dashed)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("examples/out"), help="output directory")
    parser.add_argument("--quick", action="store_true", help="1 s instead of 10 s, one run (CI)")
    args = parser.parse_args()
    matplotlib.use("Agg")
    args.out.mkdir(parents=True, exist_ok=True)
    duration = 1.0 if args.quick else 10.0
    res = run(duration, rate=1000.0)
    png = args.out / "s3_anisi_hamberg.png"
    plot(res, png)
    print(f"unit S³, 1 kHz, {duration:g} s, C = -1:")
    print(f"  max dist(ξ, x) = {res['dist'].max():.3e} rad (S³ arc)")
    print(
        f"  |η − v|_g: {res['dv'][0]:.3f} at t = {res['t'][0]:.3f} s -> {res['dv'][-1]:.3f} at {res['t'][-1]:.1f} s"
    )
    print(f"  max |ξ̇ − ẋ| = {np.abs(res['xid'] - res['xd'])[10:].max():.3e} rad/s (after 10 ms)")
    if not args.quick:
        up = run(duration, rate=1000.0, curvature="upsilon")
        print(
            f"  with C = -2Υ(S): max dist {up['dist'].max():.3e}, "
            f"|η − v|_g at end {up['dv'][-1]:.3f}"
        )
    print(f"wrote {png}")
