"""Meshcat playback: the scene and timeline in the HTML, and what a real browser shows.

The browser tests render the page in headless Chromium (SwiftShader WebGL)
and count pixels by colour; they skip only where no Chromium is installed.
"""

from __future__ import annotations

import base64
import dataclasses
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
    assert pb._hex(pb.GHOST_COLOURS[0][1]) in legend  # the ghost's swatch colour


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
    geom = pb._visual_model(robot)
    spheres = [go for go in geom.geometryObjects if go.name.endswith("_joint")]
    rods = [go for go in geom.geometryObjects if go.name.endswith(("_rod", "_tip"))]
    assert len(spheres) == robot.model.njoints - 1
    assert len(rods) == robot.model.njoints - 1  # two rods between joints, one tip
    result = pinobs.simulate(robot, ["kf"], duration=0.2, sensor=pinobs.Sensor(rate=100.0), seed=1)
    html = write_html(result, robot, tmp_path / "bare.html")
    assert len([p for p in clips(html) if p.startswith("/meshcat/truth/")]) == geom.ngeoms


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
    v2, f2 = pb._decimate(verts, faces, 2000)
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
    html = write_html(played, robot, tmp_path / "log.html", truth_label="measured")
    text = html.read_text(encoding="utf-8")
    assert 'data-label="measured"' in text and "recorded motion" in text
    by_path = clips(html)
    assert any(p.startswith("/meshcat/ghost_0_kf/") for p in by_path)
    measured = np.all(np.isfinite(result.q_meas), axis=1)
    np.testing.assert_array_equal(played.q[measured], result.q_meas[measured])


def test_result_of_another_robot_is_rejected(cartpole_run: dict[str, Any], tmp_path: Path) -> None:
    with pytest.raises(DimensionError, match="nq = 1"):
        write_html(cartpole_run["result"], pinobs.load("pendulum"), tmp_path / "x.html")


def test_unknown_observer_label_is_rejected(cartpole_run: dict[str, Any], tmp_path: Path) -> None:
    with pytest.raises(UnknownNameError, match="no observer 'ekf'"):
        write_html(
            cartpole_run["result"], cartpole_run["robot"], tmp_path / "x.html", observers=["ekf"]
        )


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

    window = pb._RecordingWindow()
    window.web_url = "http://127.0.0.1:7000/static/"
    real = meshcat.Visualizer
    monkeypatch.setattr(meshcat, "Visualizer", lambda zmq_url=None: real(window=window))
    lines: list[str] = []
    viewer = serve(cartpole_run["result"], cartpole_run["robot"], echo=lines.append)
    assert viewer.url == "http://127.0.0.1:7000/static/"
    assert lines[0].endswith("http://127.0.0.1:7000/static/")
    assert any("kf: estimate, orange" in line for line in lines)
    assert any(umsgpack.unpackb(c)["type"] == "set_animation" for c in window.commands)


# --------------------------------------------------------------- browser

chromium = pytest.mark.skipif(
    find_chromium() is None, reason="no Chromium on PATH (apt-get install chromium)"
)


def colour_masks(png: Path) -> dict[str, np.ndarray]:
    """Pixels of the ghost's orange, the truth's blue pole and anything not white."""
    from matplotlib.colors import rgb_to_hsv
    from PIL import Image

    rgb = np.asarray(Image.open(png).convert("RGB"), dtype=float) / 255.0
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
    assert m["ghost"].sum() > 500  # the orange ghost (estimate)


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
