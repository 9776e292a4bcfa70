# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs"]
# ///
"""Write the tiny example log `examples/ur5_log.csv` (0.2 s of a UR5 at 1 kHz, σ = 1e-4 rad).

python examples/make_example_log.py            # rewrites examples/ur5_log.csv
pinobs estimate --robot ur5 --observer kf --log examples/ur5_log.csv --out out/ur5_est.csv
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pinobs
from pinobs.io import write_log

if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", default=str(Path(__file__).parent), help="folder for ur5_log.csv")
    parser.add_argument("--quick", action="store_true", help="(same run; it is already quick)")
    args = parser.parse_args()
    robot = pinobs.load("ur5")
    res = pinobs.simulate(robot, [], duration=0.2, sensor=pinobs.Sensor(1000.0, 1e-4), seed=7)
    path = write_log(
        Path(args.out) / "ur5_log.csv", res.t[1:], res.q_meas[1:], res.tau[1:], digits=10
    )
    print(f"wrote {path}: {res.t.size - 1} rows, columns t, q0..q5, tau0..tau5")
