# /// script
# requires-python = ">=3.10"
# dependencies = ["pinobs", "matplotlib"]
# ///
"""Watch an observer converge: meshcat playback (HTML), a plot, and a screenshot strip.

A cart-pole tracks a PD reference; a Kalman observer starts 0.6 rad / 0.5 rad/s
off and converges.  Writes ``<out>/cartpole_playback.html`` (open it in any
browser: the true robot, the estimate as an orange ghost, a timeline to play
and scrub), ``<out>/cartpole_plot.png`` and, when Chromium is installed,
``<out>/playback.png``: the page paused at t = 0, 20 and 40 ms, side by side, the README's
screenshot (``--screenshot docs/playback.png`` regenerates that file).

    python examples/playback.py            # 3 s run
    python examples/playback.py --quick    # 1 s run, for CI
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

import pinobs
from pinobs.visualization import plot, screenshot, write_html
from pinobs.visualization.browser import find_chromium


def strip(html: Path, out: Path, times: list[float]) -> Path:
    """Screenshots of ``html`` paused at ``times`` [s], placed side by side."""
    from PIL import Image

    with tempfile.TemporaryDirectory() as tmp:
        shots = [
            Image.open(screenshot(html, Path(tmp) / f"{i}.png", t=t, size=(600, 450))).convert(
                "RGB"
            )
            for i, t in enumerate(times)
        ]
    w, h = shots[0].size
    sheet = Image.new("RGB", (w * len(shots), h), "white")
    for i, im in enumerate(shots):
        sheet.paste(im, (i * w, 0))
    out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(out)
    return out


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("examples/out"))
    parser.add_argument("--quick", action="store_true", help="a 1 s run")
    parser.add_argument("--screenshot", type=Path, default=None, help="where to write the strip")
    args = parser.parse_args()

    duration = 1.0 if args.quick else 3.0
    robot = pinobs.load("cartpole")
    result = pinobs.simulate(
        robot,
        ["kf"],
        duration=duration,
        sensor=pinobs.Sensor(rate=200.0, noise_std=1e-4),
        q0=np.array([0.0, 0.0]),
        perturb_q=0.6,
        perturb_v=0.5,
        seed=3,
    )
    (m,) = pinobs.evaluate(result, robot)
    html = write_html(result, robot, args.out / "cartpole_playback.html")
    png = plot(result, robot, args.out / "cartpole_plot.png")
    print(f"playback: {html} ({html.stat().st_size / 1e6:.1f} MB)")
    print(f"plot:     {png}")
    print(
        f"kf: convergence time {m.convergence_time:.3g} s, "
        f"velocity RMS after {duration / 4:.3g} s: {m.rms_v_error:.3g}"
    )
    if find_chromium() is None:
        print("no Chromium on PATH: screenshot strip skipped (apt-get install chromium)")
    else:
        target = args.screenshot or args.out / "playback.png"
        print(f"screenshots: {strip(html, target, [0.0, 0.02, 0.04])}")
