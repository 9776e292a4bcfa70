# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs", "matplotlib"]
# ///
"""Watch estimates go wrong: meshcat playback with a velocity chart (HTML), a plot, a screenshot.

A UR5 carries a payload its observers do not know about (the
``inertia20_payload`` truth of :mod:`pinobs.simulation.mismatch`).  The
model-free Kalman filter ``kf`` and the finite difference ``fd`` stay close;
the EKF, trusting the nominal model, drifts off.  Writes
``<out>/ur5_payload_playback.html`` (open it in any browser: the true robot,
each estimate as a translucent ghost, and under it the true and estimated
velocities with a cursor at the animation time), ``<out>/ur5_payload_plot.png``
and, when Chromium is installed, ``<out>/playback.png``: the page paused at
t = 1 s, the README's screenshot (``--screenshot docs/playback.png``
regenerates that file).

    python examples/playback.py            # 3 s run
    python examples/playback.py --quick    # 1.2 s run, for CI
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pinobs
from pinobs.simulation import mismatched_plant
from pinobs.visualization import plot, screenshot, write_html
from pinobs.visualization.browser import find_chromium

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("examples/out"))
    parser.add_argument("--quick", action="store_true", help="a 1.2 s run")
    parser.add_argument("--screenshot", type=Path, default=None, help="where to write the PNG")
    args = parser.parse_args()

    duration = 1.2 if args.quick else 3.0
    robot = pinobs.load("ur5")
    result = pinobs.simulate(
        robot,
        ["kf", "ekf", "fd"],
        duration=duration,
        sensor=pinobs.Sensor(rate=500.0, noise_std=1e-4),
        plant=mismatched_plant(robot, "inertia20_payload", seed=0),
        perturb_q=0.05,
        perturb_v=0.5,
        seed=0,
    )
    html = write_html(result, robot, args.out / "ur5_payload_playback.html")
    png = plot(result, robot, args.out / "ur5_payload_plot.png")
    print(f"playback: {html} ({html.stat().st_size / 1e6:.1f} MB)")
    print(f"plot:     {png}")
    for m in pinobs.evaluate(result, robot):
        print(
            f"{m.observer:4s} velocity RMS after {duration / 4:.3g} s: {m.rms_v_error:.3g} rad/s, "
            f"configuration RMS {m.rms_q_error:.3g} rad"
        )
    if find_chromium() is None:
        print("no Chromium on PATH: screenshot skipped (apt-get install chromium)")
    else:
        target = args.screenshot or args.out / "playback.png"
        shot = screenshot(html, target, t=1.0, size=(1000, 700))
        print(f"screenshot at t = 1 s: {shot}")
