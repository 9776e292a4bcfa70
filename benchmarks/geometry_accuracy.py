# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""Accuracy of the model layer's geometry against the independent reference.

For each robot, at 5 seeded random points: the largest relative error
(absolute where the reference's norm is below 1) of
``connection`` against the Koszul formula, of ``curvature`` against finite
differences of that connection (both in ``pinobs.model.reference``), the
first-Bianchi residual, and known closed forms.  Writes a markdown table.

    python benchmarks/geometry_accuracy.py --out benchmarks
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import pinobs
from pinobs.model.reference import fd_curvature, koszul_connection

ROBOTS = (
    "cartpole",
    "planar_3r",
    "ur5",
    "panda",
    "top",
    "rigid_body",
    "double_pendulum_continuous",
    "go1",
)


def rel(a: np.ndarray, b: np.ndarray) -> float:
    """Relative error; absolute where the reference is below 1 (a flat metric's R is ~0)."""
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1.0))


def main(points: int, out: Path) -> str:
    lines = [
        "| robot | nv | connection vs Koszul | curvature vs FD | first-Bianchi residual |",
        "|---|---:|---:|---:|---:|",
    ]
    for name in ROBOTS:
        robot = pinobs.load(name)
        rng = np.random.default_rng(0)
        ec, er, eb = [], [], []
        for _ in range(points):
            q = robot.random_configuration(rng)
            x, y, z = rng.standard_normal((3, robot.nv))
            ec.append(rel(robot.connection(q, x, y), koszul_connection(robot, q, x, y)))
            r = robot.curvature(q, x, y, z)
            er.append(rel(r, fd_curvature(robot, q, x, y, z)))
            b = r + robot.curvature(q, y, z, x) + robot.curvature(q, z, x, y)
            eb.append(float(np.linalg.norm(b) / max(np.linalg.norm(r), 1.0)))
        lines.append(f"| {name} | {robot.nv} | {max(ec):.1e} | {max(er):.1e} | {max(eb):.1e} |")
        print(lines[-1], flush=True)
    top = pinobs.load("cartpole")
    rng = np.random.default_rng(1)
    flat = max(
        float(
            np.linalg.norm(
                top.curvature(
                    top.random_configuration(rng, scale=3.0), *rng.standard_normal((3, 2))
                )
            )
        )
        for _ in range(points)
    )
    lines.append("")
    lines.append(
        f"Closed forms: cart-pole |R(x,y)z| ≤ {flat:.1e} (flat); isotropic body on a spherical joint: see tests."
    )
    text = "\n".join(lines) + "\n"
    out.mkdir(parents=True, exist_ok=True)
    (out / "geometry_accuracy.md").write_text(text)
    return text


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", default=str(Path(__file__).parent))
    parser.add_argument("--quick", action="store_true", help="one point per robot")
    args = parser.parse_args()
    print(main(1 if args.quick else 5, Path(args.out)))
