"""Plots of a run: true and estimated velocities per joint, and the error norm.

One PNG (matplotlib, the ``plot`` extra): a panel per velocity coordinate with
the true velocity in black and each observer in its playback colour
(:mod:`pinobs.visualization.palette`), and a bottom panel with
``|v̂(t) − v(t)|₂`` on a log scale, each observer's convergence time
(:func:`pinobs.evaluation.evaluate`) marked by a dashed line and quoted in the
legend (one for the figure, under the panels).  Every axis names its unit.  The velocity panels' y-range is the
truth's whole run and the estimates after the slowest convergence time
(:func:`pinobs.visualization.axes.velocity_range`): the start transient, which
can be far larger than the motion, is clipped, shaded and said so in the title.
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
from pinobs.visualization.axes import clip_start, velocity_labels, velocity_range, velocity_units
from pinobs.visualization.palette import TRUTH_LINE, hex_colour, observer_colours
from pinobs.visualization.playback import truth_colours

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from pinobs.evaluation.metrics import Metrics

__all__ = ["figure", "plot", "plot_path"]


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
    path = plot_path(path)
    fig = figure(
        result, robot, observers=observers, max_joints=max_joints, transient=transient, dpi=dpi
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def plot_path(path: str | Path) -> Path:
    """The file :func:`plot` writes for ``path``: ``.png`` added when it has no suffix.

    Raises:
        GainError: a suffix matplotlib cannot write (names the ones it can).
    """
    require("matplotlib", "plots")
    from matplotlib.backend_bases import FigureCanvasBase

    path = Path(path)
    if not path.suffix:
        return path.with_name(path.name + ".png")  # as matplotlib would, said in the path
    formats = FigureCanvasBase.get_supported_filetypes()
    if path.suffix[1:].lower() not in formats:
        raise GainError(
            f"plot {str(path)!r}: matplotlib cannot write {path.suffix!r} files; give one of "
            + ", ".join("." + f for f in sorted(formats))
        )
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
    # the page's colours: the palette in this order, away from the truth's model colours
    picked = observer_colours(len(names), truth_colours(robot))
    colours = {name: hex_colour(rgb) for name, (_, rgb) in zip(names, picked, strict=True)}
    labels = velocity_labels(robot)
    units = velocity_units(robot)
    shown = min(robot.nv, max_joints)
    ncols = 1 if shown <= 3 else 2 if shown <= 8 else 3
    nrows = math.ceil(shown / ncols)
    fig = Figure(figsize=(4.6 * ncols, 2.0 * nrows + 3.0), dpi=dpi, layout="constrained")
    grid = fig.add_gridspec(nrows + 1, ncols, height_ratios=[1.0] * nrows + [1.6])
    start = clip_start(result.t, [metrics[n].convergence_time for n in names])
    clipped = False
    # a diverged estimate does not set the range (it is clipped, and the legend says it diverged)
    sane = [n for n in names if metrics[n].diverged_at is None]
    for i in range(shown):
        ax = fig.add_subplot(grid[i // ncols, i % ncols])
        label = f"{labels[i]} [{units[i]}]"
        clipped |= _velocity_panel(ax, result, i, label, names, sane, colours, start)
    title = f"{robot.name}: true (black) and estimated velocity"
    if shown < robot.nv:
        title += f" (first {shown} of {robot.nv} coordinates)"
    if clipped:
        title += f"\nstart transient clipped (shaded): y-range from t = {start:.3g} s"
    fig.suptitle(title, fontsize=10)

    ax = fig.add_subplot(grid[nrows, :])
    unit = units[0] if len(set(units)) == 1 else "rad/s and m/s mixed"
    _error_panel(ax, result, names, colours, metrics, unit)
    # one legend for every panel, under them, where it hides no curve
    handles = [
        fig.axes[0].get_lines()[0],
        *(line for line in ax.get_lines() if not str(line.get_label()).startswith("_")),
    ]
    fig.legend(
        handles=handles, loc="outside lower center", ncols=min(ncols, len(handles)), fontsize=7
    )
    return fig


def _velocity_panel(
    ax: Axes,
    result: Result,
    i: int,
    label: str,
    names: list[str],
    sane: list[str],
    colours: dict[str, str],
    start: float,
) -> bool:
    """Coordinate ``i``'s panel: the truth and each estimate, the y-range from the truth and
    the ``sane`` estimates after ``start``; whether an estimate is clipped (then shaded)."""
    t = result.t
    # the truth thin and on top: a converged estimate shows as its coloured rim
    ax.plot(t, result.v[:, i], color=TRUTH_LINE, lw=0.9, label="truth", zorder=3)
    estimates = np.column_stack([result.trace(n).v[:, i] for n in names] or [t * np.nan])
    for k, name in enumerate(names):
        ax.plot(t, estimates[:, k], color=colours[name], lw=1.6, label=name)
    lo, hi = velocity_range(t, result.v[:, i], [result.trace(n).v[:, i] for n in sane], start)
    with np.errstate(invalid="ignore"):
        outside = bool(np.any((estimates < lo) | (estimates > hi)))
    ax.set_ylim(lo, hi)
    if outside:
        ax.axvspan(t[0], start, color="0.88", lw=0, zorder=0)
    ax.set_ylabel(label, fontsize=8)
    ax.set_xlabel("t [s]", fontsize=7, labelpad=1)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    return outside


def _error_panel(
    ax: Axes,
    result: Result,
    names: list[str],
    colours: dict[str, str],
    metrics: dict[str, Metrics],
    unit: str,
) -> None:
    """The error-norm panel: ``|v̂ − v|₂`` of each estimate on a log scale, its convergence
    (dashed) and divergence (dotted) times marked and quoted in its label."""
    t = result.t
    for name in names:
        err = np.linalg.norm(result.trace(name).v - result.v, axis=1)
        err = np.where(err > 0, err, np.nan)  # log scale: an exact zero is not drawn
        m = metrics[name]
        label = f"{name}: RMS {m.rms_v_error:.3g}"
        if math.isfinite(m.convergence_time):
            label += f", converged at {m.convergence_time:.3g} s"
        if m.diverged_at is not None:
            label += f", diverged at {m.diverged_at:.3g} s"
        ax.plot(t, err, color=colours[name], lw=1.0, label=label)
        if math.isfinite(m.convergence_time):
            ax.axvline(m.convergence_time, color=colours[name], ls="--", lw=1.0)
        if m.diverged_at is not None:
            ax.axvline(m.diverged_at, color=colours[name], ls=":", lw=1.5)
    finite = [np.linalg.norm(result.trace(n).v - result.v, axis=1) for n in names]
    if any(np.any(np.isfinite(e) & (e > 0)) for e in finite):
        ax.set_yscale("log")
    else:  # every estimate diverged at once (or is exact): nothing to draw on a log scale
        ax.text(0.5, 0.5, "no finite velocity error to plot", ha="center", transform=ax.transAxes)
    ax.set_xlabel("t [s]")
    ax.set_ylabel(f"|v̂ − v|₂ [{unit}]")
    ax.grid(alpha=0.3, which="both")
    ax.set_title("velocity error, log scale (dashed: convergence time)", fontsize=9)
