"""One palette for the page and the plots; axis names, units and ranges shared by both."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

import pinobs
from pinobs.visualization import figure, write_html
from pinobs.visualization.axes import clip_start, velocity_range, velocity_units
from pinobs.visualization.palette import (
    MIN_DISTANCE,
    PALETTE,
    colour,
    hex_colour,
    observer_colours,
)
from pinobs.visualization.playback import truth_colours


def test_ten_observers_get_ten_colours_at_least_60_apart_in_rgb() -> None:
    rgb = [np.array(c) * 255.0 for _, c in (colour(i) for i in range(10))]
    names = {colour(i)[0] for i in range(10)}
    assert len(names) == 10
    closest = min(np.linalg.norm(a - b) for a, b in itertools.combinations(rgb, 2))
    assert closest >= 60.0
    assert colour(10) == colour(0)  # then they repeat


def test_the_first_seven_are_okabe_ito() -> None:
    okabe_ito = {"#d55e00", "#0072b2", "#009e73", "#e69f00", "#cc79a7", "#56b4e9", "#f0e442"}
    assert {hex_colour(c) for _, c in PALETTE[:7]} == okabe_ito


def test_page_and_plot_give_each_observer_the_same_colour(tmp_path: Path) -> None:
    robot = pinobs.load("cartpole")
    result = pinobs.simulate(
        robot, ["fd", "kf", "ekf"], duration=0.3, sensor=pinobs.Sensor(rate=200.0), seed=2
    )
    shown = ["ekf", "fd"]
    text = write_html(result, robot, tmp_path / "p.html", observers=shown).read_text("utf-8")
    fig = figure(result, robot, observers=shown)
    plot_colours = [line.get_color() for line in fig.axes[0].get_lines()[1:]]
    assert plot_colours == [hex_colour(rgb) for _, rgb in observer_colours(2, truth_colours(robot))]
    for name, c in zip(shown, plot_colours, strict=True):
        row = text[text.index(f'data-label="{name}"') :]
        assert f"background:{c}" in row[: row.index("</div>")]


def test_truth_swatch_shows_the_colours_the_robot_renders_in(tmp_path: Path) -> None:
    robot = pinobs.load("cartpole")
    result = pinobs.simulate(robot, ["kf"], duration=0.2, sensor=pinobs.Sensor(rate=100.0), seed=1)
    text = write_html(result, robot, tmp_path / "p.html").read_text("utf-8")
    row = text[text.index('data-label="truth"') :]
    row = row[: row.index("</div>")]
    for go in robot.visual_model.geometryObjects:  # a grey cart and a blue pole
        assert hex_colour(go.meshColor[:3]) in row


def test_velocity_units_follow_the_joint_type() -> None:
    assert velocity_units(pinobs.load("cartpole")) == ["m/s", "rad/s"]
    assert velocity_units(pinobs.load("rigid_body")) == ["m/s"] * 3 + ["rad/s"] * 3
    assert velocity_units(pinobs.load("ur5")) == ["rad/s"] * 6


def test_velocity_range_keeps_the_truth_and_drops_the_estimates_transient() -> None:
    t = np.linspace(0.0, 2.0, 201)
    truth = np.sin(3 * t)
    estimate = truth + 50.0 * np.exp(-t / 0.02)  # a start 50 off, converged by 0.2 s
    lo, hi = velocity_range(t, truth, [estimate], 0.5)
    assert lo < -0.99 and hi > 0.99  # the whole truth
    assert hi < 1.3  # the transient is left out (10 % margin)
    assert clip_start(t, [0.3, np.inf, 0.1]) == 0.3
    assert clip_start(t, [1.7]) == 1.0  # at most the middle of the run


def test_observer_colours_keep_away_from_the_truths_colours() -> None:
    cartpole = truth_colours(pinobs.load("cartpole"))
    assert cartpole == ("#80808c", "#3366cc")  # a grey cart, a blue pole
    picked = observer_colours(10, cartpole)
    assert PALETTE[1] not in picked  # blue: 58 from the pole
    assert PALETTE[7] not in picked  # purple: 59 from the cart
    assert picked[:2] == [PALETTE[0], PALETTE[2]]
    assert picked[8] == picked[0]  # eight left, then they repeat
    rgb = [np.array(c) * 255.0 for _, c in picked[:8]]
    for truth in cartpole:
        t = np.array([int(truth[i : i + 2], 16) for i in (1, 3, 5)], dtype=float)
        assert min(np.linalg.norm(c - t) for c in rgb) >= MIN_DISTANCE
    assert observer_colours(3) == list(PALETTE[:3])
    assert truth_colours(pinobs.load("ur5")) == ("#e6e6e6",)  # drawn from meshColor: white
