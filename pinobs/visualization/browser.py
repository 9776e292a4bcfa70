"""Screenshots of a playback page in headless Chromium (for tests and the README image).

WebGL runs on SwiftShader (software), so no GPU or display is needed.  The
page is loaded from a ``file://`` URL with networking features off; the
``#t=…`` fragment pauses the animation at that time (see
:func:`pinobs.visualization.write_html`).
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

from pinobs.errors import GainError
from pinobs.visualization._deps import MissingDependencyError

__all__ = ["find_chromium", "screenshot"]

_CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_chromium() -> str | None:
    """Path of a Chromium/Chrome executable on ``PATH``, or ``None``."""
    for name in _CANDIDATES:
        found = shutil.which(name)
        if found:
            return found
    return None


def screenshot(
    html: str | Path,
    png: str | Path,
    *,
    t: float | None = None,
    legend: bool = True,
    size: tuple[int, int] = (800, 600),
    budget_ms: int = 3000,
    chromium: str | None = None,
    timeout: float = 120.0,
) -> Path:
    """Render ``html`` in headless Chromium and save a PNG screenshot.

    Args:
        html: a page written by :func:`pinobs.visualization.write_html`.
        png: output file.
        t: pause the animation at this time [s] (``None``: let it play).
        legend: keep the legend overlay (``False`` hides it, e.g. to count pixels).
        size: window width and height [px].
        budget_ms: virtual time given to the page before the screenshot [ms].
        chromium: executable (default: :func:`find_chromium`).
        timeout: wall-clock limit [s].

    Raises:
        MissingDependencyError: no Chromium found (``apt-get install chromium``).
        RuntimeError: Chromium failed or wrote no image.
    """
    exe = chromium or find_chromium()
    if exe is None:
        raise MissingDependencyError(
            "screenshots need Chromium; install it with: apt-get install chromium "
            "(or put chromium / google-chrome on PATH)"
        )
    if size[0] < 16 or size[1] < 16:
        raise GainError(f"size={size!r} must be at least 16 x 16 pixels")
    html = Path(html).resolve()
    png = Path(png).resolve()
    png.parent.mkdir(parents=True, exist_ok=True)
    frag = []
    if t is not None:
        frag.append(f"t={float(t)!r}")
    if not legend:
        frag.append("nolegend")
    url = html.as_uri() + ("#" + "&".join(frag) if frag else "")
    with tempfile.TemporaryDirectory(prefix="pinobs-chromium-") as profile:
        cmd = [
            exe,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--use-gl=swiftshader",
            "--enable-unsafe-swiftshader",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            f"--user-data-dir={profile}",
            f"--window-size={size[0]},{size[1]}",
            f"--virtual-time-budget={int(budget_ms)}",
            f"--screenshot={png}",
            url,
        ]
        if png.exists():
            png.unlink()
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    if proc.returncode != 0 or not png.is_file():
        tail = "\n".join((proc.stderr or "").splitlines()[-5:])
        raise RuntimeError(f"{exe} did not write {png} (exit {proc.returncode}): {tail}")
    return png
