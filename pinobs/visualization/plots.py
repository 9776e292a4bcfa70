"""Plots of a run: true and estimated velocities per joint, and the error norm.

One PNG (matplotlib, the ``plot`` extra): a panel per velocity coordinate with
the true velocity in black and each observer in its playback colour, and a
bottom panel with ``|v̂(t) − v(t)|₂`` on a log scale, each observer's
convergence time (:func:`pinobs.evaluation.evaluate`) marked by a dashed line.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pinobs.errors import GainError, UnknownNameError
from pinobs.evaluation import evaluate
from pinobs.model import Robot
from pinobs.simulation import Result
from pinobs.visualization._deps import require
from pinobs.visualization.playback import _hex, ghost_colour

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["figure", "plot", "velocity_labels"]

_COMPONENTS = {
    "so3": ("ωx", "ωy", "ωz"),
    "se3": ("vx", "vy", "vz", "ωx", "ωy", "ωz"),
    "se2": ("vx", "vy", "ω"),
}


def velocity_labels(robot: Robot) -> list[str]:
    """One label per velocity coordinate: the joint name, with the component for multi-DOF joints."""
    labels = [""] * robot.nv
    for j in robot.joints:
        comps = _COMPONENTS.get(j.kind)
        for k in range(j.nv):
            if j.nv == 1:
                labels[j.idx_v] = j.name
            else:
                comp = comps[k] if comps is not None and k < len(comps) else str(k)
                labels[j.idx_v + k] = f"{j.name} {comp}"
    return labels


def plot(
    result: Result,
    robot: Robot,
    path: str | Path,
    *,
    observers: Sequence[str] | None = None,
    max_joints: int = 12,
    transient: float | None = None,
    dpi: int = 110,
) -> Path:
    """Write a PNG of true vs estimated velocities and the error norm of each observer.

    Same arguments as :func:`figure`, plus ``path``, the output ``.png``
    (parent folders are created).  Returns the path written.
    """
    fig = figure(
        result, robot, observers=observers, max_joints=max_joints, transient=transient, dpi=dpi
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def figure(
    result: Result,
    robot: Robot,
    *,
    observers: Sequence[str] | None = None,
    max_joints: int = 12,
    transient: float | None = None,
    dpi: int = 110,
) -> Figure:
    """The figure :func:`plot` saves: velocity panels, then the error-norm panel (last axes).

    Args:
        result: the run.
        robot: the robot it was run on.
        observers: labels to plot (default: all, in run order).
        max_joints: at most this many velocity panels (the first ones; the
            error panel always uses every coordinate).
        transient: passed to :func:`pinobs.evaluation.evaluate` [s].
        dpi: resolution of the PNG.
    """
    require("matplotlib", "plots")
    from matplotlib.figure import Figure

    if max_joints < 1:
        raise GainError(f"max_joints={max_joints!r} must be at least 1")
    names = list(result.observer_names if observers is None else observers)
    for name in names:
        if name not in result.observer_names:
            raise UnknownNameError(
                f"no observer {name!r} in this result; have {result.observer_names}"
            )
    metrics = {m.observer: m for m in evaluate(result, robot, transient=transient)}
    colours = {name: _hex(ghost_colour(result.observer_names.index(name))[1]) for name in names}
    labels = velocity_labels(robot)
    shown = min(robot.nv, max_joints)
    ncols = 1 if shown <= 3 else 2 if shown <= 8 else 3
    nrows = math.ceil(shown / ncols)
    fig = Figure(figsize=(4.6 * ncols, 1.9 * nrows + 2.8), dpi=dpi, layout="constrained")
    grid = fig.add_gridspec(nrows + 1, ncols, height_ratios=[1.0] * nrows + [1.6])
    t = result.t
    for i in range(shown):
        ax = fig.add_subplot(grid[i // ncols, i % ncols])
        ax.plot(t, result.v[:, i], color="black", lw=1.4, label="truth")
        for name in names:
            ax.plot(t, result.trace(name).v[:, i], color=colours[name], lw=1.0, label=name)
        ax.set_ylabel(labels[i], fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=7, loc="upper right", ncols=min(4, 1 + len(names)))
    title = f"{robot.name}: true (black) and estimated velocity"
    if shown < robot.nv:
        title += f" (first {shown} of {robot.nv} coordinates)"
    fig.suptitle(title, fontsize=10)

    ax = fig.add_subplot(grid[nrows, :])
    for rank, name in enumerate(names):
        err = np.linalg.norm(result.trace(name).v - result.v, axis=1)
        err = np.where(err > 0, err, np.nan)  # log scale: an exact zero is not drawn
        m = metrics[name]
        ax.plot(t, err, color=colours[name], lw=1.0, label=f"{name}: RMS {m.rms_v_error:.3g}")
        if math.isfinite(m.convergence_time):
            ax.axvline(m.convergence_time, color=colours[name], ls="--", lw=1.0)
            ax.annotate(
                f"{m.convergence_time:.3g} s",
                (m.convergence_time, 1.0),
                xycoords=("data", "axes fraction"),
                xytext=(3, -10 - 10 * rank),
                textcoords="offset points",
                color=colours[name],
                fontsize=7,
            )
        if m.diverged_at is not None:
            ax.axvline(m.diverged_at, color=colours[name], ls=":", lw=1.5)
    ax.set_yscale("log")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("|v̂ − v|₂ [rad/s, m/s]")
    ax.grid(alpha=0.3, which="both")
    ax.set_title("velocity error norm (dashed: convergence time)", fontsize=9)
    if names:
        ax.legend(fontsize=7, loc="upper right")
    return fig
