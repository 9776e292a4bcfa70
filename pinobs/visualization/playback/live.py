"""A playback on a live meshcat server."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from pinobs.model import Robot
from pinobs.simulation import Result
from pinobs.visualization._deps import require
from pinobs.visualization.playback.legend import LegendEntry
from pinobs.visualization.playback.scene import GHOST_OPACITY, Progress, make_scene

__all__ = ["LiveViewer", "serve"]


@dataclass
class LiveViewer:
    """A playback on a live meshcat server (from :func:`serve`).

    Attributes:
        url: the page to open [http://127.0.0.1:…].
        vis: the ``meshcat.Visualizer`` (send more to it if you like).
        legend: what each colour is.
    """

    url: str
    vis: Any
    legend: list[LegendEntry]

    def close(self) -> None:
        """Close the connection and stop the server if :func:`serve` started it."""
        window = self.vis.window
        socket = getattr(window, "zmq_socket", None)
        if socket is not None:
            socket.close(linger=0)
        proc = getattr(window, "server_proc", None)
        if proc is not None:
            proc.kill()
            proc.wait()
            for pipe in (proc.stdout, proc.stderr):
                if pipe is not None:
                    pipe.close()
            window.server_proc = None

    def __enter__(self) -> LiveViewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def serve(
    result: Result,
    robot: Robot,
    *,
    fps: float = 30.0,
    observers: Sequence[str] | None = None,
    opacity: float = GHOST_OPACITY,
    zmq_url: str | None = None,
    open_browser: bool = False,
    progress: Progress | None = None,
    echo: Callable[[str], None] = print,
) -> LiveViewer:
    """Send the playback to a live meshcat server and print its URL and legend.

    ``zmq_url=None`` starts a server (``meshcat-server``, listening on
    127.0.0.1 only) that lives until :meth:`LiveViewer.close` or the end of
    the process; give ``tcp://127.0.0.1:6000`` to use a running one.  The
    legend is printed (meshcat's own page has no overlay).

    Returns:
        The :class:`LiveViewer` (``with serve(...) as viewer: ...`` closes it).
    """
    meshcat = require("meshcat", "live meshcat playback")
    vis = meshcat.Visualizer(zmq_url=zmq_url)
    vis.delete()
    scene = make_scene(
        vis, result, robot, fps=fps, observers=observers, opacity=opacity, progress=progress
    )
    legend = scene.legend
    url = str(vis.url())
    echo(f"meshcat playback of {robot.name}: {url}")
    for note in scene.notes:
        echo(f"  {note}")
    for e in legend:
        what = "model colours" if e.colour is None else f"estimate, {e.colour_name}"
        echo(f"  {e.label}: {what}" + (f" ({e.gap_note})" if e.gaps else ""))
    echo("  (Open Controls → Animations: play, pause, time)")
    if open_browser:
        vis.open()
    return LiveViewer(url=url, vis=vis, legend=legend)
