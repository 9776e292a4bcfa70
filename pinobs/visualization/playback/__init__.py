"""Meshcat playback of a run: the true robot and each observer's estimate as a ghost.

The truth is drawn as the model describes it (URDF colours and meshes, loaded
by :class:`pinocchio.visualize.MeshcatVisualizer`); each observer's estimate
``q̂(t)`` is a translucent ghost of the same robot in its own colour
(:func:`pinobs.visualization.palette.observer_colours`: a colour-blind-safe
palette, away from the robot's own colours; the plots use the same).
Robots without visual geometry get a stick figure (a sphere per joint, a rod
per link).  A floor grid lies on the plane ``z = 0`` under the motion.  A
floating base (free-flyer or planar root) is followed: the scene, floor
included, moves so that the true base stays in view.  The motion is
one meshcat ``Animation`` keyframed at ``fps``
frames per second of simulated time, so meshcat's own timeline (Open Controls
→ Animations: play, pause, reset, time slider, time scale) plays, pauses and
scrubs it.  The keyframes take at most :data:`MAX_ANIMATION_BYTES` (8 MB) of
a page: a long run gets fewer keyframes per second, and says so.  Rows
without a finite configuration are not drawn: the truth holds its last pose,
a ghost is hidden, and the legend says when.

Two ways to watch:

* :func:`write_html` writes one self-contained HTML file (meshcat's viewer,
  the scene and the animation embedded; no network needed).  Scene commands
  are recorded in-process by a window object standing in for meshcat's
  server, and ``Visualizer.static_html()`` turns them into the page, so no
  server is started and no port is opened.  The page shows a legend (an HTML
  overlay, top left: the truth in its model colours and one colour swatch per
  observer), the current time, and under the 3-D view a chart of true against
  estimated velocity whose cursor follows the animation
  (:mod:`pinobs.visualization.chart`).  Opening it as ``file.html#t=1.5`` pauses the animation at
  ``t = 1.5 s`` (used by the tests to screenshot two instants); ``#paused``
  opens it paused at the start, ``&nolegend`` hides the legend.
* :func:`serve` sends the same scene to a live meshcat server (started on
  127.0.0.1 by ``meshcat.Visualizer()``) and prints its URL.
"""

from pinobs.visualization.playback.geometry import truth_colours
from pinobs.visualization.playback.legend import LegendEntry
from pinobs.visualization.playback.legend import legend_json as legend_json
from pinobs.visualization.playback.live import LiveViewer, serve
from pinobs.visualization.playback.scene import GHOST_OPACITY as GHOST_OPACITY
from pinobs.visualization.playback.scene import Progress as Progress
from pinobs.visualization.playback.scene import build_scene
from pinobs.visualization.playback.timeline import MAX_ANIMATION_BYTES, frame_indices
from pinobs.visualization.playback.writer import log_result, write_html, write_html_from_file

__all__ = [
    "MAX_ANIMATION_BYTES",
    "LegendEntry",
    "LiveViewer",
    "build_scene",
    "frame_indices",
    "log_result",
    "serve",
    "truth_colours",
    "write_html",
    "write_html_from_file",
]
