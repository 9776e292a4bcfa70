"""Plots: a velocity panel per coordinate, and the error norm with convergence times."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import pinobs
from pinobs.errors import UnknownNameError
from pinobs.visualization import MissingDependencyError, figure, plot
from pinobs.visualization.axes import velocity_labels
from pinobs.visualization.palette import PALETTE, TRUTH_LINE, hex_colour


@pytest.fixture(scope="module")
def run() -> dict[str, Any]:
    robot = pinobs.load("cartpole")
    result = pinobs.simulate(
        robot,
        ["kf", "fd"],
        duration=1.0,
        sensor=pinobs.Sensor(rate=200.0, noise_std=1e-4),
        perturb_q=0.3,
        perturb_v=1.0,
        seed=5,
    )
    return {"robot": robot, "result": result}


def test_png_is_written_and_not_blank(run: dict[str, Any], tmp_path: Path) -> None:
    from matplotlib.image import imread

    path = plot(run["result"], run["robot"], tmp_path / "sub" / "plot.png")
    img = imread(path)
    assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 300
    assert np.mean(img[..., :3] < 0.5) > 0.005  # ink on the page


def test_one_panel_per_velocity_then_the_error_panel(run: dict[str, Any]) -> None:
    fig = figure(run["result"], run["robot"])
    assert len(fig.axes) == run["robot"].nv + 1
    truth_line = fig.axes[0].get_lines()[0]
    assert truth_line.get_color() == TRUTH_LINE
    np.testing.assert_array_equal(truth_line.get_ydata(), run["result"].v[:, 0])
    colours = [line.get_color() for line in fig.axes[0].get_lines()[1:]]
    # the palette in order, without the blue of the cart-pole's pole (the truth)
    assert colours == [hex_colour(PALETTE[0][1]), hex_colour(PALETTE[2][1])]


def test_error_panel_is_logarithmic_and_marks_the_convergence_time(run: dict[str, Any]) -> None:
    fig = figure(run["result"], run["robot"])
    err_ax = fig.axes[-1]
    assert err_ax.get_yscale() == "log"
    metrics = pinobs.evaluate(run["result"], run["robot"])
    marked = sorted(
        float(line.get_xdata()[0]) for line in err_ax.get_lines() if line.get_linestyle() == "--"
    )
    expected = sorted(m.convergence_time for m in metrics if np.isfinite(m.convergence_time))
    assert expected and marked == expected
    kf = err_ax.get_lines()[0]
    np.testing.assert_allclose(
        kf.get_ydata(), np.linalg.norm(run["result"].trace("kf").v - run["result"].v, axis=1)
    )


def test_large_robots_show_the_first_coordinates_only() -> None:
    robot = pinobs.load("rigid_body")
    result = pinobs.simulate(robot, ["fd"], duration=0.2, sensor=pinobs.Sensor(rate=100.0), seed=1)
    fig = figure(result, robot, max_joints=4)
    assert len(fig.axes) == 5
    assert "first 4 of 6" in fig.get_suptitle()


def test_velocity_labels_name_lie_group_components() -> None:
    assert velocity_labels(pinobs.load("top")) == [f"root_joint ω{c}" for c in "xyz"]
    ff = velocity_labels(pinobs.load("rigid_body"))
    assert ff[:3] == [f"root_joint v{c}" for c in "xyz"]
    assert ff[3:] == [f"root_joint ω{c}" for c in "xyz"]
    assert velocity_labels(pinobs.load("cartpole")) == ["cart_x", "pole_theta"]


def test_unknown_observer_is_rejected(run: dict[str, Any], tmp_path: Path) -> None:
    with pytest.raises(UnknownNameError, match="no observer 'ukf'"):
        plot(run["result"], run["robot"], tmp_path / "x.png", observers=["ukf"])


def test_missing_matplotlib_names_the_install_command(
    run: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(MissingDependencyError, match="pip install matplotlib"):
        plot(run["result"], run["robot"], tmp_path / "x.png")


def test_every_axis_names_its_unit(run: dict[str, Any]) -> None:
    fig = figure(run["result"], run["robot"])
    ylabels = [ax.get_ylabel() for ax in fig.axes]
    assert ylabels[:2] == ["cart_x [m/s]", "pole_theta [rad/s]"]
    assert ylabels[-1] == "|v̂ − v|₂ [rad/s and m/s mixed]"
    assert all(ax.get_xlabel() == "t [s]" for ax in fig.axes)


def test_y_range_is_the_motion_after_the_transient_and_the_clipping_is_said(
    run: dict[str, Any],
) -> None:
    """The estimates start 1 rad/s off: their transient would set the y-range; it is clipped."""
    result = run["result"]
    fig = figure(result, run["robot"])
    metrics = pinobs.evaluate(result, run["robot"])
    start = max(m.convergence_time for m in metrics)
    for i, ax in enumerate(fig.axes[:-1]):
        lo, hi = ax.get_ylim()
        truth = result.v[:, i]
        assert lo < truth.min() and truth.max() < hi  # the truth is never clipped
        late = np.concatenate([result.trace(n).v[result.t >= start, i] for n in ("kf", "fd")])
        assert lo <= late.min() and late.max() <= hi
    worst = max(
        float(np.max(np.abs(result.trace(n).v[:, 1] - result.v[:, 1]))) for n in ("kf", "fd")
    )
    lo, hi = fig.axes[1].get_ylim()
    assert worst > hi - lo  # the transient does leave the range
    assert "start transient clipped (shaded)" in fig.get_suptitle()


def test_error_panel_labels_do_not_overlap(run: dict[str, Any]) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = figure(run["result"], run["robot"])
    FigureCanvasAgg(fig).draw()
    ax = fig.axes[-1]
    texts = [t for t in ax.texts if t.get_visible()]
    (legend,) = fig.legends
    texts += [*legend.get_texts(), ax.title, ax.xaxis.label]
    boxes = [t.get_window_extent() for t in texts if t.get_text()]
    for i, a in enumerate(boxes):
        for b in boxes[i + 1 :]:
            assert not a.overlaps(b)
    assert not legend.get_window_extent().overlaps(ax.get_window_extent())  # hides no curve
    assert fig.bbox.contains(*legend.get_window_extent().p0)  # and is not cut off
    assert fig.bbox.contains(*legend.get_window_extent().p1)
    lines = [t.get_text() for t in legend.get_texts()]
    assert lines[0] == "truth" and all("converged at" in line for line in lines[1:])


def test_a_diverged_estimate_does_not_set_the_y_range(run: dict[str, Any]) -> None:
    import dataclasses

    result = run["result"]
    fd = result.trace("fd")
    v = np.array(fd.v)
    half = len(result.t) // 2
    v[half:] = 1e6  # blows up, as a diverging observer does before its NaN
    broken = dataclasses.replace(
        result,
        traces=(
            result.trace("kf"),
            dataclasses.replace(fd, v=v, diverged_at=float(result.t[half])),
        ),
    )
    lo, hi = figure(broken, run["robot"]).axes[0].get_ylim()
    assert hi - lo < 10.0  # [m/s]: the cart's motion, not the 1e6
    assert lo < result.v[:, 0].min() and result.v[:, 0].max() < hi


def test_plot_returns_the_file_it_wrote_and_refuses_unknown_formats(run, tmp_path) -> None:
    pytest.importorskip("matplotlib")
    written = plot(run["result"], run["robot"], tmp_path / "adir")
    assert written == tmp_path / "adir.png" and written.is_file()  # was reported as 'adir'
    with pytest.raises(pinobs.errors.GainError, match=r"cannot write '\.txt' files"):
        plot(run["result"], run["robot"], tmp_path / "p.txt")
    assert not (tmp_path / "p.txt").exists()


def test_plot_of_a_run_where_every_observer_diverged_is_written(run, tmp_path) -> None:
    pytest.importorskip("matplotlib")
    import dataclasses

    res = run["result"]
    nan = tuple(
        dataclasses.replace(
            tr, q=np.full_like(tr.q, np.nan), v=np.full_like(tr.v, np.nan), diverged_at=0.0
        )
        for tr in res.traces
    )
    # was: ValueError: Data cannot be log-scaled (no finite error to draw)
    path = plot(dataclasses.replace(res, traces=nan), run["robot"], tmp_path / "d.png")
    assert path.stat().st_size > 0


def test_slide_axis_is_the_axis_of_prismatic_joints_only(tmp_path: Path) -> None:
    """Read from the motion subspace: aligned and unaligned prismatic joints (their velocity
    in m/s), not revolute ones."""
    from pinobs.visualization.axes import slide_axis, velocity_units

    urdf = tmp_path / "two.urdf"
    urdf.write_text(
        """<?xml version="1.0"?><robot name="two"><link name="a"/>
  <joint name="turn" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01"
    iyz="0" izz="0.01"/></inertial></link>
  <joint name="slide" type="prismatic"><parent link="b"/><child link="c"/><axis xyz="0.6 0.8 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <link name="c"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01"
    iyz="0" izz="0.01"/></inertial></link></robot>"""
    )
    robot = pinobs.load(urdf)
    model = robot.model
    assert model.joints[2].shortname() == "JointModelPrismaticUnaligned"
    assert slide_axis(model, 1) is None
    np.testing.assert_allclose(slide_axis(model, 2), [0.6, 0.8, 0.0], atol=1e-12)
    assert velocity_units(robot) == ["rad/s", "m/s"]
