"""Watch a run: meshcat playback of the truth and the estimates, and matplotlib plots.

This layer sits above :mod:`pinobs.evaluation`; nothing below imports it.
meshcat and matplotlib are imported when a function needs them, with an
install hint if missing (:class:`MissingDependencyError`).
"""

from pinobs.visualization._deps import MissingDependencyError
from pinobs.visualization.browser import screenshot
from pinobs.visualization.palette import PALETTE
from pinobs.visualization.playback import (
    LegendEntry,
    LiveViewer,
    build_scene,
    log_result,
    serve,
    write_html,
    write_html_from_file,
)
from pinobs.visualization.plots import figure, plot

__all__ = [
    "PALETTE",
    "LegendEntry",
    "LiveViewer",
    "MissingDependencyError",
    "build_scene",
    "figure",
    "log_result",
    "plot",
    "screenshot",
    "serve",
    "write_html",
    "write_html_from_file",
]
