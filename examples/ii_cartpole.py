# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs", "matplotlib"]
# ///
"""I&I observer (Sarras et al.) on cart-poles: Assumption 1 report, decay rate measured vs predicted.

With the Cholesky factor that eliminates θ first, the columns of T commute,
β = kQ and the momentum error z = P̂ − P obeys ż = −kz: |z| decays at
exactly the rate k.  This script checks Assumption 1, runs the observer from a
perturbed velocity on the project's cart-pole and two variants (PD tracking,
1 kHz, no noise), fits the decay rate of |z|, and plots |z|² against the bound
e^{−εt}|z(0)|² (ε = 2k).

python examples/ii_cartpole.py            # writes examples/out/ii_cartpole.png
python examples/ii_cartpole.py --quick    # shorter runs (CI)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib
import numpy as np
import pinocchio as pin

import pinobs
from pinobs.model import Robot
from pinobs.observers import make_observer
from pinobs.observers.ii import check_assumption1


def cartpole_variant(m_cart: float, m_pole: float, length: float) -> Robot:
    """The project's cart-pole with other masses [kg] and pole length [m] (uniform rod)."""
    model = pinobs.load("cartpole").model.copy()
    model.inertias[1] = pin.Inertia(m_cart, np.zeros(3), np.diag([0.01, 0.02, 0.02]) * m_cart)
    i_rod = m_pole * length**2 / 12.0
    model.inertias[2] = pin.Inertia(
        m_pole, np.array([0.0, 0.0, 0.5 * length]), np.diag([i_rod, i_rod, 1e-4])
    )
    return Robot(model, name=f"cartpole(m_c={m_cart}, m_p={m_pole}, l={length})", source="example")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", default="examples/out", help="folder for the PNG")
    parser.add_argument("--quick", action="store_true", help="short runs (a few seconds)")
    parser.add_argument("--gain", type=float, default=10.0, help="k [1/s]")
    args = parser.parse_args()
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    duration = 0.4 if args.quick else 1.2
    k = args.gain
    robots = [
        pinobs.load("cartpole"),
        cartpole_variant(3.0, 0.8, 0.5),
        cartpole_variant(0.5, 0.3, 2.0),
    ]
    print(check_assumption1(robots[0]).format())
    print()
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    print(
        f"{'robot':<36} {'k':>5} {'fitted rate':>12} {'max |z|/bound - 1':>18} {'invariance':>11}"
    )
    for i, robot in enumerate(robots):
        ob = make_observer("ii", robot, gain=k)
        res = pinobs.simulate(
            robot, {"ii": ob}, duration=duration, inputs="pd", seed=1, perturb_v=1.0
        )
        vh = res.trace("ii").v
        z = np.linalg.norm(
            [ob.momentum(q, a - b) for q, a, b in zip(res.q, vh, res.v, strict=True)], axis=1
        )
        bound = np.exp(-0.5 * ob.options["assumption2_epsilon"] * res.t) * z[0]
        window = z > 1e-4 * z[0]  # above the invariance floor (~1e-10)
        rate = -np.polyfit(res.t[window], np.log(z[window]), 1)[0]
        excess = float(np.max(z[window] / bound[window]) - 1.0)
        on_truth = make_observer("ii", robot, gain=k)
        res0 = pinobs.simulate(robot, {"ii": on_truth}, duration=duration, inputs="pd", seed=1)
        inv = float(np.abs(res0.trace("ii").v - res0.v).max())
        print(f"{robot.name:<36} {k:>5.1f} {rate:>12.8f} {excess:>18.2e} {inv:>11.2e}")
        ax.semilogy(res.t, (z / z[0]) ** 2, color=f"C{i}", label=robot.name)
        ax2.plot(res.t, res.v[:, 1], color=f"C{i}", lw=1)
        ax2.plot(res.t, vh[:, 1], color=f"C{i}", ls="--", lw=1)
    ax.semilogy(res.t, np.exp(-2.0 * k * res.t), "k:", label="bound exp(−εt), ε = 2k")
    ax.set(
        xlabel="t [s]",
        ylabel="|P̂ − P|² / |P̂(0) − P(0)|²",
        title=f"I&I momentum error, k = {k:g} /s",
    )
    ax.legend(fontsize=7)
    ax2.set(xlabel="t [s]", ylabel="θ̇ [rad/s]", title="pole rate: truth (solid), estimate (dashed)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(out / "ii_cartpole.png", dpi=120)
    print(f"\npredicted rate k = {k:g} /s; wrote {out / 'ii_cartpole.png'}")
