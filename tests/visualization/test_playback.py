"""Meshcat playback: the scene and timeline in the HTML, and what a real browser shows.

The browser tests render the page in headless Chromium (SwiftShader WebGL)
and count pixels by colour; they skip only where no Chromium is installed.
"""

from __future__ import annotations

import base64
import dataclasses
import math
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
import umsgpack

import pinobs
from pinobs.errors import DimensionError, GainError, UnknownNameError
from pinobs.visualization import (
    MissingDependencyError,
    log_result,
    screenshot,
    serve,
    write_html,
    write_html_from_file,
)
from pinobs.visualization import playback as pb
from pinobs.visualization.browser import find_chromium
from pinobs.visualization.palette import PALETTE, hex_colour
from pinobs.visualization.playback import geometry, timeline
from pinobs.visualization.playback.page import RecordingWindow, fill_template

DURATION = 1.5  # [s]
FPS = 30.0


@pytest.fixture(scope="module")
def cartpole_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A cart-pole run whose Kalman ghost starts 0.6 rad off and converges; its HTML page."""
    robot = pinobs.load("cartpole")
    result = pinobs.simulate(
        robot,
        ["kf"],
        duration=DURATION,
        sensor=pinobs.Sensor(rate=200.0, noise_std=1e-4),
        q0=np.array([0.0, 0.0]),
        perturb_q=0.6,
        perturb_v=0.5,
        seed=3,
    )
    html = write_html(result, robot, tmp_path_factory.mktemp("playback") / "cartpole.html")
    return {"robot": robot, "result": result, "html": html}


def commands(html: Path) -> list[dict[str, Any]]:
    """The meshcat commands embedded in a page, decoded."""
    text = html.read_text(encoding="utf-8")
    block = text[
        text.index("var pinobsCommands = [") : text.index("];", text.index("var pinobsCommands"))
    ]
    return [
        umsgpack.unpackb(base64.b64decode(b)) for b in re.findall(r'"([A-Za-z0-9+/=]+)"', block)
    ]


def clips(html: Path) -> dict[str, dict[str, Any]]:
    """Animation clips of a page, by node path."""
    (anim,) = [c for c in commands(html) if c["type"] == "set_animation"]
    return {a["path"]: a["clip"] for a in anim["animations"]}


# ---------------------------------------------------------------- frames


def test_frame_indices_pick_the_sample_nearest_each_frame_time() -> None:
    t = np.arange(0, 1001) * 1e-3
    idx = pb.frame_indices(t, 30.0)
    assert len(idx) == 31
    assert np.max(np.abs(t[idx] - np.arange(31) / 30.0)) <= 0.5e-3
    assert idx[0] == 0


def test_frame_indices_reject_a_nonpositive_rate() -> None:
    with pytest.raises(GainError, match="fps=0"):
        pb.frame_indices(np.arange(10.0), 0.0)


# ------------------------------------------------------------------ page


def test_page_is_self_contained_with_a_legend(cartpole_run: dict[str, Any]) -> None:
    text = cartpole_run["html"].read_text(encoding="utf-8")
    assert "<script src" not in text and "<link" not in text  # nothing fetched
    assert "MeshCat.Viewer" in text
    legend = text[text.index('id="pinobs-legend"') :]
    assert 'data-label="truth"' in legend and 'data-label="kf"' in legend
    assert hex_colour(PALETTE[0][1]) in legend  # the ghost's swatch colour


def test_timeline_has_one_keyframe_per_frame_for_truth_and_ghost(
    cartpole_run: dict[str, Any],
) -> None:
    n = len(pb.frame_indices(cartpole_run["result"].t, FPS))
    by_path = clips(cartpole_run["html"])
    truth = [p for p in by_path if p.startswith("/meshcat/truth/")]
    ghost = [p for p in by_path if p.startswith("/meshcat/ghost_0_kf/")]
    assert len(truth) == len(ghost) == cartpole_run["robot"].visual_model.ngeoms
    for clip in by_path.values():
        assert clip["fps"] == FPS
        for track in clip["tracks"]:
            assert [k["time"] for k in track["keys"]] == list(range(n))


def test_ghost_keyframes_are_the_estimated_placements(cartpole_run: dict[str, Any]) -> None:
    """Keyframe k of each node is its placement by forward kinematics of q̂ (or q) at frame k."""
    robot, result = cartpole_run["robot"], cartpole_run["result"]
    idx = pb.frame_indices(result.t, FPS)
    by_path = clips(cartpole_run["html"])
    model, geom = robot.model, robot.visual_model
    data, gdata = model.createData(), pin.GeometryData(geom)
    worst = 0.0
    for q_all, prefix in (
        (result.q, "/meshcat/truth/visuals/"),
        (result.trace("kf").q, "/meshcat/ghost_0_kf/"),
    ):
        for k in (0, len(idx) // 2, len(idx) - 1):
            pin.forwardKinematics(model, data, q_all[idx[k]])
            pin.updateGeometryPlacements(model, data, geom, gdata)
            for g, go in enumerate(geom.geometryObjects):
                tracks = {
                    tr["name"]: tr["keys"][k]["value"] for tr in by_path[prefix + go.name]["tracks"]
                }
                M = gdata.oMg[g]
                quat = pin.Quaternion(*(tracks[".quaternion"][i] for i in (3, 0, 1, 2)))
                worst = max(
                    worst,
                    float(np.max(np.abs(np.array(tracks[".position"]) - M.translation))),
                    float(np.max(np.abs(quat.toRotationMatrix() - M.rotation))),
                )
    assert worst < 1e-12


def test_ghost_starts_apart_and_ends_on_the_truth(cartpole_run: dict[str, Any]) -> None:
    by_path = clips(cartpole_run["html"])
    name = cartpole_run["robot"].visual_model.geometryObjects[1].name  # the pole

    def positions(prefix: str) -> np.ndarray:
        (pos,) = [tr for tr in by_path[prefix + name]["tracks"] if tr["name"] == ".position"]
        return np.array([k["value"] for k in pos["keys"]])

    gap = np.linalg.norm(
        positions("/meshcat/ghost_0_kf/") - positions("/meshcat/truth/visuals/"), axis=1
    )
    assert gap[0] > 0.1  # [m]: the perturbed start is visible
    assert gap[-1] < 0.01 * gap[0]


def test_diverged_ghost_freezes_at_its_last_estimate_and_says_so(
    cartpole_run: dict[str, Any], tmp_path: Path
) -> None:
    result = cartpole_run["result"]
    tr = result.trace("kf")
    half = len(result.t) // 2
    q = np.array(tr.q)
    q[half:] = np.nan
    broken = dataclasses.replace(
        result,
        traces=(dataclasses.replace(tr, q=q, diverged_at=float(result.t[half])),),
    )
    html = write_html(broken, cartpole_run["robot"], tmp_path / "diverged.html")
    assert f"diverged at {result.t[half]:.3g} s" in html.read_text(encoding="utf-8")
    name = cartpole_run["robot"].visual_model.geometryObjects[1].name
    (pos,) = [
        t for t in clips(html)["/meshcat/ghost_0_kf/" + name]["tracks"] if t["name"] == ".position"
    ]
    values = np.array([k["value"] for k in pos["keys"]])
    frozen = pb.frame_indices(result.t, FPS) >= half
    assert np.all(np.isfinite(values))
    assert frozen.sum() > 5
    np.testing.assert_array_equal(values[frozen], np.repeat(values[frozen][:1], frozen.sum(), 0))
    # and hidden from then on (the legend: "diverged at …; hidden from …")
    (track,) = clips(html)["/meshcat/ghost_0_kf"]["tracks"]
    first = int(np.argmax(frozen))
    assert [(k["time"], k["value"]) for k in track["keys"]] == [
        (0, True),
        (first, False),
        (len(frozen) - 1, False),
    ]


def commands_b64(html: Path) -> list[str]:
    """The meshcat commands embedded in a page, as the base64 strings the page holds."""
    text = html.read_text(encoding="utf-8")
    block = text[
        text.index("var pinobsCommands = [") : text.index("];", text.index("var pinobsCommands"))
    ]
    return re.findall(r'"([A-Za-z0-9+/=]+)"', block)


@pytest.mark.parametrize(
    "budget",
    [1_000_000, pytest.param(pb.MAX_ANIMATION_BYTES, marks=pytest.mark.slow)],  # 1.5 s, 4 s
    ids=["1MB", "default"],
)
def test_long_run_keyframes_fit_the_page_budget_at_a_lower_rate_that_is_said(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, budget: int
) -> None:
    """A 300 s UR5 run with two ghosts: 28.7 MB of page before (30 keyframes per second, no
    cap); now its keyframes take at most MAX_ANIMATION_BYTES (8 MB: 11.8 MB of page), at a
    rate the page and a warning give.  (Packing 8 MB of keyframes takes seconds: the default
    suite checks a 1 MB budget.)"""
    monkeypatch.setattr(timeline, "MAX_ANIMATION_BYTES", budget)  # (the rate and the note)
    robot = pinobs.load("ur5")

    def run(duration: float) -> Any:
        t = np.arange(0.0, duration + 1e-9, 0.02)
        q = robot.neutral() + 0.5 * np.sin(0.7 * t[:, None] + np.arange(robot.nq))
        zeros = np.zeros((t.size, robot.nv))
        traces = tuple(
            pinobs.simulation.ObserverTrace(name, q + d, zeros, np.zeros(t.size))
            for name, d in (("kf", 0.01), ("ekf", -0.02))
        )
        return pinobs.simulation.Result(robot.name, t, q, zeros, zeros, q, traces)

    def animation(html: Path) -> str:
        (anim,) = [b for b in commands_b64(html) if b"set_animation" in base64.b64decode(b)[:40]]
        return anim

    with pytest.warns(pinobs.errors.PinobsWarning, match=r"keyframes at \d+(\.\d+)? per second"):
        html = write_html(run(300.0), robot, tmp_path / "long.html")
    short = write_html(run(1.5), robot, tmp_path / "short.html")
    anim = animation(html)
    assert 0.8 * budget < len(anim) <= budget  # 9000 frames of 21 shapes wanted
    # the rest of the page is the short run's (viewer, meshes), but for the chart's samples
    # (at most MAX_POINTS a curve; 2 ghosts: 21 curves)
    rest = html.stat().st_size - len(anim)
    assert rest < short.stat().st_size - len(animation(short)) + 21 * 800 * 10
    fps = {clip["fps"] for clip in clips(html).values()}
    assert len(fps) == 1 and 0.5 < min(fps) < FPS
    (track, _) = clips(html)["/meshcat/ghost_0_kf/" + robot.visual_model.geometryObjects[1].name][
        "tracks"
    ]
    fps = min(fps)
    assert track["keys"][-1]["time"] / fps == pytest.approx(300.0, abs=1.0 / fps)  # the whole run
    assert "keyframes at" in html.read_text(encoding="utf-8").split('id="pinobs-legend"')[1]


def test_short_run_keeps_every_frame_and_says_nothing_of_a_budget(
    cartpole_run: dict[str, Any],
) -> None:
    # (warnings are errors in the suite: the fixture's write_html warned of nothing)
    text = cartpole_run["html"].read_text(encoding="utf-8")
    assert "keyframes at" not in text and "pinobs-note" not in text.split("</style>")[1]
    assert all(clip["fps"] == FPS for clip in clips(cartpole_run["html"]).values())


def test_nan_rows_of_the_truth_hold_its_last_pose_and_the_page_says_so(
    cartpole_run: dict[str, Any], tmp_path: Path
) -> None:
    """A NaN stretch in ``Result.q`` (it was a numpy LinAlgError in the camera's SVD)."""
    result = cartpole_run["result"]
    q = np.array(result.q)
    q[100:200] = np.nan  # 0.5 s to 1.0 s at 200 Hz
    with pytest.warns(pinobs.errors.PinobsWarning, match=r"truth: no data 0.5–1 s: pose held"):
        html = write_html(
            dataclasses.replace(result, q=q), cartpole_run["robot"], tmp_path / "q.html"
        )
    legend = html.read_text(encoding="utf-8").split('id="pinobs-legend"')[1]
    assert "no data 0.5–1 s: pose held" in legend and "no data now: pose held" in legend
    name = cartpole_run["robot"].visual_model.geometryObjects[1].name
    (pos,) = [
        t
        for t in clips(html)["/meshcat/truth/visuals/" + name]["tracks"]
        if t["name"] == ".position"
    ]
    values = np.array([k["value"] for k in pos["keys"]])
    idx = pb.frame_indices(result.t, FPS)
    held = (idx >= 100) & (idx < 200)
    assert np.all(np.isfinite(values)) and held.sum() > 10
    robot = cartpole_run["robot"]
    geom = robot.visual_model
    placed = geometry.placements(
        robot.model, robot.model.createData(), geom, pin.GeometryData(geom), q[99]
    )
    np.testing.assert_array_equal(values[held], np.tile(placed[1].translation, (held.sum(), 1)))
    (before,) = [
        t
        for t in clips(cartpole_run["html"])["/meshcat/truth/visuals/" + name]["tracks"]
        if t["name"] == ".position"
    ]
    np.testing.assert_array_equal(
        values[~held], np.array([k["value"] for k in before["keys"]])[~held]
    )


def test_a_result_without_a_finite_configuration_is_refused(
    cartpole_run: dict[str, Any], tmp_path: Path
) -> None:
    result = cartpole_run["result"]
    empty = dataclasses.replace(result, q=np.full_like(result.q, np.nan))
    with pytest.raises(pinobs.errors.NonFiniteError, match="no motion to play back"):
        write_html(empty, cartpole_run["robot"], tmp_path / "x.html")


def ghost_with_a_gap(result: Any, lo: int, hi: int, off: float = 0.0) -> Any:
    """``result`` whose kf estimate is the truth, ``off`` [rad] off in its last coordinate, NaN on
    rows ``lo:hi`` (no divergence: dropped samples)."""
    tr = result.trace("kf")
    q = np.array(result.q)
    q[:, -1] += off
    q[lo:hi] = np.nan
    return dataclasses.replace(result, traces=(dataclasses.replace(tr, q=q),))


def test_ghost_is_hidden_while_its_estimate_is_nan_and_the_page_says_so(
    cartpole_run: dict[str, Any], tmp_path: Path
) -> None:
    """A ghost froze silently at its last estimate through NaN rows; now it is hidden there."""
    result = cartpole_run["result"]
    with pytest.warns(pinobs.errors.PinobsWarning, match=r"kf: no estimate 0.5–1 s: hidden"):
        html = write_html(
            ghost_with_a_gap(result, 100, 200), cartpole_run["robot"], tmp_path / "g.html"
        )
    assert "no estimate now: hidden" in html.read_text(encoding="utf-8")
    (track,) = clips(html)["/meshcat/ghost_0_kf"]["tracks"]
    assert track["name"] == ".visible" and track["type"] == "boolean"
    keys = {k["time"]: k["value"] for k in track["keys"]}
    idx = pb.frame_indices(result.t, FPS)
    frames = np.arange(len(idx))
    # a boolean track holds each key's value until the next key
    shown = np.array([keys[max(k for k in keys if k <= f)] for f in frames])
    np.testing.assert_array_equal(shown, ~((idx >= 100) & (idx < 200)))
    assert max(keys) == frames[-1]  # the clip lasts the whole run (clips loop on their own length)


def test_legend_names_the_stretches_without_an_estimate() -> None:
    e = pb.LegendEntry("kf", "#000000", "black", "ghost_0_kf", gaps=((0.5, 1.0), (1.2, 1.5)))
    assert e.gap_note == "no estimate in 2 stretches between 0.5 and 1.5 s (0.8 s in all): hidden"
    diverged = dataclasses.replace(e, diverged_at=1.2, gaps=((1.2, 1.5),))
    assert diverged.gap_note == "hidden from 1.2 s"  # (the divergence is said next to it)
    truth = pb.LegendEntry("truth", None, "model colours", "truth", gaps=((0.5, 1.0),))
    assert truth.gap_note == "no data 0.5–1 s: pose held"


def test_run_without_observers_shows_the_truth_alone(
    cartpole_run: dict[str, Any], tmp_path: Path
) -> None:
    bare = dataclasses.replace(cartpole_run["result"], traces=())
    html = write_html(bare, cartpole_run["robot"], tmp_path / "truth.html")
    assert not any("ghost" in p for p in clips(html))


@pytest.mark.parametrize("name", ["top", "rigid_body", "ur5"])
def test_every_root_joint_kind_plays_back(name: str, tmp_path: Path) -> None:
    robot = pinobs.load(name)
    result = pinobs.simulate(
        robot, ["kf"], duration=0.3, sensor=pinobs.Sensor(rate=100.0), perturb_q=0.2, seed=1
    )
    html = write_html(result, robot, tmp_path / f"{name}.html")
    by_path = clips(html)
    assert sum(p.startswith("/meshcat/ghost_0_kf/") for p in by_path) == robot.visual_model.ngeoms
    assert html.stat().st_size < 8e6
    # a floating base is followed: the scene moves opposite to the true base
    follows = "/meshcat" in by_path
    assert follows == (robot.joints[0].kind == "se3")
    if follows:
        (track,) = by_path["/meshcat"]["tracks"]
        shift = np.array([k["value"] for k in track["keys"]])
        base = result.q[pb.frame_indices(result.t, FPS), :3]
        np.testing.assert_allclose(shift - shift[0], -(base - base[0]), atol=1e-12)


def test_robot_without_meshes_gets_a_stick_figure(tmp_path: Path) -> None:
    bare = pinobs.load("planar_3r")
    robot = pinobs.Robot(bare.model, name="bare_3r", source="test")
    geom = geometry.visual_model(robot)
    spheres = [go for go in geom.geometryObjects if go.name.endswith("_joint")]
    rods = [go for go in geom.geometryObjects if go.name.endswith(("_rod", "_tip"))]
    assert len(spheres) == robot.model.njoints - 1
    assert len(rods) == robot.model.njoints - 1  # two rods between joints, one tip
    result = pinobs.simulate(robot, ["kf"], duration=0.2, sensor=pinobs.Sensor(rate=100.0), seed=1)
    html = write_html(result, robot, tmp_path / "bare.html")
    assert len([p for p in clips(html) if p.startswith("/meshcat/truth/")]) == geom.ngeoms


SLIDER_ARM_URDF = """<?xml version="1.0"?>
<robot name="slider_arm">
  <link name="base"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="5"/></joint>
  <link name="upper"><inertial><origin xyz="0.25 0 0"/><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="slide" type="prismatic"><parent link="upper"/><child link="carriage"/>
    <origin xyz="0.5 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.2" upper="0.4" effort="10" velocity="1"/></joint>
  <link name="carriage"><inertial><origin xyz="0.2 0 0"/><mass value="0.5"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
</robot>
"""


def test_stick_figure_of_a_prismatic_joint_stays_connected_as_it_slides(tmp_path: Path) -> None:
    """The rod to a slider ended where it is at q = 0: sliding out left a gap of the slide's
    length (0.3 m at q = 0.3).  Now it slides along a rail spanning its motion (here past its
    limit, 0.4 m), and its sphere stays on the figure."""
    urdf = tmp_path / "slider_arm.urdf"
    urdf.write_text(SLIDER_ARM_URDF)
    robot = pinobs.load(urdf)
    assert robot.visual_model is None or robot.visual_model.ngeoms == 0
    slides = np.array([-0.15, 0.0, 0.3, 0.6])
    qs = np.column_stack([np.full(slides.size, 0.4), slides])
    geom = geometry.visual_model(robot, [qs])
    model, data, gdata = robot.model, robot.model.createData(), pin.GeometryData(geom)
    j = model.getJointId("slide")
    assert [go.name for go in geom.geometryObjects if go.name.endswith("_rail")] == ["slide_rail"]

    def gap(q: np.ndarray) -> float:
        """Distance [m] from the slider's sphere to the nearest rod or rail not moving with it."""
        pin.framesForwardKinematics(model, data, q)
        pin.updateGeometryPlacements(model, data, geom, gdata)
        c = data.oMi[j].translation
        best = np.inf
        for k, go in enumerate(geom.geometryObjects):
            if go.name.endswith("_joint") or go.parentJoint == j:
                continue
            M, h = gdata.oMg[k], go.geometry.halfLength
            a, b = M.act(np.array([0.0, 0.0, -h])), M.act(np.array([0.0, 0.0, h]))
            s = np.clip((c - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
            best = min(best, float(np.linalg.norm(a + s * (b - a) - c)))
        return best

    assert max(gap(q) for q in qs) < 1e-12
    # without the motion, the rail spans the joint's limits
    bare = geometry.stick_figure(robot.model)
    (rail,) = [go for go in bare.geometryObjects if go.name == "slide_rail"]
    assert 2 * rail.geometry.halfLength == pytest.approx(0.6)
    html = write_html(
        pinobs.simulation.Result(robot.name, np.arange(4) / 30, qs, qs * 0, qs * 0, qs, ()),
        robot,
        tmp_path / "slider.html",
    )
    assert "/meshcat/truth/visuals/slide_rail" in clips(html)


def test_decimation_meets_the_triangle_budget_inside_the_mesh_box(
    rng: np.random.Generator,
) -> None:
    # a finely tessellated sphere (UV grid)
    u, v = np.meshgrid(np.linspace(0, np.pi, 120), np.linspace(0, 2 * np.pi, 240), indexing="ij")
    verts = np.stack([np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), np.cos(u)], -1).reshape(-1, 3)
    i = np.arange(119)[:, None] * 240 + np.arange(239)[None, :]
    faces = np.concatenate(
        [np.stack([i, i + 240, i + 1], -1), np.stack([i + 1, i + 240, i + 241], -1)]
    ).reshape(-1, 3)
    v2, f2 = geometry.decimate(verts, faces, 2000)
    assert len(faces) > 50_000 and 0 < len(f2) <= 2000
    assert np.all(np.abs(v2) <= 1.0 + 1e-12)
    assert np.max(np.abs(np.linalg.norm(v2, axis=1) - 1.0)) < 0.1  # still a sphere


def test_saved_result_plays_back_the_same_motion(
    cartpole_run: dict[str, Any], tmp_path: Path
) -> None:
    saved = cartpole_run["result"].save(tmp_path / "run.npz")
    html = write_html_from_file(saved, tmp_path / "from_file.html")
    assert clips(html) == clips(cartpole_run["html"])


def test_recorded_log_plays_back_measured_motion_and_estimate(
    cartpole_run: dict[str, Any], tmp_path: Path
) -> None:
    from pinobs.io import estimate_log, read_log, write_log

    robot, result = cartpole_run["robot"], cartpole_run["result"]
    path = write_log(tmp_path / "log.csv", result.t, result.q_meas, result.tau)
    log = read_log(path, robot)
    observer = pinobs.make_observer("kf", robot, rate=200.0, noise_std=1e-4)
    played = log_result(robot, log, {"kf": estimate_log(observer, log)})
    # the first row has no reading (the simulated sensor's first sample is dropped), hence no
    # estimate either: said
    with pytest.warns(pinobs.errors.PinobsWarning) as said:
        html = write_html(played, robot, tmp_path / "log.html", truth_label="measured")
    assert sorted(str(w.message) for w in said) == [
        "playback of cartpole: kf: no estimate 0–0.005 s: hidden",
        "playback of cartpole: measured: no data 0–0.005 s: pose held",
    ]
    text = html.read_text(encoding="utf-8")
    assert 'data-label="measured"' in text and "recorded motion" in text
    by_path = clips(html)
    assert any(p.startswith("/meshcat/ghost_0_kf/") for p in by_path)
    measured = np.all(np.isfinite(result.q_meas), axis=1)
    np.testing.assert_array_equal(played.q[measured], result.q_meas[measured])
    assert np.all(np.isnan(played.q[~measured]))  # kept as no data, not filled in


def test_result_of_another_robot_is_rejected(cartpole_run: dict[str, Any], tmp_path: Path) -> None:
    with pytest.raises(DimensionError, match="nq = 1"):
        write_html(cartpole_run["result"], pinobs.load("pendulum"), tmp_path / "x.html")


def test_unknown_observer_label_is_rejected(cartpole_run: dict[str, Any], tmp_path: Path) -> None:
    with pytest.raises(UnknownNameError, match="no observer 'ekf'"):
        write_html(
            cartpole_run["result"], cartpole_run["robot"], tmp_path / "x.html", observers=["ekf"]
        )


def test_every_template_is_package_data_and_fills_its_slots() -> None:
    """The templates ship in a wheel (pyproject's package-data globs cover each file); a
    template filled with the wrong slots is refused."""
    tomllib = pytest.importorskip("tomllib")  # (Python 3.11+)
    root = Path(pb.__file__).parent
    pyproject = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text("utf-8"))
    shipped = pyproject["tool"]["setuptools"]["package-data"]["pinobs.visualization.playback"]
    files = sorted(p.relative_to(root) for p in (root / "templates").iterdir())
    assert Path("templates/page.html") in files
    assert all(any(f.match(glob) for glob in shipped) for f in files)
    assert "pinobs.visualization.playback" in pyproject["tool"]["setuptools"]["packages"]
    page = fill_template("page.html", mainminjs="@X@", commands="", overlay="<p>@TITLE@</p>")
    assert "@X@" in page and "<p>@TITLE@</p>" in page  # (values are not read for slots)
    with pytest.raises(KeyError, match="has slots"):
        fill_template("page.html", mainminjs="", commands="")


def test_missing_meshcat_names_the_install_command(
    cartpole_run: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "meshcat", None)
    with pytest.raises(MissingDependencyError, match="pip install meshcat"):
        write_html(cartpole_run["result"], cartpole_run["robot"], tmp_path / "x.html")


def test_serve_prints_the_url_and_legend(
    cartpole_run: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The live path, on a recording window standing in for the server (no port opened)."""
    import meshcat

    window = RecordingWindow()
    window.web_url = "http://127.0.0.1:7000/static/"
    real = meshcat.Visualizer
    monkeypatch.setattr(meshcat, "Visualizer", lambda zmq_url=None: real(window=window))
    lines: list[str] = []
    viewer = serve(cartpole_run["result"], cartpole_run["robot"], echo=lines.append)
    assert viewer.url == "http://127.0.0.1:7000/static/"
    assert lines[0].endswith("http://127.0.0.1:7000/static/")
    assert any(f"kf: estimate, {PALETTE[0][0]}" in line for line in lines)
    assert any(umsgpack.unpackb(c)["type"] == "set_animation" for c in window.commands)


# --------------------------------------------------------------- browser

chromium = pytest.mark.skipif(
    find_chromium() is None, reason="no Chromium on PATH (apt-get install chromium)"
)


def chart_top(height: int) -> int:
    """First pixel row of the chart under the 3-D view (the page's CSS:
    ``--pinobs-chart-height: clamp(170px, 34vh, 340px)``)."""
    return height - round(min(max(170.0, 0.34 * height), 340.0))


def image(png: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(png).convert("RGB"), dtype=float)


def colour_masks(png: Path) -> dict[str, np.ndarray]:
    """In the 3-D view: pixels of the ghost's vermillion, the truth's blue pole, anything not white."""
    from matplotlib.colors import rgb_to_hsv

    rgb = image(png) / 255.0
    rgb = rgb[: chart_top(rgb.shape[0])]
    hsv = rgb_to_hsv(rgb)
    h, s, v = hsv[..., 0] * 360.0, hsv[..., 1], hsv[..., 2]
    return {
        "ghost": (h > 15) & (h < 45) & (s > 0.35) & (v > 0.5),
        "truth": (h > 200) & (h < 240) & (s > 0.4),
        "ink": np.any(rgb < 0.9, axis=-1),
    }


def centroid(mask: np.ndarray) -> np.ndarray:
    return np.argwhere(mask).mean(axis=0)


@chromium
def test_browser_shows_truth_and_ghost_in_their_colours(
    cartpole_run: dict[str, Any], tmp_path: Path
) -> None:
    png = screenshot(cartpole_run["html"], tmp_path / "t0.png", t=0.0, legend=False)
    m = colour_masks(png)
    total = m["ink"].size
    assert m["ink"].sum() > 0.01 * total  # not blank
    assert m["truth"].sum() > 500  # the blue pole (true motion)
    assert m["ghost"].sum() > 500  # the vermillion ghost (estimate)


@chromium
def test_browser_ghost_moves_onto_the_truth_along_the_timeline(
    cartpole_run: dict[str, Any], tmp_path: Path
) -> None:
    """Paused at t = 0, 0.02 s and the end: the ghost moves towards the truth, then disappears
    into it (ghosts are drawn behind a coincident truth), while the truth stays in full view."""
    html = cartpole_run["html"]
    start, early, end = (
        colour_masks(screenshot(html, tmp_path / f"{i}.png", t=t, legend=False))
        for i, t in enumerate((0.0, 0.02, DURATION))
    )
    # the cart-pole moves in the image plane: compare horizontal centroids [px]
    moved = abs(centroid(start["ghost"])[1] - centroid(early["ghost"])[1])
    gap_start = abs(centroid(start["ghost"])[1] - centroid(start["truth"])[1])
    gap_early = abs(centroid(early["ghost"])[1] - centroid(early["truth"])[1])
    assert moved > 20
    assert gap_start > 50  # apart at the perturbed start
    assert gap_early < 0.7 * gap_start
    assert end["ghost"].sum() < 0.02 * start["ghost"].sum()  # converged: inside the truth
    assert end["truth"].sum() > 0.8 * start["truth"].sum()


@chromium
def test_browser_hides_the_ghost_while_its_estimate_is_nan(
    cartpole_run: dict[str, Any], tmp_path: Path
) -> None:
    """A ghost 0.6 rad off the truth, its estimate NaN from 0.5 to 1 s: seen before, not within."""
    played = ghost_with_a_gap(cartpole_run["result"], 100, 200, off=0.6)
    with pytest.warns(pinobs.errors.PinobsWarning, match="no estimate"):
        html = write_html(played, cartpole_run["robot"], tmp_path / "gap.html")
    before, within = (
        colour_masks(screenshot(html, tmp_path / f"{i}.png", t=t, legend=False))
        for i, t in enumerate((0.25, 0.75))
    )
    assert before["ghost"].sum() > 500
    assert within["ghost"].sum() < 20
    assert within["truth"].sum() > 500


# ------------------------------------------------------------------ chart and floor


def chart_json(html: Path) -> dict[str, Any]:
    import json

    text = html.read_text(encoding="utf-8")
    start = text.index('<script id="pinobs-chart-data" type="application/json">')
    body = text[text.index(">", start) + 1 : text.index("</script>", start)]
    return dict(json.loads(body))


def test_page_embeds_the_chart_data_in_the_legend_colours(cartpole_run: dict[str, Any]) -> None:
    html, result = cartpole_run["html"], cartpole_run["result"]
    text = html.read_text(encoding="utf-8")
    assert 'id="pinobs-chart"' in text and "<canvas" in text
    data = chart_json(html)
    assert data["joints"] == ["cart_x", "pole_theta"] and data["units"] == ["m/s", "rad/s"]
    (kf,) = data["obs"]
    assert kf["colour"] == hex_colour(PALETTE[0][1])
    t = np.array(data["t"])
    assert t[0] == result.t[0] and t[-1] == pytest.approx(result.t[-1], abs=1e-12)
    assert len(t) <= 800
    k = np.searchsorted(result.t, t)  # the embedded samples are samples of the run
    err = np.linalg.norm(result.trace("kf").v - result.v, axis=1)[k]
    np.testing.assert_allclose(np.array(kf["err"], dtype=float), err, rtol=1e-3)
    np.testing.assert_allclose(np.array(data["truth"][1], dtype=float), result.v[k, 1], atol=1e-3)


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e200])
def test_chart_of_an_estimate_lost_before_the_clip_start_warns_nothing(
    cartpole_run: dict[str, Any], bad: float
) -> None:
    """An estimate NaN (or inf, or overflowing) from early on next to a good one: numpy's "Mean
    of empty slice" (and overflow) RuntimeWarnings leaked out of chart_data; warnings are errors
    here.  The joint shown first is the good estimate's worst."""
    from pinobs.visualization.chart import chart_data

    result, robot = cartpole_run["result"], cartpole_run["robot"]
    kf = result.trace("kf")
    v = np.array(kf.v)
    v[len(v) // 10 :] = bad  # lost from 0.15 s on, before the transient clipped for the range
    lost = dataclasses.replace(kf, name="lost", v=v, diverged_at=float(result.t[len(v) // 10]))
    data = chart_data(
        dataclasses.replace(result, traces=(kf, lost)), robot, ["kf", "lost"], ["#111111"] * 2
    )
    alone = chart_data(result, robot, ["kf"], ["#111111"])
    assert data["joint"] == alone["joint"] and data["range"] == alone["range"]
    assert all(x is None for x in data["obs"][1]["err"][len(data["t"]) // 5 :])


def test_floor_grid_lies_under_the_ur5_and_ends_before_the_camera(tmp_path: Path) -> None:
    robot = pinobs.load("ur5")
    result = pinobs.simulate(robot, ["kf"], duration=0.3, sensor=pinobs.Sensor(rate=100.0), seed=1)
    cmds = commands(write_html(result, robot, tmp_path / "ur5.html"))
    (floor,) = [c for c in cmds if c["type"] == "set_object" and c["path"] == "/meshcat/floor"]
    geometry = floor["object"]["geometries"][0]["data"]["attributes"]["position"]
    xyz = np.frombuffer(geometry["array"].data, dtype=np.float32).reshape(
        -1, 3
    )  # msgpack ext: raw float32
    assert np.all(xyz[:, 2] == 0.0)  # the plane the base stands on
    lo, hi = xyz[:, :2].min(axis=0), xyz[:, :2].max(axis=0)
    assert np.all(lo < 0.0) and np.all(hi > 0.0)  # under the base
    hidden = [c for c in cmds if c["type"] == "set_property" and c["path"] == "/Grid"]
    assert hidden and hidden[-1]["value"] is False  # meshcat's own grid is off
    (cam,) = [c for c in cmds if c["path"] == "/Cameras/default/rotated/<object>"]
    (scene,) = [c for c in cmds if c["type"] == "set_transform" and c["path"] == "/meshcat"]
    centre = -np.array(scene["matrix"], dtype=float).reshape(4, 4).T[:3, 3]
    x, y_up, minus_y = cam["value"]  # meshcat's camera frame: world (x, y, z) = (x, -z, y)
    camera = centre + np.array([x, -minus_y, y_up])
    assert not (lo[0] <= camera[0] <= hi[0] and lo[1] <= camera[1] <= hi[1])


@pytest.fixture(scope="module")
def payload_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A cart-pole carrying a payload its observers do not know: at t = 1 s the EKF (model-based,
    nominal model) is far off, kf and fd (model-free) are close (seeded; measured errors at 1 s:
    ekf 0.66, fd 0.05, kf 0.01)."""
    from pinobs.simulation import mismatched_plant

    robot = pinobs.load("cartpole")
    result = pinobs.simulate(
        robot,
        ["kf", "ekf", "fd"],
        duration=1.5,
        sensor=pinobs.Sensor(rate=500.0, noise_std=1e-4),
        plant=mismatched_plant(robot, "inertia20_payload", seed=0),
        perturb_q=0.05,
        perturb_v=0.5,
        seed=0,
    )
    html = write_html(result, robot, tmp_path_factory.mktemp("payload") / "payload.html")
    return {"robot": robot, "result": result, "html": html}


def near(img: np.ndarray, hex_rgb: str, tol: float = 25.0) -> np.ndarray:
    rgb = np.array([int(hex_rgb[i : i + 2], 16) for i in (1, 3, 5)], dtype=float)
    return np.linalg.norm(img - rgb, axis=-1) < tol


def chart_cursor_columns(img: np.ndarray) -> list[int]:
    """Columns of the chart where the cursor colour (#444444) runs down most of the panel."""
    chart = img[chart_top(img.shape[0]) :]
    cursor = near(chart, "#444444", tol=20.0)
    return [int(c) for c in np.flatnonzero(cursor.sum(axis=0) > 0.5 * chart.shape[0])]


@chromium
def test_browser_chart_is_drawn_with_one_colour_per_observer(
    payload_run: dict[str, Any], tmp_path: Path
) -> None:
    img = image(screenshot(payload_run["html"], tmp_path / "c.png", t=1.0, legend=False))
    chart = img[chart_top(img.shape[0]) + 25 :]  # below the chart's header line
    w = chart.shape[1]
    assert near(chart[:, : w // 2], "#000000", tol=60.0).sum() > 300  # the truth, left panel
    colours = [o["colour"] for o in chart_json(payload_run["html"])["obs"]]
    assert len(set(colours)) == 3
    for c in colours:  # each estimate is drawn, in both panels, in its own colour
        assert near(chart[:, : w // 2], c).sum() > 30
        assert near(chart[:, w // 2 :], c).sum() > 100


@chromium
def test_browser_screenshot_at_one_second_shows_which_estimate_is_worst(
    payload_run: dict[str, Any], tmp_path: Path
) -> None:
    """On the error panel, at the cursor, the worst estimate's dot is the highest (log axis):
    the one a person would point at.  The data's worst at t = 1 s is checked independently."""
    result = payload_run["result"]
    k = int(np.argmin(np.abs(result.t - 1.0)))
    errors = {
        n: float(np.linalg.norm(result.trace(n).v[k] - result.v[k])) for n in ("kf", "ekf", "fd")
    }
    worst = max(errors, key=errors.__getitem__)
    img = image(screenshot(payload_run["html"], tmp_path / "w.png", t=1.0, legend=False))
    (x,) = [c for c in chart_cursor_columns(img) if c >= img.shape[1] // 2][:1]
    top = chart_top(img.shape[0]) + 25
    band = img[top:, x - 6 : x + 8]
    rows = {}
    for o in chart_json(payload_run["html"])["obs"]:
        hit = np.flatnonzero(near(band, o["colour"]).any(axis=1))
        assert hit.size, o["name"]
        rows[o["name"]] = float(np.median(hit))
    assert min(rows, key=rows.__getitem__) == worst == "ekf"
    others = [r for n, r in rows.items() if n != worst]
    assert min(others) - rows[worst] > 30  # [px]: clearly apart


class Browser:
    """Headless Chromium driven over the DevTools protocol on a pipe (``--remote-debugging-pipe``:
    JSON messages ending in NUL; the browser reads fd 3 and writes fd 4).  Test-only."""

    def __init__(self, url: str, size: tuple[int, int] = (800, 600)) -> None:
        import os
        import subprocess
        import tempfile

        exe = find_chromium()
        assert exe is not None
        to_child, self._out = os.pipe()
        self._in, from_child = os.pipe()
        high = [os.dup(to_child), os.dup(from_child)]  # out of the way of fds 3 and 4

        def wire() -> None:
            os.dup2(high[0], 3)
            os.dup2(high[1], 4)

        self._profile = tempfile.TemporaryDirectory(prefix="pinobs-cdp-")
        self.proc = subprocess.Popen(
            [
                exe,
                "--headless",
                "--no-sandbox",
                "--use-gl=swiftshader",
                "--enable-unsafe-swiftshader",
                "--no-first-run",
                "--disable-background-networking",
                "--remote-debugging-pipe",
                f"--user-data-dir={self._profile.name}",
                f"--window-size={size[0]},{size[1]}",
                "about:blank",
            ],
            preexec_fn=wire,
            start_new_session=True,  # its helper processes share the session: close() ends them
            close_fds=False,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for fd in (to_child, from_child, *high):
            os.close(fd)
        self._id = 0
        self._buf = b""
        target = self.call("Target.createTarget", url=url)["targetId"]
        self.session = self.call("Target.attachToTarget", targetId=target, flatten=True)[
            "sessionId"
        ]
        self.call(  # the viewport itself (the window size includes the browser's frame)
            "Emulation.setDeviceMetricsOverride",
            session=self.session,
            width=size[0],
            height=size[1],
            deviceScaleFactor=1,
            mobile=False,
        )

    def call(self, method: str, session: str | None = None, **params: Any) -> dict[str, Any]:
        import json
        import os

        self._id += 1
        msg: dict[str, Any] = {"id": self._id, "method": method, "params": params}
        if session:
            msg["sessionId"] = session
        os.write(self._out, json.dumps(msg).encode() + b"\0")
        while True:
            while b"\0" not in self._buf:
                chunk = os.read(self._in, 1 << 16)
                if not chunk:
                    raise RuntimeError("Chromium closed the DevTools pipe")
                self._buf += chunk
            raw, self._buf = self._buf.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(reply["error"])
                return dict(reply["result"])

    def js(self, expression: str) -> Any:
        out = self.call(
            "Runtime.evaluate",
            session=self.session,
            expression=expression,
            returnByValue=True,
            awaitPromise=True,
        )
        return out["result"].get("value")

    def mouse(self, kind: str, x: float, y: float, buttons: int) -> None:
        self.call(
            "Input.dispatchMouseEvent",
            session=self.session,
            type=kind,
            x=x,
            y=y,
            button="left",
            buttons=buttons,
            clickCount=1,
        )

    def wait_for_page(self, timeout: float = 60.0) -> None:
        """Until the viewer has its animation and the chart its size."""
        import time

        deadline = time.monotonic() + timeout
        while not self.js(
            "typeof viewer !== 'undefined' && viewer.animator.actions.length > 0 && "
            "document.getElementById('pinobs-chart-canvas').clientWidth > 0"
        ):
            assert time.monotonic() < deadline, "the page did not load"
            time.sleep(0.2)

    def settle(self, read: Any, ready: Any, timeout: float = 10.0) -> Any:
        """``read()`` again every 50 ms until ``ready(value)`` or ``timeout`` [s]; the last value.

        The page redraws on animation frames, which a loaded machine delays: the
        assertions then run on a settled page (no fixed sleep), unchanged."""
        import time

        deadline = time.monotonic() + timeout
        value = read()
        while not ready(value) and time.monotonic() < deadline:
            time.sleep(0.05)
            value = read()
        return value

    def screenshot(self) -> np.ndarray:
        """The page as RGB pixels (0–255)."""
        import io

        from PIL import Image

        data = self.call("Page.captureScreenshot", session=self.session, format="png")["data"]
        png = Image.open(io.BytesIO(base64.b64decode(data))).convert("RGB")
        return np.asarray(png, dtype=float)

    def close(self) -> None:
        """Chromium asked to quit (it ends its helpers and lets go of the profile), then
        whatever is left of its session killed, then the profile removed.  Killing only
        the main process left helpers writing into the profile as it was removed
        (``OSError: Directory not empty`` once, in a CI rehearsal)."""
        import os
        import signal
        import subprocess

        try:
            self.call("Browser.close")
        except (RuntimeError, OSError):
            pass  # the pipe closed first: it is quitting
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            pass
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait()
        os.close(self._out)
        os.close(self._in)
        self._profile.cleanup()


@chromium
def test_browser_dragging_on_the_chart_moves_the_animation_and_the_cursor(
    payload_run: dict[str, Any],
) -> None:
    """A real pointer drag on the chart (DevTools Input events): the animation pauses at the
    time under the pointer, the legend's clock shows it, the chart's cursor follows it, and
    the 3-D view shows that frame (a ghost node's keyframed position at that time)."""

    browser = Browser(payload_run["html"].as_uri())
    try:
        browser.wait_for_page()
        box = browser.js(
            "(() => { const r = document.getElementById('pinobs-chart-canvas')"
            ".getBoundingClientRect(); return [r.left, r.top, r.width, r.height]; })()"
        )
        left, top, width, height = box
        y = top + height / 2
        times = []
        for frac in (0.6, 0.85):  # on the error panel (the right half)
            x0, x1 = left + 0.55 * width, left + frac * width
            browser.mouse("mousePressed", x0, y, 1)
            browser.mouse("mouseMoved", (x0 + x1) / 2, y, 1)
            browser.mouse("mouseMoved", x1, y, 1)
            browser.mouse("mouseReleased", x1, y, 0)

            def read(x0: float = x0) -> tuple[Any, ...]:
                return (
                    browser.js("viewer.animator.actions[0].time"),
                    browser.js("!viewer.animator.playing"),
                    browser.js("document.getElementById('pinobs-time').textContent"),
                    browser.js("document.getElementById('pinobs-readout').textContent"),
                    [c for c in chart_cursor_columns(browser.screenshot()) if c > x0],
                )

            def ready(v: tuple[Any, ...], x1: float = x1) -> bool:
                t, paused, clock, readout, right = v
                return bool(
                    paused
                    and clock == f"t = {t:.2f} s"
                    and readout.startswith(f"at t = {t:.2f} s")
                    and right
                    and abs(np.mean(right) - x1) <= 2.0
                )

            t, paused, clock, readout, right = browser.settle(read, ready)
            assert paused
            assert clock == f"t = {t:.2f} s"
            assert readout.startswith(f"at t = {t:.2f} s")
            assert right and abs(np.mean(right) - x1) <= 2.0  # the cursor is under the pointer
            times.append(t)
            # the 3-D view shows that instant: the ekf ghost's pole where its clip has it at t
            name = payload_run["robot"].visual_model.geometryObjects[1].name
            shown = browser.js(
                f"viewer.scene_tree.find(['meshcat', 'ghost_1_ekf', '{name}']).object.position"
                ".toArray()"
            )
            (track,) = [
                tr
                for tr in clips(payload_run["html"])[f"/meshcat/ghost_1_ekf/{name}"]["tracks"]
                if tr["name"] == ".position"
            ]
            keys = np.array([k["value"] for k in track["keys"]])
            expected = [np.interp(t * FPS, np.arange(len(keys)), keys[:, i]) for i in range(3)]
            np.testing.assert_allclose(shown, expected, atol=1e-4)
        t_a, t_b = times
        duration = float(payload_run["result"].t[-1])
        # the right panel spans [half + 58, width - 12] px of the canvas (chart.py's layout)
        for frac, t in zip((0.6, 0.85), times, strict=True):
            x = frac * width
            x0, x1 = math.floor(width / 2) + 58, width - 12
            assert t == pytest.approx((x - x0) / (x1 - x0) * duration, abs=0.02)
        assert t_b > t_a + 0.2
    finally:
        browser.close()


@chromium
def test_browser_chart_cursor_follows_the_animation_time(payload_run: dict[str, Any]) -> None:
    """Paused at 0.25, 0.5 and 1 s (``#t=``, as meshcat's time slider does: ``seek``): one
    cursor per panel, moving right in proportion to time."""

    browser = Browser(payload_run["html"].as_uri())
    try:
        browser.wait_for_page()
        xs = []
        for t in (0.25, 0.5, 1.0):
            browser.js(f"window.location.hash = 't={t}&nolegend'")

            def halves() -> tuple[float, list[float], list[float]]:
                shown = browser.js("viewer.animator.actions[0].time")
                img = browser.screenshot()
                cols, w = chart_cursor_columns(img), img.shape[1]
                return shown, [c for c in cols if c < w // 2], [c for c in cols if c >= w // 2]

            def one_each(v: tuple[float, list[float], list[float]], t: float = t) -> bool:
                shown, left, right = v  # at t, and (after the first) drawn right of the last
                moved = not xs or (bool(right) and np.mean(right) > xs[-1][1] + 1.0)
                return bool(abs(shown - t) < 1e-6 and left and right and moved)

            _, left, right = browser.settle(halves, one_each)
            assert left and right and max(left) - min(left) <= 2 and max(right) - min(right) <= 2
            xs.append((np.mean(left), np.mean(right)))
    finally:
        browser.close()
    x = np.array(xs)
    assert np.all(np.diff(x, axis=0) > 20)  # [px]
    # equal time steps, equal moves: x(1.0) - x(0.5) = 2 (x(0.5) - x(0.25))
    np.testing.assert_allclose(x[2] - x[1], 2 * (x[1] - x[0]), atol=3.0)


def test_saved_result_of_a_robot_file_plays_back_from_another_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # robot_source was stored relative to the cwd, and write_html_from_file ignored it
    (tmp_path / "arm").mkdir()
    urdf = tmp_path / "arm" / "myarm.urdf"
    urdf.write_text(ARM_URDF)
    monkeypatch.chdir(tmp_path / "arm")
    robot = pinobs.load("myarm.urdf")
    result = pinobs.simulate(robot, ["kf"], duration=0.1)
    assert result.meta["robot_source"] == str(urdf)
    saved = result.save(tmp_path / "my.npz")
    monkeypatch.chdir(tmp_path)
    assert write_html_from_file(saved, tmp_path / "my.html").is_file()


ARM_URDF = """<?xml version="1.0"?>
<robot name="myarm">
  <link name="world"/>
  <joint name="j" type="revolute">
    <parent link="world"/><child link="rod"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="100" velocity="10"/>
  </joint>
  <link name="rod">
    <inertial><origin xyz="0 0 0.5"/><mass value="1"/>
      <inertia ixx="0.08" ixy="0" ixz="0" iyy="0.08" iyz="0" izz="0.001"/></inertial>
  </link>
</robot>
"""
