"""A playback written as one self-contained HTML file, from a run, a saved run or a log."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from pinobs.errors import DimensionError
from pinobs.io import Log, LogRun
from pinobs.model import Robot
from pinobs.simulation import ObserverTrace, Result
from pinobs.visualization._deps import require
from pinobs.visualization.chart import chart_data, chart_html
from pinobs.visualization.playback.legend import legend_html
from pinobs.visualization.playback.page import RecordingWindow
from pinobs.visualization.playback.scene import GHOST_OPACITY, Progress, make_scene

__all__ = ["log_result", "write_html", "write_html_from_file"]


def write_html(
    result: Result,
    robot: Robot,
    path: str | Path,
    *,
    fps: float = 30.0,
    observers: Sequence[str] | None = None,
    opacity: float = GHOST_OPACITY,
    title: str | None = None,
    truth_label: str = "truth",
    progress: Progress | None = None,
) -> Path:
    """Write a self-contained HTML playback of ``result`` (opens offline in any browser).

    The page holds meshcat's viewer, the truth, one ghost per observer (legend
    top left), the animation (Open Controls → Animations: play, pause, time
    slider) and, under the 3-D view, the velocity chart (element
    ``#pinobs-chart``: true and estimated velocity of one joint, the error
    norm on a log axis, a cursor at the animation time; dragging on it
    scrubs).  ``page.html#t=1.5`` opens paused at ``t = 1.5 s``.

    The page's size is capped: the keyframes take at most
    :data:`~pinobs.visualization.playback.MAX_ANIMATION_BYTES` (8 MB), so a
    long run gets fewer than ``fps`` keyframes per second, which the legend
    and a :class:`~pinobs.errors.PinobsWarning` say
    (:func:`~pinobs.visualization.build_scene`).  On top of the keyframes:
    meshcat's viewer (0.9 MB), the meshes (mesh files up to 4 MB, or
    decimated triangles) and the chart (at most
    :data:`~pinobs.visualization.chart.MAX_POINTS` samples per curve).

    Args:
        result: the run (``pinobs.simulate`` or ``Result.load``).
        robot: the robot it was run on.
        path: output ``.html`` file (parent folders are created).
        fps: keyframes per second of simulated time [1/s], at most.
        observers: labels to show (default: all).
        opacity: ghost opacity in (0, 1].
        title: legend title (default: robot name and duration).
        truth_label: legend name of ``result.q`` (``"measured"`` for :func:`log_result`).
        progress: called as ``progress(k, n)`` after frame ``k`` of ``n``.

    Returns:
        The path written.
    """
    meshcat = require("meshcat", "meshcat playback")
    path = Path(path)
    window = RecordingWindow()
    vis = meshcat.Visualizer(window=window)
    scene = make_scene(
        vis,
        result,
        robot,
        fps=fps,
        observers=observers,
        opacity=opacity,
        truth_label=truth_label,
        progress=progress,
    )
    legend = scene.legend
    if title is None:
        title = f"pinobs · {robot.name} · {result.t[-1] - result.t[0]:.3g} s"
    ghosts = legend[1:]
    data = chart_data(
        result, robot, [e.label for e in ghosts], [e.colour or "#000000" for e in ghosts]
    )
    overlay = legend_html(title, legend, float(result.t[0]), float(result.t[-1]), scene.notes)
    window.overlay = overlay + chart_html(data)
    page = vis.static_html()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(page, encoding="utf-8")
    return path


def write_html_from_file(
    result_path: str | Path,
    path: str | Path,
    *,
    robot: Robot | None = None,
    fps: float = 30.0,
    progress: Progress | None = None,
) -> Path:
    """Playback of a saved run (``Result.save``): load it, then :func:`write_html`.

    ``robot`` defaults to ``pinobs.load(source)``, ``source`` the registry name or
    file path recorded in the result (``meta["robot_source"]``, else its robot's
    name); pass the robot if it was built otherwise.
    """
    from pinobs.model import load

    result = Result.load(result_path)
    if robot is None:
        meta = result.meta if isinstance(result.meta, dict) else {}
        source = meta.get("robot_source") or result.robot
        robot = load(source, root_joint=meta.get("root_joint"))
    return write_html(result, robot, path, fps=fps, progress=progress)


def log_result(robot: Robot, log: Log, runs: Mapping[str, LogRun]) -> Result:
    """A :class:`Result` for playing back a recorded log and observers run over it.

    The "truth" is the logged configuration (show it with
    ``write_html(..., truth_label="measured")``); its velocity is unknown
    (NaN).  Rows whose time is unreadable or not increasing are left out; an
    unreadable configuration (a dropped sample) stays NaN: the playback holds
    the previous pose there and says so (:func:`~pinobs.visualization.build_scene`).

    Args:
        robot: the robot of the log.
        log: from :func:`pinobs.io.read_log`.
        runs: label -> :func:`pinobs.io.estimate_log` output over ``log``.
    """
    t = np.asarray(log.t, dtype=float)
    keep = np.isfinite(t)
    keep &= np.concatenate([[True], t[1:] > np.maximum.accumulate(np.where(keep, t, -np.inf))[:-1]])
    if keep.sum() < 1:
        raise DimensionError("the log has no row with a readable time")
    for name, run in runs.items():
        if run.q.shape != log.q.shape:
            raise DimensionError(
                f"estimates {name!r} have shape {run.q.shape}, the log's q has {log.q.shape}"
            )
    q = np.asarray(log.q, dtype=float)[keep]
    n = int(keep.sum())
    tau = np.zeros((n, robot.nv)) if log.tau is None else np.nan_to_num(log.tau[keep])
    traces = tuple(
        ObserverTrace(
            name=name,
            q=run.q[keep],
            v=run.v[keep],
            update_time=np.full(n, np.nan),
        )
        for name, run in runs.items()
    )
    return Result(
        robot=robot.name,
        t=t[keep],
        q=q,
        v=np.full((n, robot.nv), np.nan),
        tau=tau,
        q_meas=np.asarray(log.q, dtype=float)[keep],
        traces=traces,
        meta={"source": "log"},
    )
